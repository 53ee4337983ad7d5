"""The median filter of the bench conditioning (thesis §1.3.3: joined to the zero-phase
low-pass against "Dirac" spikes): against an independent running median, on spikes, steps
and ramps, and reachable from `bench.condition` / `tyre identify --median`."""

import numpy as np
import pytest
from typer.testing import CliRunner

from diffsusp.cli import app
from diffsusp.errors import InputError
from diffsusp.io.tables import write_table
from diffsusp.tyre import bench


def _running_median(x, width):
    """Σ-free reference: the median of each window, the ends padded with zeros."""
    h = width // 2
    padded = np.concatenate([np.zeros(h), x, np.zeros(h)])
    return np.array([np.median(padded[i:i + width]) for i in range(x.size)])


def test_median_filter_against_a_running_median():
    rng = np.random.default_rng(0)
    t = np.arange(400) / 200.0
    clean = np.stack([1000.0 * np.sin(2 * np.pi * 1.5 * t), 50.0 * t + 3.0])  # sine, ramp
    spiky = clean.copy()
    spikes = rng.choice(np.arange(10, 390), 12, replace=False)
    spiky[0, spikes] += 5e3 * rng.choice([-1, 1], spikes.size)  # one-sample Diracs
    out = bench.median_filter({"FY": spiky, "t": np.tile(t, (2, 1))}, 5)
    for row in range(2):
        np.testing.assert_array_equal(out["FY"][row], _running_median(spiky[row], 5))
    assert out["t"] is not None and np.array_equal(out["t"], np.tile(t, (2, 1)))  # untouched
    inner = slice(5, -5)
    # spikes gone: the filtered channel is within the sine's local curvature of the clean one
    assert np.abs(out["FY"][0, inner] - clean[0, inner]).max() < 60.0
    np.testing.assert_allclose(out["FY"][1, inner], clean[1, inner], atol=1e-9)  # a ramp passes
    step = np.where(t < 1.0, 0.0, 100.0)
    np.testing.assert_array_equal(bench.median_filter({"FZ": step[None]}, 7)["FZ"][0, 3:-3],
                                  step[3:-3])  # and a step
    with pytest.raises(InputError, match="odd"):
        bench.median_filter({"FY": spiky}, 4)


def test_median_option_reaches_the_conditioning(tmp_path):
    """`condition(median=…)` and `tyre identify --median`: a window wider than the trimmed
    edge is refused with the reason (before anything compiles)."""
    m = 200
    t = np.arange(m) / 200.0
    table = {"t": t, "segment": np.zeros(m), "steer": 0.01 * np.sin(2 * np.pi * 3 * t),
             "camber": np.zeros(m), "speed": np.full(m, 2.2e4), "omega": np.full(m, 75.0),
             "FZ": np.full(m, 4.5e3), "FX": np.zeros(m), "FY": np.zeros(m), "MZ": np.zeros(m)}
    with pytest.raises(InputError, match="wider than twice the trimmed edge"):
        bench.condition(table, median=41)
    path = tmp_path / "bench.csv"
    write_table(path, table)
    r = CliRunner().invoke(app, ["tyre", "identify", str(path), "--median", "41"])
    assert r.exit_code == 2 and "trimmed edge" in " ".join(r.output.split())
