"""`diffsusp kc` (Typer's test runner): metrics table, JSON, figures, and exit codes.

Every run uses the pseudo-McPherson with 13 cases, structures and shapes that test_kc.py and
test_cli.py's demo compile too (steering on the rack-mounted half axle, the thesis load table,
a 13-case vertical-force sweep), so nothing is compiled twice in one process.
"""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

import diffsusp.cli.kc  # noqa: F401  (registers `kc`)
from diffsusp import kc
from diffsusp.cli import app
from diffsusp.models import pseudo_mcpherson

STEERING = ["--event", "steering", "--rack", "-20:20:13"]


@pytest.fixture(scope="module")
def runner():
    return CliRunner()


def test_kc_prints_metrics_and_writes_figures(runner, tmp_path):
    result = runner.invoke(app, ["kc", "pseudo_mcpherson", *STEERING, "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    out = result.stdout
    assert "steering, 13 cases; reference rack travel = 0 mm" in out
    rows = {line.split()[0]: line.split()[1:] for line in out.splitlines()
            if len(line.split()) == 5}
    assert rows["toe"][0] == "deg" and rows["steer_gain"][0] == "deg/mm"
    assert 0.3 < float(rows["steer_gain"][1]) < 0.5  # deg of steer per mm of rack
    assert float(rows["steer"][2]) < -5.0 < 5.0 < float(rows["steer"][3])
    assert abs(float(rows["wheel_travel"][1])) < 1e-9  # the wheel height is held
    assert "Held fixed by the derivative metrics: wheel height" in out
    for stem in ("kc_steering", "kc_steering_derivatives"):
        for suffix in ("png", "svg"):
            path = tmp_path / f"{stem}.{suffix}"
            assert path.exists() and path.stat().st_size > 10_000, path


def test_kc_json_matches_the_library(runner):
    result = runner.invoke(app, ["kc", "pseudo_mcpherson", "--event", "table-5-1", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["event"] == "load_table" and data["x"]["values"] == list(range(1, 14))
    assert data["status"] == [0] * 13
    ev = kc.load_table(pseudo_mcpherson(), kc.TABLES["table_5_1"])
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
    assert "unknown event 'rollover'" in result.output and "parallel-travel" in result.output
    result = runner.invoke(app, ["kc", "pseudo_mcpherson", "--travel", "-60:60"])
    assert result.exit_code == 2
    assert "--travel '-60:60' is not a range" in result.output


def test_non_converging_load_exits_3(runner):
    """20 kN on a 4.5 kN corner without bump stops: no equilibrium within the travel."""
    result = runner.invoke(app, ["kc", "pseudo_mcpherson", "--event", "vertical-force",
                                 "--fz", "20000:20000:13"])
    assert result.exit_code == 3, result.output
    assert "vertical_force: case 0 (vertical_force = 20000 N) did not converge" in result.output
