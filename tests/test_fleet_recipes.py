"""Fleet recipes and placement (docs/guides/fleets.md), in-process: K&C load tables and design
variants (a model per item, several models in one batch), Magic Formula fits of bench tables
(a start tyre per item), and a least-squares batch split over two CPU devices (jax.sharding).
Every report is checked against the library function run on the same item; the scheduling on
a cluster is test_fleet.py's.

CPU: the K&C items all have 3 cases on the force rig (one solve program and one metrics
program for the load tables and the vertical-force variants); the tyre is the 1989 set with 5
coefficients; the sharded fit is the isolated bushing's."""

import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from typer.testing import CliRunner

from diffsusp import fleet, kc, load_model, measure, save_model
from diffsusp.cli import app
from diffsusp.identify import Params, least_squares_batch
from diffsusp.measure.data import from_measurements
from diffsusp.models import isolated_bushing, pseudo_mcpherson
from diffsusp.tyre import MagicFormula89
from diffsusp.tyre import fit as F


def _report(out, item):
    return json.loads((out / "reports" / f"{item}.json").read_text())


def _metrics_equal(report, ev, rtol=1e-12):
    """The report's metrics are the event's, in display units (NaN as null)."""
    assert set(report["metrics"]) == set(ev.metrics)
    for name, v in ev.metrics.items():
        want = np.asarray(kc.display(name, v), float)
        got = np.array([np.nan if x is None else x for x in report["metrics"][name]["values"]])
        np.testing.assert_allclose(got, want, rtol=rtol, atol=1e-300, equal_nan=True,
                                   err_msg=name)


@pytest.fixture(scope="module")
def mech():
    return pseudo_mcpherson()


TABLE = np.array([[4000.0, 0.0, 0.0], [4500.0, 800.0, 0.0], [5000.0, 0.0, -600.0]])


def test_kc_load_tables(mech, tmp_path):
    """`kc` on load-table items: each report is `kc.load_table` of the table (one in kN), the
    summary holds the metrics at the first case; a table without F_long fails alone."""
    (tmp_path / "a.csv").write_text("F_vert [N],F_lat [N],F_long [N]\n" + "".join(
        ",".join(repr(float(x)) for x in r) + "\n" for r in TABLE))
    (tmp_path / "b.csv").write_text("F_vert [kN],F_lat,F_long\n" + "".join(
        f"{float(r[0]) / 1e3 + 0.5!r},{-float(r[1])!r},{float(r[2])!r}\n" for r in TABLE))
    (tmp_path / "c.csv").write_text("F_vert,F_lat\n4000,0\n")
    out = tmp_path / "out"
    result = fleet.run("kc", str(tmp_path / "*.csv"), out, model=mech)
    assert (result.ok, result.failed) == (2, 1)
    table_b = TABLE * [1.0, -1.0, 1.0] + [500.0, 0.0, 0.0]
    for item, table in (("a", TABLE), ("b", table_b)):
        ev = kc.load_table(mech, table)
        report = _report(out, item)
        _metrics_equal(report, ev)
        assert report["status"] == [0, 0, 0] and report["x"]["values"] == [1.0, 2.0, 3.0]
        np.testing.assert_allclose(report["compliance_matrix"]["values"]["corner"],
                                   np.asarray(ev.compliance[""]), rtol=1e-12)
    rows = (out / "summary.csv").read_text().splitlines()
    head = rows[0].split(",")
    row_a = dict(zip(head, rows[1].split(","), strict=True))
    toe = float(np.asarray(kc.display("toe", kc.load_table(mech, TABLE).metrics["toe"]))[0])
    assert float(row_a["toe"]) == toe
    failure = fleet.status(out).failures[0]
    assert failure[:2] == ("c", "error") and "no column F_LONG" in failure[2]
    # The command line: `diffsusp fleet kc --items TABLE --out DIR --model NAME`.
    cli = CliRunner().invoke(app, ["fleet", "kc", "--items", str(tmp_path / "a.csv"), "--out",
                                   str(tmp_path / "cli"), "--model", "pseudo_mcpherson",
                                   "--json"])
    assert cli.exit_code == 0, cli.output
    assert json.loads(cli.stdout)["ok"] == 1
    _metrics_equal(_report(tmp_path / "cli", "a"), kc.load_table(mech, TABLE))


def test_kc_design_variants(mech, tmp_path):
    """`kc` with a named event: every item is a model file (a design variant). Two variants of
    one structure (bushing A's stiffness ×0.5 and ×2) share a batch; each report is the event
    run on that model; a model file that does not load fails alone; a re-run skips the done
    variants, and a changed variant file is the only one run again."""
    variants = tmp_path / "variants"
    variants.mkdir()
    for name, scale in (("soft", 0.5), ("stiff", 2.0)):
        m = eqx.tree_at(lambda x: x.bushings.k_trans, mech,
                        mech.bushings.k_trans.at[0].multiply(scale))
        save_model(m, variants / f"{name}.toml")
    (variants / "broken.toml").write_text("[units]\nlength = 'furlong'\n")
    out = tmp_path / "out"
    options = {"event": "vertical-force", "fz": "3000:5000:3"}
    result = fleet.run("kc", str(variants / "*.toml"), out, options=options)
    assert (result.ok, result.failed, result.batches) == (2, 1, 1)
    toes = {}
    for name in ("soft", "stiff"):
        ev = kc.vertical_force(load_model(variants / f"{name}.toml"), [3000.0, 4000.0, 5000.0])
        _metrics_equal(_report(out, name), ev)
        toes[name] = _report(out, name)["metrics"]["toe"]["values"]
    assert toes["soft"] != toes["stiff"]
    failures = {item: (status, msg) for item, status, msg in fleet.status(out).failures}
    assert failures["broken"][0] == "error" and "the item's model" in failures["broken"][1]
    again = fleet.run("kc", str(variants / "*.toml"), out, options=options)
    assert (again.skipped, again.batches) == (3, 0)
    m = eqx.tree_at(lambda x: x.bushings.k_trans, mech, mech.bushings.k_trans.at[1].multiply(3.0))
    save_model(m, variants / "stiff.toml")
    changed = fleet.run("kc", str(variants / "*.toml"), out, options=options)
    assert (changed.skipped, changed.ok) == (2, 1)
    _metrics_equal(_report(out, "stiff"),
                   kc.vertical_force(load_model(variants / "stiff.toml"),
                                     [3000.0, 4000.0, 5000.0]))


def test_tyre_fits(tmp_path):
    """`tyre_fit` on bench tables of the thesis's Dunlop R16 at three pressures (1989 set,
    noisy F_y) from one start tyre, and a fourth item with its own start tyre, all in one
    batch: the reports are `tyre.fit.fit_many` of the same tables and starts; a table without
    F_y fails alone."""
    names = ["a1", "a2", "a3", "a4", "a7"]
    fz = np.repeat([2000.0, 3500.0, 5000.0, 6500.0], 13)
    sa = np.tile(np.radians(np.linspace(-12.0, 12.0, 13)), 4)
    z = np.zeros(fz.size)
    inputs = F.BenchData(*(jnp.asarray(v) for v in (fz, z, sa, z, z, z)),
                         jnp.zeros((1, fz.size)), jnp.ones((1, fz.size), bool), ("FY",))
    for k, p in enumerate((2.0, 2.5, 3.0)):
        truth = MagicFormula89.from_thesis("dunlop_r16", p)
        fy = np.asarray(F.simulate(truth, inputs, noise={"FY": 20.0}, seed=k).measured[0])
        (tmp_path / f"p{k}.csv").write_text("FZ [N],SA [rad],FY [N]\n" + "".join(
            f"{a!r},{b!r},{c!r}\n" for a, b, c in zip(fz.tolist(), sa.tolist(), fy.tolist(),
                                                       strict=True)))
    (tmp_path / "text.csv").write_text("FZ [N],SA [rad],FY [N]\n4000,abc,10\n")
    base = {k: float(v) for k, v in MagicFormula89.from_thesis("dunlop_r16", 2.5)
            .coefficients.items()}
    start = MagicFormula89.from_values({**base, "a1": -10.0, "a2": 1300.0, "a3": 2200.0,
                                        "a4": 9.0, "a7": 0.45})
    own = MagicFormula89.from_values({**base, "a3": 1900.0})
    items = [*sorted(tmp_path.glob("*.csv")), fleet.Item("own", path=str(tmp_path / "p0.csv"),
                                                         model=own)]
    options = {"names": names, "noise": {"FY": 20.0}, "combined": False}
    out = tmp_path / "out"
    result = fleet.run("tyre_fit", items, out, model=start, options=options, batch_size=4)
    datas = [F.read_bench(tmp_path / f"p{k}.csv") for k in (0, 1, 2, 0)]
    _, reports = F.fit_many([start, start, start, own], datas, names, noise={"FY": 20.0},
                            combined=False)
    # a fit whose optimiser did not converge is a failure with its report, never "ok"
    stuck = sum(not r.converged for r in reports)
    assert (result.ok, result.failed, result.batches) == (4 - stuck, 1 + stuck, 2)
    for item, ref in zip(("p0", "p1", "p2", "own"), reports, strict=True):
        got = _report(out, item)
        assert got["warnings"] == [] and got["fit"]["names"] == names
        assert got["fit"]["start"] != got["fit"]["values"]
        for key in ("values", "sigma", "identifiable", "converged", "steps"):
            np.testing.assert_allclose(got["fit"][key], ref.to_dict()[key], rtol=1e-12,
                                       err_msg=f"{item} {key}")
    failures = fleet.status(out).failures
    assert [f[1] for f in failures].count("not converged") == stuck
    text = next(f for f in failures if f[0] == "text")
    assert text[1] == "error" and "text.csv:2" in text[2]


def test_batch_split_over_two_devices(tmp_path):
    """A least-squares batch on the test process's two CPU devices (`devices=2`: the data
    sets' axis placed with a NamedSharding) gives the reports of the same batch on one device
    (1e-12), which are `least_squares_batch` of the stacked data sets."""
    assert jax.local_device_count() >= 2  # tests/conftest.py: jax_num_cpu_devices = 2
    mech = isolated_bushing()
    loads = mech.loads(forces={"tip": np.array([[30.0, -20.0, 50.0], [-12.0, 8.0, 4.0],
                                                [6.0, 3.0, -9.0]])},
                       moments={"tip": np.array([[2e4, -1e4, 3e4], [-5e3, 1e4, 2e3],
                                                 [3e3, 4e3, -6e3]])})
    exact = measure.synthesize(mech, loads, layout=measure.place_landmarks(mech, seed=1))
    items = [fleet.Item(f"draw{s}", data=measure.add_noise(
        exact, measure.GaussianNoise(landmarks=0.05), jax.random.PRNGKey(s))) for s in range(3)]
    options = {"axes": ["Ktx", "Kty", "Ktz"], "max_steps": 15, "sigma": 0.05}
    one = fleet.run("least_squares", items, tmp_path / "one", model=mech, options=options,
                    batch_size=4, devices=1)
    two = fleet.run("least_squares", items, tmp_path / "two", model=mech, options=options,
                    batch_size=4, devices=2)
    assert one.ok == two.ok == 3
    data = [from_measurements(it.data, 0.05, 0.01 * np.pi / 180) for it in items]
    stacked = eqx.tree_at(lambda x: tuple(getattr(x, f) for f in x.value_fields), data[0],
                          tuple(jnp.stack([getattr(d, f) for d in [*data, data[-1]]])
                                for f in data[0].value_fields))
    ref = least_squares_batch(mech, stacked, Params.bushing_stiffness(
        mech, None, ["Ktx", "Kty", "Ktz"]), max_steps=15)
    for k, it in enumerate(items):
        a, b = _report(tmp_path / "one", it.name), _report(tmp_path / "two", it.name)
        for key in ("estimate", "sigma"):
            np.testing.assert_allclose(b[key], a[key], rtol=1e-12, err_msg=key)
            np.testing.assert_allclose(a[key], np.asarray(getattr(ref.reports[k], key)),
                                       rtol=1e-12, err_msg=key)
