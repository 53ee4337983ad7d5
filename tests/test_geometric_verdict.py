"""The geometric location on the one verdict and its rehearsal, on the Chrono double
wishbone with torsion-free arm bushings (tests/data/DoubleWishbone_bushings.json; the 24
contact-patch cases of test_geometric_free_axis, so that the compiled programs are shared):

- `identify geometry` prints its table within 120 columns and writes CSV and JSON that agree
  with it on every status (identified; not determined: a revolute's position along its axis);
- a landmark table with two landmarks of one part swapped in three cases: the
  part and the cases are named in a warning, the verdict is inconsistent and no coordinate is
  "identified";
- a small rehearsal (`GeometryScenario`: hardpoints ±5 mm, σ 0.05 mm) whose claims stay within
  3σ, and the CLI's `rehearse geometry` bad inputs (exit 2)."""

import csv
import json
import pathlib

import numpy as np
import pytest
from helpers import table_statuses
from typer.testing import CliRunner

from diffsusp import load_model, measure
from diffsusp.cli import app
from diffsusp.identify import GeometryScenario, rehearse
from diffsusp.kc.corner import equilibrium_load

MODEL = pathlib.Path(__file__).parent / "data" / "DoubleWishbone_bushings.json"
SIGMA = 0.05
SWAPPED = (3, 10, 17)  # cases (0-based) where two landmarks of the upright are swapped


@pytest.fixture(scope="module")
def chrono():
    mech = load_model(str(MODEL))
    f0 = equilibrium_load(mech, "contact_patch")
    force = np.array([[x, y, z] for z in (0.5 * f0, 0.8 * f0, 1.1 * f0, 1.4 * f0)
                      for y in (-2000.0, 0.0, 2000.0) for x in (-1500.0, 1500.0)])
    return mech, mech.loads(forces={"contact_patch": force})


@pytest.fixture(scope="module")
def tables(chrono, tmp_path_factory):
    """A noisy landmark table of the model, and the same with two landmark names of the
    upright swapped in three cases."""
    import jax

    mech, loads = chrono
    parts = ("upper_control_arm", "lower_control_arm", "upright")
    layout = measure.place_landmarks(mech, 4, parts=parts, seed=0)
    meas = measure.synthesize(mech, loads, layout=layout,
                              noise=measure.GaussianNoise(landmarks=SIGMA),
                              key=jax.random.PRNGKey(4))
    root = tmp_path_factory.mktemp("geometry_verdict")
    good = root / "landmarks.csv"
    measure.write_measurements(meas, good, mech)
    points = np.array(meas.landmarks)
    u = parts.index("upright")
    for c in SWAPPED:
        points[c, u, [0, 2]] = points[c, u, [2, 0]]
    bad = root / "swapped.csv"
    measure.write_measurements(measure.from_landmarks(layout, points, loads), bad, mech)
    return good, bad


def _run(*args):
    return CliRunner().invoke(app, [*map(str, args)])


def test_table_csv_json_agree_and_swapped_landmarks_are_flagged(tables, tmp_path):
    good, bad = tables
    report = {}
    for name, table in (("good", good), ("bad", bad)):
        csv_path, json_path = tmp_path / f"{name}.csv", tmp_path / f"{name}.json"
        printed = _run("identify", "geometry", MODEL, "-m", table, "--out", csv_path)
        assert printed.exit_code == 0, printed.output
        assert max(len(line) for line in printed.output.splitlines()) <= 120
        assert _run("identify", "geometry", MODEL, "-m", table, "--out",
                    json_path).exit_code == 0
        with open(csv_path, newline="", encoding="utf-8") as f:
            rows = {r["parameter"]: r for r in csv.DictReader(f)}
        summary = json.loads(json_path.read_text())
        from_json = {p["parameter"]: p["status"] for p in summary["parameters"]}
        from_csv = {k: r["status"] for k, r in rows.items()}
        assert from_csv == from_json == table_statuses(printed.output, set(rows))
        report[name] = (printed.output, summary, from_csv)
    text, summary, status = report["good"]
    # the torsion-free bushings are revolutes: their x (along the axis, ~x) not determined,
    # the rest identified; the ball joints identified; the registration consistent
    assert summary["consistency"]["consistent"]
    assert summary["fit_verdict"] == summary["consistency"]["verdict"]  # no warning
    for joint in ("uca_bushing", "lca_bushing"):
        assert status[f"{joint}.x"] == "not determined"
        assert status[f"{joint}.axis_y"] == "identified"
    assert "position along the axis not observable" in text
    for c in "xyz":
        assert status[f"uca_ball_joint.{c}"] == status[f"lca_ball_joint.{c}"] == "identified"
    # D6: swapped landmarks named (part and cases), verdict inconsistent, nothing identified
    text, summary, status = report["bad"]
    assert not summary["consistency"]["consistent"]
    warning = summary["fit_verdict"]
    assert "part 'upright'" in warning and "swapped or moved" in warning
    assert "part 'upper" not in warning and "part 'lower" not in warning
    assert f"case(s) {', '.join(str(c + 1) for c in SWAPPED)}:" in warning
    assert any("part 'upright'" in w for w in summary["warnings"])  # the written file's list
    assert "identified" not in status.values()
    assert "INCONSISTENT" in text and "part 'upright'" in " ".join(text.split())
    # the re-ordering the warning offers matches the landmarks by their distances: consistent
    fixed = _run("identify", "geometry", MODEL, "-m", bad, "--reorder", "--json")
    assert fixed.exit_code == 0, fixed.output
    summary = json.loads(fixed.output)
    assert summary["consistency"]["consistent"] and not summary["warnings"]
    assert {p["parameter"]: p["status"] for p in summary["parameters"]} == report["good"][2]


def test_a_small_geometry_rehearsal_claims_nothing_wrong(chrono):
    """6 random truths (hardpoints ±5 mm) of the torsion-free Chrono corner: the revolutes'
    positions along their axes are never claimed; every other claim of the bushings' lines
    (compliant: the model's bias carried in σ, noise-free they are 1–6 mm off) within 3σ, and
    at most one claim per coordinate outside 3σ for the ball joints (their σ calibrated within
    a factor 1.5 of the Monte-Carlo spread, test_geometric); a method that reported the noise
    σ alone (0.1–1.5 mm) for the bushings fails here."""
    mech, loads = chrono
    report = rehearse(GeometryScenario(mech, loads, noise=SIGMA, spread=5.0), n=6, seed=2)
    assert report.failed == 0 and report.consistent_rate == 1.0
    params = {p.name: p for p in report.parameters}
    for joint in ("uca_bushing", "lca_bushing"):
        assert params[f"{joint}.x"].identified == 0
        for c in ("z", "axis_y", "axis_z"):
            p = params[f"{joint}.{c}"]
            assert p.identified >= 4 and p.false_identified == 0, p
    for joint in ("uca_ball_joint", "lca_ball_joint"):
        for c in "xyz":
            p = params[f"{joint}.{c}"]
            assert p.identified == 6 and p.false_identified <= 1, p


@pytest.mark.parametrize("args, message", [
    (["--n", "0"], "at least 1 random truth"),
    (["--noise", "0"], "positive landmark σ"),
    (["--spread", "0"], "displacement > 0"),
    (["--params", "hinge"], "unknown parameter"),
])
def test_rehearse_geometry_bad_input_exits_2(args, message):
    result = _run("rehearse", "geometry", MODEL, *args)
    assert result.exit_code == 2, result.output
    assert message in " ".join(result.output.split())
