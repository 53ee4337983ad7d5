"""Tables of load cases and results, as CSV or Parquet, with units.

A `Table` is named float64 columns of equal length, each with an optional unit.

- **CSV**: one header row, one row per case, comma separated; a column's unit is written in
  brackets after its name (`contact_patch.fz [N]`, `wheel_travel [mm]`). Lines starting with `#`
  and blank lines are skipped. Numbers are anything Python's `float` reads (`1500`, `-2e3`,
  `nan`); anything else is an error naming the line and the column. Nothing in a file is ever
  evaluated.
- **Parquet**: numeric columns; a column's unit is the field metadata key `unit` (or, failing
  that, a bracketed suffix of its name as in CSV). Nulls are errors.

**Units** (case-sensitive): length `mm`, `cm`, `m`, `km`, `in`, `ft`; force `N`, `daN`, `kN`,
`MN`, `lbf`; angle `rad`, `deg` (or `°`); dimensionless `-` or `1`. Products and quotients:
`N·mm`, `N*mm`, `N mm`, `N.m`, `Nmm`, `kNm`, `N/mm`, `N·mm/deg`, `N/mm^3`, `N/mm³`. See
`parse_unit`.

**Load cases** (`loads_from_table`), columns (components in the load point's frame, like
`Mechanism.loads`):

| column | meaning | unit (default) |
|---|---|---|
| `<load point>.fx`, `.fy`, `.fz` | force at the load point | force (N) |
| `<load point>.mx`, `.my`, `.mz` | moment at the load point | force·length (N·mm) |
| `<driver>` | motion driver value | length (mm) |
| `fx`, `fy`, `fz`, `mx`, `my`, `mz` | K&C shorthand (see below) | as above |
| `case` | a case label or number, ignored | — |

The shorthand names the model's only load point or, when it has several, the one named
`contact_patch` (the K&C convention). A column without a unit is in the library's units (N,
N·mm, mm). Missing load-point components and drivers are zero.
"""

import csv
import dataclasses
import io
import math
import os
import re
from collections.abc import Mapping

import numpy as np

from ..errors import ModelError, ModelFileError
from ..geometry import DEG
from ..model import Loads
from .files import check_input, current_umask, read_input, write_text_atomic

# --------------------------------------------------------------------------------------- units

_L, _F, _A = (1, 0, 0), (0, 1, 0), (0, 0, 1)
_BASE_UNITS = {
    "mm": (_L, 1.0), "cm": (_L, 10.0), "m": (_L, 1000.0), "km": (_L, 1.0e6),
    "in": (_L, 25.4), "ft": (_L, 304.8),
    "N": (_F, 1.0), "daN": (_F, 10.0), "kN": (_F, 1000.0), "MN": (_F, 1.0e6),
    "lbf": (_F, 4.4482216152605),
    "rad": (_A, 1.0), "deg": (_A, DEG), "°": (_A, DEG),
}
"""Base units: (exponents of length, force, angle), factor to the library's mm, N, rad."""

DIMENSIONS = {
    "length": (1, 0, 0),
    "force": (0, 1, 0),
    "angle": (0, 0, 1),
    "moment": (1, 1, 0),
    "dimensionless": (0, 0, 0),
}
"""Named dimensions (exponents of length, force, angle)."""

_SUPERSCRIPTS = str.maketrans("⁰¹²³⁴⁵⁶⁷⁸⁹⁻", "0123456789-")
_FACTOR_RE = re.compile(r"^([^\^\d⁰¹²³⁴⁵⁶⁷⁸⁹⁻-]+)(?:\^?(-?\d+))?$")


def _base(token: str, unit: str):
    token = token.translate(_SUPERSCRIPTS)
    match = _FACTOR_RE.match(token)
    if not match:
        raise ValueError(f"cannot read '{token}' in unit '{unit}'")
    name, power = match.group(1), int(match.group(2) or 1)
    if name in _BASE_UNITS:
        dims, factor = _BASE_UNITS[name]
        return tuple(power * d for d in dims), factor**power
    # Concatenated products without a separator (Adams: Nmm, kNm).
    for cut in range(1, len(name)):
        head, tail = name[:cut], name[cut:]
        if head in _BASE_UNITS and tail in _BASE_UNITS:
            (d1, f1), (d2, f2) = _BASE_UNITS[head], _BASE_UNITS[tail]
            return tuple(power * (a + b) for a, b in zip(d1, d2, strict=True)), (f1 * f2) ** power
    known = ", ".join(_BASE_UNITS)
    raise ValueError(f"unknown unit '{name}' in '{unit}' (known: {known})")


def parse_unit(unit: str | None) -> tuple[tuple[int, int, int], float]:
    """Dimension and conversion factor of a unit string.

    **Arguments:** `unit`: e.g. `"kN"`, `"N·mm/deg"`, `"N/mm^3"`; `None`, `""`, `"-"` or `"1"`
    are dimensionless.

    **Returns:** (exponents of (length, force, angle), factor) such that a value in `unit` times
    `factor` is in the library's units (mm, N, rad).

    **Raises:** `ValueError` for a unit it cannot read.
    """
    if unit is None:
        return (0, 0, 0), 1.0
    text = unit.strip()
    if text in ("", "-", "1"):
        return (0, 0, 0), 1.0
    num, slash, den = text.partition("/")
    if "/" in den:
        raise ValueError(f"unit '{unit}' has more than one '/'; write e.g. N/mm or N·mm/rad")
    dims, factor = [0, 0, 0], 1.0
    for part, sign in ((num, 1), (den, -1)):
        tokens = [t for t in re.split(r"[·⋅*\s]+|(?<=[A-Za-z°])\.(?=[A-Za-z])", part) if t]
        if sign == -1 and slash and not tokens:
            raise ValueError(f"unit '{unit}' has nothing after '/'")
        for token in tokens:
            if sign == 1 and token == "1" and len(tokens) == 1:
                continue  # "1/mm"
            d, f = _base(token, unit)
            dims = [a + sign * b for a, b in zip(dims, d, strict=True)]
            factor *= f**sign
    return (dims[0], dims[1], dims[2]), factor


def unit_factor(unit: str | None, dimension: str | tuple[int, int, int]) -> float:
    """Factor converting values in `unit` to library units, checking its `dimension` (a name in
    `DIMENSIONS` or exponents of (length, force, angle)). `None` means library units.

    **Raises:** `ValueError` naming the expected dimension when `unit` has another one.
    """
    want = DIMENSIONS[dimension] if isinstance(dimension, str) else tuple(dimension)
    if unit is None:
        return 1.0
    dims, factor = parse_unit(unit)
    if dims != want:
        raise ValueError(f"unit '{unit}' is not a {_dimension_name(want)} unit")
    return factor


def _dimension_name(dims) -> str:
    for name, d in DIMENSIONS.items():
        if d == tuple(dims):
            return name
    parts = [f"{sym}^{e}" for sym, e in zip(("length", "force", "angle"), dims, strict=True) if e]
    return "·".join(parts)


# --------------------------------------------------------------------------------------- table


@dataclasses.dataclass(frozen=True, eq=False)
class Table:
    """Named float64 columns of equal length with optional units.

    **Fields:** `columns` (name → 1-D float64 array), `units` (name → unit string or None),
    `path` (the file it was read from, if any), `lines` (1-based source line of each row for
    CSV; None for Parquet or built tables), `header_line` (line of the CSV header).
    """

    columns: dict[str, np.ndarray]
    units: dict[str, str | None]
    path: str | None = None
    lines: tuple[int, ...] | None = None
    header_line: int | None = None

    def __post_init__(self):
        lengths = {np.shape(v)[0] for v in self.columns.values() if np.ndim(v) == 1}
        if any(np.ndim(v) != 1 for v in self.columns.values()) or len(lengths) > 1:
            raise ValueError("Table columns must be 1-D arrays of one common length.")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.columns)

    @property
    def n_rows(self) -> int:
        return len(next(iter(self.columns.values()))) if self.columns else 0

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def __contains__(self, name: str) -> bool:
        return name in self.columns

    def where(self, row: int) -> tuple[str, int | None]:
        """A phrase locating row `row` (0-based) for error messages, and its source line."""
        if self.lines is not None and row < len(self.lines):
            return f"row {row + 1} (line {self.lines[row]})", self.lines[row]
        return f"row {row + 1}", None


_HEADER_RE = re.compile(r"^(.*?)\s*\[([^\[\]]*)\]\s*$")


def split_header(text: str) -> tuple[str, str | None]:
    """`'fz [kN]'` → `('fz', 'kN')`; a name without brackets has no unit."""
    match = _HEADER_RE.match(text.strip())
    if match and match.group(1):
        unit = match.group(2).strip()
        return match.group(1), unit or None
    return text.strip(), None


def _header(name: str, unit: str | None) -> str:
    return f"{name} [{unit}]" if unit else name


def table_format(path) -> str:
    """'csv' or 'parquet', from the suffix of `path`; `ModelFileError` for any other."""
    suffix = os.path.splitext(str(path))[1].lower()
    if suffix in (".csv", ".txt"):
        return "csv"
    if suffix in (".parquet", ".pq"):
        return "parquet"
    raise ModelFileError(
        f"unknown table format '{suffix or '(no suffix)'}'; use a .csv or .parquet file.",
        path=path,
    )


def read_table(path) -> Table:
    """Read a CSV or Parquet table (format from the suffix: `.csv`, `.parquet`/`.pq`).

    **Returns:** a `Table` (float64 columns, units from the CSV header or the Parquet field
    metadata).

    **Raises:** `ModelFileError` naming the file, the line (CSV) and the column for anything it
    cannot read: text in a number column, a ragged row, a duplicate or empty column name, an
    unknown unit, a file that is not CSV/Parquet. `FileNotFoundError` if there is no file.
    """
    kind = table_format(path)
    if kind == "csv":
        return _read_csv(read_input(path, "table", "table"), path)
    check_input(path, "table", "table")
    return _read_parquet(path)


def decode_text(data: bytes, path) -> str:
    """UTF-8 text of a file's bytes (a BOM dropped); `ModelFileError` at the first bad byte."""
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = data[: e.start].count(b"\n") + 1
        raise ModelFileError(
            f"byte {data[e.start]:#04x} is not UTF-8 text; save the file as UTF-8.",
            path=path, line=line,
        ) from None


def csv_cells(data: bytes, path, header_hint: str):
    """The header cells, its line, the rows of cells and their lines of a CSV file's bytes
    (blank rows and rows starting with '#' skipped); `header_hint` says what the header names
    in the error for a file without one."""
    text = decode_text(data, path)
    reader = csv.reader(io.StringIO(text, newline=""), strict=True)
    header = None
    rows: list[list[str]] = []
    lines: list[int] = []
    try:
        for row in reader:
            if not row or all(not c.strip() for c in row) or row[0].lstrip().startswith("#"):
                continue
            if header is None:
                header = (row, reader.line_num)
            else:
                rows.append(row)
                lines.append(reader.line_num)
    except csv.Error as e:
        raise ModelFileError(f"not a valid CSV row ({e}).", path=path,
                             line=max(reader.line_num, 1)) from None
    if header is None:
        raise ModelFileError(f"the table is empty; expected a header row {header_hint}.",
                             path=path, line=1)
    return header[0], header[1], rows, lines


def _read_csv(data: bytes, path) -> Table:
    cells, header_line, rows, lines = csv_cells(
        data, path, "of column names, e.g. 'contact_patch.fz [N],contact_patch.fy [N]'")
    names, units = [], {}
    for c, cell in enumerate(cells):
        name, unit = split_header(cell)
        if not name:
            raise ModelFileError(f"column {c + 1} has no name.", path=path, line=header_line)
        if name in units:
            raise ModelFileError(f"column '{name}' appears twice.", path=path, line=header_line,
                                 field=name)
        _check_unit(unit, path, header_line, name)
        names.append(name)
        units[name] = unit
    values = np.empty((len(rows), len(names)))
    for r, (row, line) in enumerate(zip(rows, lines, strict=True)):
        if len(row) != len(names):
            raise ModelFileError(
                f"the row has {len(row)} values but the header names {len(names)} columns.",
                path=path, line=line,
            )
        for c, cell in enumerate(row):
            values[r, c] = _number(cell, path, line, names[c])
    return Table(
        columns={n: values[:, c].copy() for c, n in enumerate(names)},
        units=units, path=str(path), lines=tuple(lines), header_line=header_line,
    )


def _number(cell: str, path, line, column) -> float:
    text = cell.strip()
    if not text:
        raise ModelFileError(f"empty cell in column '{column}'; give a number.", path=path,
                             line=line, field=column)
    try:
        return float(text)
    except ValueError:
        shown = text if len(text) <= 40 else text[:37] + "..."
        raise ModelFileError(
            f"'{shown}' in column '{column}' is not a number.", path=path, line=line,
            field=column,
        ) from None


def _check_unit(unit, path, line, name):
    try:
        parse_unit(unit)
    except ValueError as e:
        raise ModelFileError(f"column '{name}': {e}.", path=path, line=line, field=name) from None


def _read_parquet(path) -> Table:
    import pyarrow.parquet as pq

    if not os.path.exists(path):
        raise FileNotFoundError(2, "No such file or directory", str(path))
    try:
        arrow = pq.read_table(path)
    except Exception as e:  # pyarrow raises several types for a damaged file
        raise ModelFileError(f"not a readable Parquet file ({type(e).__name__}: {e}).",
                             path=path) from None
    try:
        columns, units = _parquet_columns(arrow, path)
    except ModelFileError:
        raise
    except Exception as e:  # a damaged file can fail on any access (names, metadata, data)
        raise ModelFileError(f"not a readable Parquet file ({type(e).__name__}: {e}).",
                             path=path) from None
    return Table(columns=columns, units=units, path=str(path))


def _parquet_columns(arrow, path):
    import pyarrow as pa

    columns, units = {}, {}
    for field, column in zip(arrow.schema, arrow.columns, strict=True):
        field_name = field.name
        unit = None
        if field.metadata and b"unit" in field.metadata:
            try:
                unit = field.metadata[b"unit"].decode("utf-8").strip() or None
            except UnicodeDecodeError:
                raise ModelFileError(f"column '{field_name}': its unit is not UTF-8 text.",
                                     path=path, field=field_name) from None
            name = field_name
        else:
            name, unit = split_header(field_name)
        if not name:
            raise ModelFileError("a column has no name.", path=path)
        if name in columns:
            raise ModelFileError(f"column '{name}' appears twice.", path=path, field=name)
        _check_unit(unit, path, None, name)
        t = field.type
        if not (pa.types.is_integer(t) or pa.types.is_floating(t) or pa.types.is_boolean(t)):
            raise ModelFileError(
                f"column '{name}' holds {t}, not numbers; a table column must be numeric.",
                path=path, field=name,
            )
        if column.null_count:
            row = int(np.flatnonzero(np.asarray(column.is_null()))[0])
            raise ModelFileError(f"column '{name}' has no value in row {row + 1}.", path=path,
                                 field=name)
        columns[name] = np.asarray(column.to_numpy(), dtype=np.float64).copy()
        units[name] = unit
    return columns, units


def _format(value) -> str:
    """Shortest text that reads back to the same float (integers without '.0')."""
    v = float(value)
    if v.is_integer() and abs(v) < 2.0**53 and not (v == 0 and math.copysign(1.0, v) < 0):
        return str(int(v))
    return repr(v)


class TableWriter:
    """A table written as its rows come (CSV or Parquet, format from the suffix), so that a
    long run interrupted half-way leaves the rows finished so far in a readable file.

    CSV rows are flushed after every `append`; Parquet gets one row group per `append` and its
    footer at `close` (a `with` block closes it even on an exception or an interruption).
    Columns are float64, written as `write_table` writes them.
    """

    def __init__(self, path, names, units: Mapping | None = None):
        self.path, self.kind = path, table_format(path)
        self.names = tuple(str(n) for n in names)
        self.units = dict(units or {})
        self.rows = 0
        for name in self.names:
            if _HEADER_RE.match(name) or "\n" in name or "\r" in name:
                raise ValueError(f"TableWriter: column name {name!r} cannot hold a unit or a "
                                 "newline.")
        if self.kind == "csv":
            self._file = open(path, "w", newline="", encoding="utf-8")  # noqa: SIM115
            self._csv = csv.writer(self._file, lineterminator="\n")
            self._csv.writerow([_header(n, self.units.get(n)) for n in self.names])
            self._file.flush()
        else:
            import pyarrow as pa
            import pyarrow.parquet as pq

            self._schema = pa.schema([
                pa.field(n, pa.float64(),
                         metadata={"unit": self.units[n]} if self.units.get(n) else None)
                for n in self.names])
            self._parquet = pq.ParquetWriter(path, self._schema)

    def append(self, columns: Mapping) -> None:
        """Write rows: `columns` maps every name to a 1-D array (one common length)."""
        arrays = [np.asarray(columns[n], dtype=np.float64).reshape(-1) for n in self.names]
        if len({a.shape for a in arrays}) > 1:
            raise ValueError("TableWriter.append: columns of different lengths.")
        if self.kind == "csv":
            for row in zip(*arrays, strict=True):
                self._csv.writerow([_format(v) for v in row])
            self._file.flush()
        else:
            import pyarrow as pa

            self._parquet.write_table(pa.Table.from_arrays(
                [pa.array(a) for a in arrays], schema=self._schema))
        self.rows += len(arrays[0]) if arrays else 0

    def close(self) -> None:
        if self.kind == "csv":
            self._file.close()
        else:
            self._parquet.close()

    def __enter__(self):
        return self

    def __exit__(self, kind, value, tb):
        if kind is not None and self.kind == "csv" and not self._file.closed:
            # the rows so far stay readable; the mark says the table is not complete (a
            # reader skips '#' lines)
            try:
                self._file.write(f"# INCOMPLETE: {self.rows} rows written, then "
                                 f"{kind.__name__}\n")
            except OSError:
                pass
        self.close()
        return False


def write_table(path, columns: Mapping, units: Mapping | None = None) -> None:
    """Write columns to CSV or Parquet (format from the suffix).

    **Arguments:** `columns`: name → 1-D array-like (all the same length), written as float64
    (CSV with every digit needed to read the same float back); `units`: name → unit string (or
    None), written in the CSV header as `name [unit]` and as Parquet field metadata `unit`.
    """
    kind = table_format(path)
    units = dict(units or {})
    arrays = {str(k): np.asarray(v, dtype=np.float64) for k, v in columns.items()}
    if any(a.ndim != 1 for a in arrays.values()) or len({a.shape for a in arrays.values()}) > 1:
        raise ValueError("write_table: columns must be 1-D arrays of one common length.")
    for name in arrays:
        if _HEADER_RE.match(name) or "\n" in name or "\r" in name:
            raise ValueError(f"write_table: column name {name!r} cannot hold a unit or a newline.")
    # Through a temporary file renamed at the end: an interrupted or failed write never leaves
    # a table cut after whole rows under the final name.
    if kind == "csv":
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow([_header(n, units.get(n)) for n in arrays])
        for row in zip(*arrays.values(), strict=True):
            writer.writerow([_format(v) for v in row])
        write_text_atomic(path, buf.getvalue())
        return
    import tempfile

    import pyarrow as pa
    import pyarrow.parquet as pq

    fields = [
        pa.field(n, pa.float64(), metadata={"unit": units[n]} if units.get(n) else None)
        for n in arrays
    ]
    table = pa.Table.from_arrays([pa.array(a) for a in arrays.values()],
                                 schema=pa.schema(fields))
    folder = os.path.dirname(os.path.abspath(os.fspath(path)))
    fd, tmp = tempfile.mkstemp(prefix=f".{os.path.basename(os.fspath(path))}.", dir=folder)
    os.close(fd)
    try:
        pq.write_table(table, tmp)
        os.chmod(tmp, 0o666 & ~current_umask())  # a plain open's permissions, not mkstemp's 0600
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


# ---------------------------------------------------------------------------------- load cases

_COMPONENTS = ("fx", "fy", "fz", "mx", "my", "mz")


def load_columns(mech) -> dict[str, str]:
    """Valid load-case columns of `mech` → their dimension ('force', 'moment', 'length')."""
    valid = {}
    for name in mech.load_points.names:
        for comp in _COMPONENTS:
            valid[f"{name}.{comp}"] = "force" if comp[0] == "f" else "moment"
    for name in mech.drivers.names:
        valid[name] = "length"
    shorthand = _shorthand_point(mech)
    if shorthand is not None:
        for comp in _COMPONENTS:
            valid.setdefault(comp, "force" if comp[0] == "f" else "moment")
    return valid


def _shorthand_point(mech) -> str | None:
    names = mech.load_points.names
    if len(names) == 1:
        return names[0]
    if "contact_patch" in names:
        return "contact_patch"
    return None


def loads_from_table(mech, table: Table):
    """`Loads` of every row of a load-case table (see the module docstring for the columns).

    **Arguments:** `mech`: the mechanism; `table`: a `Table` (e.g. from `read_table`).

    **Returns:** `Loads` with a leading case axis (one case per row), N, N·mm and mm, components
    in each load point's frame.

    **Raises:** `ModelFileError` for unknown columns (naming them and listing the valid ones), a
    unit of the wrong dimension, a component given twice (shorthand and full name), a non-finite
    value (naming its row and line), or a table without rows.
    """
    import jax.numpy as jnp

    path = table.path
    valid = load_columns(mech)
    names = [n for n in table.names if n != "case"]
    unknown = [n for n in names if n not in valid]
    if unknown:
        raise ModelFileError(
            f"unknown column{'s' if len(unknown) > 1 else ''} "
            f"{', '.join(repr(u) for u in unknown)} for model '{mech.name}'; valid columns: "
            f"{', '.join(valid) or '(none: the model has no load point or driver)'}"
            f"{', case' if valid else ''}.",
            path=path, line=table.header_line, field=unknown[0],
        )
    if table.n_rows == 0:
        raise ModelFileError("the table has no rows; give one row per load case.", path=path,
                             line=table.header_line)
    point = _shorthand_point(mech)
    n_cases, n_l, n_d = table.n_rows, len(mech.load_points.names), len(mech.drivers.names)
    force = np.zeros((n_cases, n_l, 3))
    moment = np.zeros((n_cases, n_l, 3))
    driver = np.zeros((n_cases, n_d))
    given = {}
    for name in names:
        try:
            factor = unit_factor(table.units.get(name), valid[name])
        except ValueError as e:
            raise ModelFileError(
                f"column '{name}': {e}; it needs a {valid[name]} unit.", path=path,
                line=table.header_line, field=name,
            ) from None
        values = np.asarray(table[name], dtype=np.float64)
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            where, line = table.where(int(bad[0]))
            raise ModelFileError(
                f"column '{name}' has {values[bad[0]]} in {where}; every load must be finite.",
                path=path, line=line, field=name,
            )
        values = values * factor if factor != 1.0 else values
        if name in mech.drivers.names:
            driver[:, mech.drivers.names.index(name)] = values
            continue
        lp, _, comp = name.rpartition(".") if "." in name else (point, "", name)
        key = (lp, comp)
        if key in given:
            raise ModelFileError(
                f"columns '{given[key]}' and '{name}' both give {comp} at '{lp}'; keep one.",
                path=path, line=table.header_line, field=name,
            )
        given[key] = name
        i, a = mech.load_points.names.index(lp), _COMPONENTS.index(comp)
        target = force if a < 3 else moment
        target[:, i, a % 3] = values
    return Loads(force=jnp.asarray(force), moment=jnp.asarray(moment), driver=jnp.asarray(driver))


# ------------------------------------------------------------------------------------- results

FLAG_COLUMNS = ("stable", "law_valid")
"""Result columns after `status`: 1 where the equilibrium is stable (reduced tangent stiffness
positive definite) / every bushing's projected angles are within their law's validity, 0
otherwise and for cases that did not converge, were not solved, or a solution without the flags
(`diffsusp.statics.checks`)."""


def results_table(mech, sol, loads: Table | None = None, *, first_case: int = 0,
                  bushings=None, springs=None) -> Table:
    """One row per load case and a column per output of a batched `StaticSolution`.

    Columns (library units): `case` (0-based), the load columns of `loads` (converted to N,
    N·mm, mm), `status` (the codes of `diffsusp.statics.Status`), `stable` and `law_valid`
    (see `FLAG_COLUMNS`), `iterations`, `residual` (largest force row relative to the load
    scale), `constraint_error` (mm); per part `<part>.x`, `.y`, `.z` (mm,
    translation of the part frame, which is the global frame at design) and `.gx`, `.gy`,
    `.gz` (Gibbs vector of its rotation from design); per bushing `<bushing>.dx` … `.dz`
    (deformation, mm, in J), `.ax` … `.az` (projected angles, rad), `.fx` … `.fz` (N) and
    `.tx` … `.tz` (N·mm) on the I part in J axes; per spring `<spring>.length` (mm) and
    `.tension` (N). `first_case`: the number of the first row (a chunk of a longer table).

    The element columns are formatted, not computed, here (io depends on `diffsusp.model`
    only): `bushings` is `diffsusp.statics.bushing_states(mech, sol.q)` and `springs`
    `diffsusp.statics.spring_states(mech, sol.q)`, required when the model has bushings /
    springs.
    """
    q = np.asarray(sol.q)
    if q.ndim != 2:
        raise ValueError("results_table needs a solution with a leading case axis.")
    n = q.shape[0]
    columns: dict[str, np.ndarray] = {}
    units: dict[str, str | None] = {}

    def add(name, values, unit):
        if name in columns:
            raise ModelError(
                f"two outputs are named '{name}' (a part and an element share a name with "
                "clashing output columns); rename one of them.")
        columns[name] = np.asarray(values, dtype=np.float64).reshape(n)
        units[name] = unit

    add("case", first_case + np.arange(n), None)
    if loads is not None:
        library = {"force": "N", "moment": "N·mm", "length": "mm"}
        valid = load_columns(mech)
        for name in loads.names:
            if name in valid:
                add(name, loads[name] * unit_factor(loads.units.get(name), valid[name]),
                    library[valid[name]])
    add("status", sol.status, None)
    for flag in FLAG_COLUMNS:
        value = getattr(sol, flag, None)
        add(flag, np.zeros(n) if value is None else value, None)
    add("iterations", sol.iterations, None)
    add("residual", sol.residual, None)
    add("constraint_error", sol.constraint_error, "mm")
    for p, part in enumerate(mech.parts):
        for a, axis in enumerate("xyz"):
            add(f"{part}.{axis}", q[:, 6 * p + a], "mm")
        for a, axis in enumerate("xyz"):
            add(f"{part}.g{axis}", q[:, 6 * p + 3 + a], None)
    for given, names, arg in ((bushings, mech.bushings.names, "bushings=bushing_states"),
                              (springs, mech.springs.names, "springs=spring_states")):
        if names and given is None:
            raise ValueError(
                f"results_table: model '{mech.name}' has {len(names)} element(s) "
                f"({', '.join(names)}); pass {arg}(mech, sol.q) from diffsusp.statics.")
    if mech.bushings.names:
        states = [np.asarray(s) for s in bushings]
        for e, name in enumerate(mech.bushings.names):
            for state, prefix, unit in zip(states, "daft", ("mm", "rad", "N", "N·mm"),
                                           strict=True):
                for a, axis in enumerate("xyz"):
                    add(f"{name}.{prefix}{axis}", state[:, e, a], unit)
    if mech.springs.names:
        length, tension = (np.asarray(s) for s in springs)
        for e, name in enumerate(mech.springs.names):
            add(f"{name}.length", length[:, e], "mm")
            add(f"{name}.tension", tension[:, e], "N")
    return Table(columns=columns, units=units)

