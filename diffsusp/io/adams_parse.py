"""The Adams dataset tokeniser: statements of an .adm file into an `AdmModel` (no
interpretation; `adams_plan` turns the statements into a `Mechanism`). The subset and its rules
are in the docstring of `diffsusp.io.adams`; spec: stiffness §4.1, §6 item 10. Reading never
executes anything from a file: statements are tokenised by regular expressions.
"""

import bisect
import dataclasses
import re
from pathlib import Path

import numpy as np
from jaxtyping import ArrayLike, Float

from ..model import Loads, Mechanism
from .adams_common import error, read_source

# ----------------------------------------------------------------------------- statements

SUPPORTED = ("UNITS", "PART", "MARKER", "JOINT", "JPRIM", "BUSHING", "SPRINGDAMPER", "SFORCE",
             "GFORCE", "VFORCE", "VTORQUE", "SPLINE", "MOTION", "GCON")
"""Statements read into the model."""

NO_STATIC_EFFECT = ("GRAPHICS", "OUTPUT", "RESULTS", "REQUEST", "MREQUEST", "EQUILIBRIUM", "IC",
                    "INTEGRATOR", "KINEMATICS", "DEBUG", "LIST", "NOLIST", "SENSOR", "STRING",
                    "PREFERENCES")
"""Statements with no effect on a static solution: recorded in `AdmModel.ignored`."""

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
            raise error(f"{keyword}: unexpected {text[pos]!r}; expected NAME = value or a "
                        "keyword such as GROUND.", path, line_at(pos))
        word = m.group().upper()
        after = _SPACE.match(text, m.end()).end()
        if after < n and text[after] == "=" and text[after + 1:after + 2] != "=":
            if word in arguments:
                raise error(f"{keyword}: argument {word} is given twice.", path, line_at(pos),
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
                    raise error(f"{keyword}: {word} = has no expression.", path,
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
                raise error(f"{keyword}: expected ',' after {word}.", path, line_at(nxt))
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
            raise error(f"{keyword}: {word} = has no value.", path, body.where(pos)[0], word)
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
            raise error(f"{keyword}: expected ',' after the value of {word}; got "
                        f"{text[nxt]!r}.", path, body.where(nxt)[0], word)
        cand = _SPACE.match(text, nxt + 1).end()
        m2 = token(cand, False)
        if m2 is None:
            return values, nxt
        m = m2


@dataclasses.dataclass
class AdmModel:
    """A parsed Adams dataset. `build(time)` makes the `Mechanism`; `loads(mech, times)` the
    GFORCE/VFORCE/VTORQUE/SFORCE loads and MOTION driver values at given times.

    **Fields:** `title`; `units` (FORCE, MASS, LENGTH, TIME as written); `length_to_mm`,
    `force_to_n` (conversion factors); `statements` (the active ones, in file order); `names`
    ((keyword, id) → adams_view_name); `splines` (id → `AdmSpline`); `skipped` (statements
    outside the subset, each with line and reason); `ignored` (statements without static
    effect); `inactive` ((line, text) of commented-out statements); `path`; `plan` (the
    statements interpreted as builder calls and load definitions, `adams_plan.AdmPlan`: set by
    `adams_plan.parse_adm`, None until then).
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
    plan: object = dataclasses.field(default=None, repr=False)

    # -- public API -----------------------------------------------------------------------

    def build(self, time: float = 0.0, *, check: bool = True) -> Mechanism:
        """The `Mechanism` (mm, N, N·mm, rad; the file's global frame; design position = the
        file's positions). Two-body SFORCE functions are evaluated at `time` (s)."""
        return self.plan.build(time, check)

    def loads(self, mech: Mechanism, times: float | Float[ArrayLike, " t"] = 0.0) -> Loads:
        """Loads of the file's external forces and motions at `times` (s).

        Each GFORCE/VFORCE/VTORQUE/action-only SFORCE is the load point of the same name in
        `mech` (N, N·mm in the load point's frame); each MOTION the driver of the same name (mm,
        measured from the design position). A scalar `times` gives one case; an array a leading
        case axis.
        """
        return self.plan.loads(mech, times)

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


_NUM = r"([-+]?(?:\d+\.?\d*|\.\d+)(?:E[-+]?\d+)?)"
_BUMP = re.compile(rf"{_NUM}\*MAX\(0,{_NUM}-DM\((\d+),(\d+)\)\)"
                   rf"(?:\+{_NUM}\*MAX\(0,\2-DM\(\3,\4\)\)\*\*3)?")
_REBOUND = re.compile(rf"-\({_NUM}\*MAX\(0,DM\((\d+),(\d+)\)-{_NUM}\)"
                      rf"(?:\+{_NUM}\*MAX\(0,DM\(\2,\3\)-\4\)\*\*3)?\)")


def stop_of_function(text: str) -> tuple[str, float, float, float, int, int] | None:
    """(kind, length, k, cubic, i, j) in file units if `text` is the FUNCTION of a one-sided
    stop as `diffsusp.io.adams_write.stop_function` writes it — ``k * MAX(0, L - DM(i, j))``
    (bump) or ``-(k * MAX(0, DM(i, j) - L))`` (rebound), each with an optional
    ``+ c * MAX(…)**3`` — else None (spaces and case free)."""
    t = re.sub(r"\s+", "", text).upper()
    m = _BUMP.fullmatch(t)
    if m:
        k, length, i, j, c = m.groups()
        return "bump", float(length), float(k), float(c or 0.0), int(i), int(j)
    m = _REBOUND.fullmatch(t)
    if m:
        k, i, j, length, c = m.groups()
        return "rebound", float(length), float(k), float(c or 0.0), int(i), int(j)
    return None


def spline_stiffness(spline: AdmSpline) -> float:
    """Stiffness K of a spline written Y = −K·X (file units): least squares through the origin,
    K = −Σxy / Σx² (spec stiffness §4.3: A/Car bushing splines, force on the I part)."""
    x, y = np.asarray(spline.x, float), np.asarray(spline.y, float)
    return float(-(x @ y) / (x @ x))


# ----------------------------------------------------------------------------- parse


def parse_statements(source) -> AdmModel:
    """Parse an Adams dataset (.adm) — a path, or the text itself — into an `AdmModel`.

    The statements outside the subset (see `diffsusp.io.adams`) are listed in
    `AdmModel.skipped`; `adams_plan.parse_adm` also warns of them. Raises `ModelFileError`
    (with the line) for a malformed statement, an unknown marker or part, a non-finite number.
    """
    text, path = read_source(source, "Adams dataset")
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
                raise error("a continuation line (starting with ',') has no statement before "
                            "it.", path, number)
            current[1].add(content[column:], number, column)
            current[3] = number
            continue
        m = _STATEMENT_START.match(content)
        if m is None:
            raise error(f"expected a statement (KEYWORD/id, ...) or a comment (!); got "
                        f"{stripped[:40]!r}.", path, number)
        keyword = m.group(1).upper()
        if keyword == "END" and m.group(2) == "":
            current = None
            break
        if m.group(2) != "/":
            raise error(f"expected '/' after the statement keyword {keyword}.", path, number)
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
    return model
