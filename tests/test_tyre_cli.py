"""`diffsusp tyre info|eval|spec|fit` (docs/reference/cli.md): the CLI equals the library, units at
the edge, exit codes for bad input."""

import json
import math

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import noisy_campaign
from typer.testing import CliRunner

from diffsusp.cli import app
from diffsusp.io.tir import read_tir
from diffsusp.tyre import MagicFormula6, MagicFormula89, evaluate, examples
from diffsusp.tyre import fit as F

DATA = examples.DATA  # the example .tir files shipped in diffsusp/tyre/data
TIR = DATA / "MagicFormula61_Paramerters.tir"


def _run(*args):
    return CliRunner().invoke(app, ["tyre", *map(str, args)])


def _text(result):
    """The output with Rich's line wrapping undone."""
    return " ".join(result.output.split())


def test_info_and_spec():
    r = _run("info", TIR, "--json")
    assert r.exit_code == 0, r.output
    out = json.loads(r.output)
    assert (out["fittyp"], out["version"], out["fnomin_N"]) == (61, "6.1", 6752.0)
    assert out["unloaded_radius_m"] == 0.393581 and out["limits"]["FZMAX"] == 18000.0
    r = _run("spec", DATA / "PacejkaBook_Defaults.tir", "--loads", "4000", "--json")
    assert r.exit_code == 0, r.output
    row = json.loads(r.output)[0]
    # book file: K_yα = p_Ky1·F_z0·sin(2·atan(F_z/(p_Ky2·F_z0))) at F_z = F_z0 = 4000 N
    np.testing.assert_allclose(row["cornering_stiffness"],
                               -15.0 * 4000 * math.sin(2 * math.atan(0.5)), rtol=1e-6)


def test_eval_table_equals_library(tmp_path):
    inp = tmp_path / "in.csv"
    inp.write_text("FZ [kN],SA [deg],SL [-],IA [deg],P [kPa],VX [km/h]\n"
                   "4.5,3,0.02,-1,240,60\n6,-5,-0.05,2,280,90\n")
    out = tmp_path / "out.csv"
    r = _run("eval", TIR, "--inputs", inp, "--out", out)
    assert r.exit_code == 0, r.output
    lines = out.read_text().splitlines()
    assert lines[0] == ("FZ [N],SL [-],SA [rad],IA [rad],P_Pa,VX_m_s,FX [N],FY [N],MX [N·m],"
                        "MY [N·m],MZ [N·m]")
    got = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])
    m = MagicFormula6.from_tir(read_tir(TIR))
    f = evaluate(m, jnp.array([4500.0, 6000.0]), jnp.array([0.02, -0.05]),
                 jnp.radians(jnp.array([3.0, -5.0])), jnp.radians(jnp.array([-1.0, 2.0])),
                 jnp.array([60e6 / 3600, 90e6 / 3600]), jnp.array([2.4e5, 2.8e5]))
    np.testing.assert_allclose(got[:, 6], f.fx, rtol=1e-14)
    np.testing.assert_allclose(got[:, 7], f.fy, rtol=1e-14)
    np.testing.assert_allclose(got[:, 10], np.asarray(f.mz) / 1000.0, rtol=1e-14)
    np.testing.assert_allclose(got[:, 5], [60 / 3.6, 90 / 3.6], rtol=1e-14)
    # beyond the file's range: warned, saturated, exit 0
    inp.write_text("FZ [N],SA [rad]\n20000,0.1\n")
    r = _run("eval", TIR, "--inputs", inp)
    assert r.exit_code == 0 and "FZMAX = 18000 [VERTICAL_FORCE_RANGE]" in _text(r)


def test_bad_inputs_exit_2(tmp_path):
    bad = tmp_path / "bad.tir"
    bad.write_text(TIR.read_text().replace("FITTYP                    \t = 61", "FITTYP = 7"))
    r = _run("info", bad)
    assert r.exit_code == 2 and "bad.tir:14: FITTYP: FITTYP = 7 is not a Magic Formula" in _text(r)
    nofz = tmp_path / "nofz.csv"
    nofz.write_text("SA [rad]\n0.1\n")
    r = _run("eval", TIR, "--inputs", nofz)
    assert r.exit_code == 2 and "no FZ column" in _text(r)
    nan = tmp_path / "nan.csv"
    nan.write_text("FZ [N],SA [rad]\n4000,0.1\n4000,nan\n")
    r = _run("eval", TIR, "--inputs", nan)
    assert r.exit_code == 2 and "nan.csv: row 2 (line 3): NaN input" in _text(r)
    assert _run("eval", TIR).exit_code == 2
    assert _run("fit", nan, "--model", "mf7").exit_code == 2
    r = _run("fit", nan, "--model", "mf52", "--start", TIR)
    assert r.exit_code == 2 and "--model mf52 but" in _text(r) and "use --model mf61" in _text(r)


def test_fit_mf1989(tmp_path):
    """`tyre fit --model mf1989` recovers the Dunlop R16 2-bar F_y set from noisy data."""
    truth = MagicFormula89.from_thesis("dunlop_r16", 2.0)
    fz = np.repeat([2000.0, 3500.0, 5000.0, 6500.0], 25)
    sa = np.tile(np.radians(np.linspace(-12, 12, 25)), 4)
    z = np.zeros(fz.size)
    d = F.BenchData(*(jnp.asarray(v) for v in (fz, z, sa, z, z, z)), jnp.zeros((1, fz.size)),
                    jnp.ones((1, fz.size), bool), ("FY",))
    fy = np.asarray(F.simulate(truth, d, noise={"FY": 15.0}, seed=4).measured[0])
    csv = tmp_path / "bench.csv"
    csv.write_text("FZ [N],SA [rad],FY [N]\n" + "".join(
        f"{float(a)!r},{float(b)!r},{float(c)!r}\n" for a, b, c in zip(fz, sa, fy, strict=True)))
    rep = tmp_path / "report.json"
    r = _run("fit", csv, "--model", "mf1989", "--report", rep, "--figures", tmp_path / "fig")
    assert r.exit_code == 0, r.output
    out = json.loads(rep.read_text())["mf1989_lateral"]
    vals = dict(zip(out["names"], out["values"], strict=True))
    sig = dict(zip(out["names"], out["sigma"], strict=True))
    for k in ("a1", "a2", "a3", "a4", "a7"):
        assert abs(vals[k] - float(truth[k])) < 3 * sig[k], k
    # coefficients without effect on this data (camber, shifts) are reported as such
    ident = dict(zip(out["names"], out["identifiable"], strict=True))
    assert not ident["a5"] and not ident["a111"]
    assert (tmp_path / "fig" / "fy_measured_vs_fitted.png").exists()


def test_rig_bad_inputs_exit_2():
    """`tyre rig` (the tyre on the K&C rig): bad input is named before anything compiles."""
    r = _run("rig", TIR, "--model", "no_such_model")
    assert r.exit_code == 2 and "neither a built-in model" in _text(r), r.output
    r = _run("rig", TIR, "--slip-angle", "a:b")
    assert r.exit_code == 2 and "not a range" in _text(r), r.output
    r = _run("rig", TIR, "--longitudinal-at", "hub")
    assert r.exit_code == 2 and "longitudinal_at must be" in _text(r), r.output
    r = _run("rig", TIR, "--fz", "-5")
    assert r.exit_code == 2 and "fz must be a positive" in _text(r), r.output


def test_identify_bad_input_and_options(tmp_path):
    """`tyre identify`: bad input exits 2 before anything compiles
    (missing channel, an unknown --structure or an out-of-range --significance: Typer
    choices); --significance and --sigma-pct reach the structure search (its removal
    reasons quote them); the report says why camber powers are not determined; the
    measured-vs-model figures are written; --aero identifies the wheel-in-the-air law and
    removes it (the report carries it); --to-mf writes the 1989 set and the torsion sets."""

    from diffsusp.io.tables import write_table

    t = np.arange(60) / 200.0
    cols = {"t": t, "segment": np.zeros(60), "steer": np.zeros(60), "camber": np.zeros(60),
            "speed": np.full(60, 2e4), "omega": np.full(60, 70.0), "FZ": np.full(60, 4e3),
            "FX": np.zeros(60), "FY": np.zeros(60)}  # no MZ
    bad = tmp_path / "bad.csv"
    write_table(bad, cols)
    r = _run("identify", bad)
    assert r.exit_code == 2 and "missing channel(s) MZ" in _text(r)
    r = _run("identify", bad, "--structure", "cubic")
    assert r.exit_code == 2 and "'cubic' is not one of" in _text(r)
    assert "'just-necessary'" in _text(r)
    r = _run("identify", bad, "--significance", "2")
    assert r.exit_code == 2 and "--significance" in _text(r)
    # the shipped noise-free campaign (tests/test_tyre_bench.py) with the bench's noise
    table, rng = noisy_campaign(7)
    # the wheel's aerodynamic force (laminar, 0.05 N per rad/s) on the bench, and the
    # wheel-in-the-air spin-down run that identifies it (--aero removes it first)
    table["FY"] = table["FY"] + 0.05 * table["omega"]
    ta = np.arange(0, 30, 0.005)
    wa = 75.0 * np.exp(-ta / 10.0)
    air = {"t": ta, "segment": np.zeros_like(ta), "omega": wa,
           "FY": 2.0 + 0.05 * wa + 0.5 * rng.standard_normal(ta.size)}
    write_table(tmp_path / "air.csv", air)
    data = tmp_path / "bench.csv"
    write_table(data, table)
    rep = tmp_path / "report.json"
    r = _run("identify", data, "--structure", "just-necessary", "--significance", "1e-4",
             "--sigma-pct", "20", "--report", rep, "--figures", tmp_path / "fig",
             "--aero", tmp_path / "air.csv", "--to-mf", tmp_path / "mf.json")
    assert r.exit_code == 0, r.output
    assert "aerodynamic FY removed: laminar law" in _text(r)
    out = json.loads(rep.read_text())
    law = out["aero"]["FY"]
    assert law["law"] == "laminar" and abs(law["laminar"] - 0.05) < 3 * law["sigma"]["laminar"]
    # --to-mf: the 1989 set, and the torsion sets of the φ′ responses (the campaign's truth is
    # the Dunlop R16 at 2 bar: linear torsion laws, stiffness within 8 % of Table 14/15's)
    mf = json.loads((tmp_path / "mf.json").read_text())
    assert mf["coefficients"]["a3"] > 0 and set(mf["torsion"]) == {"Fy", "Mz"}
    from diffsusp.tyre import thesis_sets
    for o, kind in (("Fy", "torsion_fy"), ("Mz", "torsion_mz")):
        c, ref = mf["torsion"][o]["coefficients"], thesis_sets.coefficients("dunlop_r16", 2.0,
                                                                           kind)
        ratio = (c["c4"] + 4.5 * c["c3"]) / (ref["c4"] + 4.5 * ref.get("c3", 0.0))
        assert 0.85 < ratio < 1.15, (o, ratio)
    crit = "15.1"  # χ²₁ quantile of 10⁻⁴ (10⁻³, the default: 10.8)
    for o in ("Fy", "Mz"):
        reasons = [w for w in out["outputs"][o]["removed"].values() if "sigma%" in w]
        assert reasons and all("> 20 (" in w and f"< {crit}" in w for w in reasons), reasons
    assert any("gamma^2..gamma^5 are not determined" in note and "(0°, 1.5°)" in note
               for note in out["notes"]), out["notes"]
    assert out["outputs"]["Fy"]["stiffness"] == pytest.approx(157_381, rel=2e-3)
    for o in ("fy", "mz"):
        assert (tmp_path / "fig" / f"{o}_measured_vs_model.png").exists()
