"""Chrono::Vehicle suspension templates (JSON): DoubleWishbone, MacPhersonStrut, MultiLink.

What each hardpoint is, which joint it makes and how the parts are oriented follows Project
Chrono's own template classes (`ChDoubleWishbone::InitializeSide`, `ChMacPhersonStrut::
InitializeSide`, `ChMultiLink::InitializeSide`, the JSON readers `DoubleWishbone::Create`, ...,
`ReadBushingDataJSON`, `ChVehicleJoint::CreateBushing`, `ReadTSDAFunctorJSON` and the spring
force functors of `ChSubsysDefs`), as summarised in /work/shared/data/chrono/README.md. Where
the two differ, the Chrono sources were followed; the choices are listed below.

**Frame and units.** Points are given in metres in the suspension subsystem frame, x forward,
y to the left, z up, for the **left** side; the right side is Chrono's mirror image: every point
and direction with y → −y, and every frame rebuilt from the mirrored points by the same
construction (so frames stay right-handed). diffsusp works in mm and N: points × 1000, spring
rates N/m → N/mm (/1000), `Bushing Data` rotational stiffness N·m/rad → N·mm/rad (× 1000).
The JSON positions are the design position q = 0.

**Parts.** The spindle is merged into the upright: on a K&C rig the wheel spin is locked, so
statically the spindle (which Chrono joins to the upright by a revolute about its y axis) is
rigid on it. Masses, inertias and the shock damper carry no static load and are not used
(the shock's points are kept as markers).

**Templates.**

- *DoubleWishbone*: parts `upper_control_arm`, `lower_control_arm`, `upright`. Each arm pivots
  on the chassis (ground) by revolute `uca_pivot` / `lca_pivot` at the midpoint of its
  `Location Chassis Front` and `Back`, frame z along Front − Back, y normal to the arm's plane
  (Back − Upright) × (Front − Upright), x = y × z; markers I on the ground (Chrono's body 1,
  the chassis), J on the arm. Ball joints `uca_ball_joint` / `lca_ball_joint` (arm → upright) at
  `Location Upright`. Tie rod `tie_rod`: a distance constraint (Chrono's `ChLinkDistance`)
  between `Tierod/Location Chassis` on the ground (steering fixed) and `Location Upright` on the
  upright. Spring `spring` from `Spring/Location Chassis` (ground) to `Location Arm` (lower
  arm). This reproduces `diffsusp.models.double_wishbone` exactly (same names and order).
- *MacPhersonStrut*: parts `lower_control_arm` (the JSON's `Control Arm`, pivot and ball joint
  as above), `strut`, `upright`. The strut slides in the upright: cylindrical `strut_cylindrical`
  (I on the strut, J on the upright) at `Spring/Location Upright`, axis z along
  `Spring/Location Chassis` − `Location Upright`, y normal to the plane of those two points and
  `Location Chassis Back`; the strut top meets the chassis in universal `strut_universal` at
  `Spring/Location Chassis` whose cross carries the frame's x axis on the chassis and its y axis
  on the strut (Chrono's `ChLinkUniversal`: x on body 1 = chassis, y on body 2 = strut; diffsusp's
  universal keeps z_I ⟂ z_J, so marker I has z = x, marker J has z = y). Spring `spring` from
  `Spring/Location Chassis` (ground) to `Location Upright` on the upright, as Chrono attaches it.
- *MultiLink*: parts `upper_arm` (pivot `ua_pivot` and `ua_ball_joint` as a wishbone),
  `lateral`, `trailing_link`, `upright`. Each link meets the upright by a ball joint
  (`lateral_ball_joint`, `trailing_link_ball_joint` at `Location Upright`) and the chassis by a
  universal joint (`lateral_universal`, `trailing_link_universal` at `Location Chassis`). As in
  `ChMultiLink`, the cross axis named `Universal Joint Axis Chassis` is the one carried by the
  link (ChLinkUniversal body 1 = the link, x axis) and `Universal Joint Axis Link` the one
  carried by the chassis (body 2, y axis); the two are given to 6 decimals, so the link's axis
  is made exactly perpendicular to the other (a correction of ~1e-6 rad; more than 1e-3 rad is
  an error). Spring `spring` from `Location Chassis` (ground) to `Location Link` on the trailing
  link.
- `Tierod` with a `Mass` (Chrono's tie-rod bodies): part `tierod`, ball joint
  `tierod_ball_joint` to the upright at `Location Upright`, universal `tierod_universal` to the
  chassis at `Location Chassis` (frame z along the rod, x the chassis's x made perpendicular,
  the cross's x on the chassis and y on the rod).

**Bushing Data** (in `Upper/Lower Control Arm`, `Control Arm`, `Upper Arm`, `Tierod`): as
`ChVehicleJoint::CreateBushing`, the joint becomes a six-axis bushing at the joint frame (I on
Chrono's body 1, J on body 2) with `Stiffness Linear` on the three translations, `Stiffness
Rotational` on the rotations the joint locks and `DOF/Stiffness Rotational` (0 if absent) on
the ones it leaves free: a revolute's z, a universal's x and y, a spherical's three. (Chrono
reads `DOF/Stiffness Linear` but does not use it for these joints.) Damping is ignored.

**Springs** (Chrono `ReadTSDAFunctorJSON`, `LinearSpringForce`, `NonlinearSpringForce`):
`Spring Coefficient` k with `Free Length` L0 and an optional `Preload` P: tension k·(ℓ − L0) − P,
i.e. a linear spring of free length L0 + P/k; or `Spring Curve Data` (older files: `Curve Data`)
[[deflection m, force N], ...] with deflection ℓ − L0: tension = curve(ℓ − L0) − P, the curve
interpolated **linearly** as Chrono's `ChFunctionInterp` does. The model has no piecewise-linear
law, so the curve is written exactly as a linear spring (named `spring`: the first segment's
rate plus every rate decrease) and one-sided stops on the same two markers at the interior
knots (`spring_knot_<j>`: a rebound stop of rate Δs where the rate rises by Δs, a bump stop of
rate |Δs| where it falls; `piecewise_linear_hinges`). Beyond the end points the end segments
continue (Chrono holds the end value: it does not extrapolate). `spring_interpolation='akima'`
reads the curve as a tabulated spring instead (the smooth Akima spline through the points,
diffsusp's tabulated law).

**Stops** (`SpringForce::enable_stops`, `evaluate_stops`): with both `Minimum Length` and
`Maximum Length`, Chrono adds a bump force bump(min − ℓ) below the minimum and a rebound force
rebound(ℓ − max) above the maximum, both on its fixed curve `STOP_CURVE` (0 → 60 mm of
penetration, 100 N/mm stiffening to 11 250 N/mm, linear between points): here bump stops
`spring_bump_<j>` and rebound stops `spring_rebound_<j>` at min − p_j and max + p_j with the
rate increases of that curve — exact up to 60 mm of penetration (125 kN), where Chrono holds
the force and these stops keep stiffening. One length alone is ignored, as in Chrono (with a
`ModelWarning`). Dampers (`Shock`) carry no static load and are not read.

**Wheel.** Marker `wheel_centre` on the upright at `Spindle/COM`, z = the spin axis pointing
outboard (Chrono's spindle y axis, turned by `Toe Angle (deg)` and `Camber Angle (deg)` as
`spindleRot = Rz(s·toe)·Rx(s·camber)`, s = −1 left, +1 right: positive toe is toe-in, positive
camber top-out), y as close to up as possible, x = y × z (rearward on the left side). Load point
`contact_patch` on the upright `loaded_radius` mm straight below the wheel centre (global −z)
and load point `wheel_centre` at the wheel-centre marker, both with global components. With
`wheel_travel`, driver `wheel_travel` prescribes the wheel centre's global z travel (mm). The
names are those of `diffsusp.models.double_wishbone`. The model carries its corner
(`Mechanism.corners`): ISO frame, the side read, that loaded radius, the steering axis (ball
joints; strut top to lower ball joint; upper ball joint to the links' virtual pivot), and the
design load computed as the vertical contact load that holds the file's position (the file
states no wheel load), so `diffsusp kc FILE.json` needs no corner option.

**Size.** About 720 lines, kept in one file: the JSON reader with located errors (~180 lines)
and the three templates, which share the arm, joint, spring and corner builders; split, each
part would import most of the other.
"""

import json
import math
import re
import warnings
from pathlib import Path

import numpy as np

from ..errors import ModelError, ModelFileError, ModelWarning
from ..model import Mechanism, MechanismBuilder
from ..model.corner import Corner, common_perpendicular_midpoint, design_offset
from .files import read_input

DEFAULT_LOADED_RADIUS = 330.0
"""Loaded tyre radius (mm) used when `loaded_radius` is None: the contact patch is this far below
the wheel centre. The JSON files carry no tyre (`Spindle/Radius` is the spindle's drawing size),
so this is a chosen value, the one of `diffsusp.models.double_wishbone`."""

STOP_CURVE = ((0.0, 0.0), (2.0, 200.0), (4.0, 400.0), (6.0, 600.0), (8.0, 800.0),
              (10.0, 1000.0), (20.0, 2500.0), (30.0, 4500.0), (40.0, 7500.0),
              (50.0, 12500.0), (60.0, 125000.0))
"""Chrono's bump and rebound stop curve (`SpringForce::enable_stops`, "from an ADAMS/Car
example"): (penetration mm, force N) beyond 'Minimum Length' / 'Maximum Length', interpolated
linearly."""

SPRING_INTERPOLATIONS = ("linear", "akima")
"""How `read_chrono` interpolates a spring curve: 'linear' as Chrono does (exactly: a linear
spring plus one-sided stops at the knots), 'akima' the smooth spline of a tabulated spring."""

TEMPLATES = ("DoubleWishbone", "MacPhersonStrut", "MultiLink")
"""Chrono::Vehicle suspension templates read by `read_chrono`."""

_M_TO_MM = 1000.0
_MAX_COORDINATE_M = 1.0e3


def _strip_comments(text: str) -> str:
    """Remove // and /* */ comments outside strings (rapidjson's kParseCommentsFlag), keeping
    line breaks so JSON error lines stay right."""
    out, k, n = [], 0, len(text)
    in_string = False
    while k < n:
        ch = text[k]
        if in_string:
            out.append(ch)
            if ch == "\\" and k + 1 < n:
                out.append(text[k + 1])
                k += 2
                continue
            if ch == '"':
                in_string = False
            k += 1
        elif ch == '"':
            in_string = True
            out.append(ch)
            k += 1
        elif text.startswith("//", k):
            end = text.find("\n", k)
            k = n if end < 0 else end
        elif text.startswith("/*", k):
            end = text.find("*/", k + 2)
            stop = n if end < 0 else end + 2
            out.append("\n" * text.count("\n", k, stop))
            k = stop
        else:
            out.append(ch)
            k += 1
    return "".join(out)


class _BadNumber(ValueError):
    def __init__(self, token, message):
        super().__init__(message)
        self.token = token


def _reject_constant(name):
    raise _BadNumber(name, f"{name} is not a number JSON allows; give a finite number")


def _finite_float(text):
    value = float(text)
    if not math.isfinite(value):
        raise _BadNumber(text, f"{text} is out of the range of a double; give a finite number")
    return value


_TOKENS = re.compile(r'"(?:\\.|[^"\\])*"|[-+]?[A-Za-z0-9_.+-]+')


def _token_line(text: str, token: str) -> int:
    """1-based line of the first `token` outside strings (1 if not found)."""
    for m in _TOKENS.finditer(text):
        if m.group().lstrip("+-") == token.lstrip("+-") or m.group() == token:
            return text.count("\n", 0, m.start()) + 1
    return 1


class _Document:
    """The parsed JSON with field access that reports the file line on error."""

    def __init__(self, source):
        if isinstance(source, dict):
            self.data, self.text, self.path = source, "", None
        else:
            self.path = Path(source)
            try:
                raw = read_input(self.path, "Chrono JSON file")
            except FileNotFoundError:
                raise ModelFileError("cannot read the Chrono JSON file: no such file.",
                                     path=self.path) from None
            try:
                text = raw.decode("utf-8")
            except UnicodeDecodeError:
                text = raw.decode("latin-1")
            self.text = _strip_comments(text)
            try:
                self.data = json.loads(self.text, parse_constant=_reject_constant,
                                       parse_int=_finite_float, parse_float=_finite_float)
            except json.JSONDecodeError as e:
                raise ModelFileError(f"not valid JSON: {e.msg}.", path=self.path,
                                     line=e.lineno) from None
            except _BadNumber as e:
                raise ModelFileError(f"not valid JSON: {e}.", path=self.path,
                                     line=_token_line(self.text, e.token)) from None
            except (ValueError, RecursionError) as e:
                raise ModelFileError(f"not valid JSON: {e}.", path=self.path,
                                     line=1) from None
        if not isinstance(self.data, dict):
            raise self.error("the file must hold a JSON object {...}.", ())

    def line(self, keys) -> int:
        """Line of the last of `keys` found, searching each after the previous one."""
        pos, line = 0, 1
        for key in keys:
            m = re.compile(r'"' + re.escape(key) + r'"\s*:').search(self.text, pos)
            if m is None:
                break
            pos = m.end()
            line = self.text.count("\n", 0, m.start()) + 1
        return line

    def error(self, message, keys):
        return ModelFileError(message, path=self.path, line=self.line(keys),
                              field="/".join(keys) or None)

    def get(self, *keys, required=True):
        node = self.data
        for depth, key in enumerate(keys):
            if not isinstance(node, dict) or key not in node:
                if not required:
                    return None
                where = "/".join(keys[:depth]) or "the top level"
                raise self.error(f"'{key}' is missing in {where}.", keys[:depth + 1])
            node = node[key]
        return node

    def section(self, name, required=True):
        value = self.get(name, required=required)
        if value is not None and not isinstance(value, dict):
            raise self.error(f"'{name}' must be an object {{...}}.", (name,))
        return value

    def number(self, *keys, required=True, positive=False, nonnegative=False):
        value = self.get(*keys, required=required)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(
                value):
            raise self.error(f"'{keys[-1]}' must be a finite number; got {value!r}.", keys)
        if positive and not value > 0:
            raise self.error(f"'{keys[-1]}' must be positive; got {value}.", keys)
        if nonnegative and value < 0:
            raise self.error(f"'{keys[-1]}' must be ≥ 0; got {value}.", keys)
        if abs(value) > 1e15:
            raise self.error(f"'{keys[-1]}' = {value} is out of range.", keys)
        return float(value)

    def vector(self, *keys, unit=False):
        value = self.get(*keys)
        if (not isinstance(value, list) or len(value) != 3
                or any(isinstance(v, bool) or not isinstance(v, int | float) for v in value)
                or not all(math.isfinite(v) for v in value)):
            raise self.error(f"'{keys[-1]}' must be a list of 3 finite numbers; got "
                             f"{str(value)[:60]}.", keys)
        v = np.asarray(value, dtype=float)
        if np.any(np.abs(v) > _MAX_COORDINATE_M):
            raise self.error(f"'{keys[-1]}' = {value} is beyond {_MAX_COORDINATE_M:g} m; the "
                             "file is in metres.", keys)
        if unit:
            norm = np.linalg.norm(v)
            if norm < 1e-9:
                raise self.error(f"'{keys[-1]}' must be a non-zero direction.", keys)
            v = v / norm
        return v

    def table(self, *keys):
        value = self.get(*keys)
        if (not isinstance(value, list) or len(value) < 2
                or any(not isinstance(r, list) or len(r) != 2 for r in value)
                or any(isinstance(c, bool) or not isinstance(c, int | float)
                       or not math.isfinite(c) for r in value for c in r)):
            raise self.error(f"'{keys[-1]}' must be a list of at least 2 [x, y] pairs of finite "
                             "numbers.", keys)
        data = np.asarray(value, dtype=float)
        if np.any(np.diff(data[:, 0]) <= 0):
            raise self.error(f"'{keys[-1]}': the deflections (first column) must increase.",
                             keys)
        return data


class _Side:
    """Points of one side in mm (mirrored for the right side)."""

    def __init__(self, doc: _Document, side: str):
        self.doc = doc
        self.sign = 1.0 if side == "left" else -1.0

    def point(self, *keys):
        v = self.doc.vector(*keys) * _M_TO_MM
        v[1] *= self.sign
        return v

    def direction(self, *keys):
        v = self.doc.vector(*keys, unit=True)
        v[1] *= self.sign
        return v


def _arm_frame(front, back, outer) -> np.ndarray:
    """Chrono's control-arm revolute frame: z along front − back, y normal to the arm's plane."""
    v = np.cross(back - outer, front - outer)
    w = front - back
    nv, nw = np.linalg.norm(v), np.linalg.norm(w)
    if nv < 1e-9 or nw < 1e-9:
        raise ModelError("the arm's front, back and upright points are collinear (or two "
                         "coincide); they must span a plane.")
    v, w = v / nv, w / nw
    return np.column_stack([np.cross(v, w), v, w])


def _bushing_data(doc, section):
    """(k_linear N/mm, k_rotational N·mm/rad, k_rotational_dof N·mm/rad) or None."""
    if doc.get(section, "Bushing Data", required=False) is None:
        return None
    keys = (section, "Bushing Data")
    k_lin = doc.number(*keys, "Stiffness Linear", nonnegative=True) / _M_TO_MM
    k_rot = doc.number(*keys, "Stiffness Rotational", nonnegative=True) * _M_TO_MM
    dof = 0.0
    if doc.get(*keys, "DOF", required=False) is not None:
        dof = doc.number(*keys, "DOF", "Stiffness Rotational", nonnegative=True) * _M_TO_MM
    return k_lin, k_rot, dof


def _check(fn, doc, keys, *args, **kw):
    try:
        return fn(*args, **kw)
    except ModelError as e:
        raise doc.error(str(e), keys) from None


def _arm(b, doc, pts, section, prefix, arm):
    """Markers, pivot (revolute or bushing) and ball joint of a wishbone arm."""
    front = pts.point(section, "Location Chassis Front")
    back = pts.point(section, "Location Chassis Back")
    outer = pts.point(section, "Location Upright")
    b.marker(f"{prefix}_chassis_front", "ground", front)
    b.marker(f"{prefix}_chassis_back", "ground", back)
    b.marker(f"{prefix}_upright", "upright", outer)
    frame = _check(_arm_frame, doc, (section, "Location Upright"), front, back, outer)
    centre = 0.5 * (front + back)
    data = _bushing_data(doc, section)
    if data is None:
        b.joint(f"{prefix}_pivot", "revolute", parts=("ground", arm), at=centre,
                orientation=frame)
    else:
        k_lin, k_rot, dof = data
        _check(b.bushing, doc, (section, "Bushing Data"), f"{prefix}_bushing",
               parts=("ground", arm), at=centre, orientation=frame, k_trans=k_lin,
               k_rot=(k_rot, k_rot, dof))
    _check(b.joint, doc, (section, "Location Upright"), f"{prefix}_ball_joint", "spherical",
           parts=(arm, "upright"), at=outer)


def _cross_frames(x_axis, y_axis):
    """Orientations of a universal joint's two markers: z along each cross axis."""
    z = np.cross(x_axis, y_axis)
    on_x = np.column_stack([y_axis, z, x_axis])   # z = x_axis, right-handed
    on_y = np.column_stack([z, x_axis, y_axis])   # z = y_axis
    return on_x, on_y


def _universal(b, doc, keys, name, body1, body2, at, x_axis, y_axis, bushing=None):
    """Chrono ChLinkUniversal(body1, body2, frame): the frame's x axis fixed on body 1, y on
    body 2, kept perpendicular (or the `ChVehicleJoint` bushing of that joint)."""
    on_x, on_y = _cross_frames(x_axis, y_axis)
    if bushing is None:
        b.marker(f"{name}.i", body1, at, on_x)
        b.marker(f"{name}.j", body2, at, on_y)
        _check(b.joint, doc, keys, name, "universal", f"{name}.i", f"{name}.j")
    else:
        k_lin, k_rot, dof = bushing
        frame = np.column_stack([x_axis, y_axis, np.cross(x_axis, y_axis)])
        _check(b.bushing, doc, keys, name.replace("universal", "bushing"),
               parts=(body1, body2), at=at, orientation=frame, k_trans=k_lin,
               k_rot=(dof, dof, k_rot))


def _tierod(b, doc, pts):
    chassis = pts.point("Tierod", "Location Chassis")
    upright = pts.point("Tierod", "Location Upright")
    b.marker("tierod_chassis", "ground", chassis)
    b.marker("tierod_upright", "upright", upright)
    if doc.get("Tierod", "Mass", required=False) is None:
        if np.linalg.norm(upright - chassis) < 1e-6:
            raise doc.error("the tie rod's two points coincide.", ("Tierod",))
        _check(b.joint, doc, ("Tierod",), "tie_rod", "distance", "tierod_chassis",
               "tierod_upright")
        return
    # Chrono's tie-rod body: spherical to the upright, universal to the chassis.
    b.part("tierod")
    w = upright - chassis
    if np.linalg.norm(w) < 1e-6:
        raise doc.error("the tie rod's two points coincide.", ("Tierod",))
    w = w / np.linalg.norm(w)
    v = np.cross(w, np.array([1.0, 0.0, 0.0]))
    if np.linalg.norm(v) < 1e-9:
        raise doc.error("the tie rod is along x; Chrono's tie-rod frame is undefined.",
                        ("Tierod",))
    v /= np.linalg.norm(v)
    u = np.cross(v, w)
    data = _bushing_data(doc, "Tierod")
    if data is None:
        _check(b.joint, doc, ("Tierod",), "tierod_ball_joint", "spherical",
               parts=("upright", "tierod"), at=upright)
    else:
        k_lin, _, dof = data
        _check(b.bushing, doc, ("Tierod", "Bushing Data"), "tierod_ball_bushing",
               parts=("upright", "tierod"), at=upright, k_trans=k_lin, k_rot=dof)
    _universal(b, doc, ("Tierod",), "tierod_universal", "ground", "tierod", chassis, u, v,
               bushing=data)


def _spring(b, doc, pts, chassis_key, other_key, other_part, marker_name, interpolation):
    section = "Spring"
    doc.section(section)
    chassis = pts.point(section, chassis_key)
    other = pts.point(section, other_key)
    b.marker("spring_chassis", "ground", chassis)
    b.marker(marker_name, other_part, other)
    free = doc.number(section, "Free Length", positive=True) * _M_TO_MM
    preload = doc.number(section, "Preload", required=False) or 0.0
    curve_key = next((k for k in ("Spring Curve Data", "Curve Data")
                      if doc.get(section, k, required=False) is not None), None)
    keys = (section,)
    pair = ("spring_chassis", marker_name)
    if curve_key is None:
        k = doc.number(section, "Spring Coefficient", positive=True) / _M_TO_MM
        effective = free + preload / k
        if effective <= 0:
            raise doc.error(f"free length + preload/k = {effective:.6g} mm is not positive.",
                            (section, "Preload"))
        _check(b.spring, doc, keys, "spring", *pair, k=k, free_length=effective)
    else:
        data = doc.table(section, curve_key)
        x, y = data[:, 0] * _M_TO_MM, data[:, 1] - preload
        keys = (section, curve_key)
        if interpolation == "akima":
            _check(b.spring, doc, keys, "spring", *pair, table=(x, y), free_length=free)
        else:
            k, offset, hinges = piecewise_linear_hinges(x, y)
            if not k > 0 or not free - offset > 0:
                raise doc.error(
                    f"the spring curve is not a linear spring plus one-sided stops (base rate "
                    f"{k:.6g} N/mm, free length {free - offset:.6g} mm); read it with "
                    "spring_interpolation='akima'.", keys)
            _check(b.spring, doc, keys, "spring", *pair, k=k, free_length=free - offset)
            for j, (at, kind, rate) in enumerate(hinges):
                _check(b.stop, doc, keys, f"spring_knot_{j + 1}", *pair, kind=kind,
                       length=free + at, k=rate)
    lengths = [doc.get(section, key, required=False) is not None
               for key in ("Minimum Length", "Maximum Length")]
    if all(lengths):
        low = doc.number(section, "Minimum Length", positive=True) * _M_TO_MM
        high = doc.number(section, "Maximum Length", positive=True) * _M_TO_MM
        if not low < high:
            raise doc.error(f"'Minimum Length' ({low:g} mm) must be below 'Maximum Length' "
                            f"({high:g} mm).", (section, "Maximum Length"))
        x, y = (np.asarray(v, dtype=float) for v in zip(*STOP_CURVE, strict=True))
        _, _, steps = piecewise_linear_hinges(x, y)
        # The curve starts at (0, 0) with slope s0: one more hinge there.
        steps = [(0.0, "rebound", (y[1] - y[0]) / (x[1] - x[0])), *steps]
        for j, (pen, _, rate) in enumerate(steps):
            if low - pen <= 0:  # never reached: the spring cannot be shorter than 0
                continue
            _check(b.stop, doc, (section, "Minimum Length"), f"spring_bump_{j + 1}", *pair,
                   kind="bump", length=low - pen, k=rate)
        for j, (pen, _, rate) in enumerate(steps):
            _check(b.stop, doc, (section, "Maximum Length"), f"spring_rebound_{j + 1}", *pair,
                   kind="rebound", length=high + pen, k=rate)
    elif any(lengths):
        warnings.warn(f"{doc.path}: Chrono uses the spring's stops only when both 'Minimum "
                      "Length' and 'Maximum Length' are given; the one given is ignored.",
                      ModelWarning, stacklevel=4)


def piecewise_linear_hinges(x, y):
    """A piecewise-linear law y(x) through the knots (x, y) (Chrono's `ChFunctionInterp`) as a
    linear law plus one-sided hinges: y(t) = k·(t + offset) + Σ hinge, each hinge (x_j, kind,
    rate) at an interior knot where the slope changes by c: 'rebound' (c > 0) adds
    c·max(t − x_j, 0), 'bump' (c < 0) adds −|c|·max(x_j − t, 0) — exactly the tension of a
    diffsusp rebound or bump stop of rate |c| at length free + x_j. Beyond the end knots the
    end segments continue.

    **Returns:** (k, offset, hinges) with k = the first slope plus every slope decrease.
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    slope = np.diff(y) / np.diff(x)
    change = np.diff(slope)
    k = slope[0] + change[change < 0].sum()
    # Value at t = 0 of the linear part: y0 + s0·(0 − x0) plus −c·(0 − x_j) = c·x_j... of the
    # flipped hinges (c·max(t − x_j, 0) = c·(t − x_j) + c·max(x_j − t, 0)).
    value = y[0] - slope[0] * x[0] - np.sum(change[change < 0] * x[1:-1][change < 0])
    hinges = [(float(xj), "rebound" if c > 0 else "bump", float(abs(c)))
              for xj, c in zip(x[1:-1], change, strict=True) if c != 0]
    return float(k), float(value / k) if k != 0 else math.inf, hinges


def _shock(b, doc, pts, other_key, other_part, marker_name):
    if doc.get("Shock", required=False) is None:
        return
    doc.section("Shock")
    b.marker("shock_chassis", "ground", pts.point("Shock", "Location Chassis"))
    b.marker(marker_name, other_part, pts.point("Shock", other_key))


def _double_wishbone(b, doc, pts, interpolation):
    for section in ("Upper Control Arm", "Lower Control Arm", "Tierod", "Spring", "Spindle"):
        doc.section(section)
    for part in ("upper_control_arm", "lower_control_arm", "upright"):
        b.part(part)
    _arm(b, doc, pts, "Upper Control Arm", "uca", "upper_control_arm")
    _arm(b, doc, pts, "Lower Control Arm", "lca", "lower_control_arm")
    _tierod(b, doc, pts)
    _spring(b, doc, pts, "Location Chassis", "Location Arm", "lower_control_arm", "spring_arm",
            interpolation)
    _shock(b, doc, pts, "Location Arm", "lower_control_arm", "shock_arm")


def _macpherson(b, doc, pts, interpolation):
    for section in ("Control Arm", "Tierod", "Spring", "Spindle"):
        doc.section(section)
    for part in ("lower_control_arm", "strut", "upright"):
        b.part(part)
    _arm(b, doc, pts, "Control Arm", "lca", "lower_control_arm")
    _tierod(b, doc, pts)
    _spring(b, doc, pts, "Location Chassis", "Location Upright", "upright", "spring_upright",
            interpolation)
    _shock(b, doc, pts, "Location Upright", "upright", "shock_upright")
    top = pts.point("Spring", "Location Chassis")
    bottom = pts.point("Spring", "Location Upright")
    back = pts.point("Control Arm", "Location Chassis Back")
    w, v = top - bottom, np.cross(bottom - back, top - back)
    if np.linalg.norm(w) < 1e-6 or np.linalg.norm(v) < 1e-6:
        raise doc.error("the strut's points (Spring/Location Chassis, Location Upright) and "
                        "Control Arm/Location Chassis Back must span a plane.", ("Spring",))
    w, v = w / np.linalg.norm(w), v / np.linalg.norm(v)
    frame = np.column_stack([np.cross(v, w), v, w])
    _check(b.joint, doc, ("Spring",), "strut_cylindrical", "cylindrical",
           parts=("strut", "upright"), at=bottom, orientation=frame)
    _universal(b, doc, ("Spring", "Location Chassis"), "strut_universal", "ground", "strut",
               top, frame[:, 0], frame[:, 1])


def _link(b, doc, pts, section, name):
    """A link with a universal joint to the chassis and a ball joint to the upright."""
    doc.section(section)
    chassis = pts.point(section, "Location Chassis")
    upright = pts.point(section, "Location Upright")
    b.marker(f"{name}_chassis", "ground", chassis)
    b.marker(f"{name}_upright", "upright", upright)
    on_link = pts.direction(section, "Universal Joint Axis Chassis")
    on_chassis = pts.direction(section, "Universal Joint Axis Link")
    tilt = abs(on_link @ on_chassis)
    if tilt > 1e-3:
        raise doc.error(f"the two universal-joint axes are not perpendicular (cosine "
                        f"{tilt:.3g}).", (section, "Universal Joint Axis Link"))
    on_chassis = on_chassis - (on_chassis @ on_link) * on_link
    on_chassis /= np.linalg.norm(on_chassis)
    _check(b.joint, doc, (section, "Location Upright"), f"{name}_ball_joint", "spherical",
           parts=(name, "upright"), at=upright)
    _universal(b, doc, (section, "Location Chassis"), f"{name}_universal", name, "ground",
               chassis, on_link, on_chassis)


def _multilink(b, doc, pts, interpolation):
    for section in ("Upper Arm", "Lateral", "Trailing Link", "Tierod", "Spring", "Spindle"):
        doc.section(section)
    for part in ("upper_arm", "lateral", "trailing_link", "upright"):
        b.part(part)
    _arm(b, doc, pts, "Upper Arm", "ua", "upper_arm")
    _link(b, doc, pts, "Lateral", "lateral")
    _link(b, doc, pts, "Trailing Link", "trailing_link")
    _tierod(b, doc, pts)
    _spring(b, doc, pts, "Location Chassis", "Location Link", "trailing_link", "spring_link",
            interpolation)
    _shock(b, doc, pts, "Location Link", "trailing_link", "shock_link")


def _rot_x(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _outboard_axis(toe: float, camber: float, side: str) -> np.ndarray:
    """Spin axis pointing outboard: Chrono's spindle y axis, spindleRot = Rz(s·toe)·Rx(s·camber)
    with s = −1 on the left, +1 on the right (toe and camber in rad), turned outboard."""
    s = -1.0 if side == "left" else 1.0
    spin = _rot_z(s * toe) @ _rot_x(s * camber) @ np.array([0.0, 1.0, 0.0])
    return spin if side == "left" else -spin


def _corner(pts, template, side, radius, centre, stated=True):
    """The wheel: ISO frame, this side, `radius` below the wheel centre, design load computed
    (None), steering axis through the ball joints (DoubleWishbone), from the strut top to the
    lower ball joint (MacPhersonStrut), or from the upper ball joint to the virtual pivot of
    the lateral and trailing links (MultiLink: the midpoint of their lines' common
    perpendicular at design, fixed on the upright)."""
    if template == "DoubleWishbone":
        kingpin = ("uca_upright", "lca_upright")
    elif template == "MacPhersonStrut":
        kingpin = ("spring_chassis", "lca_upright")
    else:
        pivot = common_perpendicular_midpoint(
            pts.point("Lateral", "Location Chassis"), pts.point("Lateral", "Location Upright"),
            pts.point("Trailing Link", "Location Chassis"),
            pts.point("Trailing Link", "Location Upright"))
        kingpin = ("ua_upright", ("upright", design_offset(pivot, centre, "iso", side)))
    return Corner(kingpin=kingpin, side=side, frame="iso", loaded_radius=radius,
                  design_load=None, loaded_radius_stated=stated)


def read_chrono(path, *, side: str = "left", loaded_radius: float | None = None,
                wheel_travel: bool = False, spring_interpolation: str = "linear",
                check: bool = True) -> Mechanism:
    """Read a Chrono::Vehicle suspension JSON file (DoubleWishbone, MacPhersonStrut, MultiLink)
    into a K&C half-axle `Mechanism` of one side (see the module docstring for the semantics).

    **Arguments:**

    - `path`: the JSON file (comments // and /* */ are allowed, as in Chrono).
    - `side`: 'left' (the file's points) or 'right' (mirrored in y).
    - `loaded_radius`: distance (mm) from the wheel centre down to the contact patch load
      point, and the corner's loaded radius; default `DEFAULT_LOADED_RADIUS` (330 mm), marked
      as a default (`Corner.loaded_radius_stated` False: the file carries no tyre, and
      `diffsusp kc` says which radius it uses).
    - `wheel_travel`: add driver 'wheel_travel' (wheel-centre z travel, mm).
    - `spring_interpolation`: 'linear' (Chrono's) or 'akima' (smooth) for a spring curve
      (`SPRING_INTERPOLATIONS`).
    - `check`: validate the model at build (`MechanismBuilder.build`).

    **Returns:** the `Mechanism` (mm, N; Chrono frame x forward, y left, z up; design position =
    the file's points) with its wheel corner (`Mechanism.corners`). Raises `ModelFileError`
    with the line and field for a missing or invalid field, an unknown template, or a model
    that cannot be assembled.

    spec: DESIGN.md "Frames" (Chrono: x forward, y left, z up).
    """
    if spring_interpolation not in SPRING_INTERPOLATIONS:
        raise ValueError(f"spring_interpolation must be one of {SPRING_INTERPOLATIONS}; got "
                         f"{spring_interpolation!r}.")
    if side not in ("left", "right"):
        raise ValueError(f"side must be 'left' or 'right'; got {side!r}.")
    radius = DEFAULT_LOADED_RADIUS if loaded_radius is None else float(loaded_radius)
    if not (math.isfinite(radius) and radius > 0):
        raise ValueError(f"loaded_radius must be a positive length in mm; got {loaded_radius}.")
    doc = _Document(path)
    template = doc.get("Template")
    if template not in TEMPLATES:
        raise doc.error(f"Template {template!r} is not supported; use one of "
                        f"{', '.join(TEMPLATES)}.", ("Template",))
    kind = doc.get("Type", required=False)
    if kind is not None and kind != "Suspension":
        raise doc.error(f"Type {kind!r}: this reader takes suspension files (Type "
                        "'Suspension').", ("Type",))
    name = doc.get("Name", required=False)
    name = name if isinstance(name, str) else template
    b = MechanismBuilder(f"{name} ({side})" + (" (wheel travel)" if wheel_travel else ""))
    pts = _Side(doc, side)
    build = {"DoubleWishbone": _double_wishbone, "MacPhersonStrut": _macpherson,
             "MultiLink": _multilink}[template]
    try:
        build(b, doc, pts, spring_interpolation)
        toe = math.radians(doc.number("Toe Angle (deg)", required=False) or 0.0)
        camber = math.radians(doc.number("Camber Angle (deg)", required=False) or 0.0)
        outboard = _outboard_axis(toe, camber, side)
        centre = pts.point("Spindle", "COM")
        b.marker("wheel_centre", "upright", centre, z=outboard,
                 x=np.cross([0.0, 0.0, 1.0], outboard))
        b.load_point("contact_patch", part="upright", at=centre - [0.0, 0.0, radius])
        b.load_point("wheel_centre", marker="wheel_centre")
        if wheel_travel:
            b.driver("wheel_travel", marker="wheel_centre", direction=(0.0, 0.0, 1.0))
        b.corner(_corner(pts, template, side, radius, centre, loaded_radius is not None))
    except ModelError as e:
        if isinstance(e, ModelFileError):
            raise
        raise doc.error(str(e), ("Template",)) from None
    try:
        return b.build(check=check)
    except ModelError as e:
        error = doc.error(f"the model cannot be assembled: {e}", ("Template",))
        error.bad_input = getattr(e, "bad_input", False)  # unsolvable: exit 4, as .toml/.adm
        raise error from None
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as e:
        raise doc.error(f"the model cannot be assembled: {e}", ("Template",)) from None
