"""The thesis's K&C load-case tables (spec stiffness §1.13, §2.7) and their mapping to `Loads`:
the tables the K&C load-table event runs (`diffsusp.kc.TABLES`)."""

import jax.numpy as jnp
import numpy as np
from jaxtyping import Float

from ..model import Loads, Mechanism

__all__ = ["TABLE_4_4", "TABLE_5_1", "thesis_load_cases"]

TABLE_5_1 = np.array(
    [
        [1500.0, 0.0, 0.0],
        [3000.0, 0.0, 0.0],
        [4500.0, 0.0, 0.0],
        [6000.0, 0.0, 0.0],
        [7500.0, 0.0, 0.0],
        [4500.0, -4000.0, 0.0],
        [4500.0, -2000.0, 0.0],
        [4500.0, 2000.0, 0.0],
        [4500.0, 4000.0, 0.0],
        [4500.0, 0.0, -4000.0],
        [4500.0, 0.0, -2000.0],
        [4500.0, 0.0, 2000.0],
        [4500.0, 0.0, 4000.0],
    ]
)
"""Table 5-1 (spec stiffness §2.7): 13 load cases (F_vert, F_lat, F_long) in N, the Chapter 5
numerical validation on the pseudo-McPherson axle."""
TABLE_5_1.flags.writeable = False

TABLE_4_4 = np.array(
    [
        [1500.0, 0.0, 0.0],
        [3000.0, 0.0, 0.0],
        [4500.0, 0.0, 0.0],
        [6000.0, 0.0, 0.0],
        [7500.0, 0.0, 0.0],
        [4500.0, -1000.0, 0.0],
        [4500.0, 1000.0, 0.0],
        [3000.0, -1000.0, 0.0],
        [3000.0, 1000.0, 0.0],
        [6000.0, -1000.0, 0.0],
        [6000.0, 1000.0, 0.0],
        [4500.0, 0.0, -1000.0],
        [4500.0, 0.0, 1000.0],
        [3000.0, 0.0, -1000.0],
        [3000.0, 0.0, 1000.0],
        [6000.0, 0.0, -1000.0],
        [6000.0, 0.0, 1000.0],
    ]
)
"""Table 4.4 (spec stiffness §1.13): 17 K&C bench load cases (F_vert, F_lat, F_long) in N, the
Chapter 4 experimental validation on the pseudo-McPherson axle."""
TABLE_4_4.flags.writeable = False


def thesis_load_cases(
    mech: Mechanism,
    table: Float[np.ndarray, "cases 3"] = TABLE_5_1,
    point: str = "contact_patch",
) -> Loads:
    """Loads of a (F_vert, F_lat, F_long) table applied at one load point.

    Mapping (components in the load point's frame, global for the built-in models):
    F_long → x, F_lat → y, F_vert → z. In the Adams/Car frame of `pseudo_mcpherson` (x rearward,
    y right, z up) that is: vertical up, lateral to the right (inboard on the left wheel),
    longitudinal rearward (braking). Motion drivers, if any, are set to 0 and moments to 0.

    **Arguments:**

    - `mech`: the mechanism (must have a load point named `point`).
    - `table`: `(cases, 3)` array of (F_vert, F_lat, F_long) in N, e.g. `TABLE_5_1`,
      `TABLE_4_4`.
    - `point`: name of the load point.

    **Returns:** `Loads` with a leading axis of `cases`.
    """
    table = np.asarray(table, dtype=float)
    if table.ndim != 2 or table.shape[1] != 3:
        raise ValueError(
            f"table must have shape (cases, 3) with columns (F_vert, F_lat, F_long); got "
            f"{table.shape}."
        )
    force = jnp.asarray(table[:, [2, 1, 0]])
    return mech.loads(forces={point: force})
