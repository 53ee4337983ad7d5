"""The Flat Trac pipeline: conditioning, the simulation model, the two-step identification on a
synthetic campaign, its Monte-Carlo and bad input (spec: tyre §3.3–3.6, §4.1–4.3,
§7 D items 16–20)."""

import math
import pathlib

import jax.numpy as jnp
import numpy as np
import pytest
import scipy.signal

from diffsusp.errors import InputError, ModelError
from diffsusp.tyre import annex_g, bench, poly, relaxation

RNG = np.random.default_rng(1616)
K_FY = annex_g.lateral_stiffness("dunlop_r16", 2.0, "Fy")
K_MZ = annex_g.lateral_stiffness("dunlop_r16", 2.0, "Mz")


def test_filter_derivative_and_conversions():
    import jax

    x = RNG.standard_normal((2, 150)).cumsum(axis=1)
    for order in (2, 4):
        sos = bench.butterworth(25.0, 200.0, order)
        ref = scipy.signal.butter(order, 25.0 / 100.0, output="sos")
        w = np.linspace(0.01, 3.0, 30)
        np.testing.assert_allclose(np.abs(scipy.signal.sosfreqz(sos, w)[1]),
                                   np.abs(scipy.signal.sosfreqz(ref, w)[1]), atol=1e-12)
        # the conditioning's matrix form of the zero-phase filter
        F = bench.filter_matrix(25.0, 200.0, 150, order)
        np.testing.assert_allclose(x @ F.T, scipy.signal.sosfiltfilt(ref, x), atol=1e-10)
    # the scan form (long records)
    np.testing.assert_allclose(jax.jit(bench.filtfilt)(sos, x), scipy.signal.sosfiltfilt(ref, x),
                               atol=1e-10)
    t = np.arange(200) / 200.0
    d = np.asarray(bench.centred_derivative(np.sin(2 * np.pi * 6 * t), 1 / 200.0))
    np.testing.assert_allclose(d[2:-2], 2 * np.pi * 6 * np.cos(2 * np.pi * 6 * t[2:-2]),
                               rtol=0, atol=2e-4 * 2 * np.pi * 6)
    np.testing.assert_allclose(bench.difference_matrix(200, 1 / 200.0) @ np.sin(t),
                               bench.centred_derivative(np.sin(t), 1 / 200.0), rtol=1e-12)
    # (2-101…2-104) and their inverse; δ′ = −R_r·tan δ
    k, dl, ph, pb = 0.03, math.radians(2.0), 0.01, -0.02
    out = bench.deformation_from_psa(k, dl, ph, pb, rolling_radius=0.3)
    assert float(out[1]) == pytest.approx(-0.3 * math.tan(dl))
    back = bench.psa_from_deformation(*out, rolling_radius=0.3)
    np.testing.assert_allclose([float(v) for v in back], [k, dl, ph, pb], rtol=1e-12)


def test_simulation_model_first_order_relaxation():
    """A linear F_pneu = c·F_z·δ′: the state-space model (3-82…3-87) is the first-order lag
    Ḟ = (ω·K/∂F/∂δ′)(F − F_pneu), time constant |L|/ω, relaxation length R_r·|L|."""
    c, omega, fz, step = -8e4, 60.0, 4.5, -0.004
    fy = poly.PolynomialModel.create("Fy", {"delta": 1}, values={"b_Fy_delta_1_1": c})
    mz = poly.PolynomialModel.create("Mz", {"delta": 1}, values={"b_Mz_delta_1_1": -500.0})

    def inputs(s):  # a smoothed step of δ′ at 10 ms
        return {"fz": fz, "delta": step * 0.5 * (1 + jnp.tanh((s - 0.01) / 2e-4)), "phi": 0.0,
                "gamma": 0.0, "omega": omega}

    t = np.linspace(0.0, 0.2, 41)
    sim = relaxation.simulate(fy, mz, inputs, t, k_fy=K_FY, k_mz=K_MZ, rtol=1e-10, atol=1e-8)
    assert bool(sim.stable)
    tau = abs(c * fz) / (omega * K_FY)  # = |L|/ω
    later = t > 0.03
    ref = c * fz * step * (1.0 - np.exp(-(t[later] - 0.01) / tau))
    np.testing.assert_allclose(sim.fy[later], ref, rtol=2e-3, atol=0.5)
    # M_z = Mz_pneu + (K_Fy/K_Mz)(∂Mz/∂δ′)/(∂Fy/∂δ′)(F_y − Fy_pneu) (3-86, 3-87), F_x = 0
    u = {"fz": np.full(41, fz), "delta": np.asarray([inputs(s)["delta"] for s in t])}
    ref_mz = -500 * fz * u["delta"] + K_FY / K_MZ * (-500 / c) * (sim.fy - c * fz * u["delta"])
    np.testing.assert_allclose(sim.mz, ref_mz, rtol=1e-9, atol=1e-9)
    assert 0.294 * abs(c * fz) / K_FY == pytest.approx(
        float(relaxation.relaxation_length(fy, fz, K_FY)[0]))
    # beyond the grip peak: a clear error (∂Fy_pneu/∂δ′ ≥ 0)
    bad = poly.PolynomialModel.create("Fy", {"delta": 1}, values={"b_Fy_delta_1_1": 5e4})
    with pytest.raises(ModelError, match="unstable"):
        relaxation.simulate(bad, mz, inputs, t, k_fy=K_FY, k_mz=K_MZ)


SEGMENTS = bench.make_segments(
    [dict(speed=v, fz0=f, camber=g, sine_amp=1.0, sine_freq=hz, sequence=4)
     for v in (40.0, 120.0) for f in (3.0, 6.0) for g in (0.0, 1.5) for hz in (3.0, 6.0)]
    + [dict(speed=v, fz0=f, fz_amp=0.5, fz_freq=3.0, slip0=s, sequence=3)
       for v in (40.0, 120.0) for f in (4.5,) for s in (-1.0, 1.0)]
    + [dict(speed=v, fz0=f, ramp_amp=3.0, ramp_period=2.0, step_amp=1.0, step_period=1.0,
            sequence=5) for v in (40.0, 120.0) for f in (3.0, 6.0)])


def _generate_campaign():
    """How tests/data/tyre_flat_trac_campaign.npz was made (stored as float32, the time and
    segment columns rebuilt): the reduced steering-feel campaign `SEGMENTS` (slip sines, load
    sines, medium slip ramps; 2 speeds; 1 s at 200 Hz) simulated through the state-space model
    from Annex G Tables 34/46 and the G.2 stiffnesses, noise-free. Shipped because its
    simulation program costs more to compile than the tests that use it (notebook 07 runs
    the generator)."""
    fy = poly.PolynomialModel.from_annex_g("dunlop_r16", 2.0, "Fy")
    mz = poly.PolynomialModel.from_annex_g("dunlop_r16", 2.0, "Mz")
    fx = poly.PolynomialModel.create("Fx", {"one": 1}, values={"b_Fx_one_1_1": -12.0})
    return bench.synthetic_flat_trac(fy, mz, k_fy=K_FY, k_mz=K_MZ, segments=SEGMENTS,
                                     duration=1.0, rate=200.0, fx_model=fx,
                                     noise={"FY": 0.0, "MZ": 0.0, "FX": 0.0, "FZ": 0.0})


K_FY25 = annex_g.lateral_stiffness("dunlop_r16", 2.5, "Fy")
K_MZ25 = annex_g.lateral_stiffness("dunlop_r16", 2.5, "Mz")
SEGMENTS_25 = bench.make_segments(
    [dict(speed=v, fz0=f, camber=g, sine_amp=1.0, sine_freq=hz, sequence=4)
     for v in (40.0, 120.0) for f in (3.0, 4.5, 6.0) for g in (-1.5, 0.0, 1.5)
     for hz in (3.0, 6.0)]
    + [dict(speed=v, fz0=f, fz_amp=0.5, fz_freq=3.0, slip0=s, sequence=3)
       for v in (40.0, 120.0) for f in (3.0, 4.5) for s in (-1.0, 1.0)]
    + [dict(speed=v, fz0=f, camber=g, ramp_amp=3.0, ramp_period=2.0, step_amp=1.0,
            step_period=1.0, sequence=5)
       for v in (40.0, 120.0) for f, g in ((3.0, 0.0), (4.5, -1.5), (4.5, 0.0), (4.5, 1.5),
                                           (6.0, 0.0))])


def _generate_campaign_25():
    """How tests/data/tyre_flat_trac_table10.npz was made (float32, compressed; t and segment
    rebuilt): the Dunlop R16 at 2.5 bar (Tables 35/47, the closed forms (3-79), (3-81): F_y of
    degree 5 in δ′ and in φ′, the just-necessary degrees of Table 10) through the simulation
    model on `SEGMENTS_25` (slip sines at three loads and cambers, load sines, medium slip
    ramps at three loads; 40 and 120 km/h; 1 s at 200 Hz), noise-free."""
    fy = poly.PolynomialModel.from_annex_g("dunlop_r16", 2.5, "Fy")
    mz = poly.PolynomialModel.from_annex_g("dunlop_r16", 2.5, "Mz")
    fx = poly.PolynomialModel.create("Fx", {"one": 1}, values={"b_Fx_one_1_1": -12.0})
    table = bench.synthetic_flat_trac(fy, mz, k_fy=K_FY25, k_mz=K_MZ25, segments=SEGMENTS_25,
                                      duration=1.0, rate=200.0, fx_model=fx,
                                      noise={"FY": 0.0, "MZ": 0.0, "FX": 0.0, "FZ": 0.0})
    np.savez_compressed(DATA / "tyre_flat_trac_table10.npz",
                        **{c: v.astype(np.float32) for c, v in table.items()
                           if c not in ("t", "segment")})


DATA = pathlib.Path(__file__).parent / "data"


def _load(name, segments):
    z = np.load(DATA / name)
    table = {c: np.asarray(z[c], dtype=float) for c in z.files}
    n = len(table["FY"]) // segments.n
    table["t"] = np.tile(np.arange(n) / 200.0, segments.n)
    table["segment"] = np.repeat(np.arange(segments.n, dtype=float), n)
    return table


@pytest.fixture(scope="module")
def campaign():
    fy = poly.PolynomialModel.from_annex_g("dunlop_r16", 2.0, "Fy")
    mz = poly.PolynomialModel.from_annex_g("dunlop_r16", 2.0, "Mz")
    return fy, mz, _load("tyre_flat_trac_campaign.npz", SEGMENTS)


def _noisy(table, seed):
    rng = np.random.default_rng(seed)
    noisy = dict(table)
    noisy["FY"] = table["FY"] + 6.0 * rng.standard_normal(len(table["FY"]))
    noisy["MZ"] = table["MZ"] + 600.0 * rng.standard_normal(len(table["FY"]))
    return noisy


# a reduced a-priori structure: the true model's blocks and the unexcited inputs of §3.4.1
# (κ′, γ·β̇/ω) (a structure that cannot hold the truth, e.g. δ′ cubic against Table 34's δ′⁵,
# leaves a misfit that every spare column, γ·β̇/ω included, significantly reduces)
DEGREES = {"kappa": 1, "delta": 5, "phi": 1, "pi_gamma_bdot": 1, "gamma": 1, "one": 1}


def _truth(model, k, output="Fy"):
    """The true step-1 coefficients: F_pneu's, their relaxation images b_Ly_{i-1}_j =
    b_δ′_i_j / K_y (3-62, 3-71) and, for M_z, the coupling K_y⁻¹ (3-69)."""
    truth = {n: v for n, v in model.values().items() if v}
    for n, v in list(truth.items()):
        if "_delta_" in n:
            _, _, i, j = poly.parse_name(n)
            truth[f"b_{output}_Ly_{i - 1}_{j}"] = v / k
    if output == "Mz":
        truth["b_Mz_P2_0_0"] = 1.0 / k
    return truth


SEEDS = 40


@pytest.fixture(scope="module")
def monte_carlo(campaign):
    """40 noisy copies of the campaign (σ_FY = 6 N, σ_MZ = 0.6 N·m white at 200 Hz, F_z and
    F_x 3 N), one vmapped program for both outputs: per seed the two-step method on F_y, then
    on M_z with F_y's instrument, on the true structures (Tables 34/46 and their images)."""
    fy, mz, table = campaign
    return bench.monte_carlo(
        table, "Mz", poly.JUST_NECESSARY["Mz"], list(_truth(mz, K_MZ, "Mz")),
        fy_keep=list(_truth(fy, K_FY)), fy_degrees=poly.JUST_NECESSARY["Fy"],
        noise={"FY": 6.0, "FZ": 3.0, "FX": 3.0, "MZ": 600.0}, seeds=SEEDS)


@pytest.fixture(scope="module")
def monte_carlo_searched(campaign, searched):
    """24 noisy copies through the structures the search finds on the campaign (`searched`:
    F_y, then M_z with its instrument), as `bench.identify` would return them (24 seeds, a
    separate program: the spread/σ to ±15 %; measured 1.31, and 1.18 over 40 seeds)."""
    _, _, table = campaign
    return bench.monte_carlo(
        table, "Mz", poly.JUST_NECESSARY["Mz"], list(searched[1].reduced.names),
        fy_keep=list(searched[0].reduced.names), fy_degrees=poly.JUST_NECESSARY["Fy"],
        noise={"FY": 6.0, "FZ": 3.0, "FX": 3.0, "MZ": 600.0}, seeds=24)


def _check_monte_carlo(r, truth, k, step2_ratio):
    for n in truth:
        i = r["names"].index(n)
        s = np.mean(r["sigma"][:, i])
        assert 1 / 1.5 < np.std(r["x"][:, i], ddof=1) / s < 1.5, n
        assert abs(np.mean(r["x"][:, i]) - truth[n]) < 3 * s / math.sqrt(SEEDS), n
    c = r["compliance"]
    s = np.mean(r["sigma_joint"])
    assert 1 / 1.5 < np.std(c, ddof=1) / s < 1.5
    assert abs(np.mean(c) - 1 / k) < 3 * s / math.sqrt(SEEDS)
    # the thesis's step-2 σ (its one-parameter regression) understates the spread
    assert np.std(c, ddof=1) / np.mean(r["sigma_step2"]) > step2_ratio


def test_two_step_monte_carlo_fy(campaign, monte_carlo):
    """The two-step method (`bench.two_step`: instrumental variables, σ from the filtered noise
    model) on F_y recovers every coefficient and K_y within its reported σ, without bias."""
    fy, _, _ = campaign
    r = monte_carlo["fy"]
    # measured (40 seeds): spread/σ 0.89–1.06, |bias| ≤ 0.20 σ (1.24 σ/√n); K_y 0.94 and
    # 0.07 σ; the thesis's step-2 σ 1.28× too small. The least squares with the
    # white-residual σ gave spread/σ 0.3–0.5 on the slip and offset terms and a 1 σ bias of
    # φ′ and the relaxation terms (errors in variables).
    _check_monte_carlo(r, _truth(fy, K_FY), K_FY, 1.15)
    # the noise level comes back from the residual (the filter's correlations accounted for)
    assert np.mean(r["noise_sigma"]) == pytest.approx(6.0, rel=0.03)


def test_two_step_monte_carlo_mz(campaign, monte_carlo, monte_carlo_searched):
    """The same on M_z (3-63…3-71, 3-77), instrumented by F_y's predicted Ḟ_y/ω: every
    coefficient, the coupling K_y⁻¹ (−F_y·F_x, with F_x as its load polynomial (3-48)) and
    K_{Mz,y} within their reported σ."""
    _, mz, _ = campaign
    r = monte_carlo
    # measured (40 seeds): spread/σ 0.84–1.23, |bias| ≤ 0.36 σ (2.3 σ/√n); K_{Mz,y} 0.84 and
    # 0.05 σ; the step-2 σ 1.7× too small. With the raw F_x in the coupling column the
    # F_x noise (3 N) biased ten coefficients by 0.7–0.9 σ (errors in the variables).
    _check_monte_carlo(r, _truth(mz, K_MZ, "Mz"), K_MZ, 1.4)
    # M_z's own noise from its residual (0.56 N·m, 6 % low), F_y's from above the cut-off
    assert np.mean(r["noise_sigma"]) == pytest.approx(0.6, rel=0.1)
    assert np.mean(r["noise_fy"]) == pytest.approx(6.0, rel=0.1)
    # On the structure the search finds on the campaign, K_{Mz,y}'s σ is its spread too
    # (measured spread/σ 1.31 over these 24 seeds, 1.18 over 40; mean 0.31 σ (40: 0.52 σ)
    # from the truth, 0.30 σ (0.10 σ) from the noise-free estimate of the same structure;
    # σ within 1.2× from seed to seed). Before, the search kept the coupling −F_y·F_x,
    # aliased with the load polynomials (F_x ∝ F_z here), at −1.6e−4 for K⁻¹ = 5.8e−6:
    # spread/σ 0.04, K_{Mz,y} 3 % off on the noise-free data.
    a = monte_carlo_searched
    assert "b_Mz_P2_0_0" not in a["names"]
    c, s = a["compliance"], np.mean(a["sigma_joint"])
    assert 1 / 1.5 < np.std(c, ddof=1) / s < 1.5
    assert abs(np.mean(c) - 1 / K_MZ) < s
    assert np.max(a["sigma_joint"]) < 2 * np.min(a["sigma_joint"])


@pytest.fixture(scope="module")
def conditioned(campaign):
    return bench.condition(_noisy(campaign[2], 0))


def test_identify_structure_search_and_flags(campaign, conditioned):
    _, _, table = campaign
    cond = conditioned
    # the white-noise levels from the content above the cut-off (6 N, 0.6 N·m)
    assert cond.noise["FY"] == pytest.approx(6.0, rel=0.1)
    assert cond.noise["MZ"] == pytest.approx(0.6, rel=0.1)
    rep = bench.identify_output(cond, "Fy", DEGREES)
    kept = {n for n, k, f in zip(rep.fit.names, rep.fit.kept, rep.fit.fixed, strict=True)
            if k and not f}
    # the unexcited terms are gone: κ′ (free rolling: a zero column, not identifiable) and the
    # camber/slip coupling (removed by the search)
    assert not any("kappa" in n or "pi_gamma" in n for n in kept)
    assert all(n in rep.removed or n in rep.not_identifiable for n in rep.fit.names
               if "kappa" in n)
    # the excited terms of the true model survive (their load powers may move: three load
    # levels) and K_y comes back
    assert "b_Fy_phi_1_1" in kept
    for prefix in ("b_Fy_delta_1_", "b_Fy_delta_3_", "b_Fy_delta_5_", "b_Fy_gamma_1_",
                   "b_Fy_Ly_0_"):
        assert any(n.startswith(prefix) for n in kept), prefix
    assert np.all(np.isfinite(rep.reduced.sigma)) and np.all(rep.reduced.sigma > 0)
    assert rep.stiffness == pytest.approx(K_FY, rel=2e-3)
    # the structure as given (no search): κ′ is a zero column here, a clear error
    with pytest.raises(InputError, match="not identifiable on these data"):
        bench.identify_output(cond, "Fy", DEGREES, search=False)
    # bad input: each a clear error naming the fix
    with pytest.raises(InputError, match="missing channel.*FY"):
        bench.condition({k: v for k, v in table.items() if k != "FY"})
    back = dict(table)
    back["t"] = table["t"].copy()
    back["t"][5], back["t"][6] = back["t"][6], back["t"][5]
    with pytest.raises(InputError, match="not increasing"):
        bench.condition(back)
    slow = {k: v[::4] for k, v in table.items()}  # 50 Hz: 50 samples per segment
    slow["t"] = np.tile(np.arange(50) / 50.0, SEGMENTS.n)
    with pytest.raises(InputError, match="too low for the 25 Hz"):
        bench.condition(slow)
    # an identified model past its grip peak on the data is flagged, not hidden (the check
    # `identify` reports in `flags` and `stable`, the CLI's exit code 4): the campaign's F_y
    # with its sign flipped (a force growing with δ′), the structure found above
    stable, margin, flag = bench.stability(rep.model, cond.inputs)
    assert stable and margin < 0 and flag is None
    flipped = _noisy(table, 0)
    flipped["FY"] = -flipped["FY"]
    cond_flipped = bench.condition(flipped)
    names = poly.regressor_model("Fy", DEGREES, ly=True).names
    bad = bench.identify_output(cond_flipped, "Fy", DEGREES, search=False,
                                fixed=[n for n in names if n not in rep.reduced.names])
    stable, margin, flag = bench.stability(bad.model, cond_flipped.inputs)
    assert not stable and margin > 0
    assert flag.startswith("unstable identified model: dFy_pneu/ddelta' =")
    assert margin == pytest.approx(float(np.max(relaxation.stability_margin(
        bad.model, cond_flipped.inputs))))


@pytest.fixture(scope="module")
def searched(conditioned):
    """The just-necessary structure (Table 10) searched on the noisy campaign: F_y, then M_z
    with F_y's instrument (as `bench.identify` runs them)."""
    fy = bench.identify_output(conditioned, "Fy", poly.JUST_NECESSARY["Fy"])
    return fy, bench.identify_output(conditioned, "Mz", poly.JUST_NECESSARY["Mz"],
                                     fy_report=fy)


CRIT = 10.83  # χ²₁ quantile of the default significance 10⁻³


def test_structure_search_keeps_what_the_data_need(conditioned, searched):
    """The just-necessary structure (Table 10, 69 columns with the relaxation terms) searched
    on the campaign: before, the load-sign rule dropped b_Fy_delta_5_3 of an aliased
    c_{Fy,δ′,5}(F_z) (three load levels) and the white σ % then removed the true
    b_Fy_delta_5_2 and b_Fy_Ly_4_2 (σ % 10.1 and 10.6, |x|/σ ≈ 10): K_y 10 % off, the residual
    8× the noise. A removal must now pass the F-test against the noise level, on the sandwich
    σ: K_y within 0.1 % (measured 0.054 %), the residual at the noise."""
    cond = conditioned
    rep, _ = searched
    assert rep.stiffness == pytest.approx(K_FY, rel=1e-3)
    assert abs(rep.stiffness - K_FY) < 3 * rep.compliance_sigma * K_FY**2
    assert rep.noise_sigma < 1.2 * cond.noise["FY"]  # no misfit
    kept = set(rep.reduced.names)
    assert any(n.startswith("b_Fy_delta_5_") for n in kept) and "b_Fy_phi_1_1" in kept
    # every removal was insignificant, and the log says why
    assert all("F " in why for why in rep.removed.values())
    for step in rep.fit.log:  # (to round-off: near-null columns' removals change ~1e-9)
        assert step.residual_after >= step.residual_before * (1 - 1e-6)


def _check_kept_under_final_estimator(rep, threshold=10.0):
    """Every coefficient the search kept is determined by the estimator reported (`two_step`'s
    IV estimate and σ): σ % within the threshold, or significant (|x|/σ ≥ 3.3; the search's
    σ is at the noise level above the cut-off, the report's at the residual's: 10 % slack)."""
    pct = rep.reduced.sigma_pct
    stat = (rep.reduced.x / rep.reduced.sigma) ** 2
    bad = [(n, float(p), float(f)) for n, p, f in zip(rep.reduced.names, pct, stat, strict=True)
           if p > threshold and f < 0.9 * CRIT]
    assert not bad, bad
    return float(np.max(pct))


def test_structure_search_judges_the_final_estimate(conditioned, searched):
    """The search judged removals with the least-squares σ, the report gives the IV estimate
    (M_z instrumented by F_y's predicted Ḟ_y), whose σ are much larger for some terms: M_z
    kept 24 coefficients with σ % up to 268 % (b_Mz_gamma_1_3), F_y 20 up to 52 %
    (b_Fy_Ly_4_*). The rules now run again under the final estimator: M_z keeps 22 up to 18 %
    (|x|/σ 5.5), F_y 15 up to 12 %; K_{Mz,y} within its σ of the truth."""
    fy, mz = searched
    assert _check_kept_under_final_estimator(fy) < 35.0
    assert _check_kept_under_final_estimator(mz) < 35.0
    # (the second pass removed b_Mz_gamma_1_3 at 268 % when the search kept the coupling
    # −F_y·F_x below; with it held at 0 the least-squares pass leaves nothing for it here)
    assert abs(mz.compliance - 1 / K_MZ) < 3 * mz.compliance_sigma
    assert mz.noise_sigma < 1.2 * conditioned.noise["MZ"]
    # a removal an aliased column would undo takes it along (γ³ ≡ γ on constant cambers)
    assert any(why.startswith("with ") for why in mz.removed.values())
    # the campaign's cambers are 0 and +1.5°: γ² … γ⁵ are combinations of γ, and said so
    camber = {n for n, why in mz.not_identifiable.items() if "camber is held at 2 levels" in why}
    assert camber == {f"b_Mz_gamma_{i}_{j}" for i in range(2, 6) for j in range(4)}
    assert not any(n in mz.removed for n in camber)
    # the coupling −F_y·F_x (3-69): F_x is its load polynomial here (free rolling), so the
    # column is F_y·F_z·12 = a combination of the candidate δ′, φ′, γ, offset and relaxation
    # columns with one more load power (independently: 1 − R² = 4e−5 by NumPy's least
    # squares, the rest the F_y noise the column carries): held at 0 before the search (spec
    # §8.4), not kept "significant" at −1.6e−4 (truth 5.8e−6) in place of the δ′³ terms
    assert "b_Mz_P2_0_0" not in mz.reduced.names and "b_Mz_P2_0_0" not in mz.removed
    why = mz.not_identifiable["b_Mz_P2_0_0"]
    assert "not separable" in why and "§8.4" in why and "free rolling" in why
    lip = poly.regressor_model("Mz", poly.JUST_NECESSARY["Mz"], ly=True, p2=True)
    X, L, _ = (np.asarray(a) for a in bench._parts_program(lip)(conditioned.samples))
    fydot = np.asarray(conditioned.samples["fydot_w"])[..., None]
    W = np.einsum("rm,smp->srp", conditioned.operator, X + L * fydot).reshape(-1, len(lip.names))
    W = W / np.linalg.norm(W, axis=0)
    k = lip.names.index("b_Mz_P2_0_0")
    others = np.delete(W, k, axis=1)
    res = W[:, k] - others @ np.linalg.lstsq(others, W[:, k], rcond=None)[0]
    assert res @ res < 1e-3


def test_report_plot_shows_measurement_model_and_residual(campaign, conditioned, searched):
    """`OutputReport.plot(cond)`: the measured line is `cond`'s output, the model line the
    report's coefficients on `cond`'s regressor rows, the residual their difference. On the
    noisy data the residual is the noise the 25 Hz filter lets through; on the noise-free
    campaign (conditioned alike) the model line lies on the measurement (measured rms
    residual 0.90 N and 0.058 N·m; on the noisy data 8.5 N and 0.37 N·m)."""
    clean = bench.condition(campaign[2])
    for rep, unit in ((searched[0], "N"), (searched[1], "N·m")):
        noise = conditioned.noise["FY" if rep.output == "Fy" else "MZ"]
        for cond in (conditioned, clean):
            y = cond.fy if rep.output == "Fy" else cond.mz
            ax = rep.plot(cond).axes[0]
            lines = {ln.get_label(): np.asarray(ln.get_ydata()) for ln in ax.get_lines()}
            assert set(lines) == {"measured (filtered)", "model", "residual"}
            assert ax.get_ylabel() == f"{rep.output} [{unit}]"
            np.testing.assert_array_equal(lines["measured (filtered)"], y)
            np.testing.assert_allclose(lines["residual"], y - lines["model"], rtol=0,
                                       atol=1e-9 * np.max(np.abs(y)))
            rms = np.sqrt(np.mean(lines["residual"] ** 2))
            if cond is conditioned:
                # the equation error: the filtered noise, plus the noise of Ḟ_y/ω in the
                # relaxation columns (F_y: 8.5 N for 6 N of white noise), no misfit
                assert 0.5 * noise < rms < 2.0 * noise, (rep.output, rms)
            else:
                assert rms < 0.2 * noise, (rep.output, rms)


SEGMENTS_CAMBER = bench.active_safety_segments()
CAMBER_DEGREES = {"delta": 5, "phi": 5, "gamma": 3, "one": 1}
G3 = -4e5  # the γ³·F_z term added to Table 35 (N/(rad³·kN)): −32 N at 1.5°, 4.5 kN


def _generate_camber_campaign():
    """How tests/data/tyre_flat_trac_camber.npz was made (float32, compressed; t and segment
    rebuilt): the Dunlop R16 at 2.5 bar (Tables 35/47) with a γ³ term `G3` on F_y, through
    the simulation model on the active-safety sequences (`bench.active_safety_segments`: slip
    steps, camber steps ±1.5°, slip ramps with the camber ∝ slip at −0.3 and 0.5°/°; 80 km/h,
    3, 4.5, 6 kN; 1 s at 200 Hz), noise-free."""
    fy = poly.PolynomialModel.from_annex_g("dunlop_r16", 2.5, "Fy")
    values = {k: v for k, v in fy.values().items() if v} | {"b_Fy_gamma_3_1": G3}
    fy = poly.PolynomialModel.create("Fy", dict(fy.degrees) | {"gamma": 3}, values=values)
    mz = poly.PolynomialModel.from_annex_g("dunlop_r16", 2.5, "Mz")
    fx = poly.PolynomialModel.create("Fx", {"one": 1}, values={"b_Fx_one_1_1": -12.0})
    table = bench.synthetic_flat_trac(fy, mz, k_fy=K_FY25, k_mz=K_MZ25, segments=SEGMENTS_CAMBER,
                                      duration=1.0, rate=200.0, fx_model=fx,
                                      noise={"FY": 0.0, "MZ": 0.0, "FX": 0.0, "FZ": 0.0})
    np.savez_compressed(DATA / "tyre_flat_trac_camber.npz",
                        **{c: v.astype(np.float32) for c, v in table.items()
                           if c not in ("t", "segment")})


def _camber_structure(truth):
    """The true F_y terms and their relaxation images, plus γ²·F_z, γ²·F_z², γ³·F_z and
    γ³·F_z² (zero in the truth but γ³·F_z on the camber campaign): the names of
    `CAMBER_DEGREES`' model to hold at 0."""
    keep = set(truth) | {"b_Fy_gamma_2_1", "b_Fy_gamma_2_2", "b_Fy_gamma_3_1", "b_Fy_gamma_3_2"}
    names = poly.regressor_model("Fy", CAMBER_DEGREES, ly=True).names
    return [n for n in names if n not in keep]


def test_camber_varied_within_runs_determines_its_powers():
    """Spec §4.3: the steering-feel tests hold the camber at −1.5°, 0°, +1.5° (seed 001
    §3.2.3.1), where γ³ is a combination of γ and γ² (not identifiable: the Table 10 test);
    the active-safety sequences (§3.2.3.2.2–3, not used by the thesis) vary it within runs:
    on them γ² and γ³ are determined, and a γ³ term put in the data comes back (measured
    −4.20e5 ± 1.8e4 for −4e5; the spurious γ² terms within 0.5 σ of 0)."""
    fy = poly.PolynomialModel.from_annex_g("dunlop_r16", 2.5, "Fy")
    truth = _truth(fy, K_FY25) | {"b_Fy_gamma_3_1": G3}
    cond = bench.condition(_noisy(_load("tyre_flat_trac_camber.npz", SEGMENTS_CAMBER), 2))
    assert bench.camber_levels(cond.inputs["gamma"]) is None  # varied: no camber note
    rep = bench.identify_output(cond, "Fy", CAMBER_DEGREES, search=False,
                                fixed=_camber_structure(truth))
    for n in ("b_Fy_gamma_1_1", "b_Fy_gamma_2_1", "b_Fy_gamma_2_2", "b_Fy_gamma_3_1",
              "b_Fy_gamma_3_2"):
        i = rep.reduced.names.index(n)
        assert abs(rep.reduced.x[i] - truth.get(n, 0.0)) < 3 * rep.reduced.sigma[i], n
    assert rep.reduced.sigma_pct[rep.reduced.names.index("b_Fy_gamma_3_1")] < 10.0


def test_camber_powers_on_steady_and_varied_camber():
    """Steady camber levels determine as many camber powers as non-zero levels (a Vandermonde
    system); camber varied within runs determines them all (no such note)."""
    names = poly.regressor_model("Fy", {"gamma": 5, "one": 1}).names
    steady = np.radians(np.repeat([-1.5, 0.0, 1.5], 50))
    np.testing.assert_array_equal(bench.camber_levels(steady), [-1.5, 0.0, 1.5])
    why = bench.camber_powers(names, steady)
    assert set(why) == {f"b_Fy_gamma_{i}_{j}" for i in (3, 4, 5) for j in range(4)}
    assert "gamma^4 is a combination of gamma^1..gamma^2" in why["b_Fy_gamma_4_1"]
    # the Vandermonde claim itself: γ³ on these levels is a combination of γ and γ²
    G = np.stack([steady**i for i in (1, 2, 3)], axis=1)
    assert np.linalg.matrix_rank(G) == 2
    ramp = np.radians(np.linspace(-3.0, 3.0, 400))
    assert bench.camber_levels(ramp) is None and bench.camber_powers(names, ramp) == {}
    zero = bench.camber_powers(names, np.zeros(10))
    assert set(zero) == {n for n in names if "_gamma_" in n}


def test_structure_search_finds_the_table10_degrees():
    """Data generated from a model of the just-necessary degrees of Table 10 (the Dunlop R16
    at 2.5 bar, (3-79): degree 5 in δ′ and in φ′) on a steering-feel campaign with three loads
    and three cambers: the search from the a-priori structure of Table 5 (degree 7 in δ′ and
    φ′, 5 in γ, π(γ,β̇); 96 columns with the relaxation terms) plus the camber/slip coupling
    γ²·δ′ of (3-53) finds exactly the true F_pneu terms: degrees 5 in δ′ and φ′ (φ′ odd, as
    the thesis found), γ of degree 1 as the model (three camber levels could not hold more:
    γ³…γ⁵ reported as such), π(γ,β̇) and the coupling gone; K_y within its σ."""
    from diffsusp.lsq import algebra

    fy = poly.PolynomialModel.from_annex_g("dunlop_r16", 2.5, "Fy")
    table = _load("tyre_flat_trac_table10.npz", SEGMENTS_25)
    cond = bench.condition(_noisy(table, 1))
    # the thesis's camber/slip coupling test (3-53): K_δ = P_Fz1·γ² + P_Fz2, the columns
    # γ²·δ′·F_z^j searched with the others (the slip sines run at every camber level)
    g2 = algebra.LinearModel(("g2",), ("gamma",), lambda u: (u["gamma"] ** 2)[..., None])
    coupling = g2.product(algebra.monomials("delta", (1,))).product(
        algebra.monomials("fz", (1, 2, 3)))
    coupling = coupling.rename(dict(zip(coupling.names, [
        f"b_Fy_gamma2delta_1_{j}" for j in (1, 2, 3)], strict=True)))
    rep = bench.identify_output(cond, "Fy", poly.APRIORI["Fy"], extra=coupling)
    # P_Fz1 removed, as the thesis found on every tyre and pressure (§3.4.4)
    assert all(n in rep.removed and "F " in rep.removed[n] for n in coupling.names)
    truth = {n for n, v in fy.values().items() if v}
    found = {n for n, v in rep.model.values().items() if v}
    assert found == truth
    degree = {b: max((poly.parse_name(n)[2] for n in found if poly.parse_name(n)[1] == b),
                     default=0) for b in ("delta", "phi", "gamma", "pi_gamma_bdot")}
    assert degree == {"delta": 5, "phi": 5, "gamma": 1, "pi_gamma_bdot": 0}
    # three steady cambers (−1.5°, 0°, +1.5°), as the thesis's steering-feel tests (spec
    # §4.3 A): γ³ … γ⁵ are combinations of γ and γ², and the report says why
    why = {n: w for n, w in rep.not_identifiable.items() if "camber is held at 3 levels" in w}
    assert set(why) == {f"b_Fy_gamma_{i}_{j}" for i in (3, 4, 5) for j in range(4)}
    # the structure the camber-varied data determine (γ², γ³) is not identifiable here
    with pytest.raises(InputError, match="not identifiable on these data"):
        bench.identify_output(cond, "Fy", CAMBER_DEGREES, search=False,
                              fixed=_camber_structure(_truth(fy, K_FY25)))
    _check_kept_under_final_estimator(rep)
    assert not any(n in rep.removed for n in truth)
    assert abs(rep.stiffness / K_FY25 - 1) < 1e-3
    assert abs(rep.compliance - 1 / K_FY25) < 3 * rep.compliance_sigma
    assert rep.noise_sigma < 1.2 * cond.noise["FY"]
    # the recovered coefficients within 3 σ of the truth
    for n in truth:
        i = rep.reduced.names.index(n)
        assert abs(rep.reduced.x[i] - fy.values()[n]) < 3 * rep.reduced.sigma[i], n


def test_noise_growing_with_the_force_and_outliers(campaign):
    """Force rigs' noise grows with the force (σ = a + b·|F|): with σ_FY = 2 N + 1 %·|F_y| and
    the true structure, the white noise model's σ were 2.3–2.9× short of the spread of the
    δ′³, δ′⁵ terms (rms (x − truth)/σ over 40 seeds of the Table 10 campaign); the noise
    model is now estimated from the band above 60 Hz (measured a = 1.7–2.9, b = 0.0095–0.0104) and
    carried into the sandwich: rms 0.87–1.10 over 40 seeds. 2 % of
    ±20 σ spikes on F_y: the isolated ones are found and replaced (at most 2 on clean data)."""
    fy, _, table = campaign  # (the shipped 24-segment campaign: the programs of `searched`)
    truth = _truth(fy, K_FY)
    names = poly.regressor_model("Fy", poly.JUST_NECESSARY["Fy"], ly=True).names
    fixed = [n for n in names if n not in truth]
    F = table["FY"]
    z, zk = [], []
    for seed in range(6):
        rng = np.random.default_rng(seed)
        noisy = dict(table, FY=F + (2.0 + 0.01 * np.abs(F)) * rng.standard_normal(len(F)))
        cond = bench.condition(noisy)
        a, b = cond.noise_models["FY"]
        # (the intercept is the weakly determined one: |F_y| spans 0–5 kN)
        assert 1.0 < a < 3.5 and b == pytest.approx(0.01, rel=0.15)
        assert cond.outliers["FY"] <= 2  # of 4 600 samples (the intercept a is loose)
        rep = bench.identify_output(cond, "Fy", poly.JUST_NECESSARY["Fy"], search=False,
                                    fixed=fixed)
        assert rep.consistency.consistent, rep.consistency.verdict
        x = dict(zip(rep.reduced.names, zip(rep.reduced.x, rep.reduced.sigma, strict=True),
                     strict=True))
        z.append([(x[n][0] - truth[n]) / x[n][1] for n in truth])
        zk.append((rep.compliance - 1 / K_FY) / rep.compliance_sigma)
    rms = np.sqrt(np.mean(np.square(z), axis=0))
    # (on these 6 seeds the white model gives up to 2.53, overall 1.52; now up to 1.36,
    # overall 1.02 — the rms of 6 draws of N(0, 1) exceeds 1.7 with probability 1 %)
    assert np.max(rms) < 2.0, dict(zip(truth, np.round(rms, 2), strict=True))
    assert np.sqrt(np.mean(rms**2)) < 1.3
    assert np.sqrt(np.mean(np.square(zk))) < 1.5
    # outliers: 2 % of the samples ±20 σ
    rng = np.random.default_rng(11)
    hit = rng.random(len(F)) < 0.02
    noisy = dict(table, FY=F + 6.0 * rng.standard_normal(len(F))
                 + hit * rng.choice([-1.0, 1.0], len(F)) * 120.0)
    cond = bench.condition(noisy)
    inner = np.zeros(200, bool)
    inner[cond.rows[0]:cond.rows[-1] + 1] = True  # the kept rows' span (flagged: wider)
    n_hit = int(np.sum(hit.reshape(-1, 200)[:, inner]))
    assert 0.85 * n_hit <= cond.outliers["FY"] <= np.sum(hit)
    assert cond.noise["FY"] == pytest.approx(6.0, rel=0.05)
    rep = bench.identify_output(cond, "Fy", poly.JUST_NECESSARY["Fy"], search=False,
                                fixed=fixed)
    assert abs(rep.compliance - 1 / K_FY) < 3 * rep.compliance_sigma


def _statuses_of_table(text, names):
    """parameter → status from `bench.format_report`'s table (status is the last column, the
    note mark [k] after it)."""
    out = {}
    for line in text.splitlines():
        if line.startswith(("[", " ")):  # the notes below the table
            continue
        parts = line.split()
        if parts and parts[0] in names:
            cells = [p for p in parts[1:] if not p.startswith("[")]
            status = " ".join(cells[-2:]) if cells[-2:] in (["not", "determined"],
                                                            ["not", "seen"]) else cells[-1]
            out[parts[0]] = status
    return out


def test_report_table_csv_and_json_agree_on_every_status(conditioned, tmp_path):
    """The bench report (`OutputReport`, an `IdentificationReport`) rendered three ways from
    the one object — the printed table (`bench.format_report`), CSV and JSON (the CLI's
    writer, `bench.write_reports`) — gives each parameter the same status, and every status
    occurs: identified, not determined (removed by the F-test, with the reason), held (fixed by
    the user), not seen (κ′ is not excited: free rolling); the consistency verdict is printed."""
    import csv
    import json

    from diffsusp.tyre.bench import write_reports

    rep = bench.identify_output(conditioned, "Fy", DEGREES, fixed=["b_Fy_one_1_0"])
    table = bench.format_report(rep)
    write_reports(tmp_path / "r.csv", [rep])
    write_reports(tmp_path / "r.json", [rep])
    with (tmp_path / "r.csv").open() as f:
        from_csv = {r["parameter"]: r["status"] for r in csv.DictReader(f)}
    doc = json.loads((tmp_path / "r.json").read_text())
    from_json = {r["parameter"]: r["status"] for r in doc["parameters"]}
    from_table = _statuses_of_table(table, set(rep.names))
    assert from_table == from_csv == from_json
    assert set(from_csv.values()) == {"identified", "not determined", "held", "not seen"}
    assert from_csv["b_Fy_one_1_0"] == "held"
    assert all(from_csv[n] == "not seen" for n in rep.names if "kappa" in n)
    why = dict(zip(rep.names, rep.reasons, strict=True))
    assert all(why[n] for n, st in from_csv.items() if st != "identified")
    assert any(w.startswith("removed by the F-test") for w in why.values())
    assert "consistency: consistent with the data" in table
    assert doc["consistency"]["consistent"] is True
    k = rep.names.index("K_Fy_y")
    assert rep.estimates[k] == pytest.approx(K_FY / 1e3, rel=2e-3) and rep.is_identified[k]
