"""Which markers are the wheel: the static description of a suspension corner, stored with the
model (`Mechanism.corners`), so that K&C events, sensitivity and identification find the wheel
of a built-in model or a model file without being told (nothing is guessed from names).

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

from ..errors import InputError, ModelError

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
    - `loaded_radius`: wheel-centre height above the ground at design (mm): the K&C force
      events apply the tyre force at the ground contact point, the lowest point of the wheel's
      circle of this radius, moving with the wheel plane (`diffsusp.kc.force_rig`); also the
      geometric contact point of the metrics.
    - `loaded_radius_stated`: False when `loaded_radius` is a reader's default, not a value the
      model file or the user gave (a Chrono suspension file carries no tyre): `diffsusp kc`
      then says which radius it uses.
    - `design_load`: vertical wheel load at design (N), the default of force events; None:
      the vertical contact-patch load that holds the wheel centre at its design height,
      computed through the statics by `diffsusp.kc.design_load` (any number of degrees of
      freedom) — what an imported model that states no wheel load uses.
    - `prefix`: name prefix of this corner in a combined axle (e.g. 'left/'); see `with_prefix`.
    """

    wheel_centre: str = "wheel_centre"
    contact_point: str = "contact_patch"
    wheel_centre_load: str | None = "wheel_centre"
    kingpin: tuple[PointRef, PointRef] | None = None
    side: str = "auto"
    frame: str = "adams"
    loaded_radius: float = 300.0
    design_load: float | None = 4000.0
    prefix: str = ""
    loaded_radius_stated: bool = dataclasses.field(default=True, compare=False)

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
        if self.design_load is not None and not np.isfinite(self.design_load):
            raise InputError(
                f"Corner.design_load must be a finite force in N or None; got {self.design_load}."
            )

    def with_prefix(self, prefix: str) -> "Corner":
        """The same corner in a combined axle whose names carry `prefix` (e.g. 'left/')."""
        return dataclasses.replace(self, prefix=prefix + self.prefix)

    def mirrored(self) -> "Corner":
        """The same corner on the other side (for the mirror image of a half axle: offsets
        given as (forward, outboard, up) stay right)."""
        side = {"left": "right", "right": "left"}.get(self.side, self.side)
        return dataclasses.replace(self, side=side)

    def side_in(self, mech) -> str:
        """'left' or 'right': the stated side, or with 'auto' the side of the vehicle's
        centreline the wheel centre is on at design."""
        if self.side != "auto":
            return self.side
        k = mech.markers.names.index(self.prefix + self.wheel_centre)
        w0 = np.asarray(mech.markers.position[k], dtype=float)
        return "right" if float(w0 @ np.array(FRAMES[self.frame][1])) > 0 else "left"

    def check_names(self, mech) -> None:
        """Raise `ModelError` if a marker, load point or part this corner names is not in
        `mech` (what the builder and the file readers check)."""
        p = self.prefix
        wanted = [
            ("wheel_centre", self.wheel_centre, mech.markers.names),
            ("contact_point", self.contact_point, mech.load_points.names),
            ("wheel_centre_load", self.wheel_centre_load, mech.load_points.names),
        ]
        for k, ref in enumerate(self.kingpin or ()):
            if isinstance(ref, str):
                wanted.append((f"kingpin[{k}]", ref, mech.markers.names))
            else:
                wanted.append((f"kingpin[{k}]", ref[0], ("ground", *mech.parts)))
        for what, name, known in wanted:
            if name is not None and p + name not in known:
                raise ModelError(
                    f"corner {what}: '{p + name}' is not in the model (known: "
                    f"{', '.join(known) or 'none'})."
                )

    def resolve(self, mech, design_load: float | None = None) -> "ResolvedCorner":
        """Indices and axes of this corner in `mech` (raises `InputError` on unknown names).

        The resolved `design_load` is the one the corner states, else `design_load` (N; the
        equilibrium load of `diffsusp.kc.design_load`, which the K&C events pass), else None.
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
            prefix=p,
            wheel_centre=wc,
            contact_point=load_point(self.contact_point, "contact_point"),
            wheel_centre_load=load_point(self.wheel_centre_load, "wheel_centre_load"),
            kingpin=kingpin,
            side=side,
            sigma=sigma,
            outboard=tuple(outboard.tolist()),
            forward=tuple(forward.tolist()),
            rearward=tuple(rear.tolist()),
            up=tuple(up.tolist()),
            toe_out=tuple(toe_out.tolist()),
            loaded_radius=float(self.loaded_radius),
            design_load=float(self.design_load) if self.design_load is not None
            else None if design_load is None else float(design_load),
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
    design_load: float | None  # N; None: not stated and not computed

    def load_vectors(self, vertical, lateral, longitudinal, aligning):
        """Per-side components → global force (N) and moment (N·mm) at the contact point.

        Per side: `vertical` up, `lateral` inboard (toward the vehicle centreline),
        `longitudinal` rearward (a braking force), `aligning` torque about the vertical in the
        toe-out sense.
        """
        up, o, r, a = (np.asarray(v) for v in (self.up, self.outboard, self.rearward, self.toe_out))
        vertical, lateral, longitudinal, aligning = (
            np.asarray(v, dtype=float)[..., None]
            for v in (vertical, lateral, longitudinal, aligning)
        )
        force = vertical * up - lateral * o + longitudinal * r
        return force, aligning * a


def design_offset(point, wheel_centre, frame: str, side: str) -> tuple[float, float, float]:
    """A global design position as the (forward, outboard, up) offset (mm) from the wheel centre
    that a `PointRef` takes, for a corner on `side` ('left'/'right') drawn in `frame`."""
    rear, right = (np.array(v) for v in FRAMES[frame])
    outboard = right if side == "right" else -right
    d = np.asarray(point, dtype=float) - np.asarray(wheel_centre, dtype=float)
    return float(-d @ rear), float(d @ outboard), float(d[2])


def common_perpendicular_midpoint(a0, a1, b0, b1) -> np.ndarray:
    """Midpoint of the common perpendicular of lines a0–a1 and b0–b1 (a virtual pivot of two
    links). Raises `InputError` for parallel lines."""
    a0, a1, b0, b1 = (np.asarray(v, dtype=float) for v in (a0, a1, b0, b1))
    u, v, w = a1 - a0, b1 - b0, a0 - b0
    m = np.array([[u @ u, -u @ v], [u @ v, -v @ v]])
    if abs(np.linalg.det(m)) < 1e-12 * (u @ u) * (v @ v):
        raise InputError("the two links are parallel: they define no virtual pivot.")
    s, t = np.linalg.solve(m, [-w @ u, -w @ v])
    return 0.5 * (a0 + s * u + b0 + t * v)


__all__ = [
    "FRAMES",
    "Corner",
    "PointRef",
    "ResolvedCorner",
    "common_perpendicular_midpoint",
    "design_offset",
]
