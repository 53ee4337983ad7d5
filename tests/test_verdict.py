"""One verdict per parameter, whatever the writer: the suspension identifications (`direct`,
`iterative`, `fit`) run from the command line with their default options on a Chrono double
wishbone whose arm bushings are free in torsion (Krz = 0, as in Chrono's `Bushing Data`), from
exact poses of a truth that is not the start (each stiffness 0.5-2x the file's). Each must
converge, leave the free axes out, print a table and write CSV, JSON and HTML that agree on
every status, and write a model that carries exactly the values the report calls identified
(the others are the start model's, unchanged; least squares keeps the estimate of a parameter
the data see but do not determine). Plus the statuses and writers of a hand-built
report, and of the same report under a fit that does not reproduce its data."""

import csv
import json
import pathlib

import equinox as eqx
import jax
import numpy as np
import pytest
from helpers import table_statuses
from typer.testing import CliRunner

import diffsusp
import diffsusp.cli.identify  # noqa: F401  (registers `identify`)
from diffsusp import load_model, measure
from diffsusp.cli import app
from diffsusp.identify.report import (
    STATUSES,
    IdentificationReport,
    consistency_from_residuals,
    format_table,
)
from diffsusp.kc.corner import equilibrium_load

MODEL = pathlib.Path(__file__).parent / "data" / "DoubleWishbone_bushings.json"
AXES = ("Ktx", "Kty", "Ktz", "Krx", "Kry", "Krz")
TRUTH_T = np.array([[0.8, 1.3, 1.1], [1.2, 0.7, 0.9]])
TRUTH_R = np.array([[0.5, 2.0, 1.0], [1.5, 0.6, 1.0]])


@pytest.fixture(scope="module")
def corner(tmp_path_factory):
    start = load_model(str(MODEL))
    truth = eqx.tree_at(lambda m: (m.bushings.k_trans, m.bushings.k_rot), start,
                        (start.bushings.k_trans * TRUTH_T, start.bushings.k_rot * TRUTH_R))
    f0 = equilibrium_load(start, "contact_patch")
    force = np.array([[x, y, z] for z in (0.7 * f0, 1.3 * f0) for y in (-2000.0, 0.0, 2000.0)
                      for x in (-1500.0, 1500.0)])
    loads = truth.loads(forces={"contact_patch": force})
    sol = diffsusp.solve_statics(truth, loads)
    rot, trans = jax.vmap(lambda q: diffsusp.part_poses(truth, q))(sol.q)
    path = tmp_path_factory.mktemp("verdict") / "poses.csv"
    measure.write_measurements(measure.from_poses(truth.parts, rot, trans, loads), path, truth)
    return start, truth, path


def _stiffness(mech, name):
    bushing, axis = name.rsplit(".", 1)
    a = AXES.index(axis)
    k = (mech.bushings.k_trans if a < 3 else mech.bushings.k_rot)
    return float(k[mech.bushings.index(bushing)][a % 3])


@pytest.mark.parametrize("verb", ["direct", "iterative", "fit"])
def test_default_options_on_a_torsion_free_chrono_corner(corner, verb, tmp_path):
    start, truth, poses = corner
    runner = CliRunner()
    paths = {s: tmp_path / f"report.{s}" for s in ("csv", "html")}
    model = tmp_path / "identified.toml"
    first = runner.invoke(app, ["identify", verb, str(MODEL), "-m", str(poses), "--out",
                                str(paths["csv"]), "--write-model", str(model)])
    assert first.exit_code == 0, first.output
    second = runner.invoke(app, ["identify", verb, str(MODEL), "-m", str(poses), "--out",
                                 str(paths["html"]), "--json"])
    assert second.exit_code == 0, second.output
    with open(paths["csv"], newline="", encoding="utf-8") as f:
        rows = [r for r in csv.DictReader(f) if r["status"] != "derived"]
    names = [r["parameter"] for r in rows]
    # the free axes are left out of the default unknowns
    assert not any(n.endswith(".Krz") for n in names) and len(names) >= 10
    from_csv = {r["parameter"]: r["status"] for r in rows}
    from_json = {r["parameter"]: r["status"] for r in json.loads(second.stdout)["parameters"]
                 if r["status"] != "derived"}
    from_table = table_statuses(first.stdout, set(names))
    html = paths["html"].read_text()
    assert from_csv == from_json == from_table, (from_csv, from_json, from_table)
    # one rule for the three verbs: σ % judged at the start values
    assert json.loads(second.stdout)["judged_at"] == "the start values"
    assert all(f"<td>{n}</td><td>" in html for n in names)
    assert html.count("<tr class='identified'>") == sum(s == "identified"
                                                         for s in from_csv.values())
    assert set(from_csv.values()) <= set(STATUSES)
    assert "NOT converged" not in first.stdout
    identified = [n for n, s in from_csv.items() if s == "identified"]
    assert len(identified) >= 6
    # what is written is what is called identified: the truth (exact data), the rest unchanged
    written = load_model(str(model))
    for name in names:
        if not name.startswith(("uca_bushing", "lca_bushing")):
            continue
        if name in identified or (verb == "fit" and from_csv[name] == "not determined"):
            # least squares keeps its estimate where the data see it (documented): exact here
            assert _stiffness(written, name) == pytest.approx(_stiffness(truth, name),
                                                              rel=2e-3), name
        else:
            assert _stiffness(written, name) == _stiffness(start, name), name
    for b in ("uca_bushing", "lca_bushing"):  # free axes unchanged
        assert _stiffness(written, f"{b}.Krz") == 0.0


class _Toy(IdentificationReport):
    """A report built by hand: one parameter of each status."""

    family = "toy"
    names = ("a", "b", "c", "d", "e")
    estimates = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    sigmas = np.array([0.01, 1.5, np.inf, 0.1, 0.2])
    sigma_pct = 100 * sigmas / estimates
    estimate_units = ("N/mm",) * 5
    identifiable = np.array([True, True, False, True, True])
    held = np.array([False, False, False, True, False])
    reasons = ("", "σ% 75 > 10 at the start values", "", "", "")
    combinations = ()
    residuals = {}

    @property
    def determined(self):
        return np.array([True, False, False, True, True])


def test_statuses_writers_and_an_inconsistent_fit(tmp_path):
    toy = _Toy()
    assert toy.statuses == ("identified", "not determined", "not seen", "held", "identified")
    assert list(toy.is_identified) == [True, False, False, False, True]
    text = format_table(toy, width=60)
    assert max(len(line) for line in text.splitlines()) <= 80
    assert "[1] σ% 75 > 10 at the start values" in text
    for suffix in ("csv", "json", "html", "txt"):
        toy.write(tmp_path / f"r.{suffix}")
    rows = list(csv.DictReader((tmp_path / "r.csv").read_text(encoding="utf-8").splitlines()))
    assert [r["status"] for r in rows] == list(toy.statuses)
    data = json.loads((tmp_path / "r.json").read_text())
    assert [r["status"] for r in data["parameters"]] == list(toy.statuses)
    assert not list(tmp_path.glob(".r.*"))  # no temporary file left
    # the same parameters under a fit that does not reproduce its data: none identified, each
    # determined one says why
    bad = _Toy()
    bad.consistency = consistency_from_residuals([np.full((4, 3), 5.0)], [12], 2,
                                                 ("1", "2", "3", "4"))
    assert not bad.consistency.consistent
    assert "identified" not in bad.statuses
    assert bad.status_reasons[0].startswith("determined by the data, but the fit is "
                                            "inconsistent")
    assert not any(r["identified"] for r in bad.rows())
    assert "INCONSISTENT" in bad.fit_verdict
    with pytest.raises(ValueError, match="unknown report format"):
        toy.write(tmp_path / "r.xlsx")
