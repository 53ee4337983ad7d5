"""`diffsusp demo`: the main job on the embedded default model.

The thesis half axle (`pseudo_mcpherson`) under the 13 load cases of Table 5-1 (at the thesis's
contact-patch point, fixed on the hub carrier, as the thesis applies them) and a ±80 mm
parallel wheel travel (161 points), each solved in one batched, compiled call with every K&C
metric and its exact derivatives; prints a table and writes the K&C figures to a folder.
"""

import pathlib
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Annotated

import typer
from rich import box
from rich.table import Table
from rich.text import Text

from .common import EXIT_NOT_CONVERGED, check_output, cli_errors, console, enable_x64


def _timed(fn):
    import jax

    t0 = time.perf_counter()
    out = fn()
    jax.block_until_ready(out.solution.q)
    return out, time.perf_counter() - t0


def _import_matplotlib():
    """Load matplotlib's figure module (~1 s) while the main thread waits on the compiler."""
    import matplotlib.figure  # noqa: F401


def _status(code: int) -> str:
    """The table's status cell: "ok", or the statics' text of why the case stopped."""
    from diffsusp.statics import STATUS_TEXT, Status

    return "ok" if code == Status.CONVERGED else STATUS_TEXT.get(code, "failed").split(":")[0]


def register(app: typer.Typer) -> None:
    """Add `demo` to `app`."""
    app.command("demo")(demo_command)


def demo_command(
    out: Annotated[pathlib.Path, typer.Option(
        help="Folder for the figures (PNG and SVG); created if missing.")] = pathlib.Path(
        "diffsusp-demo"),
):
    """Thesis half axle: Table 5-1 load cases and ±80 mm travel; K&C table and figures."""
    check_output(out, what="figures folder", directory=True)
    threading.Thread(target=_import_matplotlib, daemon=True).start()
    enable_x64()
    import numpy as np

    from diffsusp import kc, plot
    from diffsusp.models import TABLE_5_1, pseudo_mcpherson

    term = console(markup=False)
    with cli_errors(), ThreadPoolExecutor(1) as drawing:
        with term.status("building the model and compiling the solver (first run: ~1 min)..."):
            mech = pseudo_mcpherson()
            travel_x = np.linspace(-80.0, 80.0, 161)
            cases, first_cases = _timed(
                lambda: kc.load_table(mech, TABLE_5_1, throw=False, contact="fixed"))
            # The load cases' figure is drawn while the travel compiles (or loads): that
            # thread mostly waits in XLA, without the interpreter lock.
            out.mkdir(parents=True, exist_ok=True)
            cases_figure = drawing.submit(lambda: plot.save(
                plot.kc_curves(cases, ["toe", "camber"],
                               title=f"{mech.name}: Table 5-1 load cases"), out / "table_5_1"))
            travel, first_travel = _timed(
                lambda: kc.parallel_travel(mech, travel=travel_x, throw=False))
            written_cases = cases_figure.result()  # done before the timed runs: they run alone
        _, t_cases = _timed(lambda: kc.load_table(mech, TABLE_5_1, throw=False, contact="fixed"))
        _, t_travel = _timed(lambda: kc.parallel_travel(mech, travel=travel_x, throw=False))

    # On the host from here: indexing a JAX array case by case would compile (or load) a
    # small program per shape and dtype.
    m = {k: np.asarray(v) for k, v in cases.metrics.items()}
    wc = np.stack([m[f"wheel_centre_{a}"] for a in "xyz"], axis=1)
    wc0 = np.asarray(mech.markers.position)[mech.markers.index("wheel_centre")]
    disp = wc - wc0
    iterations, status = np.asarray(cases.solution.iterations), np.asarray(cases.solution.status)
    table = Table(title=f"{mech.name}: thesis load cases (Table 5-1) at the contact patch",
                  box=box.SIMPLE_HEAD)
    for col in ("case", "Fz N", "Fy N", "Fx N", "Δx mm", "Δy mm", "Δz mm", "toe°", "camber°",
                "iter", "status"):
        table.add_column(col, justify="right", no_wrap=True)
    for c in range(len(TABLE_5_1)):
        fv, fl, fx = TABLE_5_1[c]
        table.add_row(
            str(c + 1), f"{fv:.0f}", f"{fl:.0f}", f"{fx:.0f}",
            *(f"{v:+.2f}" for v in disp[c]),
            *(f"{kc.display(k, m[k][c]):+.3f}" for k in ("toe", "camber")),
            str(int(iterations[c])), _status(int(status[c])),
        )
    term.print(table)
    term.print(
        "Fz, Fy, Fx: vertical, lateral, longitudinal force at the contact patch (Adams/Car "
        "frame: x rearward, y right, z up; left wheel, so Fy > 0 is inboard and Fx > 0 braking). "
        "Δ: wheel-centre displacement from design. toe: toe-in positive; camber: top outboard "
        "positive (Adams/Car, per side)."
    )

    t = travel.metrics
    i0 = int(np.argmin(np.abs(travel.x)))
    summary = Table(title="parallel wheel travel −80…+80 mm (161 points): at design",
                    box=box.SIMPLE_HEAD)
    for col in ("metric", "value", "unit", "range over the travel"):
        summary.add_column(col, justify="right" if col != "metric" else "left", no_wrap=True)
    for name in kc.flagged("summary"):
        v = np.asarray(kc.display(name, t[name]))
        summary.add_row(name, f"{v[i0]:+.4g}", kc.display_unit(name),
                        f"{np.nanmin(v):+.4g} … {np.nanmax(v):+.4g}")
    term.print(summary)

    written = plot.save(plot.kc_curves(travel, kc.default_plots(travel.name, t)[0],
                                       title=f"{mech.name}: parallel wheel travel"),
                        out / "parallel_travel") + written_cases
    term.print(f"figures: {', '.join(str(p) for p in written)}")
    term.print(
        f"compile + first run: {first_cases:.1f} s (load cases), {first_travel:.1f} s (travel); "
        f"after compile: 13 cases {t_cases * 1e3:.1f} ms, 161-point travel with all metrics and "
        f"derivatives {t_travel * 1e3:.1f} ms ({(13 + 161) / (t_cases + t_travel):.0f} "
        "equilibria/s)"
    )
    failed = int(np.sum(~cases.converged)) + int(np.sum(~travel.converged))
    if failed:
        term.print(Text(f"{failed} case(s) did not converge.", style="red"))
        raise typer.Exit(code=EXIT_NOT_CONVERGED)
