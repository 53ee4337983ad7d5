"""K&C-rig correlation from the command line (docs/guides/kc_rig.md): `diffsusp identify fit MODEL
--measurements rig.csv` fits rig curves — toe, camber, wheel-centre x/y/z against the loads of
each case, σ per channel — with the least-squares report and verdict of the landmark fits.

The truth is the Chrono double wishbone with `Bushing Data` with its arm bushings' stiffnesses
0.5–2× the file's and the lower arm bushing's centre (a hardpoint) moved by (1.5, −1, 2.5) mm;
its rig curves are the K&C metrics of its equilibria on the force rig (`kc.force_rig`: the tyre
force at the ground contact point) under a rig's combined-load grid (vertical 0.7 and 1.3 × the
design load, lateral ±2 kN and 0, braking ±1.5 kN), with Gaussian noise whose σ grows with
the signal (a rig's resolution, 0.001° and 0.01 mm, plus 0.5 % of the channel's change, given
per case in `sigma.<channel>` columns). The fit (every bushing stiffness and centre, the
defaults with `--centres`) starts from the file's values. Every parameter called identified is
within 3σ of the truth, the moved hardpoint among them, the verdict is consistent, and the
table, the CSV and the JSON agree on every status. Bad rig tables (unknown column, a channel
without σ, a non-finite value, σ ≤ 0, a unit of the wrong kind) exit 2 naming the file, the
line and the column, before any solve.

The two CLI fits share one compiled fit."""

import csv
import json
import pathlib

import equinox as eqx
import numpy as np
import pytest
from typer.testing import CliRunner

import diffsusp
import diffsusp.cli.identify  # noqa: F401  (registers `identify`)
from diffsusp import kc, load_model
from diffsusp.cli import app
from diffsusp.identify.report import STATUSES
from diffsusp.measure.rig import read_rig_table, write_rig_table

MODEL = pathlib.Path(__file__).parent / "data" / "DoubleWishbone_bushings.json"
TRUTH_T = np.array([[0.8, 1.3, 1.1], [1.2, 0.7, 0.9]])
TRUTH_R = np.array([[0.5, 2.0, 1.0], [1.5, 0.6, 1.0]])
MOVE = np.array([1.5, -1.0, 2.5])  # the lower arm bushing's centre (mm)
NOISE = {"toe": 0.001, "camber": 0.001, "wheel_centre_x": 0.01, "wheel_centre_y": 0.01,
         "wheel_centre_z": 0.01}  # base σ, display units (deg, mm): a rig's resolution
UNITS = {"toe": "deg", "camber": "deg", "lateral_force": "N", "vertical_force": "kN"}


@pytest.fixture(scope="module")
def rig_table(tmp_path_factory):
    start = load_model(str(MODEL))
    f0 = diffsusp.kc.design_load(start, start.corners[0])
    truth = eqx.tree_at(lambda m: (m.bushings.k_trans, m.bushings.k_rot), start,
                        (start.bushings.k_trans * TRUTH_T, start.bushings.k_rot * TRUTH_R))
    b = truth.bushings.index("lca_bushing")
    ends = np.array([truth.bushings.i_marker[b], truth.bushings.j_marker[b]])
    truth = eqx.tree_at(lambda m: m.markers.position, truth,
                        truth.markers.position.at[ends].add(MOVE))
    grid = np.array([[z, y, x] for z in (0.7 * f0, 1.3 * f0) for y in (-2000.0, 0.0, 2000.0)
                     for x in (-1500.0, 1500.0)])  # a rig's combined-load grid, 12 cases
    rig = kc.force_rig(truth)
    loads = kc.corner_loads(rig.mech, grid)
    sol = diffsusp.solve_statics(rig.mech, loads)
    rc = rig.corners[0]
    geometry = [kc.corner_geometry(rig.mech, rc, q) for q in sol.q]
    rng = np.random.default_rng(28)
    channels, sigma = {}, {}
    for name, base in NOISE.items():
        value = np.asarray([kc.display(name, g[name]) for g in geometry])
        s = base + 0.005 * np.abs(value - value.mean())  # grows with the signal
        channels[name] = value + s * rng.standard_normal(value.size)
        sigma[name] = s
    path = tmp_path_factory.mktemp("rig") / "rig.csv"
    write_rig_table(path, {"vertical_force": grid[:, 0] / 1e3, "lateral_force": grid[:, 1],
                           "longitudinal_force": grid[:, 2]}, channels, sigma, UNITS)
    return start, truth, path


def _truth_value(truth, name):
    bushing, what = name.rsplit(".", 1)
    b = truth.bushings.index(bushing)
    if what in "xyz":
        return float(truth.markers.position[truth.bushings.i_marker[b], "xyz".index(what)])
    axes = ("Ktx", "Kty", "Ktz", "Krx", "Kry", "Krz")
    a = axes.index(what)
    k = truth.bushings.k_trans if a < 3 else truth.bushings.k_rot
    return float(k[b, a % 3])


def test_rig_table_fitted_back_from_the_cli(rig_table, tmp_path):
    start, truth, path = rig_table
    table = read_rig_table(path)
    assert table.mode == "force" and table.channels == tuple(NOISE)
    f0 = diffsusp.kc.design_load(start, start.corners[0])
    np.testing.assert_allclose(np.unique(table.inputs["vertical_force"]), [0.7 * f0, 1.3 * f0],
                               rtol=1e-12)
    runner = CliRunner()
    args = ["identify", "fit", str(MODEL), "-m", str(path), "--centres"]
    out, written = tmp_path / "fit.csv", tmp_path / "identified.toml"
    first = runner.invoke(app, [*args, "--out", str(out), "--write-model", str(written)])
    assert first.exit_code == 0, first.output
    assert "K&C rig: toe, camber" in first.stdout and "12 cases" in first.stdout
    second = runner.invoke(app, [*args, "--json"])
    assert second.exit_code == 0, second.output
    data = json.loads(second.stdout)
    rows = [r for r in data["parameters"] if r["status"] != "derived"]
    from_json = {r["parameter"]: r["status"] for r in rows}
    with open(out, newline="", encoding="utf-8") as f:
        from_csv = {r["parameter"]: r["status"] for r in csv.DictReader(f)
                    if r["status"] != "derived"}
    from_table = {}
    for line in first.stdout.splitlines():
        words = line.split()
        if words and words[0] in from_json:
            from_table[words[0]] = min((line.index(s), s) for s in STATUSES if s in line)[1]
    assert from_csv == from_json == from_table, (from_csv, from_json, from_table)
    assert "consistent" in first.stdout and "NOT converged" not in first.stdout
    verdict = json.dumps(data)
    assert "inconsistent" not in verdict
    names, status = data["names"], data["status"]
    identified = [k for k, st in enumerate(status) if st == "identified"]
    assert len(identified) >= 3, dict(zip(names, status, strict=True))
    for k in identified:  # model units (N/mm, N·mm/rad, mm)
        truth_value = _truth_value(truth, names[k])
        assert abs(data["estimate"][k] - truth_value) <= 3.0 * data["sigma"][k], (
            names[k], data["estimate"][k], data["sigma"][k], truth_value)
    # the written model is the user's (not the rig's): the estimates where the data see them
    model = load_model(str(written))
    assert model.load_points.names == start.load_points.names
    for k, name in enumerate(names):
        want = data["estimate"][k] if data["identifiable"][k] else data["start"][k]
        assert _truth_value(model, name) == pytest.approx(want, rel=1e-9, abs=1e-9), name
    # the moved hardpoint: identified, and the fit moved it from the file's value to the truth
    centre = [k for k in identified if names[k].startswith("lca_bushing.")
              and names[k][-1] in "xyz"]
    assert any(abs(data["estimate"][k] - data["start"][k]) > 3.0 * data["sigma"][k]
               for k in centre), [(names[k], data["estimate"][k], data["start"][k])
                                  for k in centre]


@pytest.mark.parametrize("content, message", [
    ("# sigma: toe=0.01\nlateral_force [N],toe [deg],tow [deg]\n0,0.1,0.1\n",
     r"rig\.csv:2: tow: column 'tow' is neither a rig input"),
    ("# sigma: toe=0.01\nlateral_force [N],toe [deg],camber [deg]\n0,0.1,0.1\n",
     r"rig\.csv:2: camber: channel 'camber' has no sigma"),
    ("# sigma: toe=0.01\nlateral_force [N],toe [deg]\n0,0.1\n1000,nan\n",
     r"rig\.csv:4: toe: row 2 \(line 4\): 'nan' in column 'toe' is not a finite"),
    ("# sigma: toe=-1\nlateral_force [N],toe [deg]\n0,0.1\n",
     r"rig\.csv:1: sigma: sigma: 'toe=-1' is not name=value"),
    ("# sigma: toe=0.01\nlateral_force [m],toe [deg]\n0,0.1\n",
     r"rig\.csv:2: lateral_force: column 'lateral_force': unit 'm' is not a force unit"),
])
def test_bad_rig_tables_exit_2(tmp_path, content, message):
    import re

    path = tmp_path / "rig.csv"
    path.write_text(content)
    result = CliRunner().invoke(app, ["identify", "fit", "double_wishbone", "-m", str(path)])
    assert result.exit_code == 2, result.output
    assert re.search(message, " ".join(result.output.split())), result.output


def test_rig_table_units_inputs_and_sigma(tmp_path):
    """Reading alone: a travel table (the wheel height driven), units to the library's (deg →
    rad, N·m → N·mm, kN → N), σ from the '# sigma:' line, replaced by the option's text, or
    per case from sigma.<channel> columns; wheel_travel in a force table is a channel."""
    travel = tmp_path / "travel.csv"
    travel.write_text("# sigma: toe=0.01, half_track_change=0.05\n"
                      "wheel_travel [mm],toe [deg],half_track_change [mm]\n"
                      "-40,0.2,-3\n0,0,0\n40,-0.3,2\n")
    table = read_rig_table(travel)
    assert table.mode == "travel" and table.channels == ("toe", "half_track_change")
    np.testing.assert_allclose(table.measured[:, 0], np.radians([0.2, 0.0, -0.3]))
    np.testing.assert_allclose(table.sigma[:, 0], np.radians(0.01))
    table = read_rig_table(travel, sigma="toe=0.02,half_track_change=0.1")
    np.testing.assert_allclose(table.sigma[0], [np.radians(0.02), 0.1])
    force = tmp_path / "force.csv"
    force.write_text("aligning_torque [N·m],vertical_force [kN],wheel_travel,camber [deg],"
                     "sigma.wheel_travel,sigma.camber [deg]\n"
                     "-100,4,-1.5,0.1,0.02,0.01\n100,4,1.5,-0.1,0.04,0.02\n")
    table = read_rig_table(force)
    assert table.mode == "force" and table.channels == ("wheel_travel", "camber")
    np.testing.assert_allclose(table.inputs["aligning_torque"], [-1e5, 1e5])
    np.testing.assert_allclose(table.inputs["vertical_force"], [4000.0, 4000.0])
    np.testing.assert_allclose(table.sigma, [[0.02, np.radians(0.01)],
                                             [0.04, np.radians(0.02)]])


def test_travel_rig_table_fitted_back_from_the_cli(tmp_path):
    """A travel-rig table (parallel wheel travel, the wheel centre driven: bump steer, camber
    gain, the wheel centre's x and y against the travel) fitted end to end. The unknowns a
    suspension engineer fits from those curves are the geometry: here the control arms' inner
    pivots, the bushings' centres (`--centres`); the tie rod's ends are joints, not parameters
    of `identify fit`. The arms' stiffnesses along z ride along (`--axes Ktz`): a travel rig
    loads the bushings only with the spring's reaction, and the report says what it cannot see.
    Truth: the lower arm's pivot moved by MOVE; 9 travels −80…80 mm, noise growing with the
    signal. Measured here: the pivots' heights are identified (the lower one's z moved 2.5 mm
    from the file's value), the other coordinates and the stiffnesses not seen or not
    determined; every value called identified is within 3σ of the truth and the verdict is
    consistent."""
    start = load_model(str(MODEL))
    b = start.bushings.index("lca_bushing")
    ends = np.array([start.bushings.i_marker[b], start.bushings.j_marker[b]])
    truth = eqx.tree_at(lambda m: m.markers.position, start,
                        start.markers.position.at[ends].add(MOVE))
    from diffsusp.kc.events import event_loads

    travel = np.linspace(-80.0, 80.0, 9)
    rig = kc.travel_rig(truth)
    sol = diffsusp.solve_statics(rig.mech, event_loads(rig, travel.size, travel=travel))
    assert np.all(np.asarray(sol.status) == 0)
    rc = rig.corners[0]
    geometry = [kc.corner_geometry(rig.mech, rc, q) for q in sol.q]
    rng = np.random.default_rng(7)
    noise = {k: NOISE[k] for k in ("toe", "camber", "wheel_centre_x", "wheel_centre_y")}
    channels, sigma = {}, {}
    for name, base in noise.items():
        value = np.asarray([kc.display(name, g[name]) for g in geometry])
        s = base + 0.005 * np.abs(value - value.mean())
        channels[name] = value + s * rng.standard_normal(value.size)
        sigma[name] = s
    path = tmp_path / "travel.csv"
    write_rig_table(path, {"wheel_travel": travel}, channels, sigma, UNITS)
    assert read_rig_table(path).mode == "travel"
    r = CliRunner().invoke(app, ["identify", "fit", str(MODEL), "-m", str(path), "--centres",
                                 "--axes", "Ktz", "--json"])
    assert r.exit_code == 0, r.output
    data = json.loads(r.stdout)
    assert "inconsistent" not in json.dumps(data)
    names, status = data["names"], data["status"]
    identified = [k for k, st in enumerate(status) if st == "identified"]
    # the pivots' heights set the camber gain: the lower one's z (moved 2.5 mm) is identified;
    # the coordinates along the arms' axes are not seen (a pivot slides along its own axis)
    assert len(identified) >= 2 and "lca_bushing.z" in [names[k] for k in identified], (
        dict(zip(names, status, strict=True)))
    assert "not seen" in status
    for k in identified:
        truth_value = _truth_value(truth, names[k])
        assert abs(data["estimate"][k] - truth_value) <= 3.0 * data["sigma"][k], (
            names[k], data["estimate"][k], data["sigma"][k], truth_value)
    moved = [k for k in identified if names[k].startswith("lca_bushing.") and
             names[k][-1] in "xyz" and abs(data["estimate"][k] - data["start"][k])
             > 3.0 * data["sigma"][k]]
    assert moved, dict(zip(names, status, strict=True))
