"""Iterative (correlation) stiffness identification: the thesis's Chapter 5 loop on our solver.

spec: stiffness §2 (§2.2 measured deformation, §2.4 per-direction regression and Pearson gate,
eq. 5.13 x/y equalisation, §2.5 relative-change stop, §7 R5).

Each iteration is one batched static solve of every load case with the current stiffnesses
(warm-started from the previous iteration's equilibria). Then, per selected bushing and per
direction, the model's restoring force (−F_I in J axes, Adams convention) is regressed with an
intercept on the *measured* deformation of that direction across the cases:

    K = cov(δ, F) / var(δ),  E0 = mean(δ) − mean(F) / K,  r = cov(δ, F) / sqrt(var δ · var F)

and K is accepted only when r > `r_min` (a positive slope); otherwise the previous value is
kept and the direction is reported as not identified. For axisymmetric bushings the x and y
slopes are merged by the force-amplitude weights of eq. 5.13 [R] (w = Σ(F − mean F)², the square
restored). The loop stops when every selected stiffness changed by less than `eps` relatively
(eq. 5.14). At a fixed point the model's deformations equal the measured ones up to the
offsets E0 (eq. 5.17); the stiffnesses themselves need not be unique (§2.7).
"""

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..errors import InputError
from ..geometry import DEG
from ..measure.data import Deformations, Measurement, as_deformations
from ..measure.measurements import Measurements
from ..measure.noise import ARM_SIGMA
from ..model.mechanism import Loads, Mechanism
from ..statics import Status, bushing_states, solve_statics
from ._least_squares import least_squares, whitened_residuals
from .params import AXES, Params, selected_entries
from .report import (
    AT_START,
    MAX_SIGMA_PCT,
    Consistency,
    IdentificationReport,
    MeasurementResiduals,
    check_consistency,
    check_data,
    chi2_quantile,
    sigma_pct,
    sigma_pct_at_start,
)


@dataclasses.dataclass(frozen=True)
class IterationRecord:
    """One pass of the loop: stiffnesses *after* the update (N/mm, N·mm/rad) `(n, 6)`,
    correlation r `(n, 6)`, accepted (gate passed) `(n, 6)`, largest relative change, and the
    number of load cases that did not converge."""

    stiffness: np.ndarray
    r: np.ndarray
    accepted: np.ndarray
    max_change: float
    failed_cases: int


@dataclasses.dataclass(frozen=True)
class IterativeReport(IdentificationReport):
    """Result of `identify.iterative`.

    - `bushings`: names of the identified bushings; `stiffness` `(n, 6)` final values
      (Ktx, Kty, Ktz in N/mm; Krx, Kry, Krz in N·mm/rad); `start` the initial values.
    - `identified` `(n, 6)`: the direction's regression passed the gate at least once (a value
      that never did is the start value, kept); `equalised` `(n, 6)`: set from the other radial
      direction by axisymmetry (eq. 5.13) rather than by its own regression.
    - `r` `(n, 6)`: correlation coefficients of the last iteration; `offset` `(n, 6)`: the
      intercepts E0 (mm, rad) of the last iteration.
    - `residual` `(cases, n, 6)`: model deformation − (measured − E0) at the final equilibria.
    - `iterations`, `converged`, `history` (one `IterationRecord` per iteration).
    - `slope_sigma` `(n, 6)`: the standard error of the last regression's slope (N/mm,
      N·mm/rad; the textbook √(Σe²/(c − 2) / Σ(δ − δ̄)²) over the c converged cases);
      `selected` `(n, 6)`: the directions the selection asked for (the others keep their start
      value); `weight` `(cases, n, 6)`: 1/σ of the measured deformations (1 when given as
      plain arrays), which whitens `residual` in `residuals`.
    """

    bushings: tuple[str, ...]
    stiffness: np.ndarray
    start: np.ndarray
    identified: np.ndarray
    equalised: np.ndarray
    r: np.ndarray
    offset: np.ndarray
    residual: np.ndarray
    iterations: int
    converged: bool
    history: tuple[IterationRecord, ...]
    slope_sigma: np.ndarray | None = None
    selected: np.ndarray | None = None
    weight: np.ndarray | None = None
    consistency: Consistency | None = None
    polished: object = None
    sigma_data: np.ndarray | None = None
    notes: tuple[str, ...] = ()
    gate_sigma_pct: np.ndarray | None = None
    max_sigma_pct: float = MAX_SIGMA_PCT
    _mech: Mechanism | None = dataclasses.field(default=None, repr=False, compare=False)
    _data: tuple | None = dataclasses.field(default=None, repr=False, compare=False)

    family: ClassVar[str] = "iterative"

    def polish(self, **options) -> tuple[Mechanism, "object"]:
        """Least squares through the equilibrium (`identify.least_squares`) from this loop's
        stiffnesses, on the same measurements (landmarks or poses when the loop was given
        them, else the deformations), over the selected directions: what to do when the
        consistency verdict says the loop's fixed point does not reproduce the data (spec
        stiffness §2.7: the loop's fixed point need not be the truth). `options` go to
        `least_squares`. **Returns:** `(mech', FitReport)`."""
        if self._mech is None or self._data is None:
            raise InputError("this report does not carry its model and data; call "
                             "identify.iterative(..., polish=True) instead.")
        sel = self._selected
        index = np.array([self._mech.bushings.index(n) for n in self.bushings], dtype=int)
        kt = np.zeros((len(self._mech.bushings.names), 3), bool)
        kr = np.zeros_like(kt)
        kt[index], kr[index] = sel[:, :3], sel[:, 3:]
        params = Params.leaves(self._mech, lambda m: (m.bushings.k_trans, m.bushings.k_rot),
                               (kt, kr))
        return least_squares(self._mech, self._data, params, **options)

    # The base API (identify.report): one parameter per selected direction, model units.
    @property
    def _selected(self) -> np.ndarray:
        return np.ones(self.stiffness.shape, bool) if self.selected is None else self.selected

    @property
    def names(self) -> tuple[str, ...]:
        sel = self._selected
        return tuple(f"{b}.{a}" for i, b in enumerate(self.bushings)
                     for j, a in enumerate(AXES) if sel[i, j])

    @property
    def estimates(self) -> np.ndarray:
        return self.stiffness[self._selected]

    @property
    def sigmas(self) -> np.ndarray:
        """The σ the measurements give each selected stiffness at the loop's values (the
        linearised σ of a least-squares fit of the same data, `sigma_data`), when checked;
        else the regression slope's standard error (which ignores how the deformations were
        measured: it is 0 on noise-free data, however little they determine the value)."""
        if self.sigma_data is not None:
            return self.sigma_data
        if self.slope_sigma is None:
            return np.full(len(self.names), np.nan)
        return self.slope_sigma[self._selected]

    @property
    def determined(self) -> np.ndarray:
        """The correlation gate passed and, when checked, σ% ≤ `max_sigma_pct` judged at the
        start values (`gate_sigma_pct`: the measurements' information at the start model, the
        one rule of the suspension methods, `report.sigma_pct_at_start`; the σ of the loop's
        values depends on θ, and a bar at the estimate selects the draws by their noise).
        A report built by hand without `gate_sigma_pct` judges `sigma_pct`, at the estimate."""
        ok = np.asarray(self.identifiable, bool)
        if self.sigma_data is None and self.gate_sigma_pct is None:
            return ok
        return ok & self.within_bar()

    @property
    def judged_at(self) -> str:
        return "the estimate" if self.gate_sigma_pct is None else AT_START

    @property
    def sigma_pct(self) -> np.ndarray:
        return sigma_pct(self.sigmas, self.estimates)

    @property
    def reasons(self) -> tuple[str, ...]:
        """Why a selected direction is not determined: the correlation gate never passed (its
        start value kept), or σ % above the bar."""
        gate, det, pct = self.identifiable, self.determined, self.judged_sigma_pct
        return tuple("" if det[k] else
                     "the regression never passed the correlation gate: start value kept"
                     if not gate[k] else
                     f"σ% {pct[k]:.3g} > {self.max_sigma_pct:g} at {self.judged_at}"
                     for k in range(len(self.names)))

    @property
    def stop_reason(self) -> str:
        last = self.history[-1].max_change if self.history else float("nan")
        return (f"converged after {self.iterations} iterations (max |Δk/k| {last:.3g})"
                if self.converged else
                f"NOT converged after {self.iterations} iterations (max |Δk/k| {last:.3g})")

    @property
    def estimate_units(self) -> tuple[str, ...]:
        sel = self._selected
        return tuple("N/mm" if j < 3 else "N·mm/rad" for i in range(len(self.bushings))
                     for j in range(6) if sel[i, j])

    @property
    def identifiable(self) -> np.ndarray:
        """Directions whose regression passed the gate (`identified`)."""
        return self.identified[self._selected]

    @property
    def combinations(self) -> list[str]:
        return []  # the correlation method identifies direction by direction

    @property
    def residuals(self) -> dict:
        """`{'deformations': MeasurementResiduals}`: model − (measured − E0) where the
        direction was identified, model − measured elsewhere (its E0 means nothing)."""
        raw = np.where(self.identified, self.residual, self.residual - self.offset)
        weight = np.ones_like(raw) if self.weight is None else self.weight
        return {"deformations": MeasurementResiduals(raw, raw * weight)}

    def table(self) -> str:
        """The stiffnesses as the thesis prints them (N/mm and N·mm/deg), `*` = not identified
        (start value kept), `=` = equalised by axisymmetry."""
        head = f"{'bushing':<14}" + "".join(f"{a:>12}" for a in AXES)
        lines = [head, "-" * len(head)]
        scale = np.array([1, 1, 1, DEG, DEG, DEG])
        for b, name in enumerate(self.bushings):
            cells = []
            for a in range(6):
                mark = "=" if self.equalised[b, a] else (" " if self.identified[b, a] else "*")
                cells.append(f"{self.stiffness[b, a] * scale[a]:>11.6g}{mark}")
            lines.append(f"{name:<14}" + "".join(cells))
        state = "converged" if self.converged else "NOT converged"
        lines.append(f"{state} after {self.iterations} iterations; * not identified (start value "
                     "kept), = equalised with the other radial direction (axisymmetric).")
        if self.consistency is not None:
            lines.append(f"model vs data: {self.consistency.verdict}")
            if self.polished is not None:
                lines.append("polished by least squares through the equilibrium: "
                             "report.polished (its own model vs data verdict).")
            elif not self.consistency.consistent:
                lines.append("the loop's fixed point need not be the truth (spec stiffness "
                             "§2.7): polish it by least squares through the equilibrium "
                             "(report.polish(), iterative(..., polish=True), or "
                             "`diffsusp identify iterative --polish`).")
        return "\n".join(lines)

    def csv_rows(self) -> list[dict]:
        """The .csv rows (`write`), one per identified direction (`names`): parameter, value,
        unit, start (the thesis's units: rotational per degree), status and reason (the
        report's one verdict: `statuses`), identified (status is 'identified'), gate_passed
        (the correlation gate passed at least once), equalised, r."""
        rows = []
        sel = self._selected
        statuses, reasons, ident = self.statuses, self.status_reasons, self.is_identified
        k = 0
        for b, name in enumerate(self.bushings):
            for a, axis in enumerate(AXES):
                if not sel[b, a]:
                    continue
                scale, unit = (DEG, "N*mm/deg") if a >= 3 else (1.0, "N/mm")
                rows.append(dict(
                    parameter=f"{name}.{axis}", value=float(self.stiffness[b, a] * scale),
                    unit=unit, start=float(self.start[b, a] * scale), status=statuses[k],
                    reason=reasons[k], identified=bool(ident[k]),
                    gate_passed=bool(self.identified[b, a]),
                    equalised=bool(self.equalised[b, a]), r=float(self.r[b, a])))
                k += 1
        return rows

    def json_data(self) -> dict:
        """The .json content (`write`): `to_dict()`."""
        return self.to_dict()

    def to_dict(self) -> dict:
        return {
            "bushings": list(self.bushings), "axes": list(AXES),
            "stiffness": self.stiffness.tolist(), "units": ["N/mm"] * 3 + ["N*mm/rad"] * 3,
            "gate_passed": self.identified.tolist(), "equalised": self.equalised.tolist(),
            "r": self.r.tolist(), "offset": self.offset.tolist(),
            "iterations": self.iterations, "converged": self.converged,
            "consistency": None if self.consistency is None else self.consistency.summary(),
            "fit_verdict": self.fit_verdict, "stop_reason": self.stop_reason,
            "judged_at": self.judged_at, "notes": list(self.notes),
            "parameters": self.rows(),
        }


@jax.jit
def _regress(delta: Float[Array, "c n 6"], force: Float[Array, "c n 6"]):
    """Per (bushing, direction) slope, intercept offset and Pearson r of force on deformation
    (spec stiffness eq. 5.10–5.12)."""
    d = delta - delta.mean(axis=0)
    f = force - force.mean(axis=0)
    cov, var_d, var_f = (d * f).mean(axis=0), (d * d).mean(axis=0), (f * f).mean(axis=0)
    tiny = jnp.finfo(delta.dtype).tiny
    slope = cov / jnp.maximum(var_d, tiny)
    r = cov / jnp.sqrt(jnp.maximum(var_d * var_f, tiny))
    offset = delta.mean(axis=0) - force.mean(axis=0) / jnp.where(slope != 0, slope, 1.0)
    weight = (f * f).sum(axis=0)  # eq. 5.13 weights: force amplitude per direction
    return slope, offset, r, weight


def _equalise(k_new, accepted, weight, axisymmetric):
    """Eq. 5.13 on (x, y) translations and rotations of the axisymmetric bushings, using the
    directions that passed the gate; returns the values and which entries were set by it."""
    k_new, equalised = k_new.copy(), np.zeros_like(accepted)
    for b in np.flatnonzero(axisymmetric):
        for x, y in ((0, 1), (3, 4)):
            ok = accepted[b, [x, y]]
            if not ok.any():
                continue
            w = weight[b, [x, y]] * ok
            merged = float(np.dot(w, k_new[b, [x, y]]) / w.sum()) if w.sum() > 0 else float(
                k_new[b, [x, y]][ok].mean())
            for a, own in ((x, ok[0]), (y, ok[1])):
                k_new[b, a] = merged
                equalised[b, a] = not own
    return k_new, equalised


def _measured_array(measured, names: Sequence[str], n_cases: int) -> np.ndarray:
    if isinstance(measured, Mapping):
        missing = [n for n in names if n not in measured]
        if missing:
            raise InputError(f"measured deformations are missing bushing(s) {missing}; give a "
                             "(cases, 6) array for each identified bushing.")
        arr = np.stack([np.asarray(measured[n], dtype=float) for n in names], axis=1)
    else:
        arr = np.asarray(measured, dtype=float)
    if arr.shape != (n_cases, len(names), 6):
        raise InputError(f"measured deformations must have shape (cases, bushings, 6) = "
                         f"({n_cases}, {len(names)}, 6) (Tx, Ty, Tz mm; AX, AY, AZ rad, in J); "
                         f"got {arr.shape}.")
    if not np.all(np.isfinite(arr)):
        c, b, a = np.argwhere(~np.isfinite(arr))[0]
        raise InputError(f"measured deformation of '{names[b]}' direction {AXES[a]} in load case "
                         f"{c} is not finite; remove the case or mask it before identifying.")
    return arr


def _with_stiffness(mech: Mechanism, index: np.ndarray, k: np.ndarray) -> Mechanism:
    kt, kr = np.array(mech.bushings.k_trans), np.array(mech.bushings.k_rot)
    kt[index], kr[index] = k[:, :3], k[:, 3:]
    return eqx.tree_at(lambda m: (m.bushings.k_trans, m.bushings.k_rot), mech,
                       (jnp.asarray(kt), jnp.asarray(kr)))


@eqx.filter_jit
def _states(mech: Mechanism, q, index: tuple[int, ...]):
    """Deformation (δ_T, angles) and restoring force and torque (−F_I, −T_I) of the selected
    bushings, `(cases, n, 6)` each."""
    d_t, ang, f, t = bushing_states(mech, q)
    sel = np.asarray(index)
    return (jnp.concatenate([d_t, ang], axis=-1)[:, sel],
            -jnp.concatenate([f, t], axis=-1)[:, sel])


def iterative(
    mech: Mechanism,
    data: Measurement | Measurements | Loads,
    params: Params | Callable[[Mechanism], object] | Sequence[str] | None = None,
    *,
    measured=None,
    axisymmetric: Sequence[str] = (),
    r_min: float = 0.75,
    resolution: tuple[float, float] | None = None,
    eps: float = 0.01,
    max_iterations: int = 100,
    callback: Callable[[int, IterationRecord], None] | None = None,
    check: bool = True,
    polish: bool = False,
    sigma: tuple[float, float] | None = None,
    max_sigma_pct: float = MAX_SIGMA_PCT,
) -> tuple[Mechanism, IterativeReport]:
    """Identify bushing stiffnesses by the correlation loop of spec stiffness §2.

    **Arguments:**
    - `mech`: the model with the start stiffnesses (the thesis starts every direction at
      10⁴ N/mm and 10⁴ N·mm/deg) and the known geometry, springs and other bushings.
    - `data`: the measurements every identification method takes: a `Deformations`, or
      measured part poses (`measure.Measurements`, `Poses`) from which the bushings'
      deformations are computed (`measure.as_deformations`); their load table is the rig's.
      Or the thesis's form: `data` the `Loads` (leading case axis) and `measured=` the
      deformations `(cases, n, 6)` in the order of the bushings `params` names, or a mapping
      name → `(cases, 6)`: Tx, Ty, Tz (mm) and projected angles AX, AY, AZ (rad) of I relative
      to J, in J.
    - `params`: the selection every identification method takes (a `Params` or a `where`
      function) among the bushings' `k_trans` and `k_rot` entries: the bushings with a selected
      entry are identified, and only the selected directions are updated; or a sequence of
      names: bushings (every direction) or directions ('bushing_A.Ktz'). Default: every
      direction of all of the model's bushings.
    - `measured`: with `data` a `Loads` only: the measured deformations (see `data`).
    - `axisymmetric`: names whose x and y stiffnesses are merged (eq. 5.13).
    - `r_min`: correlation gate (spec: 0.75); `eps`: relative-change stop (spec: 0.01).
    - `resolution`: (mm, rad) — a direction whose measured deformation varies less than this
      over the cases (standard deviation) is not identified: the measurement does not resolve it
      (spec §2.8, §2.10: "bushings whose deformation is below the measurement capability cannot
      be identified"). Default: no such gate (exact synthetic data correlate at any amplitude).
    - `max_iterations`: bound on the loop; `callback(i, record)` is called after each pass.
    - `check`: re-solve the identified model at the measured cases and compare with
      the measurements in units of their noise (`report.consistency`: landmarks or poses when
      given them, else the deformations). The loop's fixed point matches the deformations only
      up to the offsets E0 and need not be the truth (spec stiffness §2.7): when the model does
      not reproduce the data, the report says so with its χ², and no direction counts as
      identified (`is_identified`, `rows()`), whatever the correlation gate said.
    - `polish`: then polish the loop's result by least squares through the equilibrium
      (`report.polish()`); the returned mechanism is the polished one and `report.polished`
      its `FitReport` (the loop's own values stay in `report.stiffness`).
    - `sigma`: (mm, rad) noise of deformations given as plain arrays, for the check (default
      the measuring arm's 0.05 mm and 0.05 mm over the model's length scale).
    - `max_sigma_pct`: with `check`, a direction whose σ % at the start values (the
      measurements' information at `mech`, `report.sigma_pct_at_start`: the rule of `direct`
      and `least_squares` too) exceeds this is not determined, and keeps its start value.

    **Returns:** the identified mechanism and an `IterativeReport`.
    """
    names, selected = _selection(mech, params)
    if isinstance(data, Loads):  # the thesis's form (mech, loads, names, measured=)
        if measured is None:
            raise InputError("iterative(mech, loads, ...) needs the measured deformations "
                             "(measured=); or give measurements as data.")
        loads = data
    elif measured is not None:
        raise InputError("measured= goes with a Loads as data; these data carry their own "
                         "measurements.")
    index = np.array([mech.bushings.index(n) for n in names], dtype=int)
    unknown = set(axisymmetric) - set(names)
    if unknown:
        raise InputError(f"axisymmetric names {sorted(unknown)} are not among the identified "
                         f"bushings {list(names)}.")
    if measured is None:
        defo = as_deformations(mech, data, names)
        loads, delta = defo.loads, np.asarray(defo.measured)
        weight = np.asarray(defo.weight)
    if loads.n_cases is None or loads.n_cases < 3:
        raise InputError("iterative identification needs a table of at least 3 load cases "
                         "(a regression over cases per direction).")
    if measured is not None:
        delta = _measured_array(measured, names, loads.n_cases)
        weight = None
    chosen = np.ones((len(names), 6), bool) if selected is None else selected
    k = np.concatenate([np.asarray(mech.bushings.k_trans)[index],
                        np.asarray(mech.bushings.k_rot)[index]], axis=1)
    # A direction that is 0 in the model is free (e.g. a Chrono bushing's torsion): it carries
    # no force, so the regression of force on deformation has nothing to correlate and the
    # loop can neither move nor judge it. It is left out of the selection, with a note.
    free = chosen & ~(k != 0)
    if free.all():
        raise InputError("nothing to identify: every selected stiffness is 0 in the model "
                         "(free directions); give start values (e.g. --start) or another "
                         "selection.")
    free_note = ("left out " + ", ".join(f"{names[i]}.{AXES[j]}" for i, j in np.argwhere(free))
                 + ": 0 in the model (a free direction carries no force; the correlation "
                 "loop cannot identify it)") if free.any() else ""
    chosen = chosen & ~free
    keep = chosen.any(axis=1)
    if not keep.all():
        names, index, chosen, k = (tuple(n for n, ok in zip(names, keep, strict=True) if ok),
                                   index[keep], chosen[keep], k[keep])
        delta = delta[:, keep]
        weight = None if weight is None else weight[:, keep]
    axi = np.array([n in axisymmetric for n in names])
    resolved = np.ones((len(names), 6), bool)
    if resolution is not None:
        floor = np.repeat(np.asarray(resolution, dtype=float), 3)
        resolved = delta.std(axis=0) > floor

    start = k.copy()
    ever = np.zeros(k.shape, bool)
    history, q, converged = [], None, False
    for it in range(1, max_iterations + 1):
        current = _with_stiffness(mech, index, k)
        sol = solve_statics(current, loads, q0=q, throw=False)
        status = np.asarray(sol.status)
        if np.all(status != Status.CONVERGED):
            raise InputError(f"iteration {it}: no load case converged with the stiffnesses "
                             f"{k.tolist()}; start from values closer to the expected ones.")
        q = jnp.where((status == Status.CONVERGED)[:, None], sol.q, sol.q if q is None else q)
        _, force = _states(current, q, tuple(int(i) for i in index))
        ok = status == Status.CONVERGED
        slope, offset, r, weight = (np.asarray(a) for a in _regress(jnp.asarray(delta[ok]),
                                                                    force[ok]))
        accepted = (r > r_min) & resolved & chosen
        k_new = np.where(accepted, slope, k)
        slope_sigma = _slope_sigma(delta[ok], np.asarray(force)[ok], slope)
        k_new, equalised = _equalise(k_new, accepted, weight, axi)
        change = _relative_change(k_new, k, chosen)
        ever |= accepted
        record = IterationRecord(k_new, r, accepted, change, int((~ok).sum()))
        history.append(record)
        if callback is not None:
            callback(it, record)
        k = k_new
        if change < eps:
            converged = True
            break

    final = _with_stiffness(mech, index, k)
    sol = solve_statics(final, loads, q0=q, throw=False)
    model = np.asarray(_states(final, sol.q, tuple(int(i) for i in index))[0])
    consistency, check_items, sigma_data, gate_pct = None, None, None, None
    if check or polish:
        if isinstance(data, Loads):
            s_t, s_r = sigma if sigma is not None else (ARM_SIGMA,
                                                       ARM_SIGMA / mech.length_scale)
            check_items = (Deformations(loads, names, delta, (s_t,) * 3 + (s_r,) * 3),)
        else:
            check_items = check_data(mech, data)
        consistency = check_consistency(final, check_items, int(np.sum(ever & chosen)))
        sigma_data, consistency = _least_squares_gap(final, names, chosen, check_items,
                                                      consistency)
        gate_pct = _start_gate(mech, names, chosen, check_items, start)
    report = IterativeReport(
        bushings=names, stiffness=k, start=start, identified=ever, equalised=equalised,
        r=r, offset=offset, residual=model - (delta - offset), iterations=len(history),
        converged=converged, history=tuple(history), slope_sigma=slope_sigma,
        selected=chosen, weight=weight, consistency=consistency, _mech=final,
        notes=(free_note,) if free_note else (),
        _data=check_items, sigma_data=sigma_data if check or polish else None,
        gate_sigma_pct=gate_pct, max_sigma_pct=float(max_sigma_pct),
    )
    # The returned model carries the values the report determines; a direction the data do
    # not determine (gate never passed, or σ% above the bar) keeps the model's start value.
    kept = np.zeros(k.shape, bool)
    kept[chosen] = report.determined
    written = np.where(kept | ~chosen, k, start)
    if not np.array_equal(written, k):
        final = _with_stiffness(mech, index, written)
        if check_items is not None:
            consistency = check_consistency(final, check_items, int(np.sum(kept)))
            _, consistency = _least_squares_gap(final, names, chosen, check_items,
                                                 consistency)
        report = dataclasses.replace(report, _mech=final, consistency=consistency)
    if polish:
        polished_mech, fit = report.polish()
        return polished_mech, dataclasses.replace(report, polished=fit)
    return final, report


def _relative_change(new: np.ndarray, old: np.ndarray, chosen: np.ndarray) -> float:
    """max |Δk|/|k| over the selected directions (spec stiffness §2.5's stop test), finite
    whatever the values: a direction with k = 0 compares with its new value, and one that is 0
    before and after has not changed."""
    scale = np.maximum(np.abs(old), np.abs(new))
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(scale > 0, np.abs(new - old) / scale, 0.0)
    rel = np.where(chosen & np.isfinite(rel), rel, np.where(chosen, np.inf, 0.0))
    return float(rel.max()) if rel.size else 0.0


def _selected_params(mech, names, chosen):
    """The selected directions as `Params` of `mech` (its values the start) and their order
    as the report names them: bushing by bushing, axis by axis."""
    index = np.array([mech.bushings.index(n) for n in names], dtype=int)
    kt = np.zeros((len(mech.bushings.names), 3), bool)
    kr = np.zeros_like(kt)
    kt[index], kr[index] = chosen[:, :3], chosen[:, 3:]
    params = Params.leaves(mech, lambda m: (m.bushings.k_trans, m.bushings.k_rot), (kt, kr))
    order = [params.names.index(f"{n}.{a}") for i, n in enumerate(names)
             for j, a in enumerate(AXES) if chosen[i, j]]
    return params, order


def _start_gate(mech, names, chosen, items, start) -> np.ndarray:
    """σ % of the selected stiffnesses judged at the start values (`report.sigma_pct_at_start`):
    the measurements' information (whitened Jacobian through the equilibrium) at the start
    model `mech`, the same for every noise draw, as `least_squares` judges. inf where the
    data carry no information, or where the start model has no equilibrium in a case."""
    params, order = _selected_params(mech, names, chosen)
    try:
        _, jac = whitened_residuals(mech, items, params, params.start)
    except InputError:  # the start model has no equilibrium in a measured case
        return np.full(len(order), np.inf)
    jac = np.asarray(jac, float)[:, order]
    _, s, vt = np.linalg.svd(jac, full_matrices=False)
    keep = s > s[0] * 1e-12 if s.size and s[0] > 0 else np.zeros(s.size, bool)
    inv = np.where(keep, 1.0 / np.where(keep, s, 1.0) ** 2, 0.0)
    sigma = np.sqrt((vt.T ** 2) @ inv)
    sigma[((vt.T ** 2) @ (~keep).astype(float)) > 1e-12] = np.inf
    return sigma_pct_at_start(sigma, np.asarray(start)[chosen])


def _least_squares_gap(final, names, chosen, items, consistency):
    """σ of the selected stiffnesses from the measurements (whitened Jacobian through the
    equilibrium at the loop's values, widened by the loop's distance from the least-squares
    estimate) and Δχ² = ‖QᵀR‖²: how much a least-squares fit of the
    same data would still lower χ² from here. The loop does not minimise χ², so a value within
    the noise's χ² band can still be far from what the data say; Δχ² above the χ² quantile of
    p dof marks it inconsistent (see `report.Consistency.gap`)."""
    params, order = _selected_params(final, names, chosen)
    if consistency.failed_cases:
        return np.full(len(order), np.inf), consistency
    z, jac = (np.asarray(a, float) for a in whitened_residuals(final, items, params,
                                                               params.start))
    jac = jac[:, order]
    u, s, vt = np.linalg.svd(jac, full_matrices=False)
    keep = s > s[0] * 1e-12 if s.size and s[0] > 0 else np.zeros(s.size, bool)
    gap = float(np.sum((u[:, keep].T @ z) ** 2))
    inv = np.where(keep, 1.0 / np.where(keep, s, 1.0) ** 2, 0.0)
    sigma = np.sqrt((vt.T ** 2) @ inv)
    # The loop's values are not the least-squares estimate: they lie a Gauss–Newton step
    # Δ = −J⁺z from it, and the truth lies within σ of that estimate. The gap test admits Δ up
    # to the χ² quantile of p dof (≈ 4σ along one direction for p = 6), so σ alone would call
    # values identified that are several σ off; the reported σ is √(σ² + Δ²).
    step = vt.T @ (np.where(keep, 1.0 / np.where(keep, s, 1.0), 0.0) * (u.T @ z))
    sigma = np.hypot(sigma, step)
    sigma[((vt.T ** 2) @ (~keep).astype(float)) > 1e-12] = np.inf
    critical = chi2_quantile(len(order), consistency.alpha)
    consistency = dataclasses.replace(
        consistency, gap=gap, gap_critical=critical,
        consistent=bool(consistency.consistent and gap <= critical))
    return sigma, consistency


def _slope_sigma(delta: np.ndarray, force: np.ndarray, slope: np.ndarray) -> np.ndarray:
    """Standard error of the regression slope per (bushing, direction), `(n, 6)`."""
    c = delta.shape[0]
    d = delta - delta.mean(axis=0)
    f = force - force.mean(axis=0)
    sxx = (d * d).sum(axis=0)
    e = f - slope * d
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.sqrt((e * e).sum(axis=0) / max(c - 2, 1) / sxx)


def _selection(mech: Mechanism, params) -> tuple[tuple[str, ...], np.ndarray | None]:
    """(bushing names, selected directions `(n, 6)`; None: every direction) of the one
    selector: a `Params` or a `where` function, or a sequence of bushing or direction names
    ('bushing_A', 'bushing_A.Ktz'); None: every bushing of the model."""
    if params is None:
        return tuple(mech.bushings.names), None
    sel = np.zeros((len(mech.bushings.names), 6), bool)
    if isinstance(params, str) or (not isinstance(params, Params) and not callable(params)):
        wanted = (params,) if isinstance(params, str) else tuple(params)
        if not all(isinstance(n, str) for n in wanted):
            raise InputError("params must be a Params, a `where` function or a sequence of "
                             "bushing names.")
        if all("." not in n for n in wanted):  # bushings: every direction, in the given order
            return wanted, None
        for n in wanted:
            bushing, _, axis = n.rpartition(".") if "." in n else (n, "", "")
            if axis and axis not in AXES:
                raise InputError(f"'{n}': the iterative method identifies the directions "
                                 f"{', '.join(AXES)} of a bushing.")
            sel[mech.bushings.index(bushing), [AXES.index(axis)] if axis else slice(None)] = True
    else:
        for path, idx in selected_entries(mech, params).items():
            if path not in (("bushings", "k_trans"), ("bushings", "k_rot")):
                raise InputError(f"the iterative method identifies bushing stiffnesses "
                                 f"(m.bushings.k_trans, m.bushings.k_rot); the selection has "
                                 f"m.{'.'.join(path)}. Use least_squares for other parameters.")
            offset = 0 if path[-1] == "k_trans" else 3
            sel[idx // 3, offset + idx % 3] = True
    rows = np.flatnonzero(sel.any(axis=1))
    if not rows.size:
        raise InputError("nothing to identify: the selection picks no bushing stiffness.")
    return tuple(mech.bushings.names[i] for i in rows), sel[rows]
