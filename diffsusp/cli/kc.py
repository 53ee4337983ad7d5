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

import pathlib
import time
import warnings
from typing import Annotated

import typer
from rich import box
from rich.table import Table
from rich.text import Text

from .common import (
    EXIT_BAD_INPUT,
    app,
    check_output,
    cli_errors,
    console,
    enable_x64,
    fail,
    print_json,
    show_warnings,
    warn,
)

EVENTS = {
    "parallel-travel": "wheel travel (mm), --travel",
    "opposite-travel": "wheel travel (mm), --travel; axle = model + its mirror image",
    "vertical-force": "vertical force (N), --fz",
    "lateral-force": "lateral force (N, inboard +), --force, at --fz",
    "braking": "braking force (N) at the contact patch, --force, at --fz",
    "traction": "traction force (N) at the wheel centre, --force, at --fz",
    "aligning-torque": "aligning torque (N·m, toe-out +), --torque, at --fz",
    "steering": "rack travel (mm, left +), --rack",
    "table-5-1": "the 13 cases of the thesis's Table 5-1",
    "table-4-4": "the 17 cases of the thesis's Table 4.4",
}

_FIGURE_METRICS = {
    "parallel-travel": ("toe", "camber", "half_track_change"),
    "opposite-travel": ("toe", "camber", "half_track_change"),
    "vertical-force": ("wheel_travel", "toe", "camber"),
    "steering": ("steer", "camber", "mechanical_trail"),
}


def parse_range(text: str, what: str):
    """`start:stop:count` → numpy.linspace(start, stop, count); a single number → [number]."""
    import numpy as np

    from diffsusp.errors import InputError

    parts = text.split(":")
    try:
        if len(parts) == 1:
            return np.array([float(parts[0])])
        if len(parts) == 3:
            start, stop, count = float(parts[0]), float(parts[1]), int(parts[2])
            if count < 1:
                raise ValueError
            return np.linspace(start, stop, count)
    except ValueError:
        pass
    raise InputError(f"--{what} '{text}' is not a range: give start:stop:count (e.g. "
                     "-80:80:161) or one number.")


def _model(name: str):
    """A built-in model (`diffsusp.models.ZOO` or `STOP_VARIANTS`) or a model file
    (`diffsusp.io.load_model`)."""
    from diffsusp.errors import InputError
    from diffsusp.models import STOP_VARIANTS, ZOO

    if name in ZOO:
        return ZOO[name]()
    if name in STOP_VARIANTS and not pathlib.Path(name).exists():
        return STOP_VARIANTS[name]()
    path = pathlib.Path(name)
    if not path.exists():
        raise InputError(
            f"model '{name}' is neither a built-in model ({', '.join([*ZOO, *STOP_VARIANTS])}) "
            "nor an existing file. Give a built-in name or the path of a model file (.toml, "
            ".adm, .json)."
        )
    from diffsusp.io import load_model

    return load_model(path)


def _corner(mech, frame, loaded_radius, kingpin, side):
    from diffsusp import kc
    from diffsusp.errors import InputError

    if frame is None and loaded_radius is None and kingpin is None and side is None:
        return None  # the model's registered corner
    try:
        base = kc.default_corner(mech)
    except InputError:
        base = kc.Corner()
    changes = {}
    if frame is not None:
        changes["frame"] = frame
    if loaded_radius is not None:
        changes["loaded_radius"] = loaded_radius
    if side is not None:
        changes["side"] = side
    if kingpin is not None:
        names = kingpin.split(",")
        if len(names) != 2:
            raise InputError("--kingpin must be two marker names 'upper,lower'.")
        changes["kingpin"] = tuple(n.strip() for n in names)
    import dataclasses

    return dataclasses.replace(base, **changes)


def _run_event(mech, event, corner, travel, fz, force, torque, rack):
    from diffsusp import kc
    from diffsusp.errors import InputError
    from diffsusp.model.combine import combine
    from diffsusp.model.mirror import mirror

    fz_value = None
    if fz is not None and event != "vertical-force":
        values = parse_range(fz, "fz")
        if values.size != 1:
            raise InputError(f"--fz must be one value (N) for the {event} event.")
        fz_value = float(values[0])
    if event == "parallel-travel":
        return kc.parallel_travel(mech, parse_range(travel, "travel"), corner=corner)
    if event == "opposite-travel":
        from diffsusp.model.combine import component_names

        axle = mech if component_names(mech) else combine({"left": mech, "right": mirror(mech)})
        corners = None if corner is None else {"left": corner,
                                               "right": _mirrored_corner(corner)}
        return kc.opposite_travel(axle, parse_range(travel, "travel"), corner=corners)
    if event == "vertical-force":
        if fz is None:
            fz = _default_fz_range(mech, corner)
        return kc.vertical_force(mech, parse_range(fz, "fz"), corner=corner)
    if event == "lateral-force":
        return kc.lateral_force(mech, parse_range(force, "force"), fz=fz_value, corner=corner)
    if event == "braking":
        return kc.braking(mech, parse_range(force, "force"), fz=fz_value, corner=corner)
    if event == "traction":
        return kc.traction(mech, parse_range(force, "force"), fz=fz_value, corner=corner)
    if event == "aligning-torque":
        return kc.aligning_torque(mech, 1e3 * parse_range(torque, "torque"), fz=fz_value,
                                  corner=corner)
    if event == "steering":
        frame = (corner or kc.corners_of(mech)[""]).frame
        return kc.steering(kc.with_rack(mech, frame=frame), parse_range(rack, "rack"),
                           corner=corner)
    table = kc.TABLES["table_5_1" if event == "table-5-1" else "table_4_4"]
    return kc.load_table(mech, table, corner=corner)


def _mirrored_corner(corner):
    import dataclasses

    side = {"left": "right", "right": "left"}.get(corner.side, corner.side)
    return dataclasses.replace(corner, side=side)


def _default_fz_range(mech, corner) -> str:
    from diffsusp import kc

    fz0 = (corner or kc.corners_of(mech)[""]).design_load
    return f"{0.5 * fz0}:{1.5 * fz0}:21"


def _reference_case(ev) -> int:
    import numpy as np

    if ev.x_name == "vertical_force":
        target = ev.rig.corners[0].design_load
    elif ev.x_name == "case":
        return 0
    else:
        target = 0.0
    return int(np.argmin(np.abs(np.asarray(ev.x) - target)))


def _json(ev, mech_name: str) -> dict:
    import numpy as np

    from diffsusp import kc

    def clean(a):
        a = np.asarray(a, dtype=float)
        return np.where(np.isfinite(a), a, np.nan).tolist()

    x_scale = 1e-3 if ev.x_unit == "N·mm" else 1.0
    out = {
        "model": mech_name,
        "event": ev.name,
        "x": {"name": ev.x_name, "unit": "N·m" if ev.x_unit == "N·mm" else ev.x_unit,
              "values": clean(np.asarray(ev.x) * x_scale)},
        "held": ev.held,
        "status": np.asarray(ev.solution.status).tolist(),
        "iterations": np.asarray(ev.solution.iterations).tolist(),
        "stable": _flag_list(ev.solution.stable),
        "law_valid": _flag_list(ev.solution.law_valid),
        "metrics": {name: {"unit": kc.display_unit(name), "values": clean(kc.display(name, v))}
                    for name, v in sorted(ev.metrics.items())},
    }
    if ev.compliance:
        out["compliance_matrix"] = {
            "unit": "mm/N, mm/(N·mm), rad/N, rad/(N·mm); rows and columns x, y, z, rx, ry, rz "
                    "(global) at the wheel centre",
            "values": {prefix or "corner": clean(c) for prefix, c in ev.compliance.items()},
        }
    # NaN is not JSON: non-converged cases are null.
    return _nan_to_none(out)


def _flag_list(flag):
    """Per-case flag as a list of booleans (None when the solution carries no flags)."""
    import numpy as np

    return None if flag is None else np.asarray(flag, dtype=bool).tolist()


def _flag_notes(ev) -> list[str]:
    """One warning per flag that some converged case fails (stable, law_valid)."""
    import numpy as np

    sol = ev.solution
    notes = []
    for flag, what in (("stable", "an unstable equilibrium (the reduced tangent stiffness is "
                        "not positive definite)"),
                       ("law_valid", "a bushing beyond its law's validity (|AX|, |AY| < 15°, "
                        "|AZ| < 90°)")):
        value = getattr(sol, flag)
        if value is None:
            continue
        cases = np.flatnonzero((np.asarray(sol.status) == 0) & ~np.asarray(value, dtype=bool))
        if cases.size:
            shown = ", ".join(map(str, cases[:10])) + (
                f" and {cases.size - 10} more" if cases.size > 10 else "")
            notes.append(f"{cases.size} converged case{'s' * (cases.size != 1)} of the event "
                         f"with {what}: {shown} ('{flag}' is false in --json).")
    return notes


def _nan_to_none(obj):
    import math

    if isinstance(obj, dict):
        return {k: _nan_to_none(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_nan_to_none(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def _table(ev, mech_name: str) -> Table:
    import numpy as np

    from diffsusp import kc

    ref = _reference_case(ev)
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


@app.command("kc")
def kc_command(
    model: Annotated[str, typer.Argument(help="built-in model name or model file path")],
    event: Annotated[str, typer.Option("--event", "-e", help="K&C event: "
                                       + ", ".join(EVENTS))] = "parallel-travel",
    travel: Annotated[str, typer.Option(help="wheel travel range (mm) start:stop:count")]
    = "-80:80:161",
    fz: Annotated[str | None, typer.Option(
        help="vertical load (N): one value for the force events (default: the design load), "
        "a range for vertical-force (default 0.5–1.5× the design load, 21 cases)")] = None,
    force: Annotated[str, typer.Option(help="lateral / braking / traction force range (N)")]
    = "-4000:4000:17",
    torque: Annotated[str, typer.Option(help="aligning torque range (N·m)")] = "-200:200:17",
    rack: Annotated[str, typer.Option(help="rack travel range (mm)")] = "-30:30:61",
    frame: Annotated[str | None, typer.Option(
        help="model frame: adams or iso (default: the model's registered corner)")] = None,
    side: Annotated[str | None, typer.Option(help="left, right or auto")] = None,
    loaded_radius: Annotated[float | None, typer.Option(help="loaded tyre radius (mm)")] = None,
    kingpin: Annotated[str | None, typer.Option(
        help="steering axis markers 'upper,lower'")] = None,
    out: Annotated[pathlib.Path | None, typer.Option(
        help="write figures (PNG and SVG) to this folder")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="machine-readable output on stdout")]
    = False,
):
    """Run a K&C event on MODEL and print its metrics (Adams/Car conventions, per side)."""
    enable_x64()
    if event not in EVENTS:
        raise fail(f"unknown event '{event}'; known events: {', '.join(EVENTS)}.",
                   EXIT_BAD_INPUT)
    check_output(out, what="figures folder", directory=True)
    err = console(stderr=True, markup=False)
    with cli_errors(), warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mech = _model(model)
        corner = _corner(mech, frame, loaded_radius, kingpin, side)
        t0 = time.perf_counter()
        with err.status(f"running {event} on {mech.name} (the first run compiles, ~30 s)..."):
            ev = _run_event(mech, event, corner, travel, fz, force, torque, rack)
        elapsed = time.perf_counter() - t0
        if out is not None:
            from diffsusp import plot

            names = _FIGURE_METRICS.get(event, ("steer", "camber", "wheel_travel"))
            fig = plot.kc_curves(ev, names, title=f"{mech.name}: {ev.name.replace('_', ' ')}")
            paths = plot.save(fig, out / f"kc_{ev.name}")
            fig = plot.kc_curves(ev, _derivative_names(ev), title=f"{mech.name}: derivatives")
            paths += plot.save(fig, out / f"kc_{ev.name}_derivatives")
    show_warnings(caught)
    for note in _flag_notes(ev):
        warn(note)
    if as_json:
        print_json(_json(ev, mech.name))
        return
    con = console(markup=False)
    con.print(_table(ev, mech.name))
    con.print(Text(f"Held fixed by the derivative metrics: {ev.held}. Signs: toe-in, camber top "
              "outboard, lateral force inboard, longitudinal force rearward (braking) positive "
              f"(Adams/Car, per side). {elapsed:.2f} s."), highlight=False)
    if out is not None:
        con.print(Text("figures: " + ", ".join(str(p) for p in paths)), highlight=False)


def _derivative_names(ev) -> tuple[str, ...]:
    keys = {k.rsplit("/", 1)[-1] for k in ev.metrics}
    if "bump_steer" in keys:
        return ("bump_steer", "bump_camber", "wheel_rate")
    return ("steer_gain", "lateral_compliance_steer", "aligning_torque_compliance_steer")
