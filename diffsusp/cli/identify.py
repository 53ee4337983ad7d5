"""`diffsusp identify direct|iterative|fit MODEL --measurements TABLE`: stiffness (and
hardpoint) identification from measured equilibria.

- `direct`: the linear method (spec stiffness §1.8–1.14); every moving part measured.
- `iterative`: the thesis's correlation loop (spec stiffness §2); the parts of the identified
  bushings measured.
- `fit`: least squares through the equilibrium (spec stiffness §3, §6 item 8); any subset of
  the parts, with σ, identifiability and the combinations the data cannot see.

MODEL is anything `diffsusp.io.load_model` reads (a `.toml`, `.adm`, `.json` file or a built-in
name). TABLE is a landmark or pose table with the loads, CSV or Parquet (format in
`diffsusp.measure.table`). The report goes to the terminal (or `--json`), optionally to `--out`
(.csv: one row per unknown; .json: the whole report), the identified model to `--write-model`
(.toml native file; .adm: the stiffnesses written into the Adams dataset the model came from,
or a complete dataset), and for `iterative` and `fit` the figures to `--figures`.

**Size.** About 750 lines for three verbs (direct, iterative, fit) with their options, outputs
(terminal table, CSV/JSON reports, model files, figures) and interrupt handling; moving the
bushing selection and the report rows into the library (the reports' `rows()`) is the next step
of issue 11, not done yet (the CSV columns are a file format).
"""

import contextlib
import csv
import os
from pathlib import Path
from typing import Annotated

import typer
from rich import box
from rich.table import Table as RichTable

from .common import (
    EXIT_BAD_INPUT,
    EXIT_NOT_CONVERGED,
    SideOption,
    check_output,
    cli_errors,
    console,
    enable_x64,
    fail,
    print_json,
)

identify_app = typer.Typer(add_completion=False, no_args_is_help=True,
                           help="Identify stiffnesses from measurements (spec stiffness ch. 4).")

_CHOICES = {
    "method": ("basic", "min_norm", "tsvd", "tikhonov", "nonneg"),
    "hold": ("zero", "model"),
    "weighting": ("noise", "none"),
    "polish": ("auto", "on", "off"),
}


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


def _check_choice(name: str, value: str):
    if value not in _CHOICES[name]:
        raise fail(f"--{name} must be one of {', '.join(_CHOICES[name])}; got '{value}'.",
                   EXIT_BAD_INPUT)


def direct(
    model: ModelArg,
    measurements: MeasurementsOpt,
    side: SideOption = None,
    out: OutOpt = None,
    write_model: WriteModelOpt = None,
    method: Annotated[str, typer.Option(
        help="basic | min_norm | tsvd | tikhonov | nonneg.")] = "basic",
    hold: Annotated[str, typer.Option(
        help="Value of undetermined unknowns: zero | model.")] = "zero",
    eliminate: Annotated[bool, typer.Option(
        help="Hold unknowns whose sigma% exceeds --max-sigma-pct one by one (noisy data: "
        "with --hold model).")] = False,
    weighting: Annotated[str, typer.Option(
        help="noise (GLS from landmark noise) | none.")] = "noise",
    element: Annotated[list[str] | None, typer.Option(
        "--element", "-e", help="Identify only this bushing or spring (repeatable).")] = None,
    axisymmetric: Annotated[list[str] | None, typer.Option(
        help="Bushing with Ktx = Kty and Krx = Kry (repeatable).")] = None,
    offsets: Annotated[bool, typer.Option(
        help="Also identify the bushings' offsets.")] = False,
    reorder: ReorderOpt = False,
    max_sigma_pct: Annotated[float, typer.Option(
        help="Largest sigma% still called identified.")] = 10.0,
    threshold: Annotated[float | None, typer.Option(
        help="Relative identifiability threshold (default 1e-5).")] = None,
    polish: Annotated[str, typer.Option(
        help="Refine the determined stiffnesses by least squares through the equilibrium "
        "(errors in variables): auto (noisy data) | on | off (the thesis's linear "
        "estimate).")] = "auto",
    json_output: JsonOpt = False,
):
    """Identify bushing and spring stiffnesses by the direct (linear) method.

    Units: N/mm and N·mm/deg (as the thesis's tables), spring K·L0 in N.
    """
    for name, value in (("method", method), ("hold", hold), ("weighting", weighting),
                        ("polish", polish)):
        _check_choice(name, value)
    _check_paths(out, write_model)
    enable_x64()
    from .. import identify, measure
    from .common import load_model_file

    with cli_errors():
        model_file = load_model_file(model, side=side)
        mech = model_file.mechanism
        meas = measure.read_measurements(measurements, mech, reorder=reorder)
        where = None
        if offsets:
            def where(m):
                return (m.bushings.k_trans, m.bushings.k_rot, m.bushings.offset_trans,
                        m.bushings.offset_rot, m.springs.k, m.springs.free_length)
        fitted, report = identify.direct(
            mech, meas, where=where, elements=element or None,
            axisymmetric=tuple(axisymmetric or ()), method=method, hold=hold,
            eliminate=eliminate, weighting=weighting, threshold=threshold,
            max_sigma_pct=max_sigma_pct, polish={"on": True, "off": False}.get(polish, "auto"))
        if out is not None:
            _write_report(report, out)
        if write_model is not None:
            _write_model(fitted, write_model, model_file)
    if json_output:
        print_json(report.to_dict())
        return
    _print(report, mech, measurements, out, write_model)


def _write_report(report, path: Path):
    if path.suffix.lower() == ".json":
        import json

        path.write_text(json.dumps(report.to_dict(), indent=2) + "\n", encoding="utf-8")
        return
    rows = report.rows()
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        for row in rows:
            writer.writerow({k: "" if v is None else v for k, v in row.items()})


def _write_model(mech, path: Path, model_file):
    if path.suffix.lower() == ".toml":
        from ..io import save_model

        save_model(mech, path)
        return
    from ..io.adams import write_adm

    source = model_file.path
    template = source if source and os.path.splitext(str(source))[1].lower() == ".adm" else None
    write_adm(mech, path, template=template)


def _print(report, mech, measurements, out, write_model):
    con = console(markup=False)
    table = RichTable(
        title=f"{mech.name}: direct identification from {measurements.name} "
        f"({len(report.cases)} cases, {report.n_equations} equations, rank {report.rank})",
        box=box.SIMPLE_HEAD)
    for col, justify in (("parameter", "left"), ("value", "right"), ("sigma%", "right"),
                         ("unit", "left"), ("model", "right"), ("status", "left")):
        table.add_column(col, justify=justify, no_wrap=col != "status")
    for i, name in enumerate(report.names):
        shown = report.identified[i]
        pct = report.sigma_pct[i]
        table.add_row(name, f"{report.values[i]:.6g}" if shown else "—",
                      f"{pct:.3g}" if shown and pct == pct else "—", report.units[i],
                      f"{report.prior[i]:.6g}", report.status[i])
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
    for label, path in (("report", out), ("identified model", write_model)):
        if path is not None:
            con.print(f"{label} written to {path}", highlight=False)


# ----------------------------------------------------------------------------- shared


_DEG = 3.141592653589793 / 180.0
_ROTATIONAL = ("Krx", "Kry", "Krz")


def _check_paths(out, write_model, figures=None):
    """Every output checked before any work (suffix, folder exists and is writable)."""
    check_output(out, suffixes=(".csv", ".json"), what="report")
    check_output(write_model, suffixes=(".toml", ".adm"), what="identified model")
    check_output(figures, what="figures folder", directory=True)


def _measured_bushings(mech, meas, names):
    """The bushings to identify: as named, or every bushing whose parts are all measured."""
    from ..errors import InputError

    if names:
        for n in names:
            if n not in mech.bushings.names:
                raise InputError(f"model '{mech.name}' has no bushing '{n}'; its bushings: "
                                 f"{', '.join(mech.bushings.names) or 'none'}.")
        return tuple(names)
    out = []
    for b, name in enumerate(mech.bushings.names):
        parts = {mech.markers.part[mech.bushings.i_marker[b]],
                 mech.markers.part[mech.bushings.j_marker[b]]}
        if all(p < 0 or mech.parts[p] in meas.parts for p in parts):
            out.append(name)
    if not out:
        raise InputError("no bushing of the model connects measured parts only; measure the "
                         "parts of the bushings to identify, or name them with --bushing.")
    return tuple(out)


def _with_start(mech, names, start):
    """`mech` with every stiffness of the bushings `names` set to `start` (N/mm and N·mm/deg,
    the thesis's start: 10⁴ for both)."""
    import equinox as eqx
    import numpy as np

    if start is None:
        return mech
    if not start > 0:
        raise fail(f"--start must be a positive stiffness; got {start}.", EXIT_BAD_INPUT)
    kt, kr = np.array(mech.bushings.k_trans), np.array(mech.bushings.k_rot)
    for n in names:
        b = mech.bushings.index(n)
        kt[b], kr[b] = start, start / _DEG
    return eqx.tree_at(lambda m: (m.bushings.k_trans, m.bushings.k_rot), mech, (kt, kr))


def _case_channels(mech, q):
    """Per-case channels for the measured-vs-model figure: toe, camber (deg) and wheel-centre
    height (mm) of the model's wheel corner when it has one, else the displacement of each
    part's frame origin (mm). `q`: (cases, n) public coordinates."""
    import jax
    import numpy as np

    from .. import kc
    from ..errors import InputError
    from ..kc.metrics import corner_geometry
    from ..statics import part_poses

    try:
        rc = kc.default_corner(mech).resolve(mech)
    except (InputError, KeyError, ValueError):
        rc = None
    if rc is not None:
        geo = jax.vmap(lambda qq: corner_geometry(mech, rc, qq))(q)
        return ({"toe": np.degrees(np.asarray(geo["toe"])),
                 "camber": np.degrees(np.asarray(geo["camber"])),
                 "wheel_centre_z": np.asarray(geo["wheel_centre_z"])},
                [("toe", "toe (deg, in +)"), ("camber", "camber (deg)"),
                 ("wheel_centre_z", "wheel centre z (mm)")], mech.markers.part[rc.wheel_centre])
    _, trans = part_poses(mech, q)
    trans = np.asarray(trans)
    channels, values = [], {}
    for p, part in enumerate(mech.parts[:3]):
        values[part] = np.linalg.norm(trans[:, p], axis=-1)
        channels.append((part, f"{part} displacement (mm)"))
    return values, channels, None


def _comparison_figure(mech_start, mech_fitted, meas, title):
    """Measured vs start vs identified model per load case."""
    from .. import plot
    from ..statics import solve_statics

    series = {}
    values, channels, wheel_part = _case_channels(mech_fitted, meas.coordinates(
        mech_fitted, unmeasured="design"))
    measured_parts = set(meas.parts)
    if wheel_part is not None and mech_fitted.parts[wheel_part] in measured_parts:
        series["measured"] = values
    elif wheel_part is None:
        series["measured"] = {k: v for k, v in values.items() if k in measured_parts}
    for label, m in (("start model", mech_start), ("identified", mech_fitted)):
        sol = solve_statics(m, meas.loads, throw=False)
        series[label] = _case_channels(m, sol.q)[0]
    return plot.case_comparison(series, channels, title=title)


@contextlib.contextmanager
def _save_on_interrupt(out, rows, what):
    """On SIGINT / SIGTERM, write the last estimate (`rows()`: the report rows of the last
    accepted step, each with status 'interrupted') to `out` before exiting with 130."""
    from .common import EXIT_INTERRUPTED, _Terminated, interruptible

    try:
        with interruptible():
            yield
    except KeyboardInterrupt as e:
        how = "terminated (SIGTERM)" if isinstance(e, _Terminated) else "interrupted"
        data = rows()
        where = ""
        if out is not None and data:
            if out.suffix.lower() == ".json":
                import json

                out.write_text(json.dumps({"interrupted": True, "rows": data}, indent=2) + "\n",
                               encoding="utf-8")
            else:
                _write_rows(data, out)
            where = f"; the estimate of the last {what} is in {out} (status 'interrupted')"
        elif not data:
            where = f"; no {what} had finished"
        raise fail(f"{how}{where}.", EXIT_INTERRUPTED) from None


def _partial_fit_rows(params, last):
    if not last:
        return []
    rows = []
    for k, name in enumerate(params.names):
        value, unit = _display(name, float(last[0].estimate[k]))
        rows.append(dict(parameter=name, value=value, unit=unit,
                         start=float(_display(name, float(params.start[k]))[0]),
                         step=last[0].step, status="interrupted"))
    return rows


def _partial_iterative_rows(mech0, names, last):
    from ..identify.iterative import AXES

    if not last:
        return []
    rows = []
    for b, name in enumerate(names):
        index = mech0.bushings.index(name)
        for a, axis in enumerate(AXES):
            scale = _DEG if axis in _ROTATIONAL else 1.0
            start = (mech0.bushings.k_trans if a < 3 else mech0.bushings.k_rot)[index][a % 3]
            rows.append(dict(parameter=f"{name}.{axis}",
                             value=float(last[0].stiffness[b, a] * scale),
                             unit="N*mm/deg" if axis in _ROTATIONAL else "N/mm",
                             start=float(start) * scale, status="interrupted"))
    return rows


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

    _check_paths(out, write_model, figures)
    res = None
    if resolution.strip().lower() != "none":
        try:
            mm, deg = (float(v) for v in resolution.split(","))
        except ValueError:
            raise fail(f"--resolution must be 'mm,deg' or 'none'; got '{resolution}'.",
                       EXIT_BAD_INPUT) from None
        res = (mm, deg * _DEG)
    enable_x64()
    from .. import measure
    from ..identify.iterative import iterative
    from .common import load_model_file

    with cli_errors():
        model_file = load_model_file(model, side=side)
        mech = model_file.mechanism
        meas = measure.read_measurements(measurements, mech, reorder=reorder)
        names = _measured_bushings(mech, meas, bushing)
        d_t, d_r = measure.bushing_deformations(mech, meas, names)
        measured = np.concatenate([np.asarray(d_t), np.asarray(d_r)], axis=-1)
        mech0 = _with_start(mech, names, start)
        last = []
        with _progress() as progress, _save_on_interrupt(out, lambda: _partial_iterative_rows(
                mech0, names, last), "iteration"):
            task = progress.add_task("iteration", total=max_iterations)

            def step(i, record):
                last[:] = [record]
                progress.update(task, completed=i,
                                description=f"iteration {i}: largest change "
                                f"{100 * record.max_change:.3g}%")

            fitted, report = iterative(
                mech0, meas.loads, measured, bushings=names,
                axisymmetric=tuple(axisymmetric or ()), r_min=r_min, resolution=res, eps=eps,
                max_iterations=max_iterations, callback=step)
        if out is not None:
            _write_iterative(report, out)
        if write_model is not None:
            _write_model(fitted, write_model, model_file)
        paths = []
        if figures is not None:
            paths = _iterative_figures(report, mech0, fitted, meas, figures)
    if json_output:
        print_json(report.to_dict())
    else:
        con = console(markup=False)
        con.print(f"{mech.name}: iterative identification from {measurements.name} "
                  f"({meas.n_cases} cases)", highlight=False)
        con.print(report.table(), highlight=False)
        for label, path in (("report", out), ("identified model", write_model)):
            if path is not None:
                con.print(f"{label} written to {path}", highlight=False)
        if paths:
            con.print("figures: " + ", ".join(str(p) for p in paths), highlight=False)
    if not report.converged:
        raise fail(f"the iterative identification did not converge in {report.iterations} "
                   "iterations; the stiffnesses written are the last iteration's. Try more "
                   "--max-iterations or a larger --eps.", EXIT_NOT_CONVERGED)


def _iterative_rows(report):
    from ..identify.iterative import AXES

    rows = []
    for b, name in enumerate(report.bushings):
        for a, axis in enumerate(AXES):
            scale = _DEG if axis in _ROTATIONAL else 1.0
            rows.append(dict(
                parameter=f"{name}.{axis}", value=float(report.stiffness[b, a] * scale),
                unit="N*mm/deg" if axis in _ROTATIONAL else "N/mm",
                start=float(report.start[b, a] * scale),
                identified=bool(report.identified[b, a]),
                equalised=bool(report.equalised[b, a]), r=float(report.r[b, a])))
    return rows


def _write_iterative(report, path: Path):
    import json

    if path.suffix.lower() == ".json":
        path.write_text(json.dumps(report.to_dict(), indent=2) + "\n", encoding="utf-8")
        return
    _write_rows(_iterative_rows(report), path)


def _write_rows(rows, path: Path):
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def _iterative_figures(report, mech0, fitted, meas, folder: Path):
    import numpy as np

    from .. import plot
    from ..identify.iterative import AXES

    k = np.stack([r.stiffness for r in report.history])  # (iterations, n, 6)
    histories = {}
    for b, name in enumerate(report.bushings):
        for a, axis in enumerate(AXES):
            if report.identified[b, a]:
                histories[f"{name}.{axis}"] = np.abs(k[:, b, a] / report.stiffness[b, a] - 1.0
                                                     ) + 1e-16
    fig = plot.convergence(histories, ylabel="|K / K_final − 1|",
                           title=f"{fitted.name}: iterative identification")
    paths = plot.save(fig, folder / "iterative_convergence")
    fig = _comparison_figure(mech0, fitted, meas, f"{fitted.name}: measured vs identified")
    return paths + plot.save(fig, folder / "iterative_cases")


# ----------------------------------------------------------------------------- fit


def _fit_params(mech, bushings, axes, centres, springs, start, notes):
    """The selection of `identify fit`. Without --start, a stiffness that is 0 in the model
    (a free direction of a bushing: no log-scaled start exists) is left out, with a note."""
    import numpy as np

    from ..errors import InputError
    from ..identify.params import AXES, Params

    axes = tuple(a.strip() for a in axes.split(",")) if axes else AXES
    names = tuple(bushings or mech.bushings.names)
    params = None
    if names and axes and start is None:
        for name in names:
            if name not in mech.bushings.names:
                break  # Params names the unknown bushing
        else:
            k = np.concatenate([np.asarray(mech.bushings.k_trans),
                                np.asarray(mech.bushings.k_rot)], axis=1)
            zero = [f"{n}.{a}" for n in names for a in axes
                    if a in AXES and not k[mech.bushings.index(n), AXES.index(a)] > 0]
            if zero:
                notes.append(
                    f"left out {len(zero)} stiffness(es) that are 0 in the model (free "
                    f"directions; a zero cannot be fitted on a log scale): {', '.join(zero)}. "
                    "Give --start to fit every selected stiffness from one positive value.")
            pairs = [(n, a) for n in names for a in axes if f"{n}.{a}" not in zero]
            for n in dict.fromkeys(n for n, _ in pairs):
                axes_n = tuple(a for m, a in pairs if m == n)
                p = Params.bushing_stiffness(mech, (n,), axes=axes_n)
                params = p if params is None else params + p
    elif names and axes:
        # Every value is replaced by --start: select from a copy without zero stiffnesses.
        params = Params.bushing_stiffness(_without_zeros(mech), names, axes=axes)
    if centres:
        c = Params.bushing_centres(mech, names)
        params = c if params is None else params + c
    if springs and mech.springs.names:
        rate = np.asarray(mech.springs.k) > 0
        if start is None and not rate.all():
            notes.append("left out the spring rate(s) that are 0 in the model: " + ", ".join(
                n for n, ok in zip(mech.springs.names, rate, strict=True) if not ok) + ".")
        if rate.any() or start is not None:
            s = Params.leaves(_without_zeros(mech), lambda m: m.springs.k,
                              None if start is not None else rate)
            params = s if params is None else params + s
    if params is None:
        raise InputError("nothing to identify: the model has no bushings (or --axes is empty, "
                         "or every selected stiffness is 0: give --start) and neither "
                         "--centres nor --springs was asked.")
    if start is not None:
        values = np.array(params.start, dtype=float)
        for k, name in enumerate(params.names):
            axis = name.rsplit(".", 1)[-1]
            if axis in AXES:
                values[k] = start / _DEG if axis in _ROTATIONAL else start
        params = params.with_start(values)
    return params


def _without_zeros(mech):
    """`mech` with every non-positive stiffness and spring rate set to 1 (a placeholder for a
    selection whose start values are all given)."""
    import equinox as eqx
    import numpy as np

    def positive(a):
        a = np.asarray(a, dtype=float)
        return np.where(a > 0, a, 1.0)

    return eqx.tree_at(lambda m: (m.bushings.k_trans, m.bushings.k_rot, m.springs.k), mech,
                       tuple(positive(a) for a in (mech.bushings.k_trans, mech.bushings.k_rot,
                                                  mech.springs.k)))


def _display(name, value):
    """Value in the thesis's units: rotational stiffness per degree."""
    axis = name.rsplit(".", 1)[-1]
    if axis in _ROTATIONAL:
        return value * _DEG, "N*mm/deg"
    if axis in ("Ktx", "Kty", "Ktz") or name.endswith(".k"):
        return value, "N/mm"
    return value, "mm"


def _fit_rows(report):
    rows = []
    for k, name in enumerate(report.names):
        value, unit = _display(name, report.estimate[k])
        scale = value / report.estimate[k] if report.estimate[k] else 1.0
        rows.append(dict(parameter=name, value=float(value), sigma=float(report.sigma[k] * scale),
                         sigma_pct=float(report.sigma_percent[k]), unit=unit,
                         start=float(_display(name, report.start[k])[0]),
                         identifiable=bool(report.identifiable[k])))
    return rows


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
    loss: Annotated[str, typer.Option(help="linear | huber | cauchy.")] = "linear",
    max_steps: Annotated[int, typer.Option(help="Levenberg–Marquardt steps.")] = 200,
    reorder: ReorderOpt = False,
    out: OutOpt = None,
    write_model: WriteModelOpt = None,
    figures: FiguresOpt = None,
    json_output: JsonOpt = False,
):
    """Identify stiffnesses (and hardpoints) by least squares through the equilibrium: the
    model's landmarks or poses are fitted to the measured ones (Levenberg–Marquardt, exact
    derivatives), with σ, σ% and the combinations the data cannot see.
    """
    from ..identify.least_squares import LOSSES

    _check_paths(out, write_model, figures)
    if loss not in LOSSES:
        raise fail(f"--loss must be one of {', '.join(LOSSES)}; got '{loss}'.", EXIT_BAD_INPUT)
    if not (sigma > 0 and sigma_rotation > 0):
        raise fail("--sigma and --sigma-rotation must be positive.", EXIT_BAD_INPUT)
    enable_x64()
    from .. import measure
    from ..identify.least_squares import least_squares
    from ..measure.data import from_measurements
    from .common import load_model_file

    with cli_errors():
        model_file = load_model_file(model, side=side)
        mech = model_file.mechanism
        meas = measure.read_measurements(measurements, mech, reorder=reorder)
        data = from_measurements(meas, sigma, sigma_rotation * _DEG)
        notes: list[str] = []
        params = _fit_params(mech, bushing, axes, centres, springs, start, notes)
        last = []
        with _progress() as progress, _save_on_interrupt(out, lambda: _partial_fit_rows(
                params, last), "LM step"):
            task = progress.add_task("step", total=max_steps)

            def step(i, record):
                if record.accepted or not last:
                    last[:] = [record]
                progress.update(task, completed=i, description=f"step {i}: loss "
                                f"{record.trial_loss:.4g}")

            fitted, report = least_squares(mech, data, params, loss=loss, max_steps=max_steps,
                                           callback=step)
        if out is not None:
            if out.suffix.lower() == ".json":
                import json

                out.write_text(json.dumps(report.to_dict(), indent=2) + "\n", encoding="utf-8")
            else:
                _write_rows(_fit_rows(report), out)
        if write_model is not None:
            _write_model(fitted, write_model, model_file)
        paths = []
        if figures is not None:
            paths = _fit_figures(report, params.apply(mech, params.start), fitted, meas,
                                 figures)
    if json_output:
        print_json(dict(report.to_dict(), notes=notes))
    else:
        _print_fit(report, mech, measurements, meas, out, write_model, paths, notes)
    if not report.converged:
        raise fail(f"the fit did not converge ({report.message}) after {report.steps} steps; "
                   "the estimates written are the last accepted ones. Try more --max-steps, "
                   "other --start values, or fewer parameters.", EXIT_NOT_CONVERGED)


def _fit_figures(report, mech0, fitted, meas, folder: Path):
    from .. import plot

    losses = {"loss ½Σr² at the estimate": [max(r.trial_loss, 1e-300) if r.accepted else
                                            float("nan") for r in report.history]}
    fig = plot.convergence(losses, ylabel="loss", xlabel="LM step",
                           title=f"{fitted.name}: least-squares fit")
    paths = plot.save(fig, folder / "fit_convergence")
    fig = _comparison_figure(mech0, fitted, meas, f"{fitted.name}: measured vs identified")
    return paths + plot.save(fig, folder / "fit_cases")


def _print_fit(report, mech, measurements, meas, out, write_model, paths, notes=()):
    con = console(markup=False)
    table = RichTable(
        title=f"{mech.name}: least-squares fit to {measurements.name} ({meas.n_cases} cases, "
        f"{report.n_residuals} residuals, loss {report.loss_name})", box=box.SIMPLE_HEAD)
    for col in ("parameter", "start", "estimate", "sigma", "sigma%", "unit", "status"):
        table.add_column(col, justify="left" if col in ("parameter", "unit", "status")
                         else "right", no_wrap=col != "status")
    for row in _fit_rows(report):
        pct = row["sigma_pct"]
        table.add_row(row["parameter"], f"{row['start']:.6g}", f"{row['value']:.6g}",
                      f"{row['sigma']:.3g}", f"{pct:.3g}" if pct == pct else "—", row["unit"],
                      "identified" if row["identifiable"] else "not identifiable")
    con.print(table)
    if report.null_space:
        con.print("combinations the data cannot see (internal coordinates: log K, mm):")
        for d in report.null_space:
            con.print(f"  {d.text}  (σ {d.sigma:.3g})", highlight=False)
    state = "converged" if report.converged else "NOT converged"
    con.print(f"{state} in {report.steps} steps ({report.accepted_steps} accepted); chi2/dof "
              f"{report.chi2 / max(report.dof, 1):.3g}.", highlight=False)
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
