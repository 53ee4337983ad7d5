"""IGES reader for what a measuring arm exports: points, lines and planes (spec geometry §3.6,
Annex B; CORRECTIONS 12).

An IGES file is fixed-format ASCII, 80 columns per record: columns 1–72 hold data, column 73
the section letter (S start, G global, D directory, P parameters, T terminate) and columns
74–80 the record's sequence number. (The thesis's prose says column 66; its code reads 73, as
the IGES standard does — CORRECTIONS 12.)

- **G**: free-format parameters; the first two are the parameter and record delimiters (default
  `,` and `;`), strings are Hollerith (`4HTEMP`). Parameter 13 is the model-space scale and 14
  the units flag (1 inch, 2 mm, 3 named by parameter 15, 4 foot, 5 mile, 6 metre, 7 km, 8 mil,
  9 micron, 10 cm, 11 microinch); coordinates are returned in **mm** (model units × scale).
- **D**: two records per entity: entity type in columns 1–8 and the pointer to its first P record
  in 9–16 of the first; the transformation-matrix pointer in 49–56 of the first; the parameter
  line count in 25–32 and the entity label in 57–64 of the second.
- **P**: the entity's parameters in columns 1–64 (columns 65–72: back pointer to its D record),
  the entity type first, ended by the record delimiter.

Entities read: **116** point (x, y, z), **110** line (start and end points; its unit direction is
end − start), **108** plane (A, B, C, D: A x + B y + C z = D; returned with a unit normal),
and **124** transformation matrices, which the three are mapped through when their D record
points to one. Every other entity is listed in `IgesFile.skipped` with its type and the line of
its D record (the thesis's sample has spheres 158 and a circular arc 100). The T record's
counts are not checked (the thesis's sample, with records lost in extraction, still reads).

Errors: anything unreadable raises `ModelFileError` naming the file and the line.
"""

import dataclasses
import os
import re
from typing import NamedTuple

import numpy as np

from ..errors import ModelFileError
from .files import read_input

__all__ = ["IgesFile", "IgesLine", "IgesPlane", "IgesPoint", "read_iges"]

_UNITS_MM = {1: 25.4, 2: 1.0, 4: 304.8, 5: 1609344.0, 6: 1000.0, 7: 1.0e6, 8: 0.0254,
             9: 1.0e-3, 10: 10.0, 11: 2.54e-5}
_UNIT_NAMES = {"IN": 1, "INCH": 1, "MM": 2, "FT": 4, "MI": 5, "M": 6, "KM": 7, "MIL": 8,
               "UM": 9, "MICRON": 9, "CM": 10, "UIN": 11}


class IgesPoint(NamedTuple):
    """A point entity (116): `name` (entity label, or `'116@D<n>'`), `position` (3,) mm,
    `line` the file line of its D record."""

    name: str
    position: np.ndarray
    line: int


class IgesLine(NamedTuple):
    """A line entity (110): `start`, `end` (3,) mm, `direction` unit (end − start), `length` mm."""

    name: str
    start: np.ndarray
    end: np.ndarray
    direction: np.ndarray
    length: float
    line: int


class IgesPlane(NamedTuple):
    """A plane entity (108): points x with `normal`·x = `offset` (unit normal, offset in mm)."""

    name: str
    normal: np.ndarray
    offset: float
    line: int


@dataclasses.dataclass(frozen=True)
class IgesFile:
    """What `read_iges` found: points, lines and planes in file order, and the skipped entities
    as (entity type, line of the D record). `units` is the file's unit name and `scale` the
    factor applied to reach mm."""

    points: tuple[IgesPoint, ...]
    lines: tuple[IgesLine, ...]
    planes: tuple[IgesPlane, ...]
    skipped: tuple[tuple[int, int], ...]
    units: str
    scale: float
    path: str | None = None

    def point(self, name: str) -> np.ndarray:
        """Position (mm) of the point labelled `name`."""
        for p in self.points:
            if p.name == name:
                return p.position
        raise KeyError(f"no point named '{name}' (points: "
                       f"{', '.join(p.name for p in self.points) or 'none'}).")


def _source(source) -> tuple[str, str | None]:
    if isinstance(source, bytes):
        try:
            return source.decode("utf-8"), None
        except UnicodeDecodeError:
            return source.decode("latin-1"), None
    if isinstance(source, os.PathLike) or (isinstance(source, str) and "\n" not in source):
        path = os.fspath(source)
        try:
            # A regular file within the size limit (a device, a FIFO or an endless file is
            # refused before it is read: `io.files`).
            raw = read_input(path, "IGES file")
        except FileNotFoundError as exc:
            raise ModelFileError(f"cannot read the IGES file ({exc.strerror or exc}).",
                                 path=path) from None
        return _source(raw)[0], path
    if isinstance(source, str):
        return source, None
    raise TypeError(f"read_iges takes a path, text or bytes; got {type(source).__name__}.")


_HOLLERITH = re.compile(r"\s*(\d+)H")


def _split_free(text: str, pdelim: str, rdelim: str, path, line: int) -> list[str]:
    """Free-format parameters up to the record delimiter; Hollerith strings kept whole.

    Linear in the length of `text` (every match starts at a position, no slice of the rest:
    an entity of 1.6 M parameters took 85 s with slices)."""
    out, i, n = [], 0, len(text)
    while i < n:
        # a Hollerith string: digits, 'H', then that many characters
        m = _HOLLERITH.match(text, i)
        if m:
            count = int(m.group(1))
            start = m.end()
            if start + count > n:
                raise ModelFileError(
                    f"Hollerith string of {count} characters runs past the end of the section.",
                    path=path, line=line)
            out.append(text[start:start + count])
            i = start + count
            while i < n and text[i] == " ":
                i += 1
            nxt = text[i:i + 1]
            if nxt == rdelim:
                return out
            if nxt != pdelim:
                raise ModelFileError(
                    f"expected '{pdelim}' after a Hollerith string; found {nxt!r}.",
                    path=path, line=line)
            i += 1
            continue
        j = i
        while j < n and text[j] not in (pdelim, rdelim):
            j += 1
        out.append(text[i:j].strip())
        if j >= n or text[j] == rdelim:
            return out
        i = j + 1
    return out


COORDINATE_LIMIT = 1e12
"""Largest coordinate (mm) after the model scale: beyond it (a scale of 1e300) a line has no
direction and a point no meaning."""


def _in_range(values, path, line, what, scale):
    v = np.asarray(values, float)
    if not np.all(np.isfinite(v)) or np.max(np.abs(v), initial=0.0) > COORDINATE_LIMIT:
        raise ModelFileError(f"{what} lies beyond ±{COORDINATE_LIMIT:g} mm after the model "
                             f"scale {scale:g} (G parameter 13); check the scale and units.",
                             path=path, line=line)
    return v


def _number(token: str, path, line: int, what: str) -> float:
    try:
        value = float(token.replace("D", "E").replace("d", "e")) if token else 0.0
    except ValueError:
        raise ModelFileError(f"{what} must be a number; got {token!r}.", path=path,
                             line=line) from None
    if not np.isfinite(value):
        raise ModelFileError(f"{what} must be finite; got {token!r}.", path=path, line=line)
    return value


def _records(text: str, path):
    sections: dict[str, list[tuple[int, str]]] = {k: [] for k in "SGDPT"}
    for number, raw in enumerate(text.splitlines(), start=1):
        rec = raw.rstrip("\r\n")
        if not rec.strip():
            continue
        if len(rec) < 73 or len(rec.rstrip()) > 80:
            raise ModelFileError(
                f"an IGES record has 80 columns with the section letter in column 73; this "
                f"line has {len(rec.rstrip())} columns.", path=path, line=number)
        letter = rec[72]
        if letter not in sections:
            raise ModelFileError(
                f"column 73 must hold the section letter S, G, D, P or T; found {letter!r}.",
                path=path, line=number)
        seq = rec[73:80].strip()
        if not seq.isdigit():
            raise ModelFileError("columns 74–80 must hold the record's sequence number; got "
                                 f"{rec[73:80]!r}.", path=path, line=number)
        sections[letter].append((number, rec[:72], int(seq)))
    if not sections["D"]:
        raise ModelFileError("no directory (D) section: this is not an IGES file with entities.",
                             path=path, line=None)
    return sections


def _global(records, path):
    text = "".join(r for _, r, _ in records)
    line = records[0][0] if records else None
    if not text.strip():
        return ",", ";", 1.0, 2, "MM"
    pdelim, rdelim = ",", ";"
    m = re.match(r"\s*1H(.)", text)
    if m:
        pdelim = m.group(1)
    params = _split_free(text, pdelim, ";", path, line) if pdelim != ";" else []
    if len(params) > 1 and len(params[1]) == 1:
        rdelim = params[1]
        params = _split_free(text, pdelim, rdelim, path, line)
    scale = _number(params[12], path, line, "G parameter 13 (model scale)") \
        if len(params) > 12 and params[12] else 1.0
    flag = int(_number(params[13], path, line, "G parameter 14 (units flag)")) \
        if len(params) > 13 and params[13] else 2
    name = params[14].strip().upper() if len(params) > 14 else ""
    if flag == 3:
        if name not in _UNIT_NAMES:
            raise ModelFileError(f"unknown unit name {name!r} (G parameter 15).", path=path,
                                 line=line)
        flag = _UNIT_NAMES[name]
    if flag not in _UNITS_MM:
        raise ModelFileError(f"unknown units flag {flag} (G parameter 14); expected 1–11.",
                             path=path, line=line)
    if scale <= 0:
        raise ModelFileError(f"the model scale (G parameter 13) must be positive; got {scale}.",
                             path=path, line=line)
    return pdelim, rdelim, scale, flag, name or {2: "MM"}.get(flag, str(flag))


def _field(rec: str, k: int, path, line: int, what: str) -> int:
    token = rec[8 * k: 8 * k + 8].strip()
    if not token:
        return 0
    if not re.fullmatch(r"[+-]?\d+", token):
        raise ModelFileError(f"{what} (D columns {8 * k + 1}–{8 * k + 8}) must be an integer; "
                             f"got {token!r}.", path=path, line=line)
    return int(token)


def read_iges(source) -> IgesFile:
    """Read the points, lines and planes of an IGES file (see the module docstring).

    **Arguments:** `source`: a path, text (with a newline) or bytes.

    **Returns:** an `IgesFile` (coordinates in mm).

    **Raises:** `ModelFileError` naming the file and line for anything unreadable.
    """
    text, path = _source(source)
    sections = _records(text, path)
    pdelim, rdelim, scale, flag, units = _global(sections["G"], path)
    factor = scale * _UNITS_MM[flag]
    d_records = sections["D"]
    if len(d_records) % 2:
        raise ModelFileError("the directory (D) section has an odd number of records; each "
                             "entity takes two.", path=path, line=d_records[-1][0])
    entries = []
    for k in range(0, len(d_records), 2):
        (l1, r1, seq), (l2, r2, _) = d_records[k], d_records[k + 1]
        entries.append(dict(
            type=_field(r1, 0, path, l1, "entity type"),
            pointer=_field(r1, 1, path, l1, "parameter pointer"),
            transform=_field(r1, 6, path, l1, "transformation pointer"),
            count=_field(r2, 3, path, l2, "parameter line count"),
            label=r2[56:64].strip(), line=l1, de=seq))
    # Pointers are sequence numbers (columns 74–80), which may skip (records lost).
    de_seq = {e["de"]: i for i, e in enumerate(entries)}
    p_seq = {seq: (number, rec) for number, rec, seq in sections["P"]}

    def parameters(entry):
        lines = []
        if not 0 <= entry["count"] <= len(p_seq):
            raise ModelFileError(f"parameter line count {entry['count']} of entity "
                                 f"{entry['type']} is out of range.", path=path,
                                 line=entry["line"] + 1)
        for s in range(entry["pointer"], entry["pointer"] + max(entry["count"], 1)):
            if s not in p_seq:
                raise ModelFileError(
                    f"entity {entry['type']} points to parameter record {s}, which the P "
                    "section does not have.", path=path, line=entry["line"])
            lines.append(p_seq[s])
        data = "".join(rec[:64] for _, rec in lines)
        params = _split_free(data, pdelim, rdelim, path, lines[0][0])
        first = lines[0][0]
        if not params or params[0].strip() != str(entry["type"]):
            raise ModelFileError(
                f"the parameters of entity {entry['type']} must start with its type; found "
                f"{params[0] if params else 'nothing'!r}.", path=path, line=first)
        return params[1:], first

    def numbers(entry, n, what):
        params, first = parameters(entry)
        if len(params) < n:
            raise ModelFileError(f"{what} (entity {entry['type']}) needs {n} parameters; got "
                                 f"{len(params)}.", path=path, line=first)
        return np.array([_number(t, path, first, f"{what} parameter {i + 1}")
                         for i, t in enumerate(params[:n])])

    def matrix(entry):
        if entry["transform"] == 0:
            return np.eye(3), np.zeros(3)
        index = de_seq.get(entry["transform"])
        if index is None or entries[index]["type"] != 124:
            raise ModelFileError(
                f"entity {entry['type']} points to transformation {entry['transform']}, which "
                "is not a 124 entity of the D section.", path=path, line=entry["line"])
        m = numbers(entries[index], 12, "transformation matrix").reshape(3, 4)
        return m[:, :3], m[:, 3]

    points, lines_, planes, skipped = [], [], [], []
    for entry in entries:
        kind = entry["type"]
        name = entry["label"] or f"{kind}@D{entry['de']}"
        if kind == 116:
            r, t = matrix(entry)
            p = numbers(entry, 3, "point")
            points.append(IgesPoint(name, _in_range((r @ p + t) * factor, path, entry["line"],
                                                    "a point (116)", scale), entry["line"]))
        elif kind == 110:
            r, t = matrix(entry)
            v = numbers(entry, 6, "line")
            a = _in_range((r @ v[:3] + t) * factor, path, entry["line"], "a line (110)", scale)
            b = _in_range((r @ v[3:] + t) * factor, path, entry["line"], "a line (110)", scale)
            length = float(np.linalg.norm(b - a))
            if not length > 0:
                raise ModelFileError("a line (110) has equal start and end points.", path=path,
                                     line=entry["line"])
            lines_.append(IgesLine(name, a, b, (b - a) / length, length, entry["line"]))
        elif kind == 108:
            r, t = matrix(entry)
            v = numbers(entry, 4, "plane")
            norm = float(np.linalg.norm(v[:3]))
            if not norm > 0:
                raise ModelFileError("a plane (108) has a zero normal (A, B, C).", path=path,
                                     line=entry["line"])
            normal = r @ (v[:3] / norm)
            offset = v[3] / norm + normal @ t
            offset = float(_in_range(offset * factor, path, entry["line"], "a plane (108)",
                                     scale))
            planes.append(IgesPlane(name, normal, offset, entry["line"]))
        elif kind != 124:
            skipped.append((kind, entry["line"]))
    return IgesFile(tuple(points), tuple(lines_), tuple(planes), tuple(skipped), units,
                    factor, path)
