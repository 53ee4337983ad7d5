"""The full-vehicle pseudo-McPherson front axle located in the thesis's chapter 3 (spec geometry
§4.9, Table 3.3): joint centres and axes only, for kinematic use."""

import numpy as np

from ..model import Mechanism, MechanismBuilder

TABLE_3_3_CENTRES = {
    "wishbone_ball_joint": (-7.91, -678.26, 183.22),
    "tie_rod_outer": (123.46, -658.40, 269.37),
    "drop_link_hub": (-21.97, -524.63, 567.92),
    "drop_link_bar": (-101.50, -484.74, 236.46),
    "tie_rod_inner": (174.59, -305.51, 275.20),
    "strut_top": (26.31, -563.21, 759.99),
    "wishbone_pivot": (177.00, -351.03, 195.11),
    "bar_pivot": (113.30, -453.73, 250.19),
}
"""Table 3.3 joint centres (mm, Adams/Car frame: x rearward, y right, z up; left wheel)."""

TABLE_3_3_AXES = {
    "strut_slide": (-0.020, -0.050, 0.999),
    "wishbone_pivot": (0.997, 0.081, 0.009),
    "bar_pivot": (-0.028, 1.000, 0.003),
    "rack_slide": (0.0, 1.0, 0.0),
}
"""Table 3.3 joint axes (unit directions as printed; the rack's was assumed a priori)."""

TABLE_3_3_WHEEL_CENTRE = (0.0, -740.0, 290.0)
"""Wheel centre on the hub carrier (mm): **not in the thesis**; an assumption (outboard of the
ball joints, about a loaded radius above the ground) for the wheel-travel driver only."""

__all__ = ["TABLE_3_3_AXES", "TABLE_3_3_CENTRES", "TABLE_3_3_WHEEL_CENTRE", "front_axle_table_3_3"]


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _pins(a, b):
    """Pins of a universal joint on the link a→b: orthogonal to it and to each other."""
    e = _unit(np.subtract(b, a))
    z1 = _unit(np.cross(e, (0.0, 0.0, 1.0)))
    return _unit(np.cross(e, z1)), z1, e


def _universal(b: MechanismBuilder, name: str, parts, at, toward) -> None:
    """A universal joint `name` at `at` between `parts` (the link's, then the other), its pins
    (`_pins`) set by the link from `at` to `toward`: markers `name.i`, `name.j`."""
    z_link, z_other, e = _pins(at, toward)
    b.marker(f"{name}.i", parts[0], at, z=z_link, x=e)
    b.marker(f"{name}.j", parts[1], at, z=z_other, x=e)
    b.joint(name, "universal", f"{name}.i", f"{name}.j")


def front_axle_table_3_3() -> Mechanism:
    """The left front pseudo-McPherson axle of the thesis's full-vehicle test (Table 3.3), with
    ideal joints only: a kinematic model (no bushing, spring or stiffness).

    **Source:** spec geometry §4.9, Table 3.3 (joint centres, and the axes of the strut, the two
    bushing pairs taken as revolute joints, and the rack assumed along y).

    **Frame:** Adams/Car (x rearward, y right, z up), mm; q = 0 is Table 3.3 (the reference
    attitude with 2 × 75 kg on the front seats).

    **Parts and joints:**

    - `'wishbone'`: revolute to the ground at `'wishbone_pivot'` (the two bushings as one
      revolute joint, Table 3.3 axis), spherical to the hub carrier at `'wishbone_ball_joint'`;
    - `'hub_carrier'` (with the strut tube): translational joint `'strut_slide'` with the
      `'strut'` rod along the Table 3.3 strut axis through the strut top (*assumption*: the
      cylinder axis passes through the strut-top centre; the joint is translational rather than
      cylindrical so that the rod does not spin freely); the rod is spherical to the ground at
      `'strut_top'` (the strut-top bushing taken as a ball joint, as the thesis does);
    - `'tie_rod'`: spherical to the hub carrier at `'tie_rod_outer'`, universal to the
      `'rack'` at `'tie_rod_inner'` (pins orthogonal to the rod: only its free spin is
      removed); the rack slides along y (`'rack_slide'`), driven by `'rack_travel'` (mm);
    - `'bar'` (anti-roll bar half): revolute to the ground at `'bar_pivot'` (its bushing pair);
    - `'drop_link'`: spherical to the hub carrier at `'drop_link_hub'`, universal to the bar at
      `'drop_link_bar'` (again removing the link's spin).

    **Drivers:** `'rack_travel'` (rack along +y, mm) and `'wheel_travel'` (vertical travel of
    the wheel centre, mm; the wheel centre `TABLE_3_3_WHEEL_CENTRE` is an assumption): with both,
    the model has no degree of freedom left (7 parts, 42 coordinates, 40 joint rows + 2
    drivers).

    **Returns:** the validated `Mechanism`.
    """
    c, ax = TABLE_3_3_CENTRES, TABLE_3_3_AXES
    b = MechanismBuilder("front axle, Table 3.3 (kinematic)")
    for part in ("wishbone", "hub_carrier", "strut", "tie_rod", "rack", "bar", "drop_link"):
        b.part(part)
    b.joint("wishbone_pivot", "revolute", parts=("wishbone", "ground"), at=c["wishbone_pivot"],
            z=_unit(ax["wishbone_pivot"]))
    b.joint("wishbone_ball_joint", "spherical", parts=("wishbone", "hub_carrier"),
            at=c["wishbone_ball_joint"])
    b.joint("strut_slide", "translational", parts=("strut", "hub_carrier"), at=c["strut_top"],
            z=_unit(ax["strut_slide"]))
    b.joint("strut_top", "spherical", parts=("strut", "ground"), at=c["strut_top"])
    b.joint("tie_rod_outer", "spherical", parts=("tie_rod", "hub_carrier"),
            at=c["tie_rod_outer"])
    _universal(b, "tie_rod_inner", ("tie_rod", "rack"), c["tie_rod_inner"], c["tie_rod_outer"])
    b.joint("rack_slide", "translational", parts=("rack", "ground"), at=c["tie_rod_inner"],
            z=ax["rack_slide"], x=(1.0, 0.0, 0.0))
    b.joint("bar_pivot", "revolute", parts=("bar", "ground"), at=c["bar_pivot"],
            z=_unit(ax["bar_pivot"]))
    b.joint("drop_link_hub", "spherical", parts=("drop_link", "hub_carrier"),
            at=c["drop_link_hub"])
    _universal(b, "drop_link_bar", ("drop_link", "bar"), c["drop_link_bar"], c["drop_link_hub"])
    b.marker("wheel_centre", "hub_carrier", TABLE_3_3_WHEEL_CENTRE, z=(0.0, -1.0, 0.0))
    b.marker("rack_end", "rack", c["tie_rod_inner"])
    b.driver("rack_travel", marker="rack_end", direction=(0.0, 1.0, 0.0))
    b.driver("wheel_travel", marker="wheel_centre", direction=(0.0, 0.0, 1.0))
    b.load_point("wheel_centre", marker="wheel_centre")
    return b.build()
