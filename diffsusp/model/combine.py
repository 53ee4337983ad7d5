"""Combine several mechanisms that share the ground into one (e.g. a full axle from two corners).

Every part, marker, element, driver and load point keeps its name with a prefix ('left/',
'right/', ...). Constraint rows are renumbered (all joints of the first mechanism, then of the
second, ..., then all drivers in the same order) and each mechanism's independent rows are kept:
the mechanisms share nothing but the ground, so rows independent in each stay independent. The
combined mechanism is named 'axle(left/=<name>; right/=<name>)', from which
`component_names` recovers the prefixes and the original names (used by `diffsusp.kc` to find
each side's default corner).
"""

import jax.numpy as jnp
import numpy as np

from ..errors import ModelError
from .mechanism import (
    GROUND,
    Bushings,
    Drivers,
    Joints,
    LoadPoints,
    Markers,
    Mechanism,
    Springs,
    Stops,
)


def _prefixes(mechs: dict) -> dict[str, Mechanism]:
    out = {}
    for key, mech in mechs.items():
        if not isinstance(mech, Mechanism):
            raise ModelError(f"combine: '{key}' is a {type(mech).__name__}, not a Mechanism.")
        prefix = key if key.endswith("/") else key + "/"
        if "/" in prefix[:-1] or ";" in prefix or "=" in prefix:
            raise ModelError(
                f"combine: key '{key}' must be a plain name (no '/', ';' or '='), e.g. 'left'."
            )
        out[prefix] = mech
    if len(out) < 1:
        raise ModelError("combine: give at least one mechanism, e.g. {'left': m1, 'right': m2}.")
    return out


def _pad_tables(xs, ys, used, what):
    """Bring (n, ..., k) knot tables to one knot count; unused tables are replaced."""
    counts = {x.shape[-1] for x, u in zip(xs, used, strict=True) if u}
    if len(counts) > 1:
        raise ModelError(
            f"combine: the {what} tables of the mechanisms have different knot counts "
            f"{sorted(counts)}; resample them to a common count first."
        )
    k = counts.pop() if counts else max(x.shape[-1] for x in xs)
    out_x, out_y = [], []
    for x, y, u in zip(xs, ys, used, strict=True):
        if x.shape[-1] != k:
            if u:  # pragma: no cover - excluded above
                raise AssertionError
            x = jnp.broadcast_to(jnp.linspace(-1.0, 1.0, k), (*x.shape[:-1], k))
            y = jnp.zeros((*y.shape[:-1], k))
        out_x.append(x)
        out_y.append(y)
    return jnp.concatenate(out_x), jnp.concatenate(out_y)


def combine(mechs: dict[str, Mechanism], *, name: str | None = None) -> Mechanism:
    """One mechanism from several that share the ground (see the module docstring).

    **Arguments:**

    - `mechs`: prefix → mechanism, e.g. `{"left": m, "right": mirror(m)}` (prefixes become
      'left/', 'right/').
    - `name`: the combined mechanism's name (default 'axle(left/=...; right/=...)'; keep the
      default for `diffsusp.kc` to find the corners of built-in models).

    **Returns:** the combined `Mechanism` (not re-validated: each part was).
    """
    mechs = _prefixes(mechs)
    items = list(mechs.items())
    part_offset, marker_offset = 0, 0
    parts, mpart, mnames, positions, orientations = [], [], [], [], []
    joints = dict(kind=[], i=[], j=[], names=[])
    elements = {key: dict(i=[], j=[], names=[]) for key in ("bushings", "springs", "stops")}
    drivers = dict(direction=[], marker=[], names=[])
    load_points = dict(marker=[], frame=[], names=[])
    reference = []
    for prefix, mech in items:
        mk = mech.markers
        parts += [prefix + p for p in mech.parts]
        mpart += [GROUND if p == GROUND else p + part_offset for p in mk.part]
        mnames += [prefix + n for n in mk.names]
        positions.append(mk.position)
        orientations.append(mk.orientation)
        joints["kind"] += list(mech.joints.kind)
        joints["i"] += [i + marker_offset for i in mech.joints.i_marker]
        joints["j"] += [j + marker_offset for j in mech.joints.j_marker]
        joints["names"] += [prefix + n for n in mech.joints.names]
        for key in elements:
            group = getattr(mech, key)
            elements[key]["i"] += [i + marker_offset for i in group.i_marker]
            elements[key]["j"] += [j + marker_offset for j in group.j_marker]
            elements[key]["names"] += [prefix + n for n in group.names]
        drivers["direction"].append(mech.drivers.direction)
        drivers["marker"] += [m + marker_offset for m in mech.drivers.marker]
        drivers["names"] += [prefix + n for n in mech.drivers.names]
        load_points["marker"] += [m + marker_offset for m in mech.load_points.marker]
        load_points["frame"] += [GROUND if f == GROUND else f + marker_offset
                                 for f in mech.load_points.frame]
        load_points["names"] += [prefix + n for n in mech.load_points.names]
        reference += list(mech.reference_points)
        part_offset += len(mech.parts)
        marker_offset += len(mk.names)

    # Independent rows: joints of each mechanism in turn, then drivers of each in turn.
    joint_rows = [m.joints.n_rows for _, m in items]
    driver_rows = [len(m.drivers.names) for _, m in items]
    total_joint_rows = sum(joint_rows)
    independent = []
    joint_base, driver_base = 0, total_joint_rows
    for (_, mech), nj, nd in zip(items, joint_rows, driver_rows, strict=True):
        for r in mech.independent_rows:
            independent.append(joint_base + r if r < nj else driver_base + (r - nj))
        joint_base += nj
        driver_base += nd
    independent = sorted(independent)

    bs = [m.bushings for _, m in items]
    used = [b.has_splines for b in bs]
    spline_x, spline_y = _pad_tables([b.spline_x for b in bs], [b.spline_y for b in bs], used,
                                     "bushing spline")

    def cat(objs, field):
        return jnp.concatenate([getattr(o, field) for o in objs])

    bushings = Bushings(
        **{f: cat(bs, f) for f in ("k_trans", "k_rot", "cubic_trans", "cubic_rot",
                                   "offset_trans", "offset_rot", "preload_force",
                                   "preload_torque")},
        spline_x=spline_x, spline_y=spline_y,
        i_marker=tuple(elements["bushings"]["i"]), j_marker=tuple(elements["bushings"]["j"]),
        spline_axes=tuple(row for b in bs for row in b.spline_axes),
        names=tuple(elements["bushings"]["names"]),
    )
    ss = [m.springs for _, m in items]
    table_x, table_y = _pad_tables([s.table_x for s in ss], [s.table_y for s in ss],
                                   [any(s.tabulated) for s in ss], "spring")
    springs = Springs(
        k=cat(ss, "k"), free_length=cat(ss, "free_length"), table_x=table_x, table_y=table_y,
        i_marker=tuple(elements["springs"]["i"]), j_marker=tuple(elements["springs"]["j"]),
        tabulated=tuple(t for s in ss for t in s.tabulated),
        names=tuple(elements["springs"]["names"]),
    )
    st = [m.stops for _, m in items]
    stops = Stops(
        length=cat(st, "length"), k=cat(st, "k"), cubic=cat(st, "cubic"),
        i_marker=tuple(elements["stops"]["i"]), j_marker=tuple(elements["stops"]["j"]),
        kind=tuple(k for s in st for k in s.kind), names=tuple(elements["stops"]["names"]),
    )
    position = jnp.concatenate(positions)
    pos = np.asarray(position)
    spread = np.sum((pos - pos.mean(0)) ** 2, axis=1)
    default_name = "axle(" + "; ".join(f"{p}={m.name}" for p, m in items) + ")"
    return Mechanism(
        parts=tuple(parts),
        markers=Markers(position=position, orientation=jnp.concatenate(orientations),
                        part=tuple(mpart), names=tuple(mnames)),
        joints=Joints(kind=tuple(joints["kind"]), i_marker=tuple(joints["i"]),
                      j_marker=tuple(joints["j"]), names=tuple(joints["names"])),
        bushings=bushings,
        springs=springs,
        stops=stops,
        drivers=Drivers(direction=jnp.concatenate(drivers["direction"]).reshape(-1, 3),
                        marker=tuple(drivers["marker"]), names=tuple(drivers["names"])),
        load_points=LoadPoints(marker=tuple(load_points["marker"]),
                               frame=tuple(load_points["frame"]),
                               names=tuple(load_points["names"])),
        independent_rows=tuple(independent),
        length_scale=max(float(np.sqrt(np.mean(spread))), 1.0),
        reference_points=tuple(reference),
        name=default_name if name is None else name,
        corners=tuple(c.with_prefix(prefix) for prefix, m in items for c in m.corners),
    )


def component_names(mech: Mechanism) -> dict[str, str]:
    """Prefix → original name of the mechanisms a `combine`d one was made of ({} otherwise)."""
    name = mech.name
    if not (name.startswith("axle(") and name.endswith(")")):
        return {}
    out = {}
    for item in name[5:-1].split("; "):
        prefix, sep, original = item.partition("=")
        if not sep or not prefix.endswith("/"):
            return {}
        out[prefix] = original
    return out
