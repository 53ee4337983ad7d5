"""`diffsusp tyre onboard DATA`: tyre identification from on-board vehicle measurements (spec:
tyre §5.3–5.6).

DATA is a .npz archive with the channels of `diffsusp.tyre.onboard.CHANNELS` (SI units, as
`diffsusp.tyre.vehicle.measure` writes them; laser dropouts as NaN). The report has one column
per grouping and camber choice, as the thesis's Tables 32/33 (value and σ % per coefficient);
the Correvit delay is estimated and removed unless `--delay` gives it (`--delay 0` and
`--no-estimate-delay` is the thesis's naive pipeline). `--kinematics kc` uses the 30-DOF
model's K&C tables (`diffsusp.tyre.vehicle_kc`; or a tables .npz) in place of the 12-DOF chain;
`--joint` (with `--mass`, `--tyre-vertical`) identifies vehicle and tyre together without the
wheels' lateral forces ((4-3), `diffsusp.tyre.onboard_joint`). `--json` machine-readable, `--figures
DIR` measured vs model F_y, `--report FILE.csv|.json` the reports (per parameter value, σ, σ %,
status and reason, each fit's consistency verdict), the same objects the table prints. Exit
code 2 for bad input (missing channels, non-finite values outside the lasers, a window longer
than the record).
"""

from pathlib import Path
from typing import Annotated

import typer

from .common import (
    EXIT_BAD_INPUT,
    check_number,
    check_output,
    cli_errors,
    console,
    enable_x64,
    fail,
    plain,
    print_json,
)


def register(tyre_app: typer.Typer) -> None:
    """Add `onboard` to the `tyre` group (`cli.tyre.tyre_app`)."""
    tyre_app.command("onboard")(onboard_command)


def onboard_command(
    data: Annotated[Path, typer.Argument(help="On-board record (.npz, SI channels).")],
    grouping: Annotated[str, typer.Option(
        help="Wheel groupings, comma separated: all, front, rear.")] = "all,front,rear",
    delay: Annotated[float | None, typer.Option(
        help=plain("Correvit delay to remove [s] (default: estimated)."))] = None,
    estimate_delay: Annotated[bool, typer.Option(
        help="Estimate the Correvit delay when --delay is not given.")] = True,
    window: Annotated[str, typer.Option(help="hamming or blackman.")] = "hamming",
    window_time: Annotated[float, typer.Option(help=plain("Window length T [s]."))]
    = 0.05,
    json_out: Annotated[bool, typer.Option("--json", help="Machine-readable.")] = False,
    figures: Annotated[Path | None, typer.Option(
        help="Folder for measured-vs-model figures.")] = None,
    report: Annotated[Path | None, typer.Option(
        help="Write the reports: .json or .csv (one line per parameter and report).")]
    = None,
    kinematics: Annotated[str, typer.Option(
        help=plain("Wheel-carrier kinematics: 12dof (travel and steer only), kc (the 30-DOF "
                   "model's K&C tables of the built-in pseudo-McPherson) or a tables .npz."))]
    = "12dof",
    joint: Annotated[bool, typer.Option(
        help=plain("Joint vehicle + tyre identification (4-3) without the wheels' lateral "
                   "forces; needs --mass and --tyre-vertical."))] = False,
    mass: Annotated[float | None, typer.Option(help=plain("Car mass [kg] (--joint)."))]
    = None,
    tyre_vertical: Annotated[str | None, typer.Option(
        help=plain("Tyre vertical data k_t [N/m], R_0 [m], c_t [N s/m], comma separated "
                   "(--joint)."))] = None,
):
    """Identify the reduced lateral tyre model (4-16…4-18) from on-board measurements."""
    from diffsusp.tyre import onboard
    from diffsusp.tyre.input_tables import read_onboard_record

    check_output(figures, what="figures folder", directory=True)
    check_output(report, suffixes=(".json", ".csv"), what="report")
    check_number(window_time, "--window-time", positive=True, unit="s")
    check_number(delay, "--delay")
    groups = tuple(g.strip() for g in grouping.split(",") if g.strip())
    if not groups:
        raise fail(f"--grouping '{grouping}' names no grouping; give all, front or rear "
                   "(comma separated).", EXIT_BAD_INPUT)
    from diffsusp.tyre.bench import format_report, report_rows, write_reports

    with cli_errors():
        record = read_onboard_record(data, window_time)
        enable_x64()
        tables = _kinematics(kinematics)
        options = onboard.Options(window=window, window_time=window_time)
        if joint:
            _joint(record, tables, options, delay, mass, tyre_vertical, json_out, report)
            return
        out = onboard.identify(record, groupings=groups, camber=(True, False),
                               delay=delay, estimate_delay=estimate_delay,
                               options=options, kinematics=tables)

    labels = [f"{r.grouping}{'' if r.camber else ', gamma = 0'}" for r in out["reports"]]
    if figures is not None:
        _figures(out, figures)
    if report is not None:
        write_reports(report, out["reports"], labels,
                      extra={"delay_s": out["delay"], "delay_sigma_s": out["delay_sigma"]})
    if json_out:
        print_json({"delay_s": out["delay"], "delay_sigma_s": out["delay_sigma"],
                    "reports": [r.to_dict() | {"parameters": report_rows(r)}
                                for r in out["reports"]]})
        return
    con = console(markup=False)
    con.print(f"Correvit delay removed: {1000 * out['delay']:.1f} "
              f"± {1000 * out['delay_sigma']:.2f} ms (its σ is in the coefficients'); "
              f"instants excluded (laser dropouts, end of the delayed Correvit): "
              f"{out['excluded']}")
    cols = [f"{r.grouping}{'' if r.camber else ', γ = 0'}" for r in out["reports"]]
    width = max(len(c) for c in cols) + 2
    con.print("parameter".ljust(14) + "".join(c.rjust(max(width, 22)) for c in cols))
    for i, name in enumerate(onboard.NAMES):
        cells = []
        for r in out["reports"]:
            x, s = r.estimates[i], r.sigma_pct[i]
            cells.append(("0" if x == 0 else f"{x:.5g} ({s:.2g}%)").rjust(max(width, 22)))
        con.print(name.ljust(14) + "".join(cells))
    for r, label in zip(out["reports"], labels, strict=True):
        con.print("")
        con.print(format_report(r, label=f"== {label}"))


def _figures(out, folder: Path) -> None:
    from diffsusp import plot

    for r in out["reports"]:
        plot.save(r.plot(), folder / f"onboard_{r.grouping}_"
                  f"{'camber' if r.camber else 'nocamber'}", formats=("png",), dpi=100)


def _kinematics(choice: str):
    """None (the 12-DOF chain), the shipped K&C tables, or tables from an .npz."""
    from diffsusp.tyre import vehicle_kc

    if choice == "12dof":
        return None
    if choice == "kc":
        return vehicle_kc.load_tables()
    return vehicle_kc.load_tables(Path(choice))


def _joint(record, tables, options, delay, mass, tyre_vertical, json_out, report) -> None:
    """`--joint`: the joint vehicle + tyre identification (4-3), its report as the others'."""
    from diffsusp.tyre import onboard_joint
    from diffsusp.tyre.bench import format_report, report_rows, write_reports

    if mass is None or tyre_vertical is None:
        raise fail("--joint needs --mass (kg) and --tyre-vertical 'k_t,R_0,c_t'.",
                   EXIT_BAD_INPUT)
    check_number(mass, "--mass", positive=True, unit="kg")
    try:
        tv = tuple(float(v) for v in tyre_vertical.split(","))
    except ValueError:
        tv = ()
    if len(tv) != 3:
        raise fail(f"--tyre-vertical '{tyre_vertical}': three numbers k_t,R_0,c_t "
                   "(N/m, m, N s/m).", EXIT_BAD_INPUT)
    rep = onboard_joint.identify(record, mass=mass, tyre_vertical=tv, options=options,
                                 delay=delay, kinematics=tables)
    if report is not None:
        write_reports(report, [rep], ["joint"], extra={"delay_s": rep.delay})
    if json_out:
        print_json(rep.to_dict() | {"parameters": report_rows(rep)})
        return
    con = console(markup=False)
    con.print(format_report(rep, label="== joint vehicle + tyre (4-3)"))
