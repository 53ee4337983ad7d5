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
the Magic Formula 1989 set (§3.8, conversion radius `--radius`); `--speed-test` runs the
speed test (3-54) (`bench_speed`), `--select CHANNEL:LO:HI` keeps the samples in a range
first (`bench_select`, thesis §1.3.6.3). Exit codes: 2 bad input
(missing channels, non-monotonic time, a rate too low for the filter, an unknown structure),
4 an unstable identified model (∂Fy_pneu/∂δ′ ≥ 0 on the data) unless `--allow-unstable`.
"""

import enum
import json
from pathlib import Path
from typing import Annotated

import typer

from .common import (
    EXIT_MODEL_ERROR,
    check_number,
    check_output,
    cli_errors,
    console,
    enable_x64,
    fail,
    plain,
)

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
        "--to-mf", help="Convert to the Magic Formula 1989 set (.json), with the torsion "
                        "sets of the phi' responses.")] = None,
    radius: Annotated[float, typer.Option(help=plain("Conversion radius for --to-mf [m]."))]
    = 0.33,
    rolling_radius: Annotated[float, typer.Option(help=plain("Rolling radius R_r [mm]."))]
    = 294.0,
    hold: Annotated[list[str] | None, typer.Option(
        "--hold", help="Hold a coefficient at 0 (repeatable), e.g. b_Fy_one_1_0.")] = None,
    cutoff: Annotated[float, typer.Option(help="Low-pass cut-off [Hz].")] = 25.0,
    allow_unstable: Annotated[bool, typer.Option(help="Report an unstable model, exit 0.")]
    = False,
    median: Annotated[int | None, typer.Option(
        help="Remove spikes first: a sample far from the running median of this many "
             "samples (odd) is replaced by it, on every channel.")] = None,
    aero: Annotated[Path | None, typer.Option(
        help="Wheel-in-the-air spin-down run (t, segment, omega, FY, optional MZ): its "
             "aerodynamic force against spin speed is identified (laminar, turbulent or both) "
             "and removed from the bench data first.")] = None,
    speed_test: Annotated[bool, typer.Option(
        "--speed-test", help="The speed test (3-54): speed terms (omega, omega^2 times the "
                             "slip and offset load polynomials) join the structure search; "
                             "the verdict is in the report's notes.")] = False,
    select: Annotated[list[str] | None, typer.Option(
        "--select", help="Keep only the samples with CHANNEL in [LO, HI] (repeatable; the "
                         "table's units: rad, mm/s, N...; d:CH its time derivative, int:CH "
                         "its integral from the run's start), e.g. steer:-0.01745:0.01745 "
                         "for |slip| <= 1 deg (thesis §1.3.6).")] = None,
    select_duration: Annotated[float, typer.Option(
        "--select-duration", help="--select: the selected runs are cut into segments of "
                                  "this many seconds (shorter ones dropped).")] = 0.5,
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
        from diffsusp.tyre.input_tables import flat_trac_columns, read_tyre_table

        raw = read_tyre_table(data, "Flat Trac table")   # regular file, UTF-8, FZ >= 0, units
        table = flat_trac_columns(raw, rolling_radius=rolling_radius, cutoff=cutoff)
        enable_x64()
        from diffsusp.errors import InputError
        from diffsusp.tyre import aero as aerodynamics
        from diffsusp.tyre import bench, convert
        laws = {}
        if aero is not None:
            air = flat_trac_columns(read_tyre_table(aero, "wheel-in-the-air run"),
                                    rolling_radius=rolling_radius, cutoff=cutoff)
            if "omega" not in air or "FY" not in air:
                raise InputError(f"{aero}: a wheel-in-the-air run needs 'omega' and 'FY' "
                                 "columns (and optionally 'MZ').")
            laws = aerodynamics.identify(air["omega"], {ch: air[ch] for ch in ("FY", "MZ")
                                                        if ch in air})
            table = aerodynamics.remove(table, laws)
            for law in laws.values():
                c.print(f"aerodynamic {law.channel} removed: {law.law} law, "
                        f"{law.laminar:.4g}·ω + {law.turbulent:.4g}·ω|ω| "
                        f"(σ {law.sigma[1]:.2g}, {law.sigma[2]:.2g}; ω in rad/s)")
        if select:  # the predicate sample selection (thesis §1.3.6.3)
            from diffsusp.tyre import bench_select
            check_number(select_duration, "--select-duration", positive=True, unit="s")
            table = bench_select.select(
                table, dict(bench_select.parse_bound(b) for b in select),
                duration=select_duration)
            c.print(f"--select: {len(table['t'])} samples in "
                    f"{int(table['segment'].max()) + 1} segments of {select_duration:g} s")
        rep = bench.identify(table, structure=structure, cutoff=cutoff,
                             rolling_radius=rolling_radius, significance=significance,
                             sigma_pct_threshold=sigma_pct, fixed=tuple(hold or ()),
                             median=median, speed_test=speed_test)
        c.print(rep.table())
        if report is not None:
            bench.write_reports(report, [rep], extra={"aero": {k: v.to_dict() for k, v in
                                                              laws.items()}} if laws else None)
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
            torsion = {}
            for o, model in (("Fy", fy), ("Mz", mz)):
                if model is not None and dict(model.degrees).get("phi", 0):
                    ts, ts_notes = convert.torsion_set(model)
                    torsion[o] = {"coefficients": {k: float(ts.coefficients[k]) for k in
                                                   ("c0", "c1", "c2", "c3", "c4", "c9", "c12",
                                                    "c13")}, "notes": ts_notes["torsion"]}
            to_mf.write_text(json.dumps({"coefficients": {k: float(v) for k, v in
                                                          fitted.coefficients.items()},
                                         "notes": notes, "radius_m": radius,
                                         "converged": mf_rep.converged,
                                         "torsion": torsion}, indent=2) + "\n")
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
