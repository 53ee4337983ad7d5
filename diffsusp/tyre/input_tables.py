"""The tyre verbs' input tables (`tyre eval --inputs`, `tyre fit`, `fleet tyre-fit` items), read
safely and checked before any work (the checks below and the round trip of `tyre eval --out`).

`read_tyre_table(path)` is `diffsusp.tyre.fit.read_bench_table` (the header `NAME [unit]`, the
pressure and speed units it knows) behind the checks every other reader of `diffsusp.io` makes
and a few of its own:

- only a regular file within the table size limit is opened (`io.files`: a FIFO or `/dev/zero`
  is refused before it is read);
- CSV must be UTF-8 text (a binary file named `.csv` is an error naming the line);
- `P_Pa` and `VX_m_s`, the columns `tyre eval --out` writes, read back as `P [Pa]` and
  `VX [m/s]` (a round trip evaluates at the table's pressure and speed, not the file's nominal);
- a table with no data rows, or two columns of one quantity (`FZ` and `LOAD`), is an error;
- every cell of a known column is checked in library units: no infinite value, a vertical load
  `FZ` >= 0 (ISO: a table in the SAE sign, FZ < 0, must be negated), a pressure `P` > 0,
  forces and moments no larger than `PLAUSIBLE` (a 1e300 N force is a broken file, not a
  measurement). NaN stays the explicit exclusion `tyre fit` documents.
- slip angle or inclination beyond ±π/2 rad is warned (`ModelWarning`): degrees in a column
  read as radians (write `SA [deg]`).

Every error is a `ModelFileError` naming the file, the line and the column.
"""

import math
import os
import warnings

import numpy as np

from ..errors import ModelFileError, ModelWarning
from ..io.files import check_input, read_input
from ..io.tables import Table, decode_text, table_format
from .fit import COLUMN_ALIASES, read_bench_table, unit_scale

__all__ = ["PLAUSIBLE", "ROUND_TRIP", "read_tyre_table"]

ROUND_TRIP = {"P_PA": ("P", "Pa"), "VX_M_S": ("VX", "m/s")}
"""Column names `tyre eval --out` writes (upper case) → (column, unit) read back."""

PLAUSIBLE = {"FZ": 1e6, "FX": 1e6, "FY": 1e6, "MX": 1e9, "MY": 1e9, "MZ": 1e9, "VX": 1e9,
             "P": 1e9}
"""Largest magnitude of a cell in library units (N, N·mm, mm/s, Pa): 1 MN, 1 MN·m, 1 km/s,
1 GPa — far beyond any tyre; anything above is a broken or mislabelled file."""


def _row_line(table: Table, row: int):
    return table.lines[row] if table.lines is not None and row < len(table.lines) else None


def read_tyre_table(path, what: str = "tyre input table") -> Table:
    """The table at `path` (CSV or Parquet) after the checks of the module docstring.

    **Raises:** `ModelFileError` (file, line, column) for anything it refuses;
    `FileNotFoundError` when there is no file."""
    path = os.fspath(path)
    kind = table_format(path)
    if kind == "csv":
        decode_text(read_input(path, what, "table"), path)
    else:
        check_input(path, what, "table")
    table = read_bench_table(path)
    columns, units = {}, {}
    for name in table.names:
        new, unit = name, table.units.get(name)
        if name.upper() in ROUND_TRIP and unit is None:
            new, unit = ROUND_TRIP[name.upper()]
            if new in table.names:
                raise ModelFileError(f"columns {name!r} and {new!r} both give {new}; keep one",
                                     path=path, line=table.header_line, field=name)
        columns[new], units[new] = table[name], unit
    table = Table(columns, units, table.path or path, table.lines, table.header_line)
    if table.n_rows == 0:
        raise ModelFileError("the table has a header but no data rows", path=path,
                             line=table.header_line)
    canon: dict[str, str] = {}
    for name in table.names:
        c = COLUMN_ALIASES.get(name.upper())
        if c is None:
            continue
        if c in canon:
            raise ModelFileError(f"columns {canon[c]!r} and {name!r} are both {c}; keep one "
                                 "(or rename the other)", path=path, line=table.header_line,
                                 field=name)
        canon[c] = name
        values = np.asarray(table[name], float) * unit_scale(c, table.units.get(name), path)
        _check_column(table, name, c, values, path)
    return table


def _check_column(table: Table, name: str, c: str, values: np.ndarray, path) -> None:
    def refuse(mask, why):
        row = int(np.flatnonzero(mask)[0])
        raw = float(table[name][row])
        raise ModelFileError(f"{raw!r} {why} ({int(mask.sum())} row(s); first: row {row + 1})",
                             path=path, line=_row_line(table, row), field=name)

    with np.errstate(invalid="ignore"):
        if np.isinf(values).any():
            refuse(np.isinf(values), "is not a finite number; write nan to exclude a point")
        bound = PLAUSIBLE.get(c)
        if bound is not None and (np.abs(values) > bound).any():
            refuse(np.abs(values) > bound, "is implausibly large for a tyre: a broken or "
                   "mislabelled column?")
        if c == "FZ" and (values < 0).any():
            refuse(values < 0, "is a negative vertical load; FZ is >= 0 (ISO; a table in the "
                   "SAE sign convention needs FZ negated)")
        if c == "P" and (values <= 0).any():
            refuse(values <= 0, "is not a positive inflation pressure")
        if c in ("SA", "IA") and (np.abs(values) > math.pi / 2).any():
            mask = np.abs(values) > math.pi / 2
            row = int(np.flatnonzero(mask)[0])
            where = f"{path}:{_row_line(table, row) or f'row {row + 1}'}: {name}"
            warnings.warn(f"{where}: {int(mask.sum())} value(s) beyond ±90° (up to "
                          f"{np.nanmax(np.abs(values)):.4g} rad): degrees in a column read as "
                          f"radians? Write '{name} [deg]' in the header.", ModelWarning,
                          stacklevel=3)
