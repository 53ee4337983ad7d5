"""Which markers are the wheel: the static description of a suspension corner for K&C.

A `Corner` names the wheel-centre marker (its z axis is the spin axis), the load points where
contact-patch and wheel-centre loads act, the steering (kingpin) axis, the side of the vehicle
and the frame the model is drawn in. K&C metrics and per-side load components are defined from
it (see `diffsusp.kc.metrics` for every definition and sign).

Frames (DESIGN.md "Conventions"): Adams/Car: x rearward, y to the right, z up; Chrono /
ISO 8855: x forward, y to the left, z up. Both have z up; they differ by a half turn about z.
"""

import dataclasses
from typing import NamedTuple

import numpy as np

from ..errors import InputError
from ..model import Mechanism

FRAMES = {
    # rearward, right (unit vectors in the model's global frame)
    "adams": ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
    "iso": ((-1.0, 0.0, 0.0), (0.0, -1.0, 0.0)),
}
"""Vehicle axes per model frame: (rearward, right) unit vectors; z is up in both."""

PointRef = str | tuple[str, tuple[float, float, float]]
"""A point on the model: a marker name, or (part name, (forward, outboard, up) offset in mm from
the wheel centre's design position, along the vehicle's axes on this corner's side) — the
second form stays right when the corner is mirrored or drawn in another frame."""


@dataclasses.dataclass(frozen=True)
class Corner:
    """A wheel of a suspension model: the markers and load points K&C events and metrics use.

    **Fields:**

    - `wheel_centre`: marker at the wheel centre; its z axis is the spin axis (either sense:
      the metrics orient it outboard).
    - `contact_point`: load point where contact-patch forces and the aligning torque act (on the
      wheel carrier, `loaded_radius` below the wheel centre at design).
    - `wheel_centre_load`: load point at the wheel centre (traction forces, compliance matrix);
      None if the model has none.
    - `kingpin`: (upper, lower) points of the steering axis, each a marker name or
      (part, (forward, outboard, up) design offset from the wheel centre in mm, see
      `PointRef`); None when the model has no steering axis (caster, KPI, scrub radius and
      trail are then not reported).
    - `side`: 'left', 'right', or 'auto' (the side of the vehicle's centreline, y = 0 of the
      model's frame, that the wheel centre is on at design).
    - `frame`: 'adams' (x rearward, y right, z up) or 'iso' (Chrono, ISO 8855: x forward,
      y left, z up).
    - `loaded_radius`: wheel-centre height above the ground at design (mm), for the geometric
      contact point (rigid disc: the lowest point of the wheel's circle of this radius).
    - `design_load`: vertical wheel load at design (N), the default of force events.
    - `prefix`: name prefix of this corner in a combined axle (e.g. 'left/'); see `with_prefix`.
    """

    wheel_centre: str = "wheel_centre"
    contact_point: str = "contact_patch"
    wheel_centre_load: str | None = "wheel_centre"
    kingpin: tuple[PointRef, PointRef] | None = None
    side: str = "auto"
    frame: str = "adams"
    loaded_radius: float = 300.0
    design_load: float = 4000.0
    prefix: str = ""

    def __post_init__(self):
        if self.side not in ("left", "right", "auto"):
            raise InputError(f"Corner.side must be 'left', 'right' or 'auto'; got '{self.side}'.")
        if self.frame not in FRAMES:
            raise InputError(
                f"Corner.frame must be one of {', '.join(FRAMES)}; got '{self.frame}'."
            )
        if not (np.isfinite(self.loaded_radius) and self.loaded_radius > 0):
            raise InputError(
                f"Corner.loaded_radius must be a positive length in mm; got {self.loaded_radius}."
            )

    def with_prefix(self, prefix: str) -> "Corner":
        """The same corner in a combined axle whose names carry `prefix` (e.g. 'left/')."""
        return dataclasses.replace(self, prefix=prefix + self.prefix)

    def resolve(self, mech: Mechanism) -> "ResolvedCorner":
        """Indices and axes of this corner in `mech` (raises `InputError` on unknown names).

        With `side='auto'` the wheel centre's design position must be concrete (not traced).
        """
        p = self.prefix
        mk = mech.markers

        def marker(name: str, what: str) -> int:
            if p + name not in mk.names:
                raise InputError(
                    f"Corner.{what}: the model has no marker '{p + name}'. Pass a Corner whose "
                    f"{what} names one of its markers (see mech.markers.names)."
                )
            return mk.names.index(p + name)

        def load_point(name: str | None, what: str) -> int:
            if name is None:
                return -1
            if p + name not in mech.load_points.names:
                raise InputError(
                    f"Corner.{what}: the model has no load point '{p + name}'; known load "
                    f"points: {', '.join(mech.load_points.names) or 'none'}."
                )
            return mech.load_points.names.index(p + name)

        wc = marker(self.wheel_centre, "wheel_centre")
        w0 = np.asarray(mk.position[wc], dtype=float)
        rear, right = (np.array(v) for v in FRAMES[self.frame])
        side = self.side
        if side == "auto":
            side = "right" if float(w0 @ right) > 0 else "left"
        sigma = 1.0 if side == "right" else -1.0
        outboard = sigma * right
        forward = -rear
        up = np.array([0.0, 0.0, 1.0])

        def point(ref: PointRef, what: str) -> tuple[int, int, tuple[float, float, float]]:
            # (marker index or -1, part index or -1, global design position)
            if isinstance(ref, str):
                return marker(ref, what), -1, (0.0, 0.0, 0.0)
            part, (a, b, c) = ref
            try:
                k = mech.part_index(p + part)
            except ValueError as e:
                raise InputError(f"Corner.{what}: {e}") from None
            x = w0 + a * forward + b * outboard + c * up
            return -1, k, tuple(float(v) for v in x)

        kingpin = None
        if self.kingpin is not None:
            kingpin = (point(self.kingpin[0], "kingpin[0]"), point(self.kingpin[1], "kingpin[1]"))
        # Rotation about +up by ε changes toe (atan2(s·f, s·o)) by ((up × o)·f) ε: the toe-out
        # sense of the aligning torque is the axis that lowers toe.
        toe_out = -float(np.cross(up, outboard) @ forward) * up
        return ResolvedCorner(
            prefix=p, wheel_centre=wc, contact_point=load_point(self.contact_point,
                                                                "contact_point"),
            wheel_centre_load=load_point(self.wheel_centre_load, "wheel_centre_load"),
            kingpin=kingpin, side=side, sigma=sigma,
            outboard=tuple(outboard.tolist()), forward=tuple(forward.tolist()),
            rearward=tuple(rear.tolist()), up=tuple(up.tolist()), toe_out=tuple(toe_out.tolist()),
            loaded_radius=float(self.loaded_radius), design_load=float(self.design_load),
        )


class ResolvedCorner(NamedTuple):
    """A `Corner` bound to one mechanism: indices and unit vectors (static, hashable)."""

    prefix: str
    wheel_centre: int
    contact_point: int
    wheel_centre_load: int
    kingpin: tuple | None
    side: str
    sigma: float  # +1 right, -1 left
    outboard: tuple[float, float, float]
    forward: tuple[float, float, float]
    rearward: tuple[float, float, float]
    up: tuple[float, float, float]
    toe_out: tuple[float, float, float]
    loaded_radius: float
    design_load: float

    def load_vectors(self, vertical, lateral, longitudinal, aligning):
        """Per-side components → global force (N) and moment (N·mm) at the contact point.

        Per side: `vertical` up, `lateral` inboard (toward the vehicle centreline),
        `longitudinal` rearward (a braking force), `aligning` torque about the vertical in the
        toe-out sense.
        """
        up, o, r, a = (np.asarray(v) for v in (self.up, self.outboard, self.rearward,
                                               self.toe_out))
        vertical, lateral, longitudinal, aligning = (
            np.asarray(v, dtype=float)[..., None] for v in (vertical, lateral, longitudinal,
                                                            aligning))
        force = vertical * up - lateral * o + longitudinal * r
        return force, aligning * a


def _virtual_lower_pivot() -> tuple[float, float, float]:
    """The pseudo-McPherson's design virtual lower steering pivot as a (forward, outboard, up)
    offset from the wheel centre L9: the midpoint of the common perpendicular of its two lower
    links' lines (front arm L1–L8, rear arm L2–L7, Table 2.2), at (−1.62, −716.49, 197.11) mm
    in the Adams/Car frame. The two lines pass 70 mm apart vertically; in plan view they cross
    8–12 % beyond the ball joints."""
    from ..models.pseudo_mcpherson import JOINT_POSITIONS as P

    a0, a1 = np.array(P["L1"]), np.array(P["L8"])
    b0, b1 = np.array(P["L2"]), np.array(P["L7"])
    u, v, w = a1 - a0, b1 - b0, a0 - b0
    s, t = np.linalg.solve([[u @ u, -u @ v], [u @ v, -v @ v]], [-w @ u, -w @ v])
    d = 0.5 * (a0 + s * u + b0 + t * v) - np.array(P["L9"])
    # Adams/Car frame, left wheel: forward = −x, outboard = −y.
    return float(-d[0]), float(-d[1]), float(d[2])


def _pseudo_mcpherson_corner() -> Corner:
    from ..models.pseudo_mcpherson import DESIGN_LOAD, LOADED_RADIUS

    return Corner(kingpin=("L4_strut_top", ("hub_carrier", _virtual_lower_pivot())),
                  frame="adams", loaded_radius=LOADED_RADIUS, design_load=DESIGN_LOAD)


def _double_wishbone_corner() -> Corner:
    from ..models.double_wishbone import DOUBLE_WISHBONE_DESIGN_LOAD, LOADED_RADIUS

    return Corner(kingpin=("uca_upright", "lca_upright"), frame="iso",
                  loaded_radius=LOADED_RADIUS, design_load=DOUBLE_WISHBONE_DESIGN_LOAD)


DEFAULT_CORNERS = {
    "pseudo-McPherson half axle": _pseudo_mcpherson_corner,
    "Chrono generic double wishbone": _double_wishbone_corner,
}
"""Mechanism name prefix → default `Corner` of the built-in models.

- pseudo-McPherson (`diffsusp.models.pseudo_mcpherson`): Adams/Car frame, side from the wheel
  centre (left as built), wheel centre L9 (its z axis is the spin axis, outboard), contact
  patch 305 mm below it, steering axis from the strut top L4 to the design virtual lower pivot
  of the two lower links (`_virtual_lower_pivot`, fixed on the hub carrier), design load 4500 N.
- Chrono double wishbone (`diffsusp.models.double_wishbone`): ISO frame (x forward, y left),
  side from the wheel centre (left as built), spin axis +y, contact patch 330 mm below, steering
  axis through the two ball joints, design load 9018.1 N.
"""


def default_corner(mech: Mechanism, prefix: str = "") -> Corner:
    """The registered `Corner` of a built-in model (by its name), or an `InputError` that says
    how to describe the wheel."""
    name = mech.name
    for key, make in DEFAULT_CORNERS.items():
        if name.startswith(key):
            corner = make()
            return corner.with_prefix(prefix) if prefix else corner
    raise InputError(
        f"no default K&C corner for model '{name}'. Describe the wheel with "
        "diffsusp.kc.Corner(wheel_centre=..., contact_point=..., kingpin=(upper, lower), "
        "frame='adams'|'iso', loaded_radius=...) and pass it as corner=."
    )


def corners_of(mech: Mechanism) -> dict[str, Corner]:
    """Default corners of a model: one for a half axle (key ''), or one per side for an axle
    made by `diffsusp.model.combine.combine` (keys are its prefixes, e.g. 'left/')."""
    from ..model.combine import component_names

    parts = component_names(mech)
    if not parts:
        return {"": default_corner(mech)}
    out = {}
    for prefix, name in parts.items():
        probe = dataclasses.replace(mech, name=name)
        out[prefix] = default_corner(probe, prefix)
    return out
