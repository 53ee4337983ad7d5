"""`diffsusp identify geometry|correct MODEL --measurements TABLE`: joint locations from the
measured motion of the parts (spec geometry §4, chapter 3) and the equilibrium-consistent
geometric correction (spec geometry §3.8, chapter 2).

- `geometry`: the joint list comes from the model (`diffsusp.identify.geometric.
  joints_from_model`: ball joints and bushings between measured parts as ball joints, bushings
  named with `--compliant` by the compliant-link method, revolute joints, the tie rod on an
  unmeasured rack, the strut top on an unmeasured strut) or from `--joints FILE.json` (a list
  of `GeometricJoint` fields). The report (one row per located coordinate with value, σ and
  one status: identified / not determined (why) / not seen; the registration's verdict,
  warnings for swapped or moved landmarks; the model's compliance bias carried in σ unless
  `--no-compliance`) goes to the terminal (or `--json`), optionally to `--out` (.csv, .json,
  .html, .txt: `IdentificationReport.write`, the same rows), the former one-row-per-joint
  table to `--joint-table`, the model with the identified joints to `--write-model`, and a
  figure of the located joints against the model to `--figures`.
- `correct`: the model's joint frames moved so that its equilibrium under the loads of case
  `--case` reproduces the measured poses (iterated to `--tol` mm); the same report, one row
  per moved marker coordinate, to the terminal and `--out`.

TABLE is a landmark or pose table (format in `diffsusp.io.measurements`). Units: mm.
"""

import textwrap
from pathlib import Path
from typing import Annotated

import typer

from .common import (
    EXIT_BAD_INPUT,
    JsonOption,
    MeasurementsOption,
    ModelArgument,
    ReorderOption,
    check_identify_outputs,
    check_number,
    check_output,
    cli_errors,
    console,
    enable_x64,
    fail,
    load_model_file,
    print_json,
    write_model_file,
)


def register(identify_app: typer.Typer) -> None:
    """Add `geometry` and `correct` to the `identify` group (`cli.identify.identify_app`)."""
    identify_app.command("geometry")(geometry_command)
    identify_app.command("correct")(correct_command)


def geometry_command(
    model: ModelArgument,
    measurements: MeasurementsOption,
    joints: Annotated[Path | None, typer.Option(
        help="Joint list (.json); default: derived from the model.")] = None,
    compliant: Annotated[list[str] | None, typer.Option(
        "--compliant", "-c",
        help="Bushing located by the compliant-link method (repeatable).")] = None,
    landmark_sigma: Annotated[float, typer.Option(
        help="Landmark noise per coordinate (mm) for the reported sigma.")] = 0.05,
    max_sigma: Annotated[float, typer.Option(
        help="Hardpoint tolerance (mm): a joint whose centre sigma (inflated by its lack of "
             "fit) exceeds it is not observable.")] = 10.0,
    min_snr: Annotated[float, typer.Option(
        help="A joint whose weakest singular value is below this many times its noise level "
             "is not observable.")] = 3.0,
    compliance: Annotated[bool, typer.Option(
        help="Carry the model's compliance bias in sigma (its own equilibria at the measured "
             "loads, located the same way).")] = True,
    out: Annotated[Path | None, typer.Option(
        help="Write the report: .csv, .json, .html or .txt (one row per located coordinate, "
             "with its status).")] = None,
    joint_table: Annotated[Path | None, typer.Option(
        help="Write the joint table, one row per joint (.csv or .json).")] = None,
    write_model: Annotated[Path | None, typer.Option(
        help="Write the model with the identified joints (.toml or .adm).")] = None,
    figures: Annotated[Path | None, typer.Option(
        help="Write the located joints against the model (PNG) in this directory.")] = None,
    reorder: ReorderOption = False,
    json_output: JsonOption = False,
):
    """Locate the joints from the relative motion of the measured parts (mm)."""
    check_output(out, suffixes=(".csv", ".json", ".html", ".txt"), what="report")
    check_output(joint_table, suffixes=(".csv", ".json"), what="joint table")
    check_output(write_model, suffixes=(".toml", ".adm"), what="identified model")
    check_output(figures, what="figures folder", directory=True)
    for value, option, unit in ((landmark_sigma, "--landmark-sigma", "mm"),
                                (max_sigma, "--max-sigma", "mm"), (min_snr, "--min-snr", "")):
        check_number(value, option, positive=True, unit=unit)  # nan, inf, <= 0: exit 2
    enable_x64()
    from ..identify import geometric
    from ..identify.report import format_table
    from ..measure import read_measurements

    with cli_errors():
        model_file = load_model_file(model)
        mech = model_file.mechanism
        meas = read_measurements(measurements, mech, reorder=reorder)
        notes = ()
        if joints is not None:
            joint_list = geometric.read_joints(joints)
        else:
            joint_list, notes = geometric.joints_from_model(mech, meas.parts,
                                                            compliant=tuple(compliant or ()))
        if not joint_list:
            raise fail("no joint to locate: measure the parts on both sides of a joint, or "
                       "give --joints.", EXIT_BAD_INPUT)
        report = geometric.locate_joints(meas, joint_list, landmark_sigma=landmark_sigma,
                                         max_sigma=max_sigma, min_snr=min_snr,
                                         model=mech if compliance else None)
        if out is not None:
            report.write(out)
        if joint_table is not None:
            geometric.write_joints(report, joint_table)
        if write_model is not None:
            located, _ = geometric.apply_locations(mech, report, joint_list)
            write_model_file(located, write_model, model_file)
        if figures is not None:
            from .. import plot

            fig = report.plot(mech, joint_list)
            plot.save(fig, figures / "geometry_joints", formats=("png",))
    if json_output:
        print_json(report.summary() | {"notes_model": list(notes)})
        return
    con = console(markup=False)
    con.print(f"{mech.name}: joints located from {measurements.name} ({report.n_cases} cases, "
              f"σ at landmark noise {landmark_sigma:g} mm)", highlight=False, soft_wrap=True)
    con.print(format_table(report, 120), highlight=False, soft_wrap=True)
    for note in (*report.notes, *notes):
        con.print(textwrap.fill(f"note: {note}", 120, subsequent_indent="  "),
                  highlight=False, soft_wrap=True)
    for label, path in (("report", out), ("joint table", joint_table), ("model", write_model),
                        ("figure", figures)):
        if path is not None:
            con.print(f"{label} written to {path}", highlight=False, soft_wrap=True)


def correct_command(
    model: ModelArgument,
    measurements: MeasurementsOption,
    case: Annotated[str, typer.Option(
        help="The measured case to reproduce (its label in the table).")],
    element: Annotated[list[str] | None, typer.Option(
        "--element", "-e", help="Correct only this joint or bushing (repeatable).")] = None,
    tol: Annotated[float | None, typer.Option(
        help="Pose tolerance (mm); default: 1e-4 mm, or the noise floor (a pass no longer "
             "lowers the pose error by 0.1 sigma and a factor 2).")] = None,
    max_iterations: Annotated[int, typer.Option(help="Re-solve/re-correct passes.")] = 20,
    write_model: Annotated[Path | None, typer.Option(
        help="Write the corrected model (.toml or .adm).")] = None,
    out: Annotated[Path | None, typer.Option(
        help="Write the report: .csv, .json, .html or .txt (one row per moved marker "
             "coordinate, with its status).")] = None,
    reorder: ReorderOption = False,
    json_output: JsonOption = False,
):
    """Move the bolted-side joint frames so that the model's equilibrium reproduces the
    measured poses of one case (spec geometry §3.8)."""
    check_output(out, suffixes=(".csv", ".json", ".html", ".txt"), what="report")
    check_identify_outputs(None, write_model)
    check_number(tol, "--tol", positive=True, unit="mm")
    if max_iterations < 1:
        raise fail("--max-iterations must be at least 1.", EXIT_BAD_INPUT)
    enable_x64()
    from ..identify import geometric
    from ..identify.report import format_table
    from ..measure import read_measurements

    with cli_errors():
        model_file = load_model_file(model)
        mech = model_file.mechanism
        meas = read_measurements(measurements, mech, reorder=reorder)
        if case not in meas.cases:
            raise fail(f"--case '{case}' is not a case of {measurements.name} (cases: "
                       f"{', '.join(meas.cases)}).", EXIT_BAD_INPUT)
        corrected, report = geometric.correct_geometry(
            mech, meas, element or None, case=meas.cases.index(case), tol=tol,
            max_iterations=max_iterations)
        if write_model is not None:
            write_model_file(corrected, write_model, model_file)
        if out is not None:
            report.write(out)
    if json_output:
        print_json(report.summary() | dict(
            case_errors=dict(zip(meas.cases, report.case_errors, strict=True))))
        return
    con = console(markup=False)
    con.print(str(report), highlight=False, soft_wrap=True)
    con.print(format_table(report, 120), highlight=False, soft_wrap=True)
    worst = max(range(len(meas.cases)), key=lambda c: report.case_errors[c])
    con.print(f"pose error of the corrected model at the other cases: largest "
              f"{report.case_errors[worst]:.3g} mm (case {meas.cases[worst]})", highlight=False)
    for label, path in (("corrected model", write_model), ("report", out)):
        if path is not None:
            con.print(f"{label} written to {path}", highlight=False, soft_wrap=True)
