"""Mirror a mechanism in the vehicle's longitudinal plane (y → −y): a left corner becomes a right
one.

With M = diag(1, −1, 1): positions x' = M x; marker frames R' = M R M (a proper rotation: the
marker's x and z axes are mirrored, its y axis is mirrored and reversed, so frames stay
right-handed). Under this map every element law mirrors exactly:

- a bushing's deformation in its J frame becomes δ'_T = M δ_T and its projected angles
  (−AX, AY, −AZ), so a diagonal law (any odd per-axis law: linear, cubic) gives the mirrored
  forces; offsets and preloads are mirrored the same way (y of translations, x and z of
  rotations change sign) and splines on those axes become y'(e) = −y(−e);
- joint rows keep their zero level (some change sign), springs and stops keep their lengths;
- the model's corners change side (`Corner.mirrored`);
- a driver's direction is mirrored (d' = M d), so the same driver value gives the mirrored
  motion; load components, global or in a marker frame, map as F' = M F and, for moments (axial
  vectors), T' = −M T (`mirror_loads`).

The mirrored mechanism's equilibrium under mirrored loads is the mirror of the original's: part
poses R' = M R M, p' = M p, i.e. public coordinates (M p, −M b) with b the Gibbs vector
(`mirror_coordinates`).
"""

import dataclasses

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .mechanism import Loads, Mechanism

_M = np.array([1.0, -1.0, 1.0])
_AXIAL = np.array([-1.0, 1.0, -1.0])  # −M: how axial vectors (moments, rotations) mirror


def mirror(mech: Mechanism, *, suffix: str = "", name: str | None = None) -> Mechanism:
    """The mirror image of `mech` through the plane y = 0 (see the module docstring).

    **Arguments:**

    - `mech`: the mechanism (e.g. a left corner in a frame whose y axis is lateral).
    - `suffix`: appended to every part, marker and element name (default: names kept, so the
      mirrored model has the same structure and reuses compiled solvers).
    - `name`: the mechanism's name (default: the original's + ' (mirrored)').

    **Returns:** the mirrored `Mechanism` (same topology, same parameters, mirrored geometry).
    """
    m = jnp.asarray(_M)
    a = jnp.asarray(_AXIAL)
    mk = mech.markers

    def names(t):
        return tuple(n + suffix for n in t)

    markers = dataclasses.replace(
        mk,
        position=mk.position * m,
        orientation=mk.orientation * m[:, None] * m[None, :],
        names=names(mk.names),
    )
    b = mech.bushings
    spline_x, spline_y = b.spline_x, b.spline_y
    if b.has_splines:
        # Axes whose deformation changes sign (ty, rx, rz): y'(e) = −y(−e), knots reversed.
        flip = np.array([False, True, False, True, False, True])
        flip_x = jnp.where(flip[None, :, None], -spline_x[..., ::-1], spline_x)
        flip_y = jnp.where(flip[None, :, None], -spline_y[..., ::-1], spline_y)
        spline_x, spline_y = flip_x, flip_y
    bushings = dataclasses.replace(
        b,
        offset_trans=b.offset_trans * m, offset_rot=b.offset_rot * a,
        preload_force=b.preload_force * m, preload_torque=b.preload_torque * a,
        spline_x=spline_x, spline_y=spline_y, names=names(b.names),
    )
    drivers = dataclasses.replace(mech.drivers, direction=mech.drivers.direction * m,
                                  names=names(mech.drivers.names))
    return dataclasses.replace(
        mech,
        parts=names(mech.parts),
        markers=markers,
        joints=dataclasses.replace(mech.joints, names=names(mech.joints.names)),
        bushings=bushings,
        springs=dataclasses.replace(mech.springs, names=names(mech.springs.names)),
        stops=dataclasses.replace(mech.stops, names=names(mech.stops.names)),
        drivers=drivers,
        load_points=dataclasses.replace(mech.load_points, names=names(mech.load_points.names)),
        reference_points=tuple((x, -y, z) for x, y, z in mech.reference_points),
        name=mech.name + " (mirrored)" if name is None else name,
        corners=tuple(_mirrored_corner(c, names) for c in mech.corners),
    )


def _mirrored_corner(corner, names):
    """The corner on the other side, its names carrying the mirror's suffix (the prefix
    stays in front of them)."""
    def name(n):
        return None if n is None else names((n,))[0]

    kingpin = None
    if corner.kingpin is not None:
        kingpin = tuple(name(r) if isinstance(r, str) else (name(r[0]), r[1])
                        for r in corner.kingpin)
    return dataclasses.replace(corner.mirrored(), wheel_centre=name(corner.wheel_centre),
                               contact_point=name(corner.contact_point),
                               wheel_centre_load=name(corner.wheel_centre_load), kingpin=kingpin)


def mirror_loads(loads: Loads) -> Loads:
    """Loads mirrored through y = 0: forces F' = M F, moments T' = −M T (axial vectors), driver
    values and road-contact radii unchanged (the mirrored drivers' directions are mirrored; the
    wheel plane's lowest point mirrors with the wheel)."""
    return Loads(force=loads.force * jnp.asarray(_M), moment=loads.moment * jnp.asarray(_AXIAL),
                 driver=loads.driver, contact_radius=loads.contact_radius)


def mirror_coordinates(q: Float[Array, "*cases n"]) -> Float[Array, "*cases n"]:
    """Public coordinates of the mirrored pose: per part (p, b) → (M p, −M b)."""
    q = jnp.asarray(q)
    per_part = jnp.asarray(np.r_[_M, _AXIAL])
    return (q.reshape(*q.shape[:-1], -1, 6) * per_part).reshape(q.shape)
