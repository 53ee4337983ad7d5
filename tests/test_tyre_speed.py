"""The speed test of the bench identification (thesis §3.4.5, (3-54); `bench_speed`): on the
shipped two-speed campaign (40 and 120 km/h, tests/test_tyre_bench.py; truth the Dunlop R16
at 2 bar, Table 34, speed-independent) with the bench's noise, a speed offset term injected
on F_y is detected and recovered within 3σ, and without it no speed term is kept, over a few
noise seeds; the speed levels and the powers they can determine against an independent
computation. (A speed-dependent cornering stiffness, b_Fy_wdelta_1_1 = −15 through the
simulation model, came back at −14.92, −14.99, −15.04 ± 0.11 on three seeds; its campaign
costs 30 s to simulate, so it is not a test.)"""

import pathlib

import numpy as np
import pytest

from diffsusp.tyre import bench, bench_speed, poly

DATA = pathlib.Path(__file__).parent / "data"
C_TRUE = 0.4  # N per rad/s: an offset growing with the wheel spin, S_v = 0.4·ω₀ (3-54)
FY_DEGREES = poly.JUST_NECESSARY["Fy"]


def _campaign(seed):
    z = np.load(DATA / "tyre_flat_trac_campaign.npz")
    table = {c: np.asarray(z[c], float) for c in z.files}
    n = len(table["FY"]) // 24  # 24 segments of 1 s at 200 Hz
    table["t"] = np.tile(np.arange(n) / 200.0, 24)
    table["segment"] = np.repeat(np.arange(24, dtype=float), n)
    rng = np.random.default_rng(seed)
    table["FY"] = table["FY"] + 6.0 * rng.standard_normal(len(table["FY"]))
    table["MZ"] = table["MZ"] + 600.0 * rng.standard_normal(len(table["FY"]))
    return table


def _with_speed_term(table, c):
    out = dict(table)
    out["FY"] = table["FY"] + c * table["speed"] / 294.0  # ω₀ = V_T/R_r, V_T mm/s, R_r mm
    return out


def _speed_kept(rep):
    return {n: (x, s) for n, x, s in zip(rep.reduced.names, rep.reduced.x, rep.reduced.sigma,
                                         strict=True)
            if poly.parse_name(n)[1] in bench_speed.SPEED_BLOCKS + (bench_speed.SPEED_LY,)}


def test_speed_levels_and_powers():
    """ω₀ per run from the bench kinematics equals V_T/R_r of the table's belt speed (the
    runs at 40 and 120 km/h merged into two levels); on two levels ω₀² is a combination of 1
    and ω₀ (reported, with the reason), on three it is not; one level admits no speed term."""
    table = _campaign(0)
    cond = bench.condition(table)
    omega0, levels = bench_speed.speed_levels(cond.samples, 0.294)
    v = np.asarray(table["speed"]).reshape(24, -1)[:, 0] / 294.0
    # the table is stored in float32: 1e-7
    np.testing.assert_allclose(levels, [40 / 3.6 / 0.294, 120 / 3.6 / 0.294], rtol=2e-7)
    np.testing.assert_allclose(omega0[:, 0], v, rtol=2e-7)
    assert np.all(omega0 == omega0[:, :1])  # one level per run
    names = bench_speed.speed_columns("Fy").names
    two = bench_speed.speed_powers(names, levels)
    assert set(two) == {n for n in names if poly.parse_name(n)[2] == 2}
    assert "combination of ω₀^0..ω₀^1" in two["b_Fy_wone_2_0"]
    assert bench_speed.speed_powers(names, [40.0, 80.0, 120.0]) == {}
    assert set(bench_speed.speed_powers(names, [40.0])) == set(names)
    # within the level tolerance (2 %) two runs are one level
    s = {"omega": np.array([[100.0], [101.0], [150.0]]), "kappa": np.zeros((3, 1)),
         "delta": np.zeros((3, 1))}
    _, lv = bench_speed.speed_levels(s, 0.3)
    np.testing.assert_allclose(lv, [100.5, 150.0])


def _held(offsets: bool):
    """Table 10's F_y candidates held at 0 but the truth's (Table 34's), their relaxation
    images and, with `offsets`, every offset term b_Fy_one_1_j (the constant among them: the
    term the ω, ω² of the instantaneous spin had stood in for); the search among the others
    is tested in tests/test_tyre_bench.py, here the speed columns are at stake (a full search
    costs 5×)."""
    truth = {n for n, v in poly.PolynomialModel.from_annex_g(
        "dunlop_r16", 2.0, "Fy").values().items() if v}
    keep = truth | {f"b_Fy_Ly_{poly.parse_name(n)[2] - 1}_{poly.parse_name(n)[3]}"
                    for n in truth if "_delta_" in n}
    if offsets:
        keep |= {f"b_Fy_one_1_{j}" for j in range(4)}
    return [n for n in poly.regressor_model("Fy", FY_DEGREES, ly=True).names if n not in keep]


def test_no_speed_term_on_a_speed_independent_campaign():
    """Through `bench.identify`, on the noise draw where ω, ω² of the instantaneous spin had
    made a "significant" speed offset (the whole search kept −1.71 ± 0.03 N·s/rad with
    0.0113·ω²: the constant offset in disguise, −48.5 and −48.1 N at the two speeds): no
    speed term is kept, the note says so, ω₀² is not identifiable on two speeds (the reason
    in the row), the units of the rows, K_y within 3σ of the truth (157 381 N/m)."""
    rep = bench.identify(_campaign(7), outputs=("Fy",), speed_test=True,
                         fixed=_held(offsets=True))
    fy = rep.outputs["Fy"]
    assert _speed_kept(fy) == {}
    assert any("speed test (3-54) on 2 speed levels" in n and "no speed term is kept" in n
               for n in rep.notes), rep.notes
    assert "2 speed level" in fy.not_identifiable["b_Fy_wone_2_0"]
    rows = {r["parameter"]: r for r in fy.rows()}
    assert rows["b_Fy_wdelta_1_1"]["status"] == "not determined"
    assert rows["b_Fy_wdelta_1_1"]["unit"] == "N/(m·rad/s·kN)"
    assert rows["b_Fy_wLy_1_1"]["unit"] == "1/(rad/s·kN)"
    assert rows["b_Fy_wone_2_0"]["status"] == "not determined"
    assert "2 speed level" in rows["b_Fy_wone_2_0"]["reason"]
    assert abs(fy.stiffness - 157_381) < 3 * fy.stiffness * fy.stiffness_sigma_pct / 100


@pytest.fixture(scope="module")
def seeds():
    """Seeds 1 and 2 with the injected speed offset, seed 1 without (seed 7 without: above),
    on the true structure and the speed columns (the offsets held but Table 34's: with the
    four free, the injected offset is found as the aliased cubic of the test below on more
    draws, as the δ′⁵ term splits over F_z and F_z³ in notebook 07)."""
    out = {}
    for seed, c in ((1, 0.0), (1, C_TRUE), (2, C_TRUE)):
        cond = bench.condition(_with_speed_term(_campaign(seed), c))
        out[seed, c] = bench.identify_output(cond, "Fy", FY_DEGREES, fixed=_held(False),
                                             rolling_radius=0.294, speed_test=True)
    return out


def test_speed_offset_detected_and_recovered(seeds):
    """With S_v = 0.4·ω₀ added, the search keeps speed offset terms only, and their response
    Σ_j b_Fy_wone_1_j·F_z^j at the campaign's loads (3, 4.5, 6 kN) is 0.4 within 3σ (σ of the
    sum bounded by Σ_j F_z^j·σ_j, the final structure's σ): on these seeds the constant
    b_Fy_wone_1_0 alone, 0.4 ± 0.0025 (over seeds 10–29: 16 of 20 so, mean 0.40014, spread
    1.00 σ); on the other 4 the search kept the F_z, F_z², F_z³ terms instead, a cubic equal
    to 0.4 at the three load levels, where those powers alias. Without the offset, no speed
    term (none on those 20 seeds either, the offsets free)."""
    for (seed, c), rep in seeds.items():
        kept = _speed_kept(rep)
        if c == 0.0:
            assert kept == {}, (seed, kept)
            continue
        assert kept and all(poly.parse_name(n)[1] == "wone" for n in kept), (seed, kept)
        for fz in (3.0, 4.5, 6.0):
            v = sum(x * fz ** poly.parse_name(n)[3] for n, (x, _) in kept.items())
            s = sum(sg * fz ** poly.parse_name(n)[3] for n, (_, sg) in kept.items())
            assert abs(v - C_TRUE) < 3 * s, (seed, fz, v, s)
        if set(kept) == {"b_Fy_wone_1_0"}:
            x, s = kept["b_Fy_wone_1_0"]
            assert 100 * s / x < 2.0, (seed, x, s)
