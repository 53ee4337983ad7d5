"""`diffsusp fleet RECIPE --items GLOB|LIST --out DIR [--workers N | --scheduler ADDRESS]` and
`diffsusp fleet status DIR`: one identification per data set, many data sets
(`diffsusp.fleet`).

RECIPE is `direct`, `iterative`, `least-squares` (measurement tables), `kc` (K&C load tables
with columns F_vert, F_lat, F_long; or, with `--option event=NAME`, model files run through
that event of `diffsusp kc`) or `tyre-fit` (bench tables, `--model START.tir`). `--items` is a
glob (quote it: the program expands it, so a remote scheduler sees the same list), a path, or
a `.txt` file listing one path per line; repeatable. Each item's report goes to
`DIR/reports/ITEM.json` (the JSON of the single-item verb: `diffsusp identify … --out`,
`diffsusp kc --json`, `diffsusp tyre fit --report`) as soon as its batch is done, one row per
item to `DIR/summary.csv`; a second run in the same DIR skips the items done (same content
hash). `--devices N|all` splits a batch over a worker's local devices.
Without `--workers` or `--scheduler` the fleet runs in this process. Exit codes: 0 every item
ok, 3 some items failed (listed, and in the summary), 2 bad input.
"""

import inspect
import json
import pathlib
from typing import Annotated

import typer

from .common import (
    EXIT_BAD_INPUT,
    EXIT_NOT_CONVERGED,
    JsonOption,
    check_output,
    cli_errors,
    console,
    enable_x64,
    fail,
    print_json,
)

fleet_app = typer.Typer(add_completion=False, no_args_is_help=True,
                        help="Many identifications, one per data set, in-process or on a Dask "
                        "cluster; resumable.")


def register(app: typer.Typer) -> None:
    """Add the `fleet` group to `app`, with its verbs (one per recipe, and `status`)."""
    app.add_typer(fleet_app, name="fleet")
    fleet_app.command("direct")(direct_command)
    fleet_app.command("iterative")(iterative_command)
    fleet_app.command("least-squares")(least_squares_command)
    fleet_app.command("kc")(kc_command)
    fleet_app.command("tyre-fit")(tyre_fit_command)
    fleet_app.command("status")(status_command)

ItemsOpt = Annotated[list[str], typer.Option(
    "--items", "-i", help="Data sets: a glob ('data/*.csv', quoted), a table, or a .txt list "
    "of paths (repeatable).")]
OutOpt = Annotated[pathlib.Path, typer.Option("--out", "-o", help="Output folder.")]
ModelOpt = Annotated[str | None, typer.Option(
    "--model", "-M", help="Model file (.toml, .adm, .json) or built-in name, for every item "
    "(tyre-fit: the start .tir).")]
DevicesOpt = Annotated[str | None, typer.Option(
    help="Local devices a worker splits a batch over: a count or 'all' (default "
    "$DIFFSUSP_DEVICES, else 1).")]
WorkersOpt = Annotated[int | None, typer.Option(
    help="Start a local Dask cluster of N worker processes.")]
SchedulerOpt = Annotated[str | None, typer.Option(
    help="Address of a running Dask scheduler (tcp://host:8786).")]
BatchOpt = Annotated[int, typer.Option(help="Items per task (and padded batch of a fit).")]
TimeOpt = Annotated[float | None, typer.Option(help="Time limit per item, seconds.")]
OptionOpt = Annotated[list[str] | None, typer.Option(
    "--option", help="Recipe option KEY=VALUE (VALUE as JSON, else text), e.g. hold=model, "
    "eliminate=true (repeatable): the identification function's keyword arguments.")]
RetryOpt = Annotated[bool, typer.Option(help="Also re-run the items that failed before.")]


def _options(values: list[str] | None) -> dict:
    """`--option KEY=VALUE` (VALUE as JSON, else text) → the recipe's keyword arguments."""
    options = {}
    for v in values or ():
        key, sep, text = v.partition("=")
        if not sep or not key.strip():
            raise fail(f"--option must be KEY=VALUE; got '{v}'.", EXIT_BAD_INPUT)
        try:
            options[key.strip()] = json.loads(text)
        except json.JSONDecodeError:
            options[key.strip()] = text
    return options


def _recipe_command(recipe: str, doc: str, *, model_required: bool = True):
    """The verb `diffsusp fleet <recipe>`: `diffsusp.fleet.run` on the items, then its result
    and the failures (`diffsusp.fleet.status`); exit 3 when some item failed. `--model` is
    required unless the recipe's items can carry their own model."""

    def command(
        items: ItemsOpt, out: OutOpt, model: ModelOpt = None, workers: WorkersOpt = None,
        scheduler: SchedulerOpt = None, batch_size: BatchOpt = 16, time_limit: TimeOpt = None,
        option: OptionOpt = None, retry_failed: RetryOpt = False, json_output: JsonOption = False,
        devices: DevicesOpt = None,
    ):
        check_output(out, what="fleet folder", directory=True)
        options = _options(option)
        enable_x64()
        from .. import fleet

        with cli_errors():
            result = fleet.run(recipe, items, out, model=model, options=options,
                               workers=workers, scheduler=scheduler, batch_size=batch_size,
                               time_limit=time_limit, retry_failed=retry_failed,
                               devices=devices, progress=not json_output)
            state = fleet.status(out)
        if json_output:
            print_json({"ok": result.ok, "failed": result.failed, "skipped": result.skipped,
                        "total": result.total, "seconds": result.seconds,
                        "items_per_s": result.items_per_s, "compiled": result.compiled,
                        "cache_hits": result.cache_hits, "summary": str(result.summary),
                        "failures": [list(f) for f in state.failures]})
        else:
            con = console(markup=False)
            con.print(result.text(), highlight=False)
            for item, st, msg in state.failures:
                con.print(f"  {item}: {st}: {msg}", highlight=False)
        if state.failed:
            raise typer.Exit(code=EXIT_NOT_CONVERGED)

    if model_required:
        signature = inspect.signature(command)
        command.__signature__ = signature.replace(parameters=[
            p.replace(default=inspect.Parameter.empty) if p.name == "model" else p
            for p in signature.parameters.values()])
    command.__name__ = command.__qualname__ = f"{recipe}_command"
    command.__doc__ = doc
    return command


direct_command = _recipe_command(
    "direct", "The direct (linear) stiffness identification on every data set.")
iterative_command = _recipe_command(
    "iterative", "The iterative (correlation loop) identification on every data set.")
least_squares_command = _recipe_command(
    "least_squares", "Least squares through the equilibrium on every data set, a batch at a "
    "time (vmapped).")
kc_command = _recipe_command(
    "kc", """A K&C event on every item: load tables (F_vert, F_lat, F_long, N) on --model, or
    with --option event=NAME (and its ranges, e.g. travel=-80:80:161) every item a model
    file.""", model_required=False)
tyre_fit_command = _recipe_command(
    "tyre_fit", """A Magic Formula fit of every bench table from the start tyre --model
    START.tir (options: groups, names, loss, noise, ...; a batch is one vmapped fit).""",
    model_required=False)


def status_command(
    out: Annotated[pathlib.Path, typer.Argument(help="The fleet's output folder.")],
    json_output: JsonOption = False,
):
    """Items done, failed (with their messages) and still to do in a fleet's folder."""
    from .. import fleet

    with cli_errors():
        state = fleet.status(out)
    if json_output:
        print_json({"recipe": state.recipe, "total": state.total, "ok": state.ok,
                    "failed": state.failed, "pending": state.pending,
                    "items_per_s": state.items_per_s,
                    "failures": [list(f) for f in state.failures]})
        return
    console(markup=False).print(state.text(), highlight=False)
