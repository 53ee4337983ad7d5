"""Fleets: thousands of independent identifications or analyses, in this process or on a Dask
cluster.

A fleet is one recipe applied to many items: `direct`, `iterative`, `least_squares`
identification (an item: a measurement table), `kc` (a K&C load table, or a design variant's
model run through a named event), `tyre_fit` (a bench table → Magic Formula fit). Every item
uses the fleet's model or its own (`Item(name, path, model=...)`):

```python
from diffsusp import fleet

result = fleet.run("direct", "measurements/*.csv", "out/", model="pseudo_mcpherson")
result = fleet.run("least_squares", paths, "out/", model=mech, workers=8)       # local cluster
result = fleet.run("direct", paths, "out/", model=mech, scheduler="tcp://head:8786")
result = fleet.run("kc", "variants/*.toml", "out/", options={"event": "parallel-travel"})
result = fleet.run("tyre_fit", "bench/*.csv", "out/", model="start.tir")
print(fleet.status("out/").text())
```

- Items of the same model structure and data shape are batched; a batched recipe fits a
  whole batch (items of one model) as one vmapped program, padded to the batch size so that
  every batch of a shape compiles one program (`diffsusp.fleet.run`).
- Inside a worker a batch is split over the local devices (`devices=`, `jax.sharding`; on
  the CPU, `jax_num_cpu_devices` in the fleet's worker processes).
- Reports stream to `out/reports/ITEM.json` (the single-item verbs' JSON report) and a journal
  as each batch returns; `out/summary.csv` has one row per item; a re-run skips every item done
  with the same content hash (the item's bytes, its model, the recipe and its options;
  `diffsusp.fleet.store`).
- A failing item gets a status and a message and never stops the fleet; a worker killed
  mid-batch costs that batch, re-run elsewhere; a time limit per item (checked between items
  and fit steps everywhere, and enforced on Dask by restarting the worker of a batch past it:
  `diffsusp.fleet.engine`); a progress line.
- Workers share the persistent compilation cache (compile once per shape, load elsewhere).
- The engine is behind a small interface (`diffsusp.fleet.engine`): `InProcessEngine`,
  `DaskEngine`; Ray would be one more class. Why Dask: see there.

The same fleet gives the same numbers in-process and on a cluster (same batches, same
programs, float64); the summary holds no timing, so it is identical.
"""

from ._run import FleetResult, Item, run
from .engine import HARD_GRACE, DaskEngine, Engine, InProcessEngine
from .recipes import (
    KC,
    RECIPES,
    Direct,
    ItemTimeout,
    Iterative,
    LeastSquares,
    Recipe,
    TyreFit,
    recipe,
)
from .store import FleetStatus, status

__all__ = [
    "HARD_GRACE", "KC", "DaskEngine", "Direct", "Engine", "FleetResult", "FleetStatus",
    "InProcessEngine", "Item", "ItemTimeout", "Iterative", "LeastSquares", "RECIPES", "Recipe",
    "TyreFit", "recipe", "run", "status",
]
