"""The interpreter of an Adams dataset: from the parsed statements (`adams_parse.AdmModel`) to
a `MechanismBuilder` (the subset and its rules are in `adams`'s docstring; spec stiffness §4.1,
§6 item 10), and `parse_adm`, which attaches it to the parsed model for `AdmModel.build` and
`AdmModel.loads`. It evaluates function expressions with the grammar of `expr`, never by
executing file content."""

import dataclasses
import math
import re
import warnings

import jax.numpy as jnp
import numpy as np

from ..errors import ModelError, ModelWarning
from ..geometry import reuler_to_matrix
from ..model import Loads, Mechanism, MechanismBuilder
from ..model.builder import frame_from_axes
from .adams_common import FORCE_TO_N, LENGTH_TO_MM, SYSTEMS, error
from .adams_parse import (
    AdmModel,
    AdmSpline,
    AdmStatement,
    AdmValue,
    SkippedStatement,
    parse_statements,
    stop_of_function,
)
from .expr import (
    ExpressionError,
    distance_constraint,
    evaluate,
    parse_expression,
)

_IGNORED_IN_STATICS = {"MASS", "CM", "IP", "IM", "VX", "VY", "VZ", "WX", "WY", "WZ", "VM", "WM",
                       "EXACT", "C", "CT", "IC", "ICTRAN", "ICROT", "ICDISP", "ICVEL", "DELTA_V",
                       "MAXIMUM_DEFORMATION"}
_KNOWN = {
    # statement: (arguments, flags) read or deliberately ignored (masses, damping, initial
    # conditions); anything else is reported in `AdmModel.skipped`.
    "UNITS": ({"FORCE", "MASS", "LENGTH", "TIME", "SYSTEM"}, set()),
    "PART": ({"QG", "REULER", "ZG", "XG"}, {"GROUND"}),
    "MARKER": ({"PART", "QP", "REULER", "ZP", "XP"}, {"FLOATING", "USEXP"}),
    "JOINT": ({"I", "J"}, {"SPHERICAL", "REVOLUTE", "CYLINDRICAL", "TRANSLATIONAL", "UNIVERSAL",
                           "FIXED", "HOOKE", "PLANAR", "RACKPIN", "SCREW", "CONVEL"}),
    "JPRIM": ({"I", "J"}, {"INLINE", "INPLANE", "PERPENDICULAR", "ATPOINT", "ORIENTATION",
                           "PARALLEL_AXES"}),
    "BUSHING": ({"I", "J", "K", "KT", "FORCE", "TORQUE"}, set()),
    "SPRINGDAMPER": ({"I", "J", "K", "KT", "LENGTH", "FORCE", "ANGLE", "TORQUE"},
                     {"TRANSLATIONAL", "ROTATIONAL"}),
    "SFORCE": ({"I", "J", "FUNCTION"}, {"TRANSLATIONAL", "ROTATIONAL", "ACTIONONLY"}),
    "GFORCE": ({"I", "JFLOAT", "RM", "FX", "FY", "FZ", "TX", "TY", "TZ", "FUNCTION"}, set()),
    "VFORCE": ({"I", "JFLOAT", "RM", "FX", "FY", "FZ", "FUNCTION"}, set()),
    "VTORQUE": ({"I", "JFLOAT", "RM", "TX", "TY", "TZ", "FUNCTION"}, set()),
    "SPLINE": ({"X", "Y", "Z", "FILE"}, {"LINEAR_EXTRAPOLATE"}),
    "MOTION": ({"I", "J", "JOINT", "FUNCTION"}, {"X", "Y", "Z", "B1", "B2", "B3", "TRANSLATION",
                                                 "ROTATION", "DISPLACEMENT", "VELOCITY",
                                                 "ACCELERATION"}),
    "GCON": ({"I", "FUNCTION"}, set()),
}
_INTEGER = re.compile(r"[+-]?\d{1,18}")
_REAL = re.compile(r"([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)([dD]?)")


@dataclasses.dataclass
class _Marker:
    id: int
    part: int
    name: str
    position: np.ndarray
    orientation: np.ndarray
    floating: bool
    line: int
    named: bool


@dataclasses.dataclass
class _Load:
    """An external load (load point) defined by GFORCE/VFORCE/VTORQUE/action-only SFORCE."""

    name: str
    statement: AdmStatement
    force: tuple            # 3 expression trees (or None) in the frame below
    moment: tuple
    rotation: np.ndarray    # file frame → load point frame (identity, or RM's axes → global)


@dataclasses.dataclass
class _Driver:
    name: str
    statement: AdmStatement
    function: object
    offset: float


def _real(value: AdmValue, path, what, *, angle=False) -> float:
    m = _REAL.fullmatch(value.text)
    if m is None:
        raise error(f"{what}: {value.text!r} is not a number.", path, value.line, what)
    x = float(m.group(1))
    if not math.isfinite(x):
        raise error(f"{what}: {value.text} is not a finite number.", path, value.line, what)
    if m.group(2):
        if not angle:
            raise error(f"{what}: the degree suffix D is only allowed on angles.", path,
                        value.line, what)
        x = math.radians(x)
    return x


def _check_magnitude(values, path, line, what, limit=1e15):
    if any(abs(v) > limit for v in values):
        raise error(f"{what}: {values} exceeds {limit:g} in magnitude; check the value and "
                    "its units.", path, line, what)


class AdmPlan:
    """The statements interpreted as builder calls and load definitions (no JAX here)."""

    def __init__(self, model: AdmModel):
        self.model = model
        self.path = model.path
        self.statements = model.statements
        self.by_key: dict[tuple[str, int], AdmStatement] = {}
        for s in model.statements:
            if s.id is not None:
                key = (s.keyword, s.id)
                if key in self.by_key:
                    raise error(f"{s.keyword}/{s.id} is defined twice (first at line "
                                f"{self.by_key[key].line}).", self.path, s.line)
                self.by_key[key] = s
                if s.name:
                    model.names[(s.keyword, s.id)] = s.name
        for s in model.statements:
            arguments, flags = _KNOWN[s.keyword]
            unknown = [a for a in s.arguments if a not in arguments | _IGNORED_IN_STATICS]
            unknown += [f for f in s.flags if f not in flags]
            if unknown:
                self.skip(s, "argument(s) outside the subset ignored: " + ", ".join(unknown))
        self._units()
        self._parts()
        self._markers()
        self._elements()

    # -- helpers ------------------------------------------------------------------------

    def skip(self, s: AdmStatement, reason: str):
        self.model.skipped.append(SkippedStatement(s.keyword, s.id, s.name, s.line, reason))

    def reals(self, s, key, count=None, *, default=None, angle=False, scale=1.0):
        arg = s.arguments.get(key)
        if arg is None:
            if default is None:
                raise error(f"{s.label}: {key} is missing.", self.path, s.line, key)
            return list(default)
        if arg.expression is not None:
            raise error(f"{s.label}: {key} must be numbers.", self.path, arg.line, key)
        out = [_real(v, self.path, f"{s.label} {key}", angle=angle) * scale for v in arg.values]
        if count is not None and len(out) != count:
            raise error(f"{s.label}: {key} needs {count} value(s); got {len(out)}.",
                        self.path, arg.line, key)
        _check_magnitude(out, self.path, arg.line, f"{s.label} {key}")
        return out

    def integer(self, s, key, *, required=True):
        arg = s.arguments.get(key)
        if arg is None:
            if required:
                raise error(f"{s.label}: {key} is missing.", self.path, s.line, key)
            return None
        if len(arg.values) != 1 or not _INTEGER.fullmatch(arg.values[0].text):
            raise error(f"{s.label}: {key} must be one integer id.", self.path, arg.line, key)
        return int(arg.values[0].text)

    def word(self, s, key):
        arg = s.arguments.get(key)
        if arg is None:
            return None
        if len(arg.values) != 1:
            raise error(f"{s.label}: {key} must be one word.", self.path, arg.line, key)
        return arg.values[0].text.strip("'\"").upper()

    def marker(self, s, key) -> _Marker:
        ident = self.integer(s, key)
        if ident not in self.markers:
            raise error(f"{s.label}: {key} = {ident} is not a defined MARKER.", self.path,
                        s.arguments[key].line, key)
        return self.markers[ident]

    def expression(self, s, key):
        arg = s.arguments.get(key)
        if arg is None:
            return None
        if arg.expression is None:
            raise error(f"{s.label}: {key} must be a function expression.", self.path,
                        arg.line, key)
        try:
            return parse_expression(arg.expression)
        except ExpressionError as e:
            raise _Unsupported(f"{key} = {arg.expression[:60]!r}: {e}") from None

    # -- units, parts, markers ------------------------------------------------------------

    def _units(self):
        model = self.model
        length, force = "MILLIMETER", "NEWTON"
        units = [s for s in self.statements if s.keyword == "UNITS"]
        if len(units) > 1:
            raise error("UNITS/ is given twice.", self.path, units[1].line)
        if units:
            s = units[0]
            system = self.word(s, "SYSTEM")
            if system is not None:
                if system not in SYSTEMS:
                    raise error(f"UNITS/: SYSTEM = {system} is not one of "
                                f"{', '.join(SYSTEMS)}.", self.path, s.line, "SYSTEM")
                length, force = SYSTEMS[system]
            length = self.word(s, "LENGTH") or length
            force = self.word(s, "FORCE") or force
            for key in ("FORCE", "MASS", "LENGTH", "TIME", "SYSTEM"):
                if (value := self.word(s, key)) is not None:
                    model.units[key] = value
            if length not in LENGTH_TO_MM:
                raise error(f"UNITS/: LENGTH = {length} is not one of "
                            f"{', '.join(LENGTH_TO_MM)}.", self.path, s.line, "LENGTH")
            if force not in FORCE_TO_N:
                raise error(f"UNITS/: FORCE = {force} is not one of "
                            f"{', '.join(FORCE_TO_N)}.", self.path, s.line, "FORCE")
        model.length_to_mm = LENGTH_TO_MM[length]
        model.force_to_n = FORCE_TO_N[force]
        self.lf, self.ff = model.length_to_mm, model.force_to_n

    def _frame(self, s, origin_key, z_key, x_key):
        """(position, rotation) from QP/QG + REULER or ZP/XP (ZG/XG), in the parent frame."""
        origin = np.array(self.reals(s, origin_key, 3, default=(0, 0, 0), scale=self.lf))
        has_euler = "REULER" in s.arguments
        if has_euler and z_key in s.arguments:
            raise error(f"{s.label}: give REULER or {z_key}/{x_key}, not both.", self.path,
                        s.line, z_key)
        if has_euler:
            angles = self.reals(s, "REULER", 3, angle=True)
            rot = np.asarray(reuler_to_matrix(jnp.asarray(angles, dtype=float)))
        elif z_key in s.arguments:
            z = np.array(self.reals(s, z_key, 3, scale=self.lf)) - origin
            x = (np.array(self.reals(s, x_key, 3, scale=self.lf)) - origin
                 if x_key in s.arguments else None)
            try:
                rot = frame_from_axes(z, x)
            except ModelError as e:
                raise error(f"{s.label}: {e}", self.path, s.line, z_key) from None
        else:
            rot = np.eye(3)
        return origin, rot

    def _parts(self):
        self.ground = None
        self.parts: dict[int, tuple[str, np.ndarray, np.ndarray, int]] = {}
        parts = [s for s in self.statements if s.keyword == "PART"]
        names = _unique_names([s for s in parts if "GROUND" not in s.flags], "PART", {"ground"})
        for s in parts:
            if s.keyword != "PART":
                continue
            if s.id is None:
                raise error("PART/ needs an id.", self.path, s.line)
            if "GROUND" in s.flags:
                if self.ground is not None:
                    raise error(f"PART/{s.id}: a second GROUND part (the first is "
                                f"PART/{self.ground}).", self.path, s.line)
                self.ground = s.id
                self.parts[s.id] = ("ground", np.zeros(3), np.eye(3), s.line)
                continue
            position, rot = self._frame(s, "QG", "ZG", "XG")
            self.parts[s.id] = (names[s.line], position, rot, s.line)

    def _markers(self):
        self.markers: dict[int, _Marker] = {}
        names = _unique_names([s for s in self.statements if s.keyword == "MARKER"], "MARKER")
        for s in self.statements:
            if s.keyword != "MARKER":
                continue
            if s.id is None:
                raise error("MARKER/ needs an id.", self.path, s.line)
            part = self.integer(s, "PART")
            if part not in self.parts:
                raise error(f"{s.label}: PART = {part} is not a defined PART.", self.path,
                            s.arguments["PART"].line, "PART")
            floating = "FLOATING" in s.flags
            _, p_part, r_part, _ = self.parts[part]
            if floating:
                position, rot = np.zeros(3), np.eye(3)
            else:
                qp, r_local = self._frame(s, "QP", "ZP", "XP")
                position, rot = p_part + r_part @ qp, r_part @ r_local
            self.markers[s.id] = _Marker(s.id, part, names[s.line], position, rot, floating,
                                         s.line, bool(s.name))

    # -- elements --------------------------------------------------------------------------

    def _elements(self):
        handlers_keys = ("JOINT", "JPRIM", "GCON", "BUSHING", "SPRINGDAMPER", "SFORCE",
                         "GFORCE", "VFORCE", "VTORQUE", "MOTION")
        self.calls: list[tuple[AdmStatement, str, tuple, dict]] = []
        self.load_defs: list[_Load] = []
        self.driver_defs: list[_Driver] = []
        self.internal: list[tuple[AdmStatement, object]] = []
        self.frame_use: dict[int, int] = {}
        self.geometry_use: dict[int, int] = {}
        elements = [s for s in self.statements if s.keyword in handlers_keys]
        self.element_names = _unique_names(elements, None, {"ground"})
        self.loads_frame: dict[str, tuple[int, int]] = {}
        handlers = {
            "JOINT": self._joint, "JPRIM": self._joint, "GCON": self._gcon,
            "BUSHING": self._bushing, "SPRINGDAMPER": self._springdamper,
            "SFORCE": self._sforce, "GFORCE": self._gforce, "VFORCE": self._gforce,
            "VTORQUE": self._gforce, "MOTION": self._motion, "SPLINE": self._spline,
        }
        for s in self.statements:
            handler = handlers.get(s.keyword)
            if handler is None:
                continue
            if s.id is None:
                raise error(f"{s.keyword}/ needs an id.", self.path, s.line)
            try:
                handler(s)
            except _Unsupported as e:
                if s.keyword in ("GFORCE", "VFORCE", "VTORQUE"):
                    self._load_point_only(s, e)
                else:
                    self.skip(s, str(e))

    def _load_point_only(self, s, reason):
        """A load whose values cannot be read keeps its load point (the K&C tables and the
        CLI's load tables need it) with no load from the file; one that cannot be placed is
        skipped with a reason that names the load point the model will not have (never a
        silently missing load point)."""
        name = self.element_name(s)
        try:
            self._gforce(s, values=False)
        except _Unsupported as e:
            self.skip(s, f"{e}; THE MODEL HAS NO LOAD POINT '{name}' (rewrite the statement in "
                         "the supported subset to keep it)")
            return
        self.skip(s, f"{reason}; its load point '{name}' is kept with no load from the file "
                     "(give its loads in a load table)")

    def use(self, marker: _Marker, kind: str):
        table = self.geometry_use if kind == "geometry" else self.frame_use
        table[marker.id] = table.get(marker.id, 0) + 1

    def element_name(self, s: AdmStatement) -> str:
        return self.element_names[s.line]

    def pair(self, s, i_key="I", j_key="J"):
        i, j = self.marker(s, i_key), self.marker(s, j_key)
        for m, key in ((i, i_key), (j, j_key)):
            if m.floating:
                raise error(f"{s.label}: {key} = {m.id} is a FLOATING marker; only "
                            "GFORCE/VFORCE/VTORQUE reactions (JFLOAT) may use one.",
                            self.path, s.arguments[key].line, key)
        return i, j

    def _joint(self, s):
        kinds = {"SPHERICAL": "spherical", "REVOLUTE": "revolute",
                 "CYLINDRICAL": "cylindrical", "TRANSLATIONAL": "translational",
                 "UNIVERSAL": "universal", "FIXED": "fixed"}
        if s.keyword == "JPRIM":
            kinds = {"INLINE": "inline", "INPLANE": "inplane",
                     "PERPENDICULAR": "perpendicular", "ATPOINT": "spherical"}
        found = [f for f in s.flags if f in kinds]
        if len(found) != 1:
            others = [f for f in s.flags if f not in kinds]
            raise _Unsupported(
                f"joint type {'/'.join(others) or 'missing'} is not supported (supported: "
                f"{', '.join(kinds)})")
        i, j = self.pair(s)
        self.use(i, "geometry")
        self.use(j, "geometry")
        self.calls.append((s, "joint", (self.element_name(s), kinds[found[0]], i.id, j.id), {}))

    def _gcon(self, s):
        node = self.expression(s, "FUNCTION")
        found = distance_constraint(node) if node is not None else None
        if found is None:
            raise _Unsupported("only GCON FUNCTION = DM(i, j) - L (a distance constraint) is "
                               "supported")
        a, b, length = found
        for ident in (a, b):
            if ident not in self.markers or self.markers[ident].floating:
                raise error(f"{s.label}: DM({a}, {b}) refers to marker {ident}, which is not "
                            "a defined fixed MARKER.", self.path, s.line, "FUNCTION")
        i, j = self.markers[a], self.markers[b]
        design = float(np.linalg.norm(i.position - j.position))
        length *= self.lf
        if abs(design - length) > 1e-6 * max(1.0, design):
            raise error(f"{s.label}: DM({a}, {b}) - L with L = {length:.9g} mm, but the "
                        f"markers are {design:.9g} mm apart at design; the design position "
                        "must satisfy the constraint.", self.path, s.line, "FUNCTION")
        self.use(i, "geometry")
        self.use(j, "geometry")
        self.calls.append((s, "joint", (self.element_name(s), "distance", i.id, j.id), {}))

    def _bushing(self, s):
        i, j = self.pair(s)
        self.use(i, "geometry")
        self.use(j, "geometry")
        k_scale = self.ff / self.lf
        kt_scale = self.ff * self.lf
        kw = dict(
            k_trans=self.reals(s, "K", 3, default=(0, 0, 0), scale=k_scale),
            k_rot=self.reals(s, "KT", 3, default=(0, 0, 0), scale=kt_scale),
            preload_force=self.reals(s, "FORCE", 3, default=(0, 0, 0), scale=self.ff),
            preload_torque=self.reals(s, "TORQUE", 3, default=(0, 0, 0), scale=kt_scale),
        )
        self.reals(s, "C", 3, default=(0, 0, 0))
        self.reals(s, "CT", 3, default=(0, 0, 0))
        self.calls.append((s, "bushing", (self.element_name(s), i.id, j.id), kw))

    def _springdamper(self, s):
        i, j = self.pair(s)
        self.use(i, "geometry")
        self.use(j, "geometry")
        name = self.element_name(s)
        if "ROTATIONAL" in s.flags:
            kt = self.reals(s, "KT", 1, default=(0,), scale=self.ff * self.lf)[0]
            angle = self.reals(s, "ANGLE", 1, default=(0,), angle=True)[0]
            torque = self.reals(s, "TORQUE", 1, default=(0,), scale=self.ff * self.lf)[0]
            self.reals(s, "CT", 1, default=(0,))
            kw = dict(k_rot=(0.0, 0.0, kt), offset_rot=(0.0, 0.0, angle),
                      preload_torque=(0.0, 0.0, torque))
            self.calls.append((s, "bushing", (name, i.id, j.id), kw))
            return
        k = self.reals(s, "K", 1, default=(0,), scale=self.ff / self.lf)[0]
        length = self.reals(s, "LENGTH", 1, default=(0,), scale=self.lf)[0]
        force = self.reals(s, "FORCE", 1, default=(0,), scale=self.ff)[0]
        self.reals(s, "C", 1, default=(0,))
        self.calls.append((s, "spring", (name, i.id, j.id), _spring_law(k, length, force)))

    def _sforce(self, s):
        arg = s.arguments.get("FUNCTION")
        stop = None if arg is None or arg.expression is None else stop_of_function(arg.expression)
        if stop and "TRANSLATIONAL" in s.flags and "ACTIONONLY" not in s.flags:
            kind, length, k, cubic, i_id, j_id = stop  # the writer's stop SFORCE (adams.py)
            i, j = self.pair(s)
            if {i_id, j_id} == {i.id, j.id}:
                self.use(i, "geometry")
                self.use(j, "geometry")
                lf, ff = self.lf, self.ff
                self.calls.append((s, "stop", (self.element_name(s), i.id, j.id), dict(
                    kind=kind, length=length * lf, k=k * ff / lf, cubic=cubic * ff / lf**3)))
                return
        node = self.expression(s, "FUNCTION")
        if node is None:
            raise error(f"{s.label}: FUNCTION is missing.", self.path, s.line, "FUNCTION")
        _check_evaluable(node)
        rotational = "ROTATIONAL" in s.flags
        if not rotational and "TRANSLATIONAL" not in s.flags:
            raise error(f"{s.label}: give TRANSLATIONAL or ROTATIONAL.", self.path, s.line)
        i, j = self.pair(s)
        if "ACTIONONLY" in s.flags:
            self.use(i, "geometry")
            self.use(j, "frame")
            zero = (None, None, None)
            comps = (None, None, node)
            self.load_defs.append(_Load(
                self.element_name(s), s, zero if rotational else comps,
                comps if rotational else zero, np.eye(3)))
            self.loads_frame[self.load_defs[-1].name] = (i.id, j.id)
            return
        self.use(i, "geometry")
        self.use(j, "geometry")
        name = self.element_name(s)
        if rotational:
            self.internal.append((s, node))
            self.calls.append((s, "bushing", (name, i.id, j.id), dict(torque_function=node)))
        else:
            if np.linalg.norm(i.position - j.position) < 1e-6:
                raise error(f"{s.label}: a two-body TRANSLATIONAL SFORCE needs distinct I and "
                            "J positions (it acts along their line).", self.path, s.line)
            self.calls.append((s, "spring", (name, i.id, j.id), dict(force_function=node)))

    def _gforce(self, s, values=True):
        keys = {"GFORCE": ("FX", "FY", "FZ", "TX", "TY", "TZ"), "VFORCE": ("FX", "FY", "FZ"),
                "VTORQUE": ("TX", "TY", "TZ")}[s.keyword]
        if "FUNCTION" in s.arguments and values:
            raise _Unsupported("FUNCTION = USER(...) subroutines are not supported")
        comps = {}
        for key in keys if values else ():
            node = self.expression(s, key)
            if node is not None:
                _check_evaluable(node)
            comps[key] = node
        i = self.marker(s, "I")
        if i.floating:
            raise error(f"{s.label}: I = {i.id} is a FLOATING marker.", self.path, s.line, "I")
        jfloat = self.marker(s, "JFLOAT")
        rm = self.marker(s, "RM")
        if not jfloat.floating:
            raise error(f"{s.label}: JFLOAT = {jfloat.id} must be a FLOATING marker.",
                        self.path, s.line, "JFLOAT")
        if rm.floating:
            raise error(f"{s.label}: RM = {rm.id} must be a fixed marker.", self.path, s.line,
                        "RM")
        if jfloat.part != self.ground:
            raise _Unsupported(
                f"the reaction marker JFLOAT = {jfloat.id} is on a moving part; only loads "
                "whose reaction goes to the ground are supported")
        self.use(i, "geometry")
        self.use(rm, "frame")
        force = tuple(comps.get(k) for k in ("FX", "FY", "FZ"))
        moment = tuple(comps.get(k) for k in ("TX", "TY", "TZ"))
        load = _Load(self.element_name(s), s, force, moment, np.eye(3))
        self.load_defs.append(load)
        self.loads_frame[load.name] = (i.id, rm.id)

    def _motion(self, s):
        node = self.expression(s, "FUNCTION")
        if node is None:
            raise error(f"{s.label}: FUNCTION is missing.", self.path, s.line, "FUNCTION")
        _check_evaluable(node)
        if any(f in s.flags for f in ("VELOCITY", "ACCELERATION")):
            raise _Unsupported("only DISPLACEMENT motions are supported")
        if "JOINT" in s.arguments:
            if "ROTATION" in s.flags:
                raise _Unsupported("rotational joint motions are not supported")
            joint = self.by_key.get(("JOINT", self.integer(s, "JOINT")))
            if joint is None or not any(f in joint.flags
                                        for f in ("TRANSLATIONAL", "CYLINDRICAL")):
                raise error(f"{s.label}: JOINT must be a translational or cylindrical JOINT.",
                            self.path, s.line, "JOINT")
            i, j = self.pair(joint)
            axis = 2
        else:
            found = [f for f in s.flags if f in ("X", "Y", "Z", "B1", "B2", "B3")]
            if len(found) != 1 or found[0].startswith("B"):
                raise _Unsupported("only translational motions along X, Y or Z of J are "
                                   "supported")
            i, j = self.pair(s)
            axis = "XYZ".index(found[0])
            self.use(j, "frame")
        if j.part != self.ground:
            raise _Unsupported(f"the J marker {j.id} of the motion is on a moving part; "
                               "only motions relative to the ground are supported")
        self.use(i, "geometry")
        direction = j.orientation[:, axis]
        offset = float((i.position - j.position) @ direction)
        name = self.element_name(s)
        self.driver_defs.append(_Driver(name, s, node, offset))
        self.calls.append((s, "driver", (name, i.id), dict(direction=direction)))

    def _spline(self, s):
        if "Z" in s.arguments or "FILE" in s.arguments:
            raise _Unsupported("only 2-D SPLINEs with X and Y values in the dataset are "
                               "supported")
        x = np.array(self.reals(s, "X"))
        y = np.array(self.reals(s, "Y"))
        if x.size != y.size or x.size < 2:
            raise error(f"{s.label}: X and Y need the same number of values (at least 2); got "
                        f"{x.size} and {y.size}.", self.path, s.arguments["Y"].line, "Y")
        if np.any(np.diff(x) <= 0):
            raise error(f"{s.label}: X must be strictly increasing.", self.path,
                        s.arguments["X"].line, "X")
        self.model.splines[s.id] = AdmSpline(s.id, s.name, x, y,
                                             "LINEAR_EXTRAPOLATE" in s.flags, s.line)

    # -- build ----------------------------------------------------------------------------

    def kept(self, marker: _Marker) -> bool:
        if marker.floating:
            return False
        frame_only = (self.frame_use.get(marker.id, 0) > 0
                      and self.geometry_use.get(marker.id, 0) == 0)
        return not (frame_only and marker.part == self.ground and not marker.named)

    def build(self, time, check) -> Mechanism:
        time = float(time)
        if not any(ident != self.ground for ident in self.parts):
            what = ("the dataset holds no statement (an empty file?)" if not self.statements
                    else "the dataset defines no moving PART")
            raise error(f"{what}; an Adams dataset (.adm) needs PART/ statements (one with "
                        "GROUND), MARKER/s on them and the joints and forces between them.",
                        self.path, 1)
        if not any(kind in ("joint", "bushing", "spring") for _, kind, _, _ in self.calls):
            raise error("the dataset defines no joint, bushing or spring between its parts "
                        "(a truncated file?); nothing holds the parts.", self.path,
                        max(s.line for s in self.statements))
        title = re.sub(r"^ADAMS/View model name:\s*", "", self.model.title, flags=re.I)
        builder = MechanismBuilder(title or (self.path.stem if self.path else "adm"))
        lines: dict[str, int] = {}
        for ident, (name, _, _, line) in self.parts.items():
            if ident != self.ground:
                self._call(builder.part, lines, line, name)
                lines[name] = line
        for marker in self.markers.values():
            if self.kept(marker):
                part = self.parts[marker.part][0]
                self._call(builder.marker, lines, marker.line, marker.name, part,
                           marker.position, marker.orientation)
                lines[marker.name] = marker.line
        frames = self.loads_frame
        mk = self.markers
        for s, kind, args, kw in self.calls:
            lines[args[0]] = s.line
            if kind == "joint":
                name, joint_kind, i, j = args
                self._call(builder.joint, lines, s.line, name, joint_kind, mk[i].name,
                           mk[j].name)
            elif kind == "bushing":
                name, i, j = args
                if "torque_function" in kw:
                    value = _evaluate(kw["torque_function"], time, s, self.path)
                    kw = dict(preload_torque=(0.0, 0.0, value * self.ff * self.lf))
                self._call(builder.bushing, lines, s.line, name, mk[i].name, mk[j].name, **kw)
            elif kind == "spring":
                name, i, j = args
                if "force_function" in kw:
                    value = _evaluate(kw["force_function"], time, s, self.path) * self.ff
                    kw = _spring_law(0.0, 0.0, value)
                self._call(builder.spring, lines, s.line, name, mk[i].name, mk[j].name, **kw)
            elif kind == "driver":
                name, i = args
                self._call(builder.driver, lines, s.line, name, mk[i].name, **kw)
            elif kind == "stop":
                name, i, j = args
                self._call(builder.stop, lines, s.line, name, mk[i].name, mk[j].name, **kw)
        for load in self.load_defs:
            i, frame = frames[load.name]
            frame_name = mk[frame].name if self.kept(mk[frame]) else None
            lines[load.name] = load.statement.line
            self._call(builder.load_point, lines, load.statement.line, load.name, mk[i].name,
                       frame=frame_name)
        _harmonise_tables(builder)
        try:
            return builder.build(check=check)
        except ModelError as e:
            err = error(str(e), self.path, _line_of(str(e), lines, self.statements))
            # A model well written but not solvable as given (free modes, joints not assembled)
            # is exit 4 whatever its format, like a native file's.
            err.bad_input = getattr(e, "bad_input", False)
            raise err from None
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as e:
            raise error(f"the model cannot be assembled: {e}", self.path,
                        self.statements[-1].line if self.statements else 1) from None

    def _call(self, fn, lines, line, *args, **kw):
        try:
            return fn(*args, **kw)
        except ModelError as e:
            raise error(str(e), self.path, line) from None

    def loads(self, mech: Mechanism, times) -> Loads:
        t = np.asarray(times, dtype=float)
        if t.ndim > 1 or not np.all(np.isfinite(t)):
            raise ValueError("times must be a finite scalar or 1-D array (s).")
        ts = np.atleast_1d(t)
        forces, moments, drivers = {}, {}, {}
        frames = self.loads_frame
        for load in self.load_defs:
            _, frame = frames[load.name]
            rot = np.eye(3) if self.kept(self.markers[frame]) else self.markers[frame].orientation
            scale_m = self.ff * self.lf
            f = np.array([[0.0 if e is None else _evaluate(e, tc, load.statement, self.path)
                           for e in load.force] for tc in ts]) * self.ff
            m = np.array([[0.0 if e is None else _evaluate(e, tc, load.statement, self.path)
                           for e in load.moment] for tc in ts]) * scale_m
            forces[load.name] = f @ rot.T
            moments[load.name] = m @ rot.T
        for d in self.driver_defs:
            drivers[d.name] = np.array([_evaluate(d.function, tc, d.statement, self.path)
                                        * self.lf - d.offset for tc in ts])
        if t.ndim == 0:
            forces = {k: v[0] for k, v in forces.items()}
            moments = {k: v[0] for k, v in moments.items()}
            drivers = {k: v[0] for k, v in drivers.items()}
        return mech.loads(forces=forces, moments=moments, drivers=drivers)


class _Unsupported(Exception):
    """A statement that is well formed but outside the subset: it is skipped and reported."""


def _unique_names(statements, prefix, reserved=()) -> dict[int, str]:
    """Statement line → a unique name: its adams_view_name (first use), else PREFIX_id (or
    KEYWORD_id), with _2, _3, ... appended if that is taken."""
    used = set(reserved)
    names: dict[int, str] = {}
    for s in statements:
        if s.name and s.name not in used:
            used.add(s.name)
            names[s.line] = s.name
    for s in statements:
        if s.line in names:
            continue
        base = f"{prefix or s.keyword}_{s.id}"
        name, k = base, 2
        while name in used:
            name, k = f"{base}_{k}", k + 1
        used.add(name)
        names[s.line] = name
    return names


def _check_evaluable(node):
    try:
        evaluate(node, 0.0)
    except ExpressionError as e:
        if "no numeric value" in str(e):
            raise _Unsupported(str(e)) from None


def _evaluate(node, time, s, path) -> float:
    try:
        value = evaluate(node, time)
    except ExpressionError as e:
        raise error(f"{s.label}: its function cannot be evaluated at time {time}: {e}.", path,
                    s.line) from None
    if not math.isfinite(value) or abs(value) > 1e15:
        raise error(f"{s.label}: its function gives {value} at time {time}.", path, s.line)
    return value


def _spring_law(k: float, length: float, force: float) -> dict:
    """Builder arguments for tension k·(ℓ − length) − force (Adams SPRINGDAMPER)."""
    if k < 0:
        return dict(k=k, free_length=1.0)  # the builder rejects it with its own message
    effective = length + force / k if k > 0 else 0.0
    if k > 0 and effective > 0:
        return dict(k=k, free_length=effective)
    # Free length ≤ 0 (or a constant force): the same law as a straight 2-point table of
    # tension against ℓ (free_length 0).
    x = np.array([-1.0, 1.0])
    return dict(table=(x, k * (x - length) - force))


def _harmonise_tables(builder: MechanismBuilder):
    """Give every tabulated spring of the builder the same number of points (the ones made
    here are straight lines, exact at any count)."""
    tables = [s for s in builder._springs if s["table"] is not None]
    counts = {len(s["table"][0]) for s in tables}
    if len(counts) <= 1:
        return
    k = max(counts)
    for s in tables:
        x, y = s["table"]
        if len(x) != k:
            xs = np.linspace(x[0], x[-1], k)
            s["table"] = (xs, np.interp(xs, x, y))


def _line_of(message: str, lines: dict[str, int], statements) -> int:
    for name in re.findall(r"'([^']+)'", message):
        if name in lines:
            return lines[name]
    return statements[-1].line if statements else 1


def parse_adm(source) -> AdmModel:
    """Parse an Adams dataset (.adm) — a path, or the text itself — into an `AdmModel` ready to
    `build` (the subset is in the docstring of `diffsusp.io.adams`).

    The statements outside the subset are listed in `AdmModel.skipped` and in one
    `ModelWarning`. Raises `ModelFileError` (with the line) for a malformed statement, an
    unknown marker or part, a non-finite number.
    """
    model = parse_statements(source)
    path = model.path
    model.plan = AdmPlan(model)
    if model.skipped:
        warnings.warn(
            f"{path or '<input>'}: skipped {len(model.skipped)} statement(s) outside the "
            "supported subset: " + "; ".join(str(s) for s in model.skipped),
            ModelWarning, stacklevel=2,
        )
    return model
