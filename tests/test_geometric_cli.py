"""`diffsusp identify geometry` and `identify correct` (Typer's runner) on the isolated bushing:
the arm turned about a known point (a ball joint at (10, −5, 3) mm), and a corrected model
against a measured equilibrium."""

import csv
import json

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from typer.testing import CliRunner

from diffsusp import load_model, measure, save_model
from diffsusp.cli import app
from diffsusp.geometry import rotvec_to_matrix
from diffsusp.identify.geometric import correct_geometry
from diffsusp.models import isolated_bushing

CENTRE = np.array([10.0, -5.0, 3.0])


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    mech = isolated_bushing()
    root = tmp_path_factory.mktemp("geometry")
    layout = measure.place_landmarks(mech, seed=2)
    rotvecs = np.radians([[3, 0, 0], [0, 4, 0], [0, 0, -5], [2, 2, 1], [-3, 1, 2], [1, -4, 3]])
    rot = np.stack([np.asarray(rotvec_to_matrix(v)) for v in rotvecs])[:, None]
    trans = (CENTRE - np.einsum("cpij,j->cpi", rot, CENTRE))
    points = measure.landmark_positions(layout, jnp.asarray(rot), jnp.asarray(trans))
    loads = mech.loads(forces={"tip": np.zeros((6, 3))})
    motion = root / "motion.csv"
    measure.write_measurements(measure.from_landmarks(layout, points, loads), motion, mech)
    # a measured equilibrium (any pose is the equilibrium of some geometry: the correction
    # must find it), and a model with its I marker 0.8 mm off
    load = mech.loads(forces={"tip": np.array([[30.0, -20.0, 50.0]])})
    r = np.asarray(rotvec_to_matrix(np.radians([1.0, -2.0, 0.5])))[None, None]
    points = measure.landmark_positions(layout, jnp.asarray(r), jnp.asarray([[[0.3, 0.2, 0.4]]]))
    equilibrium = root / "equilibrium.csv"
    measure.write_measurements(measure.from_landmarks(layout, points, load), equilibrium, mech)
    perturbed = eqx.tree_at(lambda m: m.markers.position, mech,
                            mech.markers.position.at[0].add(jnp.array([0.5, -0.4, 0.5])))
    model = root / "perturbed.toml"
    save_model(perturbed, model)
    return dict(motion=motion, equilibrium=equilibrium, perturbed=model, root=root)


def _run(*args):
    return CliRunner().invoke(app, ["identify", *map(str, args)])


def test_identify_geometry(files, tmp_path):
    out, model, figs = tmp_path / "joints.csv", tmp_path / "located.toml", tmp_path / "figs"
    report = tmp_path / "report.csv"
    result = _run("geometry", "isolated_bushing", "--measurements", files["motion"],
                  "--joint-table", out, "--out", report, "--write-model", model, "--figures",
                  figs)
    assert result.exit_code == 0, result.output
    assert "bush.x" in result.output and "identified" in result.output
    assert max(len(line) for line in result.output.splitlines()) <= 120
    rows = out.read_text().splitlines()
    assert rows[0].startswith("joint,kind,part_1,part_2,x,y,z")
    assert report.read_text().splitlines()[0].startswith("method,parameter,estimate,sigma")
    located = load_model(model)
    np.testing.assert_allclose(located.markers.position[0], CENTRE, atol=1e-9)
    np.testing.assert_allclose(located.markers.position[1], CENTRE, atol=1e-9)
    assert (figs / "geometry_joints.png").stat().st_size > 1000
    result = _run("geometry", "isolated_bushing", "--measurements", files["motion"], "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    (joint,) = summary["joints"]
    assert joint["kind"] == "ball" and joint["observable"]
    assert [p["status"] for p in summary["parameters"]] == ["identified"] * 3
    np.testing.assert_allclose(joint["centre"], CENTRE, atol=1e-9)


def test_identify_geometry_bad_input(files, tmp_path):
    bad = tmp_path / "joints.json"
    bad.write_text(json.dumps([{"name": "j", "kind": "ball", "parts": ["ground", "wing"]}]))
    result = _run("geometry", "isolated_bushing", "--measurements", files["motion"],
                  "--joints", bad)
    assert result.exit_code == 2 and "part 'wing', which has no measured pose" in \
        " ".join(result.output.split())
    bad.write_text("[{")
    result = _run("geometry", "isolated_bushing", "--measurements", files["motion"],
                  "--joints", bad)
    assert result.exit_code == 2 and "not JSON" in result.output


def test_identify_correct(files, tmp_path):
    model = tmp_path / "corrected.toml"
    result = _run("correct", files["perturbed"], "--measurements", files["equilibrium"],
                  "--case", "1", "--write-model", model, "--json")
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    assert report["converged"] and report["pose_errors"][-1] < 1e-4
    assert report["pose_errors"][0] > 0.1
    assert list(report["case_errors"]) == ["1"] and report["case_errors"]["1"] < 1e-4
    # the report base's rows: the moved I marker's coordinates, σ from the landmark noise
    (marker,) = report["moves"]
    rows = report["parameters"]
    assert [r["parameter"] for r in rows] == [f"{marker}.{c}" for c in "xyz"]
    assert all(r["status"] == "identified" and r["sigma"] > 0 for r in rows), rows
    # the printed table and the CSV say the same (one verdict, every writer)
    out = tmp_path / "correct.csv"
    printed = _run("correct", files["perturbed"], "--measurements", files["equilibrium"],
                   "--case", "1", "--out", out)
    assert printed.exit_code == 0, printed.output
    with open(out, newline="", encoding="utf-8") as f:
        from_csv = {r["parameter"]: r["status"] for r in csv.DictReader(f)
                    if r["parameter"] in {x["parameter"] for x in rows}}
    assert from_csv == {r["parameter"]: r["status"] for r in rows}
    for name, status in from_csv.items():
        line = next(t for t in printed.output.splitlines() if t.split()[:1] == [name])
        assert status in line, line
    # the written model is the library's correction (same compiled solve: same model)
    perturbed = load_model(files["perturbed"])
    meas = measure.read_measurements(files["equilibrium"], perturbed)
    expected, _ = correct_geometry(perturbed, meas, case=0)
    corrected = load_model(model)
    np.testing.assert_allclose(corrected.markers.position, expected.markers.position, atol=1e-9)
    np.testing.assert_allclose(corrected.markers.orientation, expected.markers.orientation,
                               atol=1e-12)
    # the bushing's I marker moved (the J marker, on the ground, did not)
    assert np.linalg.norm(corrected.markers.position[0] - perturbed.markers.position[0]) > 0.1
    np.testing.assert_array_equal(corrected.markers.position[1], perturbed.markers.position[1])
    result = _run("correct", files["perturbed"], "--measurements", files["equilibrium"],
                  "--case", "7")
    assert result.exit_code == 2 and "is not a case" in result.output
