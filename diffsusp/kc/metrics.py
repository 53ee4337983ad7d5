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
  wheel-centre heights: atan2(z_R − z_L, track)), `roll_stiffness` (N·mm/rad: −(T/2)
  d(F_L − F_R)/dφ with T the design track of the wheel centres) and, per corner, the
  roll-steer coefficient `roll_steer` = d(steer)/dφ (rad/rad: steer with the vehicle sign,
  left turn positive, per roll angle φ, right side down positive).

Every metric has an entry in the registry `METRICS` (`Metric`: units, display, default
figures, and for a per-corner derivative metric the function that computes it from the
derivatives of the raw metrics): the K&C kernel, the CLI, the demo, `sensitivity` and the
figures read it, so a new derivative metric is added here (and tested) only.

`compliance_matrix` (force events, per corner): the 6×6 derivative of the wheel centre's
displacement (mm) and rotation (rad, global rotation vector) with respect to a force (N) and
moment (N·mm) at the wheel-centre load point, global components, rows and columns
(x, y, z, rx, ry, rz).
"""

import dataclasses
from collections.abc import Callable
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ..geometry import DEG
from ..statics import marker_poses, part_poses
from .corner import ResolvedCorner

EVENTS = ("parallel_travel", "opposite_travel", "vertical_force", "lateral_force",
          "longitudinal_force", "aligning_torque", "steering", "load_table")
"""The K&C events (`KCEvent.name`), for the metrics' default figures."""
_TRAVEL = ("parallel_travel", "opposite_travel")
_FORCES = ("lateral_force", "longitudinal_force", "aligning_torque", "load_table")


class Derivatives(NamedTuple):
    """What a derivative metric is computed from, for one corner and one case: `jac` the
    derivatives (n_u,) of every raw metric with respect to the rig inputs (see
    `events._basis`: 0 the primary input, 1–3 lateral force, longitudinal force, aligning
    torque, last the rack), `m` the raw metrics, `rc` the corner, `rig` the rig."""

    jac: dict
    m: dict
    rc: ResolvedCorner
    rig: object

    def d(self, key: str, u: int):
        """Derivative of this corner's raw metric `key` with respect to input `u`."""
        return self.jac[self.rc.prefix + key][u]

    def per_travel(self, key: str):
        """d key / d wheel travel along the primary input."""
        return self.d(key, 0) / self.d("wheel_travel", 0)

    def path(self, point: str):
        """d(point)/d(primary input) of `contact_patch` or `wheel_centre`, (3,)."""
        return jnp.stack([self.d(f"{point}_{a}", 0) for a in "xyz"])


@dataclasses.dataclass(frozen=True)
class Metric:
    """One K&C metric: units, display, and (derivative metrics) how it is computed.

    **Fields:** `unit` (internal), `display_unit`, `scale` (display = internal × scale),
    `description`; `derive(Derivatives) -> value | None` for a per-corner derivative metric
    (None where the rig does not have it); `derivative` (computed from derivatives through
    the equilibrium); `plots` the events (`EVENTS`) whose default figures show it;
    `sensitivity` shown by default by `diffsusp sensitivity`; `summary` in the demo's table;
    `per_roll` a derivative with respect to the body roll angle (an axle in opposite travel:
    left out of parallel travel, where the roll angle does not move).
    Unpacks as the tuple (unit, display unit, scale, description).
    """

    unit: str
    display_unit: str
    scale: float
    description: str
    derive: Callable[[Derivatives], object] | None = None
    derivative: bool = False
    plots: tuple[str, ...] = ()
    sensitivity: bool = False
    summary: bool = False
    per_roll: bool = False

    def __post_init__(self):
        if self.derive is not None:
            object.__setattr__(self, "derivative", True)

    def __iter__(self):
        return iter((self.unit, self.display_unit, self.scale, self.description))

    def __getitem__(self, i):
        return tuple(self)[i]


def _gain(key):
    def gain(at: Derivatives):
        return at.d(key, at.rig.n_inputs - 1) if at.rig.rack_driver >= 0 else None
    return gain


METRICS: dict[str, Metric] = {
    "toe": Metric("rad", "deg", 1 / DEG, "toe angle (toe-in +)",
                  plots=(*_TRAVEL, "vertical_force"), sensitivity=True, summary=True),
    "steer": Metric("rad", "deg", 1 / DEG, "steer angle (left turn +)",
                    plots=(*_FORCES, "steering")),
    "camber": Metric("rad", "deg", 1 / DEG, "camber angle (top outboard +)", plots=EVENTS,
                     sensitivity=True, summary=True),
    "caster": Metric("rad", "deg", 1 / DEG, "caster angle (top rearward +)"),
    "kingpin_inclination": Metric("rad", "deg", 1 / DEG, "kingpin inclination (top inboard +)"),
    "scrub_radius": Metric("mm", "mm", 1.0, "scrub radius (axis meets ground inboard +)"),
    "mechanical_trail": Metric("mm", "mm", 1.0, "mechanical trail (axis meets ground ahead +)",
                               plots=("steering",)),
    "wheel_centre_x": Metric("mm", "mm", 1.0, "wheel centre x (model frame)"),
    "wheel_centre_y": Metric("mm", "mm", 1.0, "wheel centre y (model frame)"),
    "wheel_centre_z": Metric("mm", "mm", 1.0, "wheel centre z (model frame)"),
    "wheel_travel": Metric("mm", "mm", 1.0, "wheel travel (bump +)",
                           plots=("vertical_force", *_FORCES)),
    "contact_patch_x": Metric("mm", "mm", 1.0, "contact point x (model frame)"),
    "contact_patch_y": Metric("mm", "mm", 1.0, "contact point y (model frame)"),
    "contact_patch_z": Metric("mm", "mm", 1.0, "contact point z (model frame)"),
    "spin_axis_x": Metric("-", "-", 1.0, "spin axis x (outboard unit vector)"),
    "spin_axis_y": Metric("-", "-", 1.0, "spin axis y (outboard unit vector)"),
    "spin_axis_z": Metric("-", "-", 1.0, "spin axis z (outboard unit vector)"),
    "half_track_change": Metric("mm", "mm", 1.0, "half-track change (outboard +)",
                                plots=_TRAVEL, sensitivity=True, summary=True),
    "wheelbase_change": Metric("mm", "mm", 1.0, "wheel base change (wheel centre rearward +)"),
    "vertical_force": Metric("N", "N", 1.0, "vertical wheel load (up +)"),
    "lateral_force": Metric("N", "N", 1.0, "lateral force (inboard +)"),
    "longitudinal_force": Metric("N", "N", 1.0, "longitudinal force (rearward/braking +)"),
    "aligning_torque": Metric("N·mm", "N·m", 1e-3, "aligning torque (toe-out +)"),
    "bump_steer": Metric("rad/mm", "deg/m", 1 / DEG * 1e3, "bump steer (toe per travel)",
                         derive=lambda at: at.per_travel("toe"), plots=EVENTS,
                         sensitivity=True, summary=True),
    "bump_camber": Metric("rad/mm", "deg/m", 1 / DEG * 1e3, "bump camber (camber per travel)",
                          derive=lambda at: at.per_travel("camber"), plots=EVENTS,
                          sensitivity=True, summary=True),
    "wheel_rate": Metric("N/mm", "N/mm", 1.0, "wheel rate",
                         derive=lambda at: at.per_travel("vertical_force"), plots=EVENTS,
                         sensitivity=True, summary=True),
    "roll_centre_height": Metric(
        "mm", "mm", 1.0, "kinematic roll centre height above ground",
        derive=lambda at: at.m[at.rc.prefix + "_lateral_position"] * (
            at.path("contact_patch") @ jnp.asarray(at.rc.outboard)) / (
            at.path("contact_patch") @ jnp.asarray(at.rc.up)), summary=True),
    "contact_recession_rate": Metric(
        "mm/mm", "mm/mm", 1.0, "contact point rearward per travel",
        derive=lambda at: (at.path("contact_patch") @ jnp.asarray(at.rc.rearward))
        / at.d("wheel_travel", 0)),
    "wheel_centre_recession_rate": Metric(
        "mm/mm", "mm/mm", 1.0, "wheel centre rearward per travel",
        derive=lambda at: (at.path("wheel_centre") @ jnp.asarray(at.rc.rearward))
        / at.d("wheel_travel", 0)),
    **{f"{what}_compliance_{angle}": Metric(
        unit, shown, scale, f"{text} compliance {'steer' if angle == 'steer' else 'camber'}",
        derive=lambda at, u=u, key=("toe" if angle == "steer" else "camber"): at.d(key, u),
        sensitivity=(what, angle) == ("lateral", "steer"))
       for u, what, unit, shown, scale, text in (
           (1, "lateral", "rad/N", "deg/kN", 1 / DEG * 1e3, "lateral force"),
           (2, "longitudinal", "rad/N", "deg/kN", 1 / DEG * 1e3, "longitudinal (braking) force"),
           (3, "aligning_torque", "rad/(N·mm)", "deg/(kN·m)", 1 / DEG * 1e6, "aligning torque"))
       for angle in ("steer", "camber")},
    "steer_gain": Metric("rad/mm", "deg/mm", 1 / DEG, "steer per rack travel",
                         derive=_gain("steer"), sensitivity=True),
    "camber_steer_gain": Metric("rad/mm", "deg/mm", 1 / DEG, "camber per rack travel",
                                derive=_gain("camber")),
    "roll_angle": Metric("rad", "deg", 1 / DEG, "body roll angle (right side down +)"),
    "roll_stiffness": Metric("N·mm/rad", "N·m/deg", 1e-3 * DEG, "roll stiffness",
                             derivative=True, per_roll=True),
    "roll_steer": Metric(
        "rad/rad", "deg/deg", 1.0, "roll steer (steer per body roll, left turn +)",
        derive=lambda at: (at.d("steer", 0) / at.jac["roll_angle"][0]
                           if "roll_angle" in at.jac else None),
        plots=("opposite_travel",), per_roll=True),
}
"""The metric registry: every metric the K&C kernel returns, with its units and display
(`Metric`). A per-corner derivative metric is added here only: its `derive` function is what
the kernel evaluates (`events._derived`), and the CLI, the demo, `sensitivity` and the figures
read its entry."""

DERIVATIVE_METRICS = tuple(name for name, m in METRICS.items() if m.derivative)
"""Metrics computed from derivatives through the equilibrium."""


def default_plots(event: str, available) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(metrics, derivative metrics) the default figures of `event` (a `KCEvent.name`) show,
    among the metric names `available` (with or without a corner prefix 'left/')."""
    have = {k.rsplit("/", 1)[-1] for k in available}
    chosen = [n for n, m in METRICS.items() if event in m.plots and n in have]
    return (tuple(n for n in chosen if not METRICS[n].derivative),
            tuple(n for n in chosen if METRICS[n].derivative))


def flagged(flag: str) -> tuple[str, ...]:
    """The metrics whose `flag` ('sensitivity', 'summary') is set, in registry order."""
    return tuple(n for n, m in METRICS.items() if getattr(m, flag))


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
