"""`diffsusp info` and `diffsusp simulate` (Typer's test runner).

Every solve uses the isolated bushing (closed form: a force F at the bushing's I marker moves the
arm by F/K, and a moment M there turns it by projected angles R_Jᵀ·M/K_T) under one table of
three load cases, so the solver compiles once for the module.
"""

import json
import pathlib
import warnings

import numpy as np
import pytest
from typer.testing import CliRunner

import diffsusp.cli.model as cli_model  # registers `info` and `simulate`
from diffsusp import simulation
from diffsusp.cli import app
from diffsusp.io import read_table, write_table
from diffsusp.model.mechanism import PARAMETER_UNITS
from diffsusp.models import isolated_bushing

DATA = pathlib.Path(cli_model.__file__).parents[1] / "models" / "data"
K, K_T = 100.0, 1e4 * 180 / np.pi  # isolated_bushing(): N/mm, N·mm/rad
FORCE = np.array([100.0, -50.0, 20.0])  # N at 'centre'
MOMENT = np.array([0.0, 300.0, 1000.0])  # N·mm at 'centre'
HUGE = 1e7  # N·mm about x: the bushing cannot turn that far (projected angles): no equilibrium


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def loads_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("loads") / "loads.csv"
    write_table(path, {
        "centre.fx": [FORCE[0], 0.0, 0.0], "centre.fy": [FORCE[1], 0.0, 0.0],
        "centre.fz": [FORCE[2], 0.0, 0.0], "centre.mx": [0.0, MOMENT[0], HUGE],
        "centre.my": [0.0, MOMENT[1], 0.0], "centre.mz": [0.0, MOMENT[2], 0.0],
    }, {"centre.fx": "N", "centre.mx": "N·mm"})
    return path


@pytest.fixture(scope="module")
def csv_run(loads_csv, tmp_path_factory):
    out = tmp_path_factory.mktemp("out") / "results.csv"
    result = invoke("simulate", "isolated_bushing", "--loads", loads_csv, "--out", out)
    return result, out


def test_simulate_builtin_csv_matches_the_closed_form(csv_run):
    result, out = csv_run
    assert result.exit_code == 3, result.output  # case 2 cannot converge
    assert "1 load case did not converge: 2 (stalled)" in result.stderr
    assert "beyond the projected angles' validity" in result.stderr  # the warning, printed
    assert "2 of 3 load cases converged" in result.stdout
    table = read_table(out)
    np.testing.assert_array_equal(table["case"], [0, 1, 2])
    np.testing.assert_array_equal(table["status"], [0, 0, 3])  # 3: stalled
    assert table.units["arm.x"] == "mm" and table.units["bush.tx"] == "N·mm"
    rj = np.asarray(isolated_bushing().markers.orientation[1])  # J marker frame (columns)
    # Case 0: a force at the I marker translates the arm by F/K; deformation and force in J.
    pos = np.array([table[f"arm.{a}"][0] for a in "xyz"])
    np.testing.assert_allclose(pos, FORCE / K, rtol=1e-12)
    np.testing.assert_allclose([table[f"arm.g{a}"][0] for a in "xyz"], 0.0, atol=1e-14)
    np.testing.assert_allclose([table[f"bush.d{a}"][0] for a in "xyz"], rj.T @ FORCE / K,
                               rtol=1e-12)
    np.testing.assert_allclose([table[f"bush.f{a}"][0] for a in "xyz"], -rj.T @ FORCE,
                               rtol=1e-12)
    # Case 1: a moment turns it by projected angles R_Jᵀ·M/K_T exactly, no translation.
    np.testing.assert_allclose([table[f"bush.a{a}"][1] for a in "xyz"], rj.T @ MOMENT / K_T,
                               rtol=1e-10)
    np.testing.assert_allclose([table[f"bush.t{a}"][1] for a in "xyz"], -rj.T @ MOMENT,
                               rtol=1e-10)
    np.testing.assert_allclose([table[f"arm.{a}"][1] for a in "xyz"], 0.0, atol=1e-12)
    # The loads are echoed, in library units.
    np.testing.assert_array_equal(table["centre.mx"], [0.0, 0.0, HUGE])
    assert table["residual"][0] < 1e-12 and table["residual"][2] > 1e-6


def test_simulate_toml_parquet_json_and_named_table(csv_run, loads_csv, tmp_path):
    _, csv_out = csv_run
    reference = read_table(csv_out)
    # Parquet loads in other units, a .toml model file, Parquet results, a JSON summary.
    loads = read_table(loads_csv)
    parquet_in = tmp_path / "loads.parquet"
    write_table(parquet_in, {n: loads[n] / 1000.0 for n in loads.names},
                {n: "kN" if ".f" in n else "N·m" for n in loads.names})
    out = tmp_path / "results.parquet"
    result = invoke("simulate", DATA / "isolated_bushing.toml", "--loads", parquet_in,
                    "--out", out, "--json")
    assert result.exit_code == 3
    summary = json.loads(result.stdout)
    assert summary["cases"] == 3 and summary["converged"] == 2
    assert summary["failed"][0]["case"] == 2
    assert summary["failed"][0]["status"] == "stalled"
    assert summary["columns"] == len(reference.names)
    assert summary["max_residual"] > 1e-6
    got = read_table(out)
    assert got.names == reference.names and got.units == reference.units
    for name in ("arm.x", "arm.gz", "bush.dx", "bush.ay", "bush.fz", "iterations"):
        # atol: round-off of a zero (mm, rad, N): the loads went through kN and back.
        np.testing.assert_allclose(got[name][:2], reference[name][:2], rtol=1e-12,
                                   atol=1e-12)
    # A load table named in the model file.
    model = tmp_path / "with_table.toml"
    rows = "\n".join(f"    [{', '.join(repr(float(loads[n][r])) for n in loads.names)}],"
                     for r in range(3))
    model.write_text((DATA / "isolated_bushing.toml").read_text() + (
        "\n[load_tables.three]\n"
        f"columns = [{', '.join(json.dumps(n) for n in loads.names)}]\n"
        f"rows = [\n{rows}\n]\n"))
    out = tmp_path / "named.csv"
    result = invoke("simulate", model, "--loads", "three", "--out", out)
    assert result.exit_code == 3
    named = read_table(out)["arm.x"]
    np.testing.assert_array_equal(named[:2], reference["arm.x"][:2])
    # The stalled case stops where its line search gives up: a round-off zero (mm).
    np.testing.assert_allclose(named[2], reference["arm.x"][2], atol=1e-12)


def test_progress_over_chunks_gives_the_same_results(csv_run, loads_csv, tmp_path,
                                                     monkeypatch):
    _, csv_out = csv_run
    reference = read_table(csv_out)
    # Five cases in chunks of three (the table's own shape: nothing new to compile), the last
    # chunk padded by repeating its final case.
    loads = read_table(loads_csv)
    order = [0, 1, 2, 1, 0]
    five = tmp_path / "five.csv"
    write_table(five, {n: loads[n][order] for n in loads.names})
    monkeypatch.setattr(simulation, "CHUNK", 3)
    out = tmp_path / "chunked.csv"
    result = invoke("simulate", "isolated_bushing", "--loads", five, "--out", out)
    assert result.exit_code == 3
    assert "1 load case did not converge: 2 (stalled)" in result.stderr
    got = read_table(out)
    np.testing.assert_array_equal(got["case"], np.arange(5))
    for name in reference.names:
        if name != "case":
            np.testing.assert_array_equal(got[name], reference[name][order])


def test_simulate_table_is_the_library_call_behind_simulate(csv_run, loads_csv, tmp_path,
                                                            monkeypatch):
    """`diffsusp.simulation` without the command: a load table named by a model file or a
    path (`load_cases`), solved and written chunk by chunk (`simulate_table`: the rows the CLI
    writes); an interruption after the first chunk leaves the rest written with status -1 and
    is returned, not raised."""
    from diffsusp.errors import InputError, ModelFileError
    from diffsusp.resolve import load_model_file

    mf = load_model_file("isolated_bushing")
    table = simulation.load_cases(mf, str(loads_csv))
    with pytest.raises(ModelFileError, match="not a load table of the model"):
        simulation.load_cases(mf, str(tmp_path / "nope.csv"))
    empty = tmp_path / "empty.csv"
    empty.write_text("centre.fx [N]\n")
    with pytest.raises(InputError, match="has no rows"):
        simulation.load_cases(mf, str(empty))
    out = tmp_path / "lib.csv"
    done = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run = simulation.simulate_table(mf.mechanism, table, out, progress=done.append)
    assert any("projected angles' validity" in str(w.message) for w in caught)
    assert done == [3] and run.interrupted is None and run.done == 3
    summary = run.summary()
    assert (summary["cases"], summary["converged"], summary["not_solved"]) == (3, 2, 0)
    assert [f["case"] for f in summary["failed"]] == [2]
    _, cli_out = csv_run
    reference, got = read_table(cli_out), read_table(out)
    for name in reference.names:
        np.testing.assert_array_equal(got[name], reference[name])

    def stop(n):
        raise KeyboardInterrupt

    monkeypatch.setattr(simulation, "CHUNK", 3)  # one chunk: the same compiled shape
    five = tmp_path / "five.csv"
    write_table(five, {n: table[n][[0, 1, 2, 1, 0]] for n in table.names})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # case 2's, as above
        run = simulation.simulate_table(mf.mechanism, read_table(five), out, progress=stop)
    assert isinstance(run.interrupted, KeyboardInterrupt) and run.done == 3
    got = read_table(out)
    np.testing.assert_array_equal(got["status"], [0, 0, 3, -1, -1])
    assert run.summary()["not_solved"] == 2 and run.summary()["interrupted"]


def test_flagged_cases_lists_failures_and_converged_cases_with_a_false_flag():
    """`statics.flagged_cases` (what `simulate` and `kc` warn about): not converged (status > 0,
    not -1: not solved), and converged cases whose stable / law_valid flag is False."""
    from diffsusp.statics import StaticSolution, flagged_cases

    status = np.array([0, 0, 3, 0, -1, 1, 0])
    stable = np.array([True, False, False, True, False, False, False])
    law_valid = np.array([True, True, False, False, False, False, True])
    zeros = np.zeros(status.size)
    sol = StaticSolution(q=np.zeros((status.size, 6)), multipliers=np.zeros((status.size, 0)),
                         status=status, iterations=zeros, residual=zeros,
                         constraint_error=zeros, stable=stable, law_valid=law_valid)
    flags = flagged_cases(sol)
    assert {k: v.tolist() for k, v in flags.items()} == {
        "failed": [2, 5], "unstable": [1, 6], "law_invalid": [3]}
    unflagged = flagged_cases(StaticSolution(**{**vars(sol), "stable": None, "law_valid": None}))
    assert unflagged["failed"].tolist() == [2, 5]
    assert unflagged["unstable"].size == unflagged["law_invalid"].size == 0


def test_chunked_solve_refuses_a_single_case_and_an_empty_chunk():
    """`solve_statics_chunks` (the loop `simulate` streams from) needs a case axis and a chunk
    of at least one case; both are refused before anything is traced."""
    from diffsusp.statics import solve_statics_chunks

    mech = isolated_bushing()
    one = mech.loads(forces={"centre": FORCE})
    with pytest.raises(ValueError, match="leading case axis"):
        next(solve_statics_chunks(mech, one, 2))
    table = mech.loads(forces={"centre": np.stack([FORCE, -FORCE])})
    with pytest.raises(ValueError, match="chunk must be at least 1"):
        next(solve_statics_chunks(mech, table, 0))


@pytest.mark.parametrize("content,message", [
    ("centre.fx,centre.fq\n1,2\n", "unknown column 'centre.fq' for model"),
    ("centre.fx,centre.fy\n1,2\n3\n", ":3: the row has 1 values but the header names 2"),
    ("centre.fx,centre.fy\n1,2\n3,4 N\n", ":3: centre.fy: '4 N' in column 'centre.fy' is not"),
    ("centre.fx [mm]\n1\n", "unit 'mm' is not a force unit"),
])
def test_bad_load_tables_exit_2(tmp_path, content, message):
    path = tmp_path / "loads.csv"
    path.write_text(content)
    result = invoke("simulate", "isolated_bushing", "--loads", path, "--out", tmp_path / "r.csv")
    assert result.exit_code == 2, result.output
    assert message in " ".join(result.stderr.split())
    assert not (tmp_path / "r.csv").exists()


def test_bad_paths_exit_2(tmp_path, loads_csv):
    for args, message in (
        (("simulate", tmp_path / "nope.toml", "--loads", loads_csv, "--out", tmp_path / "r.csv"),
         "no such file"),
        (("simulate", "isolated_bushing", "--loads", tmp_path / "nope.csv", "--out",
          tmp_path / "r.csv"), "not a load table of the model"),
        (("simulate", "isolated_bushing", "--loads", loads_csv, "--out", tmp_path / "r.xlsx"),
         "unknown format '.xlsx' for the results table"),
        (("info", "no_such_model"), "not a model file or a built-in model"),
    ):
        result = invoke(*args)
        assert result.exit_code == 2, result.output
        assert message in " ".join(result.stderr.split())


# A link on a revolute and a spherical joint at the same point: the spherical's three rows are
# redundant, and the spin about the revolute axis has neither constraint nor stiffness.
FREE_LINK = """\
# A deliberately broken model.
parts = ["link"]
[units]
length = "mm"
force = "N"
angle = "rad"
[joints.hinge]
kind = "revolute"
parts = ["link", "ground"]
at = [0, 0, 0]
[joints.ball]
kind = "spherical"
parts = ["link", "ground"]
at = [0, 0, 0]
[load_points.tip]
part = "link"
at = [100, 0, 0]
"""


@pytest.fixture(scope="module")
def free_link(tmp_path_factory):
    path = tmp_path_factory.mktemp("models") / "free_link.toml"
    path.write_text(FREE_LINK)
    return path


def test_info_on_a_file_reports_redundancy_and_free_modes(free_link):
    result = invoke("info", free_link)
    assert result.exit_code == 0, result.output
    out = result.stdout
    assert "coordinates: 6, constraint rows: 8, rank: 5, DOF: 1" in out
    assert ("redundant rows: joint 'ball' (spherical) row 0, joint 'ball' (spherical) row 1, "
            "joint 'ball' (spherical) row 2") in out
    assert "free modes: part 'link' is free: " in out
    result = invoke("info", free_link, "--json")
    info = json.loads(result.stdout)
    assert (info["dof"], info["rank"], info["constraint_rows"]) == (1, 5, 8)
    assert [j["kind"] for j in info["joints"]] == ["revolute", "spherical"]
    assert info["markers"] == 5  # hinge.i/j, ball.i/j, tip.m


def test_simulate_unsolvable_model_exits_4(free_link, loads_csv, tmp_path):
    path = tmp_path / "loads.csv"
    path.write_text("fz\n1\n")
    result = invoke("simulate", free_link, "--loads", path, "--out", tmp_path / "r.csv")
    assert result.exit_code == 4, result.output
    assert "free_link.toml:2: parts: the mechanism has modes with neither constraint" in \
        " ".join(result.stderr.split())


def test_info_builtin_json_lists_every_parameter_with_its_unit():
    result = invoke("info", "isolated_bushing", "--json")
    assert result.exit_code == 0, result.output
    info = json.loads(result.stdout)
    assert info["parts"] == ["arm"] and info["markers"] == 4
    assert (info["coordinates"], info["rank"], info["dof"]) == (6, 0, 6)
    assert info["bushings"] == ["bush"] and info["load_points"] == ["tip", "centre"]
    assert info["redundant"] == [] and info["free_modes"] == []
    params = {p["path"]: p for p in info["parameters"]}
    assert params["bushings.k_rot"] == dict(path="bushings.k_rot", shape=[1, 3],
                                            unit="N·mm/rad")
    assert params["markers.orientation"]["shape"] == [4, 3, 3]
    assert set(params) == {f"markers.{f}" for f in ("position", "orientation")} | {
        f"bushings.{f}" for f in ("k_trans", "k_rot", "cubic_trans", "cubic_rot",
                                  "offset_trans", "offset_rot", "preload_force",
                                  "preload_torque", "spline_x", "spline_y")}
    from diffsusp import load_model
    from diffsusp.model import parameter_leaves

    assert parameter_leaves(load_model("isolated_bushing")) == info["parameters"]
    text = invoke("info", "isolated_bushing")
    assert "bushings.k_trans" in text.stdout and "N/mm" in text.stdout


def test_every_parameter_leaf_has_a_unit():
    """Adding a float leaf to Mechanism must come with its unit in PARAMETER_UNITS."""
    import jax

    mech = isolated_bushing()
    paths = {jax.tree_util.keystr(p).lstrip(".")
             for p, _ in jax.tree_util.tree_leaves_with_path(mech)}
    assert paths == set(PARAMETER_UNITS)


def test_info_prints_the_computed_design_load_with_its_sign():
    """A file that states no wheel load (the Chrono strut): `info` prints the load that holds
    the design position (`kc.corner.equilibrium_load`, −11.6 kN) and what its sign means (the
    spring in tension at design), and gives its value in the JSON."""
    from diffsusp import load_model
    from diffsusp.kc.corner import equilibrium_load

    path = pathlib.Path(__file__).parent / "data" / "chrono" / "MacPhersonStrut.json"
    result = invoke("info", path)
    assert result.exit_code == 0, result.output
    text = " ".join(result.stdout.split())
    assert "design load computed: -11.6 kN" in text and "spring is in tension" in text, text
    info = json.loads(invoke("info", path, "--json").stdout)
    (corner,) = info["corners"]
    assert corner["design_load"] is None
    expected = equilibrium_load(load_model(str(path)), "contact_patch")
    assert corner["design_load_value"] == pytest.approx(expected, rel=1e-12)
    assert -11700.0 < expected < -11500.0
