"""The thesis's pseudo-McPherson half axle with a real tie rod and a steering rack (spec geometry
§4.7, §5 item 3; stiffness §1.13; CORRECTIONS 16)."""

import numpy as np

from ..model import Mechanism, MechanismBuilder
from ._pseudo_mcpherson import (
    LOADED_RADIUS,
    PSEUDO_MCPHERSON_JOINTS,
    PSEUDO_MCPHERSON_REULER_DEG,
    SPRING_FREE_LENGTH,
    SPRING_RATE,
    add_arm_markers,
    add_bushings,
    add_hub_markers,
    corner,
)

RACK_AXIS = (0.0, 1.0, 0.0)
"""Direction of the steering rack's slide (global; the thesis's numerical model: along y)."""

__all__ = ["RACK_AXIS", "pseudo_mcpherson_steering"]


def _cross_axes(e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors orthogonal to each other and to `e` (the universal joint's pins)."""
    z_rack = np.cross(e, (0.0, 0.0, 1.0))
    z_rack /= np.linalg.norm(z_rack)
    z_rod = np.cross(e, z_rack)
    return z_rod / np.linalg.norm(z_rod), z_rack


def pseudo_mcpherson_steering(*, strut: bool = True, rack: bool = True,
                              wheel_travel: bool = False,
                              spring_free_length: float = SPRING_FREE_LENGTH) -> Mechanism:
    """The pseudo-McPherson half axle of `pseudo_mcpherson` with the tie rod as a part and an
    optional steering rack: the structure the geometric identification observes.

    **Source:** spec geometry §4.7 (Chapter 3's numerical model: landmarks on front arm, rear arm,
    tie rod and hub carrier; 5 wheel heights and 5 rack positions), §5 item 3 (hardpoints of
    Table 2.2, rack along y), spec stiffness §1.13 (n = 24 identification structure),
    CORRECTIONS 16 (the built-in model's tie rod is a distance link; this variant makes it a
    part). Geometry, stiffnesses (Table 2.1) and spring are those of `pseudo_mcpherson`.

    **Frame:** Adams/Car (x rearward, y right, z up), left wheel, mm; q = 0 is Table 2.2.

    **Parts:** `'front_arm'`, `'rear_arm'`, `'tie_rod'`, `'hub_carrier'`, and with `strut=True`
    `'strut'`, with `rack=True` `'rack'`.

    **Joints and elements:**

    - bushings A (L2, ground ↔ rear arm), B (L1, ground ↔ front arm) as in `pseudo_mcpherson`;
    - `'front_ball_joint'` (L8), `'rear_ball_joint'` (L7): spherical, arm ↔ hub carrier;
    - `'tie_rod_outer'` (L6): spherical, tie rod ↔ hub carrier;
    - `'tie_rod_inner'` (L3): **universal**, tie rod ↔ rack (or ground without a rack).
      *Assumption:*
      the physical joint is a ball joint, but with ball joints at both ends the tie rod spins
      freely about its own axis (a mode with neither stiffness nor constraint, which a static
      solver cannot hold); a universal joint whose two pins are orthogonal to the tie rod and to
      each other removes only that spin. Both joints keep their centre fixed on both parts, so
      every joint centre moves exactly as with two ball joints.
    - with `rack=True`: `'rack_slide'`, translational, rack ↔ ground along `RACK_AXIS` at L3, and
      driver `'rack_travel'` (mm along +y) prescribing the rack's travel from design.
    - with `strut=True`: strut, bushing F (L4), translational strut slide (L5) and spring
      L4–L5 as in `pseudo_mcpherson`. With `strut=False` (the simplified structure of spec
      stiffness §1.13: the strut rod cannot be measured), the hub carrier is held by an
      `'strut_line'` **inline** joint (point-on-line: the ground point L4 stays on the hub
      carrier's line through L4 along the strut axis, z of REULER L5; *assumption*: the line
      passes through L4, which Table 2.2 puts 2.5 mm off the L5 axis) and the spring acts
      between L4 on the ground and L5 on the hub carrier.

    **Structure:** with `strut=False, rack=False`: n = 24 (four parts), m = 15 rows: spec
    stiffness §1.13 counts m = 14 with four ball joints, leaving the tie-rod spin free; the
    universal joint's extra row holds it. The default (`strut=True, rack=True`): n = 36, 23 joint
    rows and the `'rack_travel'` driver, 12 DOF (plus the `'wheel_travel'` driver with
    `wheel_travel=True`).

    **Loads:** load points `'contact_patch'` (0, −787, 0) and `'wheel_centre'` (L9), global
    components (as `pseudo_mcpherson`; `thesis_load_cases` applies).

    **Markers:** as `pseudo_mcpherson`, plus `'L3_tie_rod_inner'` and `'L6_tie_rod_outer_rod'`
    on the tie rod, `'L3_rack'` on the rack (or ground).

    **Arguments:** `strut`, `rack`, `wheel_travel` (add the wheel-centre vertical travel driver,
    mm), `spring_free_length` (mm).

    **Returns:** the validated `Mechanism`.
    """
    p, e = PSEUDO_MCPHERSON_JOINTS, PSEUDO_MCPHERSON_REULER_DEG
    name = "pseudo-McPherson half axle, tie rod and rack" if rack else \
        "pseudo-McPherson half axle, tie rod"
    b = MechanismBuilder(name + ("" if strut else ", strut removed")
                         + (" (wheel travel)" if wheel_travel else ""))
    parts = ["front_arm", "rear_arm", "tie_rod", "hub_carrier"]
    parts += ["strut"] if strut else []
    parts += ["rack"] if rack else []
    for part in parts:
        b.part(part)
    inner_side = "rack" if rack else "ground"

    add_arm_markers(b)
    b.marker("L3_tie_rod_inner", "tie_rod", p["L3"])
    b.marker("L6_tie_rod_outer_rod", "tie_rod", p["L6"])
    b.marker("L3_rack", inner_side, p["L3"])
    if strut:
        b.marker("L4_strut_top", "strut", p["L4"], reuler_deg=e["L4"])
    add_hub_markers(b)
    add_bushings(b, ("bushing_B", "bushing_A") + (("bushing_F",) if strut else ()))

    axis = np.subtract(p["L6"], p["L3"])
    z_rod, z_rack = _cross_axes(axis / np.linalg.norm(axis))
    b.marker("tie_rod_inner.i", "tie_rod", p["L3"], z=z_rod, x=axis)
    b.marker("tie_rod_inner.j", inner_side, p["L3"], z=z_rack, x=axis)
    b.joint("tie_rod_inner", "universal", "tie_rod_inner.i", "tie_rod_inner.j")
    b.joint("tie_rod_outer", "spherical", parts=("tie_rod", "hub_carrier"), at=p["L6"])
    if rack:
        b.joint("rack_slide", "translational", parts=("rack", "ground"), at=p["L3"],
                z=RACK_AXIS, x=(1.0, 0.0, 0.0))
        b.driver("rack_travel", marker="L3_rack", direction=RACK_AXIS)
    if strut:
        b.joint("strut_slide", "translational", parts=("strut", "hub_carrier"), at=p["L5"],
                reuler_deg=e["L5"])
        b.spring("spring", parts=("strut", "hub_carrier"), at=(p["L4"], p["L5"]),
                 k=SPRING_RATE, free_length=spring_free_length)
    else:
        b.marker("strut_line.i", "ground", p["L4"])
        b.marker("strut_line.j", "hub_carrier", p["L4"], reuler_deg=e["L5"])
        b.joint("strut_line", "inline", "strut_line.i", "strut_line.j")
        b.spring("spring", parts=("ground", "hub_carrier"), at=(p["L4"], p["L5"]),
                 k=SPRING_RATE, free_length=spring_free_length)
    b.joint("rear_ball_joint", "spherical", parts=("rear_arm", "hub_carrier"), at=p["L7"])
    b.joint("front_ball_joint", "spherical", parts=("front_arm", "hub_carrier"), at=p["L8"])

    x9, y9, z9 = p["L9"]
    b.load_point("contact_patch", part="hub_carrier", at=(x9, y9, z9 - LOADED_RADIUS))
    b.load_point("wheel_centre", marker="wheel_centre")
    b.corner(corner(strut=strut))
    if wheel_travel:
        b.driver("wheel_travel", marker="wheel_centre", direction=(0.0, 0.0, 1.0))
    return b.build()
