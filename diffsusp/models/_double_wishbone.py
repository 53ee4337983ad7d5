"""Chrono::Vehicle's generic double wishbone (data/vehicle/generic/suspension/DoubleWishbone.json).

The hardpoints, spring rate and free length below are read from Project Chrono's vehicle data
set, file `data/vehicle/generic/suspension/DoubleWishbone.json` ("Generic DoubleWishbone"),
Copyright (c) 2014 projectchrono.org, distributed under the BSD-3-Clause license
(http://projectchrono.org/license-chrono.txt); a copy is in /work/shared/data/chrono/. Values
are converted from metres to millimetres and N/m to N/mm; frame as Chrono's suspension
subsystem: x forward, y to the left, z up; the left side.
"""

import numpy as np

from ..model import Mechanism, MechanismBuilder
from ..model.corner import Corner

__all__ = ["DOUBLE_WISHBONE_DESIGN_LOAD", "double_wishbone"]

_M_TO_MM = 1000.0

# DoubleWishbone.json, in metres (Chrono suspension frame, left side).
_CHRONO_POINTS_M = {
    "spindle": (-0.040, 1.100, -0.026),  # Spindle/COM = wheel centre
    "upright": (-0.040, 0.880, -0.026),  # Upright/COM
    "uca_chassis_front": (-0.160, 0.539, 0.243),
    "uca_chassis_back": (-0.339, 0.587, 0.249),
    "uca_upright": (-0.088, 0.808, 0.243),
    "lca_chassis_front": (0.199, 0.479, -0.206),
    "lca_chassis_back": (-0.279, 0.539, -0.200),
    "lca_upright": (-0.040, 0.898, -0.265),
    "tierod_chassis": (-0.279, 0.479, -0.026),
    "tierod_upright": (-0.220, 0.898, -0.026),
    "spring_chassis": (-0.064, 0.659, 0.094),
    "spring_arm": (-0.040, 0.718, -0.206),
    "shock_chassis": (-0.088, 0.599, 0.393),
    "shock_arm": (-0.040, 0.718, -0.206),
}

HARDPOINTS = {name: tuple(_M_TO_MM * v for v in xyz) for name, xyz in _CHRONO_POINTS_M.items()}
"""Chrono generic DoubleWishbone hardpoints (mm; x forward, y left, z up; left side)."""

SPRING_RATE = 369149.0 / _M_TO_MM
"""`Spring Coefficient` 369149 N/m = 369.149 N/mm."""
SPRING_FREE_LENGTH = 0.356 * _M_TO_MM
"""`Free Length` 0.356 m = 356 mm."""

LOADED_RADIUS = 330.0
"""Chosen loaded tyre radius (mm): the contact patch is this far below the wheel centre (the
JSON's spindle `Radius` 0.15 m is the spindle's drawing size, not a tyre)."""

BUSHING_K_TRANS = 5000.0
"""Default translational stiffness (N/mm) of the control-arm bushings (`bushings=True`)."""
BUSHING_K_ROT = 1.0e8
"""Default rotational stiffness (N·mm/rad) of the control-arm bushings about the two axes the
revolute locks (`bushings=True`); 0 about the pivot axis. One bushing stands for the pair at
the front and back chassis points (185 mm apart on the upper arm, 482 mm on the lower one),
whose tilting stiffness is k_radial·d²/2 ≈ 5000·185²/2 = 8.6e7 and 5.8e8 N·mm/rad; 1e8 is of
that order. (A much softer 1e6 lets the arms tilt 30–50° under the design load, far beyond the
projected angles' 15° validity, and the equilibria do not converge.)"""

BUMP_STOP = dict(length=575.0, k=200.0, cubic=4.0)
"""Bump stop of `double_wishbone(stops=True)` on the shock length |shock_chassis − shock_arm|
(mm, N/mm, N/mm³): engaged below 575 mm, 37.6 mm of shock compression from the design length
612.6 mm (about +75 mm of wheel travel; the shock moves ≈ 0.5 mm per mm of wheel travel),
force 200·p + 4·p³ N (6 kN at 10 mm, 36 kN at 20 mm of penetration). Chosen: the JSON has
no stop data."""

REBOUND_STOP = dict(length=662.0, k=400.0, cubic=8.0)
"""Rebound stop of `double_wishbone(stops=True)` on the shock length (mm, N/mm, N/mm³): engaged
above 662 mm, 49.4 mm of shock extension (about −100 mm of wheel travel), force
400·p + 8·p³ N. Chosen: the JSON has no stop data."""

DOUBLE_WISHBONE_DESIGN_LOAD = 9018.1007
"""Vertical contact-patch load (N) for which the design position is the equilibrium of the
revolute model (see `double_wishbone`)."""


def pivot_frame(front, back, outer) -> np.ndarray:
    """Chrono's revolute frame: z along front − back, y normal to the arm's plane."""
    front, back, outer = (np.asarray(v, dtype=float) for v in (front, back, outer))
    v = np.cross(back - outer, front - outer)
    v /= np.linalg.norm(v)
    w = front - back
    w /= np.linalg.norm(w)
    u = np.cross(v, w)
    return np.column_stack([u, v, w])


def double_wishbone(bushings: bool = False, wheel_travel: bool = False, *,
                    bushing_k_trans: float = BUSHING_K_TRANS,
                    bushing_k_rot: float = BUSHING_K_ROT, stops: bool = False) -> Mechanism:
    """The Chrono::Vehicle generic double wishbone, left side, as a K&C half axle.

    **Source:** Project Chrono, `data/vehicle/generic/suspension/DoubleWishbone.json`
    (BSD-3-Clause, see the module docstring), with the topology of Chrono's `ChDoubleWishbone`
    template as summarised in /work/shared/data/chrono/README.md and checked against
    `ChDoubleWishbone::InitializeSide`.

    **Frame:** Chrono suspension subsystem frame: x forward, y to the left, z up; mm; left side
    (y > 0). The JSON positions are the design position q = 0.

    **Parts:** `'upper_control_arm'`, `'lower_control_arm'`, `'upright'`. The spindle is merged
    into the upright (on a K&C rig the spin is locked, so statically it is rigid on the
    upright). n = 18 coordinates.

    **Joints and elements:**

    - `'uca_pivot'`, `'lca_pivot'`: each control arm pivots on the chassis (ground) by a revolute
      at the midpoint of its `Location Chassis Front` and `Back` points, frame as Chrono's:
      z along Front − Back, y normal to the arm's plane (Back − Upright) × (Front − Upright),
      x = y × z. Markers: I on the ground, J on the arm.
    - `'uca_ball_joint'`, `'lca_ball_joint'`: spherical joints arm ↔ upright at
      `Location Upright`.
    - `'tie_rod'`: distance joint (massless link, Chrono's `ChLinkDistance` when the JSON gives
      no tie-rod mass) between `Tierod/Location Chassis` on the ground (steering fixed) and
      `Tierod/Location Upright` on the upright.
    - `'spring'`: linear, k = 369149 N/m = 369.149 N/mm, free length 0.356 m = 356 mm, between
      `Spring/Location Chassis` (ground) and `Location Arm` (lower arm). Its design length is
      306.69 mm, i.e. compressed 49.31 mm (18.2 kN). The shock carries no static load and is
      not modelled.
    - With `bushings=True` each revolute becomes bushing `'uca_bushing'` / `'lca_bushing'` at
      the same place and frame (I on the ground, J on the arm; Chrono's `Bushing Data` use),
      with `bushing_k_trans` N/mm on the three translations (default 5000, radial and axial),
      `bushing_k_rot` N·mm/rad on the two rotations the revolute locks (x, y; default 1e8, see
      `BUSHING_K_ROT` for why) and 0 about the pivot axis z. These stiffnesses are chosen (the
      JSON has no `Bushing Data`).

    **Markers and loads:** `'wheel_centre'` on the upright at `Spindle/COM` (−40, 1100, −26)
    with x rearward, y up, z outboard (+y, the spin axis); load point `'contact_patch'` on the
    upright straight below it at the chosen loaded radius 330 mm, (−40, 1100, −356), global
    components (F_long → x = forward here, F_lat → y = to the left, i.e. outboard on this left
    wheel, F_vert → +z); load point `'wheel_centre'` at the wheel centre marker, global
    components. Hardpoint markers carry the JSON names in snake case
    (`'uca_upright'`, `'lca_chassis_front'`, ...), each on the part it belongs to (chassis
    points on the ground). With `wheel_travel=True`, driver `'wheel_travel'` prescribes the
    wheel centre's global z travel (mm).

    **Structure:** revolute version: 17 joint rows (5 + 5 + 3 + 3 + 1), rank 17, 1 kinematic
    DOF (wheel travel, held by the spring); with the driver 18 rows, rank 18, 0 DOF. Bushing
    version: 7 rows (3 + 3 + 1), rank 7, 11 DOF held by the bushings and the spring; with the
    driver 8 rows, rank 8, 10 DOF. No redundant row, no free mode.

    **Design load:** with the revolutes, the design position is exactly the equilibrium under a
    vertical contact-patch load `DOUBLE_WISHBONE_DESIGN_LOAD` = 9018.1 N: the spring preload
    seen at the wheel, F = −Lᵀ Q_spring / Lᵀ Q_unit with L the (one-column) null space of Φ_q
    at design, Q_spring the design generalised force of the spring and Q_unit that of a 1 N
    vertical contact-patch force (solve_statics then returns q = 0 in 0 iterations). It is a
    heavy corner (≈ 920 kg): the JSON's design position is not a static ride height. With
    bushings (defaults) the same load moves the wheel centre by (1.0, 0.2, 3.5) mm, because
    the joint reactions (the lower bushing carries most of the 18 kN spring force) now deflect
    the bushings. Wheel rate about the design position ≈ 88 N/mm (revolute model).

    **Stops** (`stops=True`): a bump stop `'bump_stop'` and a rebound stop `'rebound_stop'` on
    the shock (damper) line, `shock_chassis` (ground) to `shock_arm` (lower arm), where an
    Adams/Car template puts them: bump stop engaged below 575 mm (37.6 mm of shock compression
    from the 612.6 mm design length, about +75 mm of wheel travel), 200·p + 4·p³ N; rebound stop
    engaged above 662 mm (49.4 mm of extension, about −100 mm of wheel travel), 400·p + 8·p³ N
    (`BUMP_STOP`, `REBOUND_STOP`; the shock moves about 0.5 mm per mm of wheel travel, so the
    laws are four times softer at the wheel). Neither is engaged at the design load.

    **Arguments:**

    - `bushings`: replace the two control-arm revolutes by six-axis bushings.
    - `wheel_travel`: add the wheel-travel driver.
    - `bushing_k_trans`: bushing translational stiffness (N/mm), with `bushings=True`.
    - `bushing_k_rot`: bushing rotational stiffness about the two locked axes (N·mm/rad).
    - `stops`: add the bump and rebound stops on the shock line.

    **Returns:** the `Mechanism`.
    """
    p = HARDPOINTS
    b = MechanismBuilder(
        "Chrono generic double wishbone" + (" (bushings)" if bushings else "")
        + (" (wheel travel)" if wheel_travel else "") + (" (stops)" if stops else "")
    )
    for part in ("upper_control_arm", "lower_control_arm", "upright"):
        b.part(part)

    for arm, prefix in (("upper_control_arm", "uca"), ("lower_control_arm", "lca")):
        front, back = p[f"{prefix}_chassis_front"], p[f"{prefix}_chassis_back"]
        outer = p[f"{prefix}_upright"]
        b.marker(f"{prefix}_chassis_front", "ground", front)
        b.marker(f"{prefix}_chassis_back", "ground", back)
        b.marker(f"{prefix}_upright", "upright", outer)
        centre = 0.5 * (np.asarray(front) + np.asarray(back))
        frame = pivot_frame(front, back, outer)
        if bushings:
            b.bushing(f"{prefix}_bushing", parts=("ground", arm), at=centre, orientation=frame,
                      k_trans=bushing_k_trans, k_rot=(bushing_k_rot, bushing_k_rot, 0.0))
        else:
            b.joint(f"{prefix}_pivot", "revolute", parts=("ground", arm), at=centre,
                    orientation=frame)
        b.joint(f"{prefix}_ball_joint", "spherical", parts=(arm, "upright"), at=outer)

    b.marker("tierod_chassis", "ground", p["tierod_chassis"])
    b.marker("tierod_upright", "upright", p["tierod_upright"])
    b.joint("tie_rod", "distance", "tierod_chassis", "tierod_upright")
    b.marker("spring_chassis", "ground", p["spring_chassis"])
    b.marker("spring_arm", "lower_control_arm", p["spring_arm"])
    b.spring("spring", "spring_chassis", "spring_arm", k=SPRING_RATE,
             free_length=SPRING_FREE_LENGTH)
    b.marker("shock_chassis", "ground", p["shock_chassis"])
    b.marker("shock_arm", "lower_control_arm", p["shock_arm"])
    if stops:
        b.stop("bump_stop", "shock_chassis", "shock_arm", kind="bump", **BUMP_STOP)
        b.stop("rebound_stop", "shock_chassis", "shock_arm", kind="rebound", **REBOUND_STOP)

    x, y, z = p["spindle"]
    b.marker("wheel_centre", "upright", (x, y, z), z=(0.0, 1.0, 0.0), x=(-1.0, 0.0, 0.0))
    b.load_point("contact_patch", part="upright", at=(x, y, z - LOADED_RADIUS))
    b.load_point("wheel_centre", marker="wheel_centre")
    if wheel_travel:
        b.driver("wheel_travel", marker="wheel_centre", direction=(0.0, 0.0, 1.0))
    b.corner(corner())
    return b.build()


def corner():
    """The wheel (`diffsusp.model.corner.Corner`): ISO frame (x forward, y left), the left side,
    spin axis +y, contact patch `LOADED_RADIUS` below the wheel centre, steering axis through
    the two ball joints, design load `DOUBLE_WISHBONE_DESIGN_LOAD` (the Chrono importer
    attaches the same corner to the file, with the design load computed: None)."""
    return Corner(kingpin=("uca_upright", "lca_upright"), side="left", frame="iso",
                  loaded_radius=LOADED_RADIUS, design_load=DOUBLE_WISHBONE_DESIGN_LOAD)
