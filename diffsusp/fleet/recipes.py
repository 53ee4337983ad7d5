"""What a fleet does with each item: a recipe reads an item (a measurement table) and runs one
identification on a batch of items of the same shape.

A recipe is a small picklable object (it travels to the workers): its `name` and `options`
(JSON-able; part of every item's content hash, so changing an option re-runs the fleet), and

- `read(mech, path)`: the item's data from its file (CSV or Parquet table, as the single-item
  verbs read it);
- `run(mech, data, deadline)`: the reports of a batch of items (a list of data of one shape),
  one `(report_dict, values)` or an exception per item: `report_dict` is the report the
  single-item verb writes with `--out report.json`, `values` the estimates for the summary
  table (name → float).

A batched recipe (`least_squares`) solves the whole batch as one vmapped program
(`identify.least_squares_batch`); the others run the items of a batch one after the other in
the same worker, which still compiles their programs once per batch shape.
"""

import dataclasses
import math
import time
import typing

import numpy as np

__all__ = ["Direct", "ItemTimeout", "Iterative", "LeastSquares", "Recipe", "RECIPES", "recipe"]

_DEG = math.pi / 180.0


class ItemTimeout(Exception):
    """An item (or its batch) ran past the fleet's time limit per item."""


def _check_deadline(deadline, what="the item"):
    if deadline is not None and time.monotonic() > deadline:
        raise ItemTimeout(f"{what} ran past the time limit per item")


@dataclasses.dataclass(frozen=True)
class Recipe:
    """Base of the recipes: a name and JSON-able `options` (see the module docstring)."""

    options: dict = dataclasses.field(default_factory=dict)
    name: typing.ClassVar[str] = ""
    batched: typing.ClassVar[bool] = False

    def read(self, mech, path):
        from .. import measure

        return measure.read_measurements(path, mech)

    def run(self, mech, data: list, deadline: float | None) -> list:
        out = []
        for item in data:
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

    def run_one(self, mech, data):
        from .. import identify

        _, report = identify.direct(mech, data, **self.options)
        return report.to_dict(), dict(zip(report.names, map(float, report.values),
                                          strict=True))


class Iterative(Recipe):
    """`identify.iterative` (the correlation loop, spec stiffness §2) on every item; `options`
    are its keyword arguments. Summary values: `<bushing>.<axis>` stiffnesses, N/mm and
    N·mm/rad."""

    name = "iterative"

    def run_one(self, mech, data):
        from .. import identify

        _, report = identify.iterative(mech, data, **self.options)
        d = report.to_dict()
        values = {f"{b}.{a}": float(report.stiffness[i][j])
                  for i, b in enumerate(d["bushings"]) for j, a in enumerate(d["axes"])}
        return d, values


class LeastSquares(Recipe):
    """Least squares through the equilibrium (`identify.least_squares_batch`). `options`:
    `bushings` (default all) and `axes` (default all six) of the stiffnesses identified, start
    at the model's values; `sigma` (mm, landmarks or pose translations; default 0.05) and
    `sigma_rotation` (deg, poses; 0.01); `pad_to` (set by the fleet to its batch size); any
    other keyword argument of `least_squares_batch` (`max_steps`, `loss`, …). The items of a
    batch that share their loads, landmark layout and mask are fitted as one vmapped program,
    padded to `pad_to` data sets (repeating its last item) so that every batch of a fleet has
    the same shape and compiles once. Summary values: the estimates (N/mm, N·mm/rad)."""

    name = "least_squares"
    batched = True
    _OWN = ("bushings", "axes", "sigma", "sigma_rotation", "pad_to")

    def read(self, mech, path):
        from ..measure.data import from_measurements

        return from_measurements(super().read(mech, path), self.options.get("sigma", 0.05),
                                 self.options.get("sigma_rotation", 0.01) * _DEG)

    def run(self, mech, data: list, deadline: float | None) -> list:
        from ..identify import Params, least_squares_batch

        o = self.options
        bushings = o.get("bushings")
        params = Params.bushing_stiffness(
            mech, None if bushings is None else list(bushings),
            list(o.get("axes") or ("Ktx", "Kty", "Ktz", "Krx", "Kry", "Krz")))
        kwargs = {k: v for k, v in o.items() if k not in self._OWN}
        out: list = [None] * len(data)
        for group in _same_layout(data):
            items = [data[i] for i in group]
            items = items + [items[-1]] * (max(len(items), o.get("pad_to") or 0) - len(items))

            def check(step, arrays, deadline=deadline):
                _check_deadline(deadline, "the batch")

            try:
                batch = least_squares_batch(mech, _stack(items), params, callback=check,
                                            **kwargs)
            except Exception as e:
                for i in group:
                    out[i] = e
                continue
            for k, i in enumerate(group):
                report = batch.reports[k]
                out[i] = (report.to_dict(), dict(zip(report.names, map(float, report.estimate),
                                                     strict=True)))
        return out


def _layout_key(m) -> bytes:
    """Everything of a measurement but its measured values: items with equal keys batch."""
    import jax

    fields = [f.name for f in dataclasses.fields(m) if f.name not in m._values]
    leaves = jax.tree.leaves([getattr(m, f) for f in fields])
    return repr((type(m).__name__, [np.asarray(x).tobytes() for x in leaves])).encode()


def _same_layout(data: list) -> list[list[int]]:
    groups: dict[bytes, list[int]] = {}
    for i, m in enumerate(data):
        groups.setdefault(_layout_key(m), []).append(i)
    return list(groups.values())


def _stack(items):
    import equinox as eqx
    import jax.numpy as jnp

    first = items[0]
    return eqx.tree_at(lambda x: tuple(getattr(x, f) for f in x._values), first,
                       tuple(jnp.stack([getattr(m, f) for m in items]) for f in first._values))


RECIPES = {"direct": Direct, "iterative": Iterative, "least_squares": LeastSquares}


def recipe(name_or_recipe, **options) -> Recipe:
    """A recipe from its name (`'direct'`, `'iterative'`, `'least_squares'`) and options, or
    the recipe itself."""
    from ..errors import InputError

    if isinstance(name_or_recipe, Recipe):
        if options:
            raise InputError("give the options to the recipe object, not to recipe().")
        return name_or_recipe
    if name_or_recipe not in RECIPES:
        raise InputError(f"unknown recipe {name_or_recipe!r}; choose one of "
                         f"{', '.join(RECIPES)} (or pass a Recipe object).")
    return RECIPES[name_or_recipe](options=dict(options))
