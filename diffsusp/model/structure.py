"""A mechanism's structure at its design position, in NumPy: what `MechanismBuilder.build`
checks, compiling nothing.

At q = 0 every part is at its design pose, so the constraint rows and their Jacobian are closed
forms of the markers' design positions and axes (the candidate quantities of
`topology.JOINT_CANDIDATES`, spec stiffness §1.6): differentiated in twist coordinates (δP, ω)
of each part, a point x of part a moves by δP + ω × (x − P_a) and an axis by ω × a; the Gibbs
coordinates of the solver turn a part by ω = G(0)·db = 2·db (spec §1.4). The force elements
contribute their material stiffness at design, Bᵀ·k·B with B the element's deformation rates and
k its law's slope (linear and cubic terms; tables by the secant of the knot interval);
preload (geometric) terms are left out.

`analyse` reads the structure from these matrices: Φ_q is scaled to consistent units (angular
rows and rotation columns by the model's length scale) and its rows that depend on earlier rows
are redundant: dropped from the solve (their multipliers are zero, one valid distribution of the
joint reactions), as Adams does. A mode that no constraint blocks and no element resists — a
direction in the null space of Φ_q where the stiffness vanishes — makes the equilibrium
singular; it is named by the part that moves most in it. `diffsusp.statics.validate` runs the
same analysis on the solver's exact design Jacobian (preloads included).
"""

import dataclasses

import numpy as np

from ..errors import ModelError
from .kinds import JOINT_ROWS
from .mechanism import Mechanism


def _skew(v):
    """Cross-product matrices (..., 3, 3) of vectors (..., 3): `_skew(u) @ v = u × v`."""
    z = np.zeros(v.shape[:-1])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([np.stack([z, -w, y], -1), np.stack([w, z, -x], -1),
                     np.stack([-y, x, z], -1)], -2)


def _gap_rate(xi, xj, pi, pj):
    """∂(x_i − x_j)/∂(δP_I, ω_I, δP_J, ω_J) (E, 3, 12) of points x_i on part I, x_j on J."""
    eye = np.broadcast_to(np.eye(3), (*xi.shape[:-1], 3, 3))
    return np.concatenate([eye, -_skew(xi - pi), -eye, _skew(xj - pj)], -1)


def _turn_rate(c):
    """∂(a·b)/∂(δP_I, ω_I, δP_J, ω_J) (E, 12) of a dot product of an axis a of I and b of J,
    c = a × b: (ω_I − ω_J)·c."""
    z = np.zeros_like(c)
    return np.concatenate([z, c, z, -c], -1)


class _Elements:
    """Design poses of the two markers of each element of a kind, and their parts' slots."""

    def __init__(self, mech: Mechanism, i_marker, j_marker):
        topo = mech.topology
        i, j = np.asarray(i_marker, dtype=int), np.asarray(j_marker, dtype=int)
        position = np.asarray(mech.markers.position, dtype=float)
        axes = np.asarray(mech.markers.orientation, dtype=float)
        self.xi, self.xj = position[i], position[j]
        self.ai, self.aj = axes[i], axes[j]
        self.pi, self.pj = topo.centre[topo.marker_part[i]], topo.centre[topo.marker_part[j]]
        self.coords = topo.coords(i, j)
        self.gap = _gap_rate(self.xi, self.xj, self.pi, self.pj)


def _to_gibbs(mech: Mechanism, twist_columns: np.ndarray) -> np.ndarray:
    """Columns in twist coordinates (full slot vector, ground last) → the Gibbs coordinates of
    the moving parts at design (ground dropped, rotation columns × 2)."""
    n = mech.n_coordinates
    return twist_columns[..., :n] * np.tile([1.0, 1.0, 1.0, 2.0, 2.0, 2.0], n // 6)


def design_rows(mech: Mechanism) -> tuple[np.ndarray, np.ndarray]:
    """Every constraint row at the design position under no driver motion, and its Jacobian
    in the solver's Gibbs coordinates: (Φ (n_rows,), Φ_q (n_rows, n)), joints then drivers,
    redundant rows included."""
    topo = mech.topology
    n_rows, size = mech.n_rows, topo.n + 6
    phi = np.zeros(n_rows + 1)  # the last entry takes the padding rows
    jac = np.zeros((n_rows + 1, size))
    if mech.joints.names:
        e = _Elements(mech, mech.joints.i_marker, mech.joints.j_marker)
        d = e.xi - e.xj
        dist = np.linalg.norm(d, axis=-1)
        zi, xi_axis, aj = e.ai[..., 2], e.ai[..., 0], e.aj
        u = d / np.where(dist > 0.0, dist, 1.0)[:, None]
        values = np.concatenate([
            d, np.einsum("eik,ei->ek", aj, d), np.einsum("eik,ei->ek", aj[..., :2], zi),
            np.sum(xi_axis * aj[..., 1], -1)[:, None], np.sum(zi * aj[..., 2], -1)[:, None],
            np.zeros((len(d), 2)),
        ], -1)
        spin = np.zeros((len(d), 3, 12))
        spin[..., 9:] = np.cross(np.swapaxes(aj, 1, 2), d[:, None, :])  # a_k × d, on ω_J
        rates = np.concatenate([
            e.gap, np.einsum("eik,eic->ekc", aj, e.gap) + spin,
            _turn_rate(np.cross(zi[:, None, :], np.swapaxes(aj[..., :2], 1, 2))),
            _turn_rate(np.cross(xi_axis, aj[..., 1]))[:, None],
            _turn_rate(np.cross(zi, aj[..., 2]))[:, None],
            np.einsum("ei,eic->ec", u, e.gap)[:, None], np.zeros((len(d), 1, 12)),
        ], 1)
        select = topo.joints.select  # (E, width, candidates)
        rows = topo.joints.rows
        phi[rows] = np.einsum("ewc,ec->ew", select, values)
        np.add.at(jac, (rows[:, :, None], e.coords[:, None, :]),
                  np.einsum("ewc,ecq->ewq", select, rates))
    if mech.drivers.names:
        e = _Elements(mech, mech.drivers.marker, mech.drivers.marker)
        direction = np.asarray(mech.drivers.direction, dtype=float)
        rate = np.concatenate([direction, np.cross(e.xi - e.pi, direction)], -1)
        rows = mech.joints.n_rows + np.arange(len(direction))
        jac[rows[:, None], e.coords[:, :6]] += rate
    return phi[:-1], _to_gibbs(mech, jac[:-1])


def _secant(x, y, t):
    """Slope of the table (x, y) over the knot interval of t (the end ones beyond the table)."""
    i = np.clip(np.searchsorted(x, t, side="right") - 1, 0, x.shape[-1] - 2)
    return (y[i + 1] - y[i]) / (x[i + 1] - x[i])


def _projected_angles(r):
    """Adams projected angles of relative rotations r (E, 3, 3) (`geometry.projected_angles`)."""
    return np.stack([np.arctan2(-r[:, 1, 2], r[:, 2, 2]), np.arctan2(r[:, 0, 2], r[:, 2, 2]),
                     np.arctan2(r[:, 1, 0], r[:, 0, 0])], -1)


def design_stiffness(mech: Mechanism) -> np.ndarray:
    """Material stiffness (n, n) of the force elements at the design position in the solver's
    Gibbs coordinates: Σ Bᵀ·k·B over bushings (six axes), springs and engaged stops (along
    their line), k the law's slope at the design deformation (see the module docstring)."""
    size = mech.topology.n + 6
    k_full = np.zeros((size, size))

    def add(e, rates, slopes):
        k_e = np.einsum("eac,ea,ead->ecd", rates, slopes, rates)
        np.add.at(k_full, (e.coords[:, :, None], e.coords[:, None, :]), k_e)

    b = mech.bushings
    if b.names:
        e = _Elements(mech, b.i_marker, b.j_marker)
        aj = e.aj
        zero = np.zeros((len(aj), 3, 3))
        spin = np.zeros((len(aj), 3, 12))
        spin[..., 9:] = np.cross(np.swapaxes(aj, 1, 2), (e.xi - e.xj)[:, None, :])
        rates = np.concatenate([
            np.einsum("eik,eic->ekc", aj, e.gap) + spin,
            np.concatenate([zero, np.swapaxes(aj, 1, 2), zero, -np.swapaxes(aj, 1, 2)], -1),
        ], 1)
        deformation = np.concatenate([
            np.einsum("eik,ei->ek", aj, e.xi - e.xj),
            _projected_angles(np.einsum("eki,ekj->eij", aj, e.ai)),
        ], -1)
        f = {k: np.asarray(getattr(b, k), dtype=float) for k in (
            "k_trans", "k_rot", "cubic_trans", "cubic_rot", "offset_trans", "offset_rot")}
        error = deformation - np.concatenate([f["offset_trans"], f["offset_rot"]], -1)
        linear = np.concatenate([f["k_trans"], f["k_rot"]], -1)
        cubic = np.concatenate([f["cubic_trans"], f["cubic_rot"]], -1)
        slopes = linear + 3.0 * cubic * error**2
        spline = np.asarray(b.spline_axes, dtype=bool).reshape(-1, 6)
        if spline.any():  # a table gives the force on I: its stiffness is minus its slope
            table = -_secant_rows(np.asarray(b.spline_x, dtype=float),
                                  np.asarray(b.spline_y, dtype=float), error)
            slopes = np.where(spline, table, slopes)
        add(e, rates, slopes)
    for elements, slope in _line_elements(mech):
        e = _Elements(mech, elements.i_marker, elements.j_marker)
        length = np.linalg.norm(e.xi - e.xj, axis=-1)
        u = (e.xi - e.xj) / length[:, None]
        add(e, np.einsum("ei,eic->ec", u, e.gap)[:, None], slope(length)[:, None])
    t = np.tile([1.0, 1.0, 1.0, 2.0, 2.0, 2.0], mech.n_coordinates // 6)
    n = mech.n_coordinates
    return t[:, None] * k_full[:n, :n] * t[None, :]


def _secant_rows(x, y, t):
    """`_secant` per row: tables (..., k), points (...)."""
    flat = [_secant(xr, yr, tr) for xr, yr, tr in zip(x.reshape(-1, x.shape[-1]),
                                                       y.reshape(-1, y.shape[-1]), t.ravel(),
                                                       strict=True)]
    return np.asarray(flat, dtype=float).reshape(t.shape)


def _line_elements(mech: Mechanism):
    """Springs and stops as (elements, slope of the tension at the design length)."""
    s = mech.springs
    if s.names:
        k, free = np.asarray(s.k, dtype=float), np.asarray(s.free_length, dtype=float)
        x, y = np.asarray(s.table_x, dtype=float), np.asarray(s.table_y, dtype=float)
        tabulated = np.asarray(s.tabulated, dtype=bool)

        def spring(length):
            return np.where(tabulated, _secant_rows(x, y, length - free), k)

        yield s, spring
    st = mech.stops
    if st.names:
        stop_length = np.asarray(st.length, dtype=float)
        k, cubic = np.asarray(st.k, dtype=float), np.asarray(st.cubic, dtype=float)
        bump = np.asarray([kind == "bump" for kind in st.kind])

        def stop(length):
            pen = np.where(bump, stop_length - length, length - stop_length)
            return np.where(pen > 0.0, k + 3.0 * cubic * pen**2, 0.0)

        yield st, stop


@dataclasses.dataclass(frozen=True)
class Structure:
    """What the design matrices say: `rank` of Φ_q, `independent` rows (the others are
    `redundant`, by name), `free_modes` (descriptions), `assembly` (each row's violation at
    design, mm; angular rows times the length scale) and the rows' `names`."""

    rank: int
    independent: tuple[int, ...]
    redundant: tuple[str, ...]
    free_modes: tuple[str, ...]
    assembly: np.ndarray
    names: tuple[str, ...]


def row_names(mech: Mechanism) -> list[str]:
    """A name per constraint row: "joint 'name' (kind) row r", then "driver 'name'"."""
    names = []
    for name, kind in zip(mech.joints.names, mech.joints.kind, strict=True):
        names += [f"joint '{name}' ({kind}) row {r}" for r in range(JOINT_ROWS[kind])]
    names += [f"driver '{name}'" for name in mech.drivers.names]
    return names


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


def analyse(mech: Mechanism, phi: np.ndarray, phi_q: np.ndarray, stiffness: np.ndarray,
            tol: float) -> Structure:
    """The structure read from the constraint values Φ, Φ_q (every row) and the tangent
    stiffness at design (see the module docstring); `tol`: a mode is free when its stiffness
    is at most `tol` times the largest diagonal stiffness (scaled)."""
    angular = mech.topology.angular
    n_parts = len(mech.parts)
    col_scale = np.tile(np.r_[np.ones(3), np.full(3, 1.0 / mech.length_scale)], n_parts)
    row_scale = np.where(angular, mech.length_scale, 1.0)
    names = row_names(mech)
    assembly = np.abs(phi) * row_scale
    n = mech.n_coordinates
    scaled = phi_q * row_scale[:, None] * col_scale[None, :]
    independent = _independent_rows(scaled, 1e-7)
    rank = len(independent)
    if rank:
        _, _, vt = np.linalg.svd(scaled[independent], full_matrices=True)
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
    return Structure(
        rank=rank, independent=tuple(independent),
        redundant=tuple(names[r] for r in range(mech.n_rows) if r not in independent),
        free_modes=tuple(free), assembly=assembly, names=tuple(names))


def finalize(mech: Mechanism, *, check: bool = True) -> Mechanism:
    """Drop redundant rows (kept in `independent_rows`) and, with `check`, raise `ModelError`
    for joints not assembled at design and for free modes (the NumPy design matrices of this
    module: building compiles nothing)."""
    all_rows = dataclasses.replace(mech, independent_rows=tuple(range(mech.n_rows)))
    s = analyse(all_rows, *design_rows(all_rows), design_stiffness(all_rows), 1e-9)
    if check:
        bad = np.flatnonzero(s.assembly > 1e-6)
        if bad.size:
            r = int(bad[0])
            raise ModelError(
                f"{s.names[r]} is violated by {s.assembly[r]:.3g} mm at design: the joint's "
                "markers must coincide (and their axes agree) in the design position. Check the "
                "markers' positions and orientations."
            )
        if s.free_modes:
            raise ModelError(
                "the mechanism has modes with neither constraint nor stiffness, so its "
                "equilibrium is undetermined: " + "; ".join(s.free_modes) + ". Add a joint "
                "or stiffness that holds it (e.g. a distance joint for a link between two ball "
                "joints), or build with check=False."
            )
    return dataclasses.replace(mech, independent_rows=s.independent)
