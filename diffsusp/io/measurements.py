"""Measurement tables (CSV or Parquet): what a bench and a measuring arm give, per load case.

One row per case and landmark (a **landmark table**) or per case and part (a **pose table**).
The format is recognised from the columns. Columns may carry a unit in brackets (`x [mm]`,
`psi [deg]`, `contact_patch.fz [kN]`; units of `diffsusp.io.tables.parse_unit`); without one,
lengths are mm, forces N, moments N·mm and angles **degrees** (as in Adams result files).

**Landmark table** (poses by registration, spec geometry §3.3–3.6):

| column | meaning |
|---|---|
| `case` | case label (text or number); cases are taken in order of first appearance |
| `part` | a moving part of the model |
| `landmark` | the landmark's name (unique within its part) |
| `x`, `y`, `z` | the landmark measured in the global frame (mm); empty or `nan`: not measured |
| `x0`, `y0`, `z0` | the landmark at design (mm; part frame = global frame at design) |
| `weight` | optional: 1 to use the landmark, 0 to exclude it |

A landmark's design position is the same on every row where it appears.

**Pose table**: `case`, `part`, `x`, `y`, `z` (where the part frame's origin — the point at the
global origin at design — has moved, mm) and `psi`, `theta`, `phi` (the part's rotation from
design as Adams REULER z-x-z angles, degrees: R = Rz(ψ)·Rx(θ)·Rz(φ)).

**Loads**, in both formats: the load-case columns of `diffsusp.io.tables` (`<load point>.fx`
… `.mz`, `<driver>`, or `fx` … `mz` for the model's contact patch / only load point), in the
load point's frame. A case's loads are repeated on its rows; empty cells take the value given
on another row of the same case, and different values within a case are an error.

Everything read is checked: a missing column, text in a number column, non-finite coordinates
of a reference landmark, a landmark or pose given twice, loads that disagree within a case —
each a `ModelFileError` naming the file, the line (CSV) and the column.

This module reads and writes the cells (`read_measurement_rows`, `write_measurement_rows`);
`diffsusp.measure.read_measurements` and `write_measurements` turn them into `Measurements`
(registering the poses from the landmarks) and back.
"""

import csv
import math
import os

import numpy as np

from ..errors import ModelFileError
from ..geometry import DEG
from ..model.mechanism import Loads, Mechanism
from .files import check_input, read_input
from .tables import Table, csv_cells, loads_from_table, split_header, unit_factor

LANDMARK_COLUMNS = ("case", "part", "landmark", "x", "y", "z", "x0", "y0", "z0")
POSE_COLUMNS = ("case", "part", "x", "y", "z", "psi", "theta", "phi")
TEXT_COLUMNS = ("case", "part", "landmark")
LENGTH_COLUMNS = ("x", "y", "z", "x0", "y0", "z0")
ANGLE_COLUMNS = ("psi", "theta", "phi")
LENGTH_LIMIT = 1e6
"""Largest |coordinate| read (mm: 1 km); larger is a typo or a damaged file."""
ANGLE_LIMIT = 1e4
"""Largest |angle| read (rad, ~1600 turns)."""
LOAD_LIMIT = 1e12
"""Largest |load| read (N, N·mm, mm for drivers)."""


class MeasurementRows:
    """A measurement table as read: its column names, their units (None: the default of
    the column), text cells (str) row by row, the source line of each row (CSV) and the path;
    its methods read the cells as numbers, labels and loads, each error a `ModelFileError`
    naming the line and the column."""

    def __init__(self, names, units, rows, lines, path):
        self.names, self.units, self.rows, self.lines, self.path = names, units, rows, lines, path

    def where(self, r):
        return None if self.lines is None else self.lines[r]

    def column(self, name):
        c = self.names.index(name)
        return [row[c] for row in self.rows]

    def numbers(self, name, factor=1.0, allow_empty=False, limit=None, unit=""):
        """The column as floats times `factor`; beyond ±`limit` (library units: a typo or a
        corrupted file, e.g. 1e300) is an error naming the line and the column."""
        out = np.empty(len(self.rows))
        for r, cell in enumerate(self.column(name)):
            text = "" if cell is None else str(cell).strip()
            if not text:
                if allow_empty:
                    out[r] = np.nan
                    continue
                raise ModelFileError(f"empty cell in column '{name}'; give a number.",
                                     path=self.path, line=self.where(r), field=name)
            try:
                out[r] = float(text) * factor
            except ValueError:
                shown = text if len(text) <= 40 else text[:37] + "..."
                raise ModelFileError(f"'{shown}' in column '{name}' is not a number.",
                                     path=self.path, line=self.where(r), field=name) from None
            if limit is not None and abs(out[r]) > limit:
                raise ModelFileError(
                    f"{text} in column '{name}' (column {self.names.index(name) + 1}) is "
                    f"beyond ±{limit:g} {unit}; check the value and its unit.".replace(
                        "  ", " "), path=self.path, line=self.where(r), field=name)
        return out

    def text(self, name: str) -> list[str]:
        """The column as labels; an empty cell is an error."""
        out = [("" if c is None else str(c).strip()) for c in self.column(name)]
        for r, v in enumerate(out):
            if not v:
                raise ModelFileError(f"empty cell in column '{name}'.", path=self.path,
                                     line=self.where(r), field=name)
        return out

    def factor(self, name: str, dimension: str) -> float:
        """The factor of column `name` to library units (an angle without a unit: degrees)."""
        unit = self.units.get(name)
        if dimension == "angle" and unit is None:
            return DEG  # degrees, as in Adams result files
        try:
            return unit_factor(unit, dimension)
        except ValueError as e:
            raise ModelFileError(f"column '{name}': {e}; it needs a {dimension} unit.",
                                 path=self.path, line=1 if self.lines else None,
                                 field=name) from None

    def cases(self) -> tuple[list[str], list[str]]:
        """The case label of every row, and the cases in order of first appearance."""
        labels = [("" if c is None else str(c).strip()) for c in self.column("case")]
        for r, label in enumerate(labels):
            if not label:
                raise ModelFileError("empty cell in column 'case'; every row needs its case.",
                                     path=self.path, line=self.where(r), field="case")
        order = list(dict.fromkeys(labels))
        return labels, order

    def case_loads(self, mech: Mechanism, labels, order, known) -> Loads:
        """Per-case loads from the load columns (every column not in `known`: one value per
        case, repeated on its rows; empty cells take the value of another row of the case)."""
        columns, units = {}, {}
        rows_of = {case: [] for case in order}  # one pass: linear in the rows
        for r, c in enumerate(labels):
            rows_of[c].append(r)
        for name in self.names:
            if name in known:
                continue
            values = self.numbers(name, allow_empty=True, limit=LOAD_LIMIT)
            per_case = np.zeros(len(order))
            for k, case in enumerate(order):
                rows = rows_of[case]
                given = [(r, values[r]) for r in rows if np.isfinite(values[r])]
                if not given:
                    raise ModelFileError(f"column '{name}' has no value for case '{case}'.",
                                         path=self.path, line=self.where(rows[0]), field=name)
                r0, v0 = given[0]
                for r, v in given[1:]:
                    if not math.isclose(v, v0, rel_tol=1e-12, abs_tol=1e-12):
                        raise ModelFileError(
                            f"column '{name}' has {v0:g} and {v:g} in case '{case}'; a case's "
                            "loads must be the same on all its rows.", path=self.path,
                            line=self.where(r), field=name)
                per_case[k] = v0
            columns[name] = per_case
            units[name] = self.units.get(name)
        if not columns:
            raise ModelFileError(
                "the table has no load columns; give the loads of each case (e.g. "
                "'contact_patch.fz [N]', or fx, fy, fz, mx, my, mz).", path=self.path,
                line=1 if self.lines else None)
        return loads_from_table(mech, Table(columns=columns, units=units, path=self.path))

    def require(self, columns) -> None:
        """Raise for a missing column, naming both formats' columns."""
        missing = [c for c in columns if c not in self.names]
        if missing:
            raise ModelFileError(
                f"missing column{'s' if len(missing) > 1 else ''} "
                f"{', '.join(map(repr, missing))}; a landmark table has "
                f"{', '.join(LANDMARK_COLUMNS)} (+ weight, loads) and a pose table "
                f"{', '.join(POSE_COLUMNS)} (+ loads).", path=self.path,
                line=1 if self.lines else None, field=missing[0])

    def check_parts(self, mech: Mechanism, parts) -> None:
        """Every part of the table is a moving part of the model (named, with its line)."""
        known = set(mech.parts)
        for r, part in enumerate(parts):
            if part not in known:
                raise ModelFileError(
                    f"part '{part}' is not a moving part of model '{mech.name}'; its parts: "
                    f"{', '.join(mech.parts) or 'none'}.", path=self.path, line=self.where(r),
                    field="part")


def read_measurement_rows(path) -> MeasurementRows:
    """Read a measurement table (.csv, .txt or .parquet) as text cells, with the units of its
    column headers (`x [mm]`) or Parquet field metadata."""
    path = os.fspath(path)
    suffix = os.path.splitext(path)[1].lower()
    if suffix in (".csv", ".txt"):
        cells, header_line, rows, lines = csv_cells(
            read_input(path, "measurement table", "table"), path,
            f"({', '.join(LANDMARK_COLUMNS)}, and load columns)")
        for r, row in enumerate(rows):
            if len(row) != len(cells):
                raise ModelFileError(f"the row has {len(row)} values but the header names "
                                     f"{len(cells)} columns.", path=path, line=lines[r])
        names, units = [], {}
        for cell in cells:
            name, unit = split_header(cell)
            if not name or name in units:
                raise ModelFileError(f"column name {cell!r} is empty or repeated.", path=path,
                                     line=header_line)
            names.append(name)
            units[name] = unit
        return MeasurementRows(names, units, rows, lines, path)
    if suffix in (".parquet", ".pq"):
        import pyarrow.parquet as pq

        check_input(path, "measurement table", "table")
        try:
            arrow = pq.read_table(path)
            names, units, columns = [], {}, []
            for field, column in zip(arrow.schema, arrow.columns, strict=True):
                if field.metadata and b"unit" in field.metadata:
                    name, unit = field.name, field.metadata[b"unit"].decode() or None
                else:
                    name, unit = split_header(field.name)
                names.append(name)
                units[name] = unit
                columns.append(column.to_pylist())
        except Exception as e:  # pyarrow raises many types for a damaged file
            raise ModelFileError(f"not a readable Parquet file ({type(e).__name__}: {e}).",
                                 path=path) from None
        rows = [list(r) for r in zip(*columns, strict=True)] if columns else []
        return MeasurementRows(names, units, rows, None, path)
    raise ModelFileError(f"unknown table format '{suffix or '(no suffix)'}'; use a .csv or "
                         ".parquet file.", path=path)


def write_measurement_rows(path, header, units, rows) -> None:
    """Write a measurement table: column names `header`, their `units` ('' for none), and
    `rows` (text for the `TEXT_COLUMNS`, numbers otherwise), CSV or Parquet by the suffix."""
    titles = [f"{h} [{u}]" if u else h for h, u in zip(header, units, strict=True)]
    path = os.fspath(path)
    suffix = os.path.splitext(path)[1].lower()
    if suffix in (".csv", ".txt"):
        with open(path, "w", newline="", encoding="utf-8") as f:
            out = csv.writer(f)
            out.writerow(titles)
            for row in rows:
                out.writerow([v if isinstance(v, str) else repr(float(v)) for v in row])
    elif suffix in (".parquet", ".pq"):
        import pyarrow as pa
        import pyarrow.parquet as pq

        fields, arrays = [], []
        for k, (h, u) in enumerate(zip(header, units, strict=True)):
            values = [row[k] for row in rows]
            text = h in TEXT_COLUMNS
            fields.append(pa.field(h, pa.string() if text else pa.float64(),
                                   metadata={"unit": u} if u else None))
            arrays.append(pa.array(values if text else [float(v) for v in values],
                                   type=pa.string() if text else pa.float64()))
        pq.write_table(pa.Table.from_arrays(arrays, schema=pa.schema(fields)), path)
    else:
        raise ModelFileError(f"unknown table format '{suffix or '(no suffix)'}'; use a .csv "
                             "or .parquet file.", path=path)
