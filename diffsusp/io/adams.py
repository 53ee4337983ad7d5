"""Adams files: datasets (.adm), A/Car load-case files (.lcf) and bushing property files (.bus).

spec: stiffness §4.1 (the .adm of Annex F, `model_exemple11`), §4.2 (.lcf, Annex H), §4.3 (A/Car
bushing splines, Annex I), §4.4, §6 item 10, §7 R9. Reading never executes anything from a file:
statements are tokenised by regular expressions and function expressions are parsed by the small
grammar of `diffsusp.io.expr`.

**.adm subset read** (statement → diffsusp):

- first line: the title (Adams's rule; a first line that is itself a statement is read as one);
- ``!`` comments; ``! adams_view_name='x'`` names the next statement (parts, markers, elements
  take these names; unnamed ones are called ``MARKER_7``, ``BUSHING_1``, ...); a commented-out
  statement (``!JOINT/1, ...``) is inactive and listed in `AdmModel.inactive`; lines starting
  with ``,`` continue the statement; ``\\`` ends a function expression; ``END`` ends the dataset;
- ``UNITS/`` FORCE, LENGTH (MASS and TIME recorded), or SYSTEM; values are converted to mm, N,
  N·mm, rad (no UNITS statement: mm and N assumed);
- ``PART/`` GROUND; QG/REULER (or ZG/XG) place the part frame at design; MASS, CM, IP, initial
  velocities are ignored (statics);
- ``MARKER/`` PART, QP, REULER (or ZP/XP) in the part frame; a ``D`` suffix means degrees;
  FLOATING markers get no pose (they only carry GFORCE/VFORCE/VTORQUE reactions);
- ``JOINT/`` SPHERICAL, REVOLUTE, CYLINDRICAL, TRANSLATIONAL, UNIVERSAL, FIXED;
  ``JPRIM/`` INLINE, INPLANE, PERPENDICULAR, ATPOINT (= spherical rows);
- ``BUSHING/`` I, J, K, KT, FORCE, TORQUE (C, CT are damping: ignored in statics) — Adams
  convention, the one of `diffsusp.model.Bushings`;
- ``SPRINGDAMPER/`` TRANSLATIONAL: tension K·(ℓ − LENGTH) − FORCE, i.e. a linear spring of free
  length LENGTH + FORCE/K (when that is ≤ 0 or K = 0, the same law as a 2-point table);
  ROTATIONAL: a bushing with only KT about z (offset ANGLE, preload TORQUE);
- ``SFORCE/`` with a FUNCTION of the grammar: ACTIONONLY → a load point on I in J's axes
  (TRANSLATIONAL: force along z_J, ROTATIONAL: torque about z_J); two-body TRANSLATIONAL → a
  constant tension −f along I–J (Adams: positive repels); two-body ROTATIONAL → a zero-stiffness
  bushing with torque preload f about z_J; two-body functions are evaluated at `time`;
- ``GFORCE/``, ``VFORCE/``, ``VTORQUE/`` with JFLOAT a floating marker on the ground: a load
  point on I, components in RM's axes; their FX…TZ expressions are evaluated by
  `AdmModel.loads` at the times asked for (a reaction on a moving part is not supported:
  skipped);
- ``MOTION/`` I, J on the ground, X/Y/Z (or JOINT= a translational joint, TRANSLATION): a motion
  driver on I along J's axis, values from `AdmModel.loads`;
- ``GCON/`` FUNCTION = DM(i, j) − L: a distance joint (massless link) between markers i and j;
- ``SPLINE/`` X, Y, LINEAR_EXTRAPOLATE: stored in `AdmModel.splines`; A/Car bushing splines
  (six splines named ``<bushing>_{fx,fy,fz,tx,ty,tz}_spline``) are grouped by
  `AdmModel.spline_bushings` and their linear stiffness read by `spline_stiffness` (Y = −K·X,
  §4.3). The GFORCE/FIELD that uses them in A/Car datasets is not printed in the thesis, so they
  are not attached to a bushing.

Statements without effect on a static solution (GRAPHICS, OUTPUT, RESULTS, REQUEST, ...) are
listed in `AdmModel.ignored`. Every other statement (ACCGRAV, FIELD, BEAM, CONTACT, an
unsupported joint type, a function outside the grammar, ...) is reported by keyword, id, name and
line in `AdmModel.skipped` and in a `ModelWarning`, never silently dropped.

Ground markers without an ``adams_view_name`` that serve only as reference frames (RM, the J of
an action-only SFORCE or of a MOTION) are not added to the mechanism: their axes never move, so
loads are given in global components and motions along their global axis.
"""

import bisect
import dataclasses
import math
import re
import warnings
from pathlib import Path

import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float

from ..errors import ModelError, ModelFileError, ModelWarning
from ..geometry import matrix_to_reuler_deg, reuler_to_matrix
from ..model import Loads, Mechanism, MechanismBuilder
from ..model.builder import frame_from_axes
from .expr import (
    ExpressionError,
    distance_constraint,
    evaluate,
    parse_expression,
)

# ----------------------------------------------------------------------------- units

_LENGTH_TO_MM = {
    "MILLIMETER": 1.0, "MM": 1.0, "CENTIMETER": 10.0, "CM": 10.0, "METER": 1000.0, "M": 1000.0,
    "KILOMETER": 1.0e6, "KM": 1.0e6, "INCH": 25.4, "IN": 25.4, "FOOT": 304.8, "FT": 304.8,
    "MILE": 1609344.0,
}
_FORCE_TO_N = {
    "NEWTON": 1.0, "N": 1.0, "KILONEWTON": 1000.0, "KN": 1000.0, "MILLINEWTON": 1.0e-3,
    "DYNE": 1.0e-5, "POUND_FORCE": 4.4482216152605, "LBF": 4.4482216152605,
    "KPOUND_FORCE": 4448.2216152605, "KILOGRAM_FORCE": 9.80665, "KGF": 9.80665,
    "OUNCE_FORCE": 0.27801385095378125,
}
_SYSTEMS = {
    "MKS": ("METER", "NEWTON"), "MMKS": ("MILLIMETER", "NEWTON"), "CGS": ("CENTIMETER", "DYNE"),
    "IPS": ("INCH", "POUND_FORCE"), "FPS": ("FOOT", "POUND_FORCE"),
}

# ----------------------------------------------------------------------------- statements

SUPPORTED = ("UNITS", "PART", "MARKER", "JOINT", "JPRIM", "BUSHING", "SPRINGDAMPER", "SFORCE",
             "GFORCE", "VFORCE", "VTORQUE", "SPLINE", "MOTION", "GCON")
"""Statements read into the model."""

NO_STATIC_EFFECT = ("GRAPHICS", "OUTPUT", "RESULTS", "REQUEST", "MREQUEST", "EQUILIBRIUM", "IC",
                    "INTEGRATOR", "KINEMATICS", "DEBUG", "LIST", "NOLIST", "SENSOR", "STRING",
                    "PREFERENCES")
"""Statements with no effect on a static solution: recorded in `AdmModel.ignored`."""

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
_EXPRESSION_KEYS = frozenset(
    ["FUNCTION", "FX", "FY", "FZ", "TX", "TY", "TZ"] + [f"F{k}" for k in range(1, 9)]
)
_STATEMENT_START = re.compile(r"\s*([A-Za-z_][A-Za-z0-9_]*)\s*(/|$)")
_VIEW_NAME = re.compile(r"!\s*adams_view_name\s*=\s*(['\"])(.*?)\1", re.IGNORECASE)
_COMMENTED_STATEMENT = re.compile(r"!\s*([A-Za-z_][A-Za-z0-9_]*)\s*/")
_SPACE = re.compile(r"\s*")
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?(?:[dD](?![A-Za-z0-9_]))?")
_STRING = re.compile(r"'[^'\n]*'|\"[^\"\n]*\"")
_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_.:]*")
_INTEGER = re.compile(r"[+-]?\d{1,18}")
_REAL = re.compile(r"([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)([dD]?)")
_ID = re.compile(r"\d{1,18}")
_END_OF_VALUE = re.compile(r"[A-Za-z0-9_.]")


@dataclasses.dataclass
class AdmValue:
    """One value token of a statement argument: its text and where it is in the file (1-based
    `line`, 0-based columns `start`:`end`)."""

    text: str
    line: int
    start: int
    end: int


@dataclasses.dataclass
class AdmArgument:
    """``NAME = v1, v2, ...`` (values) or ``NAME = expression`` (`expression`, for FUNCTION and
    FX…TZ)."""

    name: str
    values: list[AdmValue]
    expression: str | None
    line: int


@dataclasses.dataclass
class AdmStatement:
    """One statement: keyword (upper case), id, `name` (from ``adams_view_name``), arguments,
    flags (bare words such as GROUND, REVOLUTE, LINEAR_EXTRAPOLATE), first and last line."""

    keyword: str
    id: int | None
    name: str | None
    arguments: dict[str, AdmArgument]
    flags: list[str]
    line: int
    end_line: int

    @property
    def label(self) -> str:
        out = self.keyword + (f"/{self.id}" if self.id is not None else "")
        return out + (f" '{self.name}'" if self.name else "")


@dataclasses.dataclass
class SkippedStatement:
    """A statement outside the subset: keyword, id, name, line and why it was skipped."""

    keyword: str
    id: int | None
    name: str | None
    line: int
    reason: str

    def __str__(self) -> str:
        label = self.keyword + (f"/{self.id}" if self.id is not None else "")
        label += f" '{self.name}'" if self.name else ""
        return f"{label} (line {self.line}): {self.reason}"


@dataclasses.dataclass
class AdmSpline:
    """A SPLINE statement, values as in the file (file units; X of rotations in rad)."""

    id: int
    name: str | None
    x: np.ndarray
    y: np.ndarray
    linear_extrapolate: bool
    line: int


def _read_source(source, what: str) -> tuple[str, Path | None]:
    """Text of `source`: a `Path`, a path string (one line), text (with a newline) or bytes."""
    if isinstance(source, bytes | bytearray):
        return _decode(bytes(source)), None
    if isinstance(source, Path) or (isinstance(source, str) and "\n" not in source):
        from .files import read_input

        path = Path(source)
        try:
            data = read_input(path, f"{what} file")
        except FileNotFoundError:
            raise ModelFileError(f"cannot read the {what} file: no such file.", path=path,
                                 line=None) from None
        return _decode(data), path
    if isinstance(source, str):
        return source, None
    raise TypeError(f"expected a path, text or bytes; got {type(source).__name__}.")


def _decode(data: bytes) -> str:
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def _strip_comment(text: str) -> str:
    """Text before the first ``!`` that is not inside quotes."""
    quote = None
    for k, ch in enumerate(text):
        if quote:
            if ch == quote:
                quote = None
        elif ch in "'\"":
            quote = ch
        elif ch == "!":
            return text[:k]
    return text


class _Body:
    """A statement's text after ``KEYWORD/``, joined over its continuation lines, with a map
    from character offsets back to (line, column) in the file."""

    def __init__(self):
        self.parts: list[str] = []
        self.starts: list[int] = []
        self.origin: list[tuple[int, int]] = []
        self.length = 0

    def add(self, text: str, line: int, column: int):
        if self.parts:
            self.parts.append("\n")
            self.length += 1
        self.starts.append(self.length)
        self.origin.append((line, column))
        self.parts.append(text)
        self.length += len(text)

    @property
    def text(self) -> str:
        return "".join(self.parts)

    def where(self, offset: int) -> tuple[int, int]:
        k = max(bisect.bisect_right(self.starts, offset) - 1, 0)
        line, column = self.origin[k]
        return line, column + offset - self.starts[k]


def _error(message, path, line, field=None):
    """A located error; the field is named in the prefix only if the message does not already
    name it (`file:43: BUSHING/1: K needs 3 values`, not `file:43: K: BUSHING/1: K needs ...`)."""
    if field and re.search(rf"(?<![\w.]){re.escape(str(field))}(?![\w])", message):
        error = ModelFileError(message, path=path, line=line)
        error.field = field
        return error
    return ModelFileError(message, path=path, line=line, field=field)


def _parse_body(keyword: str, body: _Body, path, first_line: int):
    """Arguments and flags of one statement (see the module docstring for the syntax)."""
    text = body.text
    n = len(text)
    arguments: dict[str, AdmArgument] = {}
    flags: list[str] = []
    ident = None
    pos = _SPACE.match(text, 0).end()
    m = _ID.match(text, pos)
    if m and not (m.end() < n and _END_OF_VALUE.match(text, m.end())):
        ident = int(m.group())
        pos = m.end()

    def line_at(offset):
        return body.where(offset)[0]

    while True:
        pos = _SPACE.match(text, pos).end()
        if pos >= n:
            break
        if text[pos] == ",":
            pos += 1
            continue
        m = _NAME.match(text, pos)
        if m is None:
            raise _error(f"{keyword}: unexpected {text[pos]!r}; expected NAME = value or a "
                         "keyword such as GROUND.", path, line_at(pos))
        word = m.group().upper()
        after = _SPACE.match(text, m.end()).end()
        if after < n and text[after] == "=" and text[after + 1:after + 2] != "=":
            if word in arguments:
                raise _error(f"{keyword}: argument {word} is given twice.", path, line_at(pos),
                             word)
            start = _SPACE.match(text, after + 1).end()
            if word in _EXPRESSION_KEYS:
                depth, k = 0, start
                while k < n:
                    ch = text[k]
                    if ch == "(":
                        depth += 1
                    elif ch == ")":
                        depth -= 1
                    elif ch == "\\" or (ch == "," and depth <= 0):
                        break
                    k += 1
                expression = text[start:k].strip()
                if not expression:
                    raise _error(f"{keyword}: {word} = has no expression.", path,
                                 line_at(start), word)
                arguments[word] = AdmArgument(word, [], expression, line_at(start))
                pos = k + 1 if k < n and text[k] == "\\" else k
                continue
            values, pos = _read_values(keyword, word, text, start, body, path)
            arguments[word] = AdmArgument(word, values, None, line_at(m.start()))
        else:
            flags.append(word)
            pos = m.end()
            nxt = _SPACE.match(text, pos).end()
            if nxt < n and text[nxt] != ",":
                raise _error(f"{keyword}: expected ',' after {word}.", path, line_at(nxt))
    return ident, arguments, flags


def _read_values(keyword, word, text, pos, body, path):
    """Values after ``NAME =``: the first may be a word or string; more must be numbers."""
    n = len(text)
    values = []

    def token(at, first):
        m = _NUMBER.match(text, at)
        if m and not (m.end() < n and _END_OF_VALUE.match(text, m.end())):
            return m
        if not first:
            return None
        for pattern in (_STRING, _WORD):
            m = pattern.match(text, at)
            if m:
                return m
        return None

    m = token(pos, True)
    if m is None:
        # A value outside the simple forms (e.g. a USER(...) list): keep it raw, balanced.
        depth, k = 0, pos
        while k < n and not (text[k] == "," and depth <= 0):
            depth += text[k] == "("
            depth -= text[k] == ")"
            k += 1
        raw = text[pos:k].strip()
        if not raw:
            raise _error(f"{keyword}: {word} = has no value.", path, body.where(pos)[0], word)
        line, col = body.where(pos)
        return [AdmValue(raw, line, col, col + len(raw))], k
    while True:
        line, col = body.where(m.start())
        values.append(AdmValue(m.group(), line, col, col + len(m.group())))
        pos = m.end()
        if m.re is _WORD and pos < n and text[pos] == "(":
            depth, k = 0, pos
            while k < n:
                depth += text[k] == "("
                depth -= text[k] == ")"
                k += 1
                if depth == 0:
                    break
            values[-1].text = text[m.start():k]
            pos = k
        nxt = _SPACE.match(text, pos).end()
        if nxt >= n:
            return values, nxt
        if text[nxt] != ",":
            raise _error(f"{keyword}: expected ',' after the value of {word}; got "
                         f"{text[nxt]!r}.", path, body.where(nxt)[0], word)
        cand = _SPACE.match(text, nxt + 1).end()
        m2 = token(cand, False)
        if m2 is None:
            return values, nxt
        m = m2


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


@dataclasses.dataclass
class AdmModel:
    """A parsed Adams dataset. `build(time)` makes the `Mechanism`; `loads(mech, times)` the
    GFORCE/VFORCE/VTORQUE/SFORCE loads and MOTION driver values at given times.

    **Fields:** `title`; `units` (FORCE, MASS, LENGTH, TIME as written); `length_to_mm`,
    `force_to_n` (conversion factors); `statements` (the active ones, in file order); `names`
    ((keyword, id) → adams_view_name); `splines` (id → `AdmSpline`); `skipped` (statements
    outside the subset, each with line and reason); `ignored` (statements without static
    effect); `inactive` ((line, text) of commented-out statements); `path`.
    """

    title: str
    units: dict
    length_to_mm: float
    force_to_n: float
    statements: list[AdmStatement]
    names: dict
    splines: dict
    skipped: list[SkippedStatement]
    ignored: list[SkippedStatement]
    inactive: list[tuple[int, str]]
    path: Path | None = None
    _plan: object = dataclasses.field(default=None, repr=False)

    # -- public API -----------------------------------------------------------------------

    def build(self, time: float = 0.0, *, check: bool = True) -> Mechanism:
        """The `Mechanism` (mm, N, N·mm, rad; the file's global frame; design position = the
        file's positions). Two-body SFORCE functions are evaluated at `time` (s)."""
        return self._plan.build(time, check)

    def loads(self, mech: Mechanism, times: float | Float[ArrayLike, " t"] = 0.0) -> Loads:
        """Loads of the file's external forces and motions at `times` (s).

        Each GFORCE/VFORCE/VTORQUE/action-only SFORCE is the load point of the same name in
        `mech` (N, N·mm in the load point's frame); each MOTION the driver of the same name (mm,
        measured from the design position). A scalar `times` gives one case; an array a leading
        case axis.
        """
        return self._plan.loads(mech, times)

    def spline_bushings(self) -> dict[str, dict[str, AdmSpline]]:
        """A/Car bushing splines grouped by bushing: name stem → {axis: spline}, for splines
        named ``<stem>_fx_spline`` ... ``<stem>_tz_spline`` (axes 'tx', 'ty', 'tz' for forces,
        'rx', 'ry', 'rz' for torques)."""
        groups: dict[str, dict[str, AdmSpline]] = {}
        for spline in self.splines.values():
            m = re.fullmatch(r"(.+)_([ft])([xyz])_spline", spline.name or "", re.IGNORECASE)
            if m:
                axis = ("t" if m.group(2).lower() == "f" else "r") + m.group(3).lower()
                groups.setdefault(m.group(1), {})[axis] = spline
        return groups

    def spline_stiffnesses(self, stem: str) -> dict[str, float]:
        """Linear stiffness of each axis of the A/Car bushing `stem` (N/mm, N·mm/rad), from
        Y = −K·X fitted through the origin (spec stiffness §4.3)."""
        group = self.spline_bushings().get(stem)
        if group is None:
            raise KeyError(f"no A/Car bushing splines named '{stem}_*_spline'; known: "
                           f"{', '.join(self.spline_bushings()) or 'none'}.")
        out = {}
        for axis, spline in group.items():
            scale = (self.force_to_n / self.length_to_mm if axis[0] == "t"
                     else self.force_to_n * self.length_to_mm)
            out[axis] = spline_stiffness(spline) * scale
        return out


def spline_stiffness(spline: AdmSpline) -> float:
    """Stiffness K of a spline written Y = −K·X (file units): least squares through the origin,
    K = −Σxy / Σx² (spec stiffness §4.3: A/Car bushing splines, force on the I part)."""
    x, y = np.asarray(spline.x, float), np.asarray(spline.y, float)
    return float(-(x @ y) / (x @ x))


# ----------------------------------------------------------------------------- parse


def parse_adm(source) -> AdmModel:
    """Parse an Adams dataset (.adm) — a path, or the text itself — into an `AdmModel`.

    The statements outside the subset (see the module docstring) are listed in
    `AdmModel.skipped` and in one `ModelWarning`. Raises `ModelFileError` (with the line) for
    a malformed statement, an unknown marker or part, a non-finite number.
    """
    text, path = _read_source(source, "Adams dataset")
    lines = text.splitlines()
    title = ""
    raw: list[tuple[str, _Body, int, int, str | None]] = []
    inactive: list[tuple[int, str]] = []
    pending_name = None
    current = None
    for number, line in enumerate(lines, start=1):
        stripped = line.lstrip()
        if number == 1:
            m = _STATEMENT_START.match(line)
            if not (m and m.group(1).upper() in SUPPORTED + NO_STATIC_EFFECT
                    and m.group(2) == "/"):
                title = line.strip()
                continue
        if not stripped:
            continue
        if stripped.startswith("!"):
            m = _VIEW_NAME.match(stripped)
            if m:
                pending_name = m.group(2)
            elif _COMMENTED_STATEMENT.match(stripped):
                inactive.append((number, stripped[1:].strip()))
                pending_name = None  # the name belonged to the commented-out statement
            continue
        content = _strip_comment(line)
        column = len(line) - len(stripped)
        if stripped.startswith(","):
            if current is None:
                raise _error("a continuation line (starting with ',') has no statement before "
                             "it.", path, number)
            current[1].add(content[column:], number, column)
            current[3] = number
            continue
        m = _STATEMENT_START.match(content)
        if m is None:
            raise _error(f"expected a statement (KEYWORD/id, ...) or a comment (!); got "
                         f"{stripped[:40]!r}.", path, number)
        keyword = m.group(1).upper()
        if keyword == "END" and m.group(2) == "":
            current = None
            break
        if m.group(2) != "/":
            raise _error(f"expected '/' after the statement keyword {keyword}.", path, number)
        body = _Body()
        body.add(content[m.end():], number, m.end())
        current = [keyword, body, number, number, pending_name]
        raw.append(current)
        pending_name = None

    statements: list[AdmStatement] = []
    skipped: list[SkippedStatement] = []
    ignored: list[SkippedStatement] = []
    for keyword, body, first, last, name in raw:
        if keyword not in SUPPORTED:
            ident = _ID.match(body.text.lstrip())
            record = SkippedStatement(keyword, int(ident.group()) if ident else None, name,
                                      first, "")
            if keyword in NO_STATIC_EFFECT:
                record.reason = "no effect on a static solution"
                ignored.append(record)
            else:
                record.reason = "statement outside the supported subset"
                skipped.append(record)
            continue
        ident, arguments, flags = _parse_body(keyword, body, path, first)
        statements.append(AdmStatement(keyword, ident, name, arguments, flags, first, last))

    model = AdmModel(title=title, units={}, length_to_mm=1.0, force_to_n=1.0,
                     statements=statements, names={}, splines={}, skipped=skipped,
                     ignored=ignored, inactive=inactive, path=path)
    model._plan = _Plan(model)
    if model.skipped:
        warnings.warn(
            f"{path or '<input>'}: skipped {len(model.skipped)} statement(s) outside the "
            "supported subset: " + "; ".join(str(s) for s in model.skipped),
            ModelWarning, stacklevel=2,
        )
    return model


def read_adm(path, *, time: float = 0.0, check: bool = True) -> Mechanism:
    """Read an Adams dataset (.adm) into a `Mechanism` (see the module docstring for the
    subset). Two-body SFORCE functions are evaluated at `time` (s); the external loads and
    motions of the file are given by `parse_adm(path).loads(mech, times)`. `check`: validate
    the model (free modes, joints assembled), as `MechanismBuilder.build`.

    spec: stiffness §4.1 (Annex F), §6 item 10.
    """
    return parse_adm(path).build(time, check=check)


# ----------------------------------------------------------------------------- interpretation


def _real(value: AdmValue, path, what, *, angle=False) -> float:
    m = _REAL.fullmatch(value.text)
    if m is None:
        raise _error(f"{what}: {value.text!r} is not a number.", path, value.line, what)
    x = float(m.group(1))
    if not math.isfinite(x):
        raise _error(f"{what}: {value.text} is not a finite number.", path, value.line, what)
    if m.group(2):
        if not angle:
            raise _error(f"{what}: the degree suffix D is only allowed on angles.", path,
                         value.line, what)
        x = math.radians(x)
    return x


def _check_magnitude(values, path, line, what, limit=1e15):
    if any(abs(v) > limit for v in values):
        raise _error(f"{what}: {values} exceeds {limit:g} in magnitude; check the value and "
                     "its units.", path, line, what)


class _Plan:
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
                    raise _error(f"{s.keyword}/{s.id} is defined twice (first at line "
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
                raise _error(f"{s.label}: {key} is missing.", self.path, s.line, key)
            return list(default)
        if arg.expression is not None:
            raise _error(f"{s.label}: {key} must be numbers.", self.path, arg.line, key)
        out = [_real(v, self.path, f"{s.label} {key}", angle=angle) * scale for v in arg.values]
        if count is not None and len(out) != count:
            raise _error(f"{s.label}: {key} needs {count} value(s); got {len(out)}.",
                         self.path, arg.line, key)
        _check_magnitude(out, self.path, arg.line, f"{s.label} {key}")
        return out

    def integer(self, s, key, *, required=True):
        arg = s.arguments.get(key)
        if arg is None:
            if required:
                raise _error(f"{s.label}: {key} is missing.", self.path, s.line, key)
            return None
        if len(arg.values) != 1 or not _INTEGER.fullmatch(arg.values[0].text):
            raise _error(f"{s.label}: {key} must be one integer id.", self.path, arg.line, key)
        return int(arg.values[0].text)

    def word(self, s, key):
        arg = s.arguments.get(key)
        if arg is None:
            return None
        if len(arg.values) != 1:
            raise _error(f"{s.label}: {key} must be one word.", self.path, arg.line, key)
        return arg.values[0].text.strip("'\"").upper()

    def marker(self, s, key) -> _Marker:
        ident = self.integer(s, key)
        if ident not in self.markers:
            raise _error(f"{s.label}: {key} = {ident} is not a defined MARKER.", self.path,
                         s.arguments[key].line, key)
        return self.markers[ident]

    def expression(self, s, key):
        arg = s.arguments.get(key)
        if arg is None:
            return None
        if arg.expression is None:
            raise _error(f"{s.label}: {key} must be a function expression.", self.path,
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
            raise _error("UNITS/ is given twice.", self.path, units[1].line)
        if units:
            s = units[0]
            system = self.word(s, "SYSTEM")
            if system is not None:
                if system not in _SYSTEMS:
                    raise _error(f"UNITS/: SYSTEM = {system} is not one of "
                                 f"{', '.join(_SYSTEMS)}.", self.path, s.line, "SYSTEM")
                length, force = _SYSTEMS[system]
            length = self.word(s, "LENGTH") or length
            force = self.word(s, "FORCE") or force
            for key in ("FORCE", "MASS", "LENGTH", "TIME", "SYSTEM"):
                if (value := self.word(s, key)) is not None:
                    model.units[key] = value
            if length not in _LENGTH_TO_MM:
                raise _error(f"UNITS/: LENGTH = {length} is not one of "
                             f"{', '.join(_LENGTH_TO_MM)}.", self.path, s.line, "LENGTH")
            if force not in _FORCE_TO_N:
                raise _error(f"UNITS/: FORCE = {force} is not one of "
                             f"{', '.join(_FORCE_TO_N)}.", self.path, s.line, "FORCE")
        model.length_to_mm = _LENGTH_TO_MM[length]
        model.force_to_n = _FORCE_TO_N[force]
        self.lf, self.ff = model.length_to_mm, model.force_to_n

    def _frame(self, s, origin_key, z_key, x_key):
        """(position, rotation) from QP/QG + REULER or ZP/XP (ZG/XG), in the parent frame."""
        origin = np.array(self.reals(s, origin_key, 3, default=(0, 0, 0), scale=self.lf))
        has_euler = "REULER" in s.arguments
        if has_euler and z_key in s.arguments:
            raise _error(f"{s.label}: give REULER or {z_key}/{x_key}, not both.", self.path,
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
                raise _error(f"{s.label}: {e}", self.path, s.line, z_key) from None
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
                raise _error("PART/ needs an id.", self.path, s.line)
            if "GROUND" in s.flags:
                if self.ground is not None:
                    raise _error(f"PART/{s.id}: a second GROUND part (the first is "
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
                raise _error("MARKER/ needs an id.", self.path, s.line)
            part = self.integer(s, "PART")
            if part not in self.parts:
                raise _error(f"{s.label}: PART = {part} is not a defined PART.", self.path,
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
                raise _error(f"{s.keyword}/ needs an id.", self.path, s.line)
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
                raise _error(f"{s.label}: {key} = {m.id} is a FLOATING marker; only "
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
                raise _error(f"{s.label}: DM({a}, {b}) refers to marker {ident}, which is not "
                             "a defined fixed MARKER.", self.path, s.line, "FUNCTION")
        i, j = self.markers[a], self.markers[b]
        design = float(np.linalg.norm(i.position - j.position))
        length *= self.lf
        if abs(design - length) > 1e-6 * max(1.0, design):
            raise _error(f"{s.label}: DM({a}, {b}) - L with L = {length:.9g} mm, but the "
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
        node = self.expression(s, "FUNCTION")
        if node is None:
            raise _error(f"{s.label}: FUNCTION is missing.", self.path, s.line, "FUNCTION")
        _check_evaluable(node)
        rotational = "ROTATIONAL" in s.flags
        if not rotational and "TRANSLATIONAL" not in s.flags:
            raise _error(f"{s.label}: give TRANSLATIONAL or ROTATIONAL.", self.path, s.line)
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
                raise _error(f"{s.label}: a two-body TRANSLATIONAL SFORCE needs distinct I and "
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
            raise _error(f"{s.label}: I = {i.id} is a FLOATING marker.", self.path, s.line, "I")
        jfloat = self.marker(s, "JFLOAT")
        rm = self.marker(s, "RM")
        if not jfloat.floating:
            raise _error(f"{s.label}: JFLOAT = {jfloat.id} must be a FLOATING marker.",
                         self.path, s.line, "JFLOAT")
        if rm.floating:
            raise _error(f"{s.label}: RM = {rm.id} must be a fixed marker.", self.path, s.line,
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
            raise _error(f"{s.label}: FUNCTION is missing.", self.path, s.line, "FUNCTION")
        _check_evaluable(node)
        if any(f in s.flags for f in ("VELOCITY", "ACCELERATION")):
            raise _Unsupported("only DISPLACEMENT motions are supported")
        if "JOINT" in s.arguments:
            if "ROTATION" in s.flags:
                raise _Unsupported("rotational joint motions are not supported")
            joint = self.by_key.get(("JOINT", self.integer(s, "JOINT")))
            if joint is None or not any(f in joint.flags
                                        for f in ("TRANSLATIONAL", "CYLINDRICAL")):
                raise _error(f"{s.label}: JOINT must be a translational or cylindrical JOINT.",
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
            raise _error(f"{s.label}: X and Y need the same number of values (at least 2); got "
                         f"{x.size} and {y.size}.", self.path, s.arguments["Y"].line, "Y")
        if np.any(np.diff(x) <= 0):
            raise _error(f"{s.label}: X must be strictly increasing.", self.path,
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
            raise _error(f"{what}; an Adams dataset (.adm) needs PART/ statements (one with "
                         "GROUND), MARKER/s on them and the joints and forces between them.",
                         self.path, 1)
        if not any(kind in ("joint", "bushing", "spring") for _, kind, _, _ in self.calls):
            raise _error("the dataset defines no joint, bushing or spring between its parts "
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
            error = _error(str(e), self.path, _line_of(str(e), lines, self.statements))
            # A model well written but not solvable as given (free modes, joints not assembled)
            # is exit 4 whatever its format, like a native file's.
            error.bad_input = getattr(e, "bad_input", False)
            raise error from None
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as e:
            raise _error(f"the model cannot be assembled: {e}", self.path,
                         self.statements[-1].line if self.statements else 1) from None

    def _call(self, fn, lines, line, *args, **kw):
        try:
            return fn(*args, **kw)
        except ModelError as e:
            raise _error(str(e), self.path, line) from None

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
        raise _error(f"{s.label}: its function cannot be evaluated at time {time}: {e}.", path,
                     s.line) from None
    if not math.isfinite(value) or abs(value) > 1e15:
        raise _error(f"{s.label}: its function gives {value} at time {time}.", path, s.line)
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


# ----------------------------------------------------------------------------- write .adm


def _fmt(x: float) -> str:
    return repr(float(x)).upper()


def write_adm(mech: Mechanism, path, *, template=None) -> str:
    """Write `mech` as an Adams dataset; returns the text written.

    - With `template` (the path or text of the .adm the mechanism came from): the template's
      text is kept and only stiffnesses are updated, in the template's units — BUSHING K and KT
      of the bushings named like `mech`'s, SPRINGDAMPER K and LENGTH of its springs, and the Y
      values of A/Car bushing splines (``<bushing>_{fx..tz}_spline``, Y = −K·X, spec stiffness
      §4.3, X of torque splines in rad). This is the thesis's workflow of writing identified
      stiffnesses back.
    - Without: a complete dataset in mm, N: one PART per part, one MARKER per marker (QP and
      REULER in degrees, global at design), JOINT/JPRIM for joints, GCON DM(i, j) − L for
      distance joints, BUSHING, SPRINGDAMPER, a zero GFORCE per load point (the user's loads
      go in load cases) and a MOTION per driver. `read_adm` of the result gives the same
      mechanism. Laws outside the .adm subset (tabulated or cubic laws, bushing splines or
      translational offsets, stops) raise `ModelError`.

    **Arguments:** `mech`; `path` (file to write, or None to only return the text);
    `template` (path or text).
    """
    text = _write_with_template(mech, template) if template is not None else _write_full(mech)
    if path is not None:
        Path(path).write_text(text)
    return text


def _write_full(mech: Mechanism) -> str:
    out = [f"ADAMS/View model name: {mech.name}",
           "UNITS/FORCE = NEWTON, MASS = KILOGRAM, LENGTH = MILLIMETER, TIME = SECOND",
           "! adams_view_name='ground'", "PART/1, GROUND"]
    for k, part in enumerate(mech.parts):
        out += [f"! adams_view_name='{part}'", f"PART/{k + 2}"]
    pos = np.asarray(mech.markers.position, float)
    rot = np.asarray(mech.markers.orientation, float)
    ids = {}
    for k, name in enumerate(mech.markers.names):
        ids[k] = k + 1
        part = mech.markers.part[k]
        line = f"MARKER/{k + 1}, PART = {1 if part < 0 else part + 2}"
        line += ", QP = " + ", ".join(_fmt(v) for v in pos[k])
        if not np.allclose(rot[k], np.eye(3), rtol=0, atol=1e-15):
            angles = np.asarray(matrix_to_reuler_deg(jnp.asarray(rot[k])))
            line += ", REULER = " + ", ".join(_fmt(a) + "D" for a in angles)
        out += [f"! adams_view_name='{name}'", line]
    next_id = len(mech.markers.names) + 1
    aux = []

    def aux_marker(position=(0.0, 0.0, 0.0), rotation=None, floating=False):
        nonlocal next_id
        ident = next_id
        next_id += 1
        line = f"MARKER/{ident}, PART = 1"
        if floating:
            line += ", FLOATING"
        else:
            line += ", QP = " + ", ".join(_fmt(v) for v in position)
            if rotation is not None and not np.allclose(rotation, np.eye(3), rtol=0, atol=1e-15):
                angles = np.asarray(matrix_to_reuler_deg(jnp.asarray(rotation)))
                line += ", REULER = " + ", ".join(_fmt(a) + "D" for a in angles)
        aux.append(line)
        return ident

    elements = []
    j = mech.joints
    adams_joint = {"spherical": "JOINT/{}, SPHERICAL", "revolute": "JOINT/{}, REVOLUTE",
                   "cylindrical": "JOINT/{}, CYLINDRICAL",
                   "translational": "JOINT/{}, TRANSLATIONAL",
                   "universal": "JOINT/{}, UNIVERSAL", "fixed": "JOINT/{}, FIXED",
                   "inline": "JPRIM/{}, INLINE", "inplane": "JPRIM/{}, INPLANE",
                   "perpendicular": "JPRIM/{}, PERPENDICULAR"}
    for k, (name, kind) in enumerate(zip(j.names, j.kind, strict=True)):
        i_id, j_id = ids[j.i_marker[k]], ids[j.j_marker[k]]
        elements.append(f"! adams_view_name='{name}'")
        if kind == "distance":
            length = float(np.linalg.norm(pos[j.i_marker[k]] - pos[j.j_marker[k]]))
            elements.append(f"GCON/{k + 1}, I = {i_id}, FUNCTION = DM({i_id}, {j_id}) - "
                            f"{_fmt(length)}")
        else:
            elements.append(adams_joint[kind].format(k + 1) + f", I = {i_id}, J = {j_id}")
    b = mech.bushings
    for k, name in enumerate(b.names):
        arrays = {f: np.asarray(getattr(b, f)[k], float) for f in
                  ("k_trans", "k_rot", "cubic_trans", "cubic_rot", "offset_trans", "offset_rot",
                   "preload_force", "preload_torque")}
        if any(b.spline_axes[k]) or np.any(arrays["cubic_trans"]) or np.any(
                arrays["cubic_rot"]) or np.any(arrays["offset_trans"]):
            raise ModelError(f"bushing '{name}' has a spline, cubic or offset law, which the "
                             ".adm subset (linear BUSHING) cannot express.")
        i_id, j_id = ids[b.i_marker[k]], ids[b.j_marker[k]]
        elements.append(f"! adams_view_name='{name}'")
        torsion = (not np.any(arrays["k_trans"]) and not np.any(arrays["k_rot"][:2])
                   and not np.any(arrays["preload_force"])
                   and not np.any(arrays["preload_torque"][:2])
                   and not np.any(arrays["offset_rot"][:2]))
        if np.any(arrays["offset_rot"]) and not torsion:
            raise ModelError(f"bushing '{name}' has rotational offsets on more than its z axis; "
                             "the .adm subset cannot express them.")
        if torsion and np.any(arrays["offset_rot"]):
            elements.append(
                f"SPRINGDAMPER/{k + 1}, ROTATIONAL, I = {i_id}, J = {j_id}, "
                f"KT = {_fmt(arrays['k_rot'][2])}, CT = 0, ANGLE = {_fmt(arrays['offset_rot'][2])}"
                f", TORQUE = {_fmt(arrays['preload_torque'][2])}")
            continue
        line = (f"BUSHING/{k + 1}, I = {i_id}, J = {j_id}, K = "
                + ", ".join(_fmt(v) for v in arrays["k_trans"]) + ", C = 0, 0, 0, KT = "
                + ", ".join(_fmt(v) for v in arrays["k_rot"]) + ", CT = 0, 0, 0")
        if np.any(arrays["preload_force"]):
            line += ", FORCE = " + ", ".join(_fmt(v) for v in arrays["preload_force"])
        if np.any(arrays["preload_torque"]):
            line += ", TORQUE = " + ", ".join(_fmt(v) for v in arrays["preload_torque"])
        elements.append(line)
    s = mech.springs
    offset = len(b.names)
    for k, name in enumerate(s.names):
        i_id, j_id = ids[s.i_marker[k]], ids[s.j_marker[k]]
        free = float(s.free_length[k])
        if s.tabulated[k]:
            x, y = np.asarray(s.table_x[k], float), np.asarray(s.table_y[k], float)
            slope = (y[-1] - y[0]) / (x[-1] - x[0])
            intercept = y[0] - slope * x[0]
            if not np.allclose(y, intercept + slope * x, rtol=1e-12, atol=1e-9):
                raise ModelError(f"spring '{name}' has a nonlinear table, which the .adm "
                                 "subset cannot express.")
            # tension = slope·(ℓ − free) + intercept = K·(ℓ − LENGTH) − FORCE
            k_value, length, force = slope, free, -intercept
        else:
            k_value, length, force = float(s.k[k]), free, 0.0
        elements += [f"! adams_view_name='{name}'",
                     f"SPRINGDAMPER/{offset + k + 1}, TRANSLATIONAL, I = {i_id}, J = {j_id}, "
                     f"K = {_fmt(k_value)}, C = 0, LENGTH = {_fmt(length)}, FORCE = {_fmt(force)}"]
    if mech.stops.names:
        raise ModelError(f"stops ({', '.join(mech.stops.names)}) are outside the .adm subset.")
    lp = mech.load_points
    for k, name in enumerate(lp.names):
        jfloat = aux_marker(floating=True)
        rm = ids[lp.frame[k]] if lp.frame[k] >= 0 else aux_marker()
        elements += [f"! adams_view_name='{name}'",
                     f"GFORCE/{k + 1}, I = {ids[lp.marker[k]]}, JFLOAT = {jfloat}, RM = {rm}",
                     ", FX = 0\\", ", FY = 0\\", ", FZ = 0\\", ", TX = 0\\", ", TY = 0\\",
                     ", TZ = 0"]
    d = mech.drivers
    for k, name in enumerate(d.names):
        direction = np.asarray(d.direction[k], float)
        j_id = aux_marker(pos[d.marker[k]], frame_from_axes(direction))
        elements += [f"! adams_view_name='{name}'",
                     f"MOTION/{k + 1}, I = {ids[d.marker[k]]}, J = {j_id}, Z, FUNCTION = 0"]
    return "\n".join(out + aux + elements + ["END", ""])


def _write_with_template(mech: Mechanism, template) -> str:
    text, path = _read_source(template, "Adams dataset")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ModelWarning)
        model = parse_adm(text)
    lines = text.splitlines()
    edits: list[tuple[int, int, int, str]] = []
    lf, ff = model.length_to_mm, model.force_to_n
    plan = model._plan
    names = {s.line: n for s, _, (n, *_), _ in plan.calls}

    def replace(s, key, values):
        arg = s.arguments.get(key)
        if arg is not None and len(arg.values) == len(values):
            for v, new in zip(arg.values, values, strict=True):
                edits.append((v.line, v.start, v.end, _fmt(new)))
        else:
            if arg is not None:
                raise ModelError(f"{s.label}: {key} has {len(arg.values)} value(s) in the "
                                 f"template; expected {len(values)}.")
            last = s.end_line
            edits.append((last, len(lines[last - 1]), len(lines[last - 1]),
                          f", {key} = " + ", ".join(_fmt(v) for v in values)))

    bushings, springs = mech.bushings, mech.springs
    for s in model.statements:
        name = names.get(s.line)
        if s.keyword == "BUSHING" and name in bushings.names:
            k = bushings.index(name)
            replace(s, "K", np.asarray(bushings.k_trans[k]) * lf / ff)
            replace(s, "KT", np.asarray(bushings.k_rot[k]) / (ff * lf))
        elif (s.keyword == "SPRINGDAMPER" and "ROTATIONAL" not in s.flags
              and name in springs.names):
            k = springs.names.index(name)
            if springs.tabulated[k]:
                raise ModelError(f"spring '{name}' is tabulated; its SPRINGDAMPER cannot be "
                                 "updated.")
            k_file = float(springs.k[k]) * lf / ff
            force = plan.reals(s, "FORCE", 1, default=(0,))[0]
            replace(s, "K", [k_file])
            replace(s, "LENGTH", [float(springs.free_length[k]) / lf - force / k_file])
    for stem, group in model.spline_bushings().items():
        target = stem if stem in bushings.names else next(
            (n for n in bushings.names if stem.endswith("_" + n)), None)
        if target is None:
            continue
        k = bushings.index(target)
        for axis, spline in group.items():
            a = "xyz".index(axis[1])
            if axis[0] == "t":
                slope = float(bushings.k_trans[k, a]) * lf / ff
            else:
                slope = float(bushings.k_rot[k, a]) / (ff * lf)
            s = next(st for st in model.statements
                     if st.keyword == "SPLINE" and st.id == spline.id)
            replace(s, "Y", -slope * spline.x)
    for line, start, end, new in sorted(edits, key=lambda e: (e[0], -e[1])):
        row = lines[line - 1]
        lines[line - 1] = row[:start] + new + row[end:]
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- TeimOrbit files


@dataclasses.dataclass
class TeimTable:
    """A ``{col1 col2 ...}`` table: column names and rows (floats, or strings for quoted
    cells), with the header's line."""

    columns: tuple[str, ...]
    rows: list[list]
    line: int


@dataclasses.dataclass
class TeimBlock:
    """A ``[SECTION]`` or ``(SUBSECTION)``: ``key = value`` pairs, tables, subsections."""

    name: str
    line: int
    values: dict = dataclasses.field(default_factory=dict)
    tables: list[TeimTable] = dataclasses.field(default_factory=list)
    blocks: dict = dataclasses.field(default_factory=dict)


_TEIM_SECTION = re.compile(r"\[([^\[\]]*)\]\s*$")
_TEIM_SUBSECTION = re.compile(r"\(([^()]*)\)\s*$")
_TEIM_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_ ]*")
_TEIM_HEADER = re.compile(r"\{([^{}]*)\}\s*$")
_TEIM_PAIR = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)\s*=\s*(.*?)\s*$")
_TEIM_CELL = re.compile(r"\s*('[^']*'|\"[^\"]*\"|[^\s'\"]+)")
_TEIM_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")


def _teim_value(text: str, path, line):
    if len(text) >= 2 and text[0] == text[-1] and text[0] in "'\"":
        return text[1:-1]
    if _TEIM_NUMBER.fullmatch(text):
        value = float(text)
        if not math.isfinite(value):
            raise _error(f"{text} is not a finite number.", path, line)
        return value
    if re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.]*", text):
        return text
    raise _error(f"value {text[:40]!r} is not a number, a quoted string or a word.", path, line)


def parse_teimorbit(source, what: str = "property") -> dict[str, TeimBlock]:
    """Parse a TeimOrbit file (the format of A/Car .lcf and property files) into its sections.

    Lines: ``$`` comments, ``[SECTION]``, ``(SUBSECTION)``, ``key = value`` (quoted string,
    number or word), ``{col1 col2 ...}`` table headers followed by rows of numbers or quoted
    strings. Raises `ModelFileError` with the line of anything else.
    """
    text, path = _read_source(source, what)
    sections: dict[str, TeimBlock] = {}
    section = block = None
    table = None
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("$"):
            continue
        if (m := _TEIM_SECTION.match(stripped)) and _TEIM_NAME.fullmatch(m.group(1).strip()):
            name = m.group(1).strip().upper()
            if name in sections:
                raise _error(f"section [{name}] is given twice (first at line "
                             f"{sections[name].line}).", path, number)
            section = block = sections[name] = TeimBlock(name, number)
            table = None
        elif (m := _TEIM_SUBSECTION.match(stripped)) and _TEIM_NAME.fullmatch(
                m.group(1).strip()):
            if section is None:
                raise _error(f"({m.group(1).strip()}) is outside any [SECTION].", path, number)
            name = m.group(1).strip().upper()
            block = section.blocks[name] = TeimBlock(name, number)
            table = None
        elif m := _TEIM_HEADER.match(stripped):
            if block is None:
                raise _error("a {table header} is outside any [SECTION].", path, number)
            columns = tuple(m.group(1).split())
            if not columns:
                raise _error("the table header {} names no column.", path, number)
            table = TeimTable(columns, [], number)
            block.tables.append(table)
        elif (m := _TEIM_PAIR.match(stripped)) and not _TEIM_NUMBER.match(stripped):
            if block is None:
                raise _error(f"'{m.group(1)}' is outside any [SECTION].", path, number)
            block.values[m.group(1).upper()] = _teim_value(m.group(2), path, number)
            table = None
        elif table is not None:
            cells, pos = [], 0
            while pos < len(stripped):
                c = _TEIM_CELL.match(stripped, pos)
                if c is None:
                    break
                cells.append(_teim_value(c.group(1), path, number))
                pos = c.end()
            if len(cells) != len(table.columns):
                raise _error(f"row has {len(cells)} value(s) but the table header at line "
                             f"{table.line} names {len(table.columns)} column(s).", path, number)
            table.rows.append(cells)
        else:
            raise _error(f"unexpected line {stripped[:40]!r}: expected [SECTION], (SUBSECTION), "
                         "key = value, {table header} or a table row.", path, number)
    return sections


def _teim_format(value) -> str:
    if isinstance(value, str):
        return f"'{value}'"
    return _fmt(value)


def _write_teim(sections: list[tuple[str, dict, list[TeimTable], dict]]) -> str:
    out = []
    for name, values, tables, blocks in sections:
        out += [f"${'-' * max(60 - len(name), 3)}{name}", f"[{name}]"]
        out += [f" {k} = {_teim_format(v)}" for k, v in values.items()]
        for sub, (sub_values, sub_tables) in blocks.items():
            out.append(f"({sub})")
            out += [f" {k} = {_teim_format(v)}" for k, v in sub_values.items()]
            for t in sub_tables:
                out.append("{" + " ".join(t.columns) + "}")
                out += [" " + " ".join(_teim_format(c) for c in row) for row in t.rows]
        for t in tables:
            out.append("{" + " ".join(t.columns) + "}")
            out += [" " + " ".join(_teim_format(c) for c in row) for row in t.rows]
    return "\n".join(out) + "\n"


# ----------------------------------------------------------------------------- .lcf


@dataclasses.dataclass
class LoadCaseTable:
    """An A/Car load-case file: one row of `data` per load case, columns named by the
    ``{...}`` header of [DATA] (per wheel: ``whl_z_l``, ``lat_l``, ``brake_l``, ...; spec
    stiffness §4.2). Values are as written, in the file's [UNITS]; `mode` says what the columns
    mean (``VERTICAL_MODE = 'wheel_vertical_force'``: ``whl_z`` is a force).

    **Fields:** `columns`, `data` (cases, columns), `units`, `mode`, `header` ([MDI_HEADER]),
    `comments` (the (COMMENTS) rows), `path`.
    """

    columns: tuple[str, ...]
    data: np.ndarray
    units: dict = dataclasses.field(default_factory=dict)
    mode: dict = dataclasses.field(default_factory=dict)
    header: dict = dataclasses.field(default_factory=dict)
    comments: list = dataclasses.field(default_factory=list)
    path: Path | None = None

    @property
    def n_cases(self) -> int:
        return self.data.shape[0]

    def column(self, name: str) -> np.ndarray:
        """The values of column `name` (case-insensitive), one per load case."""
        lower = [c.lower() for c in self.columns]
        if name.lower() not in lower:
            raise KeyError(f"no column '{name}'; the file has {', '.join(self.columns)}.")
        return self.data[:, lower.index(name.lower())]


def read_lcf(path) -> LoadCaseTable:
    """Read an A/Car load-case file (.lcf, spec stiffness §4.2): [MDI_HEADER], (COMMENTS),
    [UNITS], [MODE] and the [DATA] table, parsed by column name. Raises `ModelFileError` with
    the line for anything malformed (a row with the wrong number of values, a value that is not
    a finite number, a missing [DATA] table)."""
    text, file = _read_source(path, "load-case")
    sections = parse_teimorbit(text)
    n_lines = max(len(text.splitlines()), 1)
    header = sections.get("MDI_HEADER")
    if header is not None:
        kind = header.values.get("FILE_TYPE")
        if kind is not None and str(kind).lower() != "lcf":
            raise _error(f"FILE_TYPE = {kind!r}; a load-case file has FILE_TYPE = 'lcf'.",
                         file, header.line, "FILE_TYPE")
    data = sections.get("DATA")
    if data is None or not data.tables:
        raise _error("no [DATA] section with a {column header} and rows.", file,
                     data.line if data else n_lines, "DATA")
    if len(data.tables) > 1:
        raise _error("[DATA] has more than one table.", file, data.tables[1].line, "DATA")
    table = data.tables[0]
    for row_index, row in enumerate(table.rows):
        if any(isinstance(c, str) for c in row):
            raise _error(f"load case {row_index + 1} has a non-numeric value.", file,
                         table.line + 1 + row_index, "DATA")
    columns = table.columns
    if len({c.lower() for c in columns}) != len(columns):
        raise _error("the [DATA] header names a column twice.", file, table.line, "DATA")
    comments = []
    if header is not None and "COMMENTS" in header.blocks:
        for t in header.blocks["COMMENTS"].tables:
            comments += [str(r[0]) for r in t.rows]
    return LoadCaseTable(
        columns=columns,
        data=np.array(table.rows, dtype=float).reshape(len(table.rows), len(columns)),
        units={k: v for k, v in sections["UNITS"].values.items()} if "UNITS" in sections
        else {},
        mode={k: v for k, v in sections["MODE"].values.items()} if "MODE" in sections else {},
        header=dict(header.values) if header is not None else {},
        comments=comments,
        path=file,
    )


def write_lcf(table: LoadCaseTable, path) -> str:
    """Write `table` as an A/Car load-case file; returns the text. `read_lcf` of it gives the
    same table."""
    data = np.asarray(table.data, dtype=float)
    if data.ndim != 2 or data.shape[1] != len(table.columns):
        raise ValueError(f"data must have shape (cases, {len(table.columns)}).")
    if not np.all(np.isfinite(data)):
        raise ValueError("load-case values must be finite.")
    header = {"FILE_TYPE": "lcf", "FILE_VERSION": 6.0, "FILE_FORMAT": "ascii"}
    header.update(table.header)
    blocks = {}
    if table.comments:
        blocks["COMMENTS"] = ({}, [TeimTable(("comment_string",), [[c] for c in table.comments],
                                             0)])
    sections = [("MDI_HEADER", header, [], blocks)]
    if table.units:
        sections.append(("UNITS", table.units, [], {}))
    if table.mode:
        sections.append(("MODE", table.mode, [], {}))
    sections.append(("DATA", {}, [TeimTable(tuple(table.columns), data.tolist(), 0)], {}))
    text = _write_teim(sections)
    if path is not None:
        Path(path).write_text(text)
    return text


# ----------------------------------------------------------------------------- .bus

_BUS_SECTIONS = {"tx": "TX_FORCE", "ty": "TY_FORCE", "tz": "TZ_FORCE", "rx": "RX_TORQUE",
                 "ry": "RY_TORQUE", "rz": "RZ_TORQUE"}
_ANGLE_TO_RAD = {"DEG": math.pi / 180, "DEGREE": math.pi / 180, "DEGREES": math.pi / 180,
                 "RAD": 1.0, "RADIAN": 1.0, "RADIANS": 1.0}


@dataclasses.dataclass
class BushingProperty:
    """An A/Car bushing property file, in diffsusp units and sign convention.

    **Fields:** `splines`: axis ('tx' … 'rz') → (x, y), deformation (mm or rad) and force on the
    I part (N or N·mm) — the file lists the restoring force with the deformation's sign
    (y_file = +k·x), diffsusp's laws give the force on I, y = −y_file; `k_trans` (3,) N/mm and
    `k_rot` (3,) N·mm/rad, least-squares slopes of the file curves through the origin (0 for an
    axis without a curve); `damping` (the [DAMPING] values as written); `units`; `header`.
    """

    splines: dict
    k_trans: np.ndarray
    k_rot: np.ndarray
    damping: dict = dataclasses.field(default_factory=dict)
    units: dict = dataclasses.field(default_factory=dict)
    header: dict = dataclasses.field(default_factory=dict)
    path: Path | None = None


def _unit_factor(units: dict, key: str, table: dict, default: str, path, line) -> float:
    value = str(units.get(key, default)).upper()
    aliases = {"MILLIMETER": "MM", "METER": "M", "NEWTON": "N", "MILLIMETERS": "MM",
               "METERS": "M"}
    value = aliases.get(value, value)
    if value not in table:
        raise _error(f"[UNITS] {key} = {value!r} is not one of {', '.join(table)}.", path, line,
                     key)
    return table[value]


def read_bushing_property(path) -> BushingProperty:
    """Read an A/Car bushing property file (.bus): [UNITS], [TX_FORCE] {tx force} …
    [RZ_TORQUE] {rz torque} curves, [DAMPING]. Raises `ModelFileError` with the line for a
    malformed file (no curve at all, a curve whose deformations do not increase, units that
    are not known)."""
    text, file = _read_source(path, "bushing property")
    sections = parse_teimorbit(text, "bushing property")
    units_block = sections.get("UNITS")
    units = dict(units_block.values) if units_block else {}
    uline = units_block.line if units_block else 1
    length = _unit_factor(units, "LENGTH", _LENGTH_TO_MM, "MM", file, uline)
    force = _unit_factor(units, "FORCE", _FORCE_TO_N, "N", file, uline)
    angle = _unit_factor(units, "ANGLE", _ANGLE_TO_RAD, "DEG", file, uline)
    splines, k_trans, k_rot = {}, np.zeros(3), np.zeros(3)
    for axis, name in _BUS_SECTIONS.items():
        block = sections.get(name)
        if block is None:
            continue
        if len(block.tables) != 1 or len(block.tables[0].columns) != 2:
            raise _error(f"[{name}] needs one table with two columns "
                         f"{{{axis} {'force' if axis[0] == 't' else 'torque'}}}.", file,
                         block.line, name)
        t = block.tables[0]
        rows = np.array(t.rows, dtype=object)
        if rows.size == 0 or any(isinstance(c, str) for r in t.rows for c in r):
            raise _error(f"[{name}] needs numeric rows.", file, t.line, name)
        x = np.asarray(rows[:, 0], float) * (length if axis[0] == "t" else angle)
        y = np.asarray(rows[:, 1], float) * (force if axis[0] == "t" else force * length)
        if x.size < 2 or np.any(np.diff(x) <= 0):
            raise _error(f"[{name}] needs at least two rows with increasing deformation.", file,
                         t.line, name)
        splines[axis] = (x, -y)
        slope = float(x @ y / (x @ x)) if np.any(x) else 0.0
        (k_trans if axis[0] == "t" else k_rot)["xyz".index(axis[1])] = slope
    if not splines:
        raise _error("no force curve ([TX_FORCE] … [RZ_TORQUE]) in the file.", file,
                     max(len(text.splitlines()), 1))
    damping = dict(sections["DAMPING"].values) if "DAMPING" in sections else {}
    header = dict(sections["MDI_HEADER"].values) if "MDI_HEADER" in sections else {}
    return BushingProperty(splines, k_trans, k_rot, damping, units, header, file)


def write_bushing_property(path, k_trans: Float[ArrayLike, "3"], k_rot: Float[ArrayLike, "3"],
                           *, max_deflection: float = 10.0, max_angle_deg: float = 30.0,
                           points: int = 5, comment: str = "written by diffsusp") -> str:
    """Write a linear A/Car bushing property file (mm, N, deg; the thesis's
    ``ecriture_bushing``): for each axis a `points`-row curve force = k·x over ±`max_deflection`
    mm (torques over ±`max_angle_deg`). `k_trans` in N/mm, `k_rot` in N·mm/rad. Returns the
    text; `read_bushing_property` gives back the stiffnesses."""
    k_trans = np.broadcast_to(np.asarray(k_trans, float), (3,))
    k_rot = np.broadcast_to(np.asarray(k_rot, float), (3,))
    if not (np.all(np.isfinite(k_trans)) and np.all(np.isfinite(k_rot))):
        raise ValueError("stiffnesses must be finite.")
    sections = [
        ("MDI_HEADER", {"FILE_TYPE": "bus", "FILE_VERSION": 4.0, "FILE_FORMAT": "ascii"}, [],
         {"COMMENTS": ({}, [TeimTable(("comment_string",), [[comment]], 0)])}),
        ("UNITS", {"LENGTH": "mm", "ANGLE": "deg", "FORCE": "newton", "MASS": "kg",
                   "TIME": "second"}, [], {}),
    ]
    for axis, name in _BUS_SECTIONS.items():
        a = "xyz".index(axis[1])
        if axis[0] == "t":
            x = np.linspace(-max_deflection, max_deflection, points)
            y = k_trans[a] * x
        else:
            x = np.linspace(-max_angle_deg, max_angle_deg, points)
            y = k_rot[a] * np.radians(x)
        col = "force" if axis[0] == "t" else "torque"
        sections.append((name, {}, [TeimTable((axis, col), np.c_[x, y].tolist(), 0)], {}))
    text = _write_teim(sections)
    if path is not None:
        Path(path).write_text(text)
    return text
