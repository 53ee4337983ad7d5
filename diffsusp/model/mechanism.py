"""The mechanism pytree: parameters are float array leaves, topology is static.

Conventions (DESIGN.md): mm, N, N·mm, rad. q = 0 is the design position, where every part frame
coincides with the global frame, so every marker is given by its global pose at design. Elements of
one kind are stacked (arrays with a leading element axis); indices into the marker table and names
are static Python tuples.
"""

import dataclasses

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .kinds import GROUND, JOINT_ROWS
from .topology import Topology

BUSHING_AXES = ("tx", "ty", "tz", "rx", "ry", "rz")


def _index(names: tuple[str, ...], name: str, what: str, plural: str) -> int:
    try:
        return names.index(name)
    except ValueError:
        raise ValueError(f"unknown {what} '{name}'; known {plural}: {', '.join(names)}.") from None


def _check_markers(what: str, names: tuple[str, ...], markers: tuple[int, ...], n_markers: int):
    for name, m in zip(names, markers, strict=True):
        if not 0 <= m < n_markers:
            raise ValueError(f"{what} '{name}' refers to marker index {m}, which does not exist.")


class Markers(eqx.Module):
    """Frames fixed on parts, given by their global pose at design (q = 0).

    **Fields:** `position` (mm, global), `orientation` (columns are the marker axes in the
    global frame), `part` (part index, -1 for ground), `names`.
    """

    position: Float[Array, "m 3"] = eqx.field(metadata={"unit": "mm"})
    orientation: Float[Array, "m 3 3"] = eqx.field(
        metadata={"unit": "1 (rotation matrix, columns = axes)"})
    part: tuple[int, ...] = eqx.field(static=True)
    names: tuple[str, ...] = eqx.field(static=True)

    def __check_init__(self):
        m = len(self.names)
        if self.position.shape != (m, 3) or self.orientation.shape != (m, 3, 3):
            raise ValueError(
                f"Markers: position must have shape ({m}, 3) and orientation ({m}, 3, 3); got "
                f"{self.position.shape} and {self.orientation.shape}."
            )
        if len(self.part) != m:
            raise ValueError("Markers: 'part' must give one part index per marker.")

    def index(self, name: str) -> int:
        return _index(self.names, name, "marker", "markers")


class Joints(eqx.Module):
    """Ideal joints between marker I (on one part) and marker J (on another), Adams definitions.

    Kinds and rows (d = x_I − x_J, axes of I and J in the global frame): spherical d = 0;
    revolute d = 0, z_I·x_J = z_I·y_J = 0; cylindrical d·x_J = d·y_J = 0 and the revolute's two
    angular rows; translational = cylindrical + x_I·y_J = 0; universal d = 0, z_I·z_J = 0; fixed
    d = 0 and z_I·x_J = z_I·y_J = x_I·y_J = 0; inline d·x_J = d·y_J = 0; inplane d·z_J = 0;
    perpendicular z_I·z_J = 0; distance |d| = its design value (a massless link).
    spec: stiffness §1.6.
    """

    kind: tuple[str, ...] = eqx.field(static=True)
    i_marker: tuple[int, ...] = eqx.field(static=True)
    j_marker: tuple[int, ...] = eqx.field(static=True)
    names: tuple[str, ...] = eqx.field(static=True)

    def __check_init__(self):
        for name, kind in zip(self.names, self.kind, strict=True):
            if kind not in JOINT_ROWS:
                raise ValueError(
                    f"joint '{name}' has unknown kind '{kind}'; use one of "
                    f"{', '.join(JOINT_ROWS)}."
                )

    @property
    def n_rows(self) -> int:
        return sum(JOINT_ROWS[k] for k in self.kind)


class Bushings(eqx.Module):
    """Six-axis bushings in the Adams BUSHING convention, stacked.

    Deformation of I relative to J, in J: δ_T = R_Jᵀ(x_I − x_J) (mm) and the projected angles
    (AX, AY, AZ) of R_{I/J} (rad). Per axis, with e = δ − offset, the force on I in J axes is
    −(k·e + cubic·e³) + preload, or the axis's spline value y(e) (A/Car: y = −k·x for a linear
    spline) where `spline_axes` says so. J receives F_J = −F_I, T_J = −T_I − δ × F_I.
    spec: stiffness §1.8 and §4.3; DESIGN.md "Bushings".

    **Fields:** `k_trans` (N/mm), `k_rot` (N·mm/rad), `cubic_trans` (N/mm³), `cubic_rot`
    (N·mm/rad³), `offset_trans` (mm), `offset_rot` (rad), `preload_force` (N),
    `preload_torque` (N·mm), all `(n, 3)` in the J frame; `spline_x`, `spline_y` `(n, 6, k)`
    tables (mm or rad → N or N·mm) used on the axes flagged in the static `spline_axes`.
    """

    k_trans: Float[Array, "n 3"] = eqx.field(metadata={"unit": "N/mm"})
    k_rot: Float[Array, "n 3"] = eqx.field(metadata={"unit": "N·mm/rad"})
    cubic_trans: Float[Array, "n 3"] = eqx.field(metadata={"unit": "N/mm³"})
    cubic_rot: Float[Array, "n 3"] = eqx.field(metadata={"unit": "N·mm/rad³"})
    offset_trans: Float[Array, "n 3"] = eqx.field(metadata={"unit": "mm"})
    offset_rot: Float[Array, "n 3"] = eqx.field(metadata={"unit": "rad"})
    preload_force: Float[Array, "n 3"] = eqx.field(metadata={"unit": "N"})
    preload_torque: Float[Array, "n 3"] = eqx.field(metadata={"unit": "N·mm"})
    spline_x: Float[Array, "n 6 k"] = eqx.field(
        metadata={"unit": "mm (tx, ty, tz) | rad (rx, ry, rz)"})
    spline_y: Float[Array, "n 6 k"] = eqx.field(
        metadata={"unit": "N (tx, ty, tz) | N·mm (rx, ry, rz)"})
    i_marker: tuple[int, ...] = eqx.field(static=True)
    j_marker: tuple[int, ...] = eqx.field(static=True)
    spline_axes: tuple[tuple[bool, ...], ...] = eqx.field(static=True)
    names: tuple[str, ...] = eqx.field(static=True)

    def __check_init__(self):
        n = len(self.names)
        for field in ("k_trans", "k_rot", "cubic_trans", "cubic_rot", "offset_trans",
                      "offset_rot", "preload_force", "preload_torque"):
            shape = getattr(self, field).shape
            if shape != (n, 3):
                raise ValueError(f"Bushings.{field} must have shape ({n}, 3); got {shape}.")
        if self.spline_x.shape[:2] != (n, 6) or self.spline_x.shape != self.spline_y.shape:
            raise ValueError(
                f"Bushings.spline_x and spline_y must both have shape ({n}, 6, k); got "
                f"{self.spline_x.shape} and {self.spline_y.shape}."
            )

    @property
    def has_splines(self) -> bool:
        return any(any(row) for row in self.spline_axes)

    def index(self, name: str) -> int:
        return _index(self.names, name, "bushing", "bushings")


class Springs(eqx.Module):
    """Springs acting along the line of two markers (tension positive), stacked.

    Linear: tension = k·(ℓ − free_length). Tabulated (static flag `tabulated`): tension is the
    Akima interpolant of (`table_x` = ℓ − free_length in mm, `table_y` = tension in N), linear
    beyond the ends. spec: stiffness §1.7.

    **Fields:** `k` (N/mm), `free_length` (mm), `table_x`, `table_y` `(n, k)`.
    """

    k: Float[Array, " n"] = eqx.field(metadata={"unit": "N/mm"})
    free_length: Float[Array, " n"] = eqx.field(metadata={"unit": "mm"})
    table_x: Float[Array, "n k"] = eqx.field(metadata={"unit": "mm (extension)"})
    table_y: Float[Array, "n k"] = eqx.field(metadata={"unit": "N (tension)"})
    i_marker: tuple[int, ...] = eqx.field(static=True)
    j_marker: tuple[int, ...] = eqx.field(static=True)
    tabulated: tuple[bool, ...] = eqx.field(static=True)
    names: tuple[str, ...] = eqx.field(static=True)

    def __check_init__(self):
        n = len(self.names)
        if self.k.shape != (n,) or self.free_length.shape != (n,):
            raise ValueError(f"Springs.k and Springs.free_length must have shape ({n},).")
        if self.table_x.shape[0] != n or self.table_x.shape != self.table_y.shape:
            raise ValueError(f"Springs.table_x and table_y must both have shape ({n}, k).")


class Stops(eqx.Module):
    """One-sided bump (compression) and rebound (extension) stops on the distance of two markers.

    Penetration p = length − ℓ for a bump stop (engaged when ℓ < length) and ℓ − length for a
    rebound stop; force k·p + cubic·p³ for p > 0, pushing the markers apart (bump) or pulling
    them together (rebound), zero otherwise.

    **Fields:** `length` (mm), `k` (N/mm), `cubic` (N/mm³); static `kind` ("bump"/"rebound").
    """

    length: Float[Array, " n"] = eqx.field(metadata={"unit": "mm"})
    k: Float[Array, " n"] = eqx.field(metadata={"unit": "N/mm"})
    cubic: Float[Array, " n"] = eqx.field(metadata={"unit": "N/mm³"})
    i_marker: tuple[int, ...] = eqx.field(static=True)
    j_marker: tuple[int, ...] = eqx.field(static=True)
    kind: tuple[str, ...] = eqx.field(static=True)
    names: tuple[str, ...] = eqx.field(static=True)


class Drivers(eqx.Module):
    """Motion drivers: prescribe the travel of a marker along a global direction.

    Row: (x_m(q) − x_m(0))·direction − value = 0, with `value` (mm) taken from the load case
    (e.g. wheel-centre height, rack travel).

    **Fields:** `direction` (n, 3) unit vectors in the global frame.
    """

    direction: Float[Array, "n 3"] = eqx.field(metadata={"unit": "1 (unit vector)"})
    marker: tuple[int, ...] = eqx.field(static=True)
    names: tuple[str, ...] = eqx.field(static=True)


class LoadPoints(eqx.Module):
    """Where external forces and moments act: a marker, and the frame their components are in.

    `frame` is a marker index (Adams GFORCE RM: components in that marker's current axes) or -1
    for global components.
    """

    marker: tuple[int, ...] = eqx.field(static=True)
    frame: tuple[int, ...] = eqx.field(static=True)
    names: tuple[str, ...] = eqx.field(static=True)

    def index(self, name: str) -> int:
        return _index(self.names, name, "load point", "load points")


class Loads(eqx.Module):
    """One load case (or a table of them, with a leading case axis on every array).

    **Fields:** `force` (N) and `moment` (N·mm) per load point, in the frame the load point names;
    `driver` values (mm) per motion driver; `contact_radius` (mm, optional, per load point):
    where it is > 0 the load point's force acts at the *ground contact point* of a wheel of that
    radius about the load point's marker — the lowest point, along the road normal (global +z),
    of the circle of that radius in the plane normal to the marker's z axis (the spin axis):
    C = x_m − R·u, u = unit(e_z − (e_z·s)s). C moves with the wheel plane, not with the wheel
    carrier (`diffsusp.kc`: the tyre force of a K&C rig; spec kc §1). None: every load acts at
    its marker.
    """

    force: Float[Array, "*cases l 3"] = eqx.field(metadata={"unit": "N"})
    moment: Float[Array, "*cases l 3"] = eqx.field(metadata={"unit": "N·mm"})
    driver: Float[Array, "*cases d"] = eqx.field(metadata={"unit": "mm"})
    contact_radius: Float[Array, "*cases l"] | None = eqx.field(default=None,
                                                                 metadata={"unit": "mm"})

    @property
    def n_cases(self) -> int | None:
        return None if self.force.ndim == 2 else self.force.shape[0]


class Mechanism(eqx.Module):
    """A suspension model: parts, markers, joints, force elements, drivers and load points.

    Every physical number is a float array leaf (differentiable, batchable, identifiable);
    topology and names are static. Build one with `diffsusp.MechanismBuilder`.
    `independent_rows` lists the constraint rows (joints then drivers) kept in the solve: rows
    found redundant at design are dropped, as Adams does, and reported by `validate`.
    `reference_points` (one per part, its markers' centroid at design, mm) are where the solver
    measures each part's translation internally; they do not change any result. `corners`
    describe the wheel(s) (`diffsusp.model.corner.Corner`; empty when the model states none).
    """

    parts: tuple[str, ...] = eqx.field(static=True)
    markers: Markers
    joints: Joints
    bushings: Bushings
    springs: Springs
    stops: Stops
    drivers: Drivers
    load_points: LoadPoints
    independent_rows: tuple[int, ...] = eqx.field(static=True)
    length_scale: float = eqx.field(static=True)
    reference_points: tuple[tuple[float, float, float], ...] = eqx.field(static=True)
    name: str = eqx.field(static=True, default="mechanism")
    corners: tuple = eqx.field(static=True, default=())
    """The wheels of the model (`diffsusp.model.corner.Corner`, one per half axle, each with the
    name prefix of its half in a combined axle): which markers and load points K&C uses."""
    topology: object = eqx.field(static=True, default=None, init=False, repr=False)
    """Index data of the solver (`diffsusp.model.topology.Topology`), resolved once here."""

    def __post_init__(self):
        self.__check_init__()
        self.topology = Topology(self)

    def __check_init__(self):
        n_markers = len(self.markers.names)
        for part in self.markers.part:
            if not (part == GROUND or 0 <= part < len(self.parts)):
                raise ValueError(f"a marker refers to part index {part}, which does not exist.")
        for what, elements in (
            ("joint", self.joints),
            ("bushing", self.bushings),
            ("spring", self.springs),
            ("stop", self.stops),
        ):
            _check_markers(what, elements.names, elements.i_marker, n_markers)
            _check_markers(what, elements.names, elements.j_marker, n_markers)
        _check_markers("driver", self.drivers.names, self.drivers.marker, n_markers)
        _check_markers("load point", self.load_points.names, self.load_points.marker, n_markers)

    @property
    def n_coordinates(self) -> int:
        return 6 * len(self.parts)

    @property
    def n_rows(self) -> int:
        """All constraint rows, joints then drivers (before dropping redundant ones)."""
        return self.joints.n_rows + len(self.drivers.names)

    @property
    def n_multipliers(self) -> int:
        return len(self.independent_rows)

    def part_index(self, name: str) -> int:
        if name == "ground":
            return GROUND
        try:
            return self.parts.index(name)
        except ValueError:
            raise ValueError(
                f"unknown part '{name}'; known parts: ground, {', '.join(self.parts)}."
            ) from None

    def loads(
        self,
        forces: dict | None = None,
        moments: dict | None = None,
        drivers: dict | None = None,
    ) -> Loads:
        """Build `Loads` from named load points and drivers.

        **Arguments:** `forces` / `moments`: load-point name → array `(3,)` or `(cases, 3)` (N,
        N·mm, in the load point's frame); `drivers`: driver name → value(s) (mm). Anything not
        given is zero. All given arrays must agree on the number of cases.

        **Returns:** a `Loads` with a leading case axis if any input had one.
        """
        forces, moments, drivers = forces or {}, moments or {}, drivers or {}
        arrays = [jnp.asarray(v, dtype=float) for v in (*forces.values(), *moments.values())]
        arrays_d = [jnp.asarray(v, dtype=float) for v in drivers.values()]
        cases = {a.shape[0] for a in arrays if a.ndim == 2} | {
            a.shape[0] for a in arrays_d if a.ndim == 1
        }
        if len(cases) > 1:
            raise ValueError(f"load arrays disagree on the number of cases: {sorted(cases)}.")
        batch = tuple(cases)
        n_l, n_d = len(self.load_points.names), len(self.drivers.names)
        force = jnp.zeros((*batch, n_l, 3))
        moment = jnp.zeros((*batch, n_l, 3))
        driver = jnp.zeros((*batch, n_d))
        for table, target in ((forces, "force"), (moments, "moment")):
            for name, value in table.items():
                value = jnp.asarray(value, dtype=float)
                if value.shape[-1:] != (3,):
                    raise ValueError(
                        f"{target} at '{name}' must have 3 components (x, y, z); got shape "
                        f"{value.shape}."
                    )
                i = self.load_points.index(name)
                if target == "force":
                    force = force.at[..., i, :].set(value)
                else:
                    moment = moment.at[..., i, :].set(value)
        for name, value in drivers.items():
            if name not in self.drivers.names:
                raise ValueError(
                    f"unknown driver '{name}'; known drivers: {', '.join(self.drivers.names)}."
                )
            driver = driver.at[..., self.drivers.names.index(name)].set(jnp.asarray(value))
        return Loads(force=force, moment=moment, driver=driver)

    def describe(self) -> str:
        """A one-paragraph summary (counts of parts, joints, elements)."""
        return (
            f"{self.name}: {len(self.parts)} moving parts ({self.n_coordinates} coordinates), "
            f"{len(self.joints.names)} joints ({self.joints.n_rows} rows), "
            f"{len(self.drivers.names)} drivers, {len(self.bushings.names)} bushings, "
            f"{len(self.springs.names)} springs, {len(self.stops.names)} stops, "
            f"{len(self.load_points.names)} load points."
        )


def field_unit(tree, path: tuple[str, ...]) -> str:
    """The unit of the array field at `path` of a `Mechanism` (e.g. `("bushings", "k_rot")` →
    `'N·mm/rad'`): the `unit` metadata each parameter field declares, so that reports,
    tables and plots read one source. `'-'` for a field without one."""
    node = tree
    for name in path[:-1]:
        node = getattr(node, name)
    for field in dataclasses.fields(node):
        if field.name == path[-1]:
            return field.metadata.get("unit", "-")
    raise KeyError(f"{type(node).__name__} has no field {path[-1]!r}")


PARAMETER_UNITS = {
    f"{group}.{field.name}": field.metadata["unit"]
    for group, cls in (("markers", Markers), ("bushings", Bushings), ("springs", Springs),
                       ("stops", Stops), ("drivers", Drivers))
    for field in dataclasses.fields(cls) if "unit" in field.metadata
}
"""Unit of every float leaf of a `Mechanism` (the parameters one can differentiate and fit),
from the fields' `unit` metadata."""


def parameter_leaves(mech: Mechanism) -> list[dict]:
    """Path, shape and unit of every non-empty array leaf of `mech` (its parameters: what one
    can differentiate and fit), in pytree order: `[{"path": "bushings.k", "shape": [4, 3],
    "unit": "N/mm"}, ...]`; the unit from `PARAMETER_UNITS` (`'?'` for a leaf without one)."""
    import jax

    return [dict(path=(name := jax.tree_util.keystr(path).lstrip(".")),
                 shape=list(leaf.shape), unit=PARAMETER_UNITS.get(name, "?"))
            for path, leaf in jax.tree_util.tree_leaves_with_path(mech)
            if hasattr(leaf, "shape") and np.size(leaf) > 0]


def describe(mech: Mechanism) -> dict:
    """What `mech` is made of, as plain data (what `diffsusp info` prints; DESIGN.md
    "Architecture"):
    `name`, `parts` (names), `markers` (count), `joints` (`{"name", "kind", "i", "j"}` with
    the marker names), the names of its `bushings`, `springs`, `stops`, `drivers` and
    `load_points`, and its `corners` (`{"prefix", "wheel_centre", "contact_point",
    "wheel_centre_load", "kingpin", "side", "frame", "loaded_radius", "design_load"}`: marker
    and load point names, the kingpin's two ends as marker names or `{"part", "offset"}` (None
    without a kingpin), the side resolved (`Corner.side_in`), the loaded radius in mm and the
    design load in N, None when it is computed). Its parameters: `parameter_leaves`."""
    names = mech.markers.names
    joints = mech.joints
    return dict(
        name=mech.name,
        parts=list(mech.parts),
        markers=len(names),
        joints=[dict(name=n, kind=k, i=names[i], j=names[j]) for n, k, i, j in zip(
            joints.names, joints.kind, joints.i_marker, joints.j_marker, strict=True)],
        bushings=list(mech.bushings.names),
        springs=list(mech.springs.names),
        stops=list(mech.stops.names),
        drivers=list(mech.drivers.names),
        load_points=list(mech.load_points.names),
        corners=[_corner_summary(c, mech) for c in mech.corners],
    )


def _corner_summary(c, mech) -> dict:
    return dict(prefix=c.prefix, wheel_centre=c.wheel_centre, contact_point=c.contact_point,
                wheel_centre_load=c.wheel_centre_load,
                kingpin=None if c.kingpin is None else [
                    r if isinstance(r, str) else {"part": r[0], "offset": list(r[1])}
                    for r in c.kingpin],
                side=c.side_in(mech), frame=c.frame, loaded_radius=c.loaded_radius,
                design_load=c.design_load)
