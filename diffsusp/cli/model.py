"""`diffsusp info MODEL` and `diffsusp simulate MODEL --loads TABLE --out RESULTS`.

MODEL is anything `diffsusp.load_model` reads: a native `.toml` file, an Adams `.adm`, a
Chrono `.json`, or a built-in model name (`diffsusp.models.ZOO`, or `STOP_VARIANTS` such as
`pseudo_mcpherson_stops`: the axles with bump and rebound stops). TABLE is a CSV/Parquet load
table (columns in `diffsusp.io.tables`) or the name of a load table in the model file.
"""

import time
import warnings
from typing import Annotated

import typer
from rich import box
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn
from rich.table import Table as RichTable
from rich.text import Text

from ..model import describe, parameter_leaves
from .common import (
    EXIT_BAD_INPUT,
    EXIT_INTERRUPTED,
    EXIT_NOT_CONVERGED,
    JsonOption,
    ModelArgument,
    SideOption,
    Terminated,
    check_output,
    cli_errors,
    console,
    enable_x64,
    fail,
    flagged_note,
    listed,
    load_model_file,
    print_json,
    warn,
)


def register(app: typer.Typer) -> None:
    """Add `info` and `simulate` to `app`."""
    app.command("info")(info_command)
    app.command("simulate")(simulate_command)


def info_command(
    model: ModelArgument,
    side: SideOption = None,
    json_output: JsonOption = False,
):
    """Describe a model: parts, markers, joints, elements, DOF, rank, redundant rows, free modes
    and its parameters (float leaves) with their shapes and units."""
    enable_x64()
    with cli_errors():
        from ..kc import design_load
        from ..statics import validate

        mf = load_model_file(model, check=False, side=side)
        mech = mf.mechanism
        report = validate(mech)
    described = describe(mech)
    summary = dict(
        name=described.pop("name"),
        source=model,
        **described,
        load_tables={k: dict(rows=t.n_rows, columns=list(t.names))
                     for k, t in mf.load_tables.items()},
        coordinates=report.n_coordinates,
        constraint_rows=report.n_rows,
        rank=report.rank,
        dof=report.dof,
        redundant=list(report.redundant),
        free_modes=list(report.free_modes),
        max_assembly_error=report.max_assembly_error,
        parameters=parameter_leaves(mech),
    )
    for c, corner in zip(summary["corners"], mech.corners, strict=True):
        try:  # `info` describes a model that does not solve too (`validate` says why)
            c["design_load_value"] = design_load(mech, corner)
        except Exception:  # noqa: BLE001
            c["design_load_value"] = None
    if json_output:
        print_json(summary)
        return
    out = console(markup=False)
    out.print(Text(mech.name, style="bold") + Text(f" ({model})"), highlight=False)
    out.print(Text(f"parts ({len(mech.parts)}): {', '.join(mech.parts)}"), highlight=False)
    out.print(f"markers: {summary['markers']}")
    for label, items in (("bushings", summary["bushings"]), ("springs", summary["springs"]),
                         ("stops", summary["stops"]), ("drivers", summary["drivers"]),
                         ("load points", summary["load_points"])):
        out.print(Text(f"{label} ({len(items)}): {', '.join(items) or '-'}"), highlight=False)
    for c in summary["corners"]:
        kingpin = " – ".join(map(str, c["kingpin"])) if c["kingpin"] else "none"
        load = (f"{c['design_load']:g} N" if c["design_load"] is not None else
                _design_load_text(c["design_load_value"]))
        out.print(Text(
            f"corner {c['prefix'] or ''}: {c['side']} side, {c['frame']} frame, wheel centre "
            f"{c['wheel_centre']}, contact point {c['contact_point']}, loaded radius "
            f"{c['loaded_radius']:g} mm, kingpin {kingpin}, design load {load}"),
            highlight=False)
    joints = ", ".join(f"{j['name']} ({j['kind']})" for j in summary["joints"])
    out.print(Text(f"joints ({len(summary['joints'])}): {joints or '-'}"), highlight=False)
    if mf.load_tables:
        tables = ", ".join(f"{k} ({v['rows']} rows)" for k, v in summary["load_tables"].items())
        out.print(Text(f"load tables: {tables}"), highlight=False)
    out.print(Text(
        f"coordinates: {report.n_coordinates}, constraint rows: {report.n_rows}, rank: "
        f"{report.rank}, DOF: {report.dof}"), highlight=False)
    out.print(Text(f"redundant rows: {', '.join(report.redundant) or 'none'}"), highlight=False)
    out.print(Text(f"free modes: {'; '.join(report.free_modes) or 'none'}"), highlight=False)
    table = RichTable(title="parameters (float leaves)", box=box.SIMPLE_HEAD)
    for col in ("leaf", "shape", "unit"):
        table.add_column(col, no_wrap=True)
    for p in summary["parameters"]:
        table.add_row(p["path"], "×".join(map(str, p["shape"])), p["unit"])
    out.print(table)


def _design_load_text(value: float | None) -> str:
    """'computed: -11.6 kN (...)' with what the sign means for the model at design."""
    if value is None or value != value:
        return "computed (not available: the corner does not resolve)"
    if abs(value) < 1e-6:
        meaning = "none: the design position is the unloaded one"
    elif value > 0:
        meaning = ("upward on the wheel: the springs carry the wheel load at design, as on "
                   "the road")
    else:
        meaning = ("DOWNWARD: the design position holds only if the wheel is pulled down, so "
                   "the spring is in tension at design (check its free length or preload)")
    return (f"computed: {value / 1000:.3g} kN, the vertical contact load that holds the design "
            f"position ({meaning})")


def simulate_command(
    model: ModelArgument,
    loads: Annotated[str, typer.Option(
        "--loads", "-l", help="Load table (.csv, .parquet) or a load table of the model.")],
    out: Annotated[str, typer.Option(
        "--out", "-o", help="Results table to write (.csv, .parquet).")],
    side: SideOption = None,
    max_steps: Annotated[int, typer.Option(
        "--max-steps", help="Newton iterations per case.")] = 50,
    json_output: JsonOption = False,
):
    """Solve the static equilibrium of MODEL under every row of a load table and write one row
    of results per case (status, stable and law_valid flags, poses, bushing deformations and
    forces, springs).

    A converged case whose equilibrium is unstable or turns a bushing beyond its law's validity
    is written with its flag at 0 and named in a warning (exit 0).

    Rows are written as their cases are solved (256 at a time): a run interrupted by Ctrl-C or
    SIGTERM leaves the finished cases on disk and the others with status -1 (exit 130)."""
    # A bad output path fails before the model is read, let alone solved.
    check_output(out, suffixes=(".csv", ".txt", ".parquet", ".pq"), what="results table")
    if max_steps < 1:
        raise fail(f"--max-steps must be at least 1; got {max_steps}.", EXIT_BAD_INPUT)
    enable_x64()
    from .. import simulation

    t0 = time.perf_counter()
    with cli_errors():
        mf = load_model_file(model, side=side)
        mech = mf.mechanism
        table = simulation.load_cases(mf, loads)
        with warnings.catch_warnings(record=True) as caught, Progress(
                "solving" + (" (compiling first)" if table.n_rows <= simulation.CHUNK else ""),
                BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                console=console(stderr=True, markup=False), transient=True,
                disable=json_output) as bar:
            warnings.simplefilter("always")
            task = bar.add_task("cases", total=table.n_rows)
            run = simulation.simulate_table(
                mech, table, out, max_steps=max_steps,
                progress=lambda done: bar.update(task, completed=done))
    elapsed = time.perf_counter() - t0
    notes = sorted({str(w.message) for w in caught
                    if "cases did not converge" not in str(w.message)})
    summary = dict(model=mech.name, source=model, loads=loads, **run.summary(), out=str(out),
                   seconds=elapsed, warnings=notes)
    if json_output:
        print_json(summary)
    else:
        con = console(markup=False)
        con.print(Text(
            f"{mech.name}: {summary['converged']} of {summary['cases']} load cases converged "
            f"in {elapsed:.2f} s; {summary['columns']} columns written to {out}"))
    for note in notes:
        warn(note)
    for key, what in (("unstable", "with an unstable equilibrium (the reduced tangent "
                       "stiffness is not positive definite; column 'stable' = 0)"),
                      ("law_invalid", "beyond a bushing law's validity (|AX|, |AY| < 15°, "
                       "|AZ| < 90°; column 'law_valid' = 0)")):
        if summary[key]:
            warn(flagged_note(summary[key], "load case", what))
    n, done = summary["cases"], run.done
    if run.interrupted is not None:
        what = ("terminated (SIGTERM)" if isinstance(run.interrupted, Terminated) else
                "interrupted")
        raise fail(f"{what} after {done} of {n} load cases; the rows of the {n - done} not "
                   f"solved have status -1 in {out}.", EXIT_INTERRUPTED)
    failed = summary["failed"]
    if failed:
        shown = listed([f"{d['case']} ({d['status']})" for d in failed])
        raise fail(
            f"{len(failed)} load case{'s' * (len(failed) != 1)} did not converge: {shown}. "
            f"Their rows in {out} have a non-zero status.", EXIT_NOT_CONVERGED)
