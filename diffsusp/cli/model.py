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
from rich.table import Table as RichTable
from rich.text import Text

from ..model import describe, parameter_leaves
from .common import (
    EXIT_BAD_INPUT,
    EXIT_INTERRUPTED,
    EXIT_NOT_CONVERGED,
    SideOption,
    Terminated,
    check_output,
    cli_errors,
    console,
    enable_x64,
    fail,
    interruptible,
    load_model_file,
    print_json,
    warn,
)

_CHUNK = 256
"""Cases per solve (`diffsusp.statics.solve_statics_chunks`: the last chunk is padded so every
chunk reuses one compiled shape)."""


ModelArgument = Annotated[str, typer.Argument(
    help="Model file (.toml, .adm, .json) or built-in name.")]
"""MODEL of `info` and `simulate`."""


def register(app: typer.Typer) -> None:
    """Add `info` and `simulate` to `app`."""
    app.command("info")(info_command)
    app.command("simulate")(simulate_command)


def info_command(
    model: ModelArgument,
    side: SideOption = None,
    json_output: Annotated[bool, typer.Option("--json", help="Machine-readable output.")]
    = False,
):
    """Describe a model: parts, markers, joints, elements, DOF, rank, redundant rows, free modes
    and its parameters (float leaves) with their shapes and units."""
    enable_x64()
    with cli_errors():
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
        c["design_load_value"] = _design_load(mech, corner)
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


def _design_load(mech, corner) -> float | None:
    """The corner's design load (N, vertical up at its contact point): the stated one, or the
    load that holds the design position (`kc.design_load` when the model states none); None
    when the corner cannot be resolved."""
    from ..kc.corner import design_load

    if corner.design_load is not None:
        return float(corner.design_load)
    try:
        return design_load(mech, corner)
    except Exception:  # noqa: BLE001 - `info` describes broken models too; validate says why
        return None


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


def _load_table(mf, loads: str):
    import os

    from ..errors import ModelFileError
    from ..io import read_table

    if loads in mf.load_tables and not os.path.exists(loads):
        return mf.load_tables[loads]
    if not os.path.exists(loads):
        known = ", ".join(mf.load_tables) or "none"
        raise ModelFileError(
            f"no such file, and not a load table of the model (its tables: {known}); give a "
            ".csv or .parquet load table.", path=loads)
    return read_table(loads)


class _Run:
    """What `_solve_and_write` did: per-case status, flags and residuals (NaN / -1 / False for
    cases not solved), the number of result columns, and whether it was interrupted."""

    def __init__(self, n):
        import numpy as np

        self.status = np.full(n, -1, dtype=int)
        self.stable = np.zeros(n, dtype=bool)
        self.law_valid = np.zeros(n, dtype=bool)
        self.residual = np.full(n, np.nan)
        self.constraint_error = np.full(n, np.nan)
        self.columns = 0
        self.done = 0
        self.interrupted = None

    def record(self, start: int, stop: int, sol) -> None:
        """Keep the status, flags and residuals of the solved cases `start:stop`."""
        import numpy as np

        self.status[start:stop] = np.asarray(sol.status)
        self.stable[start:stop] = np.asarray(sol.stable)
        self.law_valid[start:stop] = np.asarray(sol.law_valid)
        self.residual[start:stop] = np.asarray(sol.residual)
        self.constraint_error[start:stop] = np.asarray(sol.constraint_error)
        self.done = stop


def _solve_and_write(mech, loads, table, out, max_steps: int, quiet: bool) -> _Run:
    """Solve every case in chunks (`diffsusp.statics.solve_statics_chunks`) and append each
    chunk's rows to `out` as it completes; on SIGINT / SIGTERM, write the cases not solved with
    status -1 and stop (a spinner for one chunk, a progress bar over chunks otherwise)."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

    from ..io.tables import TableWriter
    from ..statics import solve_statics_chunks

    err = console(stderr=True, markup=False)
    n = loads.n_cases
    run = _Run(n)
    writer = None

    def write(res):
        nonlocal writer
        if writer is None:
            writer = TableWriter(out, res.names, res.units)
            run.columns = len(res.names)
        writer.append(dict(res.columns))

    try:
        with interruptible(), Progress(
                "solving" + (" (compiling first)" if n <= _CHUNK else ""), BarColumn(),
                MofNCompleteColumn(), TimeElapsedColumn(), console=err, transient=True,
                disable=quiet) as bar:
            task = bar.add_task("cases", total=n)
            for start, stop, sol in solve_statics_chunks(mech, loads, _CHUNK,
                                                         max_steps=max_steps, throw=False):
                write(_results(mech, sol, table, start, stop))
                run.record(start, stop, sol)
                bar.update(task, completed=stop)
    except KeyboardInterrupt as e:
        run.interrupted = "terminated (SIGTERM)" if isinstance(e, Terminated) else "interrupted"
    finally:
        if run.done < n:
            # The rest: their loads and status -1, every output NaN.
            write(_results(mech, _unsolved(mech, n - run.done), table, run.done, n,
                           solved=False))
        if writer is not None:
            writer.close()
    return run


def _results(mech, sol, table, start: int, stop: int, *, solved: bool = True):
    """The results rows of cases `start:stop` (`diffsusp.io.results_table`), their load columns
    from `table` (`solved=False`: the stand-in of cases not solved)."""
    import numpy as np

    from ..io import results_table
    from ..io.tables import Table
    from ..statics import bushing_states, spring_states

    part = Table(columns={k: v[start:stop] for k, v in table.columns.items()},
                 units=dict(table.units))
    if solved:
        bushings = bushing_states(mech, sol.q) if mech.bushings.names else None
        springs = spring_states(mech, sol.q) if mech.springs.names else None
    else:  # NaN element states, no program to compile
        k, n_b, n_s = stop - start, len(mech.bushings.names), len(mech.springs.names)
        bushings, springs = [np.full((k, n_b, 3), np.nan)] * 4, [np.full((k, n_s), np.nan)] * 2
    return results_table(mech, sol, part, first_case=start, bushings=bushings, springs=springs)


def _unsolved(mech, n):
    """A stand-in solution for cases not solved: NaN outputs, status -1, flags 0."""
    import types

    import numpy as np

    nan = np.full(n, np.nan)
    return types.SimpleNamespace(
        q=np.full((n, 6 * len(mech.parts)), np.nan), status=np.full(n, -1),
        iterations=np.zeros(n), residual=nan, constraint_error=nan, stable=np.zeros(n, bool),
        law_valid=np.zeros(n, bool))


def simulate_command(
    model: ModelArgument,
    loads: Annotated[str, typer.Option(
        "--loads", "-l", help="Load table (.csv, .parquet) or a load table of the model.")],
    out: Annotated[str, typer.Option(
        "--out", "-o", help="Results table to write (.csv, .parquet).")],
    side: SideOption = None,
    max_steps: Annotated[int, typer.Option(
        "--max-steps", help="Newton iterations per case.")] = 50,
    json_output: Annotated[bool, typer.Option("--json", help="Print a JSON summary.")] = False,
):
    """Solve the static equilibrium of MODEL under every row of a load table and write one row
    of results per case (status, stable and law_valid flags, poses, bushing deformations and
    forces, springs).

    A converged case whose equilibrium is unstable or turns a bushing beyond its law's validity
    is written with its flag at 0 and named in a warning (exit 0).

    Rows are written as their cases are solved (256 at a time): a run interrupted by Ctrl-C or
    SIGTERM leaves the finished cases on disk and the others with status -1 (exit 130)."""
    import numpy as np

    from ..io import loads_from_table
    from ..io.tables import RESULT_STATUS
    from ..statics import flagged_cases

    # A bad output path fails before the model is read, let alone solved.
    check_output(out, suffixes=(".csv", ".txt", ".parquet", ".pq"), what="results table")
    if max_steps < 1:
        raise fail(f"--max-steps must be at least 1; got {max_steps}.", EXIT_BAD_INPUT)
    enable_x64()
    t0 = time.perf_counter()
    with cli_errors():
        mf = load_model_file(model, side=side)
        mech = mf.mechanism
        table = _load_table(mf, loads)
        if table.n_rows == 0:
            from ..errors import InputError

            raise InputError(f"{loads}: the load table has no rows; give one row per load "
                             "case.")
        case_loads = loads_from_table(mech, table)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            run = _solve_and_write(mech, case_loads, table, out, max_steps, json_output)
    elapsed = time.perf_counter() - t0
    status = run.status
    flags = flagged_cases(run)
    failed = flags["failed"]
    notes = sorted({str(w.message) for w in caught
                    if "cases did not converge" not in str(w.message)})
    finite = run.residual[np.isfinite(run.residual)]
    summary = dict(
        model=mech.name,
        source=model,
        loads=loads,
        cases=int(status.size),
        converged=int(np.sum(status == 0)),
        not_solved=int(np.sum(status == -1)),
        failed=[dict(case=int(c), status=RESULT_STATUS.get(int(status[c]), str(status[c])),
                     residual=float(run.residual[c])) for c in failed],
        unstable=flags["unstable"].tolist(),
        law_invalid=flags["law_invalid"].tolist(),
        max_residual=float(np.max(finite, initial=0.0)),
        max_constraint_error=float(np.nanmax(run.constraint_error, initial=0.0)),
        out=str(out),
        columns=run.columns,
        seconds=elapsed,
        warnings=notes,
        interrupted=bool(run.interrupted),
    )
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
        cases = summary[key]
        if cases:
            shown = ", ".join(map(str, cases[:10])) + (
                f" and {len(cases) - 10} more" if len(cases) > 10 else "")
            warn(f"{len(cases)} converged load case{'s' * (len(cases) != 1)} {what}: "
                 f"{shown}.")
    if run.interrupted:
        raise fail(
            f"{run.interrupted} after {run.done} of {status.size} load cases; the rows of the "
            f"{status.size - run.done} not solved have status -1 in {out}.", EXIT_INTERRUPTED)
    if failed.size:
        shown = ", ".join(f"{d['case']} ({d['status']})" for d in summary["failed"][:10])
        more = f" and {failed.size - 10} more" if failed.size > 10 else ""
        raise fail(
            f"{failed.size} load case{'s' * (failed.size != 1)} did not converge: {shown}{more}. "
            f"Their rows in {out} have a non-zero status.", EXIT_NOT_CONVERGED)
