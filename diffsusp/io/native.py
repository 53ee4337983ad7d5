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

**Modules.** This one reads (`read_model_toml`, `model_from_toml`); `native_write` writes
(`model_to_toml`, `write_model_toml`, re-exported here); `native_values` holds the units, the
key locator and the typed value reader both share. The round-trip tests
(`tests/test_io_native.py`) keep reader and writer each other's inverse.
"""

import dataclasses
import os
import re
import tomllib

import numpy as np

from ..errors import ModelFileError
from ..geometry import reuler_to_matrix
from ..model import Mechanism, MechanismBuilder
from ..model.corner import Corner
from ..model.mechanism import BUSHING_AXES, JOINT_ROWS
from .files import read_input
from .native_values import (
    ANG,
    ANGLE_UNITS,
    FORCE,
    FORCE_UNITS,
    LEN,
    LENGTH_UNITS,
    LIBRARY_UNITS,
    MAX_MAGNITUDE,
    TORQUE,
    UNIT_TABLES,
    Reader,
    Source,
    shown,
)
from .tables import Table, load_columns, split_header, unit_factor

__all__ = [
    "ANGLE_UNITS", "FORCE_UNITS", "FORMAT_VERSION", "LENGTH_UNITS", "LIBRARY_UNITS",
    "MAX_MAGNITUDE", "READ_VERSIONS", "ModelFile", "model_from_toml", "read_model_toml",
]  # and, from `native_write`, model_to_toml and write_model_toml

FORMAT_VERSION = 2
"""Version written: 2 adds the wheel corners (`[[corner]]`); version-1 files (no corner) are
still read."""
READ_VERSIONS = (1, 2)

BUSHING_FIELDS = {
    "k_trans": (-1, 1, 0), "k_rot": (1, 1, -1),
    "cubic_trans": (-3, 1, 0), "cubic_rot": (1, 1, -3),
    "offset_trans": LEN, "offset_rot": ANG,
    "preload_force": FORCE, "preload_torque": TORQUE,
}
_ORIENTATION_KEYS = ("axes", "reuler", "z", "x")
LOAD_COMPONENTS = ("fx", "fy", "fz", "mx", "my", "mz")
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
        src = Source(text, path)
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


def _build(doc: dict, src: Source, path, check: bool) -> ModelFile:
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
    rd = Reader(src, factors)
    name = doc.get("name")
    if name is None:
        name = os.path.splitext(os.path.basename(str(path)))[0] if path else "mechanism"
    b = MechanismBuilder(rd.string(name, ("name",), "the model name"))

    if "parts" not in doc:
        raise src.error("missing 'parts': list the moving parts, e.g. parts = [\"arm\"].", ())
    parts = doc["parts"]
    if not isinstance(parts, list) or not parts:
        raise src.error(f"'parts' must be a non-empty list of part names; got {shown(parts)}.",
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
        position = rd.vector(m["position"], (*keys, "position"), LEN)
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
        rd.keys(e, keys, ("i", "j", "parts", "at", *_ORIENTATION_KEYS, *BUSHING_FIELDS,
                          "splines"), ("k_trans", "k_rot"))
        values = {f: rd.vector(e[f], (*keys, f), dims, scalar=True)
                  for f, dims in BUSHING_FIELDS.items() if f in e}
        splines = {}
        if "splines" in e:
            sp = rd.table(e["splines"], (*keys, "splines"), "[...splines.<axis>] tables")
            rd.keys(sp, (*keys, "splines"), BUSHING_AXES)
            for axis, table in sp.items():
                rot = axis.startswith("r")
                splines[axis] = rd.xy(table, (*keys, "splines", axis), ANG if rot else LEN,
                                      TORQUE if rot else FORCE)
        with _located(src, keys):
            b.bushing(b_name, **_pair(rd, e, keys, oriented=True), **values,
                      splines=splines or None)

    for s_name, s, keys in section("springs"):
        rd.keys(s, keys, ("i", "j", "parts", "at", "k", "free_length", "table"))
        kw = {}
        if "k" in s:
            kw["k"] = rd.number(s["k"], (*keys, "k"), (-1, 1, 0))
        if "free_length" in s:
            kw["free_length"] = rd.number(s["free_length"], (*keys, "free_length"), LEN)
        if "table" in s:
            kw["table"] = rd.xy(s["table"], (*keys, "table"), LEN, FORCE)
        elif "k" not in s or "free_length" not in s:
            raise src.error("a spring needs k and free_length, or a [table] with x and y.", keys)
        with _located(src, keys):
            b.spring(s_name, **_pair(rd, s, keys, oriented=False), **kw)

    for s_name, s, keys in section("stops"):
        rd.keys(s, keys, ("i", "j", "parts", "at", "kind", "length", "k", "cubic"),
                ("length", "k"))
        kw = dict(
            kind=rd.string(s.get("kind", "bump"), (*keys, "kind"), "'bump' or 'rebound'"),
            length=rd.number(s["length"], (*keys, "length"), LEN),
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

    def __init__(self, src: Source, keys):
        self.src, self.keys = src, keys

    def __enter__(self):
        return self

    def __exit__(self, kind, value, tb):
        if kind is not None and issubclass(kind, ValueError) and not isinstance(
            value, ModelFileError
        ):
            raise self.src.error(f"{value}", self.keys) from None
        return False


def _units(doc, src: Source):
    if "units" not in doc:
        raise src.error(
            "missing [units]: declare the file's units, e.g. [units] length = \"mm\", "
            "force = \"N\", angle = \"rad\".", ())
    u = doc["units"]
    if not isinstance(u, dict):
        raise src.error(f"[units] must be a table; got {shown(u)}.", ("units",))
    unknown = [k for k in u if k not in UNIT_TABLES]
    if unknown:
        raise src.error(f"unknown unit '{unknown[0]}'; [units] has length, force and angle.",
                        ("units", unknown[0]))
    units, factors = {}, {}
    for key, table in UNIT_TABLES.items():
        if key not in u:
            raise src.error(f"[units] is missing '{key}' (one of {', '.join(table)}).",
                            ("units",))
        value = u[key]
        if not isinstance(value, str) or value not in table:
            raise src.error(f"unknown {key} unit {value!r}; use one of {', '.join(table)}.",
                            ("units", key))
        units[key], factors[key] = value, table[value]
    return units, factors


def _orientation(rd: Reader, m: dict, keys) -> dict:
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
            raise rd.src.error(f"axes must be [[x axis], [y axis], [z axis]]; got {shown(axes)}.",
                               (*keys, "axes"))
        cols = [rd.vector(a, (*keys, "axes")) for a in axes]
        return dict(orientation=np.column_stack(cols))
    if "reuler" in m:
        angles = rd.vector(m["reuler"], (*keys, "reuler"), ANG, convert=False)
        if rd.units["angle"] == ANGLE_UNITS["deg"]:
            return dict(reuler_deg=angles)
        return dict(orientation=np.asarray(reuler_to_matrix(angles * rd.factor(ANG))))
    if "z" in m:
        z = rd.vector(m["z"], (*keys, "z"))
        x = rd.vector(m["x"], (*keys, "x")) if "x" in m else None
        return dict(z=z, x=x)
    return {}


def _pair(rd: Reader, e: dict, keys, *, oriented: bool) -> dict:
    if "parts" in e:
        if "i" in e or "j" in e:
            raise rd.src.error("give markers i and j, or parts with at, not both.",
                               (*keys, "parts"))
        parts = e["parts"]
        if not isinstance(parts, list) or len(parts) != 2:
            raise rd.src.error(f"parts must be [I part, J part]; got {shown(parts)}.",
                               (*keys, "parts"))
        parts = [rd.string(p, (*keys, "parts"), "a part name") for p in parts]
        if "at" not in e:
            raise rd.src.error("parts needs at = [x, y, z], the location of the markers.", keys)
        at = e["at"]
        if oriented:
            at = rd.vector(at, (*keys, "at"), LEN)
            return dict(parts=parts, at=at, **_orientation(rd, e, keys))
        if isinstance(at, list) and len(at) == 2 and all(isinstance(a, list) for a in at):
            at = np.stack([rd.vector(a, (*keys, "at"), LEN) for a in at])
        else:
            raise rd.src.error(
                f"at must be [[point on I], [point on J]]; got {shown(at)}.", (*keys, "at"))
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


def _read_corner(rd: Reader, c: dict, keys):
    """A `[[corner]]` table → `Corner`: every key optional with `Corner`'s defaults, except
    `design_load` (absent: computed, the load that holds the design position);
    `wheel_centre_load = false` for none; `kingpin` two points, each a marker name or
    {part = "...", offset = [forward, outboard, up]} (length units)."""
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
            raise rd.src.error(f"kingpin must be two points [upper, lower]; got {shown(refs)}.",
                               (*keys, "kingpin"))
        points = []
        for ref in refs:
            if isinstance(ref, dict):
                rd.keys(ref, (*keys, "kingpin"), ("part", "offset"), ("part", "offset"))
                points.append((rd.string(ref["part"], (*keys, "kingpin"), "a part name"),
                               tuple(float(v) for v in rd.vector(ref["offset"],
                                                                 (*keys, "kingpin"), LEN))))
            else:
                points.append(rd.string(ref, (*keys, "kingpin"), "a marker name or "
                                        "{part, offset}"))
        kw["kingpin"] = tuple(points)
    if "loaded_radius" in c:
        kw["loaded_radius"] = rd.number(c["loaded_radius"], (*keys, "loaded_radius"), LEN)
    kw["design_load"] = (rd.number(c["design_load"], (*keys, "design_load"), FORCE)
                         if "design_load" in c else None)
    try:
        return Corner(**kw)
    except ValueError as e:
        raise rd.src.error(str(e), keys) from None


def _point(rd: Reader, e: dict, keys) -> dict:
    if "marker" in e:
        if "part" in e or "at" in e:
            raise rd.src.error("give a marker, or part with at, not both.", (*keys, "marker"))
        return dict(marker=rd.string(e["marker"], (*keys, "marker"), "a marker name"))
    if "part" not in e or "at" not in e:
        raise rd.src.error("missing 'marker' (or 'part' and 'at').", keys)
    return dict(part=rd.string(e["part"], (*keys, "part"), "a part name"),
                at=rd.vector(e["at"], (*keys, "at"), LEN))


_DIMENSION_OF_COLUMN = {"force": FORCE, "moment": TORQUE, "length": LEN}


def _load_table(rd: Reader, mech: Mechanism, t: dict, keys, units) -> Table:
    rd.keys(t, keys, ("columns", "rows"), ("columns", "rows"))
    columns = t["columns"]
    if not isinstance(columns, list) or not columns:
        raise rd.src.error(f"columns must be a list of column names; got {shown(columns)}.",
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
        raise rd.src.error(f"rows must be a list of rows; got {shown(rows)}.", (*keys, "rows"))
    values = np.empty((len(rows), len(names)))
    for r, row in enumerate(rows):
        if not isinstance(row, list) or len(row) != len(names):
            raise rd.src.error(
                f"row {r + 1} must be a list of {len(names)} numbers (one per column); got "
                f"{shown(row)}.", (*keys, "rows"))
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

