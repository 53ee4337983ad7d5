"""The median filter of the bench conditioning (thesis §1.3.3: joined to the zero-phase
low-pass against "Dirac" spikes), used as a spike detector: against an independent running
median on spikes, steps and smooth signals, and through the bench identification, where spikes
on every channel would otherwise bias K_y."""

import numpy as np
import pytest
from helpers import noisy_campaign
from typer.testing import CliRunner

from diffsusp.cli import app
from diffsusp.errors import InputError
from diffsusp.io.tables import write_table
from diffsusp.tyre import bench


def test_spikes_replaced_by_the_window_median():
    """One-sample spikes become the median of their window's other samples; every other
    sample, a smooth sine with its noise, a ramp and a step, is kept as measured."""
    rng = np.random.default_rng(0)
    t = np.arange(400) / 200.0
    clean = np.stack([1000.0 * np.sin(2 * np.pi * 1.5 * t) + rng.normal(0, 5.0, t.size),
                      50.0 * t + 3.0, np.where(t < 1.0, 0.0, 100.0)])
    spiky = clean.copy()
    spikes = rng.choice(np.arange(10, 390), 12, replace=False)
    spiky[0, spikes] += 5e3 * rng.choice([-1, 1], spikes.size)
    out = bench.median_filter({"FY": spiky, "t": np.tile(t, (3, 1))}, 5)
    others = np.stack([np.median(np.r_[spiky[0, i - 2:i], spiky[0, i + 1:i + 3]])
                       for i in spikes])
    np.testing.assert_array_equal(out["FY"][0, spikes], others)
    assert np.abs(out["FY"][0, spikes] - clean[0, spikes]).max() < 30.0  # back on the sine
    keep = np.ones(t.size, bool)
    keep[spikes] = False
    np.testing.assert_array_equal(out["FY"][0, keep], spiky[0, keep])
    np.testing.assert_array_equal(out["FY"][1:], clean[1:])  # a ramp and a step pass
    np.testing.assert_array_equal(out["t"], np.tile(t, (3, 1)))  # time is not filtered
    with pytest.raises(InputError, match="odd"):
        bench.median_filter({"FY": spiky}, 4)


@pytest.fixture(scope="module")
def spiky_campaign():
    """The shipped noise-free steering-feel campaign (tests/test_tyre_bench.py) with bench
    noise, and 1 % of the samples of F_y, M_z, the steer angle and F_z hit by spikes."""
    table, rng = noisy_campaign(3)
    n = len(table["FY"])
    for c, amp in (("FY", 3000.0), ("MZ", 3e5), ("steer", 0.02), ("FZ", 2000.0)):
        idx = rng.choice(n, n // 100, replace=False)
        table[c][idx] += amp * rng.choice([-1, 1], idx.size)
    return table


def test_spikes_removed_before_the_identification(spiky_campaign):
    """K_y on F_y (truth 157 381 N/m, the Dunlop R16 at 2 bar) within 3σ once the spikes are
    removed, and the noise estimate back near the 6 N injected."""
    rep = bench.identify(spiky_campaign, outputs=("Fy",), median=5).outputs["Fy"]
    assert abs(rep.stiffness - 157_381) < 3 * rep.stiffness * rep.stiffness_sigma_pct / 100
    assert rep.noise_sigma < 40.0
    with pytest.raises(InputError, match="wider than twice the trimmed edge"):
        bench.condition(spiky_campaign, median=41)


def test_cli_median_option(tmp_path):
    """`tyre identify --median` reaches the conditioning: a window wider than the trimmed edge
    is refused with the reason, before anything compiles."""
    m = 200
    t = np.arange(m) / 200.0
    table = {"t": t, "segment": np.zeros(m), "steer": 0.01 * np.sin(2 * np.pi * 3 * t),
             "camber": np.zeros(m), "speed": np.full(m, 2.2e4), "omega": np.full(m, 75.0),
             "FZ": np.full(m, 4.5e3), "FX": np.zeros(m), "FY": np.zeros(m), "MZ": np.zeros(m)}
    path = tmp_path / "bench.csv"
    write_table(path, table)
    r = CliRunner().invoke(app, ["tyre", "identify", str(path), "--median", "41"])
    assert r.exit_code == 2 and "trimmed edge" in " ".join(r.output.split())
