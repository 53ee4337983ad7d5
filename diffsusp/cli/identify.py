"""`diffsusp identify direct MODEL --measurements TABLE`: the direct (linear) stiffness
identification from measured equilibria (spec stiffness §1.8–1.14).

MODEL is anything `diffsusp.io.load_model` reads (a `.toml`, `.adm`, `.json` file or a built-in
name). TABLE is a landmark or pose table with the loads, CSV or Parquet (format in
`diffsusp.measure.table`). The report goes to the terminal (or `--json`), optionally to `--out`
(.csv: one row per unknown; .json: the whole report), and the identified model to
`--write-model` (.toml native file; .adm: the stiffnesses written into the Adams dataset the
model came from, or a complete dataset).
"""

import csv
import os
from pathlib import Path
from typing import Annotated

import typer
from rich import box
from rich.table import Table as RichTable

from .common import EXIT_BAD_INPUT, app, cli_errors, console, enable_x64, fail, print_json

identify_app = typer.Typer(add_completion=False, no_args_is_help=True,
                           help="Identify stiffnesses from measurements (spec stiffness ch. 4).")
app.add_typer(identify_app, name="identify")

_CHOICES = {
    "method": ("basic", "min_norm", "tsvd", "tikhonov", "nonneg"),
    "hold": ("zero", "model"),
    "weighting": ("noise", "none"),
}


def _check_choice(name: str, value: str):
    if value not in _CHOICES[name]:
        raise fail(f"--{name} must be one of {', '.join(_CHOICES[name])}; got '{value}'.",
                   EXIT_BAD_INPUT)


@identify_app.command("direct")
def direct(
    model: Annotated[str, typer.Argument(
        help="Model file (.toml, .adm, .json) or built-in name.")],
    measurements: Annotated[Path, typer.Option(
        "--measurements", "-m",
        help="Landmark or pose table with the loads of each case (.csv or .parquet).")],
    out: Annotated[Path | None, typer.Option(
        help="Write the report (.csv or .json).")] = None,
    write_model: Annotated[Path | None, typer.Option(
        help="Write the identified model (.toml, or .adm).")] = None,
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
    reorder: Annotated[bool, typer.Option(
        help="Match landmarks probed in any order by their distance tables.")] = False,
    max_sigma_pct: Annotated[float, typer.Option(
        help="Largest sigma% still called identified.")] = 10.0,
    threshold: Annotated[float | None, typer.Option(
        help="Relative identifiability threshold (default 1e-5).")] = None,
    json_output: Annotated[bool, typer.Option("--json", help="Machine-readable report.")] = False,
):
    """Identify bushing and spring stiffnesses by the direct (linear) method.

    Units: N/mm and N·mm/deg (as the thesis's tables), spring K·L0 in N.
    """
    for name, value in (("method", method), ("hold", hold), ("weighting", weighting)):
        _check_choice(name, value)
    for path, kinds in ((out, (".csv", ".json")), (write_model, (".toml", ".adm"))):
        if path is not None and path.suffix.lower() not in kinds:
            raise fail(f"{path}: use a {' or '.join(kinds)} file.", EXIT_BAD_INPUT)
    enable_x64()
    from .. import identify, measure
    from ..io import load_model_file

    with cli_errors():
        model_file = load_model_file(model)
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
            max_sigma_pct=max_sigma_pct)
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
    con = console()
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
