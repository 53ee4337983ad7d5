"""The report API every identification method shares (DESIGN.md "Identification": the same
base API for `direct`, `iterative` and `least_squares`, so a user who learnt one knows the
others).

Each report keeps its own fields (e.g. `DirectReport.values` in the thesis's table units, the
`FitReport` history) and also answers, in the model's units (N/mm, N·mm/rad, N, N·mm, mm):

- `names`: the parameters, e.g. `'bushing_A.Ktx'`;
- `estimates`, `sigmas` (1σ; NaN when the method gives none, inf when the data carry no
  information), `sigma_pct` (100·σ/|estimate|), `estimate_units`;
- `identifiable`: the data determine the parameter on its own;
- `combinations`: texts of the combinations of several parameters the method names (direct:
  the combinations the data determine; least squares: the directions the data cannot see);
- `residuals`: measurement name → `MeasurementResiduals` (raw, whitened);
- `consistency`: a `Consistency` — the identified model re-solved at the measured load cases
  and compared with the measurements in units of their noise (χ², χ²/dof, per-case RMS, a
  verdict);

and, from those, `is_identified` (a parameter is *identified* only when the data determine it
AND the identified model reproduces the data), `verdicts`, `rows()`, `to_frame()`,
`to_json()` and `plot()`.

**Why a consistency verdict.** A determined parameter (small σ, full rank) of a model that does
not reproduce the measurements is not a result: the iterative correlation loop can stop at a
fixed point that is not the truth (spec stiffness §2.7: its fixed point only matches the
deformations up to the offsets E0), and a linear estimate built from noisy poses can be biased.
The check does not trust the method's own equations: it solves the equilibrium of the identified
model at every measured load case (`solve_statics`) and evaluates the measurement models
(landmarks, poses, deformations) against the data, whitened by their σ. With Gaussian noise of
the stated σ and a correct model, χ² follows a χ² law with `dof` = residuals − determined
parameters; the model is declared inconsistent when χ² exceeds that law's upper
`CONSISTENCY_ALPHA` quantile (Wilson–Hilferty approximation, no scipy), or when a case has no
equilibrium.
"""

import csv
import dataclasses
import html
import io
import json
import math
import pathlib
import textwrap
import warnings
from collections.abc import Sequence
from typing import ClassVar

import equinox as eqx
import numpy as np

from ..errors import InputError
from ..io.files import write_text_atomic
from ..measure.data import as_fit_data, from_measurements
from ..measure.measurements import Measurements
from ..statics import Status, solve_statics

CONSISTENCY_ALPHA = 1e-3
"""Significance of the consistency test: a correct model with the stated noise is called
inconsistent with this probability."""


@dataclasses.dataclass(frozen=True)
class MeasurementResiduals:
    """Residuals of one measurement at the estimate: `raw` model − measured (physical units,
    the measured shape; 0 where masked) and `whitened` (mask·raw/σ)."""

    raw: np.ndarray
    whitened: np.ndarray


def chi2_quantile(dof: int, alpha: float = CONSISTENCY_ALPHA) -> float:
    """Upper `alpha` quantile of the χ² law with `dof` degrees of freedom (Wilson–Hilferty:
    (χ²/k)^(1/3) is nearly normal with mean 1 − 2/(9k) and variance 2/(9k); within 1 % of the
    exact quantile for k ≥ 3 at α = 1e-3)."""
    k = max(int(dof), 1)
    z = _normal_quantile(1.0 - alpha)
    c = 2.0 / (9.0 * k)
    return k * (1.0 - c + z * math.sqrt(c)) ** 3


def _normal_quantile(p: float) -> float:
    """Φ⁻¹(p) by bisection on erf (double precision, no scipy)."""
    lo, hi = -40.0, 40.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if 0.5 * (1.0 + math.erf(mid / math.sqrt(2.0))) < p:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@dataclasses.dataclass(frozen=True)
class Consistency:
    """Does the identified model reproduce the measurements? (see the module docstring)

    **Fields:** `chi2` Σ (mask·(model − measured)/σ)² over every measured entry at the
    identified model's own equilibria; `n_residuals` (unmasked entries), `n_parameters` (the
    determined parameters), `dof` = n_residuals − n_parameters (at least 1); `critical` the
    χ² above which the model is inconsistent (upper `alpha` quantile); `case_rms` `(cases,)`
    RMS whitened residual of each load case (in σ; inf where the case has no equilibrium);
    `cases` labels; `failed_cases` (no equilibrium); `consistent`; `measurements` the names of
    the measurements compared; `note` how the check was made.
    """

    chi2: float
    n_residuals: int
    n_parameters: int
    dof: int
    critical: float
    case_rms: np.ndarray
    cases: tuple[str, ...]
    failed_cases: tuple[str, ...]
    consistent: bool
    measurements: tuple[str, ...] = ()
    alpha: float = CONSISTENCY_ALPHA
    note: str = ""
    gap: float | None = None
    gap_critical: float | None = None
    """For an estimate that does not minimise χ² (the iterative loop): Δχ², how much a full
    Gauss–Newton step of the same data would still lower χ² (≈ χ² − its least-squares
    minimum), and the bound above which the estimate is not a least-squares one (upper
    `alpha` quantile of χ² with as many dof as parameters)."""

    @property
    def chi2_per_dof(self) -> float:
        return self.chi2 / self.dof

    @property
    def verdict(self) -> str:
        """One sentence: consistent or not, with χ²/dof and the worst case."""
        limit = self.critical / self.dof
        if self.failed_cases:
            return (f"INCONSISTENT: the identified model has no equilibrium in case(s) "
                    f"{', '.join(self.failed_cases)}")
        if self.gap is not None and not self.gap <= self.gap_critical:
            return (f"INCONSISTENT with the data: χ²/dof = {self.chi2_per_dof:.4g}, but the "
                    f"least-squares optimum of the same data is Δχ² = {self.gap:.4g} lower "
                    f"(> {self.gap_critical:.3g}): these values are not what the data say, so "
                    "none is reported as identified")
        worst = int(np.argmax(self.case_rms)) if self.case_rms.size else None
        where = (f"; worst case {self.cases[worst]}: RMS {self.case_rms[worst]:.3g}σ"
                 if worst is not None else "")
        if self.consistent:
            return (f"consistent with the data: χ²/dof = {self.chi2_per_dof:.3g} "
                    f"(≤ {limit:.3g}, {self.dof} dof){where}")
        return (f"INCONSISTENT with the data: χ²/dof = {self.chi2_per_dof:.4g} > {limit:.3g} "
                f"({self.dof} dof){where}; the identified model does not reproduce the "
                "measurements, so no value is reported as identified")

    def summary(self) -> dict:
        return {"chi2": _number(self.chi2), "dof": self.dof,
                "chi2_per_dof": _number(self.chi2_per_dof),
                "critical_chi2": _number(self.critical), "alpha": self.alpha,
                "consistent": bool(self.consistent),
                "case_rms": {c: _number(r) for c, r in zip(self.cases, self.case_rms,
                                                           strict=True)},
                "failed_cases": list(self.failed_cases), "gap_chi2": None if self.gap is None
                else _number(self.gap), "verdict": self.verdict}


def consistency_from_residuals(whitened: Sequence[np.ndarray], counts: Sequence[int],
                               n_parameters: int, cases: Sequence[str],
                               failed: np.ndarray | None = None,
                               measurements: Sequence[str] = (), note: str = "",
                               alpha: float = CONSISTENCY_ALPHA) -> Consistency:
    """A `Consistency` from whitened residuals (one array per measurement, leading case axis;
    masked entries 0), the number of unmasked entries of each, and the number of determined
    parameters. `failed` `(cases,)`: cases without equilibrium (their residuals ignored)."""
    n_cases = len(cases)
    failed = np.zeros(n_cases, bool) if failed is None else np.asarray(failed, bool)
    sq = np.zeros(n_cases)
    count = np.zeros(n_cases)
    for white, n in zip(whitened, counts, strict=True):
        white = np.asarray(white, float).reshape(n_cases, -1)
        with np.errstate(over="ignore", invalid="ignore"):
            sq += np.sum(np.where(np.isfinite(white), white, np.inf) ** 2, axis=1)
        count += n / n_cases
    n_res = int(sum(counts))
    dof = max(n_res - int(n_parameters), 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        rms = np.where(failed, np.inf, np.sqrt(sq / np.maximum(count, 1)))
    chi2 = float(np.inf if failed.any() else np.sum(sq))
    critical = chi2_quantile(dof, alpha)
    return Consistency(chi2=chi2, n_residuals=n_res, n_parameters=int(n_parameters), dof=dof,
                       critical=critical, case_rms=rms, cases=tuple(cases),
                       failed_cases=tuple(c for c, f in zip(cases, failed, strict=True) if f),
                       consistent=bool(np.isfinite(chi2) and chi2 <= critical),
                       measurements=tuple(measurements), alpha=alpha, note=note)


def check_data(mech, data, sigma_rotation: float | None = None):
    """The measurements a consistency check compares with: `data` as least-squares
    measurements (`measure.data.as_fit_data`), with a pose table without landmarks given a
    rotation σ (`sigma_rotation`, default its translation σ over the model's length scale)."""
    items = (data,) if not isinstance(data, list | tuple) else tuple(data)
    out = []
    for m in items:
        if isinstance(m, Measurements) and m.landmarks is None and m.sigma_rotation is None:
            rot = sigma_rotation if sigma_rotation is not None else m.sigma / mech.length_scale
            m = from_measurements(m, m.sigma, rot)
        out.append(m)
    return as_fit_data(tuple(out))


def check_consistency(mech, data, n_parameters: int, *, cases: Sequence[str] | None = None,
                      note: str = "", alpha: float = CONSISTENCY_ALPHA) -> Consistency:
    """Solve the equilibria of `mech` at every load case of `data` (`solve_statics`, no
    failure raised) and compare its predictions with the measured values in units of their σ
    (see `Consistency`). `data`: measurements as `check_data` returns them (one data set);
    `n_parameters`: how many parameters were determined from them (for the degrees of
    freedom)."""
    import jax.numpy as jnp


    whitened, counts, failed, names = [], [], None, []
    solved = {}
    for meas in data:
        key = id(meas.loads)
        if key not in solved:
            # A case without equilibrium is part of the verdict (`failed_cases`, "no
            # equilibrium in case …"), not a warning: the model judged may be a poor estimate
            # (e.g. direct's linear one, its errors in variables pulling a value toward 0).
            with warnings.catch_warnings():
                warnings.filterwarnings("ignore", message=".*cases did not converge",
                                        category=UserWarning)
                sol = solve_statics(mech, meas.loads, throw=False)
            solved[key] = (sol.q, np.asarray(sol.status) != Status.CONVERGED)
        q, bad = solved[key]
        q = jnp.where(jnp.asarray(bad)[:, None], 0.0, q)
        white = np.asarray(_whitened(meas, mech, q))
        white = np.where(bad.reshape((-1,) + (1,) * (white.ndim - 1)), 0.0, white)
        whitened.append(white)
        counts.append(int(np.count_nonzero(np.asarray(meas.weight))))
        failed = bad if failed is None else failed | bad  # tables of one length only
        names.append(meas.name)
    n_cases = whitened[0].shape[0]
    if any(w.shape[0] != n_cases for w in whitened):  # several load tables: per measurement
        whitened = [w.reshape(1, -1) for w in whitened]
        failed = np.array([bool(np.any(solved[id(m.loads)][1])) for m in data][:1])
        cases = ("all",)
    cases = tuple(cases) if cases is not None and len(cases) == n_cases else tuple(
        str(c + 1) for c in range(whitened[0].shape[0]))
    return consistency_from_residuals(whitened, counts, n_parameters, cases, failed,
                                      names, note, alpha)


@eqx.filter_jit
def _whitened(meas, mech, q):
    return meas.residual(mech, q) * meas.weight


def _number(v):
    v = float(v)
    return v if math.isfinite(v) else None


MAX_SIGMA_PCT = 10.0
"""The σ % bar of the suspension identifications (`direct`, `iterative`, `least_squares`): a
stiffness with a larger σ % at the start values is not determined (engineering accuracy; beyond
it the linearised σ no longer describes the spread of the estimate, spec
guaranteed_least_squares §3.8)."""

AT_START = "the start values"
"""Where the suspension identifications judge σ % (`judged_at`): see `sigma_pct_at_start`."""


def sigma_pct(sigma, estimate) -> np.ndarray:
    """σ % at the estimate: 100·σ/|estimate| (inf where the estimate is 0, NaN where both
    are)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return 100.0 * np.asarray(sigma, dtype=float) / np.abs(np.asarray(estimate, dtype=float))


def sigma_pct_at_start(sigma, start) -> np.ndarray:
    """The one rule for "determined" of `direct`, `iterative` and `least_squares`:
    σ % judged at the start values, 100·σ/|start|, where σ is what the experiment gives at the
    start values (the method's σ where it does not depend on θ, as the direct method's linear
    σ; the Fisher information of the data Jacobian at the start where it does, as for least
    squares and the iterative method). NaN where the start is 0 or not finite (no relative
    bar: e.g. an offset; only identifiability is judged there); inf where σ is.

    Why not at the estimate: a σ that depends on θ (a stiff bushing's effect on the poses goes
    as 1/K, so its relative σ grows with K), or 100·σ/|estimate| itself, moves with the
    estimate's own noise, so a bar there admits the draws whose noise moved the estimate where
    it looks better determined — a selection on the noise (over 100 noise draws of
    `tests/test_identify_trust.py`'s truth A.Ktz passed such a bar in 15 draws with a mean
    error of −1.98σ). The start values are known before the data: the verdict is one per
    experiment, the same for every noise draw, and the same for the three methods. When the
    start is far from the truth the bar is applied at the wrong place by up to that factor;
    the reported σ and σ % stay the ones at the estimate."""
    sigma = np.asarray(sigma, dtype=float)
    start = np.abs(np.asarray(start, dtype=float))
    ok = np.isfinite(start) & (start > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(ok, 100.0 * sigma / np.where(ok, start, 1.0), np.nan)


def within_bar(pct, bar: float = MAX_SIGMA_PCT) -> np.ndarray:
    """`pct` ≤ `bar`, or no bar applies (NaN: see `sigma_pct_at_start`); inf fails."""
    pct = np.asarray(pct, dtype=float)
    with np.errstate(invalid="ignore"):
        return ~(pct > bar)  # NaN > bar is False


def bar_reason(pct: float, bar: float = MAX_SIGMA_PCT) -> str:
    """The reason every suspension report gives for a σ % above the bar."""
    return f"σ% {pct:.3g} > {bar:g} at {AT_START}"


def plain(value):
    """`value` as JSON data: mappings and sequences recursively, numpy scalars and arrays as
    Python numbers and lists, NaN and ±inf as None (JSON has no such numbers)."""
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return _number(value)
    return value


class Report:
    """The one base of the library's reports (the identifications, their rehearsals, the
    sensitivities, the tyre fits): a subclass gives `rows()` (one dict of plain values per
    row) and `summary()` (the whole report as plain data); the base gives `to_json()` and the
    one writer `write(path)`, which chooses the format by the suffix of `path`.

    A subclass may change what a file gets: `csv_rows()` (default `rows()`), `json_data()`
    (default `summary()`), and more formats by extending `formats()`."""

    kind: ClassVar[str] = "report"
    """What the report is, for messages ('rehearsal', 'identification', …)."""

    def rows(self) -> list[dict]:
        """One dict per row (parameter, metric, …) of plain values."""
        raise NotImplementedError(f"{type(self).__name__} gives no rows()")

    def summary(self) -> dict:
        """The whole report as plain data (default: its `rows()` under "rows")."""
        return {"rows": self.rows()}

    def to_json(self, **kwargs) -> str:
        """`summary()` as JSON (NaN and inf written as null); `kwargs` go to `json.dumps`."""
        return json.dumps(plain(self.summary()), **kwargs)

    def csv_rows(self) -> list[dict]:
        """The rows a .csv file gets (default `rows()`)."""
        return self.rows()

    def json_data(self) -> dict:
        """What a .json file gets (default `summary()`)."""
        return self.summary()

    def formats(self) -> dict:
        """Suffix → a function giving the file's text: .csv (`csv_rows()` by `rows_csv`),
        .json (`json_data()`, NaN and inf as null)."""
        return {".csv": lambda: rows_csv(self.csv_rows() or [{"parameter": None}]),
                ".json": lambda: json.dumps(plain(self.json_data()), indent=2,
                                            allow_nan=False) + "\n"}

    def write(self, path) -> None:
        """Write the report to `path` in the format its suffix names (`formats()`: .csv,
        .json, and for an identification .html and .txt). Every format renders the same
        rows, so they cannot disagree; the file is written under a temporary name and renamed
        (never left truncated). Raises `InputError` for another suffix."""
        path = pathlib.Path(path)
        formats = self.formats()
        render = formats.get(path.suffix.lower())
        if render is None:
            raise InputError(f"{path}: unknown report format '{path.suffix}' for a "
                             f"{self.kind} (use {', '.join(formats)}).")
        write_text_atomic(path, render())


@dataclasses.dataclass(frozen=True)
class RowsReport(Report):
    """Rows of plain values with a few fields around them, written by the report base: e.g.
    the estimate at an interruption (`table`: the rows; `fields`: what `summary()` adds to
    them, e.g. {"interrupted": True})."""

    table: tuple[dict, ...]
    fields: dict = dataclasses.field(default_factory=dict)

    def rows(self) -> list[dict]:
        return list(self.table)

    def summary(self) -> dict:
        return {**self.fields, "rows": self.rows()}


STATUSES = ("identified", "not determined", "held", "not seen")
"""The one status of a parameter in every identification report: *identified* (determined by
the data and the fit consistent with them), *not determined* (with the reason: σ % above the
bar, only a combination determined, the fit inconsistent, …), *held* (at its start value, not
estimated), *not seen* (the data carry no information on it: σ infinite)."""


class IdentificationReport(Report):
    """Base of the identification reports (see the module docstring for what a subclass
    provides). Not a dataclass itself, so that its subclasses keep their own fields.

    Optional in a subclass: `held` (bool per parameter: held at its start value), `seen` (bool
    per parameter: the data carry information on it on its own; default σ finite), `reasons`
    (text per parameter: why it is not determined, "" otherwise), `judged_at` (where the σ %
    bar was applied), `stop_reason` (why the method stopped). The base derives from them one
    status per parameter (`statuses`, `status_reasons`), and every writer — `table_text`,
    `rows()`, `summary()`/`to_json()`, `write` (.csv, .json, .html, .txt) — renders those."""

    kind: ClassVar[str] = "identification"

    family: ClassVar[str] = "identification"
    """The method's name: 'direct', 'iterative', 'least_squares'."""

    consistency: Consistency | None = None
    """The identified model against the data (None: not checked)."""

    judged_at: ClassVar[str] = "the estimate"
    """Where `determined` applied its σ % bar (the estimate, or the start values: `direct`,
    `iterative` and `least_squares` judge at `AT_START`, `sigma_pct_at_start`)."""

    gate_sigma_pct: np.ndarray | None = None
    """`(p,)` the σ % the bar judges when it is not `sigma_pct` (the suspension methods: at the
    start values, `sigma_pct_at_start`); None: `sigma_pct`."""

    @property
    def judged_sigma_pct(self) -> np.ndarray:
        """`(p,)` the σ % `determined` compares with `max_sigma_pct`, taken at `judged_at`."""
        gate = self.gate_sigma_pct
        return np.asarray(self.sigma_pct if gate is None else gate, dtype=float)

    def within_bar(self) -> np.ndarray:
        """`(p,)` `judged_sigma_pct` ≤ the report's `max_sigma_pct` (or no bar applies): the
        one σ % rule of `direct`, `iterative` and `least_squares` (`within_bar`)."""
        return within_bar(self.judged_sigma_pct, getattr(self, "max_sigma_pct", MAX_SIGMA_PCT))

    @property
    def determined(self) -> np.ndarray:
        """Which parameters the data determine, by the method's own criterion (default
        `identifiable`; `direct`, `iterative` and `least_squares` also ask σ % at the start
        values ≤ their `max_sigma_pct`, `within_bar`: a bar on the σ % at the estimate
        selects the draws by their own noise, see `sigma_pct_at_start`)."""
        return np.asarray(self.identifiable, dtype=bool)

    @property
    def consistent(self) -> bool | None:
        """The identified model reproduces the data (None: not checked)."""
        return None if self.consistency is None else bool(self.consistency.consistent)

    @property
    def held_mask(self) -> np.ndarray:
        """`(p,)` parameters held at their start value (a subclass's `held`; none by default)."""
        held = getattr(self, "held", None)
        n = len(self.names)
        return np.zeros(n, bool) if held is None else np.asarray(held, bool).reshape(n)

    @property
    def is_identified(self) -> np.ndarray:
        """`(p,)`: determined by the data AND the identified model consistent with them (and not
        held): the only values a report calls *identified* (an unchecked model counts as
        consistent)."""
        return self.determined & (self.consistent is not False) & ~self.held_mask

    @property
    def statuses(self) -> tuple[str, ...]:
        """Per parameter one of `STATUSES`; "identified" exactly where `is_identified`."""
        return tuple(s for s, _ in self._status_pairs())

    @property
    def status_reasons(self) -> tuple[str, ...]:
        """Per parameter why it has its status ("" for identified)."""
        return tuple(r for _, r in self._status_pairs())

    def _status_pairs(self) -> list[tuple[str, str]]:
        det, held, ident = self.determined, self.held_mask, self.is_identified
        own = tuple(getattr(self, "reasons", None) or ("",) * len(self.names))
        sigma = np.asarray(self.sigmas, dtype=float)
        pct = self.judged_sigma_pct
        bar = getattr(self, "max_sigma_pct", None)
        seen = getattr(self, "seen", None)
        seen = np.ones(len(self.names), bool) if seen is None else np.asarray(seen, bool)
        out = []
        for k in range(len(self.names)):
            if held[k]:
                out.append(("held", own[k] or "held at its start value"))
            elif ident[k]:
                out.append(("identified", ""))
            elif np.isinf(sigma[k]) or not seen[k]:
                out.append(("not seen", own[k] or "the data carry no information on it"))
            elif not det[k]:
                if own[k]:
                    why = own[k]
                elif not bool(np.asarray(self.identifiable)[k]):
                    why = "not identifiable on its own by the data"
                elif bar is not None and np.isfinite(pct[k]):
                    why = f"σ% > {bar:g} at {self.judged_at}"
                else:
                    why = "not determined by the data"
                out.append(("not determined", why))
            else:
                out.append(("not determined", "determined by the data, but the fit is "
                            "inconsistent with them: " + _short_verdict(self.consistency)))
        return out

    @property
    def verdicts(self) -> tuple[str, ...]:
        """Per parameter: 'identified', 'not determined by the data' or 'determined, but the
        model is inconsistent with the data'."""
        det = self.determined
        return tuple("identified" if ok and self.consistent is not False else
                     "determined, but the model is inconsistent with the data" if ok else
                     "not determined by the data" for ok in det)

    @property
    def fit_verdict(self) -> str:
        """One line for the whole fit: the consistency verdict (or that it was not checked) and
        the stop reason."""
        text = ("consistency not checked" if self.consistency is None else
                self.consistency.verdict)
        stop = getattr(self, "stop_reason", "")
        return text + (f"; stopped: {stop}" if stop else "")

    def rows(self) -> list[dict]:
        """One dict per parameter: parameter, estimate, sigma, sigma_pct, unit, status (one of
        `STATUSES`), reason, identifiable (the data determine it), identified (status is
        'identified'), verdict (model units; None where there is no number)."""
        ident, verdicts = self.is_identified, self.verdicts
        pairs = self._status_pairs()
        return [dict(parameter=name, estimate=_number(self.estimates[i]),
                     sigma=_number(self.sigmas[i]), sigma_pct=_number(self.sigma_pct[i]),
                     unit=self.estimate_units[i], status=pairs[i][0], reason=pairs[i][1],
                     identifiable=bool(self.identifiable[i]), identified=bool(ident[i]),
                     verdict=verdicts[i])
                for i, name in enumerate(self.names)]

    def summary(self) -> dict:
        """The common part of every report as plain data: method, parameters (`rows()`),
        combinations, per measurement the RMS of its whitened residuals, the consistency of the
        identified model with the data (None when not checked), the fit's verdict and stop
        reason, where the σ % bar was judged, and the report's warnings (e.g. the geometric
        location's swapped-landmark parts and cases)."""
        rms = {}
        for name, res in self.residuals.items():
            white = np.asarray(res.whitened, dtype=float)
            rms[name] = _number(np.sqrt(np.mean(white ** 2))) if white.size else None
        return {"method": self.family, "parameters": self.rows(),
                "combinations": list(self.combinations), "residual_rms": rms,
                "consistency": None if self.consistency is None else
                self.consistency.summary(), "fit_verdict": self.fit_verdict,
                "stop_reason": getattr(self, "stop_reason", ""), "judged_at": self.judged_at,
                "warnings": [str(w) for w in getattr(self, "warnings", ()) or ()]}

    def csv_rows(self) -> list[dict]:
        """The .csv rows (`csv_text`): the base `rows()` (model units), with the method and
        the fit's verdict on every row."""
        rows = IdentificationReport.rows(self) or [{"parameter": None}]
        return [{"method": self.family, **row, "fit_verdict": self.fit_verdict}
                for row in rows]

    def json_data(self) -> dict:
        """The .json content: the base `summary()` (a method's report with a fuller
        `to_dict()` writes that)."""
        return IdentificationReport.summary(self)

    def formats(self) -> dict:
        """The base's .csv and .json, and .html (`html_text`), .txt (`format_table`)."""
        return super().formats() | {".html": lambda: html_text(self),
                                    ".htm": lambda: html_text(self),
                                    ".txt": lambda: format_table(self) + "\n"}

    def table_text(self, width: int | None = 100) -> str:
        """The report as text (`format_table`)."""
        return format_table(self, width)

    def to_frame(self):
        """`rows()` as a pandas DataFrame indexed by parameter (pandas is imported here only:
        it is not a dependency of the library)."""
        try:
            import pandas as pd
        except ImportError:  # pragma: no cover - depends on the environment
            raise ImportError("to_frame needs pandas (pip install pandas); rows() gives the "
                              "same table as dicts.") from None
        return pd.DataFrame(self.rows()).set_index("parameter")

    def plot(self, axes=None):
        """Estimates with ±σ bars on a log scale (grey: not identified). Returns the
        matplotlib Figure."""
        import matplotlib.pyplot as plt

        if axes is None:
            fig, axes = plt.subplots(figsize=(max(4.0, 0.35 * len(self.names) + 2), 3.5))
        else:
            fig = axes.figure
        idx = np.arange(len(self.names))
        ok = np.asarray(self.is_identified, dtype=bool)
        value = np.abs(np.asarray(self.estimates, dtype=float))
        sigma = np.nan_to_num(np.asarray(self.sigmas, dtype=float), nan=0.0, posinf=0.0)
        axes.bar(idx[ok], value[ok], yerr=sigma[ok], color="C0", capsize=2,
                 label="identified")
        axes.bar(idx[~ok], value[~ok], color="0.75", label="not identified")
        if np.any(value > 0):
            axes.set_yscale("log")
        axes.set_xticks(idx, self.names, rotation=90, fontsize=7)
        axes.set_ylabel("|estimate| (model units)")
        axes.set_title(f"{self.family.replace('_', ' ')} identification", fontsize=9)
        axes.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0))
        fig.tight_layout()
        return fig


def _short_verdict(consistency: Consistency | None) -> str:
    if consistency is None:
        return "not checked"
    return f"χ²/dof {consistency.chi2_per_dof:.3g}" + (
        f", no equilibrium in case(s) {', '.join(consistency.failed_cases)}"
        if consistency.failed_cases else "")


def _cell(v, fmt: str = ".6g") -> str:
    return "-" if v is None else format(v, fmt)


def format_table(report: IdentificationReport, width: int | None = 100) -> str:
    """The report as a fixed-width text table: parameter, estimate, σ, σ %, unit, status (short)
    and a note number; the notes (each status's reason, numbered once per distinct text) below
    the table, then the fit's verdict — nothing wraps inside the table. `width` folds the notes
    and the verdict (None: no folding)."""
    rows = IdentificationReport.rows(report)
    notes: dict[str, int] = {}
    for row in rows:
        if row["reason"] and row["reason"] not in notes:
            notes[row["reason"]] = len(notes) + 1
    name_w = max([len("parameter")] + [len(r["parameter"]) for r in rows])
    unit_w = max([len("unit")] + [len(r["unit"]) for r in rows])
    head = (f"{'parameter':<{name_w}}  {'estimate':>13}  {'sigma':>10}  {'sigma %':>8}  "
            f"{'unit':<{unit_w}}  status")
    lines = [head, "-" * len(head)]
    for r in rows:
        note = f" [{notes[r['reason']]}]" if r["reason"] else ""
        lines.append(f"{r['parameter']:<{name_w}}  {_cell(r['estimate']):>13}  "
                     f"{_cell(r['sigma'], '.3g'):>10}  {_cell(r['sigma_pct'], '.3g'):>8}  "
                     f"{r['unit']:<{unit_w}}  {r['status']}{note}")

    def fold(text: str, indent: str = "") -> list[str]:
        if width is None:
            return [indent + text]
        return textwrap.wrap(text, width, initial_indent=indent,
                             subsequent_indent=" " * len(indent)) or [indent]

    if notes:
        lines.append("")
        for text, k in notes.items():
            lines += fold(text, f"[{k}] ")
    lines.append("")
    lines += fold(f"{report.family.replace('_', ' ')}: {report.fit_verdict}")
    if report.judged_at:
        lines += fold(f"σ % judged at {report.judged_at}.")
    return "\n".join(lines)


def csv_text(report: IdentificationReport) -> str:
    """The report's .csv text: `IdentificationReport.csv_rows` (the base `rows()` in model
    units, with the method and the fit's verdict on every row)."""
    return rows_csv(IdentificationReport.csv_rows(report))


def rows_csv(rows: Sequence[dict]) -> str:
    """Rows (dicts with the same keys) as CSV text: None as an empty cell, and a text cell that
    a spreadsheet would run as a formula (leading = + - @, not a number) quoted with '."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: _csv_cell(v) for k, v in row.items()})
    return buf.getvalue()


def _csv_cell(v):
    if v is None:
        return ""
    if isinstance(v, str) and v[:1] in ("=", "+", "-", "@") and not _is_number(v):
        return "'" + v  # a text cell a spreadsheet would run as a formula
    return v


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def html_text(report: IdentificationReport, figures: bool = True) -> str:
    """A one-page self-contained HTML report: the fit's verdict, the table of `rows()` (status
    and reason per parameter), the combinations, and the report's figure (`plot()`) inline as
    SVG (no external file)."""
    esc = html.escape
    rows = IdentificationReport.rows(report)
    cols = ("parameter", "estimate", "sigma", "sigma_pct", "unit", "status", "reason")
    body = "".join(
        "<tr class='{}'>".format(esc(r["status"].replace(" ", "-"))) +
        "".join(f"<td>{esc(_cell(r[c]) if not isinstance(r[c], str) else r[c])}</td>"
                for c in cols) + "</tr>" for r in rows)
    svg = ""
    if figures and rows:
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt

        fig = report.plot()
        buf = io.StringIO()
        fig.savefig(buf, format="svg", bbox_inches="tight")
        plt.close(fig)
        svg = buf.getvalue()
        svg = svg[svg.index("<svg"):]
    combos = "".join(f"<li>{esc(c)}</li>" for c in report.combinations)
    title = f"{report.family.replace('_', ' ')} identification"
    return (
        "<!DOCTYPE html><html><head><meta charset='utf-8'>"
        f"<title>{esc(title)}</title><style>body{{font-family:sans-serif;margin:2em}}"
        "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:2px 6px;"
        "text-align:right}td:first-child,td:nth-child(5),td:nth-child(6),td:nth-child(7)"
        "{text-align:left}tr.identified td:nth-child(6){color:#060}"
        "tr.not-determined td:nth-child(6),tr.not-seen td:nth-child(6){color:#a00}</style>"
        f"</head><body><h1>{esc(title)}</h1><p class='verdict'>{esc(report.fit_verdict)}</p>"
        f"<p>σ % judged at {esc(report.judged_at)}.</p><table><tr>"
        + "".join(f"<th>{c}</th>" for c in cols) + f"</tr>{body}</table>"
        + (f"<h2>Combinations</h2><ul>{combos}</ul>" if combos else "")
        + (f"<h2>Figure</h2>{svg}" if svg else "") + "</body></html>\n")


__all__ = ["CONSISTENCY_ALPHA", "STATUSES", "Consistency", "IdentificationReport",
           "MeasurementResiduals", "Report", "RowsReport", "check_consistency", "check_data",
           "chi2_quantile", "consistency_from_residuals", "csv_text", "format_table",
           "html_text", "plain", "rows_csv", "sigma_pct"]
