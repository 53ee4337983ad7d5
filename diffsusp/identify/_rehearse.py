"""A rehearsal of the user's experiment: can the planned measurements give each parameter, and
when a method says "identified", is it right?

`rehearse(scenario, n)` draws `n` random truths around the user's start (the spread the user
chooses), simulates the user's measurements of each truth with the user's noise, runs the
method (batched where it has a batched form) and compares every reported value with its truth.
Per parameter it reports:

- `identified_rate`: the fraction of truths for which the method says "identified";
- `coverage` (1σ, 2σ, 3σ): among those, the fraction whose truth lies within k reported σ
  (a calibrated σ gives 68.3 %, 95.4 %, 99.7 %);
- `bias`: the mean of (estimate − truth)/σ over the identified (0 for an unbiased method), and
  `spread` their standard deviation (1 for a calibrated σ);
- `false_identified_rate`: the fraction of truths for which the method says "identified" and
  the truth lies outside 3σ — the wrong claims a user would act on.

and per method the fraction of fits whose consistency verdict is "consistent" and the number
of runs that failed outright. A user runs it before measuring, to see which parameters the
planned experiment can give (DESIGN "Identification": the rehearsal is both a planning tool and
the test every method must pass on scenarios it was not written against).

A *scenario* is any object with `method` (str), `names` (the parameters drawn, spelled as the
reports name them), `draw(rng, n) -> (n, p)` truths, and `identify(truths, rng) -> list` of one
`IdentificationReport` per truth (None for a run that failed). `SuspensionScenario` is the one
for the suspension methods (`direct`, `iterative`, `least_squares`), `GeometryScenario` for the
geometric location (joint hardpoints displaced, landmarks measured); the tyre bench
(`diffsusp.tyre.bench_batch.BenchScenario`) and the Magic Formula fit
(`diffsusp.tyre.fit.FitRehearsal`) provide theirs.
"""

import dataclasses
import math
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import measure
from ..errors import ConvergenceError, InputError
from ..kc.corner import corners_of, design_load
from ..model.mechanism import Loads, Mechanism
from ._direct import direct, direct_batch
from ._iterative import iterative
from ._least_squares import least_squares, least_squares_batch
from .geometric import (
    displace_joints,
    joint_values,
    joints_from_model,
    locate_joints,
    model_geometry,
)
from .report import Report, check_data
from .selection import named_stiffnesses

__all__ = ["GeometryScenario", "ParameterRehearsal", "RehearsalReport", "SuspensionScenario",
           "corner_cases", "rehearse"]

METHODS = ("direct", "iterative", "least_squares")
"""The suspension methods `SuspensionScenario` runs."""


def corner_cases(mech: Mechanism) -> Loads:
    """The default load table of a suspension rehearsal: at the corner's contact point, the
    design load × 0.7, 1, 1.3, each with lateral −2, 0, +2 kN and longitudinal ±1.5 kN (18
    cases: a K&C rig's combined-load grid)."""
    stated = corners_of(mech)[""]
    corner = stated.resolve(mech)
    f0 = design_load(mech, stated)
    force = [[x, y, z] for z in (0.7 * f0, f0, 1.3 * f0) for y in (-2000.0, 0.0, 2000.0)
             for x in (-1500.0, 1500.0)]
    name = mech.load_points.names[corner.contact_point]
    return mech.loads(forces={name: force})


@dataclasses.dataclass(frozen=True)
class ParameterRehearsal:
    """The rehearsal's statistics of one parameter (see the module docstring)."""

    name: str
    n: int
    identified: int
    identified_rate: float
    coverage: tuple[float, float, float]
    bias: float
    spread: float
    false_identified: int
    false_identified_rate: float

    def row(self) -> dict:
        c1, c2, c3 = (_number(c) for c in self.coverage)
        return dict(parameter=self.name, truths=self.n, identified=self.identified,
                    identified_rate=self.identified_rate, coverage_1s=c1, coverage_2s=c2,
                    coverage_3s=c3, bias=_number(self.bias), spread=_number(self.spread),
                    false_identified=self.false_identified,
                    false_identified_rate=self.false_identified_rate)


@dataclasses.dataclass(frozen=True)
class RehearsalReport(Report):
    """What a rehearsal found: `method`, `n` truths, `parameters` (one `ParameterRehearsal`
    each), `consistent_rate` (fits whose consistency verdict is "consistent", of those that
    ran), `failed` (runs without a report), `seed`. On the report base (`Report`): `rows()`,
    `summary()`, `to_json()`, `write(path)` (.csv, .json)."""

    kind = "rehearsal"

    method: str
    n: int
    parameters: tuple[ParameterRehearsal, ...]
    consistent_rate: float
    failed: int
    seed: int

    @property
    def false_identified_rate(self) -> float:
        """The largest false-"identified" rate over the parameters."""
        return max((p.false_identified_rate for p in self.parameters), default=0.0)

    def rows(self) -> list[dict]:
        return [p.row() for p in self.parameters]

    def summary(self) -> dict:
        return {"method": self.method, "truths": self.n, "seed": self.seed,
                "failed": self.failed, "consistent_rate": self.consistent_rate,
                "false_identified_rate": self.false_identified_rate,
                "parameters": self.rows(), "bottom_line": self.bottom_line()}

    def csv_rows(self) -> list[dict]:
        """The .csv rows (`write`): `rows()` with the method on each."""
        return [{"method": self.method, **r} for r in self.rows()]

    def bottom_line(self) -> list[str]:
        """One sentence per parameter a user acts on."""
        out = []
        for p in self.parameters:
            if p.identified == 0:
                out.append(f"{p.name}: the planned experiment never identifies it "
                           f"({p.n} truths).")
                continue
            right = 1.0 - p.false_identified / p.identified
            out.append(f"{p.name}: identified in {100 * p.identified_rate:.0f} % of truths; "
                       f"when it says identified it is right (within 3σ) in "
                       f"{100 * right:.1f} %.")
        return out

    def table(self) -> str:
        rows = self.rows()
        width = max([9] + [len(r["parameter"]) for r in rows])
        head = (f"{'parameter':<{width}}  {'ident.':>6}  {'1σ':>5}  {'2σ':>5}  {'3σ':>5}  "
                f"{'bias/σ':>7}  {'spread/σ':>8}  {'false id.':>9}")
        lines = [f"rehearsal of {self.method}: {self.n} random truths (seed {self.seed}); "
                 f"consistent verdicts {100 * self.consistent_rate:.1f} %; failed runs "
                 f"{self.failed}", head, "-" * len(head)]

        def pct(v):
            return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else \
                f"{100 * v:.1f}"

        for r in rows:
            lines.append(
                f"{r['parameter']:<{width}}  {pct(r['identified_rate']):>6}  "
                f"{pct(r['coverage_1s']):>5}  {pct(r['coverage_2s']):>5}  "
                f"{pct(r['coverage_3s']):>5}  "
                f"{'-' if r['bias'] is None else format(r['bias'], '.2f'):>7}  "
                f"{'-' if r['spread'] is None else format(r['spread'], '.2f'):>8}  "
                f"{pct(r['false_identified_rate']):>9}")
        lines.append("(percentages; coverage among the identified: a calibrated σ gives "
                     "68.3 / 95.4 / 99.7)")
        lines += self.bottom_line()
        return "\n".join(lines)


def _number(v):
    return None if v is None or not math.isfinite(v) else float(v)


def rehearse(scenario, n: int = 200, seed: int = 0) -> RehearsalReport:
    """Run `scenario` (see the module docstring) on `n` random truths drawn with `seed` and
    return the `RehearsalReport`. Raises `InputError` for fewer than one truth, or when the
    scenario's draws or reports do not fit its `names`."""
    if not (isinstance(n, int | np.integer) and n >= 1):
        raise InputError(f"a rehearsal needs at least one random truth; got n={n!r}.")
    names = tuple(scenario.names)
    rng = np.random.default_rng(seed)
    truths = np.asarray(scenario.draw(rng, int(n)), dtype=float)
    if truths.shape != (n, len(names)):
        raise InputError(f"the scenario drew truths of shape {truths.shape}; expected "
                         f"{(n, len(names))} (one column per name).")
    reports = list(scenario.identify(truths, rng))
    if len(reports) != n:
        raise InputError(f"the scenario returned {len(reports)} reports for {n} truths.")
    p = len(names)
    est, sig = np.full((n, p), np.nan), np.full((n, p), np.nan)
    claim = np.zeros((n, p), bool)
    consistent, failed = [], 0
    for i, rep in enumerate(reports):
        if rep is None:
            failed += 1
            continue
        index = {name: k for k, name in enumerate(rep.names)}
        ident = np.asarray(rep.is_identified, bool)
        for j, name in enumerate(names):
            k = index.get(name)
            if k is None:
                continue
            est[i, j], sig[i, j] = float(rep.estimates[k]), float(rep.sigmas[k])
            claim[i, j] = bool(ident[k])
        if rep.consistent is not None:
            consistent.append(bool(rep.consistent))
    params = []
    for j, name in enumerate(names):
        ok = claim[:, j] & np.isfinite(sig[:, j]) & (sig[:, j] > 0)
        z = (est[ok, j] - truths[ok, j]) / sig[ok, j]
        cover = tuple(float(np.mean(np.abs(z) <= k)) if z.size else math.nan
                      for k in (1.0, 2.0, 3.0))
        wrong = int(np.sum(np.abs(z) > 3.0)) + int(np.sum(claim[:, j] & ~ok))
        params.append(ParameterRehearsal(
            name=name, n=int(n), identified=int(claim[:, j].sum()),
            identified_rate=float(claim[:, j].mean()), coverage=cover,
            bias=float(z.mean()) if z.size else math.nan,
            spread=float(z.std(ddof=1)) if z.size > 1 else math.nan,
            false_identified=wrong, false_identified_rate=wrong / n))
    return RehearsalReport(method=scenario.method, n=int(n), parameters=tuple(params),
                           consistent_rate=float(np.mean(consistent)) if consistent else
                           math.nan, failed=failed, seed=int(seed))


@dataclasses.dataclass
class SuspensionScenario:
    """The rehearsal of a suspension identification (`direct`, `iterative`, `least_squares`):
    random stiffnesses around the start model, the user's load cases measured by landmarks
    (`per_part` on every part, σ `noise` mm on every coordinate, the thesis's protocol: spec
    stiffness §1.12, §2.8), identified from the start model.

    **Fields:** `method`; `mech` the user's start model; `loads` the load table (leading case
    axis; default `corner_cases`); `params` the `Params` whose truths are drawn and
    identified, or the names of stiffnesses among the default ('bushing_A.Ktx',
    `selection.named_stiffnesses`); default: every bushing stiffness that is not 0 in the
    model (`selection.fit_selection`); `noise` the landmark σ (mm, > 0); `spread` (low,
    high): each truth is the start × a log-uniform factor in it (default 0.5–2); `per_part`
    landmarks per part; `layout_seed`."""

    method: str
    mech: Mechanism
    loads: Loads | None = None
    params: object = None
    noise: float = 0.05
    spread: tuple[float, float] = (0.5, 2.0)
    per_part: int = 4
    layout_seed: int = 0

    def __post_init__(self):
        if self.method not in METHODS:
            raise InputError(f"unknown method '{self.method}' for a suspension rehearsal; "
                             f"known: {', '.join(METHODS)}.")
        if not (isinstance(self.noise, int | float) and math.isfinite(self.noise)
                and self.noise > 0):
            raise InputError(f"the rehearsal's noise must be a positive σ (mm); got "
                             f"{self.noise!r}: noise-free data would call every parameter "
                             "identified with a zero σ.")
        lo, hi = (float(v) for v in self.spread)
        if not (0 < lo <= hi and math.isfinite(hi)) or lo == hi:
            raise InputError(f"the spread must be (low, high) factors with 0 < low < high; "
                             f"got {self.spread!r}: a spread of 0 draws the start every time.")
        if self.params is None or isinstance(self.params, list | tuple):
            self.params = named_stiffnesses(self.mech, self.params)
        if self.loads is None:
            self.loads = corner_cases(self.mech)
        if self.loads.n_cases is None:
            raise InputError("the rehearsal needs a table of load cases (leading case axis).")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.params.names)

    def draw(self, rng: np.random.Generator, n: int) -> np.ndarray:
        start = np.asarray(self.params.start, dtype=float)
        lo, hi = np.log(self.spread[0]), np.log(self.spread[1])
        return start * np.exp(rng.uniform(lo, hi, size=(n, start.size)))

    def identify(self, truths: np.ndarray, rng: np.random.Generator) -> list:
        layout = measure.place_landmarks(self.mech, self.per_part, seed=self.layout_seed)
        noise = measure.GaussianNoise(landmarks=float(self.noise))
        sets = []
        for truth in truths:
            truth_mech = self.params.apply(self.mech, truth)
            key = jax.random.PRNGKey(int(rng.integers(2**31)))
            try:
                sets.append(measure.synthesize(truth_mech, self.loads, layout=layout,
                                               noise=noise, key=key))
            except (ConvergenceError, InputError):  # a truth without equilibrium: failed run
                sets.append(None)
        good = [m for m in sets if m is not None]
        reports: list = [None] * len(sets)
        where = [k for k, m in enumerate(sets) if m is not None]
        if not good:
            return reports
        try:  # batched where the method has a batched form
            if self.method == "direct":
                out = list(direct_batch(self.mech, good, self.params))
            elif self.method == "least_squares":
                data = [check_data(self.mech, m)[0] for m in good]
                out = list(least_squares_batch(self.mech, _stack(data), self.params).reports)
            else:
                out = None
        except InputError:  # a set the batch refuses (e.g. a start without equilibrium)
            out = None
        if out is None:  # one set at a time: a set the method refuses is a failed run
            out = [self._one(m) for m in good]
        for k, rep in zip(where, out, strict=True):
            reports[k] = rep
        return reports

    def _one(self, meas):
        try:
            if self.method == "direct":
                return direct(self.mech, meas, self.params)[1]
            if self.method == "least_squares":
                return least_squares(self.mech, check_data(self.mech, meas)[0],
                                     self.params)[1]
            return iterative(self.mech, meas, self.params)[1]
        except InputError:
            return None


def _stack(items: Sequence):
    """One measurement with a leading data-set axis from one-set measurements alike."""
    fields = items[0].value_fields
    return eqx.tree_at(lambda m: tuple(getattr(m, f) for f in fields), items[0],
                       tuple(jnp.stack([getattr(it, f) for it in items]) for f in fields))


def _joints_named(mech: Mechanism, names: Sequence[str] | None) -> tuple:
    """The joints `joints_from_model` finds in `mech` (every part), those named in `names` if
    given. Raises `InputError` for a name that is not one of them."""
    joints = joints_from_model(mech, mech.parts)[0]
    if names is None:
        return joints
    wanted = [n.strip() for n in names if n.strip()]
    known = [j.name for j in joints]
    unknown = [n for n in wanted if n not in known]
    if unknown or not wanted:
        raise InputError(f"unknown parameter(s) {', '.join(unknown) or repr(names)}: params "
                         f"names the joints to locate; the model's: {', '.join(known)}.")
    return tuple(j for j in joints if j.name in wanted)


@dataclasses.dataclass
class GeometryScenario:
    """The rehearsal of the geometric location (`identify.geometric.locate_joints`, spec
    geometry §4): the truths are the user's model with the hardpoints of its joints (both
    markers of each located element) displaced by a uniform ±`spread` mm per coordinate; the
    user's load cases are solved on each truth and measured by landmarks (`per_part` on every
    part the joints join, σ `noise` mm); the joints are located from them with the user's
    model as the start (its hardpoints are the revolutes' priors, its own equilibria give the
    compliance bias carried in σ). The parameters are the report's coordinates (`'<joint>.x'`,
    `'<joint>.axis_y'`…); a truth's value of each is the truth model's own (its hardpoint; a
    revolute's line cut at the prior's plane and its axis).

    **Fields:** `mech` the user's model; `loads` the load table (default `corner_cases`);
    `params` the joints to locate, `GeometricJoint`s or their names among those
    `joints_from_model` finds over every part (default: all of them); `noise` landmark σ (mm,
    > 0); `spread` (mm, > 0); `per_part`; `layout_seed`; `max_sigma`, `min_snr` as
    `locate_joints`.

    `draw` keeps the hardpoint displacements it drew for the next `identify` (the truths it
    returns are the coordinates, not the displacements)."""

    mech: Mechanism
    loads: Loads | None = None
    params: tuple = None
    noise: float = 0.05
    spread: float = 5.0
    per_part: int = 4
    layout_seed: int = 0
    max_sigma: float = 10.0
    min_snr: float = 3.0
    method: str = "geometry"

    def __post_init__(self):
        if not (isinstance(self.noise, int | float) and math.isfinite(self.noise)
                and self.noise > 0):
            raise InputError(f"the rehearsal's noise must be a positive landmark σ (mm); got "
                             f"{self.noise!r}: noise-free data would call every coordinate "
                             "identified with a zero σ.")
        if not (isinstance(self.spread, int | float) and math.isfinite(self.spread)
                and self.spread > 0):
            raise InputError(f"the spread must be a positive displacement (mm) of the "
                             f"hardpoints; got {self.spread!r}: a spread of 0 draws the start "
                             "every time.")
        if self.params is None or (self.params and all(isinstance(j, str) for j in self.params)):
            self.params = _joints_named(self.mech, self.params)
        if self.loads is None:
            self.loads = corner_cases(self.mech)
        if self.loads.n_cases is None:
            raise InputError("the rehearsal needs a table of load cases (leading case axis).")
        self.params = tuple(self.params)
        if not self.params:
            raise InputError(f"model '{self.mech.name}' has no joint the geometric location "
                             "can locate.")
        parts = tuple(p for p in self.mech.parts
                      if any(p in j.parts for j in self.params))
        self.layout = measure.place_landmarks(self.mech, self.per_part, parts=parts,
                                              seed=self.layout_seed)
        nominal = self._locate(measure.synthesize(self.mech, self.loads, layout=self.layout))
        self._names = nominal.names
        # the cut coordinate / left-out axis component of each joint, as the nominal reports
        self._rows = {j.name: self._row_map(j, est) for j, est in
                      zip(self.params, nominal.joints, strict=True)}
        self._drawn = None

    @staticmethod
    def _row_map(joint, est):
        names = [c.name for c in est.coordinates]
        kinds = ("revolute", "ball_unknown_slide")
        axis_rows = [n for n in names if n.startswith("axis_")]
        d = "xyz".index(next(c for c in "xyz" if f"axis_{c}" not in axis_rows)) \
            if joint.kind in kinds else 0
        return d

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self._names)

    def _locate(self, meas):
        return locate_joints(meas, self.params, landmark_sigma=float(self.noise),
                             max_sigma=self.max_sigma, min_snr=self.min_snr, model=self.mech)

    def truth_values(self, mech) -> np.ndarray:
        """The coordinates (in `names` order) of the joints of model `mech` (NaN where the
        model has no element for a joint)."""
        values = {}
        for j in self.params:
            geo = model_geometry(mech, j)
            if geo is None:
                continue
            d = self._rows[j.name]
            prior = j.prior if j.prior is not None else geo[0]
            names, vals, _, _, _ = joint_values(j.kind, geo[0], geo[1], prior, d)
            values.update({f"{j.name}.{n}": v for n, v in zip(names, vals, strict=True)})
        return np.array([values.get(n, np.nan) for n in self._names])

    def draw(self, rng: np.random.Generator, n: int) -> np.ndarray:
        offsets = rng.uniform(-self.spread, self.spread, size=(n, len(self.params), 3))
        self._drawn = offsets
        return np.stack([self.truth_values(displace_joints(self.mech, self.params, o))
                         for o in offsets])

    def identify(self, truths: np.ndarray, rng: np.random.Generator) -> list:
        if self._drawn is None or len(self._drawn) != len(truths):
            raise InputError("GeometryScenario.identify needs the truths of its own draw().")
        noise = measure.GaussianNoise(landmarks=float(self.noise))
        reports = []
        for offsets in self._drawn:
            truth = displace_joints(self.mech, self.params, offsets)
            key = jax.random.PRNGKey(int(rng.integers(2**31)))
            try:
                meas = measure.synthesize(truth, self.loads, layout=self.layout, noise=noise,
                                          key=key)
                reports.append(self._locate(meas))
            except (ConvergenceError, InputError):  # a truth without equilibrium: failed
                reports.append(None)
        return reports
