"""The contact compliances by the two-step method (spec tyre §1.5, §3.3, Table 7): K_x on the
F_x output model recovered from a campaign of `bench.compliant_flat_trac` (three
finite-rotation joints under a Magic-Formula-shaped law: not the model the identification
linearises), noise-free and on a few noisy draws against the σ it claims (the full
Monte-Carlo is `benchmarks/tyre_compliance.py`), and the report as the other bench reports."""

import json

import numpy as np
import pytest

from diffsusp.errors import InputError
from diffsusp.tyre import bench

TRUTH = np.array([1 / 3.0e5, 1 / 1.6e5, 1 / 1.3e4])
SEGMENTS = dict(speeds=(40.0,), loads=(3.0, 6.0))


@pytest.fixture(scope="module")
def runs():
    seg = bench.compliance_segments(**SEGMENTS)
    out = {}
    for seed in (0, 1, 2, 3):
        noise = dict(FY=0.0, MZ=0.0, FX=0.0, FZ=0.0) if seed == 0 else None
        tab = bench.compliant_flat_trac(segments=seg, seed=seed, noise=noise, duration=1.5)
        out[seed] = bench.identify_compliances(tab, outputs=("Fx",))
    return out


def test_kx_noise_free_recovery(runs):
    r = runs[0].outputs["Fx"]
    c = np.asarray(r.compliance)
    np.testing.assert_allclose(c[0], TRUTH[0], rtol=5e-3)  # K_x
    np.testing.assert_allclose(c[1], TRUTH[1], rtol=5e-2)  # K_y seen on F_x
    assert runs[0].table7()["Fx"]["x"] is not None


def test_kx_noisy_draws_within_their_sigma(runs):
    z = []
    for seed in (1, 2, 3):
        r = runs[seed].outputs["Fx"]
        c, s = float(r.compliance[0]), float(r.compliance_sigma[0])
        assert np.isfinite(s) and 0 < s < 0.2 * TRUTH[0]
        z.append((c - TRUTH[0]) / s)
    assert np.all(np.abs(z) < 4.0), z


def test_report_is_the_shared_report(runs):
    rep = runs[1]
    names = rep.names
    assert {"K_Fx_x", "K_Fx_y", "K_Fx_beta"} <= set(names)
    i = names.index("K_Fx_x")
    assert rep.estimate_units[i] == "N/mm"
    np.testing.assert_allclose(rep.estimates[i], 1e-3 / rep.outputs["Fx"].compliance[0])
    doc = json.loads(bench.ReportSet([rep]).to_json())
    assert "table7" in doc and doc["parameters"][i]["parameter"] == "K_Fx_x"
    assert "contact compliances" in rep.table()
    assert len(rep.rows()) == len(names)


def test_free_rolling_locks_the_longitudinal_joint():
    t = np.arange(200) / 200.0
    v, r = 11111.0, 0.294
    cols = {"speed": np.full(200, v), "steer": 0.01 * np.sin(t), "omega":
            v * 1e-3 * np.cos(0.01 * np.sin(t)) / r}
    assert "x" in bench.locked_joints(cols, r)
    cols["omega"] = cols["omega"] * (1 + 0.01 * np.sin(20 * t))
    assert bench.locked_joints(cols, r) == {}


def test_bad_arguments():
    with pytest.raises(InputError, match="outputs"):
        bench.identify_compliances({}, outputs=("Fq",))
    with pytest.raises(InputError, match="locked"):
        bench.identify_compliances({}, locked={"z": "?"})
