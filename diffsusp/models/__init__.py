"""Built-in reference mechanisms: the thesis's validation cases and generic axles.

Each builder returns a validated `Mechanism` whose docstring states its source, frame, and
every assumption or reconstructed value. Units: mm, N, N·mm, rad.

- `isolated_bushing`: one arm on one bushing (Adams `model_exemple11`, closed form).
- `crank_slider`: crank-slider with a redundant constraint and a slider bushing.
- `two_bushing_coupler`: two links on bushings joined by a coupler (parallel Krx/Kry).
- `pseudo_mcpherson`: the thesis's K&C test half axle (Tables 2.1, 2.2).
- `double_wishbone`: Chrono::Vehicle's generic double wishbone (JSON hardpoints).
- `pseudo_mcpherson_steering`: the same half axle with the tie rod as a part and a steering
  rack (geometric identification, spec geometry §4.7).
- `front_axle_table_3_3`: the chapter 3 full-vehicle front axle, ideal joints (kinematic).

`ZOO` maps a name to a zero-argument builder, for parametrised tests. `STOP_VARIANTS` maps
the names of the axles built with bump and rebound stops (`stops=True`, Adams/Car-style, see
each builder) to their builders: use them for loads over the whole K&C envelope; the stop-free
models are the thesis's reference models.
"""

from collections.abc import Callable

from ..model import Mechanism
from ._crank_slider import crank_slider
from ._double_wishbone import DOUBLE_WISHBONE_DESIGN_LOAD, double_wishbone
from ._double_wishbone_bushing_pairs import double_wishbone_bushing_pairs
from ._front_axle_table_3_3 import (
    TABLE_3_3_AXES,
    TABLE_3_3_CENTRES,
    TABLE_3_3_WHEEL_CENTRE,
    front_axle_table_3_3,
)
from ._isolated_bushing import isolated_bushing
from ._pseudo_mcpherson import (
    PSEUDO_MCPHERSON_JOINTS,
    PSEUDO_MCPHERSON_REULER_DEG,
    pseudo_mcpherson,
)
from ._pseudo_mcpherson_steering import RACK_AXIS, pseudo_mcpherson_steering
from ._two_bushing_coupler import two_bushing_coupler
from .loadcases import TABLE_4_4, TABLE_5_1, thesis_load_cases

ZOO: dict[str, Callable[[], Mechanism]] = {
    "isolated_bushing": isolated_bushing,
    "isolated_bushing_10000": lambda: isolated_bushing(k_trans=10000.0),
    "crank_slider": crank_slider,
    "two_bushing_coupler": two_bushing_coupler,
    "pseudo_mcpherson": pseudo_mcpherson,
    "pseudo_mcpherson_wheel_travel": lambda: pseudo_mcpherson(wheel_travel=True),
    "double_wishbone": double_wishbone,
    "double_wishbone_bushings": lambda: double_wishbone(bushings=True),
}
"""Name → zero-argument builder of every built-in model variant."""

STOP_VARIANTS: dict[str, Callable[[], Mechanism]] = {
    "pseudo_mcpherson_stops": lambda: pseudo_mcpherson(stops=True),
    "double_wishbone_stops": lambda: double_wishbone(stops=True),
    "double_wishbone_bushings_stops": lambda: double_wishbone(bushings=True, stops=True),
}
"""Name → zero-argument builder of the axles with bump and rebound stops."""

__all__ = [
    "DOUBLE_WISHBONE_DESIGN_LOAD", "STOP_VARIANTS", "TABLE_4_4", "TABLE_5_1", "ZOO",
    "crank_slider",
    "double_wishbone", "front_axle_table_3_3", "isolated_bushing", "pseudo_mcpherson",
    "double_wishbone_bushing_pairs",
    "pseudo_mcpherson_steering", "thesis_load_cases", "two_bushing_coupler",
    "PSEUDO_MCPHERSON_JOINTS", "PSEUDO_MCPHERSON_REULER_DEG", "RACK_AXIS", "TABLE_3_3_AXES",
    "TABLE_3_3_CENTRES", "TABLE_3_3_WHEEL_CENTRE",
]
