"""Errors in variables for the direct method: the polish of its linear estimate by least
squares through the equilibrium (`polish_linear`; `direct_batch`, in `identify.direct`, polishes
many measurement sets at once with the same plan). spec: stiffness §1.10 (the regressors are
built from measured poses), §6 item 8 (the gradient-based fit through the equilibrium,
`identify.least_squares`, which the polish runs)."""

import dataclasses

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..model.mechanism import Mechanism
from ._least_squares import least_squares_batch
from .direct_report import DirectReport
from .direct_unknowns import STIFFNESS_NAMES, Parameter, derived, prior
from .params import Params
from .report import MAX_SIGMA_PCT, bar_reason, check_consistency, within_bar

__all__ = ["POLISH_CHI2"]  # re-exported by `identify.direct`


POLISH_CHI2 = 1e-6
"""`direct(polish="auto")` polishes when χ²/dof of the linear estimate exceeds this: a residual
RMS above 10⁻³ σ, i.e. data that are not noise-free (noise-free data are reproduced to
rounding, and the linear estimate is then exact)."""


@dataclasses.dataclass(frozen=True)
class PolishPlan:
    """What the polish fits: `params` (the `Params` of `identify.least_squares`, started at
    the model's values) and `index` {unknown: its parameter} for the stiffnesses and spring
    rates polished."""

    params: Params
    index: dict

    @property
    def unknowns(self) -> list[int]:
        return sorted(self.index)


def polish_plan(mech: Mechanism, params: tuple[Parameter, ...]) -> PolishPlan | None:
    """The plan of the polish (see `PolishPlan`), None when nothing can be polished.

    Polished: every bushing stiffness per axis and spring rate among the unknowns whose model
    value is positive — log-scaled, started at `mech`'s values, the weak prior centred there —
    and every cubic term per axis (S of F = −(K·δ + S·δ³), either sign: linear scale, no
    prior). A stiffness the model sets to 0 (no stiffness on that axis, e.g. the strut
    bushing's Krz of the pseudo-McPherson) has no log to start from or to centre a prior on:
    it keeps its linear value, like offsets, K·L0 and axisymmetric pairs."""
    b, s = mech.bushings, mech.springs
    k_model = np.concatenate([np.asarray(b.k_trans), np.asarray(b.k_rot)], axis=1) \
        if b.names else np.zeros((0, 6))
    kt = np.zeros((len(b.names), 3), bool)
    kr, ct, cr = np.zeros_like(kt), np.zeros_like(kt), np.zeros_like(kt)
    ks = np.zeros(len(s.names), bool)
    lsq_name = {}
    for i, p in enumerate(params):
        a = p.axes[0] if len(p.axes) == 1 else None
        if p.kind == "stiffness" and a is not None and k_model[p.element, a] > 0:
            (kt if a < 3 else kr)[p.element, a % 3] = True
            lsq_name[i] = f"{b.names[p.element]}.{STIFFNESS_NAMES[a]}"
        elif p.kind == "cubic" and a is not None:
            (ct if a < 3 else cr)[p.element, a % 3] = True
            field = "cubic_trans" if a < 3 else "cubic_rot"
            lsq_name[i] = f"{b.names[p.element]}.{field}_{'xyz'[a % 3]}"
        elif p.kind == "spring_k" and float(s.k[p.element]) > 0:
            ks[p.element] = True
            lsq_name[i] = f"{s.names[p.element]}.k"
    if not lsq_name:
        return None

    def selection(groups, positive):
        leaves, masks = [], []
        for group, name, mask in groups:
            if mask.any():
                leaves.append(lambda m, group=group, name=name: getattr(getattr(m, group), name))
                masks.append(mask)
        return Params.leaves(mech, lambda m: tuple(f(m) for f in leaves), tuple(masks),
                             positive=positive) if leaves else None

    parts = [selection((("bushings", "k_trans", kt), ("bushings", "k_rot", kr),
                        ("springs", "k", ks)), None),
             selection((("bushings", "cubic_trans", ct), ("bushings", "cubic_rot", cr)), False)]
    parts = [q for q in parts if q is not None]
    lsq_params = parts[0] if len(parts) == 1 else parts[0] + parts[1]
    return PolishPlan(lsq_params, {i: lsq_params.index(n) for i, n in lsq_name.items()})


def polish_start(plan: PolishPlan, report: DirectReport) -> np.ndarray:
    """Start of the polish: the linear estimate where it determined a positive value whose σ %
    at the estimate is also within the bar, the model's value elsewhere.

    Not a verdict (that is the polish's, judged at the start values): a starting point. The
    errors in variables pull a little-deformed direction's linear estimate toward 0 by more
    than its σ says (its σ % at the estimate is then large): judged at the start values it is
    determined, and starting there the Chrono rehearsal lost 3 of 200 truths (no equilibrium
    at the polish's start)."""
    start = np.array(plan.params.start)
    plausible = within_bar(report.sigma_pct, MAX_SIGMA_PCT)  # a start, not the caller's bar
    log_scaled = np.asarray(plan.params.log_scaled)
    for i, j in plan.index.items():
        v = report.values[i] * report.parameters_to_model[i]
        if report.identified[i] and (v > 0 or not log_scaled[j]) and plausible[i]:
            start[j] = v
    return start


def merge_polish(report: DirectReport, plan: PolishPlan, fit, params: tuple[Parameter, ...],
                  mech: Mechanism) -> tuple[Mechanism, DirectReport]:
    """The model the polish fitted and the direct report of exactly that model.

    The returned model is `mech` with the polished values (`plan.params.apply`): every unknown
    the polish does not cover is *held at the model's value*, as the polish held it (offsets
    and K·L0 through the spring's free length, axisymmetric pairs, stiffnesses the model sets
    to 0). So `report.consistency` (the polish's own re-solve, at its equilibria) is the
    verdict on the returned model, and the report's values are that model's values. Per
    unknown: polished (value, σ and verdict of the fit; "identified" needs `fit.determined`,
    the least-squares gate on the information at the model's values, not on the estimate's
    own σ%), held (the model's value, σ NaN, not identified; the linear estimate, biased by
    the errors in variables, stays in `linear_values` and in the status), or neither (not
    determined by the linear estimate: unchanged). Derived quantities (L0, δ0) need a held
    unknown and are recomputed with the new verdicts."""
    # What the report calls identified is what the model carries: a polished value the data do
    # not determine keeps the model's value (its polished estimate stays in the report).
    determined = np.asarray(fit.determined, bool)
    model = plan.params.apply(mech, jnp.asarray(
        np.where(determined, fit.estimate, np.asarray(plan.params.start))))
    held_values = prior(model, params)  # the returned model's values, table units
    values, sigma = report.values.copy(), report.sigma.copy()
    sigma_pct, identified = report.sigma_pct.copy(), report.identified.copy()
    gate = (np.full(len(values), np.nan) if report.gate_sigma_pct is None else
            np.array(report.gate_sigma_pct, dtype=float))
    status = list(report.status)
    conv = report.parameters_to_model
    for i, j in plan.index.items():
        values[i], sigma[i] = fit.estimate[j] / conv[i], fit.sigma[j] / conv[i]
        sigma_pct[i] = 100.0 * fit.sigma[j] / abs(fit.estimate[j])
        ok = bool(determined[j])
        identified[i] = ok
        gate[i] = fit.judged_sigma_pct[j]  # the fit's gate: at the model's values
        status[i] = ("identified (polished through the equilibrium)" if ok else
                     "not determined: not seen by the data after the polish"
                     if not fit.identifiable[j] else
                     f"not determined: {bar_reason(gate[i], fit.max_sigma_pct)} (after the "
                     f"polish; {sigma_pct[i]:.3g}% at the estimate)")
    held = [i for i in np.flatnonzero(report.identified) if i not in plan.index]
    for i in held:
        what = {"constant": " (its offset δ0; K·δ0 with the polished K)",
                "spring_c": " (its free length L0; K·L0 with the polished K)"}.get(
                    params[i].kind, "")
        status[i] = (f"held at the model's value in the polish{what}: linear estimate "
                     f"{report.values[i]:.6g} ± {report.sigma[i]:.2g}, biased by the errors "
                     "in variables")
        values[i], sigma[i], sigma_pct[i], identified[i] = held_values[i], np.nan, np.nan, False
        gate[i] = np.nan
    notes = list(report.notes)
    notes.append(f"errors in variables: {len(plan.index)} stiffness(es) polished by least "
                 f"squares through the equilibrium from the linear estimate ({fit.message}, "
                 f"{fit.steps} steps); the model returned and judged is the polished one")
    if held:
        notes.append(f"{', '.join(report.names[i] for i in held)} held at the model's values "
                     "in the polish and in the returned model (the polish covers bushing "
                     "stiffnesses per axis and spring rates whose model value is positive, and "
                     "cubic terms per axis; a "
                     "K·L0 keeps the spring's free length); their linear estimates are in "
                     "linear_values")
    derived_values = derived(params, values, np.asarray(report.fit.covariance, float), model,
                       identified)
    report = dataclasses.replace(
        report, values=values, sigma=sigma, sigma_pct=sigma_pct, identified=identified,
        gate_sigma_pct=gate, status=tuple(status), notes=tuple(notes), polished=fit,
        linear_values=report.values, consistency=fit.consistency,
        derived=derived_values)
    return model, report.judged()


def polish_linear(fitted: Mechanism, report: DirectReport, params: tuple[Parameter, ...], data,
                  max_sigma_pct: float, mech: Mechanism) -> tuple[Mechanism, DirectReport]:
    """Least squares through the equilibrium from the linear estimate (see `direct`,
    `polish`): every bushing stiffness per axis and spring rate among the unknowns with a
    positive model value and every cubic term per axis, the other unknowns held at the
    model's values (a linear K·L0 biased by the errors in variables would bias the polish:
    notebook 02's data, max_steps with χ²/dof ≈ 4000), the weak default prior centred on the
    model's values. Returns the polished model (held values included) and its report
    (`merge_polish`); `fitted` (the linear estimate's model) when there is nothing to
    polish."""
    plan = polish_plan(mech, params)
    if plan is None or not report.identified[plan.unknowns].any():
        return fitted, report  # nothing determined to polish (e.g. all came out negative)
    start = polish_start(plan, report)
    batch = least_squares_batch(mech, as_batch(data, 1), plan.params, start=start[None],
                                max_sigma_pct=max_sigma_pct)
    fit = batch.reports[0]
    model, merged = merge_polish(report, plan, fit, params, mech)
    if not np.all(fit.determined):  # the returned model differs from the fit's: judge it
        consistency = check_consistency(model, data, int(np.sum(fit.determined)),
                                        cases=report.cases)
        merged = dataclasses.replace(merged, consistency=consistency).judged()
    return model, merged


def as_batch(data, n: int, items=None):
    """Measurements (one data set each) stacked along a leading data-set axis: `data` repeated
    `n` times, or the measured values of `items` (lists of measurements like `data`)."""
    out = []
    for k, m in enumerate(data):
        fields = m.value_fields
        if items is None:
            values = tuple(jnp.broadcast_to(getattr(m, f), (n, *getattr(m, f).shape))
                           for f in fields)
        else:
            values = tuple(jnp.stack([getattr(it[k], f) for it in items]) for f in fields)
        out.append(eqx.tree_at(lambda mm, fields=fields: tuple(getattr(mm, f) for f in fields),
                               m, values))
    return tuple(out)
