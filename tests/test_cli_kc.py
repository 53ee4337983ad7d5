"""`diffsusp kc` (Typer's test runner): metrics table, JSON, figures, and exit codes; and the
pseudo-McPherson's force events against the NumPy oracle.

Every run here is a 13-case force event on the pseudo-McPherson (the thesis load table, a
vertical-force sweep), one compiled program (the same as `thesis_load_cases` with the demo):
the library checks of those events live here too, with the helpers of test_kc.py, so that the
program is compiled once per worker (pytest-xdist gives each file to one worker).
"""

import json

import numpy as np
import pytest
from test_kc import assert_compliance_matrix, assert_derivatives, assert_geometry, pm_spec
from typer.testing import CliRunner

import diffsusp.cli.kc  # noqa: F401  (registers `kc`)
from diffsusp import kc
from diffsusp.cli import app
from diffsusp.models import TABLE_5_1, pseudo_mcpherson, thesis_load_cases

TABLE = ["--event", "table-5-1"]
N = 13


@pytest.fixture(scope="module")
def runner():
    return CliRunner()


@pytest.fixture(scope="module")
def pm():
    return pseudo_mcpherson()


@pytest.fixture(scope="module")
def pm_table(pm):
    return kc.load_table(pm, TABLE_5_1)


@pytest.fixture(scope="module")
def pm_vertical(pm):
    return kc.vertical_force(pm, np.linspace(3000.0, 6000.0, N))


def test_kc_prints_metrics_and_writes_figures(runner, tmp_path):
    result = runner.invoke(app, ["kc", "pseudo_mcpherson", *TABLE, "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    out = result.stdout
    assert "load table, 13 cases; reference case = 1" in out
    rows = {line.split()[0]: line.split()[1:] for line in out.splitlines()
            if len(line.split()) == 5}
    assert rows["toe"][0] == "deg" and rows["bump_steer"][0] == "deg/m"
    assert rows["wheel_rate"][0] == "N/mm" and 15.0 < float(rows["wheel_rate"][1]) < 30.0
    assert rows["vertical_force"][1:] == ["1500", "1500", "7500"]
    assert rows["lateral_force"][2:] == ["-4000", "4000"]
    assert "Held fixed by the derivative metrics: vertical load" in out
    for stem in ("kc_load_table", "kc_load_table_derivatives"):
        for suffix in ("png", "svg"):
            path = tmp_path / f"{stem}.{suffix}"
            assert path.exists() and path.stat().st_size > 10_000, path


def test_kc_json_matches_the_library(runner, pm_table):
    result = runner.invoke(app, ["kc", "pseudo_mcpherson", *TABLE, "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["event"] == "load_table" and data["x"]["values"] == list(range(1, 14))
    assert data["status"] == [0] * 13
    ev = pm_table
    for name in ("toe", "camber", "bump_steer", "lateral_compliance_steer", "wheel_rate",
                 "vertical_force"):
        assert data["metrics"][name]["unit"] == kc.display_unit(name)
        np.testing.assert_allclose(data["metrics"][name]["values"],
                                   kc.display(name, ev.metrics[name]), rtol=1e-12)
    matrix = np.array(data["compliance_matrix"]["values"]["corner"])
    np.testing.assert_allclose(matrix, kc.compliance_matrix(ev), rtol=1e-12)


def test_bad_model_path(runner, tmp_path):
    result = runner.invoke(app, ["kc", str(tmp_path / "missing.toml")])
    assert result.exit_code == 2
    assert "neither a built-in model" in result.output and "missing.toml" in result.output


def test_unreadable_model_file(runner, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("this is [ not a model\n")
    result = runner.invoke(app, ["kc", str(bad)])
    assert result.exit_code == 2, result.output
    assert "bad.toml" in result.output


def test_unknown_event_and_bad_range(runner):
    result = runner.invoke(app, ["kc", "pseudo_mcpherson", "--event", "rollover"])
    assert result.exit_code == 2
    # A choice of the `Event` enumeration (Typer checks it before anything runs).
    assert "'rollover' is not one of" in result.output and "parallel-travel" in result.output
    result = runner.invoke(app, ["kc", "pseudo_mcpherson", "--travel", "-60:60"])
    assert result.exit_code == 2
    assert "--travel '-60:60' is not a range" in result.output


def test_non_converging_load_exits_3(runner):
    """20 kN on a 4.5 kN corner without bump stops: no equilibrium within the travel."""
    result = runner.invoke(app, ["kc", "pseudo_mcpherson", "--event", "vertical-force",
                                 "--fz", "20000:20000:13"])
    assert result.exit_code == 3, result.output
    assert "vertical_force: case 0 (vertical_force = 20000 N) did not converge" in result.output


# ----------------------------------------------------------------------------- library


def test_pm_load_table_matches_thesis_mapping_and_oracle(pm, pm_table):
    """On the left pseudo-McPherson (Adams/Car frame) the per-side mapping (lateral inboard,
    longitudinal rearward) is exactly `thesis_load_cases`; metrics against the oracle."""
    loads = thesis_load_cases(pm, TABLE_5_1)
    # applied at the ground contact point (kc.force_rig's road_contact)
    road, cp = pm_table.rig.road[0], pm.load_points.index("contact_patch")
    np.testing.assert_array_equal(pm_table.loads.force[:, road], loads.force[:, cp])
    assert float(np.abs(pm_table.loads.force).sum()) == float(np.abs(loads.force).sum())
    np.testing.assert_array_equal(pm_table.metrics["vertical_force"], TABLE_5_1[:, 0])
    np.testing.assert_array_equal(pm_table.metrics["lateral_force"], TABLE_5_1[:, 1])
    np.testing.assert_array_equal(pm_table.metrics["longitudinal_force"], TABLE_5_1[:, 2])
    assert_geometry(pm_table, (0, 5, 9), pm_spec())


def test_pm_vertical_force_derivatives_and_compliance_matrix(pm_vertical):
    assert_derivatives(pm_vertical, 6, pm_spec())
    assert_compliance_matrix(pm_vertical, 6, pm_spec())
    assert 20.0 < float(pm_vertical.metrics["wheel_rate"][6]) < 30.0  # ≈ 24 N/mm (documented)
