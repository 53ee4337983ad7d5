"""`diffsusp info` and `diffsusp simulate` accept every model format (docs/guides/models.md):
native TOML (tests/test_cli_model.py), Adams datasets and Chrono::Vehicle JSON templates."""

import json
import pathlib

from typer.testing import CliRunner

from diffsusp.cli import app

DATA = pathlib.Path(__file__).parent / "data"


def test_info_reads_an_adams_dataset_and_a_chrono_template():
    result = CliRunner().invoke(app, ["info", str(DATA / "model_exemple11.adm"), "--json"])
    assert result.exit_code == 0, result.output
    info = json.loads(result.output)
    assert info["bushings"] == ["BUSHING_1"] and info["dof"] == 6  # one part on a bushing
    result = CliRunner().invoke(app, ["info", str(DATA / "chrono" / "DoubleWishbone.json"),
                                      "--json"])
    assert result.exit_code == 0, result.output
    info = json.loads(result.output)
    assert info["free_modes"] == [] and info["rank"] == info["constraint_rows"]
    assert "contact_patch" in info["load_points"]


def test_simulate_an_adams_dataset(tmp_path):
    """The spec's model_exemple11 (§4.1), K = 100 N/mm in every direction: a force
    F = (300, −200, 500) N at the bushing moves the part by F/K = (3, −2, 5) mm (spec §7 R1)."""
    loads = tmp_path / "loads.csv"
    loads.write_text("GFORCE_1.fx [N],GFORCE_1.fy [N],GFORCE_1.fz [N]\n300,-200,500\n")
    out = tmp_path / "results.csv"
    result = CliRunner().invoke(app, ["simulate", str(DATA / "model_exemple11.adm"),
                                      "--loads", str(loads), "--out", str(out)])
    assert result.exit_code == 0, result.output
    text = out.read_text()
    assert "status" in text.splitlines()[0]
    row = dict(zip(text.splitlines()[0].split(","), text.splitlines()[1].split(","),
                   strict=True))
    assert float(row["status"]) == 0
    moved = [float(row[f"PART_2.{a} [mm]"]) for a in "xyz"]
    assert max(abs(m - e) for m, e in zip(moved, (3.0, -2.0, 5.0), strict=True)) < 1e-9
