"""The Chrono generic double wishbone with each control arm on a *pair* of bushings (geometric
identification of a bushing pair, spec geometry §4.5a / the thesis's §3.2.4.1).

Hardpoints: `diffsusp.models.double_wishbone.HARDPOINTS` (Project Chrono's
`data/vehicle/generic/suspension/DoubleWishbone.json`, BSD-3-Clause, see that module), mm,
Chrono's suspension frame (x forward, y to the left, z up), the left side.
"""


from ..model import Mechanism, MechanismBuilder
from ._double_wishbone import (
    HARDPOINTS,
    LOADED_RADIUS,
    SPRING_FREE_LENGTH,
    SPRING_RATE,
    pivot_frame,
)

PAIR_K_RADIAL = 5000.0
"""Radial stiffness (N/mm, x and y of each bushing frame) of the pair bushings. Chosen."""
PAIR_K_AXIAL = 1000.0
"""Axial stiffness (N/mm, along the pair's axis) of each bushing. Chosen."""
PAIR_K_TILT = 1.0e6
"""Rotational stiffness (N·mm/rad) of each bushing about its two radial axes. Chosen."""


def double_wishbone_bushing_pairs(spring: bool = False, *, k_torsion: float = 0.0,
                                  k_radial: float = PAIR_K_RADIAL,
                                  k_axial: float = PAIR_K_AXIAL,
                                  k_tilt: float = PAIR_K_TILT) -> Mechanism:
    """Chrono's generic double wishbone, left side, each control arm held to the chassis by two
    bushings, at `Location Chassis Front` and `Back`, with a wheel-travel driver.

    **Frame:** Chrono suspension frame (x forward, y left, z up), mm; design position q = 0.

    **Parts:** `'upper_control_arm'`, `'lower_control_arm'`, `'upright'` (spindle merged);
    n = 18 coordinates.

    **Elements:** bushings `'uca_front'`, `'uca_back'`, `'lca_front'`, `'lca_back'` (I on the
    ground, J on the arm, at the chassis points), frame z along Front − Back (the pair's axis,
    the revolute axis of `double_wishbone`), stiffness `k_radial` on x and y, `k_axial` on z,
    `k_tilt` about x and y and `k_torsion` about z (default 0); spherical joints
    `'uca_ball_joint'`, `'lca_ball_joint'` (arm ↔ upright), distance joint `'tie_rod'` (chassis
    ↔ upright, steering fixed); driver `'wheel_travel'` (the wheel centre's global z, mm);
    with `spring=True` the spring `'spring'` of `double_wishbone` (369.149 N/mm, free length
    356 mm, lower arm ↔ chassis). Markers `'wheel_centre'` and load points `'contact_patch'`
    (330 mm below the wheel centre, global components) and `'wheel_centre'`, as in
    `double_wishbone`.

    **Assumptions** (chosen: the JSON has no bushing data): the stiffnesses above. With the
    default `spring=False` and `k_torsion=0` nothing loads a bushing under the wheel-travel
    driver alone (the arms turn freely about their pair's axis, the only force-free motion of
    the pair), so every equilibrium is the kinematic one and each arm turns exactly about the
    line through its two bushing centres: the reference for the bushing-pair solver, whose
    axis must then be exact. With loads, a spring or torsional stiffness the bushings deflect
    and the axis is only approximately fixed (spec geometry §4.5a: "other deformations are
    small").

    **Structure:** 7 joint rows (3 + 3 + 1) and the driver: 8 rows, rank 8; 10 DOF held by the
    bushings (and the spring).

    **Returns:** the `Mechanism`.
    """
    p = HARDPOINTS
    b = MechanismBuilder("Chrono generic double wishbone (bushing pairs)"
                         + (" (spring)" if spring else ""))
    for part in ("upper_control_arm", "lower_control_arm", "upright"):
        b.part(part)
    for arm, prefix in (("upper_control_arm", "uca"), ("lower_control_arm", "lca")):
        front, back = p[f"{prefix}_chassis_front"], p[f"{prefix}_chassis_back"]
        outer = p[f"{prefix}_upright"]
        frame = pivot_frame(front, back, outer)  # z along the pair's axis
        for end, at in (("front", front), ("back", back)):
            b.bushing(f"{prefix}_{end}", parts=("ground", arm), at=at, orientation=frame,
                      k_trans=(k_radial, k_radial, k_axial), k_rot=(k_tilt, k_tilt, k_torsion))
        b.marker(f"{prefix}_upright", "upright", outer)
        b.joint(f"{prefix}_ball_joint", "spherical", parts=(arm, "upright"), at=outer)
    b.marker("tierod_chassis", "ground", p["tierod_chassis"])
    b.marker("tierod_upright", "upright", p["tierod_upright"])
    b.joint("tie_rod", "distance", "tierod_chassis", "tierod_upright")
    if spring:
        b.marker("spring_chassis", "ground", p["spring_chassis"])
        b.marker("spring_arm", "lower_control_arm", p["spring_arm"])
        b.spring("spring", "spring_chassis", "spring_arm", k=SPRING_RATE,
                 free_length=SPRING_FREE_LENGTH)
    x, y, z = p["spindle"]
    b.marker("wheel_centre", "upright", (x, y, z), z=(0.0, 1.0, 0.0), x=(-1.0, 0.0, 0.0))
    b.load_point("contact_patch", part="upright", at=(x, y, z - LOADED_RADIUS))
    b.load_point("wheel_centre", marker="wheel_centre")
    b.driver("wheel_travel", marker="wheel_centre", direction=(0.0, 0.0, 1.0))
    return b.build()
