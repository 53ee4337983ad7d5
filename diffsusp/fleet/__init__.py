"""Fleets: thousands of independent identifications, in this process or on a Dask cluster.

A fleet is one recipe (`direct`, `iterative`, `least_squares` identification) applied to many
data sets (100 axles off a line, 1 000 noise draws, …) with one model:

```python
from diffsusp import fleet

result = fleet.run("direct", "measurements/*.csv", "out/", model="pseudo_mcpherson")
result = fleet.run("least_squares", paths, "out/", model=mech, workers=8)       # local cluster
result = fleet.run("direct", paths, "out/", model=mech, scheduler="tcp://head:8786")
print(fleet.status("out/").text())
```

- Items of the same table shape are batched; a batched recipe fits a whole batch as one vmapped
  program, padded to the batch size so that every batch of a shape compiles one program
  (`diffsusp.fleet.run`).
- Reports stream to `out/reports/ITEM.json` (the single-item verbs' JSON report) and a journal
  as each batch returns; `out/summary.csv` has one row per item; a re-run skips every item done
  with the same content hash (`diffsusp.fleet.store`).
- A failing item gets a status and a message and never stops the fleet; a worker killed
  mid-batch costs that batch, re-run elsewhere; a time limit per item; a progress line.
- Workers share the persistent compilation cache (compile once per shape, load elsewhere).
- The engine is behind a small interface (`diffsusp.fleet.engine`): `InProcessEngine`,
  `DaskEngine`; Ray would be one more class. Why Dask: see there.

The same fleet gives the same numbers in-process and on a cluster (same batches, same
programs, float64); the summary holds no timing, so it is identical.

Not in this version: K&C events and tyre fits as recipes, a model per item, splitting a batch
over the devices of a worker (one device per worker process: start more workers), and a hard
time limit: the limit is checked between items and between the steps of a fit, so one XLA call
that hangs is not interrupted.
"""

from .engine import DaskEngine, Engine, InProcessEngine
from .recipes import RECIPES, Direct, ItemTimeout, Iterative, LeastSquares, Recipe, recipe
from .run import FleetResult, Item, run
from .store import FleetStatus, status

__all__ = [
    "DaskEngine", "Direct", "Engine", "FleetResult", "FleetStatus", "InProcessEngine", "Item",
    "ItemTimeout", "Iterative", "LeastSquares", "RECIPES", "Recipe", "recipe", "run", "status",
]
