"""A builder that reads like a description of the suspension.

```python
b = MechanismBuilder("isolated bushing")
b.part("arm")
b.bushing("bush", parts=("arm", "ground"), at=(0, 0, 0), k_trans=100.0, k_rot=5.73e5)
b.load_point("tip", part="arm", at=(-300, 0, 0))
mech = b.build()
```

Positions are global at design (mm); orientations are rotation matrices whose columns are the
marker axes in the global frame, or given by `z` (and optionally `x`) axes, or Adams REULER
angles in degrees (`reuler_deg`).
"""

import math
from collections.abc import Sequence

import jax
import numpy as np

from ..errors import ModelError
from .corner import Corner
from .mechanism import (
    BUSHING_AXES,
    GROUND,
    JOINT_ROWS,
    Bushings,
    Drivers,
    Joints,
    LoadPoints,
    Markers,
    Mechanism,
    Springs,
    Stops,
)
from .structure import finalize


def frame_from_axes(z=None, x=None) -> np.ndarray:
    """Right-handed orthonormal frame with z along `z` and x as close to `x` as possible."""
    if z is None:
        return np.eye(3)
    z = np.asarray(z, dtype=float)
    nz = np.linalg.norm(z)
    if not np.isfinite(nz) or nz == 0:
        raise ModelError(f"axis z={z.tolist()} is not a finite non-zero vector.")
    z = z / nz
    if x is None:
        x = np.eye(3)[int(np.argmin(np.abs(z)))]
    x = np.asarray(x, dtype=float)
    x = x - (x @ z) * z
    nx = np.linalg.norm(x)
    if nx < 1e-9:
        raise ModelError("axis x is parallel to axis z; give an x axis that is not.")
    x = x / nx
    return np.column_stack([x, np.cross(z, x), z])


def _vec3(value, what: str) -> np.ndarray:
    arr = np.broadcast_to(np.asarray(value, dtype=float), (3,)).copy()
    if not np.all(np.isfinite(arr)):
        raise ModelError(f"{what} must be finite; got {arr.tolist()}.")
    return arr


class MechanismBuilder:
    """Collects parts, markers, joints and elements, then `build()`s a validated `Mechanism`."""

    def __init__(self, name: str = "mechanism"):
        self.name = name
        self._corners = []
        self._parts: list[str] = []
        self._markers: dict[str, tuple[str, np.ndarray, np.ndarray]] = {}
        self._joints: list[tuple[str, str, str, str]] = []
        self._bushings: list[dict] = []
        self._springs: list[dict] = []
        self._stops: list[dict] = []
        self._drivers: list[tuple[str, str, np.ndarray]] = []
        self._load_points: list[tuple[str, str, str | None]] = []
        self._names: set[str] = set()

    # -- parts and markers ------------------------------------------------------------------

    def part(self, name: str) -> "MechanismBuilder":
        """Add a moving rigid part (6 coordinates). The ground exists already as 'ground'."""
        if name == "ground" or name in self._parts:
            raise ModelError(f"part '{name}' is defined twice (or uses the reserved name).")
        self._parts.append(name)
        return self

    def marker(self, name: str, part: str, position, orientation=None, *, z=None, x=None,
               reuler_deg=None) -> str:
        """Add a marker on `part` at global `position` (mm) with the given orientation."""
        if name in self._markers:
            raise ModelError(f"marker '{name}' is defined twice; marker names must be unique.")
        if part != "ground" and part not in self._parts:
            raise ModelError(
                f"marker '{name}' is on unknown part '{part}'; define it first with "
                f"part('{part}') (known: ground, {', '.join(self._parts)})."
            )
        if orientation is not None:
            rot = np.asarray(orientation, dtype=float).reshape(3, 3)
            if not np.allclose(rot.T @ rot, np.eye(3), atol=1e-9) or np.linalg.det(rot) < 0:
                raise ModelError(f"orientation of marker '{name}' is not a rotation matrix.")
        elif reuler_deg is not None:
            rot = _reuler_deg(reuler_deg)
        else:
            rot = frame_from_axes(z, x)
        self._markers[name] = (part, _vec3(position, f"position of marker '{name}'"), rot)
        return name

    def _pair(self, name, i, j, parts, at, orientation, z, x, reuler_deg):
        """Markers of a two-part element: given, or created coincident at `at`."""
        if parts is not None:
            if i is not None or j is not None:
                raise ModelError(f"'{name}': give either markers i/j or parts=(...), not both.")
            if at is None:
                raise ModelError(f"'{name}': parts=(...) needs the location at=(x, y, z).")
            at_i, at_j = (at, at) if np.ndim(at) == 1 else at
            kw = dict(orientation=orientation, z=z, x=x, reuler_deg=reuler_deg)
            i = self.marker(f"{name}.i", parts[0], at_i, **kw)
            j = self.marker(f"{name}.j", parts[1], at_j, **kw)
        for m in (i, j):
            if m not in self._markers:
                raise ModelError(f"'{name}' refers to unknown marker '{m}'.")
        if self._markers[i][0] == self._markers[j][0]:
            raise ModelError(
                f"'{name}' has both markers on part '{self._markers[i][0]}'; it must join two "
                "different parts. Check its 'i' and 'j' (or 'parts')."
            )
        return i, j

    def _claim(self, name: str):
        if name in self._names:
            raise ModelError(f"element name '{name}' is used twice; names must be unique.")
        self._names.add(name)

    # -- joints -------------------------------------------------------------------------------

    def joint(self, name: str, kind: str, i: str | None = None, j: str | None = None, *,
              parts: Sequence[str] | None = None, at=None, orientation=None, z=None, x=None,
              reuler_deg=None) -> "MechanismBuilder":
        """Add an ideal joint (Adams kinds: spherical, revolute, cylindrical, translational,
        universal, fixed, inline, inplane, perpendicular, distance). Axes follow Adams: the
        revolute/cylindrical/translational axis is z, a universal joint keeps z_I ⟂ z_J."""
        if kind not in JOINT_ROWS:
            raise ModelError(
                f"joint '{name}' has unknown kind '{kind}'; use one of {', '.join(JOINT_ROWS)}."
            )
        self._claim(name)
        i, j = self._pair(name, i, j, parts, at, orientation, z, x, reuler_deg)
        self._joints.append((name, kind, i, j))
        return self

    # -- force elements ---------------------------------------------------------------------

    def bushing(self, name: str, i: str | None = None, j: str | None = None, *,
                parts: Sequence[str] | None = None, at=None, orientation=None, z=None, x=None,
                reuler_deg=None, k_trans=0.0, k_rot=0.0, cubic_trans=0.0, cubic_rot=0.0,
                offset_trans=0.0, offset_rot=0.0, preload_force=0.0, preload_torque=0.0,
                splines: dict | None = None) -> "MechanismBuilder":
        """Add a six-axis bushing (Adams convention: law on I, deformation of I in J).

        **Arguments:** stiffness `k_trans` (N/mm) and `k_rot` (N·mm/rad), cubic terms, offsets
        (mm, rad), preloads (N, N·mm), each a scalar or 3 values in the J frame; `splines`: axis
        name ('tx', ..., 'rz') → (x, y) table of force on I vs deformation (A/Car: y = −k·x).
        """
        self._claim(name)
        i, j = self._pair(name, i, j, parts, at, orientation, z, x, reuler_deg)
        entry = dict(name=name, i=i, j=j, splines={})
        for key, value in dict(k_trans=k_trans, k_rot=k_rot, cubic_trans=cubic_trans,
                               cubic_rot=cubic_rot, offset_trans=offset_trans,
                               offset_rot=offset_rot, preload_force=preload_force,
                               preload_torque=preload_torque).items():
            entry[key] = _vec3(value, f"{key} of bushing '{name}'")
        for key in ("k_trans", "k_rot", "cubic_trans", "cubic_rot"):
            if np.any(entry[key] < 0):
                raise ModelError(
                    f"{key} of bushing '{name}' is negative ({entry[key].tolist()}); stiffness "
                    "must be ≥ 0."
                )
        for axis, table in (splines or {}).items():
            if axis not in BUSHING_AXES:
                raise ModelError(
                    f"spline axis '{axis}' of bushing '{name}' is not one of {BUSHING_AXES}."
                )
            entry["splines"][axis] = _table(table, f"spline '{axis}' of bushing '{name}'")
        self._bushings.append(entry)
        return self

    def spring(self, name: str, i: str | None = None, j: str | None = None, *,
               parts: Sequence[str] | None = None, at=None, k: float | None = None,
               free_length: float | None = None, table=None) -> "MechanismBuilder":
        """Add a spring along the line of two markers (`at` = (point on I part, point on J)).

        **Arguments:** linear `k` (N/mm) and `free_length` (mm); or `table` = (extension
        ℓ − free_length in mm, tension in N) with `free_length` (default 0).
        """
        self._claim(name)
        i, j = self._pair(name, i, j, parts, at, None, None, None, None)
        length = np.linalg.norm(self._markers[i][1] - self._markers[j][1])
        if length < 1e-6:
            raise ModelError(
                f"spring '{name}' has zero length at design (markers '{i}' and '{j}' coincide); "
                "a spring needs two distinct seats."
            )
        if table is None:
            if k is None or free_length is None:
                raise ModelError(f"spring '{name}' needs k and free_length, or a table.")
            if not (math.isfinite(k) and k > 0):
                raise ModelError(f"spring '{name}': k must be positive and finite; got {k}.")
        else:
            table = _table(table, f"table of spring '{name}'")
        if free_length is not None and not (math.isfinite(free_length) and free_length > 0):
            raise ModelError(
                f"spring '{name}': free_length must be positive and finite; got {free_length}."
            )
        self._springs.append(dict(name=name, i=i, j=j, k=k or 0.0,
                                  free_length=free_length or 0.0, table=table))
        return self

    def stop(self, name: str, i: str | None = None, j: str | None = None, *,
             parts: Sequence[str] | None = None, at=None, kind: str = "bump", length: float,
             k: float, cubic: float = 0.0) -> "MechanismBuilder":
        """Add a bump ('bump', engaged below `length`) or rebound ('rebound', above) stop."""
        if kind not in ("bump", "rebound"):
            raise ModelError(f"stop '{name}': kind must be 'bump' or 'rebound'; got '{kind}'.")
        if not (k >= 0 and cubic >= 0 and length > 0):
            raise ModelError(f"stop '{name}': k, cubic must be ≥ 0 and length > 0.")
        self._claim(name)
        i, j = self._pair(name, i, j, parts, at, None, None, None, None)
        self._stops.append(dict(name=name, i=i, j=j, kind=kind, length=length, k=k, cubic=cubic))
        return self

    # -- inputs -------------------------------------------------------------------------------

    def driver(self, name: str, marker: str | None = None, *, part: str | None = None,
               at=None, direction=(0.0, 0.0, 1.0)) -> "MechanismBuilder":
        """Prescribe the travel (mm) of a marker along a global `direction` as an input."""
        self._claim(name)
        marker = self._marker_for(name, marker, part, at)
        d = _vec3(direction, f"direction of driver '{name}'")
        self._drivers.append((name, marker, d / np.linalg.norm(d)))
        return self

    def load_point(self, name: str, marker: str | None = None, *, part: str | None = None,
                   at=None, frame: str | None = None) -> "MechanismBuilder":
        """Declare where a force and moment can act; components are global, or in the axes of
        marker `frame` (Adams GFORCE RM)."""
        self._claim(name)
        marker = self._marker_for(name, marker, part, at)
        if frame is not None and frame not in self._markers:
            raise ModelError(f"load point '{name}': unknown frame marker '{frame}'.")
        self._load_points.append((name, marker, frame))
        return self

    def _marker_for(self, name, marker, part, at):
        if marker is None:
            if part is None or at is None:
                raise ModelError(f"'{name}': give a marker, or part= and at=.")
            marker = self.marker(f"{name}.m", part, at)
        elif marker not in self._markers:
            raise ModelError(f"'{name}' refers to unknown marker '{marker}'.")
        return marker

    def corner(self, corner=None, **fields) -> "MechanismBuilder":
        """Say which markers are the wheel: a `diffsusp.model.corner.Corner`, or its fields
        (`wheel_centre`, `contact_point`, `kingpin`, `side`, `frame`, `loaded_radius`,
        `design_load`, ...). The names are checked at build."""
        if corner is None:
            corner = Corner(**fields)
        elif fields:
            raise ModelError("corner: give a Corner or its fields, not both.")
        if any(c.prefix == corner.prefix for c in self._corners):
            raise ModelError(f"corner with prefix '{corner.prefix}' given twice.")
        self._corners.append(corner)
        return self

    # -- build --------------------------------------------------------------------------------

    def build(self, *, check: bool = True) -> Mechanism:
        """Stack everything into a `Mechanism`; with `check`, validate it (see `validate`)."""
        names = list(self._markers)
        index = {n: k for k, n in enumerate(names)}
        part_index = {p: k for k, p in enumerate(self._parts)} | {"ground": GROUND}
        markers = Markers(
            position=_array(np.array([self._markers[n][1] for n in names]).reshape(-1, 3)),
            orientation=_array(
                np.array([self._markers[n][2] for n in names]).reshape(-1, 3, 3)
            ),
            part=tuple(part_index[self._markers[n][0]] for n in names),
            names=tuple(names),
        )
        joints = Joints(
            kind=tuple(j[1] for j in self._joints),
            i_marker=tuple(index[j[2]] for j in self._joints),
            j_marker=tuple(index[j[3]] for j in self._joints),
            names=tuple(j[0] for j in self._joints),
        )
        bushings = self._stack_bushings(index)
        springs = self._stack_springs(index)
        st = self._stops
        stops = Stops(
            length=_array([s["length"] for s in st]),
            k=_array([s["k"] for s in st]),
            cubic=_array([s["cubic"] for s in st]),
            i_marker=tuple(index[s["i"]] for s in st),
            j_marker=tuple(index[s["j"]] for s in st),
            kind=tuple(s["kind"] for s in st),
            names=tuple(s["name"] for s in st),
        )
        drivers = Drivers(
            direction=_array(np.array([d[2] for d in self._drivers]).reshape(-1, 3)),
            marker=tuple(index[d[1]] for d in self._drivers),
            names=tuple(d[0] for d in self._drivers),
        )
        load_points = LoadPoints(
            marker=tuple(index[lp[1]] for lp in self._load_points),
            frame=tuple(GROUND if lp[2] is None else index[lp[2]] for lp in self._load_points),
            names=tuple(lp[0] for lp in self._load_points),
        )
        pos = np.array([self._markers[n][1] for n in names]).reshape(-1, 3)
        spread = np.sum((pos - pos.mean(0)) ** 2, axis=1) if len(pos) else np.ones(1)
        scale = float(np.sqrt(np.mean(spread)))
        mech = Mechanism(
            parts=tuple(self._parts),
            markers=markers,
            joints=joints,
            bushings=bushings,
            springs=springs,
            stops=stops,
            drivers=drivers,
            load_points=load_points,
            independent_rows=tuple(range(joints.n_rows + len(self._drivers))),
            length_scale=max(scale, 1.0),
            reference_points=tuple(
                tuple(float(v) for v in np.mean(
                    [self._markers[n][1] for n in names if self._markers[n][0] == part] or
                    [np.zeros(3)], axis=0))
                for part in self._parts
            ),
            name=self.name,
            corners=tuple(self._corners),
        )
        for c in self._corners:
            c.check_names(mech)
        return finalize(mech, check=check)

    def _stack_bushings(self, index) -> Bushings:
        bs = self._bushings
        n = len(bs)
        knots = {len(t[0]) for b in bs for t in b["splines"].values()}
        if len(knots) > 1:
            raise ModelError(
                f"bushing spline tables of one model must have the same number of knots; got "
                f"{sorted(knots)}. Resample the tables to a common knot count."
            )
        k = knots.pop() if knots else 2
        sx = np.tile(np.linspace(-1.0, 1.0, k), (n, 6, 1))
        sy = np.zeros((n, 6, k))
        mask = []
        for e, b in enumerate(bs):
            row = []
            for a, axis in enumerate(BUSHING_AXES):
                if axis in b["splines"]:
                    sx[e, a], sy[e, a] = b["splines"][axis]
                row.append(axis in b["splines"])
            mask.append(tuple(row))

        def stack(key):
            return _array(np.array([b[key] for b in bs]).reshape(n, 3))

        return Bushings(
            **{key: stack(key) for key in ("k_trans", "k_rot", "cubic_trans", "cubic_rot",
                                           "offset_trans", "offset_rot", "preload_force",
                                           "preload_torque")},
            spline_x=_array(sx), spline_y=_array(sy),
            i_marker=tuple(index[b["i"]] for b in bs),
            j_marker=tuple(index[b["j"]] for b in bs),
            spline_axes=tuple(mask),
            names=tuple(b["name"] for b in bs),
        )

    def _stack_springs(self, index) -> Springs:
        sp = self._springs
        knots = {len(s["table"][0]) for s in sp if s["table"] is not None}
        if len(knots) > 1:
            raise ModelError(
                f"spring tables of one model must have the same number of points; got "
                f"{sorted(knots)}."
            )
        k = knots.pop() if knots else 2
        tx = np.tile(np.linspace(-1.0, 1.0, k), (len(sp), 1))
        ty = np.zeros((len(sp), k))
        for e, s in enumerate(sp):
            if s["table"] is not None:
                tx[e], ty[e] = s["table"]
        return Springs(
            k=_array([s["k"] for s in sp]),
            free_length=_array([s["free_length"] for s in sp]),
            table_x=_array(tx), table_y=_array(ty),
            i_marker=tuple(index[s["i"]] for s in sp),
            j_marker=tuple(index[s["j"]] for s in sp),
            tabulated=tuple(s["table"] is not None for s in sp),
            names=tuple(s["name"] for s in sp),
        )


def _array(values) -> jax.Array:
    """A float array leaf, put on the device without a compiled conversion (building compiles
    nothing)."""
    return jax.device_put(np.asarray(values, dtype=float))


def _reuler_deg(angles_deg) -> np.ndarray:
    """`geometry.reuler_deg_to_matrix` in NumPy: Rz(ψ)·Rx(θ)·Rz(φ) of body-3-1-3 Euler angles
    in degrees (spec geometry §2.2 eq. 2.7)."""
    psi, theta, phi = np.deg2rad(np.asarray(angles_deg, dtype=float).reshape(3))

    def rz(a):
        return np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0],
                         [0.0, 0.0, 1.0]])

    c, s = np.cos(theta), np.sin(theta)
    return rz(psi) @ np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]) @ rz(phi)


def _table(table, what: str) -> tuple[np.ndarray, np.ndarray]:
    x, y = (np.asarray(a, dtype=float).ravel() for a in table)
    if x.shape != y.shape or x.size < 2:
        raise ModelError(f"{what}: x and y must have the same length (≥ 2).")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ModelError(f"{what}: values must be finite.")
    if np.any(np.diff(x) <= 0):
        raise ModelError(f"{what}: x must be strictly increasing.")
    return x, y
