# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 07 — Tyre identification on the bench: polynomial models, relaxation, Magic Formula
#
# The thesis's chapter 3 (spec: tyre §3–4): a polynomial model of F_y and M_z, linear in its
# parameters, in the deformations seen by the contact patch (δ′, φ′, γ) and the load; the
# lateral ("ballant") stiffness of the patch that makes the force relax; the two-step
# identification on a Flat Trac; the conversion to the Magic Formula.
#
# - Annex G as data: a thesis polynomial evaluated, its extrema and relaxation length;
# - the state-space simulation model (3-82…3-87) integrated with diffrax on a synthetic
#   steering-feel campaign (slip sines, load sines, medium slip ramps);
# - the two-step identification of the polynomial and K_y from the noisy synthetic data;
# - step 1 of the polynomial → Magic Formula conversion (closed forms);
# - the thesis's behaviour rules on its 24 published models, the torsion Magic Formula sets
#   from the φ′ response, and the wheel-in-the-air aerodynamic force.
#
# Units of the polynomial models: F_z kN, δ′ m, φ′ and γ rad, F_y N, M_z N·m.

# %%
import jax

jax.config.update("jax_enable_x64", True)
import matplotlib.pyplot as plt
import numpy as np

from diffsusp.tyre import annex_g, bench, convert, mf89, poly, relaxation

# %% [markdown]
# ## Annex G: the Dunlop R16 at 2 bar (Tables 34 and 46)
# Every printed cell is shipped with its status ("0": removed by the algorithm, "*": forced to
# 0 by the author, "/": not in the model). The F_y polynomial has no real extremum at 4.5 kN;
# the M_z one has its maximum at δ′ ≈ 12.19 mm and its minimum at ≈ −14.38 mm.

# %%
fy = poly.PolynomialModel.from_annex_g("dunlop_r16", 2.0, "Fy")
mz = poly.PolynomialModel.from_annex_g("dunlop_r16", 2.0, "Mz")
print({k: v for k, v in fy.values().items() if v})
print("F_y extrema at 4.5 kN:", fy.extrema(4.5))
print("M_z extrema at 4.5 kN:", [(round(1e3 * x, 2), round(y, 1), k)
                                 for x, y, k in mz.extrema(4.5, lo=-0.03, hi=0.03)])
k_fy = annex_g.lateral_stiffness("dunlop_r16", 2.0, "Fy")
k_mz = annex_g.lateral_stiffness("dunlop_r16", 2.0, "Mz")
print(f"K_y on F_y {k_fy:.0f} N/m (Table 11: 157 375), on M_z {k_mz:.0f} N/m (171 510)")
print("relaxation lengths at 4.5 kN [m]:",
      {t: [round(annex_g.relaxation_length(t, p), 2) for p in (2.0, 2.5, 3.0)]
       for t in annex_g.TYRES})
print(f"lateral mode of a 2 kg belt on 150 kN/m: "
      f"{relaxation.lateral_mode_frequency(150e3, 2.0):.1f} Hz (thesis: 43 Hz)")

dp = np.linspace(-0.02, 0.02, 81)
fig, axes = plt.subplots(1, 2, figsize=(10, 3.5))
for f in (3.0, 4.5, 6.0):
    u = {"fz": np.full_like(dp, f), "delta": dp}
    axes[0].plot(1e3 * dp, fy(u), label=f"{f} kN")
    axes[1].plot(1e3 * dp, mz(u), label=f"{f} kN")
axes[0].set(xlabel="δ′ [mm]", ylabel="F_y [N]")
axes[1].set(xlabel="δ′ [mm]", ylabel="M_z [N·m]")
axes[0].legend()
fig.tight_layout()

# %% [markdown]
# ## A synthetic Flat Trac campaign through the simulation model
# Slip sines ±1° at 3 and 6 Hz, load sines ±0.5 kN, medium slip ramps to ±4°, at 40 and
# 120 km/h, sampled at 200 Hz, white noise of 6 N on F_y and 0.6 N·m on M_z.

# %%
segments = bench.make_segments(
    [dict(speed=v, fz0=f, camber=g, sine_amp=1.0, sine_freq=hz, sequence=4)
     for v in (40.0, 120.0) for f in (3.0, 6.0) for g in (0.0, 1.5) for hz in (3.0, 6.0)]
    + [dict(speed=v, fz0=4.5, fz_amp=0.5, fz_freq=3.0, slip0=s, sequence=3)
       for v in (40.0, 120.0) for s in (-1.0, 1.0)]
    + [dict(speed=v, fz0=f, ramp_amp=3.0, ramp_period=2.0, step_amp=1.0, step_period=1.0,
            sequence=5) for v in (40.0, 120.0) for f in (3.0, 6.0)])
fx = poly.PolynomialModel.create("Fx", {"one": 1}, values={"b_Fx_one_1_1": -12.0})
table = bench.synthetic_flat_trac(fy, mz, k_fy=k_fy, k_mz=k_mz, segments=segments,
                                  duration=1.0, rate=200.0, fx_model=fx,
                                  noise={"FY": 6.0, "MZ": 600.0, "FX": 3.0, "FZ": 3.0})
n = 200
fig, ax = plt.subplots(figsize=(10, 3))
for s in (0, 20):  # a 3 Hz slip sine at 40 km/h and a medium slip ramp
    sl = slice(s * n, (s + 1) * n)
    ax.plot(table["t"][sl], table["FY"][sl], lw=0.8, label=f"segment {s}")
ax.set(xlabel="t [s]", ylabel="F_y [N]")
ax.legend()

# %% [markdown]
# ## Two-step identification (just-necessary structure, Table 10)
# Conditioning: zero-phase 25 Hz Butterworth, five-point centred differences for Ḟ_y, the
# deformation inputs from the bench kinematics, the regressor filtered in parallel with the
# output (Ḟ_y differenced from the raw F_y inside the filtered relaxation columns). To keep
# the notebook short the structure is given (`bench.identify` or `diffsusp tyre identify` run
# the search: a coefficient with σ % > 10 % is removed unless its removal raises the residual
# beyond the noise — an F-test on the noise-model σ at the noise level measured above the
# cut-off — then the behaviour rules under the same test, and the same rules again under the
# final (instrumental-variable) estimate, so every kept term has σ % ≤ 10 % or is significant
# under the σ reported; on this campaign it gets K_y within 0.06 %, and from the a-priori
# degrees of Table 5 it finds Table 10's degree 5 in δ′ and φ′ on data made from (3-79):
# tests/test_tyre_bench.py). The cambers here are steady (0 and +1.5°, as the thesis's
# steering-feel tests hold −1.5°, 0°, +1.5°): the report lists γ² … γ⁵ as not identifiable,
# combinations of γ on these data. The other 54 coefficients of Table 10's structure are held
# at 0. The estimate is an instrumental-variable one (Ḟ_y comes
# from the noisy F_y: errors in the variables) and its σ come from the noise model of the
# filtered data (the white-residual σ were twice the spread of the slip terms): a Monte-Carlo
# over 40 seeds puts the spread within 0.89–1.06 σ on F_y and 0.84–1.23 σ on M_z
# (tests/test_tyre_bench.py).

# %%
found = ["b_Fy_delta_1_1", "b_Fy_delta_1_3", "b_Fy_delta_3_1", "b_Fy_delta_5_1",
         "b_Fy_delta_5_3", "b_Fy_phi_1_1", "b_Fy_gamma_1_2", "b_Fy_gamma_1_3", "b_Fy_one_1_1",
         "b_Fy_Ly_0_2", "b_Fy_Ly_0_3", "b_Fy_Ly_2_1", "b_Fy_Ly_2_2", "b_Fy_Ly_2_3",
         "b_Fy_Ly_4_2"]
cond = bench.condition(table)
names = poly.regressor_model("Fy", poly.JUST_NECESSARY["Fy"], ly=True).names
res = bench.identify_output(cond, "Fy", poly.JUST_NECESSARY["Fy"], search=False,
                            fixed=[n for n in names if n not in found])
print(f"K_y on F_y: {res.stiffness:.0f} N/m (truth {k_fy:.0f}), σ {res.stiffness_sigma_pct:.3g} %"
      f" (the thesis's step-2 σ: {100 * res.compliance_sigma_step2 / res.compliance:.3g} %)")
print(f"noise on F_y: {res.noise_sigma:.2f} N from the residual, {cond.noise['FY']:.2f} N above "
      "the cut-off (6 N injected)")
for name in ("b_Fy_delta_1_1", "b_Fy_delta_1_3", "b_Fy_delta_3_1", "b_Fy_phi_1_1",
             "b_Fy_one_1_1"):  # the δ′⁵ term appears split over F_z and F_z³ (two loads)
    i = res.reduced.names.index(name)
    print(f"{name:16s} {res.reduced.x[i]: .5g} ± {res.reduced.sigma[i]:.2g} "
          f"(truth {fy.values()[name]: .5g})")

# %% [markdown]
# ## Polynomial → Magic Formula, step 1
# The slip stiffness converted with a radius of 0.33 m (the thesis's tables match 0.32–0.35 m, not
# R_r = 0.294 m), (a3, a4) by total least
# squares; the F_y polynomial has no extremum (C = 1 sets are monotone), so D comes from the
# value at the domain's edge. Step 2 (`convert.refine`) refines them with the MF fitter.

# %%
start, notes = convert.step1(fy, mz, loads=(3.0, 4.5, 6.0), radius=0.33)
print(notes)
print({k: round(float(start[k]), 4) for k in ("a1", "a2", "a3", "a4", "c1", "c2", "c3", "c4",
                                               "c12", "c13")})
d = np.linspace(-4, 4, 81)
fig, ax = plt.subplots(figsize=(6, 3.5))
u = {"fz": np.full_like(d, 4.5), "delta": convert.deg_to_dp(d, 0.33)}
ax.plot(d, fy(u) - fy({"fz": np.array([4.5])})[0], "k-", label="polynomial (offset removed)")
ax.plot(d, mf89.fy0(start, d, 4.5), "b--", label="MF step 1")
ax.set(xlabel="δ [deg]", ylabel="F_y [N]")
ax.legend()

# %% [markdown]
# ## The thesis's behaviour rules on its 24 published models
# The structure search's rules as the thesis states them (§3.3.2.1.1): each Table 6 feature
# (one zero of F(δ′) near δ = 0, one maximum, one minimum) counted in its own domain, and no
# deformation load polynomial changing sign over the loads (the camber and offset polynomials
# may: every published M_z offset crosses zero, Table 46's at 1.86 kN). Every Annex G model
# passes; the M_z models show their maximum and minimum where Table 6 expects them.

# %%
from diffsusp.tyre import aero, thesis_sets

flagged = [(o, t, p) for o in ("Fy", "Mz") for t in thesis_sets.TYRES
           for p in thesis_sets.PRESSURES
           if bench.behaviour_rules(o, (1.5, 6.0))(annex_g.coefficients(t, p, o)) is not None]
print("Annex G models flagged by the rules:", flagged or "none of 24")
for o in ("Fy", "Mz"):
    print(o, "Dunlop R16 2.5 bar, features at 4.5 kN:",
          bench.table6_features(o, annex_g.coefficients("dunlop_r16", 2.5, o), 4.5))

# %% [markdown]
# ## Torsion Magic Formula sets from the φ′ response
# `convert.torsion_set` applies the step-1 closed forms to P_{F,φ′}: the torsion stiffness,
# and the peak where the response has extrema inside the ±0.85° ramp of §3.5.5.3. Against the
# thesis's torsion set of the same tyre (Table 14/15 for the Dunlop R16): the stiffness agrees
# within 8 % where the thesis kept the linear law; where there are extrema the thesis's step 2
# refitted C, E and D.

# %%
for o, kind in (("Fy", "torsion_fy"), ("Mz", "torsion_mz")):
    model = poly.PolynomialModel.from_annex_g("dunlop_r16", 2.0, o)
    ts, tnotes = convert.torsion_set(model)
    ref = thesis_sets.coefficients("dunlop_r16", 2.0, kind)
    k, k_ref = (float(c.get("c4", 0.0)) * 4.5 + float(c.get("c3", 0.0)) * 4.5**2
                for c in (ts.coefficients, ref))
    print(f"{o}: {tnotes['torsion']}; stiffness at 4.5 kN {k:.4g} against the thesis's "
          f"{k_ref:.4g} per degree (ratio {k / k_ref:.3f})")

# %% [markdown]
# ## The wheel in the air
# Lifted off the belt, a spinning wheel feels an aerodynamic lateral force (§3.2.2.1.3.3):
# `aero.identify` fits it on a spin-down (laminar ∝ ω, turbulent ∝ ω|ω|: the terms the data
# support) and `aero.remove` takes it out of bench data (`tyre identify --aero air.csv`). Here a
# synthetic spin-down with a mixed law and 2 N of noise.

# %%
ta = np.arange(0.0, 40.0, 0.01)
wa = 75.0 * np.exp(-ta / 15.0)
fy_air = 3.0 + 0.5 * wa + 0.006 * wa**2 + np.random.default_rng(0).normal(0, 2.0, ta.size)
law = aero.identify(wa, {"FY": fy_air})["FY"]
print(f"{law.law} law: {law.laminar:.3f} ± {law.sigma[1]:.3f} N·s/rad (truth 0.5), "
      f"{law.turbulent:.5f} ± {law.sigma[2]:.5f} N·s²/rad² (truth 0.006)")
fig, ax = plt.subplots(figsize=(6, 3))
ax.plot(wa, fy_air, ".", ms=1, color="0.6", label="spin-down")
ax.plot(wa, law.offset + law(wa), "b-", label=f"{law.law} law")
ax.set(xlabel="ω [rad/s]", ylabel="F_y [N]")
ax.legend()

# %% [markdown]
# ## The speed test, sample selection and set membership
# **Speed test (3-54).** `bench.identify(table, speed_test=True)` (`tyre identify
# --speed-test`) adds to the search the columns δ′·ω₀^k·F_z^j, ω₀^k·F_z^j and their relaxation
# images (Ḟ_y/ω)·ω₀^k·F_z^j, ω₀ = V_T/R_r the run's speed level; a speed term is kept only
# when its removal raises the residual beyond the noise, and the verdict is in the report's
# notes (the thesis finds none on its steering-feel tests). On two speeds only ω₀ is
# separable from the constant: ω₀² is reported not identifiable (with the instantaneous ω,
# ω and ω² together had passed for a "significant" −1.7 N·s/rad offset, the constant in
# disguise). Here the structure is given, as above, with the speed offset ω₀·b_Fy_wone_1_0,
# on the campaign and on the campaign with S_v = 0.4·ω₀ added (the search itself:
# tests/test_tyre_speed.py).

# %%
from diffsusp.tyre import bench_select, bench_speed, setmembership

speed_names = bench_speed.speed_columns("Fy").names
held = [n for n in names if n not in found] + [n for n in speed_names if n != "b_Fy_wone_1_0"]
for c in (0.0, 0.4):
    shifted = dict(table, FY=table["FY"] + c * table["speed"] / 294.0)
    r = bench.identify_output(bench.condition(shifted), "Fy", poly.JUST_NECESSARY["Fy"],
                              search=False, speed_test=True, fixed=held)
    i = r.reduced.names.index("b_Fy_wone_1_0")
    print(f"S_v = {c}·ω₀: b_Fy_wone_1_0 = {r.reduced.x[i]:.4f} ± {r.reduced.sigma[i]:.4f} "
          f"N·s/rad, K_y {r.stiffness:.0f} N/m")

# %% [markdown]
# **Sample selection and integrals** (`tyre.bench_select`, thesis §1.3.3, §1.3.6.3): the
# samples within |δ| ≤ 1° of the campaign, cut into 0.25 s segments for the conditioning
# (`tyre identify --select steer:-0.01745:0.01745`), and the distance rolled ∫V_T dt, by
# which a run's first relaxation lengths can be dropped (`--select int:speed:2000:`).

# %%
small = bench_select.select(table, {"steer": (-np.radians(1.0), np.radians(1.0))},
                            duration=0.25)
rolled = bench_select.trapezoid(table, "speed") * 1e-3  # m
print(f"|δ| ≤ 1°: {small['t'].size} of {table['t'].size} samples in "
      f"{int(small['segment'].max()) + 1} segments; a 1 s run rolls {rolled[199]:.1f} m at "
      f"40 km/h and {rolled[-1]:.1f} m at 120 km/h")

# %% [markdown]
# **Annex A: the set of parameters** of a factorised polynomial compatible with bounded noise
# (`tyre.setmembership`): y = b·x + b·c·z, the relaxation shape of the two-step model with
# c = K_y⁻¹; the least-squares box of X = (b, b·c) in its principal axes with the radius the
# noise bound guarantees, then the (b, c) that map into it, enclosed by interval branch and
# bound. Tested against linear programming in tests/test_tyre_setmembership.py.

# %%
rng = np.random.default_rng(0)
x, z = np.sin(np.arange(200) / 7.0), np.cos(np.arange(200) / 3.0)
y = 2.0 * x + 2.0 * 0.3 * z + rng.uniform(-0.05, 0.05, 200)
X = setmembership.PolynomialMap.from_terms(("b", "c"), [{(1, 0): 1.0}, {(1, 1): 1.0}])
U, centre, radius, _ = setmembership.ellipsoid_box(np.c_[x, z], y, noise_bound=0.05)
box = setmembership.parameter_set(X, U, centre, radius, [0.0, 0.0], [5.0, 1.0], tol=1e-3)
print("outer box:", {n: (round(lo, 4), round(hi, 4))
                     for n, lo, hi in zip(box.names, box.box_lo, box.box_hi, strict=True)})
bb, cc = np.meshgrid(np.linspace(box.box_lo[0], box.box_hi[0], 120),
                     np.linspace(box.box_lo[1], box.box_hi[1], 120))
inside = np.array([box.contains([b_, c_]) for b_, c_ in zip(bb.ravel(), cc.ravel(), strict=True)])
fig, ax = plt.subplots(figsize=(4, 3))
ax.plot(bb.ravel()[inside], cc.ravel()[inside], ".", ms=1, color="0.5", label="the set")
ax.plot(2.0, 0.3, "r+", ms=10, label="truth")
ax.set(xlabel="b", ylabel="c")
ax.legend()

# %% [markdown]
# ## The descriptor relaxation model (2-52…2-57)
# The thesis's full contact model has three flexible joints between the tyre frame and the
# contact patch — lateral y, longitudinal x, torsion β — of stiffnesses K_y, K_x, K_β; the
# bench identification keeps K_y alone (the first-order model (3-49…3-52)).
# `relaxation.DescriptorModel` takes any of them (`math.inf` locks one; locking is data, not
# structure: one compiled program for every configuration). Its small-signal model at an
# operating point (`linearise`, by automatic differentiation; with `small_displacement=True`
# the linear model of (3-34), (3-35)) gives the relaxation time constants and the frequency
# response; `relaxation.simulate_descriptor` integrates it by diffrax. Below, the Dunlop R16
# at 2 bar (its δ′ response and offset: the whole model at φ′ = γ = 0), 4.5 kN, 60 rad/s, K_y
# alone: at δ′ = 0 the time constant is the relaxation length over R_r·ω; it shortens towards
# the grip peak, where ∂F_y/∂δ′ falls.

# %%
import equinox as eqx

pneu = relaxation.PolynomialPneu(*(
    poly.PolynomialModel.create(m.output, {"delta": 7, "one": 1}, values={
        k: v for k, v in m.values().items() if poly.parse_name(k)[1] in ("delta", "one")})
    for m in (fy, mz)))
wheel = relaxation.DescriptorModel.create(pneu, k_y=k_fy)       # K_x = K_β = ∞
lin_op = eqx.filter_jit(lambda m, d: m.linearise({"fz": 4.5, "delta": d, "omega": 60.0},
                                                 keys=("delta",)))
freqs = np.array([0.5, 2.0, 5.0, 10.0])
for d in (0.0, -0.004, -0.008):
    lin = lin_op(wheel, d)
    a, b, c = (np.asarray(lin[k]) for k in ("state", "input", "output"))
    h = np.array([c[:, :1] @ np.linalg.solve(2j * np.pi * f - a[:1, :1], b[:1]) for f in freqs])
    print(f"δ′ = {1e3 * d:4.0f} mm: time constant {-1e3 / a[0, 0]:.1f} ms; |F_y/δ′| "
          f"{np.round(np.abs(h[:, 1, 0]) / 1e3, 1)} kN/m at {freqs} Hz")
print("σ/(R_r·ω) at δ′ = 0:",
      round(1e3 * float(relaxation.relaxation_length(fy, 4.5, k_fy)[0]) / 0.294 / 60.0, 1), "ms")

# %% [markdown]
# ## The contact compliances K_x, K_y, K_β (Table 7)
# `bench.identify_compliances` identifies the three contact stiffnesses on each of F_x, F_y
# and M_z (two-step, then the joint least squares corrected for the noise of the measured
# channels inside the compliance terms). The campaign below is `bench.compliant_flat_trac`:
# the patch on three finite-rotation joints (K_x 300 kN/m, K_y 160 kN/m, K_β 13 kN·m/rad)
# under a Magic-Formula-shaped law, not the polynomial model the method linearises, at the
# default bench noise, with κ′ sines so that F_x has transients. On F_x, K_x comes out to a
# fraction of a percent with a calibrated σ (20-draw Monte-Carlo: spread/σ 1.04, bias
# 0.57 σ/√n, `benchmarks/tyre_compliance.py`); K_β on F_x has a σ of tens of percent and is
# reported not identifiable, with the reason (Table 7's ∞). The campaign and draw are those
# of the compliance tests, whose compiled programs this cell then shares.

# %%
compliance_campaign = bench.compliant_flat_trac(   # the campaign of the compliance tests
    segments=bench.compliance_segments(speeds=(40.0,), loads=(4.5,)), seed=1, duration=1.5)
compliance_set = bench.identify_compliances(compliance_campaign, outputs=("Fx",))
compliance_truth = {"x": 3.0e5, "y": 1.6e5, "beta": 1.3e4}   # N/m, N/m, N·m/rad
fx_rep = compliance_set.outputs["Fx"]
for j, (k, name) in enumerate(zip(bench.COMPLIANCES, fx_rep.stiffness_names, strict=True)):
    i = fx_rep.names.index(name)
    print(f"{name}: {fx_rep.stiffness[j]:.6g} (truth {compliance_truth[k]:.6g}), sigma "
          f"{fx_rep.sigma_pct[i]:.2g} %, "
          + ("identified" if fx_rep.identifiable[i] else fx_rep.reasons[i]))
print(fx_rep.consistency.verdict)
