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

from ..errors import InputError, ModelFileError, ModelWarning
from ..io.files import check_input, read_input
from ..io.tables import Table, decode_text, table_format
from .fit import COLUMN_ALIASES, read_bench_table, unit_scale

__all__ = ["FLAT_TRAC_UNITS", "PLAUSIBLE", "ROUND_TRIP", "SPEED_RATIO", "flat_trac_columns",
           "read_onboard_record", "read_tyre_table"]

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


# --------------------------------------------------------------------------------------------
# The Flat Trac table of `tyre identify` (spec: tyre §3.3) and the on-board record of
# `tyre onboard` (spec: tyre §4)

_KIND = {"steer": "angle", "camber": "angle", "speed": "speed", "FZ": "force", "FX": "force",
         "FY": "force", "MZ": "moment", "t": "time", "omega": "rate", "segment": None}
FLAT_TRAC_UNITS = {
    "angle": {"rad": 1.0, "deg": np.deg2rad(1.0)},
    "speed": {"mm/s": 1.0, "m/s": 1e3, "km/h": 1e6 / 3600.0, "kph": 1e6 / 3600.0},
    "force": {"N": 1.0, "kN": 1e3},
    "moment": {"N·mm": 1.0, "N*mm": 1.0, "Nmm": 1.0, "N·m": 1e3, "N*m": 1e3, "Nm": 1e3},
    "time": {"s": 1.0, "ms": 1e-3},
    "rate": {"rad/s": 1.0, "rpm": 2 * np.pi / 60.0, "deg/s": np.deg2rad(1.0)},
}
"""The units a Flat Trac column may carry in its header (`steer [deg]`, `MZ [N·m]`, …), per kind
of quantity: unit → factor to library units (rad, mm/s, N, N·mm, s, rad/s)."""

SPEED_RATIO = (0.5, 2.0)
"""Accepted range of the belt speed over ω·R_r (median over the rows): a speed column without
its unit (km/h read as mm/s: 278× off) or ω in rpm read as rad/s falls outside."""


def flat_trac_columns(table: Table, *, rolling_radius: float, cutoff: float) -> dict:
    """The columns of a Flat Trac table (`read_tyre_table`) in library units (the header's
    units, `FLAT_TRAC_UNITS`), after the plausibility checks of `diffsusp.tyre.bench.identify`'s
    input, each error (`InputError`) naming the file, the line and the column: known units,
    finite channels, time increasing within a segment at a rate of at least 4× the low-pass
    `cutoff` [Hz], the belt speed consistent with the wheel spin and `rolling_radius` [mm]
    (`SPEED_RATIO`)."""
    path = table.path
    where = f"{path}:{table.header_line}: " if path else ""
    cols = {}
    for name in table.names:
        kind = _KIND.get(name)
        values = np.asarray(table[name], float)
        unit = table.units.get(name)
        if kind is not None and unit:
            f = FLAT_TRAC_UNITS[kind].get(unit)
            if f is None:
                raise InputError(f"{where}{name}: unit [{unit}] not understood; use one of "
                                 f"{', '.join(FLAT_TRAC_UNITS[kind])}")
            values = values * f
        cols[name] = values

    def bad(name, row, why):
        line = _row_line(table, row)
        return InputError(f"{path}:{line or f'row {row + 1}'}: {name}: {why}")

    for name, v in cols.items():
        if name in _KIND and not np.isfinite(v).all():
            i = int(np.flatnonzero(~np.isfinite(v))[0])
            raise bad(name, i, f"{table[name][i]} is not a finite value; remove or repair "
                      "the row")
    if "t" in cols and "segment" in cols:
        t, seg = cols["t"], cols["segment"]
        same = seg[1:] == seg[:-1]
        back = same & (np.diff(t) <= 0)
        if back.any():
            i = int(np.flatnonzero(back)[0]) + 1
            raise bad("t", i, f"time {t[i]:g} s after {t[i - 1]:g} s in one segment: time "
                      "must increase (sort by segment, then time)")
        steps = np.diff(t)[same]
        if steps.size and 1.0 / float(np.median(steps)) < 4.0 * cutoff:
            unit = table.units.get("t") or "s (no unit given)"
            raise InputError(f"{path}:{table.header_line}: t: a time step of "
                             f"{np.median(steps):.4g} s ({unit}) is a rate below 4x the "
                             f"{cutoff:g} Hz cut-off: time in milliseconds without 't [ms]'? "
                             "Or record faster / lower --cutoff")
    if "speed" in cols and "omega" in cols:
        speed, omega = np.abs(cols["speed"]), np.abs(cols["omega"])
        ref = float(np.median(omega)) * rolling_radius
        if ref > 0 and np.median(speed) > 0:
            ratio = float(np.median(speed)) / ref
            if not SPEED_RATIO[0] <= ratio <= SPEED_RATIO[1]:
                unit = table.units.get("speed") or "mm/s (no unit given)"
                raise InputError(
                    f"{path}:{table.header_line}: speed: the belt speed is {ratio:.3g}× ω·R_r "
                    f"(median {np.median(speed):.4g} {unit} against {ref:.4g} mm/s from omega "
                    f"and --rolling-radius {rolling_radius:g} mm): a missing or wrong unit? "
                    "Write 'speed [km/h]' (or [m/s], [mm/s]) and 'omega [rpm]' as recorded")
    return cols


def read_onboard_record(path, window_time: float) -> dict:
    """The arrays of an on-board record (.npz, channels as `diffsusp.tyre.onboard.CHANNELS`),
    checked where the pipeline's own checks (`onboard.check`) do not, each error
    (`InputError`) naming the file and the channel: a regular file within the table size
    limit (a FIFO or a device is refused before it is opened), an archive (a renamed .npy is
    not), numeric channels; a 1-D time of at least two samples, finite and increasing, in
    seconds (a step that leaves the window `window_time` [s] fewer than three samples, e.g.
    milliseconds or whole seconds, is refused); a wheel spin that is never zero (the slip
    divides by it)."""
    path = os.fspath(path)
    if os.path.splitext(path)[1] != ".npz":
        raise InputError(f"{path}: the on-board record must be a .npz archive of arrays "
                         "(channels as diffsusp.tyre.onboard.CHANNELS).")
    try:
        check_input(path, "on-board record", "table")
    except FileNotFoundError as exc:
        raise InputError(f"{path}: cannot read the record: {exc.strerror}.") from None
    except ValueError as exc:   # ModelFileError: names the file already
        raise InputError(str(exc)) from None
    try:
        z = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        raise InputError(f"{path}: cannot read the archive ({exc}).") from None
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise InputError(f"{path}: a single array (a .npy file renamed .npz?), not an archive "
                         "of channels; save the record with numpy.savez.")
    try:
        with z:
            record = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError) as exc:
        raise InputError(f"{path}: cannot read the archive ({exc}).") from None
    _check_record(path, record, window_time)
    return record


def _check_record(path, record: dict, window_time: float) -> None:
    def bad(channel, why):
        return InputError(f"{path}: {channel}: {why}")

    for k, v in record.items():
        if v.dtype.kind not in "biuf":
            raise bad(k, f"holds {v.dtype} values, not numbers")
    if "time" in record:
        t = np.asarray(record["time"], float)
        if t.ndim != 1 or t.size < 2:
            raise bad("time", f"has shape {t.shape}; expected a 1-D array of samples [s]")
        if not np.isfinite(t).all():
            i = int(np.flatnonzero(~np.isfinite(t))[0])
            raise bad("time", f"is not finite at sample {i} ({t[i]})")
        dt = np.diff(t)
        if not (dt > 0).all():
            i = int(np.flatnonzero(dt <= 0)[0])
            raise bad("time", f"does not increase at sample {i + 1} ({t[i + 1]:g} after "
                      f"{t[i]:g}); a constant or reversed time is not a record")
        step = float(np.median(dt))
        if window_time / step < 2.0:
            raise bad("time", f"a sampling step of {step:g} s leaves the {window_time:g} s "
                      "window fewer than 3 samples: time in milliseconds or whole seconds? "
                      "Give time in seconds (or a longer --window-time)")
    if "spin" in record:
        spin = np.asarray(record["spin"], float)
        if spin.size and (spin == 0).any():
            i = int(np.flatnonzero((spin == 0).reshape(spin.shape[0], -1).any(axis=1))[0]) \
                if spin.ndim >= 1 else 0
            raise bad("spin", f"is 0 at sample {i}: the wheels must roll (the slip divides by "
                      "the spin)")
