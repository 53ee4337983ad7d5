"""K&C (kinematics and compliance) events and metrics, with exact derivatives.

```python
from diffsusp import kc
ev = kc.parallel_travel(mech, travel=jnp.linspace(-80, 80, 161))
ev.metrics["toe"], ev.metrics["bump_steer"]        # rad, rad/mm (internal units)
kc.derivative_metrics(ev)                          # the derivative subset
fz = kc.vertical_force(mech, fz=[3000.0, 4500.0, 6000.0])
kc.compliance_matrix(fz)                           # (cases, 6, 6) at the wheel centre
loads = kc.corner_loads(mech, kc.TABLES["table_5_1"])  # per-side table -> Loads, no event
```

Definitions and signs (Adams/Car, per side): `diffsusp.kc.metrics`. Which markers are the wheel:
`Corner` (stored with the model: `Mechanism.corners`). Events: `diffsusp.kc.events`.
"""

from .corner import Corner, ResolvedCorner, corners_of, default_corner, design_load
from .designs import DesignBatch, design_batch
from .events import (
    TABLES,
    KCEvent,
    Rig,
    aligning_torque,
    anti_pitch,
    braking,
    compliance_matrix,
    corner_loads,
    derivative_metrics,
    evaluate,
    force_rig,
    lateral_force,
    load_table,
    longitudinal_force,
    opposite_travel,
    parallel_travel,
    steering,
    traction,
    travel_rig,
    vertical_force,
)
from .metrics import (
    DERIVATIVE_METRICS,
    METRICS,
    Metric,
    corner_geometry,
    default_plots,
    display,
    display_unit,
    flagged,
)
from .rig import add_driver, remove_drivers, with_rack
from .second_order import HessianVectorProducts, Selection, hessian_vector_product, select

__all__ = [
    "DERIVATIVE_METRICS", "METRICS", "TABLES", "Corner", "DesignBatch", "HessianVectorProducts",
    "KCEvent", "Metric", "ResolvedCorner", "Rig", "Selection", "add_driver", "aligning_torque",
    "anti_pitch", "braking", "compliance_matrix", "corner_geometry", "corner_loads", "corners_of",
    "default_corner", "default_plots", "derivative_metrics", "design_batch", "design_load",
    "display", "display_unit", "evaluate", "flagged", "force_rig", "hessian_vector_product",
    "lateral_force", "load_table", "longitudinal_force", "opposite_travel", "parallel_travel",
    "remove_drivers", "select", "steering", "traction", "travel_rig", "vertical_force", "with_rack",
]
