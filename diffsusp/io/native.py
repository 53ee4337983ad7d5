"""The native model file: a TOML serialisation of a `Mechanism` that a human can read and edit.

```toml
# Comments are allowed anywhere (and kept when diffsusp saves over the file).
diffsusp = 2                          # file format version
name = "isolated bushing"
parts = ["arm"]                       # moving parts; 'ground' always exists

[units]                               # every number below is in these units
length = "mm"
force = "N"
angle = "deg"

[markers.tip]
part = "arm"
position = [-300.0, 0.0, 0.0]         # global, at the design position (q = 0)

[bushings.bush]
parts = ["arm", "ground"]             # creates markers 'bush.i' (arm) and 'bush.j' (ground)
at = [0.0, 0.0, 0.0]
reuler = [28.18678543, 33.2259422, 350.8538915]
k_trans = 100.0                       # one value for the three axes, or [kx, ky, kz]
k_rot = [10000.0, 10000.0, 10000.0]   # force·length/angle: N·mm/deg here

[load_points.tip]
marker = "tip"
```

**Top level:** `diffsusp` (format version, 2 — version 1, without corners, is read too;
optional), `name` (optional; default the file
name), `parts` (required, at least one), `[units]` (required).

**Units** (`[units]`, all three keys required): `length` = mm | cm | m | in, `force` = N | daN
| kN | lbf, `angle` = rad | deg. Every number is converted on load to mm, N and rad:

| quantity | dimension | e.g. length = m, force = kN, angle = deg |
|---|---|---|
| positions, `at`, offsets `offset_trans`, spring `free_length`, stop `length` | length | m |
| REULER angles, `offset_rot`, rotational spline x | angle | deg |
| `k_trans`, spring `k`, stop `k` | force/length | kN/m |
| `k_rot` | force·length/angle | kN·m/deg |
| `cubic_trans`, stop `cubic` | force/length³ | kN/m³ |
| `cubic_rot` | force·length/angle³ | kN·m/deg³ |
| `preload_force`, translational spline y, spring table y | force | kN |
| `preload_torque`, rotational spline y | force·length | kN·m |
| spring table x (extension ℓ − free_length), translational spline x | length | m |
| axes (`axes`, `z`, `x`), driver `direction` | none (unit vectors) | — |
| load tables: `<point>.fx…fz` / `.mx…mz` / drivers | force / force·length / length | |

**Markers** (`[markers.<name>]`): `part` (a part or "ground"), `position` (global, design), and at
most one orientation: `axes = [[x axis], [y axis], [z axis]]` (global components: the columns
of the orientation matrix; orthonormal to 1e-9), `reuler = [ψ, θ, φ]` (Adams z-x-z), or `z`
(and optionally `x`, made perpendicular); default: the global axes.

**Joints** (`[joints.<name>]`): `kind` (spherical, revolute, cylindrical, translational,
universal, fixed, inline, inplane, perpendicular, distance), markers `i` and `j`, or
`parts = [I part, J part]` with `at` (and an orientation as for markers) to create coincident
markers `<name>.i`, `<name>.j`.

**Bushings** (`[bushings.<name>]`): markers as joints; `k_trans`, `k_rot` (required), `cubic_trans`,
`cubic_rot`, `offset_trans`, `offset_rot`, `preload_force`, `preload_torque` (default 0), each one
number or three (J frame); `[bushings.<name>.splines.<axis>]` with `x`, `y` (axis tx … rz; force on
I vs deformation, A/Car sign: y = −k·x for a linear law).

**Springs** (`[springs.<name>]`): markers `i`, `j` (or `parts` and `at = [[on I], [on J]]`);
linear `k`, `free_length`, or `[springs.<name>.table]` with `x` (extension), `y` (tension).

**Stops** (`[stops.<name>]`): markers as springs, `kind` = bump | rebound, `length`, `k`,
`cubic` (default 0).

**Drivers** (`[drivers.<name>]`): `marker` (or `part` and `at`), `direction` (default z).

**Load points** (`[load_points.<name>]`): `marker` (or `part` and `at`), `frame` (a marker: load
components in its axes; default global).

**Corners** (`[[corner]]`, format 2; one per wheel): which markers are the wheel
(`diffsusp.model.corner.Corner`): `wheel_centre` (marker), `contact_point` and
`wheel_centre_load` (load points; `false`: none), `kingpin = [upper, lower]` (each a marker or
`{part = "...", offset = [forward, outboard, up]}` from the wheel centre, length), `side`
(left | right | auto), `frame` (adams | iso), `loaded_radius` (length), `design_load` (force;
absent: the load that holds the design position, computed), `prefix` (in a combined axle).
Every key but `design_load` defaults to `Corner`'s default. A version-1 file has no corner.

**Load tables** (`[load_tables.<name>]`): `columns` (names as in `diffsusp.io.tables`, each
optionally with a unit: `"contact_patch.fz [kN]"`; without one, in the file's units) and `rows`
(one list of numbers per load case).

Reading never evaluates anything: strings are names, numbers are TOML numbers. Errors are
`ModelFileError`s naming the file, the line and the field, and saying what is expected.
Saving writes mm, N, rad and every float with the digits that read back to the same bits, so
save → load reproduces the mechanism exactly (orientations are written as `axes`, or as `z`
alone when that rebuilds the same matrix).

**Size.** About 1 100 lines: one file format, read and written both ways (every element kind
of a `Mechanism`, named load tables, units, comment-preserving saves), with line-numbered
errors for each field; reader and writer are kept side by side so they stay each other's
inverse.
"""

import dataclasses
import math
import os
import re
import tomllib

import numpy as np

from ..errors import ModelError, ModelFileError
from ..model import GROUND, Mechanism, MechanismBuilder
from ..model.mechanism import BUSHING_AXES, JOINT_ROWS
from .tables import Table, split_header, unit_factor

FORMAT_VERSION = 2
"""Version written: 2 adds the wheel corners (`[[corner]]`); version-1 files (no corner) are
still read."""
READ_VERSIONS = (1, 2)
MAX_MAGNITUDE = 1e15
"""Largest magnitude of any number in a model file, in mm, N and rad (beyond it a value is a
typo or a unit mistake, and products in the checks would overflow)."""

LENGTH_UNITS = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
FORCE_UNITS = {"N": 1.0, "daN": 10.0, "kN": 1000.0, "lbf": 4.4482216152605}
ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180.0}
_UNIT_TABLES = {"length": LENGTH_UNITS, "force": FORCE_UNITS, "angle": ANGLE_UNITS}
LIBRARY_UNITS = {"length": "mm", "force": "N", "angle": "rad"}

# Dimensions as exponents of (length, force, angle).
_NONE, _LEN, _ANG, _FORCE = (0, 0, 0), (1, 0, 0), (0, 0, 1), (0, 1, 0)
_TORQUE = (1, 1, 0)
_BUSHING_FIELDS = {
    "k_trans": (-1, 1, 0), "k_rot": (1, 1, -1),
    "cubic_trans": (-3, 1, 0), "cubic_rot": (1, 1, -3),
    "offset_trans": _LEN, "offset_rot": _ANG,
    "preload_force": _FORCE, "preload_torque": _TORQUE,
}
_ORIENTATION_KEYS = ("axes", "reuler", "z", "x")
_LOAD_COMPONENTS = ("fx", "fy", "fz", "mx", "my", "mz")
_TOP_KEYS = ("diffsusp", "name", "parts", "units", "markers", "joints", "bushings", "springs",
             "stops", "drivers", "load_points", "corner", "load_tables")
_CORNER_KEYS = ("prefix", "wheel_centre", "contact_point", "wheel_centre_load", "kingpin",
                "side", "frame", "loaded_radius", "design_load")


@dataclasses.dataclass(frozen=True, eq=False)
class ModelFile:
    """What a native model file holds: the mechanism, its named load tables (in library units
    unless a column states its own unit) and the units the file was written in."""

    mechanism: Mechanism
    load_tables: dict[str, Table]
    units: dict[str, str]
    path: str | None


# --------------------------------------------------------------------------------- locating


_BARE = r"[A-Za-z0-9_-]+"
_BASIC = r'"(?:[^"\\]|\\.)*"'
_LITERAL = r"'[^']*'"
_KEY = rf"(?:{_BARE}|{_BASIC}|{_LITERAL})"
_KEY_RE = re.compile(rf"\s*({_KEY})\s*")


def _split_keys(text: str) -> tuple[str, ...] | None:
    """Dotted TOML key → its parts (quotes removed), or None if it cannot be read."""
    keys, pos = [], 0
    while True:
        match = _KEY_RE.match(text, pos)
        if not match:
            return None
        raw = match.group(1)
        if raw[0] == '"':
            try:
                import json

                keys.append(json.loads(raw))
            except ValueError:
                return None
        elif raw[0] == "'":
            keys.append(raw[1:-1])
        else:
            keys.append(raw)
        pos = match.end()
        if pos == len(text):
            return tuple(keys)
        if text[pos] != ".":
            return None
        pos += 1


class _Source:
    """The text of a file, to find the line of a key path for error messages."""

    _HEADER_RE = re.compile(r"^\s*\[\[?\s*(.*?)\s*\]\]?\s*(?:#.*)?$")

    def __init__(self, text: str, path):
        self.path = path
        self.lines = text.splitlines()
        self.headers: list[tuple[int, tuple[str, ...]]] = [(0, ())]
        for n, raw in enumerate(self.lines):
            if raw.lstrip().startswith("["):
                match = self._HEADER_RE.match(raw)
                keys = _split_keys(match.group(1)) if match else None
                if keys is not None:
                    self.headers.append((n, keys))

    def line(self, keys: tuple[str, ...]) -> int:
        """1-based line of the deepest part of `keys` found in the text (1 if none)."""
        for depth in range(len(keys), -1, -1):
            prefix = keys[:depth]
            for h, (start, header) in enumerate(self.headers):
                if header != prefix:
                    continue
                end = self.headers[h + 1][0] if h + 1 < len(self.headers) else len(self.lines)
                rest = keys[depth:]
                if rest:
                    found = self._key_line(start + (h > 0), end, rest)
                    if found is not None:
                        return found
                if depth > 0:
                    return start + 1
            # A table defined only through deeper headers ([a.b] defines a).
            for start, header in self.headers[1:]:
                if depth > 0 and header[:depth] == prefix:
                    return start + 1
        return 1

    def _key_line(self, start, end, rest) -> int | None:
        for n in range(start, end):
            raw = self.lines[n]
            match = re.match(rf"\s*({_KEY}(?:\s*\.\s*{_KEY})*)\s*=", raw)
            if not match:
                continue
            keys = _split_keys(match.group(1))
            if keys and tuple(keys[: len(rest)]) == tuple(rest[: len(keys)]):
                return n + 1
        return None

    def error(self, message: str, keys: tuple[str, ...], *, line: int | None = None):
        return ModelFileError(message, path=self.path, line=line or self.line(keys),
                              field=".".join(keys) if keys else None)


# --------------------------------------------------------------------------------- values


class _Reader:
    """Typed access to the parsed document, with unit conversion and located errors."""

    def __init__(self, source: _Source, units: dict[str, float]):
        self.src = source
        self.units = units

    def factor(self, dims) -> float:
        f = 1.0
        for name, e in zip(("length", "force", "angle"), dims, strict=True):
            if e:
                f *= self.units[name] ** e
        return f

    def table(self, value, keys, what: str) -> dict:
        if not isinstance(value, dict):
            raise self.src.error(f"expected a table ({what}); got {_kind(value)}.", keys)
        return value

    def keys(self, table: dict, keys, allowed, required=()):
        unknown = [k for k in table if k not in allowed]
        if unknown:
            raise self.src.error(
                f"unknown key '{unknown[0]}'; allowed keys here: {', '.join(allowed)}.",
                (*keys, unknown[0]),
            )
        for k in required:
            if k not in table:
                raise self.src.error(f"missing required key '{k}'.", keys)

    def string(self, value, keys, what="a name") -> str:
        if not isinstance(value, str):
            raise self.src.error(f"expected a string ({what}); got {_kind(value)}.", keys)
        return value

    def number(self, value, keys, dims=_NONE, *, convert=True) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.src.error(f"expected a number; got {_kind(value)}.", keys)
        try:
            x = float(value)
        except OverflowError:
            x = math.inf
        if not math.isfinite(x):
            raise self.src.error(f"expected a finite number; got {value}.", keys)
        f = self.factor(dims) if convert else 1.0
        x = x * f if f != 1.0 else x
        if abs(x) > MAX_MAGNITUDE:
            raise self.src.error(
                f"{value} is out of range (|value| ≤ {MAX_MAGNITUDE:g} in mm, N, rad); check "
                "the number and the [units].", keys)
        return x

    def vector(self, value, keys, dims=_NONE, *, scalar=False, convert=True) -> np.ndarray:
        if scalar and not isinstance(value, list):
            return np.full(3, self.number(value, keys, dims, convert=convert))
        if not isinstance(value, list) or len(value) != 3:
            what = "a number or a list of 3 numbers" if scalar else "a list of 3 numbers"
            raise self.src.error(f"expected {what}; got {_kind(value)}.", keys)
        return np.array([self.number(v, keys, dims, convert=convert) for v in value])

    def numbers(self, value, keys, dims=_NONE) -> np.ndarray:
        if not isinstance(value, list) or len(value) < 2:
            raise self.src.error(f"expected a list of at least 2 numbers; got {_kind(value)}.",
                                 keys)
        return np.array([self.number(v, keys, dims) for v in value])

    def xy(self, value, keys, dims_x, dims_y):
        table = self.table(value, keys, "with x and y lists")
        self.keys(table, keys, ("x", "y"), ("x", "y"))
        return (self.numbers(table["x"], (*keys, "x"), dims_x),
                self.numbers(table["y"], (*keys, "y"), dims_y))


def _kind(value) -> str:
    if isinstance(value, bool):
        return f"a boolean ({str(value).lower()})"
    if isinstance(value, int | float):
        return f"the number {value}"
    if isinstance(value, str):
        shown = value if len(value) <= 40 else value[:37] + "..."
        return f"the string {shown!r}"
    if isinstance(value, list):
        return f"a list of {len(value)} items"
    if isinstance(value, dict):
        return "a table"
    return type(value).__name__


# --------------------------------------------------------------------------------- reading


def read_model_toml(path, *, check: bool = True) -> ModelFile:
    """Read a native model file (see the module docstring).

    **Arguments:** `path`; `check`: validate the model at build (joints assembled, no free
    mode; see `MechanismBuilder.build`).

    **Returns:** a `ModelFile` (`mechanism`, `load_tables`, `units`).

    **Raises:** `ModelFileError` (file, line, field) for anything the file gets wrong;
    `ModelError` for a model that is well written but cannot be solved (free modes, joints not
    assembled at design); `FileNotFoundError` if there is no file.
    """
    from .files import read_input

    data = read_input(path, "model file")
    return model_from_toml(data, path=str(path), check=check)


def model_from_toml(data: str | bytes, *, path=None, check: bool = True) -> ModelFile:
    """Parse the text (or UTF-8 bytes) of a native model file; see `read_model_toml`."""
    import tomlkit
    from tomlkit.exceptions import ParseError

    if isinstance(data, bytes):
        try:
            text = data.decode("utf-8-sig")
        except UnicodeDecodeError as e:
            raise ModelFileError(
                f"byte {data[e.start]:#04x} is not UTF-8 text; save the file as UTF-8.",
                path=path, line=data[: e.start].count(b"\n") + 1,
            ) from None
    else:
        text = data
    if "\x00" in text:
        # tomlkit reads NUL as its end-of-text mark (a truncated or zero-filled file).
        nul = text.index("\x00")
        raise ModelFileError(
            "the file holds a NUL byte (a truncated or damaged file?); a model file is text.",
            path=path, line=text.count("\n", 0, nul) + 1)
    try:
        # The standard library's parser is linear and ~10x faster than tomlkit; tomlkit (kept for
        # writing with comments) is asked only for the message of a small malformed file.
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        doc = None
        fast_error = e
    except RecursionError:
        raise ModelFileError("not valid TOML: values nested too deeply.", path=path,
                             line=1) from None
    if doc is not None:
        src = _Source(text, path)
        return _build(doc, src, path, check)
    if len(text) > _TOMLKIT_MESSAGE_SIZE:
        message = re.sub(r"\s*\(at line \d+, column \d+\)$", "", str(fast_error))
        match = re.search(r"line (\d+)", str(fast_error))
        raise ModelFileError(f"not valid TOML: {message}.", path=path,
                             line=int(match.group(1)) if match else 1) from None
    try:
        doc = tomlkit.parse(text).unwrap()
    except ParseError as e:
        if "\\x00" in str(e) or "\x00" in str(e):
            # tomlkit's end-of-text mark: the file ends inside a value or a header.
            message = re.sub(r"\s*\(at end of document\)$", "", str(fast_error))
            raise ModelFileError(f"not valid TOML: the file ends early ({message}); is it "
                                 "truncated?", path=path,
                                 line=max(text.count("\n") + (not text.endswith("\n")), 1)
                                 ) from None
        raise ModelFileError(f"not valid TOML: {e}.", path=path,
                             line=max(int(e.line), 1)) from None
    except RecursionError:
        raise ModelFileError("not valid TOML: values nested too deeply.", path=path,
                             line=1) from None
    except Exception as e:  # tomlkit raises a few other types on malformed input
        raise ModelFileError(f"not valid TOML ({type(e).__name__}: {e}).", path=path,
                             line=_guess_line(text, e)) from None
    # tomlkit accepted what tomllib refused (they differ on a few corner cases): refuse it.
    match = re.search(r"line (\d+)", str(fast_error))
    raise ModelFileError(f"not valid TOML: {fast_error}.", path=path,
                         line=int(match.group(1)) if match else 1)


_TOMLKIT_MESSAGE_SIZE = 1 << 18
"""Largest malformed file (characters) whose error message is taken from tomlkit (slow, but
its messages are the ones users know from editors); larger files get tomllib's."""


def _guess_line(text: str, error: Exception) -> int:
    """Line of a tomlkit error that does not carry one (a duplicate key): ask the standard
    library's parser, whose messages end with '(at line N, column M)'."""
    import tomllib

    line = getattr(error, "line", None)
    if isinstance(line, int) and line >= 1:
        return line
    try:
        tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        match = re.search(r"line (\d+)", str(e))
        if match:
            return int(match.group(1))
    except Exception:  # noqa: S110 - only a hint for the message
        pass
    return 1


def _build(doc: dict, src: _Source, path, check: bool) -> ModelFile:
    unknown = [k for k in doc if k not in _TOP_KEYS]
    if unknown:
        raise src.error(
            f"unknown key or section '{unknown[0]}'; a model file has: {', '.join(_TOP_KEYS)}.",
            (unknown[0],),
        )
    version = FORMAT_VERSION
    if "diffsusp" in doc:
        version = doc["diffsusp"]
        if isinstance(version, bool) or version not in READ_VERSIONS:
            raise src.error(
                f"format version {version!r} is not supported; this diffsusp reads "
                f"diffsusp = {' or '.join(map(str, READ_VERSIONS))}.", ("diffsusp",))
    if "corner" in doc and version < 2:
        raise src.error("[[corner]] tables need format version 2: write diffsusp = 2 (a "
                        "version-1 file states no wheel corner).", ("corner",))
    units, factors = _units(doc, src)
    rd = _Reader(src, factors)
    name = doc.get("name")
    if name is None:
        name = os.path.splitext(os.path.basename(str(path)))[0] if path else "mechanism"
    b = MechanismBuilder(rd.string(name, ("name",), "the model name"))

    if "parts" not in doc:
        raise src.error("missing 'parts': list the moving parts, e.g. parts = [\"arm\"].", ())
    parts = doc["parts"]
    if not isinstance(parts, list) or not parts:
        raise src.error(f"'parts' must be a non-empty list of part names; got {_kind(parts)}.",
                        ("parts",))
    with _located(src, ("parts",)):
        for p in parts:
            b.part(rd.string(p, ("parts",), "a part name"))

    def section(key):
        value = doc.get(key, {})
        rd.table(value, (key,), f"[{key}.<name>] tables")
        for item_name, item in value.items():
            keys = (key, item_name)
            yield item_name, rd.table(item, keys, f"the {key[:-1].replace('_', ' ')} "
                                                  f"'{item_name}'"), keys

    for m_name, m, keys in section("markers"):
        rd.keys(m, keys, ("part", "position", *_ORIENTATION_KEYS), ("part", "position"))
        part = rd.string(m["part"], (*keys, "part"), "a part name or 'ground'")
        position = rd.vector(m["position"], (*keys, "position"), _LEN)
        with _located(src, keys):
            b.marker(m_name, part, position, **_orientation(rd, m, keys))

    for j_name, j, keys in section("joints"):
        rd.keys(j, keys, ("kind", "i", "j", "parts", "at", *_ORIENTATION_KEYS), ("kind",))
        kind = rd.string(j["kind"], (*keys, "kind"), "a joint kind")
        if kind not in JOINT_ROWS:
            raise src.error(f"unknown joint kind '{kind}'; use one of {', '.join(JOINT_ROWS)}.",
                            (*keys, "kind"))
        with _located(src, keys):
            b.joint(j_name, kind, **_pair(rd, j, keys, oriented=True))

    for b_name, e, keys in section("bushings"):
        rd.keys(e, keys, ("i", "j", "parts", "at", *_ORIENTATION_KEYS, *_BUSHING_FIELDS,
                          "splines"), ("k_trans", "k_rot"))
        values = {f: rd.vector(e[f], (*keys, f), dims, scalar=True)
                  for f, dims in _BUSHING_FIELDS.items() if f in e}
        splines = {}
        if "splines" in e:
            sp = rd.table(e["splines"], (*keys, "splines"), "[...splines.<axis>] tables")
            rd.keys(sp, (*keys, "splines"), BUSHING_AXES)
            for axis, table in sp.items():
                rot = axis.startswith("r")
                splines[axis] = rd.xy(table, (*keys, "splines", axis), _ANG if rot else _LEN,
                                      _TORQUE if rot else _FORCE)
        with _located(src, keys):
            b.bushing(b_name, **_pair(rd, e, keys, oriented=True), **values,
                      splines=splines or None)

    for s_name, s, keys in section("springs"):
        rd.keys(s, keys, ("i", "j", "parts", "at", "k", "free_length", "table"))
        kw = {}
        if "k" in s:
            kw["k"] = rd.number(s["k"], (*keys, "k"), (-1, 1, 0))
        if "free_length" in s:
            kw["free_length"] = rd.number(s["free_length"], (*keys, "free_length"), _LEN)
        if "table" in s:
            kw["table"] = rd.xy(s["table"], (*keys, "table"), _LEN, _FORCE)
        elif "k" not in s or "free_length" not in s:
            raise src.error("a spring needs k and free_length, or a [table] with x and y.", keys)
        with _located(src, keys):
            b.spring(s_name, **_pair(rd, s, keys, oriented=False), **kw)

    for s_name, s, keys in section("stops"):
        rd.keys(s, keys, ("i", "j", "parts", "at", "kind", "length", "k", "cubic"),
                ("length", "k"))
        kw = dict(
            kind=rd.string(s.get("kind", "bump"), (*keys, "kind"), "'bump' or 'rebound'"),
            length=rd.number(s["length"], (*keys, "length"), _LEN),
            k=rd.number(s["k"], (*keys, "k"), (-1, 1, 0)),
            cubic=rd.number(s.get("cubic", 0.0), (*keys, "cubic"), (-3, 1, 0)),
        )
        with _located(src, keys):
            b.stop(s_name, **_pair(rd, s, keys, oriented=False), **kw)

    exact_directions = {}
    for d_name, d, keys in section("drivers"):
        rd.keys(d, keys, ("marker", "part", "at", "direction"))
        kw = _point(rd, d, keys)
        direction = np.array([0.0, 0.0, 1.0])
        if "direction" in d:
            direction = rd.vector(d["direction"], (*keys, "direction"))
            norm = float(np.linalg.norm(direction))
            if not norm > 0:
                raise src.error("direction must be a non-zero vector.", (*keys, "direction"))
            if abs(norm - 1.0) <= 4 * np.finfo(float).eps:
                exact_directions[d_name] = direction  # already unit: keep its exact bits
        with _located(src, keys):
            b.driver(d_name, **kw, direction=direction)

    for l_name, lp, keys in section("load_points"):
        rd.keys(lp, keys, ("marker", "part", "at", "frame"))
        kw = _point(rd, lp, keys)
        frame = rd.string(lp["frame"], (*keys, "frame"), "a marker name") if "frame" in lp \
            else None
        with _located(src, keys):
            b.load_point(l_name, **kw, frame=frame)

    corners = doc.get("corner", [])
    if not isinstance(corners, list) or not all(isinstance(c, dict) for c in corners):
        raise src.error("corner must be [[corner]] tables (one per wheel).", ("corner",))
    for c in corners:
        with _located(src, ("corner",)):
            b.corner(_read_corner(rd, c, ("corner",)))

    try:
        mech = b.build(check=check)
    except ValueError as e:
        # Well written but not solvable as given (joints not assembled, free modes): still a
        # file error located at the element it names, but the CLI exits with 4, not 2.
        error = src.error(str(e), _named_in(str(e), doc))
        error.bad_input = False
        raise error from None
    if exact_directions:
        direction = np.array(mech.drivers.direction)
        for d_name, vec in exact_directions.items():
            direction[mech.drivers.names.index(d_name)] = vec
        import jax.numpy as jnp

        mech = dataclasses.replace(
            mech, drivers=dataclasses.replace(mech.drivers, direction=jnp.asarray(direction)))

    tables = {}
    for t_name, t, keys in section("load_tables"):
        tables[t_name] = _load_table(rd, mech, t, keys, units)
    return ModelFile(mechanism=mech, load_tables=tables, units=units, path=path)


def _named_in(message: str, doc: dict) -> tuple[str, ...]:
    """Key path of the first element or part named in quotes in a builder message."""
    for name in re.findall(r"'([^']+)'", message):
        for section in ("joints", "bushings", "springs", "stops", "drivers", "load_points",
                        "markers"):
            if isinstance(doc.get(section), dict) and name in doc[section]:
                return (section, name)
        if isinstance(doc.get("parts"), list) and name in doc["parts"]:
            return ("parts",)
    return ()


class _located:
    """Turn the builder's errors into ModelFileErrors at the element's line."""

    def __init__(self, src: _Source, keys):
        self.src, self.keys = src, keys

    def __enter__(self):
        return self

    def __exit__(self, kind, value, tb):
        if kind is not None and issubclass(kind, ValueError) and not isinstance(
            value, ModelFileError
        ):
            raise self.src.error(f"{value}", self.keys) from None
        return False


def _units(doc, src: _Source):
    if "units" not in doc:
        raise src.error(
            "missing [units]: declare the file's units, e.g. [units] length = \"mm\", "
            "force = \"N\", angle = \"rad\".", ())
    u = doc["units"]
    if not isinstance(u, dict):
        raise src.error(f"[units] must be a table; got {_kind(u)}.", ("units",))
    unknown = [k for k in u if k not in _UNIT_TABLES]
    if unknown:
        raise src.error(f"unknown unit '{unknown[0]}'; [units] has length, force and angle.",
                        ("units", unknown[0]))
    units, factors = {}, {}
    for key, table in _UNIT_TABLES.items():
        if key not in u:
            raise src.error(f"[units] is missing '{key}' (one of {', '.join(table)}).",
                            ("units",))
        value = u[key]
        if not isinstance(value, str) or value not in table:
            raise src.error(f"unknown {key} unit {value!r}; use one of {', '.join(table)}.",
                            ("units", key))
        units[key], factors[key] = value, table[value]
    return units, factors


def _orientation(rd: _Reader, m: dict, keys) -> dict:
    given = [k for k in ("axes", "reuler", "z") if k in m]
    if "x" in m and "z" not in m:
        raise rd.src.error("'x' needs 'z' (the x axis is made perpendicular to z).",
                           (*keys, "x"))
    if len(given) > 1:
        raise rd.src.error(
            f"give one orientation: {' or '.join(given)}, not both (axes = [[x], [y], [z]], "
            "reuler = [psi, theta, phi], or z = [...] with an optional x).", (*keys, given[1]))
    if "axes" in m:
        axes = m["axes"]
        if not isinstance(axes, list) or len(axes) != 3:
            raise rd.src.error(f"axes must be [[x axis], [y axis], [z axis]]; got {_kind(axes)}.",
                               (*keys, "axes"))
        cols = [rd.vector(a, (*keys, "axes")) for a in axes]
        return dict(orientation=np.column_stack(cols))
    if "reuler" in m:
        angles = rd.vector(m["reuler"], (*keys, "reuler"), _ANG, convert=False)
        if rd.units["angle"] == ANGLE_UNITS["deg"]:
            return dict(reuler_deg=angles)
        from ..geometry import reuler_to_matrix

        return dict(orientation=np.asarray(reuler_to_matrix(angles * rd.factor(_ANG))))
    if "z" in m:
        z = rd.vector(m["z"], (*keys, "z"))
        x = rd.vector(m["x"], (*keys, "x")) if "x" in m else None
        return dict(z=z, x=x)
    return {}


def _pair(rd: _Reader, e: dict, keys, *, oriented: bool) -> dict:
    if "parts" in e:
        if "i" in e or "j" in e:
            raise rd.src.error("give markers i and j, or parts with at, not both.",
                               (*keys, "parts"))
        parts = e["parts"]
        if not isinstance(parts, list) or len(parts) != 2:
            raise rd.src.error(f"parts must be [I part, J part]; got {_kind(parts)}.",
                               (*keys, "parts"))
        parts = [rd.string(p, (*keys, "parts"), "a part name") for p in parts]
        if "at" not in e:
            raise rd.src.error("parts needs at = [x, y, z], the location of the markers.", keys)
        at = e["at"]
        if oriented:
            at = rd.vector(at, (*keys, "at"), _LEN)
            return dict(parts=parts, at=at, **_orientation(rd, e, keys))
        if isinstance(at, list) and len(at) == 2 and all(isinstance(a, list) for a in at):
            at = np.stack([rd.vector(a, (*keys, "at"), _LEN) for a in at])
        else:
            raise rd.src.error(
                f"at must be [[point on I], [point on J]]; got {_kind(at)}.", (*keys, "at"))
        _no_orientation(rd, e, keys)
        return dict(parts=parts, at=at)
    for k in ("i", "j"):
        if k not in e:
            raise rd.src.error(f"missing marker '{k}' (or give parts and at).", keys)
    if "at" in e:
        raise rd.src.error("'at' goes with 'parts'; with markers i and j, remove it.",
                           (*keys, "at"))
    _no_orientation(rd, e, keys)
    return dict(i=rd.string(e["i"], (*keys, "i"), "a marker name"),
                j=rd.string(e["j"], (*keys, "j"), "a marker name"))


def _no_orientation(rd, e, keys):
    for k in _ORIENTATION_KEYS:
        if k in e:
            raise rd.src.error(
                f"'{k}' is only read with parts and at (markers i and j carry their own "
                "orientation).", (*keys, k))


def _read_corner(rd: _Reader, c: dict, keys):
    """A `[[corner]]` table → `Corner`: every key optional with `Corner`'s defaults, except
    `design_load` (absent: computed, the load that holds the design position);
    `wheel_centre_load = false` for none; `kingpin` two points, each a marker name or
    {part = "...", offset = [forward, outboard, up]} (length units)."""
    from ..model.corner import Corner

    rd.keys(c, keys, _CORNER_KEYS)
    kw = {}
    for key in ("prefix", "wheel_centre", "contact_point", "side", "frame"):
        if key in c:
            kw[key] = rd.string(c[key], (*keys, key), "a name")
    if "wheel_centre_load" in c:
        value = c["wheel_centre_load"]
        kw["wheel_centre_load"] = None if value is False else rd.string(
            value, (*keys, "wheel_centre_load"), "a load point name or false")
    if "kingpin" in c:
        refs = c["kingpin"]
        if not isinstance(refs, list) or len(refs) != 2:
            raise rd.src.error(f"kingpin must be two points [upper, lower]; got {_kind(refs)}.",
                               (*keys, "kingpin"))
        points = []
        for ref in refs:
            if isinstance(ref, dict):
                rd.keys(ref, (*keys, "kingpin"), ("part", "offset"), ("part", "offset"))
                points.append((rd.string(ref["part"], (*keys, "kingpin"), "a part name"),
                               tuple(float(v) for v in rd.vector(ref["offset"],
                                                                 (*keys, "kingpin"), _LEN))))
            else:
                points.append(rd.string(ref, (*keys, "kingpin"), "a marker name or "
                                        "{part, offset}"))
        kw["kingpin"] = tuple(points)
    if "loaded_radius" in c:
        kw["loaded_radius"] = rd.number(c["loaded_radius"], (*keys, "loaded_radius"), _LEN)
    kw["design_load"] = (rd.number(c["design_load"], (*keys, "design_load"), _FORCE)
                         if "design_load" in c else None)
    try:
        return Corner(**kw)
    except ValueError as e:
        raise rd.src.error(str(e), keys) from None


def _write_corners(doc, mech, put, factor):
    import tomlkit

    corners = tomlkit.aot()
    for c in mech.corners:
        t = tomlkit.table()
        if c.prefix:
            t.add("prefix", c.prefix)
        t.add("wheel_centre", c.wheel_centre)
        t.add("contact_point", c.contact_point)
        t.add("wheel_centre_load", False if c.wheel_centre_load is None else c.wheel_centre_load)
        if c.kingpin is not None:
            refs = tomlkit.array()
            for ref in c.kingpin:
                if isinstance(ref, str):
                    refs.append(ref)
                else:
                    it = tomlkit.inline_table()
                    it.add("part", ref[0])
                    it.add("offset", _floats(ref[1], factor(_LEN)))
                    refs.append(it)
            t.add("kingpin", refs)
            t["kingpin"].comment("steering axis [upper, lower]: markers or {part, offset = "
                                 "[forward, outboard, up] from the wheel centre}")
        t.add("side", c.side)
        t.add("frame", c.frame)
        put(t, "loaded_radius", c.loaded_radius, _LEN, vector=False)
        if c.design_load is not None:
            put(t, "design_load", c.design_load, _FORCE, vector=False)
        corners.append(t)
    doc.add("corner", corners)


def _point(rd: _Reader, e: dict, keys) -> dict:
    if "marker" in e:
        if "part" in e or "at" in e:
            raise rd.src.error("give a marker, or part with at, not both.", (*keys, "marker"))
        return dict(marker=rd.string(e["marker"], (*keys, "marker"), "a marker name"))
    if "part" not in e or "at" not in e:
        raise rd.src.error("missing 'marker' (or 'part' and 'at').", keys)
    return dict(part=rd.string(e["part"], (*keys, "part"), "a part name"),
                at=rd.vector(e["at"], (*keys, "at"), _LEN))


_DIMENSION_OF_COLUMN = {"force": _FORCE, "moment": _TORQUE, "length": _LEN}


def _load_table(rd: _Reader, mech: Mechanism, t: dict, keys, units) -> Table:
    from .tables import load_columns

    rd.keys(t, keys, ("columns", "rows"), ("columns", "rows"))
    columns = t["columns"]
    if not isinstance(columns, list) or not columns:
        raise rd.src.error(f"columns must be a list of column names; got {_kind(columns)}.",
                           (*keys, "columns"))
    valid = load_columns(mech) | {"case": "dimensionless"}
    names, col_units = [], {}
    for c in columns:
        name, unit = split_header(rd.string(c, (*keys, "columns"), "a column name"))
        if name not in valid:
            raise rd.src.error(
                f"unknown column '{name}' for this model; valid columns: {', '.join(valid)}.",
                (*keys, "columns"))
        if name in col_units:
            raise rd.src.error(f"column '{name}' appears twice.", (*keys, "columns"))
        if unit is not None:
            try:
                unit_factor(unit, valid[name])
            except ValueError as e:
                raise rd.src.error(f"column '{name}': {e}.", (*keys, "columns")) from None
        names.append(name)
        col_units[name] = unit
    rows = t["rows"]
    if not isinstance(rows, list):
        raise rd.src.error(f"rows must be a list of rows; got {_kind(rows)}.", (*keys, "rows"))
    values = np.empty((len(rows), len(names)))
    for r, row in enumerate(rows):
        if not isinstance(row, list) or len(row) != len(names):
            raise rd.src.error(
                f"row {r + 1} must be a list of {len(names)} numbers (one per column); got "
                f"{_kind(row)}.", (*keys, "rows"))
        for c, v in enumerate(row):
            values[r, c] = rd.number(v, (*keys, "rows"), convert=False)
    out_units = {}
    for c, name in enumerate(names):
        unit = col_units[name]
        if unit is None and name != "case":
            dims = _DIMENSION_OF_COLUMN[valid[name]]
            f = rd.factor(dims)
            if f != 1.0:
                values[:, c] *= f
            unit = {"force": "N", "moment": "N·mm", "length": "mm"}[valid[name]]
        out_units[name] = unit
    return Table(columns={n: values[:, c].copy() for c, n in enumerate(names)},
                 units=out_units, path=rd.src.path)


# --------------------------------------------------------------------------------- writing


def _unit_text(dims, units: dict[str, str]) -> str:
    num, den = [], []
    for key, e in zip(("length", "force", "angle"), dims, strict=True):
        if e == 0:
            continue
        sym = units[key] + (f"^{abs(e)}" if abs(e) > 1 else "")
        (num if e > 0 else den).append(sym)
    num.sort(key=lambda s: s[0] not in "NkdlM")  # force first: N·mm
    text = "·".join(num) or "1"
    return text + ("/" + "·".join(den) if den else "")


def _floats(values, factor: float = 1.0) -> list:
    arr = np.asarray(values, dtype=float).ravel()
    if factor != 1.0:
        arr = arr / factor
    return [float(v) for v in arr]


def _is_zero(values) -> bool:
    arr = np.asarray(values, dtype=float)
    return bool(np.all(arr == 0) and not np.any(np.signbit(arr)))


def model_to_toml(mech: Mechanism, *, load_tables: dict | None = None,
                  units: dict | None = None, source: str | None = None):
    """A native model file for `mech`, as a tomlkit document (`tomlkit.dumps` gives the text).

    **Arguments:** `load_tables`: name → `Table` (or mapping column → values, library units)
    written as `[load_tables.<name>]`; `units`: the file's units (default mm, N, rad: exact);
    `source`: a line for the header comment (where the model comes from).
    """
    import tomlkit

    units = dict(LIBRARY_UNITS, **(units or {}))
    for key, value in units.items():
        if key not in _UNIT_TABLES or value not in _UNIT_TABLES[key]:
            raise ValueError(f"units: unknown {key} unit {value!r}.")
    fac = {k: _UNIT_TABLES[k][v] for k, v in units.items()}

    def factor(dims):
        f = 1.0
        for key, e in zip(("length", "force", "angle"), dims, strict=True):
            if e:
                f *= fac[key] ** e
        return f

    def put(table, key, values, dims, *, vector=True, comment=True):
        data = _floats(values, factor(dims))
        table.add(key, data if vector else data[0])
        if comment and dims != _NONE:
            table[key].comment(_unit_text(dims, units))

    doc = tomlkit.document()
    doc.add(tomlkit.comment(f"{mech.name}: diffsusp model file (format {FORMAT_VERSION})."))
    if source:
        doc.add(tomlkit.comment(source))
    doc.add(tomlkit.comment("Positions are global at the design position (q = 0), in [units]; "
                            "see diffsusp.io.native for the format."))
    doc.add("diffsusp", FORMAT_VERSION)
    doc.add("name", mech.name)
    doc.add("parts", list(mech.parts))
    doc["parts"].comment("moving parts; 'ground' always exists")
    ut = tomlkit.table()
    for key in ("length", "force", "angle"):
        ut.add(key, units[key])
    doc.add("units", ut)

    names = mech.markers.names
    part_name = ["ground" if p == GROUND else mech.parts[p] for p in mech.markers.part]
    pos = np.asarray(mech.markers.position)
    rot = np.asarray(mech.markers.orientation)
    markers = tomlkit.table(is_super_table=True)
    for k, name in enumerate(names):
        m = tomlkit.table()
        m.add("part", part_name[k])
        put(m, "position", pos[k], _LEN)
        _write_orientation(m, rot[k])
        markers.add(name, m)
    doc.add("markers", markers)

    if mech.joints.names:
        joints = tomlkit.table(is_super_table=True)
        for e, name in enumerate(mech.joints.names):
            j = tomlkit.table()
            j.add("kind", mech.joints.kind[e])
            j.add("i", names[mech.joints.i_marker[e]])
            j.add("j", names[mech.joints.j_marker[e]])
            joints.add(name, j)
        doc.add("joints", joints)

    bu = mech.bushings
    if bu.names:
        bushings = tomlkit.table(is_super_table=True)
        for e, name in enumerate(bu.names):
            t = tomlkit.table()
            t.add("i", names[bu.i_marker[e]])
            t.add("j", names[bu.j_marker[e]])
            for field, dims in _BUSHING_FIELDS.items():
                value = np.asarray(getattr(bu, field))[e]
                if field in ("k_trans", "k_rot") or not _is_zero(value):
                    put(t, field, value, dims)
            if any(bu.spline_axes[e]):
                splines = tomlkit.table(is_super_table=True)
                sx, sy = np.asarray(bu.spline_x)[e], np.asarray(bu.spline_y)[e]
                for a, axis in enumerate(BUSHING_AXES):
                    if bu.spline_axes[e][a]:
                        rot_axis = axis.startswith("r")
                        st = tomlkit.table()
                        put(st, "x", sx[a], _ANG if rot_axis else _LEN)
                        put(st, "y", sy[a], _TORQUE if rot_axis else _FORCE)
                        splines.add(axis, st)
                t.add("splines", splines)
            bushings.add(name, t)
        doc.add("bushings", bushings)

    sp = mech.springs
    if sp.names:
        springs = tomlkit.table(is_super_table=True)
        k, free = np.asarray(sp.k), np.asarray(sp.free_length)
        for e, name in enumerate(sp.names):
            t = tomlkit.table()
            t.add("i", names[sp.i_marker[e]])
            t.add("j", names[sp.j_marker[e]])
            if not sp.tabulated[e] or not _is_zero(k[e]):
                put(t, "k", k[e], (-1, 1, 0), vector=False)
            if not sp.tabulated[e] or not _is_zero(free[e]):
                put(t, "free_length", free[e], _LEN, vector=False)
            if sp.tabulated[e]:
                tt = tomlkit.table()
                put(tt, "x", np.asarray(sp.table_x)[e], _LEN)
                put(tt, "y", np.asarray(sp.table_y)[e], _FORCE)
                t.add("table", tt)
            springs.add(name, t)
        doc.add("springs", springs)

    st = mech.stops
    if st.names:
        stops = tomlkit.table(is_super_table=True)
        for e, name in enumerate(st.names):
            t = tomlkit.table()
            t.add("i", names[st.i_marker[e]])
            t.add("j", names[st.j_marker[e]])
            t.add("kind", st.kind[e])
            put(t, "length", np.asarray(st.length)[e], _LEN, vector=False)
            put(t, "k", np.asarray(st.k)[e], (-1, 1, 0), vector=False)
            cubic = np.asarray(st.cubic)[e]
            if not _is_zero(cubic):
                put(t, "cubic", cubic, (-3, 1, 0), vector=False)
            stops.add(name, t)
        doc.add("stops", stops)

    dr = mech.drivers
    if dr.names:
        drivers = tomlkit.table(is_super_table=True)
        for e, name in enumerate(dr.names):
            t = tomlkit.table()
            t.add("marker", names[dr.marker[e]])
            t.add("direction", _floats(np.asarray(dr.direction)[e]))
            t["direction"].comment("global unit vector; the value (travel) is in length units")
            drivers.add(name, t)
        doc.add("drivers", drivers)

    lp = mech.load_points
    if lp.names:
        points = tomlkit.table(is_super_table=True)
        for e, name in enumerate(lp.names):
            t = tomlkit.table()
            t.add("marker", names[lp.marker[e]])
            if lp.frame[e] != GROUND:
                t.add("frame", names[lp.frame[e]])
            points.add(name, t)
        doc.add("load_points", points)

    if mech.corners:
        _write_corners(doc, mech, put, factor)

    if load_tables:
        tables = tomlkit.table(is_super_table=True)
        for name, table in load_tables.items():
            tables.add(name, _write_load_table(table, units))
        doc.add("load_tables", tables)
    return doc


def _write_orientation(m, rot: np.ndarray):
    from ..model import frame_from_axes

    rot = np.ascontiguousarray(rot, dtype=float)
    if rot.tobytes() == np.eye(3).tobytes():  # bitwise: -0.0 must be written out
        return
    z = rot[:, 2]
    try:
        if np.ascontiguousarray(frame_from_axes(z)).tobytes() == rot.tobytes():
            m.add("z", _floats(z))
            return
    except ModelError:
        pass
    import tomlkit

    axes = tomlkit.array()
    for c in range(3):
        axes.append(_floats(rot[:, c]))
    axes.multiline(True)
    m.add(tomlkit.comment("axes: the x, y, z axes in global components"))
    m.add("axes", axes)


def _write_load_table(table, units: dict[str, str]):
    """Columns keep their own units; a column without one is in library units, which is
    written out unless the file itself is in library units."""
    import tomlkit

    if isinstance(table, Table):
        columns, col_units = table.columns, table.units
    else:
        columns, col_units = dict(table), {}
    names = list(columns)
    arrays = [np.asarray(columns[n], dtype=float).ravel() for n in names]
    if len({a.shape for a in arrays}) > 1:
        raise ValueError("a load table's columns must all have the same length.")
    headers = []
    for n in names:
        unit = col_units.get(n)
        if unit is None and n != "case" and units != LIBRARY_UNITS:
            comp = n.rpartition(".")[2]
            unit = {"f": "N", "m": "N·mm"}.get(comp[:1], "mm") if comp in _LOAD_COMPONENTS \
                else "mm"
        headers.append(f"{n} [{unit}]" if unit else n)
    t = tomlkit.table()
    t.add("columns", headers)
    rows = tomlkit.array()
    for r in range(len(arrays[0]) if arrays else 0):
        rows.append([float(a[r]) for a in arrays])
    rows.multiline(True)
    t.add("rows", rows)
    return t


def write_model_toml(mech: Mechanism, path, *, load_tables: dict | None = None,
                     units: dict | None = None, keep_comments: bool = True,
                     source: str | None = None) -> None:
    """Write `mech` as a native model file (see `model_to_toml`).

    With `keep_comments` and an existing native file at `path`, the new content is merged into
    it: comments on keys and sections that still exist are kept, and its `[load_tables]` are
    kept when `load_tables` is None.
    """
    import tomlkit

    doc = model_to_toml(mech, load_tables=load_tables, units=units, source=source)
    if keep_comments and os.path.exists(path):
        try:
            with open(path, encoding="utf-8") as f:
                old = tomlkit.parse(f.read())
        except Exception:  # not a readable TOML file: overwrite it
            old = None
        if old is not None and isinstance(old.get("units"), dict):
            if load_tables is None and isinstance(old.get("load_tables"), dict):
                doc.add("load_tables", _with_units(old["load_tables"], old["units"]))
            doc = _merge_document(old, doc)
    text = tomlkit.dumps(doc)
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)


def _with_units(tables, old_units):
    """Load tables kept from a file being overwritten: columns without a unit were in that
    file's units, which the new file may not share, so write them out."""
    length, force = old_units.get("length", "mm"), old_units.get("force", "N")
    for table in tables.values():
        columns = table.get("columns") if isinstance(table, dict) else None
        if not isinstance(columns, list):
            continue
        for c, header in enumerate(list(columns)):
            if not isinstance(header, str):
                continue
            name, unit = split_header(header)
            if unit is not None or name == "case":
                continue
            comp = name.rpartition(".")[2]
            unit = (force if comp.startswith("f") else f"{force}·{length}") \
                if comp in _LOAD_COMPONENTS else length
            columns[c] = f"{name} [{unit}]"
    return tables


def _same(a, b) -> bool:
    """Equal values, telling -0.0 from 0.0 (an int and the equal float are the same)."""
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    numbers = (int, float)
    if isinstance(a, numbers) and isinstance(b, numbers) and not isinstance(a, bool) \
            and not isinstance(b, bool):
        try:
            x, y = float(a), float(b)
        except OverflowError:
            return False
        return x == y and math.copysign(1.0, x) == math.copysign(1.0, y)
    return type(a) is type(b) and a == b


def _merge_document(old, new):
    """`new`'s content in `old`'s layout: keys and tables that exist in both keep `old`'s
    comments; order follows `new` (marker order matters)."""
    import tomlkit
    from tomlkit.items import AoT, Table

    def merge(old_t, new_t):
        for key in list(old_t.keys()):
            if key not in new_t:
                del old_t[key]
        order = list(new_t.keys())
        for key in order:
            new_item = new_t.item(key) if hasattr(new_t, "item") else new_t[key]
            if key in old_t:
                old_item = old_t.item(key)
                if isinstance(old_item, Table) and isinstance(new_item, Table):
                    merge(old_item, new_item)
                    continue
                if not isinstance(old_item, Table | AoT) and not isinstance(new_item, Table):
                    if _same(old_item.unwrap(), new_item.unwrap()):
                        continue  # unchanged: keep its layout and the comments inside it
                    if old_item.trivia.comment:  # a human's comment beats the generated one
                        new_item.trivia.comment = old_item.trivia.comment
                        new_item.trivia.comment_ws = old_item.trivia.comment_ws
                old_t[key] = new_item
            else:
                old_t[key] = new_item
        if list(old_t.keys()) != order:
            # Reinsert in the new order (sections are tables of named elements).
            items = [(k, old_t.item(k)) for k in order]
            for k in order:
                del old_t[k]
            for k, item in items:
                old_t[k] = item
        return old_t

    merged = merge(old, new)
    # Sanity: the merged text must read back to the same content.
    if tomlkit.parse(tomlkit.dumps(merged)).unwrap() != new.unwrap():
        return new
    return merged
