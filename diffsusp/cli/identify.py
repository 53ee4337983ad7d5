"""`diffsusp identify direct|iterative|fit MODEL --measurements TABLE`: stiffness (and
hardpoint) identification from measured equilibria.

- `direct`: the linear method (spec stiffness §1.8–1.14); every moving part measured.
- `iterative`: the thesis's correlation loop (spec stiffness §2); the parts of the identified
  bushings measured.
- `fit`: least squares through the equilibrium (spec stiffness §3, §6 item 8); any subset of
  the parts, with σ, identifiability and the combinations the data cannot see.

MODEL is anything `diffsusp.load_model` reads (a `.toml`, `.adm`, `.json` file or a built-in
name). TABLE is a landmark or pose table with the loads, CSV or Parquet (format in
`diffsusp.io.measurements`). The report goes to the terminal (or `--json`), optionally to `--out`
(.csv: one row per unknown; .json: the whole report), the identified model to `--write-model`
(.toml native file; .adm: the stiffnesses written into the Adams dataset the model came from,
or a complete dataset), and for `iterative` and `fit` the figures to `--figures`.

The bushing and parameter selection and start values are `diffsusp.identify.selection`, the
CSV rows and figures `diffsusp.identify.tables`; this module parses, calls and formats.
"""

import contextlib
import enum
from pathlib import Path
from typing import Annotated

import typer
from rich import box
from rich.table import Table as RichTable

from .common import (
    EXIT_BAD_INPUT,
    EXIT_NOT_CONVERGED,
    SideOption,
    check_identify_outputs,
    cli_errors,
    console,
    enable_x64,
    fail,
    load_model_file,
    print_json,
    write_model_file,
)

identify_app = typer.Typer(add_completion=False, no_args_is_help=True,
                           help="Identify stiffnesses from measurements (spec stiffness ch. 4).")
"""The `identify` group: `direct`, `iterative`, `fit` here, `geometry` and `correct` in
`cli.geometry` (registered on it by `cli.geometry.register`)."""


def register(app: typer.Typer) -> None:
    """Add the `identify` group to `app`, with its verbs `direct`, `iterative` and `fit`."""
    app.add_typer(identify_app, name="identify")
    identify_app.command("direct")(direct_command)
    identify_app.command("iterative")(iterative_command)
    identify_app.command("fit")(fit_command)

# The choices of the direct method's options (Typer checks them: exit code 2).
Method = enum.StrEnum("Method", {v: v for v in ("basic", "min_norm", "tsvd", "tikhonov",
                                                 "nonneg")})
Hold = enum.StrEnum("Hold", {v: v for v in ("zero", "model")})
Weighting = enum.StrEnum("Weighting", {v: v for v in ("noise", "none")})
Polish = enum.StrEnum("Polish", {v: v for v in ("auto", "on", "off")})
Loss = enum.StrEnum("Loss", {v: v for v in ("linear", "huber", "cauchy")})  # lsq.LOSSES


# Options shared by the identify verbs.
ModelArg = Annotated[str, typer.Argument(help="Model file (.toml, .adm, .json) or built-in name.")]
MeasurementsOpt = Annotated[Path, typer.Option(
    "--measurements", "-m",
    help="Landmark or pose table with the loads of each case (.csv or .parquet).")]
OutOpt = Annotated[Path | None, typer.Option(help="Write the report (.csv or .json).")]
WriteModelOpt = Annotated[Path | None, typer.Option(
    help="Write the identified model (.toml, or .adm).")]
FiguresOpt = Annotated[Path | None, typer.Option(
    help="Write the convergence and measured-vs-identified figures (PNG, SVG) here.")]
ReorderOpt = Annotated[bool, typer.Option(
    help="Match landmarks probed in any order by their distance tables.")]
JsonOpt = Annotated[bool, typer.Option("--json", help="Machine-readable report.")]


def direct_command(
    model: ModelArg,
    measurements: MeasurementsOpt,
    side: SideOption = None,
    out: OutOpt = None,
    write_model: WriteModelOpt = None,
    method: Annotated[Method, typer.Option(help="Estimator.")] = Method.basic,
    hold: Annotated[Hold, typer.Option(
        help="Value of undetermined unknowns.")] = Hold.zero,
    eliminate: Annotated[bool, typer.Option(
        help="Hold unknowns whose sigma% exceeds --max-sigma-pct one by one (noisy data: "
        "with --hold model).")] = False,
    weighting: Annotated[Weighting, typer.Option(
        help="noise: GLS from the landmark noise.")] = Weighting.noise,
    element: Annotated[list[str] | None, typer.Option(
        "--element", "-e", help="Identify only this bushing or spring (repeatable).")] = None,
    axisymmetric: Annotated[list[str] | None, typer.Option(
        help="Bushing with Ktx = Kty and Krx = Kry (repeatable).")] = None,
    offsets: Annotated[bool, typer.Option(
        help="Also identify the bushings' offsets.")] = False,
    cubic: Annotated[bool, typer.Option(
        help="Also identify the bushings' cubic terms S of F = K·d + S·d³ (N/mm³, "
        "N·mm/deg³).")] = False,
    reorder: ReorderOpt = False,
    max_sigma_pct: Annotated[float, typer.Option(
        help="Largest sigma% still called identified.")] = 10.0,
    threshold: Annotated[float | None, typer.Option(
        help="Relative identifiability threshold (default 1e-5).")] = None,
    polish: Annotated[Polish, typer.Option(
        help="Refine the determined stiffnesses by least squares through the equilibrium "
        "(errors in variables): auto (noisy data), on, or off (the thesis's linear "
        "estimate).")] = Polish.auto,
    json_output: JsonOpt = False,
):
    """Identify bushing and spring stiffnesses by the direct (linear) method.

    Units: N/mm and N·mm/deg (as the thesis's tables), spring K·L0 in N.
    """
    method, hold, weighting, polish = (Method(method).value, Hold(hold).value,
                                       Weighting(weighting).value, Polish(polish).value)
    check_identify_outputs(out, write_model)
    enable_x64()
    from .. import identify, measure

    with cli_errors():
        model_file = load_model_file(model, side=side)
        mech = model_file.mechanism
        meas = measure.read_measurements(measurements, mech, reorder=reorder)
        selection = identify.direct_selection(mech, element, offsets=offsets,
                                                cubic=cubic)
        fitted, report = identify.direct(
            mech, meas, selection, axisymmetric=tuple(axisymmetric or ()), method=method,
            hold=hold, eliminate=eliminate, weighting=weighting, threshold=threshold,
            max_sigma_pct=max_sigma_pct, polish={"on": True, "off": False}.get(polish, "auto"))
        if out is not None:
            report.write(out)
        if write_model is not None:
            write_model_file(fitted, write_model, model_file)
    if json_output:
        print_json(report.to_dict())
    else:
        _print(report, mech, measurements, out, write_model)
    _exit_if_unsolvable(report)


def _exit_if_unsolvable(report):
    """Exit 3 when the returned model has no equilibrium in some measured case."""
    cons = report.consistency
    if cons is not None and cons.failed_cases:
        raise fail(f"the identified model has no equilibrium in case(s) "
                   f"{', '.join(cons.failed_cases)}: the values written do not describe the "
                   "measurements; start closer to the expected values.", EXIT_NOT_CONVERGED)


def _print(report, mech, measurements, out, write_model):
    con = console(markup=False)
    table = RichTable(
        title=f"{mech.name}: direct identification from {measurements.name} "
        f"({len(report.cases)} cases, {report.n_equations} equations, rank {report.rank})",
        box=box.SIMPLE_HEAD)
    for col, justify in (("parameter", "left"), ("value", "right"), ("sigma%", "right"),
                         ("unit", "left"), ("model", "right"), ("status", "left")):
        table.add_column(col, justify=justify, no_wrap=col != "status")
    statuses, reasons = report.statuses, report.status_reasons
    for i, name in enumerate(report.names):
        shown = report.is_identified[i]
        pct = report.sigma_pct[i]
        table.add_row(name, f"{report.values[i]:.6g}" if shown else "—",
                      f"{pct:.3g}" if shown and pct == pct else "—", report.units[i],
                      f"{report.prior[i]:.6g}",
                      statuses[i] + (f": {reasons[i]}" if reasons[i] else ""))
    con.print(table)
    if report.relations:
        con.print("identifiable combinations (the data determine only these sums):")
        for text, value, sigma in report.relations:
            pct = f" ({100 * sigma / abs(value):.3g}%)" if value and sigma == sigma else ""
            con.print(f"  {text} = {value:.6g}{pct}", highlight=False)
    for name, (value, sigma, unit) in report.derived.items():
        if value == value:
            pct = f" ({100 * sigma / abs(value):.3g}%)" if value and sigma == sigma else ""
            con.print(f"{name} = {value:.6g} {unit}{pct}", highlight=False)
    worst = max(range(len(report.cases)), key=lambda c: report.case_residuals[c])
    con.print(f"equation residual per case: largest {report.case_residuals[worst]:.3g} N "
              f"(case {report.cases[worst]}); method {report.method}"
              f"{', GLS-weighted' if report.weighted else ''}.", highlight=False)
    for note in report.notes:
        con.print(f"note: {note}", highlight=False)
    con.print(f"verdict: {report.fit_verdict}; σ% judged at {report.judged_at}.",
              highlight=False)
    for label, path in (("report", out), ("identified model", write_model)):
        if path is not None:
            con.print(f"{label} written to {path}", highlight=False)


# ----------------------------------------------------------------------------- shared


def _save_figures(figures: dict, folder: Path) -> list:
    """Save each figure as folder/<name>.png and .svg; the paths written."""
    from .. import plot

    return [p for name, fig in figures.items() for p in plot.save(fig, folder / name)]


@contextlib.contextmanager
def _save_on_interrupt(out, rows, what):
    """On SIGINT / SIGTERM, write the last estimate (`rows()`: the report rows of the last
    accepted step, each with status 'interrupted') to `out` before exiting with 130."""
    from ..identify.report import RowsReport
    from .common import EXIT_INTERRUPTED, Terminated, interruptible

    try:
        with interruptible():
            yield
    except KeyboardInterrupt as e:
        how = "terminated (SIGTERM)" if isinstance(e, Terminated) else "interrupted"
        data = rows()
        where = ""
        if out is not None and data:
            RowsReport(tuple(data), {"interrupted": True}).write(out)
            where = f"; the estimate of the last {what} is in {out} (status 'interrupted')"
        elif not data:
            where = f"; no {what} had finished"
        raise fail(f"{how}{where}.", EXIT_INTERRUPTED) from None


def _progress():
    """A transient progress bar on stderr (bounded loops: iterations, LM steps)."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                    console=console(stderr=True, markup=False), transient=True)


# ----------------------------------------------------------------------------- iterative


def iterative_command(
    model: ModelArg,
    measurements: MeasurementsOpt,
    side: SideOption = None,
    bushing: Annotated[list[str] | None, typer.Option(
        "--bushing", "-b", help="Bushing to identify (repeatable; default: every bushing "
        "between measured parts).")] = None,
    axisymmetric: Annotated[list[str] | None, typer.Option(
        help="Bushing whose x and y stiffnesses are merged (repeatable).")] = None,
    start: Annotated[float | None, typer.Option(
        help="Start every stiffness of the identified bushings here (N/mm and N·mm/deg; the "
        "thesis: 1e4). Default: the model's values.")] = None,
    r_min: Annotated[float, typer.Option(help="Correlation gate.")] = 0.75,
    eps: Annotated[float, typer.Option(help="Relative-change stop.")] = 0.01,
    resolution: Annotated[str, typer.Option(
        help="Measurement resolution 'mm,deg': a direction whose deformation varies less is "
        "not identified ('none': no such gate).")] = "0.001,0.01",
    max_iterations: Annotated[int, typer.Option(help="Bound on the loop.")] = 100,
    polish: Annotated[bool, typer.Option(
        "--polish/--no-polish", help="Then polish the loop's stiffnesses by least squares "
        "through the equilibrium (what the report recommends when the loop's model does not "
        "reproduce the data); the model written is the polished one.")] = False,
    reorder: ReorderOpt = False,
    out: OutOpt = None,
    write_model: WriteModelOpt = None,
    figures: FiguresOpt = None,
    json_output: JsonOpt = False,
):
    """Identify bushing stiffnesses by the thesis's iterative correlation loop (spec stiffness
    §2): each pass solves every load case with the current stiffnesses and regresses each
    direction's bushing force on its measured deformation.
    """
    import numpy as np

    check_identify_outputs(out, write_model, figures)
    res = None
    if resolution.strip().lower() != "none":
        try:
            mm, deg = (float(v) for v in resolution.split(","))
        except ValueError:
            raise fail(f"--resolution must be 'mm,deg' or 'none'; got '{resolution}'.",
                       EXIT_BAD_INPUT) from None
        res = (mm, deg)
    enable_x64()
    from .. import measure
    from ..geometry import DEG
    from ..identify import iterative
    from ..identify.selection import measured_bushings, with_start

    res = None if res is None else (res[0], res[1] * DEG)  # deg → rad
    from ..identify.tables import interrupted_iterative_rows, iterative_figures

    with cli_errors():
        model_file = load_model_file(model, side=side)
        mech = model_file.mechanism
        meas = measure.read_measurements(measurements, mech, reorder=reorder)
        names = measured_bushings(mech, meas, bushing)
        d_t, d_r = measure.bushing_deformations(mech, meas, names)
        measured = np.concatenate([np.asarray(d_t), np.asarray(d_r)], axis=-1)
        mech0 = with_start(mech, names, start)
        last = []
        with _progress() as progress, _save_on_interrupt(out, lambda: interrupted_iterative_rows(
                mech0, names, last[0] if last else None), "iteration"):
            task = progress.add_task("iteration", total=max_iterations)

            def step(i, record):
                last[:] = [record]
                progress.update(task, completed=i,
                                description=f"iteration {i}: largest change "
                                f"{100 * record.max_change:.3g}%")

            fitted, report = iterative(
                mech0, meas.loads, names, measured=measured,
                axisymmetric=tuple(axisymmetric or ()), r_min=r_min, resolution=res, eps=eps,
                max_iterations=max_iterations, callback=step, polish=polish)
        if out is not None:
            report.write(out)
        if write_model is not None:
            write_model_file(fitted, write_model, model_file)
        paths = []
        if figures is not None:
            paths = _save_figures(iterative_figures(report, mech0, fitted, meas), figures)
    if json_output:
        print_json(dict(report.to_dict(), polished=None if report.polished is None
                        else report.polished.to_dict()))
    else:
        con = console(markup=False)
        con.print(f"{mech.name}: iterative identification from {measurements.name} "
                  f"({meas.n_cases} cases)", highlight=False)
        from ..identify.report import format_table

        con.print(format_table(report, 120), highlight=False)
        for note in report.notes:
            con.print(f"note: {note}", highlight=False)
        if report.polished is not None:
            con.print("polished by least squares through the equilibrium (the model written):",
                      highlight=False)
            con.print(report.polished.table(), highlight=False)
        for label, path in (("report", out), ("identified model", write_model)):
            if path is not None:
                con.print(f"{label} written to {path}", highlight=False)
        if paths:
            con.print("figures: " + ", ".join(str(p) for p in paths), highlight=False)
    _exit_if_unsolvable(report)
    if not report.converged:
        raise fail(f"the iterative identification did not converge in {report.iterations} "
                   "iterations; the stiffnesses written are the last iteration's. Try more "
                   "--max-iterations or a larger --eps.", EXIT_NOT_CONVERGED)


# ----------------------------------------------------------------------------- fit


def fit_command(
    model: ModelArg,
    measurements: Annotated[Path, typer.Option(
        "--measurements", "-m",
        help="Landmark or pose table with the loads of each case (.csv or .parquet); any "
        "subset of the parts.")],
    side: SideOption = None,
    bushing: Annotated[list[str] | None, typer.Option(
        "--bushing", "-b", help="Bushing whose stiffnesses are identified (repeatable; default: "
        "all).")] = None,
    axes: Annotated[str | None, typer.Option(
        help="Stiffness axes, e.g. 'Ktx,Ktz,Krz' (default: all six).")] = None,
    centres: Annotated[bool, typer.Option(
        help="Also identify the bushings' centres (hardpoints, mm).")] = False,
    springs: Annotated[bool, typer.Option(help="Also identify the spring rates.")] = False,
    start: Annotated[float | None, typer.Option(
        help="Start every identified stiffness here (N/mm and N·mm/deg). Default: the model's "
        "values.")] = None,
    sigma: Annotated[float, typer.Option(
        help="Measurement σ (mm): landmark or pose translation (the thesis's arm: 0.05).")]
    = 0.05,
    sigma_rotation: Annotated[float, typer.Option(
        help="Pose rotation σ (deg), pose tables only.")] = 0.01,
    loss: Annotated[Loss, typer.Option(help="Robust loss of the residuals.")] = Loss.linear,
    max_sigma_pct: Annotated[float, typer.Option(
        help="Largest sigma% (at the start values) still called identified.")] = 10.0,
    max_steps: Annotated[int, typer.Option(help="Levenberg–Marquardt steps.")] = 200,
    reorder: ReorderOpt = False,
    rig_sigma: Annotated[str | None, typer.Option(
        help="K&C-rig tables: σ per channel in the column's unit, e.g. 'toe=0.01,camber=0.01,"
        "wheel_centre_y=0.05' (replaces the table's '# sigma:' line).")] = None,
    out: OutOpt = None,
    write_model: WriteModelOpt = None,
    figures: FiguresOpt = None,
    json_output: JsonOpt = False,
):
    """Identify stiffnesses (and hardpoints) by least squares through the equilibrium: the
    model's landmarks or poses are fitted to the measured ones (Levenberg–Marquardt, exact
    derivatives), with σ, σ% and the combinations the data cannot see.

    A K&C-rig table (toe, camber, wheel-centre x/y/z, ... against the loads or the wheel
    travel of each case, σ per channel; format in `diffsusp.measure.rig`) is fitted as rig
    curves: the model on a K&C rig, the tyre force at the ground contact point.
    """
    check_identify_outputs(out, write_model, figures)
    loss = Loss(loss).value
    if not (sigma > 0 and sigma_rotation > 0):
        raise fail("--sigma and --sigma-rotation must be positive.", EXIT_BAD_INPUT)
    enable_x64()
    from .. import measure
    from ..geometry import DEG
    from ..identify import least_squares, returned_values
    from ..identify.selection import fit_selection
    from ..identify.tables import fit_figures, interrupted_fit_rows
    from ..measure.data import from_measurements
    from ..measure.rig import is_rig_table, read_rig_table, rig_measurement

    with cli_errors():
        model_file = load_model_file(model, side=side)
        mech = model_file.mechanism
        fit_mech, rig_notes = mech, []
        if is_rig_table(measurements):  # K&C-rig curves (`diffsusp.measure.rig`)
            meas = read_rig_table(measurements, sigma=rig_sigma)
            rig, data, rig_notes = rig_measurement(mech, meas)
            fit_mech = rig.mech
        elif rig_sigma is not None:
            from ..errors import InputError

            raise InputError(f"--rig-sigma is for K&C-rig tables; {measurements} is a landmark "
                             "or pose table (use --sigma).")
        else:
            meas = measure.read_measurements(measurements, mech, reorder=reorder)
            data = from_measurements(meas, sigma, sigma_rotation * DEG)
        params, notes = fit_selection(fit_mech, bushing, axes, centres=centres,
                                      springs=springs, start=start)
        notes = [*rig_notes, *notes]
        last = []
        with _progress() as progress, _save_on_interrupt(out, lambda: interrupted_fit_rows(
                params, last[0] if last else None), "LM step"):
            task = progress.add_task("step", total=max_steps)

            def step(i, record):
                if record.accepted or not last:
                    last[:] = [record]
                progress.update(task, completed=i, description=f"step {i}: loss "
                                f"{record.trial_loss:.4g}")

            fitted, report = least_squares(fit_mech, data, params, loss=loss,
                                           max_steps=max_steps, max_sigma_pct=max_sigma_pct,
                                           callback=step)
        if fit_mech is not mech:  # the rig's model → the user's, with the same values
            fitted = params.apply(mech, returned_values(report))
        if out is not None:
            report.write(out)
        if write_model is not None:
            write_model_file(fitted, write_model, model_file)
        paths = []
        if figures is not None and fit_mech is not mech:
            notes.append("--figures: the fit figures are drawn for landmark and pose tables; "
                         "not for a K&C-rig table.")
        elif figures is not None:
            paths = _save_figures(fit_figures(report, params.apply(mech, params.start), fitted,
                                              meas), figures)
    if json_output:
        print_json(dict(report.to_dict(), notes=notes))
    else:
        _print_fit(report, mech, measurements, meas, out, write_model, paths, notes)
    _exit_if_unsolvable(report)
    if not report.converged:
        raise fail(f"the fit did not converge ({report.message}) after {report.steps} steps; "
                   "the estimates written are the last accepted ones. Try more --max-steps, "
                   "other --start values, or fewer parameters.", EXIT_NOT_CONVERGED)


def _print_fit(report, mech, measurements, meas, out, write_model, paths, notes=()):
    con = console(markup=False)
    channels = getattr(meas, "channels", None)  # a K&C-rig table
    kind = f"K&C rig: {', '.join(channels)}; " if channels else ""
    table = RichTable(
        title=f"{mech.name}: least-squares fit to {measurements.name} ({kind}{meas.n_cases} "
        f"cases, {report.n_residuals} residuals, loss {report.loss_name})", box=box.SIMPLE_HEAD)
    for col in ("parameter", "start", "estimate", "sigma", "sigma%", "unit", "status"):
        table.add_column(col, justify="left" if col in ("parameter", "unit", "status")
                         else "right", no_wrap=col != "status")
    for row in report.csv_rows():
        pct = row["sigma_pct"]
        table.add_row(row["parameter"], f"{row['start']:.6g}", f"{row['value']:.6g}",
                      f"{row['sigma']:.3g}", f"{pct:.3g}" if pct == pct else "—", row["unit"],
                      row["status"] + (f": {row['reason']}" if row["reason"] else ""))
    con.print(table)
    if report.null_space:
        con.print("combinations the data cannot see (internal coordinates: log K, mm):")
        for d in report.null_space:
            con.print(f"  {d.text}  (σ {d.sigma:.3g})", highlight=False)
    state = "converged" if report.converged else "NOT converged"
    con.print(f"{state} in {report.steps} steps ({report.accepted_steps} accepted); chi2/dof "
              f"{report.chi2 / max(report.dof, 1):.3g}.", highlight=False)
    if report.consistency is not None:
        con.print(f"model vs data: {report.consistency.verdict}", highlight=False)
    for note in notes:
        con.print(f"note: {note}", highlight=False)
    outliers = report.outliers(threshold=5.0)
    if outliers:
        con.print(f"{len(outliers)} residual(s) beyond 5σ, largest "
                  f"{max(abs(o[2]) for o in outliers):.3g}σ (try --loss huber).", highlight=False)
    for label, path in (("report", out), ("identified model", write_model)):
        if path is not None:
            con.print(f"{label} written to {path}", highlight=False)
    if paths:
        con.print("figures: " + ", ".join(str(p) for p in paths), highlight=False)
