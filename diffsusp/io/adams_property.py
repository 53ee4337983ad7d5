"""Adams/Car property files: TeimOrbit files (`parse_teimorbit`), A/Car load-case files (.lcf,
`read_lcf`, `write_lcf`) and bushing property files (.bus, `read_bushing_property`,
`write_bushing_property`).

spec: stiffness §4.2 (.lcf, Annex H), §4.3 (A/Car bushing splines, Annex I), §4.4. Reading
never executes anything from a file. Units are converted to mm, N, N·mm, rad.
"""

import dataclasses
import math
from pathlib import Path

import numpy as np
from jaxtyping import ArrayLike, Float

from ..geometry import DEG
from .adams_common import FORCE_TO_N, LENGTH_TO_MM, error, fmt, read_source
from .teimorbit import NUMBER, WORD, scalar, split_value, tokenise

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


def _teim_value(text: str, path, line):
    """A value or a table cell: a quoted string, a finite number or a word."""
    value = scalar(text)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise error(f"{text} is not a finite number.", path, line)
    elif text[:1] not in ("'", '"') and not WORD.fullmatch(text):
        raise error(f"value {text[:40]!r} is not a number, a quoted string or a word.", path,
                    line)
    return value


def parse_teimorbit(source, what: str = "property") -> dict[str, TeimBlock]:
    """Parse a TeimOrbit file (the format of A/Car .lcf and property files) into its sections.

    Lines (the grammar of `io.teimorbit`, shared with .tir files): ``$`` or ``!`` comments,
    ``[SECTION]``, ``(SUBSECTION)``, ``key = value`` (quoted string, number or word; an optional
    ``$`` comment after it), ``{col1 col2 ...}`` table headers followed by rows of numbers or
    quoted strings (rows of numbers without a header make a table with no column names, as in
    a .tir [SHAPE]). Raises `ModelFileError` with the line of anything else.
    """
    text, path = read_source(source, what)
    sections: dict[str, TeimBlock] = {}
    section = block = None
    table = None
    for t in tokenise(text):
        number = t.line
        if t.kind == "section":
            if t.name in sections:
                raise error(f"section [{t.name}] is given twice (first at line "
                            f"{sections[t.name].line}).", path, number)
            section = block = sections[t.name] = TeimBlock(t.name, number)
            table = None
        elif t.kind == "subsection":
            if section is None:
                raise error(f"({t.text[1:-1].strip()}) is outside any [SECTION].", path,
                            number)
            block = section.blocks[t.name] = TeimBlock(t.name, number)
            table = None
        elif t.kind == "header":
            if block is None:
                raise error("a {table header} is outside any [SECTION].", path, number)
            if not t.cells:
                raise error("the table header {} names no column.", path, number)
            table = TeimTable(t.cells, [], number)
            block.tables.append(table)
        elif t.kind == "assign":
            if block is None:
                raise error(f"'{t.name}' is outside any [SECTION].", path, number)
            try:
                text_value = split_value(t.raw, t.name)[1]
            except ValueError as exc:
                raise error(f"{exc}.", path, number, t.name) from None
            block.values[t.name.upper()] = _teim_value(text_value, path, number)
            table = None
        elif t.kind == "row" and (table is not None or (
                block is not None and all(NUMBER.fullmatch(c) for c in t.cells))):
            if table is None:  # numbers without a {header} (a .tir [SHAPE]): no column names
                table = TeimTable((), [], number)
                block.tables.append(table)
            cells = [_teim_value(c, path, number) for c in t.cells]
            if table.columns and len(cells) != len(table.columns):
                raise error(f"row has {len(cells)} value(s) but the table header at line "
                            f"{table.line} names {len(table.columns)} column(s).", path, number)
            table.rows.append(cells)
        else:
            raise error(f"unexpected line {t.text[:40]!r}: expected [SECTION], (SUBSECTION), "
                        "key = value, {table header} or a table row.", path, number)
    return sections


def _teim_format(value) -> str:
    if isinstance(value, str):
        return f"'{value}'"
    return fmt(value)


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
    text, file = read_source(path, "load-case")
    sections = parse_teimorbit(text)
    n_lines = max(len(text.splitlines()), 1)
    header = sections.get("MDI_HEADER")
    if header is not None:
        kind = header.values.get("FILE_TYPE")
        if kind is not None and str(kind).lower() != "lcf":
            raise error(f"FILE_TYPE = {kind!r}; a load-case file has FILE_TYPE = 'lcf'.",
                        file, header.line, "FILE_TYPE")
    data = sections.get("DATA")
    if data is None or not data.tables:
        raise error("no [DATA] section with a {column header} and rows.", file,
                    data.line if data else n_lines, "DATA")
    if len(data.tables) > 1:
        raise error("[DATA] has more than one table.", file, data.tables[1].line, "DATA")
    table = data.tables[0]
    if not table.columns:
        raise error("the [DATA] rows have no {column header}.", file, table.line, "DATA")
    for row_index, row in enumerate(table.rows):
        if any(isinstance(c, str) for c in row):
            raise error(f"load case {row_index + 1} has a non-numeric value.", file,
                        table.line + 1 + row_index, "DATA")
    columns = table.columns
    if len({c.lower() for c in columns}) != len(columns):
        raise error("the [DATA] header names a column twice.", file, table.line, "DATA")
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
_ANGLE_TO_RAD = {"DEG": DEG, "DEGREE": DEG, "DEGREES": DEG,
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
        raise error(f"[UNITS] {key} = {value!r} is not one of {', '.join(table)}.", path, line,
                    key)
    return table[value]


def read_bushing_property(path) -> BushingProperty:
    """Read an A/Car bushing property file (.bus): [UNITS], [TX_FORCE] {tx force} …
    [RZ_TORQUE] {rz torque} curves, [DAMPING]. Raises `ModelFileError` with the line for a
    malformed file (no curve at all, a curve whose deformations do not increase, units that
    are not known)."""
    text, file = read_source(path, "bushing property")
    sections = parse_teimorbit(text, "bushing property")
    units_block = sections.get("UNITS")
    units = dict(units_block.values) if units_block else {}
    uline = units_block.line if units_block else 1
    length = _unit_factor(units, "LENGTH", LENGTH_TO_MM, "MM", file, uline)
    force = _unit_factor(units, "FORCE", FORCE_TO_N, "N", file, uline)
    angle = _unit_factor(units, "ANGLE", _ANGLE_TO_RAD, "DEG", file, uline)
    splines, k_trans, k_rot = {}, np.zeros(3), np.zeros(3)
    for axis, name in _BUS_SECTIONS.items():
        block = sections.get(name)
        if block is None:
            continue
        if len(block.tables) != 1 or len(block.tables[0].columns) != 2:
            raise error(f"[{name}] needs one table with two columns "
                        f"{{{axis} {'force' if axis[0] == 't' else 'torque'}}}.", file,
                        block.line, name)
        t = block.tables[0]
        rows = np.array(t.rows, dtype=object)
        if rows.size == 0 or any(isinstance(c, str) for r in t.rows for c in r):
            raise error(f"[{name}] needs numeric rows.", file, t.line, name)
        x = np.asarray(rows[:, 0], float) * (length if axis[0] == "t" else angle)
        y = np.asarray(rows[:, 1], float) * (force if axis[0] == "t" else force * length)
        if x.size < 2 or np.any(np.diff(x) <= 0):
            raise error(f"[{name}] needs at least two rows with increasing deformation.", file,
                        t.line, name)
        splines[axis] = (x, -y)
        slope = float(x @ y / (x @ x)) if np.any(x) else 0.0
        (k_trans if axis[0] == "t" else k_rot)["xyz".index(axis[1])] = slope
    if not splines:
        raise error("no force curve ([TX_FORCE] … [RZ_TORQUE]) in the file.", file,
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
