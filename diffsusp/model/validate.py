"""Checks made before any solve: joints assembled at design, DOF, rank, redundancy, free modes.

At the design position (q = 0) the constraint Jacobian Φ_q is scaled to consistent units (angular
rows and rotation columns by the model's length scale) and its rank found by SVD. Rows that
depend on earlier rows are redundant: they are reported and dropped from the solve (their
multipliers are zero, one valid distribution of the joint reactions), as Adams does. A mode
that no constraint blocks and no element resists — a direction in the null space of Φ_q where
the design tangent stiffness vanishes — makes the equilibrium singular; it is named by the part
that moves most in it.
"""

import dataclasses

import jax.numpy as jnp
import numpy as np

from ..compilation import filter_jit
from ..errors import ModelError
from ..statics.kernel import assemble, constraint_values, to_internal
from .mechanism import JOINT_ROWS, Mechanism


@dataclasses.dataclass(frozen=True)
class ValidationReport:
    """Structure of a mechanism at its design position.

    **Fields:** `n_coordinates` (6 per moving part), `n_rows` (joint and driver rows), `rank`
    of Φ_q, `dof` = n_coordinates − rank (kinematic degrees of freedom, bushings ignored),
    `redundant` (names of dropped rows), `free_modes` (descriptions of modes with neither
    constraint nor stiffness), `max_assembly_error` (largest constraint violation at design, mm).
    """

    n_coordinates: int
    n_rows: int
    rank: int
    dof: int
    redundant: tuple[str, ...]
    free_modes: tuple[str, ...]
    max_assembly_error: float

    def __str__(self) -> str:
        lines = [
            f"coordinates: {self.n_coordinates}, constraint rows: {self.n_rows}, "
            f"rank: {self.rank}, kinematic DOF: {self.dof}",
            f"redundant rows: {', '.join(self.redundant) if self.redundant else 'none'}",
            f"free modes: {'; '.join(self.free_modes) if self.free_modes else 'none'}",
        ]
        return "\n".join(lines)


def _row_names(mech: Mechanism) -> list[str]:
    names = []
    for name, kind in zip(mech.joints.names, mech.joints.kind, strict=True):
        names += [f"joint '{name}' ({kind}) row {r}" for r in range(JOINT_ROWS[kind])]
    names += [f"driver '{name}'" for name in mech.drivers.names]
    return names


@filter_jit
def _at_design(mech: Mechanism, loads):
    q0 = to_internal(mech, jnp.zeros(mech.n_coordinates))
    phi = constraint_values(mech, loads, q0)
    r, jac = assemble(mech, loads, q0, jnp.zeros(mech.topology.m))
    return phi, r, jac


def design_terms(mech: Mechanism, loads=None):
    """At the design position q = 0 with every constraint row kept and zero multipliers, under
    `loads` (one case; default none): constraint values Φ, the KKT residual r (generalised
    forces, then the rows) and its Jacobian (numpy). One compiled program per model structure,
    whatever the model's name or corners (validation and `diffsusp.kc.corner.equilibrium_load`
    share it)."""
    all_rows = dataclasses.replace(mech, independent_rows=tuple(range(mech.n_rows)), name="",
                                   corners=())
    phi, r, jac = _at_design(all_rows, all_rows.loads() if loads is None else loads)
    return np.asarray(phi), np.asarray(r), np.asarray(jac)


def _design_matrices(mech: Mechanism):
    """Constraint values, Φ_q (all rows) and tangent stiffness at q = 0 with no load."""
    lay = dataclasses.replace(mech, independent_rows=tuple(range(mech.n_rows))).topology
    phi, _, jac = design_terms(mech)
    n = mech.n_coordinates
    return phi, jac[n:, :n], -jac[:n, :n], lay


def _scales(mech: Mechanism, angular: np.ndarray):
    n_parts = len(mech.parts)
    col = np.tile(np.r_[np.ones(3), np.full(3, 1.0 / mech.length_scale)], n_parts)
    row = np.where(angular, mech.length_scale, 1.0)
    return row, col


def _independent_rows(phi_q: np.ndarray, tol: float) -> list[int]:
    """Greedy selection, in row order, of rows not in the span of the rows kept before."""
    kept: list[np.ndarray] = []
    rows = []
    for r, a in enumerate(phi_q):
        v = a.copy()
        for u in kept:
            v -= (u @ v) * u
        if np.linalg.norm(v) > tol * max(np.linalg.norm(a), 1e-300):
            kept.append(v / np.linalg.norm(v))
            rows.append(r)
    return rows


def _describe_mode(mech: Mechanism, mode: np.ndarray) -> str:
    per_part = mode.reshape(-1, 6)
    weight = np.linalg.norm(per_part, axis=1)
    part = int(np.argmax(weight))
    trans, rot = per_part[part, :3], per_part[part, 3:] * mech.length_scale
    if np.linalg.norm(rot) >= np.linalg.norm(trans):
        axis = rot / np.linalg.norm(rot)
        what = f"rotation about axis ({axis[0]:.3f}, {axis[1]:.3f}, {axis[2]:.3f})"
    else:
        axis = trans / np.linalg.norm(trans)
        what = f"translation along ({axis[0]:.3f}, {axis[1]:.3f}, {axis[2]:.3f})"
    others = [mech.parts[k] for k in np.argsort(-weight)[1:] if weight[k] > 0.1 * weight[part]]
    also = f" (with {', '.join(repr(o) for o in others)})" if others else ""
    return f"part '{mech.parts[part]}' is free: {what}{also}"


def validate(mech: Mechanism, *, tol: float = 1e-9) -> ValidationReport:
    """Check a mechanism at design and report its structure (see the module docstring)."""
    report, _ = _analyse(mech, tol)
    return report


def _analyse(mech: Mechanism, tol: float):
    phi, phi_q, stiffness, lay = _design_matrices(mech)
    row_scale, col_scale = _scales(mech, lay.angular)
    names = _row_names(mech)
    assembly = np.abs(phi) * np.where(lay.angular, mech.length_scale, 1.0)
    n = mech.n_coordinates
    scaled = phi_q * row_scale[:, None] * col_scale[None, :]
    independent = _independent_rows(scaled, 1e-7)
    rank = len(independent)
    redundant = tuple(names[r] for r in range(mech.n_rows) if r not in independent)
    # Free modes: null space of Φ_q where the (scaled, symmetrised) stiffness vanishes.
    if rank:
        _, s, vt = np.linalg.svd(scaled[independent], full_matrices=True)
        null = vt[rank:].T
    else:
        null = np.eye(n)
    free = []
    if null.shape[1]:
        k_s = stiffness * col_scale[:, None] * col_scale[None, :]
        k_r = null.T @ (0.5 * (k_s + k_s.T)) @ null
        w, v = np.linalg.eigh(k_r)
        k_ref = max(np.max(np.abs(np.diag(k_s))), 1e-300)
        for e in np.flatnonzero(np.abs(w) <= tol * k_ref):
            free.append(_describe_mode(mech, col_scale * (null @ v[:, e])))
    report = ValidationReport(
        n_coordinates=n,
        n_rows=mech.n_rows,
        rank=rank,
        dof=n - rank,
        redundant=redundant,
        free_modes=tuple(free),
        max_assembly_error=float(assembly.max()) if assembly.size else 0.0,
    )
    return report, (independent, assembly, names)


def finalize(mech: Mechanism, *, check: bool = True) -> Mechanism:
    """Drop redundant rows (kept in `independent_rows`) and, with `check`, raise `ModelError`
    for joints not assembled at design and for free modes."""
    report, (independent, assembly, names) = _analyse(mech, 1e-9)
    if check:
        bad = np.flatnonzero(assembly > 1e-6)
        if bad.size:
            r = int(bad[0])
            raise ModelError(
                f"{names[r]} is violated by {assembly[r]:.3g} mm at design: the joint's markers "
                "must coincide (and their axes agree) in the design position. Check the "
                "markers' positions and orientations."
            )
        if report.free_modes:
            raise ModelError(
                "the mechanism has modes with neither constraint nor stiffness, so its "
                "equilibrium is undetermined: " + "; ".join(report.free_modes) + ". Add a joint "
                "or stiffness that holds it (e.g. a distance joint for a link between two ball "
                "joints), or build with check=False."
            )
    return dataclasses.replace(mech, independent_rows=tuple(independent))
