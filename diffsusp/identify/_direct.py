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

**Modules.** This module holds the selection of the unknowns (`Parameter`), the assembled
system (`DirectSystem`, `direct_system`), the estimate and the write-back (`direct`); about
770 lines, because these share the `Parameter` description and the assembled `_Context` and
read as one method. The rows and the noise whitening are in `identify.direct_equations`, the
measurement checks and pose covariance in `identify.direct_data`, the identifiability
analysis in `identify.direct_analysis`, the report (`DirectReport`) in `identify.direct_report`,
the errors-in-variables polish and `direct_batch` in `identify.direct_polish`; the report's
common part is in `identify.report`.
"""

import dataclasses
from collections.abc import Callable, Mapping, Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Float

from .. import lsq
from ..errors import InputError
from ..measure.data import as_equilibria
from ..measure.measurements import Measurements
from ..model.mechanism import Mechanism
from ._least_squares import least_squares_batch
from .direct_analysis import analyse, structure_of
from .direct_data import check_measurements, pose_covariance_jit
from .direct_equations import BUSHING_COLUMNS, r_factor, system_arrays, whiteners
from .direct_polish import (
    POLISH_CHI2,
    as_batch,
    merge_polish,
    polish_linear,
    polish_plan,
    polish_start,
)
from .direct_report import DirectReport
from .direct_unknowns import (
    STIFFNESS_NAMES,
    Parameter,
    bushing_arrays,
    default_where,
    derived,
    direct_selection,
    free_axes,
    parameters,
    prior,
    selected_fields,
    selection_of,
    with_cubic,
    with_offsets,
)
from .params import Params
from .report import MAX_SIGMA_PCT, check_consistency, check_data, within_bar

__all__ = ["DirectReport", "DirectSystem", "Parameter", "direct", "direct_batch",
           "direct_selection", "direct_system", "with_cubic", "with_offsets"]

DEFAULT_THRESHOLD = 1e-5
"""Default identifiability threshold of the direct method (relative, on unit-norm columns: see
`lsq.solve`). Far above rounding, so that stiffnesses told apart only by second-order effects of
large rotations — which no measurement resolves — are reported as combinations (spec §7 R3)."""
# MAX_SIGMA_PCT (`report.MAX_SIGMA_PCT`, 10): identifiable parameters with a relative standard
# deviation above it, judged at the model's values (`report.sigma_pct_at_start`), are reported
# as not determined by the data (no value in the table). Engineering accuracy rather than the
# statistical limit of spec guaranteed_least_squares §3.8 (beyond 100 % the 68 % interval
# contains 0): with noisy poses the regressors themselves are noisy (errors in variables),
# which biases stiff, little-deformed directions toward 0 by more than their σ says; they are
# the ones with a large σ%.

METHODS = ("basic", "min_norm", "tsvd", "tikhonov", "nonneg")


# ----------------------------------------------------------------------------- selection


def _evaluation_model(mech: Mechanism, params: tuple[Parameter, ...]) -> Mechanism:
    """`mech` with the unknowns removed from its laws: what remains of Q_int is known."""
    s = mech.springs
    k, offset, preload, cubic = bushing_arrays(mech, cubic=True)
    spring_k = np.asarray(s.k).copy()
    free_length = np.asarray(s.free_length).copy()
    for p in params:
        if p.kind == "stiffness":
            k[p.element, list(p.axes)] = 0.0
        elif p.kind == "cubic":
            cubic[p.element, list(p.axes)] = 0.0
        elif p.kind == "constant":
            offset[p.element, list(p.axes)] = 0.0
            preload[p.element, list(p.axes)] = 0.0
        elif p.kind == "spring_k":
            spring_k[p.element] = 0.0
        else:
            free_length[p.element] = 0.0
    return eqx.tree_at(
        lambda m: (m.bushings.k_trans, m.bushings.k_rot, m.bushings.cubic_trans,
                   m.bushings.cubic_rot, m.bushings.offset_trans, m.bushings.offset_rot,
                   m.bushings.preload_force, m.bushings.preload_torque, m.springs.k,
                   m.springs.free_length),
        mech,
        tuple(jnp.asarray(a) for a in (k[:, :3], k[:, 3:], cubic[:, :3], cubic[:, 3:],
                                       offset[:, :3], offset[:, 3:], preload[:, :3],
                                       preload[:, 3:], spring_k, free_length)),
    )


# ----------------------------------------------------------------------------- assembly


def _selection(mech: Mechanism, params: tuple[Parameter, ...]) -> np.ndarray:
    """Matrix M (table, p) mapping the unknowns (table units) onto the table of unit columns:
    per bushing 6 stiffness axes (model units), 6 constants and 6 cubic terms (model units),
    then per spring K and K·L0 (`direct_equations.BUSHING_COLUMNS`).
    Axisymmetric unknowns feed two axes; N·mm/deg unknowns carry their 180/π. The selection is
    data (not compiled structure), so every choice of unknowns of one model shares one compiled
    assembly per number of unknowns."""
    n_b = len(mech.bushings.names)
    nc = BUSHING_COLUMNS
    table = nc * n_b + 2 * len(mech.springs.names)
    m = np.zeros((table, len(params)))
    for i, p in enumerate(params):
        if p.kind in ("stiffness", "cubic"):
            first = nc * p.element + (0 if p.kind == "stiffness" else 12)
            for a in p.axes:
                m[first + a, i] = p.to_internal
        elif p.kind == "constant":
            m[nc * p.element + 6 + p.axes[0], i] = 1.0
        elif p.kind == "spring_k":
            m[nc * n_b + 2 * p.element, i] = 1.0
        else:
            m[nc * n_b + 2 * p.element + 1, i] = 1.0
    return m




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
                            prior=prior(self.mech, self.params), notes=tuple(self.meas.notes),
                            weighted=whitener is not None,
                            R=np.asarray(r_factor(jnp.asarray(W), jnp.asarray(y))))

    def whitener(self, x) -> np.ndarray:
        cov = pose_covariance_jit(self.mech, self.meas)
        return np.asarray(whiteners(self.eval_mech, jnp.asarray(self.selection),
                                     jnp.asarray(self.q), self.null, jnp.asarray(x, float),
                                     cov))


def _prepare(mech, measurements, where, elements, axisymmetric) -> _Context:
    measurements = as_equilibria(measurements)
    q = check_measurements(mech, measurements)
    fields = selected_fields(mech, where or default_where)
    params = parameters(mech, fields, elements, axisymmetric,
                         free=free_axes(mech) if where is None and elements is None else ())
    eval_mech = _evaluation_model(mech, params)
    selection = _selection(mech, params)
    rows, rhs, null = system_arrays(eval_mech, jnp.asarray(selection), jnp.asarray(q),
                                     measurements.loads)
    return _Context(mech, measurements, q, params, eval_mech, selection, np.asarray(rows),
                    np.asarray(rhs), null)


def direct_system(
    mech: Mechanism,
    measurements: Measurements,
    params: Params | Callable[[Mechanism], object] | Sequence[str] | None = None,
    *,
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
    ctx = _prepare(mech, measurements, *selection_of(params), axisymmetric)
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


def _apply(mech: Mechanism, params, values, write) -> Mechanism:
    """The mechanism with the written unknowns replaced (table units → model units)."""
    s = mech.springs
    k, off, pre, cubic = bushing_arrays(mech, cubic=True)
    spring_k = np.asarray(s.k).copy()
    free_length = np.asarray(s.free_length).copy()
    for i, p in enumerate(params):
        if write[i] and p.kind == "stiffness":
            k[p.element, list(p.axes)] = values[i] * p.to_internal
        if write[i] and p.kind == "cubic":
            cubic[p.element, list(p.axes)] = values[i] * p.to_internal
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
        lambda m: (m.bushings.k_trans, m.bushings.k_rot, m.bushings.cubic_trans,
                   m.bushings.cubic_rot, m.bushings.offset_trans, m.bushings.offset_rot,
                   m.bushings.preload_force, m.bushings.preload_torque, m.springs.k,
                   m.springs.free_length),
        mech,
        tuple(jnp.asarray(a) for a in (k[:, :3], k[:, 3:], cubic[:, :3], cubic[:, 3:],
                                       off[:, :3], off[:, 3:], pre[:, :3], pre[:, 3:], spring_k,
                                       free_length)),
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
    params: Params | Callable[[Mechanism], object] | Sequence[str] | None = None,
    *,
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

    Select (`params`), partition into the known and unknown parts of the internal
    forces, solve the stacked linear system with `diffsusp.lsq`, combine the identified values
    back into the model.

    **Arguments:**

    - `mech`: the model (its geometry is taken as exact; its values of the unknowns are the
      prior, and are kept where the data do not determine them).
    - `measurements`: `diffsusp.measure.Measurements` (part poses of every moving part and the
      loads, per case), or a `Poses` measurement (`measure.as_equilibria`).
    - `params`: the selection every identification method takes: a `Params` or a `where`
      function, equinox style, among `m.bushings.k_trans`, `k_rot` (stiffness per axis),
      `offset_trans`, `offset_rot` (offsets δ0, identified as the constant force K·δ0),
      `cubic_trans`, `cubic_rot` (the cubic terms S of F = −(K·δ + S·δ³), one column ∂Q/∂S
      each, in N/mm³ and N·mm/deg³; not with an offset on the same axis, which a cubic law
      makes nonlinear; `with_cubic` selects them with the default entries),
      `m.springs.k`, `free_length` (with k: the unknowns K and K·L0); a `Params` selects
      single entries (e.g. `Params.bushing_stiffness(mech, ["A"], ["Ktx"])`; its start values
      and bounds are not used: the model's values are the prior); or a sequence of element
      names (bushings and springs: their stiffnesses and K·L0; the other elements keep their
      model values, their forces moving to the right-hand side). Default: all bushing
      stiffnesses and the springs' K and K·L0.
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
    - `max_sigma_pct`: identifiable unknowns with a larger σ% *at the model's values*
      (100·σ/|model value|: the linear σ does not depend on θ; the one rule of `direct`,
      `iterative` and `least_squares`, `report.sigma_pct_at_start`, `judged_at`) are reported
      as not determined; an unknown whose model value is 0 (an offset) has no relative bar
      (identifiability alone). The reported σ% stays the one at the estimate.
    - `polish`: errors in variables. The rows Lᵀ·D and L are built from the
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
      inconsistent model is not reported as identified: its status reads "determined, but
      not identified: the model is inconsistent with the data", `DirectReport.judged`).

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
    selected, elements = selection_of(params)
    ctx = _prepare(mech, measurements, selected, elements, axisymmetric)
    raw = ctx.system()
    # Structure: what the equations determine (unweighted, as the thesis writes them).
    negligible = _negligible(raw, threshold)
    structure = structure_of(_fit(raw, "basic", "zero", threshold, 0.5, negligible), negligible)
    # Estimate: the structurally undetermined unknowns held for the basic solution.
    held = negligible | (~structure.kept if method in ("basic", "nonneg") else negligible)
    fit, eliminated = _estimate(raw, method, hold, eliminate, threshold, prior_sigma,
                                max_sigma_pct, held)
    system = raw
    if weighting == "noise":
        for _ in range(2):
            analysis = analyse(structure, fit, negligible, eliminated, max_sigma_pct, hold,
                                raw.prior)
            # where to linearise the noise model (not a verdict, so not the caller's bar): the
            # estimate where it is plausible (σ % at the estimate within the default bar), the
            # model's value elsewhere
            good = analysis.identifiable & within_bar(analysis.sigma_pct, MAX_SIGMA_PCT)
            at = np.where(good, np.asarray(fit.x, float), raw.prior)
            system = ctx.system(ctx.whitener(at))
            fit, eliminated = _estimate(system, method, hold, eliminate, threshold, prior_sigma,
                                        max_sigma_pct, held)
    analysis = analyse(structure, fit, negligible, eliminated, max_sigma_pct, hold, raw.prior)
    params = raw.parameters
    # The one rule of the suspension methods: σ % at the model's values.
    identified = analysis.identifiable & within_bar(analysis.gate_pct, max_sigma_pct)
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
    free = free_axes(mech) if selected is None and elements is None else []
    if free:
        notes.append("left out " + ", ".join(
            f"{mech.bushings.names[e]}.{STIFFNESS_NAMES[a]}" for e, a in free) + ": 0 in the "
            "model (free directions; select them with params to identify them)")
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
        derived=derived(params, values, cov, mech, identified), case_residuals=case_res,
        case_scale=case_scale, cases=raw.cases, notes=tuple(notes), fit=fit, method=method,
        rank=int(np.sum(structure.kept)), n_equations=len(raw.y), max_sigma_pct=max_sigma_pct,
        weighted=system.weighted, equation_residuals=residual.reshape(n_cases, -1),
        whitened_equation_residuals=whitened, gate_sigma_pct=analysis.gate_pct,
    )
    fitted = _apply(mech, params, values, write)
    if polish not in (True, False, "auto"):
        raise InputError(f"polish must be True, False or 'auto'; got {polish!r}.")
    if not (check or polish):
        return fitted, report
    data = check_data(mech, measurements)
    consistency = check_consistency(fitted, data, int(np.sum(write)), cases=raw.cases)
    report = dataclasses.replace(report, consistency=consistency)
    noisy = consistency.chi2 > POLISH_CHI2 * consistency.dof
    if polish is True or (polish == "auto" and noisy):
        fitted, report = polish_linear(fitted, report, params, data, max_sigma_pct, mech)
    return fitted, report.judged()


def _fit(system: DirectSystem, method, hold, threshold, prior_sigma, fixed, eliminate=False,
         max_sigma_pct=MAX_SIGMA_PCT):
    """One `lsq` solve (or elimination loop) of `system` with the `fixed` unknowns held."""
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



def direct_batch(
    mech: Mechanism,
    measurements: Sequence[Measurements],
    params: Params | Callable[[Mechanism], object] | None = None,
    *,
    polish: bool | str = "auto",
    max_sigma_pct: float = MAX_SIGMA_PCT,
    **options,
) -> tuple[DirectReport, ...]:
    """`direct` on many measurement sets of one layout under one load table (e.g. a
    Monte-Carlo of noise draws): the linear estimate of each set (one compiled assembly,
    shared), then the polish of every set that needs one at once (`least_squares_batch`, one
    vmapped program per LM step). `options` go to `direct`. **Returns:** one `DirectReport`
    per set (with `polished`; a polished set's identified mechanism is `mech` with its
    polished values, every other unknown held at the model's value, as `direct` returns)."""
    linear = [direct(mech, m, params, polish=False, max_sigma_pct=max_sigma_pct, **options)[1]
              for m in measurements]
    if not polish:
        return tuple(linear)
    where, elements = selection_of(params)
    unknowns = parameters(mech, selected_fields(mech, where or default_where), elements,
                          options.get("axisymmetric", ()))
    plan = polish_plan(mech, unknowns)
    if plan is None:
        return tuple(linear)
    # As `direct(polish="auto")`: sets whose linear estimate reproduces the data to
    # noise-free accuracy, or determined nothing, keep it.
    todo = [k for k, r in enumerate(linear)
            if r.identified[plan.unknowns].any() and (
                polish is True or r.consistency.chi2 > POLISH_CHI2 * r.consistency.dof)]
    out = list(linear)
    if not todo:
        return tuple(out)
    data = [check_data(mech, measurements[k]) for k in todo]
    starts = np.stack([polish_start(plan, linear[k]) for k in todo])
    batch = least_squares_batch(mech, as_batch(data[0], len(data), data), plan.params,
                                start=starts, max_sigma_pct=max_sigma_pct)
    for k, fit in zip(todo, batch.reports, strict=True):
        out[k] = merge_polish(linear[k], plan, fit, unknowns, mech)[1]
    return tuple(out)
