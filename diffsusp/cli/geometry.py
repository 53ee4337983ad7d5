"""`diffsusp identify geometry|correct MODEL --measurements TABLE`: joint locations from the
measured motion of the parts (spec geometry §4, chapter 3) and the equilibrium-consistent
geometric correction (spec geometry §3.8, chapter 2).

- `geometry`: the joint list comes from the model (`diffsusp.identify.geometric.
  joints_from_model`: ball joints and bushings between measured parts as ball joints, bushings
  named with `--compliant` by the compliant-link method, revolute joints, the tie rod on an
  unmeasured rack, the strut top on an unmeasured strut) or from `--joints FILE.json` (a list
  of `GeometricJoint` fields). The joint table goes to the terminal (or `--json`), optionally to
  `--out` (.csv: one row per joint; .json), the model with the located joints to
  `--write-model`, and a figure of the located joints against the model to `--figures`.
- `correct`: the model's joint frames moved so that its equilibrium under the loads of case
  `--case` reproduces the measured poses (iterated to `--tol` mm).

TABLE is a landmark or pose table (format in `diffsusp.io.measurements`). Units: mm.
"""

import csv
import json
from pathlib import Path
from typing import Annotated

import typer
from rich import box
from rich.table import Table as RichTable

from .common import EXIT_BAD_INPUT, cli_errors, console, enable_x64, fail, print_json
from .identify import (
    JsonOpt,
    MeasurementsOpt,
    ModelArg,
    ReorderOpt,
    _check_paths,
    _write_model,
)


def _load(model, measurements, reorder):
    from .. import measure
    from .common import load_model_file

    model_file = load_model_file(model)
    mech = model_file.mechanism
    meas = measure.read_measurements(measurements, mech, reorder=reorder)
    return model_file, mech, meas


def _joints_file(path: Path):
    from ..errors import ModelFileError
    from ..identify.geometric import GeometricJoint

    try:
        items = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as e:
        raise ModelFileError(f"cannot read the joint list ({e}).", path=path) from None
    except json.JSONDecodeError as e:
        raise ModelFileError(f"not JSON: {e.msg}.", path=path, line=e.lineno) from None
    if not isinstance(items, list):
        raise ModelFileError("the joint list must be a JSON list of objects with name, kind, "
                             "parts (and slide, prior, prior_coordinate, link_ball, elements).",
                             path=path)
    joints = []
    for k, item in enumerate(items):
        try:
            item = dict(item)
            for key in ("parts", "slide", "prior", "elements"):
                if item.get(key) is not None:
                    item[key] = tuple(item[key])
            joints.append(GeometricJoint(**item))
        except (TypeError, ValueError) as e:
            raise ModelFileError(f"joint {k + 1}: {e}", path=path, field="joints") from None
    return joints


def geometry(
    model: ModelArg,
    measurements: MeasurementsOpt,
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
    out: Annotated[Path | None, typer.Option(help="Write the joint table (.csv or .json).")]
    = None,
    write_model: Annotated[Path | None, typer.Option(
        help="Write the model with the located joints (.toml or .adm).")] = None,
    figures: Annotated[Path | None, typer.Option(
        help="Write the located joints against the model (PNG) in this directory.")] = None,
    reorder: ReorderOpt = False,
    json_output: JsonOpt = False,
):
    """Locate the joints from the relative motion of the measured parts (mm)."""
    _check_paths(out, write_model)
    if landmark_sigma <= 0 or max_sigma <= 0 or min_snr <= 0:
        raise fail("--landmark-sigma, --max-sigma and --min-snr must be positive.",
                   EXIT_BAD_INPUT)
    enable_x64()
    from ..identify import geometric

    with cli_errors():
        model_file, mech, meas = _load(model, measurements, reorder)
        notes = ()
        if joints is not None:
            joint_list = _joints_file(joints)
        else:
            joint_list, notes = geometric.joints_from_model(mech, meas.parts,
                                                            compliant=tuple(compliant or ()))
        if not joint_list:
            raise fail("no joint to locate: measure the parts on both sides of a joint, or "
                       "give --joints.", EXIT_BAD_INPUT)
        report = geometric.locate_joints(meas, joint_list, landmark_sigma=landmark_sigma,
                                         max_sigma=max_sigma, min_snr=min_snr)
        if out is not None:
            _write_joints(report, out)
        if write_model is not None:
            located, _ = geometric.apply_locations(mech, report, joint_list)
            _write_model(located, write_model, model_file)
        if figures is not None:
            _figure(mech, report, joint_list, figures)
    if json_output:
        print_json(json.loads(report.to_json()) | {"notes_model": list(notes)})
        return
    con = console(markup=False)
    table = RichTable(title=f"{mech.name}: joints located from {measurements.name} "
                      f"({report.n_cases} cases, σ at landmark noise {landmark_sigma:g} mm)",
                      box=box.SIMPLE_HEAD)
    for col in ("joint", "kind", "parts", "x", "y", "z", "σx", "σy", "σz", "axis", "rms",
                "verdict"):
        table.add_column(col, justify="left" if col in ("joint", "kind", "parts", "verdict")
                         else "right")
    for j in report.joints:
        if j.centre is None:
            table.add_row(j.name, j.kind, "–".join(j.parts), *["—"] * 8,
                          f"not observable from these cases: {j.note}")
            continue
        axis = "" if j.axis is None else "(" + ", ".join(f"{v:.4f}" for v in j.axis) + ")"
        table.add_row(j.name, j.kind, "–".join(j.parts), *(f"{v:.3f}" for v in j.centre),
                      *(f"{v:.3f}" for v in j.sigma), axis, f"{j.residual:.2e}",
                      "observable")
    con.print(table)
    for note in (*report.notes, *notes):
        con.print(f"note: {note}", highlight=False)
    for label, path in (("joint table", out), ("model", write_model), ("figure", figures)):
        if path is not None:
            con.print(f"{label} written to {path}", highlight=False)


def _write_joints(report, path: Path):
    if path.suffix.lower() == ".json":
        path.write_text(report.to_json() + "\n", encoding="utf-8")
        return
    rows = report.rows()
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        for row in rows:
            writer.writerow({k: "" if v != v else v for k, v in row.items()})


def _figure(mech, report, joints, directory: Path):
    """Top (x–y) and side (x–z) views: model hardpoints (circles) and located centres
    (crosses, with 2σ bars)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from ..identify.geometric import element_table

    directory.mkdir(parents=True, exist_ok=True)
    table = element_table(mech)
    pos = np.asarray(mech.markers.position)
    fig, axes = plt.subplots(1, 2, figsize=(11, 5))
    for ax, (a, b, label) in zip(axes, ((0, 1, "top view (x, y)"), (0, 2, "side view (x, z)")),
                                 strict=True):
        for joint in joints:
            est = report[joint.name]
            for element in joint.elements:
                if element in table:
                    p = pos[table[element][4]]
                    ax.plot(p[a], p[b], "o", mfc="none", color="0.4")
            if est.centre is not None:
                ax.errorbar(est.centre[a], est.centre[b], xerr=2 * est.sigma[a],
                            yerr=2 * est.sigma[b], fmt="x", color="C3")
                ax.annotate(joint.name, (est.centre[a], est.centre[b]), fontsize=7,
                            xytext=(3, 3), textcoords="offset points")
        ax.set_title(label)
        ax.set_xlabel("xyz"[a] + " (mm)")
        ax.set_ylabel("xyz"[b] + " (mm)")
        ax.set_aspect("equal", adjustable="datalim")
    axes[0].plot([], [], "o", mfc="none", color="0.4", label="model")
    axes[0].plot([], [], "x", color="C3", label="located (±2σ)")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(directory / "geometry_joints.png", dpi=120)
    plt.close(fig)


def correct(
    model: ModelArg,
    measurements: MeasurementsOpt,
    case: Annotated[str, typer.Option(
        help="The measured case to reproduce (its label in the table).")],
    element: Annotated[list[str] | None, typer.Option(
        "--element", "-e", help="Correct only this joint or bushing (repeatable).")] = None,
    tol: Annotated[float, typer.Option(help="Pose tolerance (mm).")] = 1e-4,
    max_iterations: Annotated[int, typer.Option(help="Re-solve/re-correct passes.")] = 20,
    write_model: Annotated[Path | None, typer.Option(
        help="Write the corrected model (.toml or .adm).")] = None,
    reorder: ReorderOpt = False,
    json_output: JsonOpt = False,
):
    """Move the bolted-side joint frames so that the model's equilibrium reproduces the
    measured poses of one case (spec geometry §3.8)."""
    _check_paths(None, write_model)
    if tol <= 0 or max_iterations < 1:
        raise fail("--tol must be positive and --max-iterations at least 1.", EXIT_BAD_INPUT)
    enable_x64()
    from ..identify import geometric

    with cli_errors():
        model_file, mech, meas = _load(model, measurements, reorder)
        if case not in meas.cases:
            raise fail(f"--case '{case}' is not a case of {measurements.name} (cases: "
                       f"{', '.join(meas.cases)}).", EXIT_BAD_INPUT)
        corrected, report = geometric.correct_geometry(
            mech, meas, case=meas.cases.index(case), elements=element or None, tol=tol,
            max_iterations=max_iterations)
        if write_model is not None:
            _write_model(corrected, write_model, model_file)
    if json_output:
        print_json(dict(pose_errors=list(report.pose_errors), converged=report.converged,
                        iterations=report.iterations, moves=report.moves,
                        case_errors=dict(zip(meas.cases, report.case_errors, strict=True)),
                        notes=list(report.notes)))
        return
    con = console(markup=False)
    con.print(str(report), highlight=False)
    worst = max(range(len(meas.cases)), key=lambda c: report.case_errors[c])
    con.print(f"pose error of the corrected model at the other cases: largest "
              f"{report.case_errors[worst]:.3g} mm (case {meas.cases[worst]})", highlight=False)
    if write_model is not None:
        con.print(f"corrected model written to {write_model}", highlight=False)
