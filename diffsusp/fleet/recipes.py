"""What a fleet does with each item: a recipe reads an item (a data table, or nothing when the
item is a model) and runs one identification or analysis on a batch of items of one shape.

A recipe is a small picklable object (it travels to the workers): its `name` and `options`
(JSON-able; part of every item's content hash, so changing an option re-runs the fleet), and

- `load_model(spec)`: the model of a file name, built-in name or object (a suspension
  `Mechanism`; a Magic Formula tyre for `tyre_fit`), in the driver;
- `read(model, path)`: the item's data from its file (CSV or Parquet table, as the single-item
  verbs read it);
- `run(models, data, deadline, mesh)`: the reports of a batch of items, one model and one data
  per item (a batch holds one model structure and one data shape; items with the same model
  share the same object), one `(report_dict, values)` or an exception per item: `report_dict`
  is the report the single-item verb writes as JSON, `values` the numbers for the summary table
  (name → float). `mesh` (a `jax.sharding.Mesh` over the worker's devices, or None) is where a
  batched recipe places its batch axis.

A batched recipe (`least_squares`, `tyre_fit`) solves the items of a batch that share their
model and layout as one vmapped program, padded to the fleet's batch size (`pad_to`) so that
every batch of a shape compiles one program; the others (`direct`, `iterative`, `kc`) run the
items of a batch one after the other in the same worker, which compiles their programs once per
model structure and data shape (no retrace when only values change).
"""

import dataclasses
import time
import typing
import warnings

import numpy as np

from .. import identify, kc, measure, tyre
from ..errors import InputError
from ..geometry import DEG
from ..identify import Params, least_squares_batch
from ..io.tables import read_table, unit_factor
from ..io.tir import read_tir
from ..kc.dispatch import EVENTS, event_json, reference_case, run_event
from ..measure.data import from_measurements
from ..model.mechanism import Mechanism
from ..resolve import load_model_file
from ..tyre import fit as F
from ..tyre.input_tables import read_tyre_table

__all__ = ["KC", "Direct", "ItemTimeout", "Iterative", "LeastSquares", "RECIPES", "Recipe",
           "TyreFit", "recipe"]


class ItemTimeout(Exception):
    """An item (or its batch) ran past the fleet's time limit per item."""


class NotConverged(Exception):
    """An item whose fit ran but did not converge: its report and values are kept, its status
    is `not converged` (a failure, never `ok`)."""

    def __init__(self, message, report, values):
        super().__init__(message)
        self.report, self.values = report, values


def _check_deadline(deadline, what="the item"):
    if deadline is not None and time.monotonic() > deadline:
        raise ItemTimeout(f"{what} ran past the time limit per item")


@dataclasses.dataclass(frozen=True)
class Recipe:
    """Base of the recipes: a name and JSON-able `options` (see the module docstring)."""

    options: dict = dataclasses.field(default_factory=dict)
    name: typing.ClassVar[str] = ""
    batched: typing.ClassVar[bool] = False

    @property
    def items_are_models(self) -> bool:
        """True when an item is a model file and nothing else (the `kc` recipe with a named
        event): a path given as an item is then the item's model."""
        return False

    def load_model(self, spec):
        """A suspension `Mechanism` from a model file, a built-in name or a `Mechanism`."""
        if isinstance(spec, Mechanism):
            return spec
        return load_model_file(spec).mechanism

    def check(self) -> None:
        """Raise `InputError` for options the recipe cannot use, before any item runs."""

    def _check_keywords(self, function, own=()) -> None:
        """Every option a keyword argument of `function` (or one of `own`): an unknown key is
        bad input before any item runs, not ignored nor an error on every item."""
        import inspect

        params = inspect.signature(function).parameters
        if any(p.kind is p.VAR_KEYWORD for p in params.values()):
            return
        known = [n for n, p in params.items()
                 if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)][2:] + list(own)
        unknown = [k for k in self.options if k not in known]
        if unknown:
            raise InputError(f"{self.name} option(s) {', '.join(map(repr, unknown))} unknown; "
                             f"known: {', '.join(known)}.")

    def read(self, mech, path):
        return measure.read_measurements(path, mech)

    def run(self, mechs: list, data: list, deadline: float | None, mesh=None) -> list:
        out = []
        for mech, item in zip(mechs, data, strict=True):
            try:
                _check_deadline(deadline)
                out.append(self.run_one(mech, item))
            except Exception as e:  # one bad item never stops its batch
                out.append(e)
        return out

    def run_one(self, mech, data):  # pragma: no cover - abstract
        raise NotImplementedError


class Direct(Recipe):
    """`identify.direct` (linear, spec stiffness §1.8–1.14) on every item; `options` are the
    function's keyword arguments (`hold`, `eliminate`, `weighting`, …, as `diffsusp identify
    direct`). Summary values: the estimates in the report's units (N/mm, N·mm/deg, N)."""

    name = "direct"

    def check(self) -> None:
        self._check_keywords(identify.direct)

    def run_one(self, mech, data):
        _, report = identify.direct(mech, data, **self.options)
        return report.to_dict(), _with_statuses(report, dict(zip(
            report.names, map(float, report.values), strict=True)))


class Iterative(Recipe):
    """`identify.iterative` (the correlation loop, spec stiffness §2) on every item; `options`
    are its keyword arguments. Summary values: `<bushing>.<axis>` stiffnesses, N/mm and
    N·mm/rad."""

    name = "iterative"

    def check(self) -> None:
        self._check_keywords(identify.iterative)

    def run_one(self, mech, data):
        _, report = identify.iterative(mech, data, **self.options)
        d = report.to_dict()
        values = {f"{b}.{a}": float(report.stiffness[i][j])
                  for i, b in enumerate(d["bushings"]) for j, a in enumerate(d["axes"])}
        return d, _with_statuses(report, values)


def _with_statuses(report, values: dict) -> dict:
    """The summary's values with each reported parameter's status (`identified`, `not
    determined`, `held`, `not seen`: `IdentificationReport.statuses`) in a column
    `<name> status` beside its value."""
    status = dict(zip(report.names, report.statuses, strict=True))
    out: dict = {}
    for name, v in values.items():
        out[name] = v
        if name in status:
            out[f"{name} status"] = status[name]
    return out


def _padded(items: list, pad_to, mesh) -> list:
    """`items` repeated (the last one) up to `pad_to`, and up to a multiple of the mesh's
    devices (every device gets the same share)."""
    n = max(len(items), int(pad_to or 0))
    if mesh is not None:
        n = -(-n // mesh.size) * mesh.size
    return items + [items[-1]] * (n - len(items))


def _shard(array, mesh):
    """`array` placed with its leading (batch) axis split over `mesh`'s one axis
    (`jax.sharding.NamedSharding`); the programs that take it run their share of the batch on
    each device (GSPMD partitions a vmapped program along its batch axis)."""
    if mesh is None:
        return array
    import jax
    from jax.sharding import NamedSharding, PartitionSpec

    return jax.device_put(array, NamedSharding(mesh, PartitionSpec(mesh.axis_names[0])))


class LeastSquares(Recipe):
    """Least squares through the equilibrium (`identify.least_squares_batch`). `options`:
    `bushings` (default all) and `axes` (default all six) of the stiffnesses identified, start
    at the model's values; `sigma` (mm, landmarks or pose translations; default 0.05) and
    `sigma_rotation` (deg, poses; 0.01); `pad_to` (set by the fleet to its batch size); any
    other keyword argument of `least_squares_batch` (`max_steps`, `loss`, …). The items of a
    batch that share their model, loads, landmark layout and mask are fitted as one vmapped
    program, padded to `pad_to` data sets (repeating its last item) so that every batch of a
    fleet has the same shape and compiles once; with a mesh, the data sets are split over its
    devices. Summary values: the estimates (N/mm, N·mm/rad)."""

    name = "least_squares"
    batched = True
    _OWN = ("bushings", "axes", "sigma", "sigma_rotation", "pad_to")

    def check(self) -> None:
        self._check_keywords(least_squares_batch, self._OWN)

    def read(self, mech, path):
        return self._measurement(super().read(mech, path))

    def _measurement(self, m):
        """A `measure.Measurements` (a table read, or an in-memory item) as the fit's
        measurement, with the recipe's σ; a measurement already is one."""
        if hasattr(m, "value_fields"):
            return m
        return from_measurements(m, self.options.get("sigma", 0.05),
                                 self.options.get("sigma_rotation", 0.01) * DEG)

    def run(self, mechs: list, data: list, deadline: float | None, mesh=None) -> list:
        data = [self._measurement(m) for m in data]
        o = self.options
        bushings = o.get("bushings")
        kwargs = {k: v for k, v in o.items() if k not in self._OWN}
        out: list = [None] * len(data)
        for group in _same_layout(data, mechs):
            mech = mechs[group[0]]
            items = _padded([data[i] for i in group], o.get("pad_to"), mesh)

            def check(step, arrays, deadline=deadline):
                _check_deadline(deadline, "the batch")

            try:
                params = Params.bushing_stiffness(
                    mech, None if bushings is None else list(bushings),
                    list(o.get("axes") or ("Ktx", "Kty", "Ktz", "Krx", "Kry", "Krz")))
                batch = least_squares_batch(mech, _stack(items, mesh), params,
                                            callback=check, **kwargs)
            except Exception as e:
                for i in group:
                    out[i] = e
                continue
            for k, i in enumerate(group):
                report = batch.reports[k]
                out[i] = (report.to_dict(), _with_statuses(report, dict(zip(
                    report.names, map(float, report.estimate), strict=True))))
        return out


def _layout_key(m) -> bytes:
    """Everything of a measurement but its measured values: items with equal keys batch."""
    import jax

    fields = [f.name for f in dataclasses.fields(m) if f.name not in m.value_fields]
    leaves = jax.tree.leaves([getattr(m, f) for f in fields])
    return repr((type(m).__name__, [np.asarray(x).tobytes() for x in leaves])).encode()


def _same_layout(data: list, models: list) -> list[list[int]]:
    """Indices of the items that share their model (the same object) and data layout."""
    groups: dict[tuple, list[int]] = {}
    for i, (m, mech) in enumerate(zip(data, models, strict=True)):
        groups.setdefault((id(mech), _layout_key(m)), []).append(i)
    return list(groups.values())


def _stack(items, mesh=None):
    """One measurement whose measured values carry a leading data-set axis (split over `mesh`'s
    devices when given)."""
    import equinox as eqx
    import jax.numpy as jnp

    first = items[0]
    return eqx.tree_at(lambda x: tuple(getattr(x, f) for f in x.value_fields), first,
                       tuple(_shard(jnp.stack([getattr(m, f) for m in items]), mesh)
                             for f in first.value_fields))


# ----------------------------------------------------------------------------- K&C events


def _load_table(mech, path):
    """A K&C load table file: columns F_vert, F_lat, F_long (per side, at the contact point:
    vertical up, lateral inboard, longitudinal rearward; N unless the header gives a force
    unit), one load case per row."""
    table = read_table(path)
    lower = {n.lower(): n for n in table.names}
    columns = []
    for want in ("f_vert", "f_lat", "f_long"):
        if want not in lower:
            raise InputError(f"{path}: no column {want.upper()} (N); columns are "
                             f"{', '.join(table.names)}: a K&C load table has F_vert, F_lat "
                             "and F_long (N, per side, at the contact point).")
        name = lower[want]
        try:
            factor = unit_factor(table.units.get(name), "force")
        except ValueError as e:
            raise InputError(f"{path}: column {name}: {e}.") from None
        columns.append(np.asarray(table[name], float) * factor)
    return np.stack(columns, axis=1)


def _event_report(ev, model_name: str, caught) -> dict:
    """The JSON of `diffsusp kc MODEL --json` for an event, plus the warnings it raised."""
    return event_json(ev, model_name) | {"warnings": [str(w.message) for w in caught]}


class KC(Recipe):
    """A K&C event on every item (`diffsusp.kc`; metrics with the Adams/Car per-side
    conventions of `diffsusp.kc.metrics`). Two kinds of fleet, by `options["event"]`:

    - `"table"` (default): every item is a load table (CSV/Parquet, columns F_vert, F_lat,
      F_long in N per side at the contact point, one case per row), run on the fleet's model
      (or the item's own) by `kc.load_table`;
    - an event name of `diffsusp kc --event` (`parallel-travel`, `vertical-force`,
      `steering`, …; `kc.dispatch.EVENTS`) with its ranges as options (`travel`, `fz`,
      `force`, `torque`, `rack`: `start:stop:count` text or a list; mm, N, N·m): every item is
      a model (a design variant: a model file, or an `Item` with `model=`), the event is run
      on it by `kc.dispatch.run_event`.

    Each item's report is the JSON of `diffsusp kc MODEL --json` (every metric at every case,
    display units) plus the warnings the event raised; its summary values are the metrics at
    the event's reference case (`kc.dispatch.reference_case`: zero travel or force, the design
    load, the first row of a table), display units (deg, mm, N/mm …). A case that does not
    converge fails the item (status `error`, with the case and its residual). The items of a
    batch run one after the other (one compiled program per model structure and number of
    cases); the cases of an event are split over the worker's devices by `solve_statics`
    (`$DIFFSUSP_DEVICES`, which the fleet sets in its workers)."""

    name = "kc"
    _RANGES = ("travel", "fz", "force", "torque", "rack")

    @property
    def event(self) -> str:
        return self.options.get("event", "table")

    @property
    def items_are_models(self) -> bool:
        return self.event != "table"

    def check(self) -> None:
        unknown = sorted(set(self.options) - {"event", *self._RANGES})
        if unknown:
            raise InputError(f"unknown kc option(s) {', '.join(unknown)}; the options are "
                             f"event and its ranges ({', '.join(self._RANGES)}).")
        if self.event != "table" and self.event not in EVENTS:
            raise InputError(f"unknown event '{self.event}'; known events: table, "
                             f"{', '.join(EVENTS)}.")

    def read(self, mech, path):
        return _load_table(mech, path)

    def run_one(self, mech, data):
        unknown = sorted(set(self.options) - {"event", *self._RANGES})
        if unknown:
            raise InputError(f"unknown kc option(s) {', '.join(unknown)}; the options are "
                             f"event and its ranges ({', '.join(self._RANGES)}).")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            if self.event == "table":
                ev = kc.load_table(mech, data)
            elif self.event not in EVENTS:
                raise InputError(f"unknown event '{self.event}'; known events: table, "
                                 f"{', '.join(EVENTS)}.")
            else:
                ranges = {k: self.options[k] for k in self._RANGES if k in self.options}
                ev = run_event(mech, self.event, **ranges)
        ref = reference_case(ev)
        values = {name: float(np.asarray(kc.display(name, v))[ref])
                  for name, v in sorted(ev.metrics.items())}
        return _event_report(ev, mech.name, caught), values


# ----------------------------------------------------------------------------- tyre fits


class TyreFit(Recipe):
    """A Magic Formula fit on every item (`diffsusp.tyre.fit`, spec tyre §7 E item 22): the
    item is a bench table (CSV/Parquet with units in the header, as `diffsusp tyre fit`
    reads it), the model the start tyre: a `.tir` file (MF 5.2/6.1/6.2), a `MagicFormula6`
    or a `MagicFormula89` object; an item may carry its own start tyre. `options`: `groups`
    (coefficient groups of `tyre.fit.GROUPS` fitted in order, each from the previous fit;
    default as `diffsusp tyre fit`: pure_lateral, pure_longitudinal, pure_aligning as the
    data's channels allow, `mf1989_lateral` for a 1989 tyre) or `names` (the coefficients of one
    fit, reported as group "fit"), `loss` (default "huber"),
    `noise` (per channel σ, N / N·mm), `loss_scale`, `combined`, `max_steps`, `rtol`,
    `atol`, `threshold`; `pad_to` (set by the fleet). The items of a batch that share their
    channels and number of rows are fitted together by `tyre.fit.fit_many` (one vmapped
    Levenberg–Marquardt), padded to `pad_to`. The report is the JSON `diffsusp tyre fit
    --report` writes (one fit report per group) plus the rows excluded at reading
    (`warnings`); summary values: the fitted coefficients of every group."""

    name = "tyre_fit"
    batched = True
    _FIT = ("loss", "noise", "loss_scale", "combined", "max_steps", "rtol", "atol",
            "threshold")
    _OPTIONS = _FIT + ("groups", "names", "pad_to")

    def check(self):
        """Unknown option keys, groups or losses are bad input before any item runs
        not an error on every item."""
        unknown = [k for k in self.options if k not in self._OPTIONS]
        if unknown:
            raise InputError(f"tyre-fit option(s) {', '.join(map(repr, unknown))} unknown; "
                             f"known: {', '.join(self._OPTIONS)}.")
        groups = self.options.get("groups")
        if groups is not None:
            if isinstance(groups, str):
                raise InputError(f"tyre-fit option groups must be a list, e.g. "
                                 f"groups='[\"{groups}\"]'.")
            bad = [g for g in groups if g not in F.GROUPS]
            if bad or not groups:
                raise InputError(f"tyre-fit option groups: {bad or '(none)'} not among "
                                 f"{', '.join(F.GROUPS)}.")
        loss = self.options.get("loss")
        if loss is not None and loss not in ("linear", "huber", "cauchy"):
            raise InputError(f"tyre-fit option loss {loss!r}: linear, huber or cauchy.")

    def load_model(self, spec):
        if isinstance(spec, tyre.AbstractTyre):
            return spec
        return tyre.MagicFormula6.from_tir(read_tir(spec))

    def read(self, model, path):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            bench = F.bench_data(read_tyre_table(path, "bench table"))
        return bench, tuple(str(w.message) for w in caught)

    def _groups(self, model, channels) -> list[str]:
        if self.options.get("names"):
            return ["fit"]
        if self.options.get("groups"):
            return list(self.options["groups"])
        return F.default_groups(model, channels)

    def run(self, models: list, data: list, deadline: float | None, mesh=None) -> list:
        import jax

        kwargs = {k: v for k, v in self.options.items() if k in self._FIT}
        out: list = [None] * len(data)
        groups: dict[tuple, list[int]] = {}
        for i, (model, (bench, _)) in enumerate(zip(models, data, strict=True)):
            key = (repr(jax.tree.structure(model)), bench.channels, bench.n)
            groups.setdefault(key, []).append(i)
        for group in groups.values():
            try:
                _check_deadline(deadline, "the batch")
                fitted = _padded([models[i] for i in group], self.options.get("pad_to"), None)
                benches = _padded([data[i][0] for i in group], self.options.get("pad_to"),
                                  None)
                reports: list[dict] = [{} for _ in fitted]
                for g in self._groups(fitted[0], benches[0].channels):
                    if g == "fit":
                        names = list(self.options["names"])
                    elif g not in F.GROUPS:
                        raise InputError(f"unknown coefficient group {g!r}; one of "
                                         f"{', '.join(F.GROUPS)}.")
                    else:
                        names = [n for n in F.GROUPS[g] if n in fitted[0].coefficients]
                    fitted, reps = F.fit_many(fitted, benches, names, **kwargs)
                    for k, r in enumerate(reps):
                        reports[k][g] = r
                    _check_deadline(deadline, "the batch")
            except Exception as e:
                for i in group:
                    out[i] = e
                continue
            for k, i in enumerate(group):
                report = {g: r.to_dict() for g, r in reports[k].items()}
                report["warnings"] = list(data[i][1])
                values = {n: float(v) for r in reports[k].values()
                          for n, v in zip(r.names, r.values, strict=True)}
                stuck = [g for g, r in reports[k].items() if not bool(r.converged)]
                out[i] = (NotConverged(f"the fit of {', '.join(stuck)} did NOT converge "
                                       f"(max_steps {kwargs.get('max_steps', 200)})",
                                       report, values) if stuck else (report, values))
        return out


RECIPES = {"direct": Direct, "iterative": Iterative, "least_squares": LeastSquares, "kc": KC,
           "tyre_fit": TyreFit}


def recipe(name_or_recipe, **options) -> Recipe:
    """A recipe from its name (`'direct'`, `'iterative'`, `'least_squares'`, `'kc'`,
    `'tyre_fit'`) and options, or the recipe itself."""
    if isinstance(name_or_recipe, Recipe):
        if options:
            raise InputError("give the options to the recipe object, not to recipe().")
        return name_or_recipe
    if name_or_recipe not in RECIPES:
        raise InputError(f"unknown recipe {name_or_recipe!r}; choose one of "
                         f"{', '.join(RECIPES)} (or pass a Recipe object).")
    return RECIPES[name_or_recipe](options=dict(options))
