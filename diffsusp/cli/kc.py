"""`diffsusp kc MODEL --event NAME`: run a K&C event and print its metrics.

Events (`--event`): parallel-travel (default), opposite-travel (on an axle made of the model and
its mirror image), vertical-force, lateral-force, braking, traction, aligning-torque, steering
(a rack is added at the model's 'tie_rod'), table-5-1, table-4-4 (the thesis load tables).
Ranges are `start:stop:count` (inclusive, like numpy.linspace) or a single value. Units at the
command line: mm, N, N·m; angles printed in degrees.

Output: a table with each metric's value at the reference case (zero travel / force, or the
design load) and its range over the event; `--json` prints every value of every case instead
(display units, stated per metric), with each case's `status`, `stable` and `law_valid`;
`--out DIR` writes the K&C curves as PNG and SVG. Converged cases that are unstable or turn a
bushing beyond its law's validity are named in a warning (exit 0).
Exit codes (`cli.common`): 2 bad input (unknown model, file or event, bad range), 3 a case did
not converge, 4 a model that cannot be solved.
"""

import enum
import pathlib
import time
import warnings
from typing import Annotated

import typer
from rich import box
from rich.table import Table
from rich.text import Text

from ..kc.dispatch import (
    EVENTS,
    corner_with,
    default_load,
    event_json,
    loaded_radius_origin,
    reference_case,
    run_event,
)
from ..statics import flagged_cases
from .common import (
    JsonOption,
    ModelArgument,
    SideOption,
    check_output,
    cli_errors,
    console,
    enable_x64,
    flagged_note,
    load_model_file,
    print_json,
    show_warnings,
    warn,
)

Event = enum.StrEnum("Event", {name.replace("-", "_"): name for name in EVENTS})
"""The `--event` choices: the events of `diffsusp.kc.dispatch.EVENTS` (the one registry)."""


class Frame(enum.StrEnum):
    """The `--frame` choices: the model frame of a corner (`diffsusp.kc.Corner.frame`)."""

    adams = "adams"
    iso = "iso"


EventOption = Annotated[Event, typer.Option(
    "--event", "-e", help="K&C event: " + "; ".join(f"{k}: {v}" for k, v in EVENTS.items()))]
"""The one `--event` option of the verbs that run a K&C event (`kc`, `sensitivity`)."""


def register(app: typer.Typer) -> None:
    """Add `kc` to `app`."""
    app.command("kc")(kc_command)


def flag_notes(ev) -> list[str]:
    """One warning per flag that some converged case of the event fails (stable, law_valid)."""
    flags = flagged_cases(ev.solution)
    return [flagged_note(flags[key], "case", f"of the event with {what}",
                         f" ('{flag}' is false in --json).")
            for key, flag, what in (
                ("unstable", "stable", "an unstable equilibrium (the reduced tangent stiffness "
                 "is not positive definite)"),
                ("law_invalid", "law_valid", "a bushing beyond its law's validity (|AX|, |AY| "
                 "< 15°, |AZ| < 90°)"))
            if flags[key].size]


def _table(ev, mech_name: str) -> Table:
    import numpy as np

    from diffsusp import kc

    ref = reference_case(ev)
    x_scale = 1e-3 if ev.x_unit == "N·mm" else 1.0
    x_unit = "N·m" if ev.x_unit == "N·mm" else ev.x_unit
    x_ref = float(np.asarray(ev.x)[ref]) * x_scale
    title = (f"{mech_name}: {ev.name.replace('_', ' ')}, {len(ev.x)} cases; reference "
             f"{ev.x_name.replace('_', ' ')} = {x_ref:g} {x_unit}")
    table = Table(title=Text(title), box=box.SIMPLE_HEAD)
    for col, justify in (("metric", "left"), ("unit", "left"), ("reference", "right"),
                         ("min", "right"), ("max", "right")):
        table.add_column(col, justify=justify, no_wrap=True)
    for name in sorted(ev.metrics):
        values = kc.display(name, ev.metrics[name])
        finite = values[np.isfinite(values)]
        lo, hi = (f"{finite.min():.5g}", f"{finite.max():.5g}") if finite.size else ("-", "-")
        table.add_row(name, kc.display_unit(name), f"{values[ref]:.5g}", lo, hi)
    return table


def kc_command(
    model: ModelArgument,
    event: EventOption = Event.parallel_travel,
    travel: Annotated[str, typer.Option(help="wheel travel range (mm) start:stop:count")]
    = "-80:80:161",
    fz: Annotated[str | None, typer.Option(
        help="vertical load (N): one value for the force events (default: the design load), "
        "a range for vertical-force (default 0.5–1.5× the design load, 21 cases)")] = None,
    force: Annotated[str, typer.Option(help="lateral / braking / traction force range (N)")]
    = "-4000:4000:17",
    torque: Annotated[str, typer.Option(help="aligning torque range (N·m)")] = "-200:200:17",
    rack: Annotated[str, typer.Option(help="rack travel range (mm)")] = "-30:30:61",
    side: SideOption = None,
    frame: Annotated[Frame | None, typer.Option(
        help="model frame (default: the model's own corner)")] = None,
    loaded_radius: Annotated[float | None, typer.Option(
        help="loaded tyre radius (mm; default: the model's own corner, or --tyre)")] = None,
    tyre: Annotated[pathlib.Path | None, typer.Option(
        help="the tyre (.tir): the loaded radius is its radius at the design load (the tyre "
        "force acts at the ground contact point of that radius)")] = None,
    kingpin: Annotated[str | None, typer.Option(
        help="steering axis markers 'upper,lower'")] = None,
    out: Annotated[pathlib.Path | None, typer.Option(
        help="write figures (PNG and SVG) to this folder")] = None,
    as_json: JsonOption = False,
):
    """Run a K&C event on MODEL and print its metrics (Adams/Car conventions, per side)."""
    enable_x64()
    check_output(out, what="figures folder", directory=True)
    err = console(stderr=True, markup=False)
    with cli_errors(), warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mech = load_model_file(model, side=side).mechanism
        tyre_model = None
        if tyre is not None:
            from ..io.tir import read_tir
            from ..tyre import MagicFormula6

            tyre_model = MagicFormula6.from_tir(read_tir(tyre))
        corner = corner_with(mech, frame=None if frame is None else Frame(frame).value,
                             loaded_radius=loaded_radius, kingpin=kingpin,
                             tyre=tyre_model)
        radius = loaded_radius_origin(mech, corner, given=loaded_radius, tyre_file=tyre)
        t0 = time.perf_counter()
        with err.status(f"running {event.value} on {mech.name} (the first run compiles, "
                        "~30 s)..."):
            ev = run_event(mech, Event(event).value, corner, travel=travel, fz=fz, force=force,
                           torque=torque, rack=rack)
        elapsed = time.perf_counter() - t0
        if out is not None:
            from diffsusp import kc, plot

            names, derivatives = kc.default_plots(ev.name, ev.metrics)
            fig = plot.kc_curves(ev, names, title=f"{mech.name}: {ev.name.replace('_', ' ')}")
            paths = plot.save(fig, out / f"kc_{ev.name}")
            fig = plot.kc_curves(ev, derivatives, title=f"{mech.name}: derivatives")
            paths += plot.save(fig, out / f"kc_{ev.name}_derivatives")
    show_warnings(caught)
    for note in flag_notes(ev):
        warn(note)
    load = default_load(mech, Event(event).value, corner, fz)
    if as_json:
        data = event_json(ev, mech.name)
        if load is not None:
            data["design_load"] = load
        data["loaded_radius"] = radius
        print_json(data)
        return
    con = console(markup=False)
    con.print(_table(ev, mech.name))
    con.print(Text(f"Held fixed by the derivative metrics: {ev.held}. Signs: toe-in, camber top "
              "outboard, lateral force inboard, longitudinal force rearward (braking) positive "
              f"(Adams/Car, per side). {elapsed:.2f} s."), highlight=False)
    if load is not None:
        con.print(Text(f"Design load {load['value']:.6g} N ({load['origin']}); --fz sets "
                       "another."), highlight=False)
    if radius is not None and (radius["default"] or tyre is not None):
        con.print(Text(f"Loaded radius {radius['value']:.6g} mm ({radius['origin']}); the tyre "
                       "force acts at the ground contact point this far below the wheel "
                       "centre in the wheel plane."), highlight=False)
    if out is not None:
        con.print(Text("figures: " + ", ".join(str(p) for p in paths)), highlight=False)

