"""The crank-slider (bielle-manivelle) of the thesis's direct-method validation (spec stiffness
§1.12b, §7 R2)."""

import math

from ..geometry import DEG
from ..model import Mechanism, MechanismBuilder

CRANK_LENGTH = 100.0
"""Crank radius (mm): revolute axis at the origin to the crank pin."""
ROD_LENGTH = 300.0
"""Connecting rod length (mm): crank pin to slider pin."""
CRANK_ANGLE_DEG = 60.0
"""Crank angle at design, from global x about global z (deg)."""


def crank_slider(k_trans: float = 10000.0, k_rot_deg: float = 10000.0) -> Mechanism:
    """A planar crank-slider whose slider is held by a translational joint and a bushing.

    **Source:** spec "suspension_stiffness_identification" §1.12b (fig. 4.7, lost) and §7 R2.
    The topology is the thesis's; the geometry is not given there and is chosen here.

    **Frame:** global, mm; the mechanism lies in the plane z = 0.

    **Parts and joints (as in the thesis):**

    - S1 `'crank'` on the ground through revolute `'crank_pivot'` at the origin, axis global z;
    - S2 `'rod'` linked to S1 by spherical joint `'crank_ball_joint'` and to S3 by revolute
      `'slider_pin'` (axis global z);
    - S3 `'slider'` on the ground through translational joint `'slide'` (axis global x) AND
      bushing `'slider_bushing'` (I on the ground, J on the slider, axes = global axes, so
      its x is the slider axis), `k_trans` N/mm and `k_rot_deg` N·mm/deg (converted to
      N·mm/rad) on every axis (thesis: 10 000 and 10 000).

    **Chosen geometry:** crank radius 100 mm at 60° from x, crank pin at (50, 86.603, 0);
    rod 300 mm; slider pin on the x axis at (50 + √(300² − 86.603²), 0, 0) =
    (337.228, 0, 0). Generic (not a dead centre), so the 1-DOF motion is regular.

    **Structure:** 18 joint rows (5 + 3 + 5 + 5) for n = 18 coordinates, rank 17, 1 kinematic
    DOF (the slider translation, with the crank and rod following). One row is redundant
    because the closed planar loop fixes the out-of-plane motions twice: the slider's spin about
    its axis is already locked by the loop (slider–rod revolute → rod; the rod cannot tilt about
    x without lifting the crank pin out of the crank's plane). Scanning rows in joint order,
    `validate` reports the slide's last row (x_I·y_J, the anti-spin row) as the redundant one and
    it is dropped from the solve (its reaction is carried by the other rows). The bushing gives
    the stiffness of the DOF; the slider cannot move in its other five directions, so they
    never deform and only the slider-axis stiffness Ktx is identifiable.

    **Load point:** `'crank_pin'` on the crank at the spherical joint, global components.

    **Returns:** the `Mechanism`.
    """
    angle = CRANK_ANGLE_DEG * DEG
    pin = (CRANK_LENGTH * math.cos(angle), CRANK_LENGTH * math.sin(angle), 0.0)
    slider_x = pin[0] + math.sqrt(ROD_LENGTH**2 - pin[1] ** 2)
    slider = (slider_x, 0.0, 0.0)

    b = MechanismBuilder("crank-slider")
    for part in ("crank", "rod", "slider"):
        b.part(part)
    b.joint("crank_pivot", "revolute", parts=("crank", "ground"), at=(0.0, 0.0, 0.0),
            z=(0.0, 0.0, 1.0))
    b.joint("crank_ball_joint", "spherical", parts=("rod", "crank"), at=pin)
    b.joint("slider_pin", "revolute", parts=("rod", "slider"), at=slider, z=(0.0, 0.0, 1.0))
    b.joint("slide", "translational", parts=("slider", "ground"), at=slider,
            z=(1.0, 0.0, 0.0), x=(0.0, 1.0, 0.0))
    b.bushing("slider_bushing", parts=("ground", "slider"), at=slider,
              k_trans=k_trans, k_rot=k_rot_deg / DEG)
    b.load_point("crank_pin", part="crank", at=pin)
    return b.build()
