"""`diffsusp sensitivity MODEL --event NAME`: exact sensitivities of K&C metrics to parameters.

Runs a K&C event (the events and range options of `diffsusp kc`), differentiates every metric
with respect to the chosen parameters through the implicit equilibrium
(`diffsusp.identify.sensitivity`, spec stiffness §3 perspective 3) and prints, per metric, the
parameters ranked by elasticity (relative change of the metric, in units of its largest
magnitude over the event, per relative change of a stiffness or per mm of a hardpoint).
`--json` prints the full Jacobians; `--out DIR` writes one bar chart per metric (PNG, SVG).
"""

import enum
import pathlib
import time
from typing import Annotated

import typer
from rich import box
from rich.table import Table

from ..identify import PARAMETER_SETS
from ..kc.dispatch import corner_with, run_event
from .common import (
    EXIT_BAD_INPUT,
    SideOption,
    check_output,
    cli_errors,
    console,
    enable_x64,
    fail,
    load_model_file,
    print_json,
)
from .kc import Event, EventOption

ParameterSet = enum.StrEnum("ParameterSet", {name: name for name in PARAMETER_SETS})
"""The `--params` choices: the named sets of `identify.sensitivity.PARAMETER_SETS`."""

ParamsOption = Annotated[ParameterSet, typer.Option(
    "--params", "-p", help="parameters: " + "; ".join(f"{k}: {v}" for k, v in
                                                     PARAMETER_SETS.items()))]


def register(app: typer.Typer) -> None:
    """Add `sensitivity` to `app`."""
    app.command("sensitivity")(sensitivity_command)


def sensitivity_command(
    model: Annotated[str, typer.Argument(help="built-in model name or model file path")],
    side: SideOption = None,
    event: EventOption = Event.parallel_travel,
    params: ParamsOption = ParameterSet.stiffness,
    metric: Annotated[list[str] | None, typer.Option(
        "--metric", help="metric to report (repeatable; default: toe, camber, half-track "
        "change and the derivative metrics the event has)")] = None,
    top: Annotated[int, typer.Option(help="parameters shown per metric")] = 5,
    derivatives: Annotated[bool, typer.Option(
        help="include the derivative metrics (bump steer, wheel rate, compliance steer...: "
        "second derivatives of the equilibrium, a longer compile)")] = True,
    travel: Annotated[str, typer.Option(help="wheel travel range (mm) start:stop:count")]
    = "-80:80:17",
    fz: Annotated[str | None, typer.Option(help="vertical load (N), as for `diffsusp kc`")]
    = None,
    force: Annotated[str, typer.Option(help="lateral / braking / traction force range (N)")]
    = "-4000:4000:9",
    torque: Annotated[str, typer.Option(help="aligning torque range (N·m)")] = "-200:200:9",
    rack: Annotated[str, typer.Option(help="rack travel range (mm)")] = "-30:30:13",
    out: Annotated[pathlib.Path | None, typer.Option(
        help="write one sensitivity bar chart per metric (PNG and SVG) to this folder")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="machine-readable output on stdout")]
    = False,
):
    """Exact sensitivities of MODEL's K&C metrics over an event to its stiffnesses or
    hardpoints, ranked by elasticity."""
    if top < 1:
        raise fail("--top must be at least 1.", EXIT_BAD_INPUT)
    check_output(out, what="figures folder", directory=True)
    enable_x64()
    from ..identify import parameter_set, sensitivity, sensitivity_metrics

    err = console(stderr=True, markup=False)
    with cli_errors():
        mech = load_model_file(model, side=side).mechanism
        corner = corner_with(mech, frame=None, loaded_radius=None, kingpin=None, tyre=None)
        t0 = time.perf_counter()
        with err.status(f"running {event.value} on {mech.name} and differentiating (the first run "
                        "compiles, 1–3 min)..."):
            ev = run_event(mech, Event(event).value, corner, travel=travel, fz=fz, force=force,
                           torque=torque, rack=rack)
            selection = parameter_set(ev.rig.mech, params.value)
            names = sensitivity_metrics(ev, metric, derivatives=derivatives)
            report = sensitivity(ev, selection, metrics=names, derivatives=derivatives)
        elapsed = time.perf_counter() - t0
        paths = []
        if out is not None:
            from diffsusp import plot

            for name in names:
                fig = report.plot(name, top=max(top, 12))
                paths += plot.save(fig, out / f"sensitivity_{name.replace('/', '_')}")
    if as_json:
        print_json({"model": mech.name, **report.summary()})
        return
    con = console(markup=False)
    con.print(_table(report, mech.name, ev, params, top))
    con.print(f"elasticity: ∂metric/∂θ · θ / max|metric| over the event (θ → 1 mm for "
              f"positions); sign + means the metric grows with the parameter. {len(ev.x)} "
              f"cases, {len(report.params)} parameters, {elapsed:.1f} s.", highlight=False)
    if paths:
        con.print("figures: " + ", ".join(str(p) for p in paths), highlight=False)


def _table(report, mech_name, ev, params, top) -> Table:
    """One row per metric and rank (metric, rank, parameter, elasticity): as narrow as the
    longest names, whatever `top` (a column per rank would cut the numbers)."""
    table = Table(title=f"{mech_name}: sensitivities over {ev.name.replace('_', ' ')} "
                  f"({params})", box=box.SIMPLE_HEAD)
    for head in ("metric", "#", "parameter"):
        table.add_column(head, no_wrap=True)
    table.add_column("elasticity", justify="right", no_wrap=True)
    for name in report.elasticity:
        for k, (p, v) in enumerate(report.ranked(name)[:top]):
            table.add_row(name if k == 0 else "", str(k + 1), p, f"{v:+.4g}",
                          end_section=k == min(top, len(report.params)) - 1)
    return table
