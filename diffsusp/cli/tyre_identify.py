"""`diffsusp tyre identify DATA`: the polynomial tyre model and the lateral stiffnesses from a
Flat Trac table (spec: tyre §3.3–3.8).

DATA (.csv/.parquet) has the columns of `diffsusp.tyre.bench.REQUIRED`: `t` [s], `segment`,
`steer`, `camber` [rad], `speed` [mm/s], `omega` [rad/s], `FZ`, `FX`, `FY` [N], `MZ` [N·mm]
(a unit in the header, e.g. `speed [km/h]`, `MZ [N·m]`, `steer [deg]`, is converted).
`--structure apriori|just-necessary` (Tables 5 / 10), the structure search's F-test level
`--significance` and σ % threshold `--sigma-pct` (`bench.identify`); the report goes to the
terminal and to `--report` (.json, .csv, .html: one report object, `bench.BenchReport`, per
parameter value, σ, σ %, status and reason, the consistency verdict; `--hold NAME` holds a
coefficient at 0), the identified polynomial models to `--out` (.json),
measured-vs-model figures to `--figures`; `--to-mf FILE.json` converts the polynomials to
the Magic Formula 1989 set (§3.8, conversion radius `--radius`). Exit codes: 2 bad input
(missing channels, non-monotonic time, a rate too low for the filter, an unknown structure),
4 an unstable identified model (∂Fy_pneu/∂δ′ ≥ 0 on the data) unless `--allow-unstable`.
"""

import enum
import json
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from .common import (
    EXIT_BAD_INPUT,
    EXIT_MODEL_ERROR,
    check_number,
    check_output,
    cli_errors,
    console,
    enable_x64,
    fail,
    plain,
)

_UNITS = {"steer": "angle", "camber": "angle", "speed": "speed", "FZ": "force", "FX": "force",
          "FY": "force", "MZ": "moment", "t": "time", "omega": "rate", "segment": None}
_FACTORS = {
    "angle": {"rad": 1.0, "deg": np.pi / 180.0},
    "speed": {"mm/s": 1.0, "m/s": 1e3, "km/h": 1e6 / 3600.0, "kph": 1e6 / 3600.0},
    "force": {"N": 1.0, "kN": 1e3},
    "moment": {"N·mm": 1.0, "N*mm": 1.0, "Nmm": 1.0, "N·m": 1e3, "N*m": 1e3, "Nm": 1e3},
    "time": {"s": 1.0, "ms": 1e-3},
    "rate": {"rad/s": 1.0, "rpm": 2 * np.pi / 60.0, "deg/s": np.pi / 180.0},
}


def _columns(table) -> dict:
    out = {}
    where = f"{table.path}:{table.header_line}: " if table.path else ""
    for name in table.names:
        kind = _UNITS.get(name)
        values = np.asarray(table[name], float)
        unit = table.units.get(name)
        if kind is not None and unit:
            f = _FACTORS[kind].get(unit)
            if f is None:
                raise fail(f"{where}{name}: unit [{unit}] not understood; use one of "
                           f"{', '.join(_FACTORS[kind])}", EXIT_BAD_INPUT)
            values = values * f
        out[name] = values
    return out


SPEED_RATIO = (0.5, 2.0)
"""Accepted range of the belt speed over ω·R_r (median over the rows): a speed column without
its unit (km/h read as mm/s: 278× off) or ω in rpm read as rad/s falls outside."""


def _check_bench(table, cols: dict, rolling_radius: float, cutoff: float) -> None:
    """The plausibility of a Flat Trac table, each error naming the file, the line and the
    column: finite channels, time increasing, loads >= 0 (the reader), the
    belt speed consistent with the wheel spin and the rolling radius."""
    path = table.path

    def line(row):
        return table.lines[row] if table.lines is not None and row < len(table.lines) else None

    def bad(name, row, why):
        where = f"{path}:{line(row) or f'row {row + 1}'}: {name}"
        return fail(f"{where}: {why}", EXIT_BAD_INPUT)

    for name, v in cols.items():
        if name in _UNITS and not np.isfinite(v).all():
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
            raise fail(f"{path}:{table.header_line}: t: a time step of {np.median(steps):.4g} "
                       f"s ({unit}) is a rate below 4x the {cutoff:g} Hz cut-off: time in "
                       "milliseconds without 't [ms]'? Or record faster / lower --cutoff",
                       EXIT_BAD_INPUT)
    if "speed" in cols and "omega" in cols:
        speed, omega = np.abs(cols["speed"]), np.abs(cols["omega"])
        ref = float(np.median(omega)) * rolling_radius
        if ref > 0 and np.median(speed) > 0:
            ratio = float(np.median(speed)) / ref
            if not SPEED_RATIO[0] <= ratio <= SPEED_RATIO[1]:
                unit = table.units.get("speed") or "mm/s (no unit given)"
                raise fail(f"{path}:{table.header_line}: speed: the belt speed is {ratio:.3g}× "
                           f"ω·R_r (median {np.median(speed):.4g} {unit} against "
                           f"{ref:.4g} mm/s from omega and --rolling-radius "
                           f"{rolling_radius:g} mm): a missing or wrong unit? Write "
                           "'speed [km/h]' (or [m/s], [mm/s]) and 'omega [rpm]' as recorded",
                           EXIT_BAD_INPUT)


# --------------------------------------------------------------------------------------------
# One report, three renderings (table, CSV, JSON): every one reads `bench.report_rows`


def write_reports(path: Path, reports, labels=None, extra: dict | None = None) -> None:
    """Write one or more reports by the suffix of `path`: .csv (`report_rows`, one line per
    parameter, a `report` column when several), .json (each report's `summary()` with the
    status and reason per parameter; `extra` merged at the top), .html (the shared report's
    writer, where the base provides one)."""
    import csv

    from diffsusp.tyre.bench import report_rows

    labels = list(labels) if labels is not None else [None] * len(reports)
    if path.suffix == ".csv":
        rows = [r for rep, lab in zip(reports, labels, strict=True)
                for r in report_rows(rep, lab if len(reports) > 1 else None)]
        with path.open("w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            for r in rows:
                w.writerow({k: ("" if v is None else v) for k, v in r.items()})
    elif path.suffix == ".json":
        out = []
        for rep, lab in zip(reports, labels, strict=True):
            summ = rep.summary()
            summ["parameters"] = report_rows(rep)
            if lab is not None:
                summ["report"] = lab
            out.append(summ)
        doc = out[0] if len(out) == 1 and labels[0] is None else {"reports": out}
        doc.update(extra or {})
        path.write_text(json.dumps(doc, indent=2, default=_json_default) + "\n")
    elif path.suffix == ".html":
        if len(reports) != 1:
            raise fail(f"{path}: HTML needs the shared report writer (one report); write "
                       ".csv or .json", EXIT_BAD_INPUT)
        reports[0].write(path)
    else:
        raise fail(f"{path}: the report is written as .csv, .json or .html", EXIT_BAD_INPUT)


def _json_default(v):
    if isinstance(v, np.generic):
        v = v.item()
        return v if not isinstance(v, float) or np.isfinite(v) else None
    if isinstance(v, np.ndarray):
        return v.tolist()
    raise TypeError(f"{type(v).__name__} is not JSON serialisable")


# the library's structures (diffsusp.tyre.poly.STRUCTURES), a Typer choice (exit code 2)
Structure = enum.StrEnum("Structure", {v: v for v in ("apriori", "just-necessary")})


def register(tyre_app: typer.Typer) -> None:
    """Add `identify` to the `tyre` group (`cli.tyre.tyre_app`)."""
    tyre_app.command("identify")(identify_command)


def identify_command(
    data: Annotated[Path, typer.Argument(help="Flat Trac table (.csv/.parquet).")],
    structure: Annotated[Structure, typer.Option(
        help="Degrees: Table 5 (apriori) or Table 10 (just-necessary).")]
    = Structure["just-necessary"],
    significance: Annotated[float, typer.Option(
        help="Structure search: the F-test level; a term whose removal raises the residual "
             "beyond the noise at this level is kept.", min=1e-12, max=0.5)] = 1e-3,
    sigma_pct: Annotated[float, typer.Option(
        "--sigma-pct", help="Structure search: remove terms with sigma % above this (unless "
                            "the F-test keeps them).", min=0.0)] = 10.0,
    out: Annotated[Path | None, typer.Option(help="Write the polynomial models (.json).")]
    = None,
    report: Annotated[Path | None, typer.Option(
        help="Write the report: .json (everything), .csv (one line per parameter), .html.")]
    = None,
    figures: Annotated[Path | None, typer.Option(help="Measured-vs-model figures folder.")]
    = None,
    to_mf: Annotated[Path | None, typer.Option(
        "--to-mf", help="Convert to the Magic Formula 1989 set (.json).")] = None,
    radius: Annotated[float, typer.Option(help=plain("Conversion radius for --to-mf [m]."))]
    = 0.33,
    rolling_radius: Annotated[float, typer.Option(help=plain("Rolling radius R_r [mm]."))]
    = 294.0,
    hold: Annotated[list[str] | None, typer.Option(
        "--hold", help="Hold a coefficient at 0 (repeatable), e.g. b_Fy_one_1_0.")] = None,
    cutoff: Annotated[float, typer.Option(help="Low-pass cut-off [Hz].")] = 25.0,
    allow_unstable: Annotated[bool, typer.Option(help="Report an unstable model, exit 0.")]
    = False,
):
    """Identify the polynomial tyre model, K_y on F_y and on M_z (two-step, structure search)."""
    structure = Structure(structure).value
    for path, suffixes, what in ((out, (".json",), "polynomial models"),
                                 (report, (".json", ".csv", ".html"), "report"),
                                 (to_mf, (".json",), "Magic Formula set")):
        check_output(path, suffixes=suffixes, what=what)
    check_output(figures, what="figures folder", directory=True)
    check_number(radius, "--radius", positive=True, unit="m")
    check_number(rolling_radius, "--rolling-radius", positive=True, unit="mm")
    check_number(cutoff, "--cutoff", positive=True, unit="Hz")
    c = console(markup=False)
    with cli_errors():
        from diffsusp.tyre.input_tables import read_tyre_table

        raw = read_tyre_table(data, "Flat Trac table")   # regular file, UTF-8, FZ >= 0, units
        table = _columns(raw)
        _check_bench(raw, table, rolling_radius, cutoff)
        enable_x64()
        from diffsusp.tyre import bench, convert
        rep = bench.identify(table, structure=structure, cutoff=cutoff,
                             rolling_radius=rolling_radius, significance=significance,
                             sigma_pct_threshold=sigma_pct, fixed=tuple(hold or ()))
        c.print(rep.table())
        if report is not None:
            write_reports(report, [rep])
        if out is not None:
            out.write_text(json.dumps({o: {"degrees": dict(r.model.degrees),
                                           "coefficients": r.model.values(),
                                           "K_y": r.stiffness}
                                       for o, r in rep.outputs.items()}, indent=2) + "\n")
            c.print(f"polynomial models written to {out}")
        if figures is not None:
            _figures(rep, table, figures, cutoff, rolling_radius)
            c.print(f"figures written to {figures}")
        if to_mf is not None:
            fy = rep.outputs["Fy"].model
            mz = rep.outputs["Mz"].model if "Mz" in rep.outputs else None
            fitted, mf_rep, notes, _ = convert.to_magic_formula(fy, mz, radius=radius)
            to_mf.write_text(json.dumps({"coefficients": {k: float(v) for k, v in
                                                          fitted.coefficients.items()},
                                         "notes": notes, "radius_m": radius,
                                         "converged": mf_rep.converged}, indent=2) + "\n")
            c.print(f"Magic Formula 1989 set written to {to_mf}")
        if not rep.stable and not allow_unstable:
            raise fail("; ".join(f for f in rep.flags if f.startswith("unstable")),
                       EXIT_MODEL_ERROR)


def _figures(rep, table, folder: Path, cutoff, rolling_radius):
    from diffsusp import plot
    from diffsusp.tyre import bench

    cond = bench.condition(table, cutoff=cutoff, rolling_radius=rolling_radius)
    for o, r in rep.outputs.items():
        plot.save(r.plot(cond), folder / f"{o.lower()}_measured_vs_model", formats=("png",),
                  dpi=110)
