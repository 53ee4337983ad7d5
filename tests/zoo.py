"""The test zoo: every built-in mechanism × its load sets, built once per
run, exposed as module-scoped fixtures a test file imports:

```python
from zoo import zoo_case, zoo_solution  # noqa: F401  (fixtures)

def test_something(zoo_solution):
    case, sol = zoo_solution          # ZooCase(model, load_set, mech, loads), diffsusp's Solution
```

Load sets: `'envelope'` for every model of `diffsusp.models.ZOO` (the thesis envelope at
'contact_patch' for the axles: Table 5-1 plus `ENVELOPE_EXTRA`; scaled random loads at the load
points otherwise, `sensible_loads`), `'travel'` for the axles built with wheel_travel=True
(`TRAVEL_MODELS`: a ±80 mm sweep of driver 'wheel_travel'). A new model is tested against every
zoo check by one line in `diffsusp.models.ZOO` (or in `TRAVEL_MODELS`); a new load set by one
line in `LOAD_SETS`. `diffsusp.solve_statics` compiles one program per (model, load set): the
checks that use `zoo_solution` share it, so a check added over the zoo costs no compilation.
"""

import dataclasses
import functools

import jax.numpy as jnp
import numpy as np
import oracle  # tests/oracle.py (pytest puts tests/ on sys.path)
import pytest

import diffsusp

TRAVEL_MODELS = {
    "pseudo_mcpherson": lambda models: models.pseudo_mcpherson(wheel_travel=True),
    "double_wishbone": lambda models: models.double_wishbone(wheel_travel=True),
    "double_wishbone_bushings": lambda models: models.double_wishbone(bushings=True,
                                                                     wheel_travel=True),
}
"""Axles of the zoo built with wheel_travel=True (driver 'wheel_travel', wheel centre z)."""

ENVELOPE_EXTRA = np.array([[6000.0, -3000.0, 3000.0], [4500.0, 3000.0, -3000.0]])
"""Combined cases added to Table 5-1 (F_vert, F_lat, F_long in N) inside the thesis envelope
(vertical 1 500–7 500 N, lateral and longitudinal ±4 000 N)."""
TRAVEL_SWEEP = np.linspace(-80.0, 80.0, 9)  # mm


def _zoo_names() -> list[str]:
    try:
        from diffsusp.models import ZOO
    except ImportError:
        return []
    return list(ZOO)


def sensible_loads(mech, *, rotation=0.05, displacement=5.0, seed=0):
    """Load cases for a model without a contact patch: forces and moments of random directions
    at every load point, each case scaled from a trial solve (by the oracle) so that no part
    turns more than `rotation` rad and no marker moves more than `displacement` mm."""
    rng = np.random.default_rng(seed)
    n_l, n_d = len(mech.load_points.names), len(mech.drivers.names)
    x0 = np.asarray(mech.markers.position)
    force, moment = [], []
    for _ in range(4):
        f = rng.normal(size=(n_l, 3))
        m = 0.2 * mech.length_scale * rng.normal(size=(n_l, 3))
        trial = oracle.solve(mech, f, m, np.zeros(n_d))
        x, _ = oracle.marker_poses(mech, trial.p, trial.R)
        turn = float(np.max(oracle.rotation_angle(trial.R), initial=0.0))
        move = float(np.max(np.abs(x - x0)))
        scale = min(rotation / max(turn, 1e-300), displacement / max(move, 1e-300), 1e5)
        force.append(scale * f)
        moment.append(scale * m)
    return diffsusp.Loads(force=jnp.asarray(np.array(force)), moment=jnp.asarray(
        np.array(moment)), driver=jnp.zeros((len(force), n_d)))


def _envelope(models, name):
    mech = models.ZOO[name]()
    if "contact_patch" in mech.load_points.names:
        table = np.vstack([np.asarray(models.TABLE_5_1), ENVELOPE_EXTRA])
        return mech, models.thesis_load_cases(mech, table)
    return mech, sensible_loads(mech)


def _travel(models, name):
    mech = TRAVEL_MODELS[name](models)
    return mech, mech.loads(drivers={"wheel_travel": jnp.asarray(TRAVEL_SWEEP)})


LOAD_SETS = {"envelope": (_zoo_names, _envelope),
             "travel": (lambda: list(TRAVEL_MODELS), _travel)}
"""Load set → (the models it applies to, (models module, name) → (mechanism, loads))."""

CASES = [(name, load_set) for load_set, (names, _) in LOAD_SETS.items() for name in names()]
"""Every (model, load set) pair of the zoo."""


@dataclasses.dataclass(frozen=True)
class ZooCase:
    """One zoo entry: the model's name, the load set's, the mechanism and its batched loads."""

    model: str
    load_set: str
    mech: diffsusp.Mechanism
    loads: diffsusp.Loads


@functools.cache
def zoo_case_of(model: str, load_set: str) -> ZooCase:
    """The zoo entry (built once per process)."""
    import diffsusp.models as models

    mech, loads = LOAD_SETS[load_set][1](models, model)
    return ZooCase(model, load_set, mech, loads)


@functools.cache
def _solution(model: str, load_set: str):
    case = zoo_case_of(model, load_set)
    return diffsusp.solve_statics(case.mech, case.loads)


@pytest.fixture(scope="module", params=CASES, ids=[f"{m}-{s}" for m, s in CASES])
def zoo_case(request) -> ZooCase:
    """Every zoo entry in turn (module scope: a test file's zoo checks run entry by entry)."""
    return zoo_case_of(*request.param)


@pytest.fixture(scope="module")
def zoo_solution(zoo_case):
    """The zoo entry and diffsusp's batched solve of its loads (one program per entry)."""
    return zoo_case, _solution(zoo_case.model, zoo_case.load_set)
