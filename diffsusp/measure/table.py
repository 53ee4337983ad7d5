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
"""

import csv
import io
import math
import os

import jax.numpy as jnp
import numpy as np

from ..errors import InputError, ModelFileError
from ..model.mechanism import Mechanism
from .landmarks import LandmarkLayout, check_layout
from .measurements import Measurements, from_landmarks, from_poses

LANDMARK_COLUMNS = ("case", "part", "landmark", "x", "y", "z", "x0", "y0", "z0")
POSE_COLUMNS = ("case", "part", "x", "y", "z", "psi", "theta", "phi")
_TEXT = ("case", "part", "landmark")
_LENGTH = ("x", "y", "z", "x0", "y0", "z0")
_ANGLE = ("psi", "theta", "phi")
LENGTH_LIMIT = 1e6
"""Largest |coordinate| read (mm: 1 km); larger is a typo or a damaged file."""
ANGLE_LIMIT = 1e4
"""Largest |angle| read (rad, ~1600 turns)."""
LOAD_LIMIT = 1e12
"""Largest |load| read (N, N·mm, mm for drivers)."""


class _Raw:
    """Columns as read: text cells (str) with their units, and the source line of each row."""

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


def _read_raw(path) -> _Raw:
    from ..io.tables import split_header

    path = os.fspath(path)
    suffix = os.path.splitext(path)[1].lower()
    from ..io.files import check_input, read_input

    if suffix in (".csv", ".txt"):
        data = read_input(path, "measurement table", "table")
        try:
            text = data.decode("utf-8-sig")
        except UnicodeDecodeError:
            raise ModelFileError("not UTF-8 text; save the table as UTF-8 CSV.",
                                 path=path) from None
        reader = csv.reader(io.StringIO(text, newline=""), strict=True)
        header, rows, lines = None, [], []
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
            raise ModelFileError("the table is empty; expected a header row "
                                 f"({', '.join(LANDMARK_COLUMNS)}, and load columns).",
                                 path=path, line=1)
        cells, header_line = header
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
        return _Raw(names, units, rows, lines, path)
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
        return _Raw(names, units, rows, None, path)
    raise ModelFileError(f"unknown table format '{suffix or '(no suffix)'}'; use a .csv or "
                         ".parquet file.", path=path)


def _factor(raw: _Raw, name: str, dimension: str) -> float:
    from ..io.tables import unit_factor

    unit = raw.units.get(name)
    if dimension == "angle" and unit is None:
        return math.pi / 180.0  # degrees, as in Adams result files
    try:
        return unit_factor(unit, dimension)
    except ValueError as e:
        raise ModelFileError(f"column '{name}': {e}; it needs a {dimension} unit.",
                             path=raw.path, line=1 if raw.lines else None, field=name) from None


def _cases(raw: _Raw):
    labels = [("" if c is None else str(c).strip()) for c in raw.column("case")]
    for r, label in enumerate(labels):
        if not label:
            raise ModelFileError("empty cell in column 'case'; every row needs its case.",
                                 path=raw.path, line=raw.where(r), field="case")
    order = list(dict.fromkeys(labels))
    return labels, order


def _loads(raw: _Raw, mech: Mechanism, labels, order, known):
    """Per-case loads from the load columns (one value per case, repeated on its rows)."""
    from ..io.tables import Table, loads_from_table

    columns, units = {}, {}
    rows_of = {case: [] for case in order}  # one pass: linear in the rows
    for r, c in enumerate(labels):
        rows_of[c].append(r)
    for name in raw.names:
        if name in known:
            continue
        values = raw.numbers(name, allow_empty=True, limit=LOAD_LIMIT)
        per_case = np.zeros(len(order))
        for k, case in enumerate(order):
            rows = rows_of[case]
            given = [(r, values[r]) for r in rows if np.isfinite(values[r])]
            if not given:
                raise ModelFileError(f"column '{name}' has no value for case '{case}'.",
                                     path=raw.path, line=raw.where(rows[0]), field=name)
            r0, v0 = given[0]
            for r, v in given[1:]:
                if not math.isclose(v, v0, rel_tol=1e-12, abs_tol=1e-12):
                    raise ModelFileError(
                        f"column '{name}' has {v0:g} and {v:g} in case '{case}'; a case's "
                        "loads must be the same on all its rows.", path=raw.path,
                        line=raw.where(r), field=name)
            per_case[k] = v0
        columns[name] = per_case
        units[name] = raw.units.get(name)
    if not columns:
        raise ModelFileError(
            "the table has no load columns; give the loads of each case (e.g. "
            "'contact_patch.fz [N]', or fx, fy, fz, mx, my, mz).", path=raw.path,
            line=1 if raw.lines else None)
    return loads_from_table(mech, Table(columns=columns, units=units, path=raw.path))


def _require(raw: _Raw, columns):
    missing = [c for c in columns if c not in raw.names]
    if missing:
        raise ModelFileError(
            f"missing column{'s' if len(missing) > 1 else ''} {', '.join(map(repr, missing))}; "
            f"a landmark table has {', '.join(LANDMARK_COLUMNS)} (+ weight, loads) and a pose "
            f"table {', '.join(POSE_COLUMNS)} (+ loads).", path=raw.path,
            line=1 if raw.lines else None, field=missing[0])


def read_measurements(path, mech: Mechanism, *, reorder: bool = False,
                      tolerance: float = 0.5) -> Measurements:
    """Read a landmark or pose table (see the module docstring) for model `mech`.

    **Arguments:** `path` (.csv or .parquet); `mech` (load points and drivers of the load
    columns); `reorder`, `tolerance`: match landmarks probed in an unknown order by their
    distance tables (spec geometry §3.5).

    **Returns:** `Measurements` (poses registered from the landmarks, or as given).

    **Raises:** `ModelFileError` (bad file, naming line and column), `InputError` (e.g. a part
    with fewer than three usable landmarks in a case), `FileNotFoundError`.
    """
    raw = _read_raw(path)
    if not raw.rows:
        raise ModelFileError("the table has no rows; give one row per case and landmark.",
                             path=raw.path, line=1 if raw.lines else None)
    if "landmark" in raw.names:
        return _landmark_table(raw, mech, reorder, tolerance)
    _require(raw, POSE_COLUMNS)
    return _pose_table(raw, mech)


def _text(raw: _Raw, name):
    out = [("" if c is None else str(c).strip()) for c in raw.column(name)]
    for r, v in enumerate(out):
        if not v:
            raise ModelFileError(f"empty cell in column '{name}'.", path=raw.path,
                                 line=raw.where(r), field=name)
    return out


def _landmark_table(raw: _Raw, mech, reorder, tolerance) -> Measurements:
    _require(raw, LANDMARK_COLUMNS)
    labels, order = _cases(raw)
    parts = _text(raw, "part")
    names = _text(raw, "landmark")
    xyz = np.stack([raw.numbers(c, _factor(raw, c, "length"), allow_empty=True,
                                limit=LENGTH_LIMIT, unit="mm") for c in ("x", "y", "z")], axis=1)
    ref = np.stack([raw.numbers(c, _factor(raw, c, "length"), limit=LENGTH_LIMIT, unit="mm")
                    for c in ("x0", "y0", "z0")], axis=1)
    weight = raw.numbers("weight", allow_empty=True) if "weight" in raw.names else None
    part_names = list(dict.fromkeys(parts))
    per_part = {p: list(dict.fromkeys(n for q, n in zip(parts, names, strict=True) if q == p))
                for p in part_names}
    k = max(len(v) for v in per_part.values())
    position = np.full((len(part_names), k, 3), np.nan)
    measured = np.full((len(order), len(part_names), k, 3), np.nan)
    weights = np.zeros((len(order), len(part_names), k))
    for p, part in enumerate(part_names):  # a landmark without a row in a case: not measured
        weights[:, p, : len(per_part[part])] = 1.0
    _known_parts(raw, mech, parts)
    seen = {}
    part_index = {p: k for k, p in enumerate(part_names)}
    case_index = {c: k for k, c in enumerate(order)}
    landmark_index = {p: {n: k for k, n in enumerate(v)} for p, v in per_part.items()}
    for r in range(len(raw.rows)):
        if not np.all(np.isfinite(ref[r])):
            raise ModelFileError("the design position (x0, y0, z0) of a landmark must be "
                                 "finite.", path=raw.path, line=raw.where(r), field="x0")
        p = part_index[parts[r]]
        a = landmark_index[parts[r]][names[r]]
        c = case_index[labels[r]]
        key = (c, p, a)
        if key in seen:
            raise ModelFileError(
                f"landmark '{names[r]}' of part '{parts[r]}' appears twice in case "
                f"'{labels[r]}' (also on line {raw.where(seen[key])}).", path=raw.path,
                line=raw.where(r), field="landmark")
        seen[key] = r
        if np.all(np.isfinite(position[p, a])):
            if np.max(np.abs(position[p, a] - ref[r])) > 1e-9 * (1 + np.abs(ref[r]).max()):
                raise ModelFileError(
                    f"landmark '{names[r]}' of part '{parts[r]}' has design position "
                    f"{ref[r].tolist()} here and {position[p, a].tolist()} on an earlier row; "
                    "it must be the same on every row.", path=raw.path, line=raw.where(r),
                    field="x0")
        position[p, a] = ref[r]
        measured[c, p, a] = xyz[r]
        weights[c, p, a] = 1.0 if weight is None or not np.isfinite(weight[r]) else weight[r]
    position = np.nan_to_num(position)
    layout = LandmarkLayout(position=jnp.asarray(position), parts=tuple(part_names),
                            names=tuple(tuple(per_part[p]) for p in part_names))
    check_layout(layout)
    loads = _loads(raw, mech, labels, order, set(LANDMARK_COLUMNS) | {"weight"})
    return from_landmarks(layout, measured, loads, weights=weights, reorder=reorder,
                          tolerance=tolerance, cases=order)


def _known_parts(raw: _Raw, mech, parts):
    """Every part of the table is a moving part of the model (named, with its line)."""
    known = set(mech.parts)
    for r, part in enumerate(parts):
        if part not in known:
            raise ModelFileError(
                f"part '{part}' is not a moving part of model '{mech.name}'; its parts: "
                f"{', '.join(mech.parts) or 'none'}.", path=raw.path, line=raw.where(r),
                field="part")


def _pose_table(raw: _Raw, mech) -> Measurements:
    from ..geometry import reuler_to_matrix

    labels, order = _cases(raw)
    parts = _text(raw, "part")
    xyz = np.stack([raw.numbers(c, _factor(raw, c, "length"), limit=LENGTH_LIMIT, unit="mm")
                    for c in ("x", "y", "z")], axis=1)
    angles = np.stack([raw.numbers(c, _factor(raw, c, "angle"), limit=ANGLE_LIMIT, unit="rad")
                       for c in _ANGLE], axis=1)
    part_names = list(dict.fromkeys(parts))
    part_index = {p: k for k, p in enumerate(part_names)}
    case_index = {c: k for k, c in enumerate(order)}
    rotation = np.full((len(order), len(part_names), 3, 3), np.nan)
    translation = np.full((len(order), len(part_names), 3), np.nan)
    for r in range(len(raw.rows)):
        for name, v in (("x", xyz[r]), ("psi", angles[r])):
            if not np.all(np.isfinite(v)):
                raise ModelFileError("a pose must be finite.", path=raw.path,
                                     line=raw.where(r), field=name)
        c, p = case_index[labels[r]], part_index[parts[r]]
        if np.isfinite(translation[c, p, 0]):
            raise ModelFileError(f"part '{parts[r]}' appears twice in case '{labels[r]}'.",
                                 path=raw.path, line=raw.where(r), field="part")
        translation[c, p] = xyz[r]
        rotation[c, p] = np.asarray(reuler_to_matrix(jnp.asarray(angles[r])))
    missing = np.argwhere(~np.isfinite(translation[..., 0]))
    if missing.size:
        c, p = missing[0]
        raise InputError(f"{raw.path}: no pose of part '{part_names[p]}' in case "
                         f"'{order[c]}'; every case needs the pose of every part.")
    _known_parts(raw, mech, parts)
    loads = _loads(raw, mech, labels, order, set(POSE_COLUMNS))
    return from_poses(tuple(part_names), rotation, translation, loads, cases=order)


def _load_columns(mech: Mechanism, meas: Measurements) -> dict[str, np.ndarray]:
    out = {}
    force, moment = np.asarray(meas.loads.force), np.asarray(meas.loads.moment)
    for i, name in enumerate(mech.load_points.names):
        for a, comp in enumerate("xyz"):
            if np.any(force[:, i, a] != 0):
                out[f"{name}.f{comp}"] = force[:, i, a]
            if np.any(moment[:, i, a] != 0):
                out[f"{name}.m{comp}"] = moment[:, i, a]
    for d, name in enumerate(mech.drivers.names):
        out[name] = np.asarray(meas.loads.driver)[:, d]
    if not out and mech.load_points.names:  # all loads zero: still say so
        out[f"{mech.load_points.names[0]}.fz"] = force[:, 0, 2]
    return out


def write_measurements(meas: Measurements, path, mech: Mechanism) -> None:
    """Write `meas` as a landmark table (if it has landmarks) or a pose table, CSV or Parquet
    (from the suffix), with the loads as `<load point>.fx` … columns of `mech` (N, N·mm)."""
    from ..geometry import matrix_to_reuler

    cases = meas.cases or tuple(str(c + 1) for c in range(meas.n_cases))
    loads = _load_columns(mech, meas)
    rows = []
    if meas.landmarks is not None:
        layout = meas.layout
        ref = np.asarray(layout.position)
        pts = np.asarray(meas.landmarks)
        w = np.asarray(meas.weights)
        header = [*LANDMARK_COLUMNS, "weight"]
        units = ["", "", "", "mm", "mm", "mm", "mm", "mm", "mm", ""]
        for c, case in enumerate(cases):
            for p, part in enumerate(layout.parts):
                for a, name in enumerate(layout.names[p]):
                    rows.append([case, part, name, *pts[c, p, a], *ref[p, a], w[c, p, a]]
                                + [v[c] for v in loads.values()])
    else:
        header = list(POSE_COLUMNS)
        units = ["", "", "mm", "mm", "mm", "deg", "deg", "deg"]
        rot, trans = np.asarray(meas.rotation), np.asarray(meas.translation)
        for c, case in enumerate(cases):
            for p, part in enumerate(meas.parts):
                angles = np.degrees(np.asarray(matrix_to_reuler(jnp.asarray(rot[c, p]))))
                rows.append([case, part, *trans[c, p], *angles]
                            + [v[c] for v in loads.values()])
    for name in loads:
        header.append(name)
        units.append("N·mm" if ".m" in name else ("mm" if name in mech.drivers.names else "N"))
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
            text = h in _TEXT
            fields.append(pa.field(h, pa.string() if text else pa.float64(),
                                   metadata={"unit": u} if u else None))
            arrays.append(pa.array(values if text else [float(v) for v in values],
                                   type=pa.string() if text else pa.float64()))
        pq.write_table(pa.Table.from_arrays(arrays, schema=pa.schema(fields)), path)
    else:
        raise ModelFileError(f"unknown table format '{suffix or '(no suffix)'}'; use a .csv "
                             "or .parquet file.", path=path)
