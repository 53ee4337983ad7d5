"""The K&C rig around a model: motion drivers for wheel travel and a steering rack.

These edit a `Mechanism`'s stacked arrays and static index tuples directly (no re-validation):
a vertical driver on a wheel marker and a rack sliding on the ground add rows that are
independent of the suspension's joints by construction. All edits use jnp operations, so they
can be applied to a traced (vmapped) mechanism.
"""

import dataclasses

import jax.numpy as jnp
import numpy as np

from ..errors import InputError
from ..model import GROUND, Mechanism
from ..model.builder import frame_from_axes


def _insert_joint_rows(mech: Mechanism, n_new: int) -> tuple[int, ...]:
    """Independent rows after appending `n_new` joint rows (drivers move down by n_new)."""
    nj = mech.joints.n_rows
    rows = [r if r < nj else r + n_new for r in mech.independent_rows]
    return tuple(sorted(rows + list(range(nj, nj + n_new))))


def add_driver(mech: Mechanism, name: str, marker: str, direction=(0.0, 0.0, 1.0)) -> Mechanism:
    """`mech` with one more motion driver: the travel (mm) of `marker` along the global unit
    `direction`, prescribed by the load case's driver value."""
    if name in mech.drivers.names:
        raise InputError(f"the model already has a driver named '{name}'.")
    k = mech.markers.index(marker)
    d = np.asarray(direction, dtype=float)
    d = d / np.linalg.norm(d)
    drivers = dataclasses.replace(
        mech.drivers,
        direction=jnp.concatenate([mech.drivers.direction.reshape(-1, 3), jnp.asarray(d)[None]]),
        marker=mech.drivers.marker + (k,),
        names=mech.drivers.names + (name,),
    )
    return dataclasses.replace(mech, drivers=drivers,
                               independent_rows=mech.independent_rows + (mech.n_rows,))


def remove_drivers(mech: Mechanism, names) -> Mechanism:
    """`mech` without the named drivers (their rows are dropped, later rows renumbered)."""
    names = set(names)
    if not names:
        return mech
    keep = [k for k, n in enumerate(mech.drivers.names) if n not in names]
    nj = mech.joints.n_rows
    new_index = {nj + k: nj + i for i, k in enumerate(keep)}
    rows = tuple(r if r < nj else new_index[r] for r in mech.independent_rows
                 if r < nj or r in new_index)
    keep_a = np.asarray(keep, dtype=int)
    drivers = dataclasses.replace(
        mech.drivers,
        direction=mech.drivers.direction.reshape(-1, 3)[keep_a],
        marker=tuple(mech.drivers.marker[k] for k in keep),
        names=tuple(mech.drivers.names[k] for k in keep),
    )
    return dataclasses.replace(mech, drivers=drivers, independent_rows=rows)


def with_rack(mech: Mechanism, tie_rod: str = "tie_rod", *, direction=None,
              frame: str | None = None, name: str = "rack_travel") -> Mechanism:
    """Put the inner end of a tie rod on a steering rack driven along the vehicle's lateral axis.

    The tie rod must be a `distance` joint (a massless link) with one marker on the ground (its
    inner end). That marker moves onto a new part `'rack'`, which slides on the ground in a
    translational joint along `direction` (`'rack.slide'`, 5 rows) and is driven by a motion
    driver `name` (1 row): 6 new coordinates, 6 new rows, the suspension's DOF unchanged.

    **Arguments:**

    - `tie_rod`: name of the distance joint.
    - `direction`: rack axis (global unit vector) along which positive rack travel moves the
      inner tie-rod point; default: the vehicle's left, i.e. −y in the Adams/Car frame and +y
      in the ISO frame (`frame`).
    - `frame`: 'adams' or 'iso', for the default direction (default: the frame of the model's
      corner, 'adams' for a model that states none).
    - `name`: the rack driver's name; its value is the rack travel (mm).

    **Returns:** the mechanism with the rack.
    """
    if tie_rod not in mech.joints.names:
        raise InputError(
            f"with_rack: the model has no joint '{tie_rod}'; known joints: "
            f"{', '.join(mech.joints.names)}."
        )
    j = mech.joints.names.index(tie_rod)
    if mech.joints.kind[j] != "distance":
        raise InputError(f"with_rack: joint '{tie_rod}' is a {mech.joints.kind[j]} joint; the "
                         "tie rod must be a distance joint (a massless link).")
    mk = mech.markers
    ends = (mech.joints.i_marker[j], mech.joints.j_marker[j])
    inner = [m for m in ends if mk.part[m] == GROUND]
    if len(inner) != 1:
        raise InputError(f"with_rack: joint '{tie_rod}' must have exactly one marker on the "
                         "ground (the inner tie-rod point).")
    inner = inner[0]
    if direction is None:
        if frame is None:
            frame = mech.corners[0].frame if mech.corners else "adams"
        direction = (0.0, 1.0, 0.0) if frame == "iso" else (0.0, -1.0, 0.0)
    d = np.asarray(direction, dtype=float)
    d = d / np.linalg.norm(d)
    orient = jnp.asarray(frame_from_axes(d))
    rack = len(mech.parts)
    at = mk.position[inner]
    part = list(mk.part)
    part[inner] = rack
    n = len(mk.names)
    markers = dataclasses.replace(
        mk,
        position=jnp.concatenate([mk.position, at[None], at[None]]),
        orientation=jnp.concatenate([mk.orientation, orient[None], orient[None]]),
        part=tuple(part) + (rack, GROUND),
        names=mk.names + ("rack.slide.i", "rack.slide.j"),
    )
    joints = dataclasses.replace(
        mech.joints,
        kind=mech.joints.kind + ("translational",),
        i_marker=mech.joints.i_marker + (n,),
        j_marker=mech.joints.j_marker + (n + 1,),
        names=mech.joints.names + ("rack.slide",),
    )
    out = dataclasses.replace(
        mech,
        parts=mech.parts + ("rack",),
        markers=markers,
        joints=joints,
        independent_rows=_insert_joint_rows(mech, 5),
        reference_points=mech.reference_points + (tuple(float(v) for v in np.asarray(at)),),
    )
    return add_driver(out, name, "rack.slide.i", d)


ROAD_CONTACT = "road_contact"
"""Name (after the corner's prefix) of the load point `add_road_contact` adds."""


def add_road_contact(mech: Mechanism, wheel_centre: int, prefix: str = "") -> tuple[Mechanism, int]:
    """`mech` with a load point `<prefix>road_contact` on the wheel-centre marker (global
    components), and its index: loaded with a `Loads.contact_radius` R, its force acts at the
    wheel plane's lowest point on the road, C = W − R·u (u the unit vector in the wheel plane
    pointing up from the road, spec kc §1), which moves with the wheel, not with the wheel
    carrier. An existing one (same marker) is reused."""
    name = prefix + ROAD_CONTACT
    lp = mech.load_points
    if name in lp.names:
        k = lp.names.index(name)
        if lp.marker[k] != wheel_centre or lp.frame[k] != GROUND:
            raise InputError(f"the model has a load point '{name}' that is not on the wheel "
                             "centre with global components; rename it.")
        return mech, k
    points = dataclasses.replace(lp, marker=lp.marker + (wheel_centre,),
                                 frame=lp.frame + (GROUND,), names=lp.names + (name,))
    return dataclasses.replace(mech, load_points=points), len(lp.names)
