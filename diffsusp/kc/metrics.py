"""K&C metrics of a suspension corner at an equilibrium, with their definitions and signs.

Conventions (Adams/Car, SAE J670 / ISO 8855 angles, per side; DESIGN.md "Conventions"): every
metric is defined from the vehicle's axes — forward f, outboard o (away from the vehicle
centreline on this corner's side), up z — so a left corner and its mirror image (a right corner)
give the same values. Vectors below are in the model's global frame; s is the wheel's spin axis
(the z axis of the wheel-centre marker) oriented outboard, W the wheel centre, k = upper − lower
the steering (kingpin) axis. Internal units: mm, N, N·mm, rad.

Geometric metrics (one equilibrium):

- `toe` = atan2(s·f, s·o): angle in the ground plane between the wheel's heading and the
  vehicle's x axis; **toe-in positive** (the front of the wheel turned toward the centreline).
- `steer`: the same rotation with the vehicle sign: positive turns the vehicle left
  (= toe on a right wheel, −toe on a left wheel).
- `camber` = atan2(−s·z, ‖s − (s·z)z‖): inclination of the wheel plane from the vertical;
  **top of the wheel outboard positive**.
- `caster` = atan2(−k·f, k·z): steering axis from the vertical in side view; top rearward
  positive.
- `kingpin_inclination` = atan2(−k·o, k·z): steering axis from the vertical in front view; top
  inboard positive.
- `contact_patch_x/y/z`: the geometric contact point C = W + R·d, with R the corner's loaded
  radius and d the downward unit vector in the wheel plane (−(z − (z·s)s) normalised): the
  lowest point of a rigid wheel (mm, model frame). Loads are applied at the corner's
  `contact_point` load point, fixed on the wheel carrier; the two differ by R·sin(camber) at
  most in plan view.
- `scrub_radius` = (P − C)·l_in and `mechanical_trail` = (P − C)·h, with P the intersection of
  the steering axis with the horizontal ground plane through C, h the wheel's heading in the
  ground plane (forward) and l_in the inboard horizontal normal to it: scrub radius positive
  when the steering axis meets the ground inboard of the contact point, trail positive when it
  meets the ground ahead of it.
- `wheel_centre_x/y/z`, `spin_axis_x/y/z` (outboard unit vector): model frame.
- `wheel_travel` = (W − W₀)·z (mm, bump positive); `half_track_change` = (C − C₀)·o (outboard
  positive); `wheelbase_change` = −(W − W₀)·f (the wheel centre's longitudinal displacement,
  positive rearward as the Adams/Car x axis: a front wheel moving rearward shortens the
  wheelbase). Index 0 is the design position q = 0.
- `vertical_force` (up), `lateral_force` (inboard), `longitudinal_force` (rearward, i.e.
  braking), `aligning_torque` (about the vertical, toe-out sense): the loads on the wheel, per
  side: the applied contact-patch and wheel-centre loads plus the wheel-travel driver's reaction
  (the rig's jack force) for travel events.

Derivative metrics (exact: forward-mode derivatives through the implicitly differentiated
equilibrium, `diffsusp.kc.evaluate`), with what is held fixed stated by the event: the
wheel-centre height (and the rack) for travel and steering events, the vertical load for force
events. "Per travel" means per mm of wheel-centre vertical travel along the event's primary
input (the travel driver, or the vertical load: d m/dz = (∂m/∂F_z)/(∂z/∂F_z)):

- `bump_steer` (rad/mm, toe per travel), `bump_camber` (rad/mm), `wheel_rate` (N/mm, vertical
  force per travel);
- `roll_centre_height` (mm above the ground plane through C): kinematic (instant centre)
  method: the line through C normal to C's path in front view, dC/dz, meets the vehicle
  centreline (y = 0 of the model frame, which must be the vehicle's plane of symmetry) at
  height (C·o)(dC/dz·o)/(dC/dz·z) above C;
- `contact_recession_rate`, `wheel_centre_recession_rate` (mm/mm): rearward motion of C and W
  per travel (side-view path slopes, for `anti_pitch`);
- `lateral_compliance_steer`, `lateral_compliance_camber` (rad/N), `longitudinal_compliance_*`
  (rad/N, braking sense), `aligning_torque_compliance_*` (rad/(N·mm)): toe and camber per unit
  contact-patch lateral (inboard) force, longitudinal (rearward) force and aligning torque
  (toe-out sense);
- models with a steering rack (`with_rack`; any event): `steer_gain` (rad/mm: steer per mm of
  rack travel), `camber_steer_gain`;
- axles in opposite travel: `roll_angle` (rad, ISO 8855: right side down positive, from the
  wheel-centre heights: atan2(z_R − z_L, track)) and `roll_stiffness` (N·mm/rad: −(T/2)
  d(F_L − F_R)/dφ with T the design track of the wheel centres).

`compliance_matrix` (force events, per corner): the 6×6 derivative of the wheel centre's
displacement (mm) and rotation (rad, global rotation vector) with respect to a force (N) and
moment (N·mm) at the wheel-centre load point, global components, rows and columns
(x, y, z, rx, ry, rz).
"""

import math

import jax.numpy as jnp
import numpy as np

from ..statics import marker_poses, part_poses
from .corner import ResolvedCorner

_DEG = 180.0 / math.pi

METRICS = {
    # name: (internal unit, display unit, display scale, description)
    "toe": ("rad", "deg", _DEG, "toe angle (toe-in +)"),
    "steer": ("rad", "deg", _DEG, "steer angle (left turn +)"),
    "camber": ("rad", "deg", _DEG, "camber angle (top outboard +)"),
    "caster": ("rad", "deg", _DEG, "caster angle (top rearward +)"),
    "kingpin_inclination": ("rad", "deg", _DEG, "kingpin inclination (top inboard +)"),
    "scrub_radius": ("mm", "mm", 1.0, "scrub radius (axis meets ground inboard +)"),
    "mechanical_trail": ("mm", "mm", 1.0, "mechanical trail (axis meets ground ahead +)"),
    "wheel_centre_x": ("mm", "mm", 1.0, "wheel centre x (model frame)"),
    "wheel_centre_y": ("mm", "mm", 1.0, "wheel centre y (model frame)"),
    "wheel_centre_z": ("mm", "mm", 1.0, "wheel centre z (model frame)"),
    "wheel_travel": ("mm", "mm", 1.0, "wheel travel (bump +)"),
    "contact_patch_x": ("mm", "mm", 1.0, "contact point x (model frame)"),
    "contact_patch_y": ("mm", "mm", 1.0, "contact point y (model frame)"),
    "contact_patch_z": ("mm", "mm", 1.0, "contact point z (model frame)"),
    "spin_axis_x": ("-", "-", 1.0, "spin axis x (outboard unit vector)"),
    "spin_axis_y": ("-", "-", 1.0, "spin axis y (outboard unit vector)"),
    "spin_axis_z": ("-", "-", 1.0, "spin axis z (outboard unit vector)"),
    "half_track_change": ("mm", "mm", 1.0, "half-track change (outboard +)"),
    "wheelbase_change": ("mm", "mm", 1.0, "wheel base change (wheel centre rearward +)"),
    "vertical_force": ("N", "N", 1.0, "vertical wheel load (up +)"),
    "lateral_force": ("N", "N", 1.0, "lateral force (inboard +)"),
    "longitudinal_force": ("N", "N", 1.0, "longitudinal force (rearward/braking +)"),
    "aligning_torque": ("N·mm", "N·m", 1e-3, "aligning torque (toe-out +)"),
    "bump_steer": ("rad/mm", "deg/m", _DEG * 1e3, "bump steer (toe per travel)"),
    "bump_camber": ("rad/mm", "deg/m", _DEG * 1e3, "bump camber (camber per travel)"),
    "wheel_rate": ("N/mm", "N/mm", 1.0, "wheel rate"),
    "roll_centre_height": ("mm", "mm", 1.0, "kinematic roll centre height above ground"),
    "contact_recession_rate": ("mm/mm", "mm/mm", 1.0, "contact point rearward per travel"),
    "wheel_centre_recession_rate": ("mm/mm", "mm/mm", 1.0, "wheel centre rearward per travel"),
    "lateral_compliance_steer": ("rad/N", "deg/kN", _DEG * 1e3, "lateral force compliance steer"),
    "lateral_compliance_camber": ("rad/N", "deg/kN", _DEG * 1e3,
                                  "lateral force compliance camber"),
    "longitudinal_compliance_steer": ("rad/N", "deg/kN", _DEG * 1e3,
                                      "longitudinal (braking) force compliance steer"),
    "longitudinal_compliance_camber": ("rad/N", "deg/kN", _DEG * 1e3,
                                       "longitudinal (braking) force compliance camber"),
    "aligning_torque_compliance_steer": ("rad/(N·mm)", "deg/(kN·m)", _DEG * 1e6,
                                         "aligning torque compliance steer"),
    "aligning_torque_compliance_camber": ("rad/(N·mm)", "deg/(kN·m)", _DEG * 1e6,
                                          "aligning torque compliance camber"),
    "steer_gain": ("rad/mm", "deg/mm", _DEG, "steer per rack travel"),
    "camber_steer_gain": ("rad/mm", "deg/mm", _DEG, "camber per rack travel"),
    "roll_angle": ("rad", "deg", _DEG, "body roll angle (right side down +)"),
    "roll_stiffness": ("N·mm/rad", "N·m/deg", 1e-3 / _DEG, "roll stiffness"),
}
"""Every metric: (internal unit, display unit, display = internal × scale, description)."""

DERIVATIVE_METRICS = (
    "bump_steer", "bump_camber", "wheel_rate", "roll_centre_height", "contact_recession_rate",
    "wheel_centre_recession_rate", "lateral_compliance_steer", "lateral_compliance_camber",
    "longitudinal_compliance_steer", "longitudinal_compliance_camber",
    "aligning_torque_compliance_steer", "aligning_torque_compliance_camber", "steer_gain",
    "camber_steer_gain", "roll_stiffness",
)
"""Metrics computed from derivatives through the equilibrium."""


def display(name: str, value):
    """`value` of metric `name` (possibly 'left/toe') in display units (deg, deg/m, ...)."""
    base = name.rsplit("/", 1)[-1]
    scale = METRICS.get(base, ("", "", 1.0, ""))[2]
    return np.asarray(value) * scale


def display_unit(name: str) -> str:
    base = name.rsplit("/", 1)[-1]
    return METRICS.get(base, ("", "", 1.0, ""))[1]


def _point(mech, q, ref, pos):
    marker, part, x0 = ref
    if marker >= 0:
        return pos[marker]
    rot, trans = part_poses(mech, q)
    return rot[part] @ jnp.asarray(x0) + trans[part]


def corner_geometry(mech, rc: ResolvedCorner, q) -> dict:
    """Geometric metrics of one corner at public coordinates q (one case; see the module
    docstring). Also returns the wheel-centre orientation under key '_orientation'."""
    f, o, z = (jnp.asarray(v) for v in (rc.forward, rc.outboard, rc.up))
    pos, rot = marker_poses(mech, q)
    w = pos[rc.wheel_centre]
    s = rot[rc.wheel_centre][:, 2]
    s0 = mech.markers.orientation[rc.wheel_centre][:, 2]
    s = s * jnp.where(s0 @ o >= 0.0, 1.0, -1.0)
    sf, so, sz = s @ f, s @ o, s @ z
    toe = jnp.arctan2(sf, so)
    horizontal = jnp.sqrt(sf**2 + so**2)
    camber = jnp.arctan2(-sz, horizontal)
    down = -(z - sz * s)
    down = down / jnp.linalg.norm(down)
    c = w + rc.loaded_radius * down
    out = dict(
        toe=toe, steer=rc.sigma * toe, camber=camber,
        wheel_centre_x=w[0], wheel_centre_y=w[1], wheel_centre_z=w[2],
        contact_patch_x=c[0], contact_patch_y=c[1], contact_patch_z=c[2],
        spin_axis_x=s[0], spin_axis_y=s[1], spin_axis_z=s[2],
        _orientation=rot[rc.wheel_centre],
    )
    if rc.kingpin is not None:
        upper = _point(mech, q, rc.kingpin[0], pos)
        lower = _point(mech, q, rc.kingpin[1], pos)
        k = upper - lower
        out["caster"] = jnp.arctan2(-(k @ f), k @ z)
        out["kingpin_inclination"] = jnp.arctan2(-(k @ o), k @ z)
        ground = lower + k * ((c - lower) @ z) / (k @ z)
        heading = (f * so - o * sf) / horizontal
        inboard = -(o * so + f * sf) / horizontal
        out["scrub_radius"] = (ground - c) @ inboard
        out["mechanical_trail"] = (ground - c) @ heading
    return out
