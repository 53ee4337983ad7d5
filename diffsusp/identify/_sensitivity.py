"""Exact sensitivities of K&C metrics to model parameters, and experiment design.

spec: stiffness §2.7 (influential, coupled and non-influential parameters), §3 (perspectives:
which load cases make a parameter identifiable); guaranteed_least_squares §3.8 (sensitivity
analysis); DESIGN.md "Identification" (sensitivity).

`sensitivity` differentiates every metric of a K&C evaluation (`diffsusp.kc.evaluate`: the
geometric metrics and the derivative metrics such as bump steer or lateral compliance steer)
with respect to every selected parameter, in forward mode through the implicitly differentiated
equilibrium: one compiled call, no finite differences. Normalised values are elasticities
∂m/∂θ · θ / scale(m), with scale(m) the metric's largest magnitude over the cases (a metric that
is zero at design, like toe, keeps a meaningful normalisation).

`design_experiment` chooses, from candidate load cases, the ones that best determine a set of
parameters from a measurement model (landmark positions, by default every marker of the moving
parts, with σ per coordinate): greedy forward selection on the Fisher information
F = Σ_c J_cᵀ J_c / σ² in relative (log) coordinates for positive parameters, by the D criterion
(log det F) or by the largest σ% of the target parameters, and reports what each added case buys.
"""

import dataclasses
from collections.abc import Callable, Sequence

import equinox as eqx
import jax
import numpy as np

from .. import plot
from ..errors import InputError
from ..kc.events import evaluate, raw_metrics
from ..kc.metrics import DERIVATIVE_METRICS, display, display_unit, flagged
from ..kc.second_order import hessian_vector_product
from ..model.mechanism import Loads, Mechanism
from ..statics import Status, marker_poses, solve_statics
from .params import Params
from .report import Report, plain

PARAMETER_SETS = {
    "stiffness": "every non-zero bushing stiffness and spring rate (log-scaled: per relative "
                 "change)",
    "centres": "the centre of every bushing (x, y, z in mm)",
    "hardpoints": "the position of every marker on a moving part (x, y, z in mm)",
}
"""Named parameter sets of a model for a sensitivity study (`parameter_set`)."""


def parameter_set(mech: Mechanism, which: str) -> Params:
    """The parameters `which` (a key of `PARAMETER_SETS`) of `mech`.

    **Raises:** `InputError` for an unknown name."""
    if which not in PARAMETER_SETS:
        raise InputError(f"--params must be one of {', '.join(PARAMETER_SETS)}; got '{which}'.")
    if which == "stiffness":
        where = [lambda m: m.bushings.k_trans, lambda m: m.bushings.k_rot,
                 lambda m: m.springs.k]
        leaves = [np.asarray(w(mech)) for w in where]
        picked = [(w, v > 0) for w, v in zip(where, leaves, strict=True) if np.any(v > 0)]
        return Params.leaves(mech, lambda m: tuple(w(m) for w, _ in picked),
                             tuple(mask for _, mask in picked))
    if which == "centres":
        return Params.bushing_centres(mech, mech.bushings.names)
    moving = np.asarray(mech.markers.part) >= 0
    mask = np.repeat(moving[:, None], 3, axis=1)
    return Params.leaves(mech, lambda m: m.markers.position, mask)


def _as_params(mech: Mechanism, params) -> Params:
    if isinstance(params, Params):
        return params
    if callable(params):
        return Params.leaves(mech, params)
    raise InputError("params must be a diffsusp.identify.Params or a `where` selector "
                     "(lambda m: m.bushings.k_trans, ...).")


@dataclasses.dataclass(frozen=True)
class SensitivityReport(Report):
    """Sensitivities of K&C metrics to parameters at each case of an event.

    - `jacobian`: metric name → `(cases, p)` ∂metric/∂θ (metric units per parameter unit).
    - `elasticity`: metric name → `(cases, p)`: ∂m/∂θ · θ / scale(m) (dimensionless: the
      relative change of the metric, in units of its largest magnitude over the cases, per
      relative change of θ; for parameters that can be zero or negative, such as positions,
      θ is replaced by 1 unit: per mm).
    - `values`: metric name → `(cases,)`; `params`: names and values θ.
    - `event`, `x_name`, `x`: the K&C event's name and its input per case (empty for a rig).
    - `direction` `(p,)` and `hvp`: metric name → `(cases, p)` ∇²m·v, the change of each
      sensitivity per unit step of the parameters along v (second order,
      `sensitivity(..., direction=v)`; None and empty otherwise).

    On the report base (`Report`): `rows()` (metric, rank, parameter, elasticity), `summary()`
    (everything, as plain data), `to_json()`, `write(path)` (.csv, .json).
    """

    kind = "sensitivity"

    params: tuple[str, ...]
    theta: np.ndarray
    values: dict
    jacobian: dict
    elasticity: dict
    event: str = ""
    x_name: str = ""
    x: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    direction: np.ndarray | None = None
    hvp: dict = dataclasses.field(default_factory=dict)

    def rows(self) -> list[dict]:
        """One row per metric and parameter, by decreasing |elasticity| (the largest over the
        cases): metric, rank (1 = the largest), parameter, elasticity."""
        return [dict(metric=name, rank=k + 1, parameter=p, elasticity=plain(v))
                for name in self.elasticity for k, (p, v) in enumerate(self.ranked(name))]

    def summary(self) -> dict:
        """The event, the parameters and θ, and per metric its display unit, its values (in
        that unit), the Jacobian, the elasticities and the parameters ranked; with a second
        order (`direction`), v and each metric's Hessian-vector product."""
        out = {
            "event": self.event, "x": {"name": self.x_name, "values": self.x},
            "params": list(self.params), "theta": self.theta,
            "metrics": {
                name: {"unit": display_unit(name), "values": display(name, self.values[name]),
                       "jacobian": self.jacobian[name], "elasticity": self.elasticity[name],
                       "ranked": [[p, v] for p, v in self.ranked(name)]}
                for name in self.elasticity},
            "units": "jacobian: metric internal units (mm, N, rad) per parameter unit (N/mm, "
                     "N·mm/rad, mm)"}
        if self.direction is not None:
            out["direction"] = self.direction
            for name, h in self.hvp.items():
                out["metrics"][name]["hvp"] = h
        return plain(out)

    def ranked(self, metric: str, case: int | None = None) -> list[tuple[str, float]]:
        """Parameters by decreasing |elasticity| of `metric` (at `case`, or the largest over
        the cases), with the signed value."""
        e = self.elasticity[_check_metric(self, metric)]
        if case is None:
            pick = np.argmax(np.abs(np.nan_to_num(e)), axis=0)
            e = e[pick, np.arange(e.shape[1])]
        else:
            e = e[case]
        order = np.argsort(-np.abs(np.nan_to_num(e)), kind="stable")
        return [(self.params[j], float(e[j])) for j in order]

    def table(self, metrics: Sequence[str] | None = None, top: int = 5) -> str:
        """The `top` parameters of each metric (largest elasticity over the cases)."""
        lines = []
        for name in metrics or sorted(self.elasticity):
            ranks = self.ranked(name)[:top]
            lines.append(f"{name}: " + ", ".join(f"{p} {v:+.3g}" for p, v in ranks))
        return "\n".join(lines)

    def plot(self, metric: str, *, case: int | None = None, top: int = 12, ax=None):
        """Bar chart of the `top` elasticities of `metric` (`diffsusp.plot.sensitivity_bars`)."""
        ranks = self.ranked(metric, case)[:top]
        return plot.sensitivity_bars([v for _, v in ranks], [p for p, _ in ranks],
                                     title=f"elasticity of {metric}", ax=ax)


def _check_metric(report, metric):
    if metric not in report.elasticity:
        raise InputError(f"unknown metric '{metric}'; available: {sorted(report.elasticity)}.")
    return metric


def sensitivity_metrics(event, metrics: Sequence[str] | None = None, *,
                        derivatives: bool = True) -> tuple[str, ...]:
    """The metric names of a K&C `event` to differentiate (`sensitivity(..., metrics=)`).

    spec: stiffness §3 (perspective 3: which metrics a parameter moves). The event's public
    metrics (its `metrics` keys, possibly per side as 'left/toe'; names starting with '_' are
    internal), without the derivative metrics (`kc.metrics.DERIVATIVE_METRICS`) when
    `derivatives` is False. With `metrics` given, those names, checked against that set;
    otherwise the ones the K&C registry marks for sensitivity studies
    (`kc.metrics.flagged('sensitivity')`: toe, camber, half-track change and the derivative
    metrics the event has), sorted.

    **Raises:** `InputError` for a name the event does not have.
    """
    def base(k):
        return k.rsplit("/", 1)[-1]

    available = {k for k in event.metrics if not base(k).startswith("_")}
    if not derivatives:
        available = {k for k in available if base(k) not in DERIVATIVE_METRICS}
    if metrics:
        unknown = sorted(set(metrics) - available)
        if unknown:
            raise InputError(f"unknown metric(s) {unknown} for the {event.name} event; "
                             f"available: {', '.join(sorted(available))}.")
        return tuple(metrics)
    chosen = flagged("sensitivity")
    return tuple(k for k in sorted(available) if base(k) in chosen)


@eqx.filter_jit
def _metric_jacobian(rig, loads, params: Params, theta, derivatives: bool):
    def metrics(th):
        r = eqx.tree_at(lambda r_: r_.mech, rig, params.apply(rig.mech, th))
        if derivatives:
            return evaluate(r, loads)[1]
        sol = solve_statics(r.mech, loads, throw=False)
        m = jax.vmap(lambda l_, q, lam: raw_metrics(r, l_, q, lam))(loads, sol.q,
                                                                      sol.multipliers)
        return {k: v for k, v in m.items() if not k.rsplit("/", 1)[-1].startswith("_")}

    return metrics(theta), jax.jacfwd(metrics)(theta)


def sensitivity(event, params, *, loads: Loads | None = None,
                metrics: Sequence[str] | None = None, derivatives: bool = True,
                direction=None) -> SensitivityReport:
    """∂(every K&C metric)/∂(every parameter) over the cases of a K&C event.

    **Arguments:**
    - `event`: a `KCEvent` (`kc.parallel_travel(...)`, `kc.load_table(...)`: its rig and load
      cases are used), or a rig (`kc.travel_rig(mech)`, `kc.force_rig(mech)`) with `loads`.
    - `params`: a `Params` or a `where` selector on the rig's mechanism.
    - `loads`: the cases (leading axis); default: the event's.
    - `metrics`: keep only these names (default: all).
    - `derivatives`: include the derivative metrics (bump steer, compliance steer, wheel
      rate...: second derivatives of the equilibrium, exact, but a much longer compile);
      `False` differentiates the geometric metrics only.
    - `direction`: second order: a direction v `(p,)` of the parameters, or a parameter name
      for its unit vector; the report's `hvp` then holds ∇²m·v for every metric (with v on a
      bushing stiffness, how each metric's sensitivity to every parameter changes with that
      stiffness). Computed by `kc.hessian_vector_product` (gradients by reverse mode, their
      derivative along v by forward mode, the equilibria pinned), which also gives the
      Jacobian. Without `metrics`, the metrics of `sensitivity_metrics` (the registry's
      sensitivity set, not every metric: a third derivative of every metric is a very large
      program).

    **Returns:** a `SensitivityReport`.
    """
    rig = getattr(event, "rig", event)
    loads = getattr(event, "loads", None) if loads is None else loads
    if loads is None:
        raise InputError("sensitivity of a rig needs `loads` (or pass a KCEvent).")
    params = _as_params(rig.mech, params)
    theta = params.values(rig.mech)
    hvp = {}
    if direction is None:
        values, jac = _metric_jacobian(rig, loads, params, theta, derivatives)
    else:
        names = metrics
        if names is None and hasattr(event, "metrics"):  # a KCEvent: the registry's choice
            names = sensitivity_metrics(event, derivatives=derivatives)
        out = hessian_vector_product(rig, params, direction, loads=loads, metrics=names)
        values, jac, hvp, direction = out.values, out.gradient, out.hvp, out.direction
    values = {k: np.asarray(v) for k, v in values.items()}
    jac = {k: np.asarray(v) for k, v in jac.items()}
    if metrics is not None:
        unknown = set(metrics) - set(values)
        if unknown:
            raise InputError(f"unknown metrics {sorted(unknown)}; available: {sorted(values)}.")
        values = {k: values[k] for k in metrics}
        jac = {k: jac[k] for k in metrics}
    hvp = {k: np.asarray(v) for k, v in hvp.items() if k in jac}
    th = np.asarray(theta)
    unit = np.where(params.log_scaled, th, 1.0)
    elasticity = {}
    for k, j in jac.items():
        scale = np.nanmax(np.abs(values[k])) if np.any(np.isfinite(values[k])) else np.nan
        elasticity[k] = j * unit / scale if scale > 0 else np.full_like(j, np.nan)
    return SensitivityReport(params=params.names, theta=th, values=values, jacobian=jac,
                             elasticity=elasticity, event=getattr(event, "name", ""),
                             x_name=getattr(event, "x_name", ""),
                             x=np.asarray(getattr(event, "x", np.zeros(0))),
                             direction=direction, hvp=hvp)


# ----------------------------------------------------------------------------- experiment design


def landmark_model(mech: Mechanism) -> Callable:
    """The default measurement model: global positions of every marker on a moving part
    `(k·3,)` per case (mm) — what probing landmarks on the parts observes."""
    moving = np.flatnonzero(np.asarray(mech.markers.part) >= 0)

    def observe(m: Mechanism, q):
        pos, _ = marker_poses(m, q)
        return pos[moving].reshape(-1)

    return observe


@dataclasses.dataclass(frozen=True)
class DesignReport:
    """Greedy experiment design.

    - `chosen`: candidate indices in the order they were added (the `start` cases first).
    - `logdet`: log det of the information matrix (target block) with the cases up to each one
      of `chosen` (one row per case of the plan, the `start` cases included).
    - `sigma`: `(len(chosen), t)` standard deviations of the target parameters with the cases
      up to each one of `chosen`: relative (σ/θ, so ×100 is σ%) for positive parameters, in
      their unit otherwise; inf while a parameter is not yet determined.
    - `targets`: names of the target parameters; `relative`: which σ are relative.
    - `n_start`: how many of `chosen` were given (`start`), not chosen by the design.
    """

    chosen: tuple[int, ...]
    logdet: np.ndarray
    sigma: np.ndarray
    targets: tuple[str, ...]
    relative: np.ndarray
    n_start: int = 0

    def table(self) -> str:
        """One row per case of the plan: step (`*` for a given `start` case), candidate index,
        log det and the σ of each target (σ% for relative ones, `—` while undetermined); each
        column as wide as its target's full name."""
        widths = [max(12, len(t)) for t in self.targets]
        head = f"{'step':>5} {'case':>5} {'log det':>10} " + " ".join(
            f"{t:>{w}}" for t, w in zip(self.targets, widths, strict=True))
        lines = [head]
        for s, c in enumerate(self.chosen):
            cells = " ".join(
                (f"{f'{100 * v:.3g}%':>{w}}" if rel else f"{v:>{w}.3g}") if np.isfinite(v)
                else f"{'—':>{w}}"
                for v, rel, w in zip(self.sigma[s], self.relative, widths, strict=True))
            step = f"{s + 1}{'*' if s < self.n_start else ''}"
            lines.append(f"{step:>5} {c:>5} {self.logdet[s]:>10.4g} {cells}")
        if self.n_start:
            lines.append("* given (start), not chosen by the design")
        return "\n".join(lines)


@eqx.filter_jit
def _case_jacobians(mech, loads, params: Params, theta, observe):
    def predict(th):
        m = params.apply(mech, th)
        sol = solve_statics(m, loads, throw=False)
        return jax.vmap(lambda q: observe(m, q))(sol.q), sol.status

    jac, status = jax.jacfwd(predict, has_aux=True)(theta)
    return jac, status


def _sigmas(info, ridge):
    """Standard deviations from an information matrix; inf for a parameter with a component
    in its null space (not determined by the cases so far)."""
    evals, vecs = np.linalg.eigh(info)
    null = evals <= ridge * max(evals.max(), 1e-300)
    sigma = np.sqrt(np.maximum(np.diag(np.linalg.pinv(info, rcond=ridge, hermitian=True)), 0))
    undetermined = np.linalg.norm(vecs[:, null], axis=1) > 1e-6
    return np.where(undetermined, np.inf, sigma)


def design_experiment(
    mech: Mechanism,
    candidates: Loads,
    params,
    n: int,
    *,
    sigma: float = 0.05,
    observe: Callable | None = None,
    targets: Sequence[str] | None = None,
    criterion: str = "D",
    start: Sequence[int] = (),
) -> DesignReport:
    """Choose `n` load cases from `candidates` that best determine `params`.

    **Arguments:**
    - `candidates`: candidate load cases (leading axis).
    - `params`: a `Params` or `where` selector; `targets`: the names whose uncertainty counts
      (default: all); the others are nuisance parameters (their uncertainty still propagates).
    - `n`: how many cases to choose (including `start`, cases already in the plan).
    - `sigma`: measurement standard deviation per coordinate (mm; default 0.05 mm, the
      portable arm of spec geometry §3.3).
    - `observe(mech, q) -> (k,)`: what is measured per case (default `landmark_model(mech)`).
    - `start`: candidate indices already in the plan (counted in `n`; their rows come first in
      the report, marked `*` in its table).
    - `criterion`: "D" (maximise log det of the targets' information, Schur complement of the
      nuisances) or "sigma" (minimise the largest σ of the targets).

    **Returns:** a `DesignReport`.
    """
    if criterion not in ("D", "sigma"):
        raise InputError(f"criterion must be 'D' or 'sigma'; got '{criterion}'.")
    if candidates.n_cases is None or not 0 < n <= candidates.n_cases:
        raise InputError(f"n must be between 1 and the number of candidate cases; got {n}.")
    params = _as_params(mech, params)
    theta = params.values(mech)
    observe = observe or landmark_model(mech)
    jac, status = _case_jacobians(mech, candidates, params, theta, observe)
    jac, status = np.asarray(jac), np.asarray(status)
    scale = np.where(params.log_scaled, np.asarray(theta), 1.0)
    jac = jac * scale / sigma  # whitened, relative coordinates for positive parameters
    infos = np.einsum("cki,ckj->cij", jac, jac)
    names = params.names
    tgt = list(range(len(names))) if targets is None else [params.index(t) for t in targets]
    nuis = [j for j in range(len(names)) if j not in tgt]
    ridge = 1e-12

    def target_info(info):
        a = info[np.ix_(tgt, tgt)]
        if nuis:
            b, c = info[np.ix_(tgt, nuis)], info[np.ix_(nuis, nuis)]
            a = a - b @ np.linalg.pinv(c) @ b.T
        return a

    def score(info):
        """Larger is better (tuples compare lexicographically): the σ criterion counts the
        determined directions first, so the greedy search can start from nothing."""
        t = target_info(info)
        scale = max(np.trace(t) / len(tgt), 1e-300)
        logdet = np.linalg.slogdet(t + ridge * scale * np.eye(len(tgt)))[1]
        if criterion == "D":
            return (logdet,)
        rank = int(np.sum(np.linalg.eigvalsh(t) > 1e-9 * scale))
        if rank < len(tgt):
            return (rank, logdet)
        return (rank, -float(np.max(_sigmas(t, ridge))))

    chosen = [int(c) for c in start]
    if len(set(chosen)) != len(chosen) or any(not 0 <= c < len(infos) for c in chosen):
        raise InputError(f"start must be distinct candidate indices (0 to {len(infos) - 1}); "
                         f"got {list(start)}.")
    if len(chosen) > n:
        raise InputError(f"n ({n}) counts the start cases: it must be at least len(start) "
                         f"({len(chosen)}).")
    log, sig = [], []

    def record(total):
        t = target_info(total)
        sign, logdet = np.linalg.slogdet(t)
        log.append(logdet if sign > 0 else -np.inf)
        sig.append(_sigmas(t, ridge))

    total = np.zeros(infos.shape[1:])
    for c in chosen:  # the plan so far: one row each, as for the chosen cases
        total = total + infos[c]
        record(total)
    ok = status == Status.CONVERGED
    while len(chosen) < n:
        best, best_score = None, None
        for c in range(len(infos)):
            if c in chosen or not ok[c]:
                continue
            s = score(total + infos[c])
            if best is None or s > best_score:
                best, best_score = c, s
        if best is None:
            raise InputError("no converged candidate case is left to choose.")
        chosen.append(best)
        total = total + infos[best]
        record(total)
    relative = np.asarray(params.log_scaled)[tgt]
    return DesignReport(chosen=tuple(chosen), logdet=np.asarray(log),
                        sigma=np.asarray(sig).reshape(len(chosen), len(tgt)),
                        targets=tuple(names[j] for j in tgt), relative=relative,
                        n_start=len(start))


__all__ = ["PARAMETER_SETS", "DesignReport", "SensitivityReport", "design_experiment",
           "landmark_model", "parameter_set", "sensitivity"]
