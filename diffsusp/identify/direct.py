"""Direct (linear) identification of bushing and spring stiffnesses from measured equilibria.

spec: stiffness §1.8–1.14 (Chapter 4), §7 R1–R4; DESIGN.md "Identification".

**Equations.** At a measured equilibrium q_c (part poses from landmarks) under known loads,

    Q_ext(q_c) + Q_int(q_c; k) + Φ_q(q_c)ᵀ λ = 0                     (spec §1.9, 4.35–4.36)

The internal generalised forces are linear in the stiffnesses: Q_int = D(q_c)·k + Q_known(q_c)
(bushings: F = −K·δ per axis, so the column of Ktx is the generalised force of a unit
−δx force; springs: tension = K·ℓ − K·L0, linear in the unknowns (K, K·L0), spec §1.7–1.8,
4.37–4.42). Here D = ∂Q_int/∂k is `jax.jacfwd` of the solver's own element force functions
(the ones `statics.kernel.assemble` sums), element by element — exact because Q_int is linear in
k — so the identification uses exactly the force laws the forward model solves; Q_known is the
solver's assembly of everything not identified (loads, other elements). The multipliers λ are
eliminated by projecting onto the admissible motions: L is an orthonormal basis of the null
space of Φ_q (4.43–4.46), giving n − m rows per case

    Lᵀ D k = −Lᵀ (Q_ext + Q_known)                                   (4.47–4.49)

stacked over the cases and solved by `diffsusp.lsq` (4.51–4.54), which also reports which
stiffnesses the data determine, the identifiable combinations, σ and σ%.

**Coordinates and scaling.** The rows are built in the solver's coordinates (each part's
reference point and its Gibbs vector, spec §1.3), with the rotational coordinates scaled by the
model's length scale ℓ so that every generalised force is a force in N (a moment in N·mm divided
by ℓ): otherwise N·mm rows would swamp N rows once the data are noisy (spec §1.10, "not invariant
to the parametrisation of q or to units"). The result is invariant to the choice of the basis L.
Columns are in the units of the thesis's tables (N/mm, N·mm/deg; spring K in N/mm and K·L0 in
N; force offsets in N and moment offsets in N·mm), and `lsq` scales them to unit norm inside.

**What the data determine.** Identifiability is decided on the unweighted equations (a
property of the model and the load cases): unknowns whose columns are rounding noise have "no
effect"; columns dependent up to `threshold` give the identifiable combinations (e.g.
`bushing_1.Krx + bushing_2.Krx`, spec §7 R3). The estimate and its σ then come from the
weighted equations.

**Noisy data.** Pose errors enter the regressors themselves (errors in variables): a direction
that deforms little compared with the landmark noise is biased toward 0 and its share of the
forces is pushed onto the others. The default generalised least squares whitens each case by the
covariance its equations get from iid landmark noise (registration geometry × tangent
stiffness), so that σ and σ% agree with the actual scatter; `hold="model"` keeps the
undetermined unknowns at the model's values (their forces stay in the equations) and
`eliminate=True` holds, one at a time, those whose σ% exceeds `max_sigma_pct` (the guaranteed
least squares' elimination loop, spec guaranteed_least_squares §3.9).

**Bushing convention (Adams vs thesis).** diffsusp's bushings follow the Adams BUSHING
convention: the law acts on the I marker's part, F_I = −K·δ_T, T_I = −K_T·δ_R (δ: I relative to J,
in J), and J receives −F_I and −T_I − δ × F_I. The thesis writes the mirrored law on the J side
(F_{1→2} = K·δ on S2 at O_j, and the δ × F transfer on S1, spec §1.8, 4.31–4.33). Both give the
same force; the moments differ by δ_T × (K·δ_T), a second-order term that vanishes for an
isotropic K_T. The identification rows here come from the Adams-convention forces the solver
uses, so a model identified here reproduces its measurements in diffsusp (and Adams); thesis
numbers computed with the mirrored law can differ in the second order of the deformation.

**Offsets.** Optional unknown offsets δ0 (spec §1.10, "Offsets", and §0: F = f(T − T0)) are
identified as the constant force K·δ0 (+ the model's preload), linear like the spring's K·L0.

**Size.** About 1 200 lines: selection, the system (exact rows from the solver's force laws),
the noise whitening, the identifiability analysis and the write-back are one method sharing
the `Parameter` description and the assembled `_Context`. The report (`DirectReport`) is in
`identify.direct_report`, the errors-in-variables polish and `direct_batch` in
`identify.direct_polish`; the report's common part is in `identify.report`.
"""

import dataclasses
import functools
from collections.abc import Callable, Mapping, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..errors import InputError, ModelError
from ..measure.data import as_equilibria
from ..measure.measurements import Measurements
from ..model.mechanism import Mechanism
from .direct_report import DEG, DirectReport
from .params import Params, selected_entries
from .report import (
    check_consistency,
    check_data,
)

__all__ = ["DirectReport", "DirectSystem", "Parameter", "direct", "direct_batch",
           "direct_system"]

AXES = ("tx", "ty", "tz", "rx", "ry", "rz")
STIFFNESS_NAMES = ("Ktx", "Kty", "Ktz", "Krx", "Kry", "Krz")
OFFSET_NAMES = ("Fx0", "Fy0", "Fz0", "Mx0", "My0", "Mz0")
DEFAULT_THRESHOLD = 1e-5
"""Default identifiability threshold of the direct method (relative, on unit-norm columns: see
`lsq.solve`). Far above rounding, so that stiffnesses told apart only by second-order effects of
large rotations — which no measurement resolves — are reported as combinations (spec §7 R3)."""
MAX_SIGMA_PCT = 10.0
"""Identifiable parameters with a relative standard deviation above this (%) are reported as
not determined by the data (no value in the table). Engineering accuracy rather than the
statistical limit of spec guaranteed_least_squares §3.8 (beyond 100 % the 68 % interval contains
0): with noisy poses the regressors themselves are noisy (errors in variables), which biases
stiff, little-deformed directions toward 0 by more than their σ says; they are the ones with a
large σ%."""

METHODS = ("basic", "min_norm", "tsvd", "tikhonov", "nonneg")


# ----------------------------------------------------------------------------- selection


@dataclasses.dataclass(frozen=True)
class Parameter:
    """One unknown of the linear system (static description).

    `kind`: 'stiffness' (bushing axis, column ∂Q/∂k), 'constant' (bushing axis: K·δ0 + preload),
    'spring_k' (spring K, with the model's L0 if `spring_c` is not also unknown), 'spring_c'
    (K·L0); `element` the bushing/spring index; `axes` the bushing axes it covers (two for an
    axisymmetric pair); `unit` of the table value; `to_internal` factor from the table unit to
    the model's (N·mm/deg → N·mm/rad).
    """

    name: str
    kind: str
    element: int
    axes: tuple[int, ...]
    unit: str
    to_internal: float


_FIELDS = {
    "bushings.k_trans": ("bushing", "k", (0, 1, 2)),
    "bushings.k_rot": ("bushing", "k", (3, 4, 5)),
    "bushings.offset_trans": ("bushing", "offset", (0, 1, 2)),
    "bushings.offset_rot": ("bushing", "offset", (3, 4, 5)),
    "springs.k": ("spring", "k", ()),
    "springs.free_length": ("spring", "free_length", ()),
}


def _default_where(m: Mechanism):
    return (m.bushings.k_trans, m.bushings.k_rot, m.springs.k, m.springs.free_length)


def _selected_fields(mech: Mechanism, where) -> dict[str, np.ndarray]:
    """{field: flat indices of the selected entries} of a `Params` or a `where` function."""
    selected = {}
    for path, idx in selected_entries(mech, where).items():
        key = ".".join(path)
        if key not in _FIELDS:
            raise InputError(
                "where= selected something the direct method cannot identify: it identifies "
                "the parameters the internal forces are linear in, entries of "
                f"{', '.join('m.' + p for p in _FIELDS)}. Choose elements with elements=(...) "
                "or entries with a Params; for other parameters (hardpoints, nonlinear laws) "
                "use a least-squares fit through the equilibrium."
            )
        if idx.size:
            selected[key] = idx
    return selected


def _parameters(mech: Mechanism, fields: Mapping[str, np.ndarray], elements, axisymmetric,
                offsets_alone_ok=True) -> tuple[Parameter, ...]:
    b, s = mech.bushings, mech.springs
    names = set(b.names) | set(s.names)
    if elements is None:
        elements = tuple(b.names) + tuple(s.names)
    elements = tuple(elements)
    unknown = [e for e in elements if e not in names]
    if unknown:
        raise InputError(
            f"elements= names {', '.join(map(repr, unknown))}, which model '{mech.name}' does "
            f"not have; its bushings: {', '.join(b.names) or 'none'}; springs: "
            f"{', '.join(s.names) or 'none'}."
        )
    axisym = tuple(axisymmetric)
    bad = [e for e in axisym if e not in b.names]
    if bad:
        raise InputError(f"axisymmetric= names {', '.join(map(repr, bad))}, which are not "
                         f"bushings of the model ({', '.join(b.names) or 'none'}).")
    # Selected axes per bushing: k (stiffness) and c (offset), (bushings, 6).
    k_sel = np.zeros((len(b.names), 6), bool)
    c_sel = np.zeros((len(b.names), 6), bool)
    spring_sel = {"k": np.zeros(len(s.names), bool), "free_length": np.zeros(len(s.names), bool)}
    for path, idx in fields.items():
        group, kind, axes = _FIELDS[path]
        if group == "bushing":
            (k_sel if kind == "k" else c_sel)[idx // 3, np.asarray(axes)[idx % 3]] = True
        else:
            spring_sel[kind][idx] = True
    spline = np.asarray(b.spline_axes, dtype=bool).reshape(len(b.names), 6)
    cubic = np.concatenate([np.asarray(b.cubic_trans), np.asarray(b.cubic_rot)], axis=1) \
        if b.names else np.zeros((0, 6))
    params = []
    for e, name in enumerate(b.names):
        if name not in elements:
            continue
        sym = name in axisym
        if sym:  # an axisymmetric pair is one unknown: selected if either axis is
            for sel in (k_sel, c_sel):
                for x in (0, 3):
                    sel[e, x:x + 2] = sel[e, x:x + 2].any()
        k_axes, c_axes = set(np.flatnonzero(k_sel[e])), set(np.flatnonzero(c_sel[e]))
        for a in sorted(k_axes | c_axes):
            if spline[e, a]:
                raise ModelError(
                    f"bushing '{name}' uses a spline law on axis {AXES[a]}; the direct method "
                    "identifies linear stiffness. Leave it out (elements=...) or replace the "
                    "spline by its slope."
                )
        for a in sorted(c_axes):
            if cubic[e, a] != 0:
                raise ModelError(
                    f"bushing '{name}' has a cubic term on axis {AXES[a]}, which makes its "
                    "offset enter nonlinearly; identify its offsets with a linear law only."
                )
        for a in sorted(k_axes):
            if sym and a in (1, 4):
                continue
            rot = a >= 3
            if sym and a in (0, 3):
                label, axes = ("Krr" if rot else "Ktr"), (a, a + 1)
            else:
                label, axes = STIFFNESS_NAMES[a], (a,)
            params.append(Parameter(f"{name}.{label}", "stiffness", e, axes,
                                    "N·mm/deg" if rot else "N/mm", 1.0 / DEG if rot else 1.0))
        for a in sorted(c_axes):
            params.append(Parameter(f"{name}.{OFFSET_NAMES[a]}", "constant", e, (a,),
                                    "N·mm" if a >= 3 else "N", 1.0))
    for e, name in enumerate(s.names):
        spring_k, spring_c = spring_sel["k"][e], spring_sel["free_length"][e]
        if name not in elements or not (spring_k or spring_c):
            continue
        if s.tabulated[e]:
            raise ModelError(f"spring '{name}' has a tabulated law; the direct method "
                             "identifies linear springs (K, L0). Leave it out (elements=...).")
        if spring_k:
            params.append(Parameter(f"{name}.K", "spring_k", e, (), "N/mm", 1.0))
        if spring_c:
            params.append(Parameter(f"{name}.KL0", "spring_c", e, (), "N", 1.0))
    if not params:
        raise InputError("nothing to identify: the selection (where=, elements=) picks no "
                         "stiffness of this model.")
    return tuple(params)


def _evaluation_model(mech: Mechanism, params: tuple[Parameter, ...]) -> Mechanism:
    """`mech` with the unknowns removed from its laws: what remains of Q_int is known."""
    b, s = mech.bushings, mech.springs
    k = np.concatenate([np.asarray(b.k_trans), np.asarray(b.k_rot)], axis=1) \
        if b.names else np.zeros((0, 6))
    offset = np.concatenate([np.asarray(b.offset_trans), np.asarray(b.offset_rot)], axis=1) \
        if b.names else np.zeros((0, 6))
    preload = np.concatenate([np.asarray(b.preload_force), np.asarray(b.preload_torque)],
                             axis=1) if b.names else np.zeros((0, 6))
    spring_k = np.asarray(s.k).copy()
    free_length = np.asarray(s.free_length).copy()
    for p in params:
        if p.kind == "stiffness":
            k[p.element, list(p.axes)] = 0.0
        elif p.kind == "constant":
            offset[p.element, list(p.axes)] = 0.0
            preload[p.element, list(p.axes)] = 0.0
        elif p.kind == "spring_k":
            spring_k[p.element] = 0.0
        else:
            free_length[p.element] = 0.0
    return eqx.tree_at(
        lambda m: (m.bushings.k_trans, m.bushings.k_rot, m.bushings.offset_trans,
                   m.bushings.offset_rot, m.bushings.preload_force, m.bushings.preload_torque,
                   m.springs.k, m.springs.free_length),
        mech,
        tuple(jnp.asarray(a) for a in (k[:, :3], k[:, 3:], offset[:, :3], offset[:, 3:],
                                       preload[:, :3], preload[:, 3:], spring_k, free_length)),
    )


# ----------------------------------------------------------------------------- assembly


def _selection(mech: Mechanism, params: tuple[Parameter, ...]) -> np.ndarray:
    """Matrix M (table, p) mapping the unknowns (table units) onto the table of unit columns:
    per bushing 6 stiffness axes (model units) then 6 constants, then per spring K and K·L0.
    Axisymmetric unknowns feed two axes; N·mm/deg unknowns carry their 180/π. The selection is
    data (not compiled structure), so every choice of unknowns of one model shares one compiled
    assembly per number of unknowns."""
    n_b = len(mech.bushings.names)
    table = 12 * n_b + 2 * len(mech.springs.names)
    m = np.zeros((table, len(params)))
    for i, p in enumerate(params):
        if p.kind == "stiffness":
            for a in p.axes:
                m[12 * p.element + a, i] = p.to_internal
        elif p.kind == "constant":
            m[12 * p.element + 6 + p.axes[0], i] = 1.0
        elif p.kind == "spring_k":
            m[12 * n_b + 2 * p.element, i] = 1.0
        else:
            m[12 * n_b + 2 * p.element + 1, i] = 1.0
    return m


def _scaling(mech: Mechanism) -> np.ndarray:
    """Per coordinate: 1 for translations, 1/ℓ for the Gibbs coordinates (turns N·mm into N)."""
    n_parts = len(mech.parts)
    return np.tile(np.r_[np.ones(3), np.full(3, 1.0 / mech.length_scale)], n_parts)


def _mechanism_at(eval_mech: Mechanism, selection, x):
    """The evaluation model with the unknowns x (table units) put back into their fields: the
    stiffnesses and constants added, each unknown K·L0 = c turned into the free length c/K
    (the evaluation model has L0 = 0 there)."""
    b, s = eval_mech.bushings, eval_mech.springs
    n_b = len(b.names)
    t = selection @ x
    kb = t[: 12 * n_b].reshape(n_b, 12)
    ks, cs = t[12 * n_b :: 2], t[12 * n_b + 1 :: 2]
    k_spring = s.k + ks
    free_length = s.free_length + cs / jnp.where(k_spring == 0, 1.0, k_spring)
    return eqx.tree_at(
        lambda mm: (mm.bushings.k_trans, mm.bushings.k_rot, mm.bushings.preload_force,
                    mm.bushings.preload_torque, mm.springs.k, mm.springs.free_length),
        eval_mech,
        (b.k_trans + kb[:, :3], b.k_rot + kb[:, 3:6], b.preload_force + kb[:, 6:9],
         b.preload_torque + kb[:, 9:], k_spring, free_length),
    )


def _element_geometry(mech: Mechanism, y):
    """Solver coordinates of every element's two parts, z (E, 12), with the ground as a virtual
    part at zero, and the markers' offsets from their parts' reference points."""
    lay = mech.topology
    yfull = jnp.concatenate([y, jnp.zeros(6, y.dtype)])
    offset = mech.markers.position - jnp.asarray(lay.centre[lay.marker_part])
    return lay, yfull, offset


def _scatter_vectors(n_full, idx, values):
    """Σ over elements of (E, 12, k) values into (n_full, k) at coordinate indices (E, 12)."""
    out = jnp.zeros((n_full,) + values.shape[2:], values.dtype)
    return out.at[np.asarray(idx)].add(values)


def _bushing_unit_forces(mech: Mechanism, y):
    """D of the bushings: ∂Q/∂θ (n, nb, 12) for θ = (Ktx, Kty, Ktz, Krx, Kry, Krz) in N/mm and
    N·mm/rad, then the six constant forces on I (preload, or K·δ0 of an offset), by `jax.jacfwd`
    of the solver's own element force function (`statics.kernel.bushing_force`, Adams
    convention, spec stiffness §1.8), one bushing at a time. Exact: the force is linear in θ."""
    from ..statics.kernel import bushing_force

    b = mech.bushings
    lay, yfull, offset = _element_geometry(mech, y)
    i, j = np.asarray(b.i_marker, dtype=int), np.asarray(b.j_marker, dtype=int)
    idx = lay.coords(i, j)
    mk = mech.markers
    zero3 = jnp.zeros(3, y.dtype)

    def one(z, x0i, r0i, x0j, r0j, off_t, off_r):
        def force(theta):
            params = dict(k_trans=theta[:3], k_rot=theta[3:6], cubic_trans=zero3,
                          cubic_rot=zero3, offset_trans=off_t, offset_rot=off_r,
                          preload_force=theta[6:9], preload_torque=theta[9:])
            return bushing_force(z, x0i, r0i, x0j, r0j, params, None)

        return jax.jacfwd(force)(jnp.zeros(12, y.dtype))  # (12 coordinates, 12 unknowns)

    gen = jax.vmap(one)(yfull[idx], offset[i], mk.orientation[i], offset[j], mk.orientation[j],
                        b.offset_trans, b.offset_rot)  # (nb, 12, 12)
    full = jnp.zeros((yfull.shape[0], len(b.names), 12), y.dtype)
    full = full.at[np.asarray(idx), np.arange(len(b.names))[:, None], :].add(gen)
    return full[: y.shape[0]]


def _spring_unit_forces(mech: Mechanism, y):
    """D of the springs: ∂Q/∂(K, K·L0) (n, ns, 2) of tension K·(ℓ − L0) − K·L0 with L0 the
    model's free length (0 where K·L0 is an unknown), by `jax.jacfwd` of the solver's line-force
    function (spec stiffness §1.7, 4.37–4.38). Exact: linear."""
    from ..statics.kernel import line_force

    s = mech.springs
    lay, yfull, offset = _element_geometry(mech, y)
    i, j = np.asarray(s.i_marker, dtype=int), np.asarray(s.j_marker, dtype=int)
    idx = lay.coords(i, j)

    def one(z, x0i, x0j, free_length):
        def force(kc):
            return line_force(z, x0i, x0j,
                               lambda length: kc[0] * (length - free_length) - kc[1])

        return jax.jacfwd(force)(jnp.zeros(2, y.dtype))  # (12, 2)

    gen = jax.vmap(one)(yfull[idx], offset[i], offset[j], s.free_length)  # (ns, 12, 2)
    full = jnp.zeros((yfull.shape[0], len(s.names), 2), y.dtype)
    full = full.at[np.asarray(idx), np.arange(len(s.names))[:, None], :].add(gen)
    return full[: y.shape[0]]


def _constraint_jacobian(mech: Mechanism, loads, y):
    """Φ_q (m, n) of the independent constraint rows at y (solver coordinates), from the
    solver's own constraint rows (Adams definitions, spec stiffness §1.6)."""
    from ..statics.kernel import constraint_jacobian

    return constraint_jacobian(mech, loads, y)


def _null_basis(eval_mech: Mechanism, loads, y, scale):
    """Orthonormal basis L (n, n − m) of the null space of the scaled Φ_q at y (spec §1.9,
    4.43–4.44), and the constraint Jacobian Φ_q (m, n) (unscaled)."""
    lay = eval_mech.topology
    n, m = lay.n, lay.m
    if not m:
        return jnp.eye(n, dtype=y.dtype), jnp.zeros((0, n), y.dtype)
    phi_q = _constraint_jacobian(eval_mech, loads, y)
    row_scale = jnp.asarray(np.where(lay.angular_live, eval_mech.length_scale, 1.0), y.dtype)
    basis, _ = jnp.linalg.qr((phi_q * row_scale[:, None] * scale[None, :]).T, mode="complete")
    return basis[:, m:], phi_q


def _case_rows(eval_mech: Mechanism, selection, q, loads):
    """Rows Lᵀ·D (r, p) and right-hand side −Lᵀ·(Q_ext + Q_known) (r,) of one case (N), and
    the null-space basis L (n, r).

    D = ∂Q_int/∂k element by element (`jax.jacfwd` of the element force functions), gathered
    onto the unknowns by `selection`; Q_known is the solver's own assembly (`assemble`) of
    everything else: the loads, the elements and axes not identified, cubic terms."""
    from ..statics.kernel import assemble, to_internal

    lay = eval_mech.topology
    n, m = lay.n, lay.m
    y = to_internal(eval_mech, q)
    known, _ = assemble(eval_mech, loads, y, jnp.zeros(m, y.dtype), with_jacobian=False)
    known = known[:n]
    parts = []
    if eval_mech.bushings.names:
        parts.append(_bushing_unit_forces(eval_mech, y).reshape(n, -1))
    if eval_mech.springs.names:
        parts.append(_spring_unit_forces(eval_mech, y).reshape(n, -1))
    columns = jnp.concatenate(parts, axis=1) @ selection
    scale = jnp.asarray(_scaling(eval_mech), y.dtype)
    null, _ = _null_basis(eval_mech, loads, y, scale)
    return null.T @ (columns * scale[:, None]), -null.T @ (known * scale), null


def _elastic_stiffness(mech: Mechanism, y):
    """Tangent stiffness −∂Q/∂y (n, n) of the bushings and linear springs of `mech` at y."""
    from ..statics.kernel import bushing_force, bushing_params, line_force

    lay, yfull, offset = _element_geometry(mech, y)
    mk = mech.markers
    full = jnp.zeros((yfull.shape[0], yfull.shape[0]), y.dtype)
    b = mech.bushings
    if b.names:
        i, j = np.asarray(b.i_marker, dtype=int), np.asarray(b.j_marker, dtype=int)
        idx = lay.coords(i, j)
        params = {k: v for k, v in bushing_params(mech).items() if not k.startswith("spline")}
        jac = jax.vmap(jax.jacfwd(functools.partial(bushing_force, spline_mask=None)))(
            yfull[idx], offset[i], mk.orientation[i], offset[j], mk.orientation[j], params)
        full = full.at[idx[:, :, None], idx[:, None, :]].add(jac)
    s = mech.springs
    if s.names:
        i, j = np.asarray(s.i_marker, dtype=int), np.asarray(s.j_marker, dtype=int)
        idx = lay.coords(i, j)

        def spring(z, x0i, x0j, k, free_length):
            return line_force(z, x0i, x0j, lambda length: k * (length - free_length))

        jac = jax.vmap(jax.jacfwd(spring))(yfull[idx], offset[i], offset[j], s.k, s.free_length)
        full = full.at[idx[:, :, None], idx[:, None, :]].add(jac)
    return full[: y.shape[0], : y.shape[0]]


def _case_whitener(eval_mech: Mechanism, selection, q, null, x, pose_cov):
    """Whitening matrix C⁻¹ (r, r) of one case: Σ_r = C Cᵀ is the covariance of the case's
    equation residual caused by pose errors of covariance `pose_cov` (n, n, solver
    coordinates), to first order, at the solution x.

    A pose error dy moves the residual Lᵀ(Q + Φ_qᵀλ) by Lᵀ·K·dy with K the tangent stiffness.
    Only the elastic part of K (bushings, springs at x) is kept: the geometric terms of the loads
    and of the joint reactions are smaller by the ratio of a part's rotation error (≈ noise /
    landmark spread) to the bushings' deformations, and the change of L itself multiplies the
    small residual.
    """
    from ..statics.kernel import to_internal

    y = to_internal(eval_mech, q)
    mech_x = _mechanism_at(eval_mech, selection, x)
    scale = jnp.asarray(_scaling(eval_mech), y.dtype)
    sens = null.T @ (scale[:, None] * _elastic_stiffness(mech_x, y))  # (r, n)
    cov = sens @ pose_cov @ sens.T
    r = cov.shape[0]
    cov = cov + (1e-12 * jnp.trace(cov) / r + 1e-300) * jnp.eye(r, dtype=cov.dtype)
    chol = jnp.linalg.cholesky(cov)
    return jax.scipy.linalg.solve_triangular(chol, jnp.eye(r, dtype=cov.dtype), lower=True)


_QR_CHUNK = 1024


@jax.jit
def _r_factor(W, y):
    """R-factor (positive diagonal) of [W, −y], by a tall-skinny QR: chunks of rows reduced
    separately, then their R's (one tall QR is several times slower for 10⁵ rows)."""
    from ..lsq import qr_r

    m = jnp.concatenate([W, -y[:, None]], axis=1)
    n, q = m.shape
    if n > 2 * _QR_CHUNK:
        k = -(-n // _QR_CHUNK)
        m = jnp.concatenate([m, jnp.zeros((k * _QR_CHUNK - n, q), m.dtype)])
        m = jax.vmap(lambda x: jnp.linalg.qr(x, mode="r"))(m.reshape(k, _QR_CHUNK, q))
        m = m.reshape(-1, q)
    return qr_r(m)


@eqx.filter_jit
def _system_arrays(eval_mech: Mechanism, selection, q, loads):
    return jax.vmap(lambda q_, l_: _case_rows(eval_mech, selection, q_, l_))(q, loads)


@eqx.filter_jit
def _whiteners(eval_mech: Mechanism, selection, q, null, x, pose_cov):
    return jax.vmap(lambda q_, n_, c_: _case_whitener(eval_mech, selection, q_, n_, x, c_))(
        q, null, pose_cov)


# ----------------------------------------------------------------------------- the system


@dataclasses.dataclass(frozen=True)
class DirectSystem:
    """The stacked linear system of the direct method, W x ≈ y (spec §1.10, 4.51–4.53).

    **Fields:** `W` (cases·r, p) and `y` (cases·r,) in N (generalised forces, rotational ones
    divided by the length scale); `r` rows per case (= n − rank Φ_q, the kinematic degrees of
    freedom); `parameters` (the unknowns, in column order, with their table units); `cases`
    (labels); `prior` (p,) the model's values in table units; `notes` (from the measurements);
    `weighted`: rows whitened by the pose-noise covariance (then W and y are dimensionless);
    `R` the (p+1)×(p+1) R-factor of [W, −y] (what `lsq` works from).
    """

    W: np.ndarray
    y: np.ndarray
    rows_per_case: int
    parameters: tuple[Parameter, ...]
    cases: tuple[str, ...]
    prior: np.ndarray
    notes: tuple[str, ...]
    weighted: bool = False
    R: np.ndarray | None = None

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    @property
    def blocks(self) -> np.ndarray:
        """The case index of every row."""
        return np.repeat(np.arange(len(self.cases)), self.rows_per_case)


def _prior(mech: Mechanism, params: tuple[Parameter, ...]) -> np.ndarray:
    b, s = mech.bushings, mech.springs
    k = np.concatenate([np.asarray(b.k_trans), np.asarray(b.k_rot)], axis=1) \
        if b.names else np.zeros((0, 6))
    off = np.concatenate([np.asarray(b.offset_trans), np.asarray(b.offset_rot)], axis=1) \
        if b.names else np.zeros((0, 6))
    pre = np.concatenate([np.asarray(b.preload_force), np.asarray(b.preload_torque)], axis=1) \
        if b.names else np.zeros((0, 6))
    out = []
    for p in params:
        if p.kind == "stiffness":
            out.append(np.mean(k[p.element, list(p.axes)]) / p.to_internal)
        elif p.kind == "constant":
            a = p.axes[0]
            out.append(k[p.element, a] * off[p.element, a] + pre[p.element, a])
        elif p.kind == "spring_k":
            out.append(float(s.k[p.element]))
        else:
            out.append(float(s.k[p.element] * s.free_length[p.element]))
    return np.asarray(out, dtype=float)


def _check_measurements(mech: Mechanism, meas: Measurements):
    if not isinstance(meas, Measurements):
        raise InputError(f"measurements must be a diffsusp.measure.Measurements; got "
                         f"{type(meas).__name__}.")
    if meas.rotation.ndim != 4:
        raise InputError("measurements must have one leading case axis (a batch of measurement "
                         "sets: identify each with its own call).")
    loads = meas.loads
    n_cases = meas.n_cases
    if loads.force.shape[:1] != (n_cases,):
        raise InputError(f"the measurements have {n_cases} cases but their loads have "
                         f"{loads.force.shape[0] if loads.force.ndim == 3 else 'no'} cases.")
    n_l, n_d = len(mech.load_points.names), len(mech.drivers.names)
    if loads.force.shape[1:] != (n_l, 3) or loads.driver.shape[1:] != (n_d,):
        raise InputError(
            f"the loads are for {loads.force.shape[1]} load points and {loads.driver.shape[1]} "
            f"drivers, but model '{mech.name}' has {n_l} load points "
            f"({', '.join(mech.load_points.names) or 'none'}) and {n_d} drivers; build them with "
            "mech.loads(...)."
        )
    _check_every_part_measured(mech, meas)
    q = np.asarray(meas.coordinates(mech))
    if not np.all(np.isfinite(q)):
        c = int(np.argwhere(~np.isfinite(q))[0][0])
        raise InputError(f"the pose of case {meas.cases[c] if meas.cases else c + 1} is not "
                         "finite (NaN or inf).")
    for field in ("force", "moment"):
        value = np.asarray(getattr(loads, field))
        if not np.all(np.isfinite(value)):
            c = int(np.argwhere(~np.isfinite(value))[0][0])
            raise InputError(f"the {field} of case {c + 1} is not finite (NaN or inf).")
    return q


def _check_every_part_measured(mech: Mechanism, meas: Measurements):
    """Raise, saying why and what to do instead, when a moving part has no measured pose.

    The equations are formed at the measured pose of every part (spec stiffness §1.1, §1.14):
    the generalised forces D(q)·k need q whole. For an unmeasured part, the joints to the
    measured parts fix some of its coordinates; the others (e.g. the pseudo-McPherson strut's
    slide in the hub carrier) are set at each equilibrium by the balance of its elastic
    elements, i.e. by the stiffnesses being identified: unknown × unknown, not a linear
    system. The message counts them: 6 per part less the rows of the joints that hold it
    (exact for independent rows, as in the thesis's models)."""
    missing = [p for p in mech.parts if p not in meas.parts]
    if not missing:
        return
    from ..model.mechanism import JOINT_ROWS

    lay = mech.topology
    part_of = [mech.parts[int(k)] if int(k) < len(mech.parts) else "ground"
               for k in np.asarray(lay.marker_part)]
    joints = [(n, kind) for n, kind, i, j in zip(mech.joints.names, mech.joints.kind,
                                                 mech.joints.i_marker, mech.joints.j_marker,
                                                 strict=True)
              if part_of[i] in missing or part_of[j] in missing]
    joints, free = [n for n, _ in joints], max(
        6 * len(missing) - sum(JOINT_ROWS[k] for _, k in joints), 0)
    names = ", ".join(map(repr, missing))
    why = (f"its joints ({', '.join(joints) or 'none'}) leave it {free} free coordinate(s) "
           "relative to the measured parts, set at every equilibrium by its elastic elements, "
           "i.e. by the stiffnesses being identified: the equations would not be linear in "
           "them" if free else
           f"its joints ({', '.join(joints)}) fix its pose from the measured parts, but the "
           "direct method does not complete poses from the joints")
    raise InputError(
        f"the measurements have no pose for part(s) {names} of model '{mech.name}' "
        f"(measured: {', '.join(meas.parts) or 'none'}). The direct method writes the "
        "equilibrium at the measured pose of every moving part (spec stiffness §1.1, §1.14); "
        f"{why}. Instead: identify.least_squares(mech, measurements, params) fits the "
        "landmarks of the measured parts through the model's own equilibrium (which places "
        f"{names}), or identify.iterative; or measure its landmarks; or simplify the model "
        "(the thesis replaced the unmeasurable strut by a point-on-line joint: spec stiffness "
        "§1.13).")


def _pose_covariance(mech: Mechanism, meas: Measurements) -> Array:
    """Covariance (cases, n, n) of the measured poses in the solver's coordinates (reference
    point, Gibbs vector), for landmark noise of unit σ (mm) per coordinate: the first-order
    covariance of a least-squares rigid registration (centroid translation σ²/k, rotation
    σ²·(Σ_a |r_a|²I − r_a r_aᵀ)⁻¹ about the landmark centroid, uncorrelated). For poses given
    without landmarks: unit σ on the reference point (mm) and on ℓ·rotation (mm).
    Only the structure matters: `lsq` estimates the noise level from the residual."""
    from ..geometry import gibbs_angular_jacobian, skew
    lay = mech.topology
    index = np.asarray([meas.parts.index(p) for p in mech.parts], dtype=int)
    centre = jnp.asarray(lay.centre[:-1])
    rot = meas.rotation[:, index]
    eye = jnp.eye(3, dtype=rot.dtype)

    if meas.landmarks is not None:
        ref = meas.layout.position[index]  # (P, k, 3)
        w = meas.weights[:, index]  # (C, P, k)

        def part_cov(r, ref_p, w_p, c):
            total = jnp.sum(w_p)
            c0 = (w_p @ ref_p) / total
            arm_l = (ref_p - c0) @ r.T  # landmarks about their centroid, current axes
            inertia = jnp.einsum("k,kij->ij", w_p,
                                 jnp.einsum("ki,ki->k", arm_l, arm_l)[:, None, None] * eye
                                 - arm_l[:, :, None] * arm_l[:, None, :])
            cov_t, cov_w = eye / total, jnp.linalg.inv(inertia)
            arm = r @ (c - c0)
            return cov_t, cov_w, arm

        cov_t, cov_w, arm = jax.vmap(jax.vmap(part_cov, in_axes=(0, 0, 0, 0)),
                                     in_axes=(0, None, 0, None))(rot, ref, w, centre)
    else:
        n_c, n_p = rot.shape[:2]
        cov_t = jnp.broadcast_to(eye, (n_c, n_p, 3, 3))
        cov_w = cov_t / mech.length_scale**2
        arm = jnp.zeros((n_c, n_p, 3), rot.dtype)

    def block(r, ct, cw, a):
        # Gibbs vector b = vee(R − Rᵀ)/(1 + tr R) (the poses were checked by `coordinates`).
        b = jnp.stack([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / (
            1.0 + jnp.trace(r))
        g_inv = jnp.linalg.inv(gibbs_angular_jacobian(b))
        top = jnp.concatenate([eye, -skew(a)], axis=1)
        bottom = jnp.concatenate([jnp.zeros((3, 3), r.dtype), g_inv], axis=1)
        t = jnp.concatenate([top, bottom], axis=0)
        cov = jnp.zeros((6, 6), r.dtype).at[:3, :3].set(ct).at[3:, 3:].set(cw)
        return t @ cov @ t.T

    blocks = jax.vmap(jax.vmap(block))(rot, cov_t, cov_w, arm)  # (C, P, 6, 6)
    n_c, n_p = blocks.shape[:2]
    full = jnp.zeros((n_c, n_p, 6, n_p, 6), blocks.dtype)
    full = full.at[:, np.arange(n_p), :, np.arange(n_p), :].set(jnp.moveaxis(blocks, 1, 0))
    return full.reshape(n_c, 6 * n_p, 6 * n_p)


_pose_covariance_jit = eqx.filter_jit(_pose_covariance)


@dataclasses.dataclass(frozen=True)
class _Context:
    mech: Mechanism
    meas: Measurements
    q: np.ndarray
    params: tuple[Parameter, ...]
    eval_mech: Mechanism
    selection: np.ndarray
    rows: np.ndarray  # (cases, r, p)
    rhs: np.ndarray  # (cases, r)
    null: object  # (cases, n, r) null-space bases (device array)

    def system(self, whitener=None) -> "DirectSystem":
        rows, rhs = self.rows, self.rhs
        if whitener is not None:
            rows = np.einsum("cij,cjp->cip", whitener, rows)
            rhs = np.einsum("cij,cj->ci", whitener, rhs)
        n_cases, r, p = rows.shape
        cases = self.meas.cases or tuple(str(c + 1) for c in range(n_cases))
        W, y = rows.reshape(n_cases * r, p), rhs.reshape(-1)
        if not (np.all(np.isfinite(W)) and np.all(np.isfinite(y))):
            raise InputError("the identification equations are not finite: check that the "
                             "measured poses are sensible (no part rotated by 180°).")
        return DirectSystem(W=W, y=y, rows_per_case=r, parameters=self.params, cases=cases,
                            prior=_prior(self.mech, self.params), notes=tuple(self.meas.notes),
                            weighted=whitener is not None,
                            R=np.asarray(_r_factor(jnp.asarray(W), jnp.asarray(y))))

    def whitener(self, x) -> np.ndarray:
        cov = _pose_covariance_jit(self.mech, self.meas)
        return np.asarray(_whiteners(self.eval_mech, jnp.asarray(self.selection),
                                     jnp.asarray(self.q), self.null, jnp.asarray(x, float),
                                     cov))


def _selection_of(params, where):
    """The one selector of `params=` (positional, as in every identification method) and
    `where=` (this method's historical keyword)."""
    if params is not None and where is not None:
        raise InputError("give the selection once: params= or where=, not both.")
    return where if params is None else params


def _prepare(mech, measurements, where, elements, axisymmetric) -> _Context:
    measurements = as_equilibria(measurements)
    q = _check_measurements(mech, measurements)
    fields = _selected_fields(mech, where or _default_where)
    params = _parameters(mech, fields, elements, axisymmetric)
    eval_mech = _evaluation_model(mech, params)
    selection = _selection(mech, params)
    rows, rhs, null = _system_arrays(eval_mech, jnp.asarray(selection), jnp.asarray(q),
                                     measurements.loads)
    return _Context(mech, measurements, q, params, eval_mech, selection, np.asarray(rows),
                    np.asarray(rhs), null)


def direct_system(
    mech: Mechanism,
    measurements: Measurements,
    params: Params | Callable[[Mechanism], object] | None = None,
    *,
    where: Callable[[Mechanism], object] | Params | None = None,
    elements: Sequence[str] | None = None,
    axisymmetric: Sequence[str] = (),
    weights_at: Float[np.ndarray, " p"] | None = None,
) -> DirectSystem:
    """Assemble the direct method's linear system (see `direct` for the arguments).

    One compiled, case-batched evaluation: per case the generalised forces and their exact
    derivative with respect to the unknowns (`jax.jacfwd` of the solver's assembly), Φ_q, and
    the orthonormal null-space basis L (complete QR of Φ_qᵀ). With `weights_at` (values of the
    unknowns, table units), each case's rows are whitened by the covariance that pose errors
    cause at those values (see `direct`, `weighting="noise"`).
    """
    ctx = _prepare(mech, measurements, _selection_of(params, where), elements, axisymmetric)
    return ctx.system(None if weights_at is None else ctx.whitener(weights_at))


# ----------------------------------------------------------------------------- identify


def _prior_sigma(prior: np.ndarray, params, prior_sigma) -> np.ndarray:
    names = [p.name for p in params]
    rel = 0.5 if not isinstance(prior_sigma, int | float) else float(prior_sigma)
    out = np.abs(prior) * rel
    for unit in {p.unit for p in params}:
        same = np.array([p.unit == unit for p in params])
        floor = rel * np.max(np.abs(prior[same]), initial=0.0)
        out[same & (out == 0)] = floor if floor > 0 else 1.0
    if isinstance(prior_sigma, Mapping):
        for name, value in prior_sigma.items():
            if name not in names:
                raise InputError(f"prior_sigma names unknown parameter {name!r}; unknowns: "
                                 f"{', '.join(names)}.")
            out[names.index(name)] = float(value)
    return out


RELATION_TOL = 1e-3
"""Terms of an identifiable combination whose coefficient is below this, on unit-norm columns,
are dropped from the printed relation: columns dependent only up to the identifiability
threshold regroup with tiny spurious coefficients on unrelated unknowns."""


@dataclasses.dataclass(frozen=True)
class _Structure:
    """What the (unweighted) equations determine: the kept (base) unknowns, the unknowns
    determined alone, and the combinations of several unknowns (kept index, coefficients)."""

    kept: np.ndarray
    alone: np.ndarray
    relation_of: list
    relations: tuple  # (kept index j, coefficient row g)


def _structure(fit, negligible: np.ndarray) -> _Structure:
    """Identifiability from an `lsq.Fit` of the unweighted equations, with the relations
    cleaned of spurious terms (`RELATION_TOL`) and the no-effect unknowns left out."""
    p = len(fit.names)
    kept = np.asarray(fit.kept, bool) & ~negligible
    scale = np.asarray(fit.scale, float)
    gamma = np.asarray(fit.regrouping, float)
    gamma_unit = gamma * scale[None, :] / np.where(scale > 0, scale, 1.0)[:, None]
    clean = np.where((np.abs(gamma_unit) > RELATION_TOL) & ~negligible[None, :], gamma, 0.0)
    relation_of = [None] * p
    relations = []
    for j in np.flatnonzero(kept):
        others = [k for k in np.flatnonzero(clean[j]) if k != j]
        if not others:
            continue
        for k in [j, *others]:
            relation_of[k] = int(j)
        relations.append((int(j), clean[j]))
    alone = kept & np.array([relation_of[i] is None for i in range(p)], dtype=bool)
    return _Structure(kept, alone, relation_of, tuple(relations))


@dataclasses.dataclass(frozen=True)
class _Analysis:
    identifiable: np.ndarray  # (p,) determined alone (and not eliminated)
    sigma: np.ndarray  # (p,)
    sigma_pct: np.ndarray  # (p,)
    relations: tuple  # (text, value, sigma)
    status: tuple


def _analyse(structure: _Structure, fit, negligible, eliminated, max_sigma_pct,
             hold) -> _Analysis:
    """Statistics of the estimate `fit` (weighted or not) on the `structure` of the equations."""
    from ..lsq import format_combination

    p = len(fit.names)
    x = np.asarray(fit.x, float)
    cov = np.asarray(fit.covariance, float)
    at_bound = np.asarray(fit.at_bound, bool)
    identifiable = structure.alone & ~eliminated & ~at_bound
    sigma = np.where(identifiable, np.sqrt(np.maximum(np.diag(cov), 0.0)), np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        pct = np.where(identifiable, 100.0 * sigma / np.abs(x), np.nan)
    texts = {}
    relations = []
    for j, g in structure.relations:
        text = format_combination(g, fit.names, j)
        texts[j] = text
        relations.append((text, float(g @ x), float(np.sqrt(max(g @ cov @ g, 0.0)))))
    status = []
    for i in range(p):
        if negligible[i]:
            status.append("not identifiable: no effect on the equations")
        elif eliminated[i]:
            status.append("not determined: held at "
                          + ("the model's value" if hold == "model" else "0"))
        elif at_bound[i]:
            status.append("at its bound (0)")
        elif structure.relation_of[i] is not None:
            status.append(f"not identifiable alone: in {texts[structure.relation_of[i]]}")
        elif not identifiable[i]:
            status.append("not identifiable")
        elif np.nan_to_num(pct[i]) > max_sigma_pct:
            status.append(f"not determined: sigma {pct[i]:.3g}% > {max_sigma_pct:g}%")
        else:
            status.append("identified")
    return _Analysis(identifiable, sigma, pct, tuple(relations), tuple(status))


def _derived(params, values, cov, mech, identified_mask):
    """Spring free lengths and bushing offsets from (K, K·L0) and (K, K·δ0 + P), with σ by
    first-order propagation of the covariance."""
    out = {}
    index = {p.name: i for i, p in enumerate(params)}
    b, s = mech.bushings, mech.springs
    for i, p in enumerate(params):
        if p.kind == "spring_c":
            name = s.names[p.element]
            j = index.get(f"{name}.K")
            c = values[i]
            if j is None:
                k, var = float(s.k[p.element]), cov[i, i] / float(s.k[p.element]) ** 2
                value = c / k
            else:
                k = values[j]
                value = c / k if k else np.nan
                grad = np.zeros(len(values))
                grad[i], grad[j] = 1.0 / k, -c / k**2
                var = grad @ cov @ grad if k else np.nan
            ok = identified_mask[i] and (j is None or identified_mask[j])
            out[f"{name}.L0"] = (value if ok else np.nan, float(np.sqrt(max(var, 0.0)))
                                 if ok else np.nan, "mm")
        elif p.kind == "constant":
            name = b.names[p.element]
            a = p.axes[0]
            k_name = f"{name}.{STIFFNESS_NAMES[a]}"
            j = index.get(k_name)
            pre = np.concatenate([np.asarray(b.preload_force), np.asarray(b.preload_torque)],
                                 axis=1)[p.element, a]
            unit_k = 1.0 / DEG if a >= 3 else 1.0  # table K → model K
            k_model = np.concatenate([np.asarray(b.k_trans), np.asarray(b.k_rot)],
                                     axis=1)[p.element, a] / unit_k
            k = values[j] if j is not None else k_model
            c = values[i] - pre
            value = c / k if k else np.nan
            grad = np.zeros(len(values))
            grad[i] = 1.0 / k if k else np.nan
            if j is not None:
                grad[j] = -c / k**2 if k else np.nan
            var = grad @ cov @ grad
            ok = identified_mask[i] and (j is None or identified_mask[j])
            unit = "deg" if a >= 3 else "mm"
            out[f"{name}.d{AXES[a][1]}0" if a < 3 else f"{name}.a{AXES[a][1]}0"] = (
                value if ok else np.nan, float(np.sqrt(max(var, 0.0))) if ok else np.nan, unit)
    return out


def _apply(mech: Mechanism, params, values, write) -> Mechanism:
    """The mechanism with the written unknowns replaced (table units → model units)."""
    b, s = mech.bushings, mech.springs
    k = np.concatenate([np.asarray(b.k_trans), np.asarray(b.k_rot)], axis=1) \
        if b.names else np.zeros((0, 6))
    off = np.concatenate([np.asarray(b.offset_trans), np.asarray(b.offset_rot)], axis=1) \
        if b.names else np.zeros((0, 6))
    pre = np.concatenate([np.asarray(b.preload_force), np.asarray(b.preload_torque)], axis=1) \
        if b.names else np.zeros((0, 6))
    spring_k = np.asarray(s.k).copy()
    free_length = np.asarray(s.free_length).copy()
    for i, p in enumerate(params):
        if write[i] and p.kind == "stiffness":
            k[p.element, list(p.axes)] = values[i] * p.to_internal
        if write[i] and p.kind == "spring_k":
            spring_k[p.element] = values[i]
    for i, p in enumerate(params):
        if not write[i]:
            continue
        if p.kind == "constant":
            a = p.axes[0]
            c = values[i] - pre[p.element, a]
            if k[p.element, a] > 0:
                off[p.element, a] = c / k[p.element, a]
            else:  # no stiffness to turn the constant force into an offset: keep it a preload
                off[p.element, a] = 0.0
                pre[p.element, a] = values[i]
        elif p.kind == "spring_c" and spring_k[p.element] > 0:
            free_length[p.element] = values[i] / spring_k[p.element]
    return eqx.tree_at(
        lambda m: (m.bushings.k_trans, m.bushings.k_rot, m.bushings.offset_trans,
                   m.bushings.offset_rot, m.bushings.preload_force, m.bushings.preload_torque,
                   m.springs.k, m.springs.free_length),
        mech,
        tuple(jnp.asarray(a) for a in (k[:, :3], k[:, 3:], off[:, :3], off[:, 3:], pre[:, :3],
                                       pre[:, 3:], spring_k, free_length)),
    )


def _negligible(system: DirectSystem, threshold: float) -> np.ndarray:
    """Unknowns whose columns are rounding noise: at a typical value (the model's, or the
    largest model value of the same unit when it is 0) their effect on the equations is below
    `threshold` times the norm of the load terms. A direction that never deforms (the
    crank-slider's slider, spec §1.12b) gives such a column; scaled to unit norm inside `lsq`
    it would look like a real one."""
    prior = np.abs(system.prior)
    typical = prior.copy()
    units = [p.unit for p in system.parameters]
    for unit in set(units):
        same = np.array([u == unit for u in units])
        top = np.max(prior[same], initial=0.0)
        typical[same & (typical == 0)] = top if top > 0 else 1.0
    effect = typical * np.linalg.norm(system.W, axis=0)
    reference = np.linalg.norm(system.y)
    if reference == 0:
        reference = np.max(effect, initial=0.0)
    return effect <= threshold * reference


def direct(
    mech: Mechanism,
    measurements: Measurements,
    params: Params | Callable[[Mechanism], object] | None = None,
    *,
    where: Callable[[Mechanism], object] | Params | None = None,
    elements: Sequence[str] | None = None,
    axisymmetric: Sequence[str] = (),
    method: str = "basic",
    hold: str = "zero",
    eliminate: bool = False,
    weighting: str = "noise",
    threshold: float | None = None,
    prior_sigma: float | Mapping[str, float] = 0.5,
    max_sigma_pct: float = MAX_SIGMA_PCT,
    polish: bool | str = "auto",
    check: bool = True,
) -> tuple[Mechanism, DirectReport]:
    """Identify bushing and spring stiffnesses from measured equilibria by the direct (linear)
    method of the thesis's Chapter 4 (spec stiffness §1.8–1.14; see the module docstring).

    Select (`where`, `elements`), partition into the known and unknown parts of the internal
    forces, solve the stacked linear system with `diffsusp.lsq`, combine the identified values
    back into the model.

    **Arguments:**

    - `mech`: the model (its geometry is taken as exact; its values of the unknowns are the
      prior, and are kept where the data do not determine them).
    - `measurements`: `diffsusp.measure.Measurements` (part poses of every moving part and the
      loads, per case), or a `Poses` measurement (`measure.as_equilibria`).
    - `params` (or `where=`, the same): the selection every identification method takes: a
      `Params` or a `where` function, equinox style, among `m.bushings.k_trans`, `k_rot`
      (stiffness per axis), `offset_trans`, `offset_rot` (offsets δ0, identified as the
      constant force K·δ0), `m.springs.k`, `free_length` (with k: the unknowns K and K·L0);
      a `Params` selects single entries (e.g. `Params.bushing_stiffness(mech, ["A"],
      ["Ktx"])`; its start values and bounds are not used: the model's values are the prior).
      Default: all bushing stiffnesses and the springs' K and K·L0.
    - `elements`: names of the bushings and springs to identify (default all); the others
      keep their model values (their forces move to the right-hand side).
    - `axisymmetric`: bushings with Ktx = Kty and Krx = Kry (4 unknowns: Ktr, Ktz, Krr, Krz;
      spec §1.8, 4.40).
    - `method`: "basic" (pivoted-QR basic solution, like MATLAB's backslash in the thesis),
      "min_norm" (the solution nearest the held values), "tsvd", "tikhonov" (toward the model's
      values with relative σ `prior_sigma`, or absolute σ by name), "nonneg" (stiffnesses ≥ 0).
    - `hold`: the value of unknowns the data do not determine: "zero" (the thesis's zeros) or
      "model" (the model's values, so that their forces stay in the equations instead of being
      shared out among the others — what noisy data need).
    - `eliminate`: also hold, one at a time (largest σ% first), the unknowns that are
      identifiable but not determined (σ% > `max_sigma_pct`), and re-estimate the others: the
      elimination loop of spec guaranteed_least_squares §3.9.
    - `weighting`: "noise" (default): generalised least squares, each case's equations
      whitened by the covariance their residual gets from landmark noise (iid per coordinate;
      from the registration geometry) through the tangent stiffness at the solution, so that
      noisy stiff directions do not drown the informative ones and σ is meaningful; two
      reweighting passes. "none": the scaled equations as they are (the thesis).
    - `threshold`: relative identifiability threshold of `lsq` on unit-norm columns (default
      `DEFAULT_THRESHOLD` = 1e-5; also the singular-value cut of "tsvd").
    - `max_sigma_pct`: identifiable unknowns with a larger σ% are reported as not determined.
    - `polish`: errors in variables (issue 12). The rows Lᵀ·D and L are built from the
      *measured* poses, so with noisy landmarks the regressors are noisy and the linear
      estimate is biased (A.Krz of the pseudo-McPherson by ≈ 3 of its own σ at 0.05 mm), a bias
      its σ does not show. "auto" (default): when the linear estimate does not reproduce the
      measurements to noise-free accuracy (consistency χ²/dof > `POLISH_CHI2`), the determined
      stiffnesses are polished by least squares through the equilibrium
      (`identify.least_squares` on the same landmarks or poses, started at the linear
      estimate, the other unknowns held at the model's values): an estimator that compares
      the model's own equilibria with the data, so its errors are those of the measurements
      only, and its σ (from the whitened Jacobian) is the spread the estimate really has. The
      report keeps the linear values in `linear_values` and the fit in `polished`. True:
      always; False: the thesis's linear estimate alone (its σ ignores the errors in
      variables; the consistency verdict still says whether the model reproduces the data).
      Only bushing stiffnesses per axis and spring rates whose model value is positive are
      polished; offsets, K·L0 (through the spring's free length), axisymmetric pairs and
      stiffnesses the model sets to 0 are *held at the model's values* — in the polish and in
      the returned model, whose consistency is the one reported (status "held at the model's
      value in the polish", with the linear estimate; a linear K·L0 biased by the errors in
      variables would spoil the polish). A polished stiffness is "identified" by the
      least-squares gate (σ% at the model's values, `FitReport.determined`).
    - `check`: re-solve the identified model at the measured cases and compare with the
      measurements in units of their σ (`report.consistency`; a determined value of an
      inconsistent model is not reported as identified).

    **Returns:** `(mech', report)`: the model with the identified values (N/mm, N·mm/rad inside;
    unknowns the data do not determine keep the model's values, except with "tikhonov" whose
    solution is complete) and a `DirectReport` (values in N/mm, N·mm/deg, N, N·mm).

    **Raises:** `InputError` for measurements that do not fit the model (a part without a pose,
    load tables of another shape, non-finite values) or a selection the method cannot identify;
    `ModelError` for a selected element with a nonlinear (spline, tabulated) law.
    """
    if method not in METHODS:
        raise InputError(f"method must be one of {', '.join(METHODS)}; got {method!r}.")
    if hold not in ("zero", "model"):
        raise InputError(f"hold must be 'zero' or 'model'; got {hold!r}.")
    if weighting not in ("noise", "none"):
        raise InputError(f"weighting must be 'noise' or 'none'; got {weighting!r}.")
    if not max_sigma_pct > 0:
        raise InputError(f"max_sigma_pct must be positive; got {max_sigma_pct!r}.")
    threshold = DEFAULT_THRESHOLD if threshold is None else float(threshold)
    ctx = _prepare(mech, measurements, _selection_of(params, where), elements, axisymmetric)
    raw = ctx.system()
    # Structure: what the equations determine (unweighted, as the thesis writes them).
    negligible = _negligible(raw, threshold)
    structure = _structure(_fit(raw, "basic", "zero", threshold, 0.5, negligible), negligible)
    # Estimate: the structurally undetermined unknowns held for the basic solution.
    held = negligible | (~structure.kept if method in ("basic", "nonneg") else negligible)
    fit, eliminated = _estimate(raw, method, hold, eliminate, threshold, prior_sigma,
                                max_sigma_pct, held)
    system = raw
    if weighting == "noise":
        for _ in range(2):
            analysis = _analyse(structure, fit, negligible, eliminated, max_sigma_pct, hold)
            good = analysis.identifiable & ~(np.nan_to_num(analysis.sigma_pct) > max_sigma_pct)
            at = np.where(good, np.asarray(fit.x, float), raw.prior)
            system = ctx.system(ctx.whitener(at))
            fit, eliminated = _estimate(system, method, hold, eliminate, threshold, prior_sigma,
                                        max_sigma_pct, held)
    analysis = _analyse(structure, fit, negligible, eliminated, max_sigma_pct, hold)
    params = raw.parameters
    identified = analysis.identifiable & ~(np.nan_to_num(analysis.sigma_pct) > max_sigma_pct)
    values = np.asarray(fit.x, float)
    # A negative stiffness is not a result, however small its σ: typically the forces of
    # unknowns held at wrong values (hold="model" with a poor model) or noisy deformations used
    # as regressors were pushed onto it. Not written to the model.
    negative = identified & (values < 0) & np.array([p.kind in ("stiffness", "spring_k")
                                                     for p in params])
    status = analysis.status
    if negative.any():
        identified = identified & ~negative
        status = tuple("not physical: negative stiffness" if negative[i] else st
                       for i, st in enumerate(status))
    cov = np.asarray(fit.covariance, float)
    n_cases = len(raw.cases)
    residual = raw.y - raw.W @ values  # in N, whatever the weighting of the solve
    case_res = np.linalg.norm(residual.reshape(n_cases, -1), axis=1)
    whitened = (system.y - system.W @ values).reshape(n_cases, -1)
    case_scale = np.linalg.norm(raw.y.reshape(n_cases, -1), axis=1)
    write = ~negligible if method == "tikhonov" else identified
    notes = list(raw.notes)
    if negative.any():
        notes.append(f"{', '.join(np.asarray(raw.names)[negative])} came out negative and "
                     "were not kept: check the values held for the other unknowns and the "
                     "loads' signs, or use method='nonneg'.")
    for step in getattr(fit, "log", ()):
        notes.append(f"eliminated {step.removed} ({step.reason.replace('sigma', 'σ')}) and "
                     "re-estimated the others")
    report = DirectReport(
        names=raw.names, values=values, sigma=analysis.sigma, sigma_pct=analysis.sigma_pct,
        identified=identified, identifiable=analysis.identifiable, status=status,
        units=tuple(p.unit for p in params), prior=raw.prior, relations=analysis.relations,
        derived=_derived(params, values, cov, mech, identified), case_residuals=case_res,
        case_scale=case_scale, cases=raw.cases, notes=tuple(notes), fit=fit, method=method,
        rank=int(np.sum(structure.kept)), n_equations=len(raw.y), max_sigma_pct=max_sigma_pct,
        weighted=system.weighted, equation_residuals=residual.reshape(n_cases, -1),
        whitened_equation_residuals=whitened,
    )
    fitted = _apply(mech, params, values, write)
    if polish not in (True, False, "auto"):
        raise InputError(f"polish must be True, False or 'auto'; got {polish!r}.")
    if not (check or polish):
        return fitted, report
    data = check_data(mech, measurements)
    consistency = check_consistency(fitted, data, int(np.sum(write)), cases=raw.cases)
    report = dataclasses.replace(report, consistency=consistency)
    from .direct_polish import polish_linear

    noisy = consistency.chi2 > POLISH_CHI2 * consistency.dof
    if polish is True or (polish == "auto" and noisy):
        fitted, report = polish_linear(fitted, report, params, data, max_sigma_pct, mech)
    return fitted, report


def _fit(system: DirectSystem, method, hold, threshold, prior_sigma, fixed, eliminate=False,
         max_sigma_pct=MAX_SIGMA_PCT):
    """One `lsq` solve (or elimination loop) of `system` with the `fixed` unknowns held."""
    from .. import lsq

    params = system.parameters
    names = system.names
    options = dict(method=method, threshold=threshold,
                   prior=system.prior if hold == "model" else np.zeros(len(names)))
    if method == "tikhonov":
        options.update(prior=system.prior,
                       prior_sigma=_prior_sigma(system.prior, params, prior_sigma))
    if method == "nonneg":
        lower = np.array([0.0 if p.kind in ("stiffness", "spring_k") else -np.inf
                          for p in params])
        options.update(method="bounded", lower=lower)
    fixed_names = [n for n, f in zip(names, fixed, strict=True) if f]
    problem = lsq.Problem(R=jnp.asarray(system.R), n=len(system.y), names=names)
    if eliminate:
        fit, _ = problem.eliminate(fixed=fixed_names, ic_threshold=0.0,
                                   sigma_pct_threshold=max_sigma_pct, **options)
        return fit
    return problem.fit(fixed=fixed_names, **options)


def _estimate(system, method, hold, eliminate, threshold, prior_sigma, max_sigma_pct, held):
    """The estimate and the unknowns the elimination loop removed (beyond `held`)."""
    fit = _fit(system, method, hold, threshold, prior_sigma, held, eliminate, max_sigma_pct)
    eliminated = np.zeros(len(system.names), bool)
    for step in getattr(fit, "log", ()):
        eliminated[system.names.index(step.removed)] = True
    return fit, eliminated


from .direct_polish import POLISH_CHI2, direct_batch  # noqa: E402  (it uses `direct`)
