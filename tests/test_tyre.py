"""The thesis's Magic Formula (Annex B) and its Tables 14–29; specification quantities,
macro-coefficients, similarity (spec tyre §2, §4.6, §8.5).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsusp.tyre import MagicFormula89, mf89, specification, thesis_sets
from diffsusp.tyre.spec import (
    bcde_to_macro,
    macro_to_bcde,
    magic_formula,
    similarity,
    similarity_primitive,
)

# spec §8.5 (digest values at F_z = 4.5 kN, γ = 0): D_y [N], BCD_y [N/°]
REFERENCE = {
    "dunlop_r16": ((5672, 5467, 5555), (1803, 1748, 1647)),
    "michelin_r15": ((5986, 5624, 5894), (1945, 1958, 1878)),
    "michelin_r16": ((5538, 5487, 5654), (1945, 1914, 1832)),
    "michelin_r17": ((6249, 6278, 6482), (1908, 1905, 1780)),
}
# spec §4.6: BCD_z = c3·F_z² + c4·F_z [N·m/°] at 4.5 kN, printed to 0.1
REFERENCE_BCDZ = {
    "dunlop_r16": (-72.4, -59.6, -48.9), "michelin_r15": (-72.1, -59.6, -50.1),
    "michelin_r16": (-72.3, -57.6, -49.6), "michelin_r17": (-83.9, -71.6, -57.7),
}
# Annex G (spec §4.7), M_z on δ': b_{Mz,δ',1,j} for j = 3, 2, 1 (Tables 46–57), Table 55
# with −99 (CORRECTIONS 5)
ANNEX_G_MZ = {
    ("dunlop_r16", 2.0): (-96.85, 1043.0, 0.0), ("dunlop_r16", 2.5): (-64.57, 793.8, 0.0),
    ("dunlop_r16", 3.0): (-37.94, 582.3, 0.0), ("michelin_r15", 2.0): (-82.61, 983.5, 0.0),
    ("michelin_r15", 2.5): (-51.77, 742.7, 0.0), ("michelin_r15", 3.0): (-35.29, 586.9, 0.0),
    ("michelin_r16", 2.0): (-99.48, 1067.0, 0.0), ("michelin_r16", 2.5): (-66.95, 818.9, 0.0),
    ("michelin_r16", 3.0): (-43.61, 626.1, 0.0), ("michelin_r17", 2.0): (-99.0, 1189.0, 0.0),
    ("michelin_r17", 2.5): (-66.07, 1011.0, -474.4), ("michelin_r17", 3.0): (-21.84, 591.6, 0.0),
}

SETS = [(t, p) for t in thesis_sets.TYRES for p in thesis_sets.PRESSURES]


@pytest.fixture(scope="module")
def thesis_results():
    """One jitted, vmapped evaluation over the 12 sets: macro-coefficients at 4.5 kN, the slopes
    at the centres by autodiff, and the M_z slip stiffness over 1.5–6 kN."""
    models = [MagicFormula89.from_thesis(t, p) for t, p in SETS]
    stacked = jax.tree.map(lambda *x: jnp.stack(x), *models)
    loads = jnp.linspace(1.5, 6.0, 19)

    @jax.jit
    @jax.vmap
    def run(m):
        mac = mf89.macro(m, 4.5)
        ky = jax.grad(mf89.fy0, argnums=1)(m, -mac["Shy"], 4.5)
        kz = jax.grad(mf89.mz0, argnums=1)(m, -mac["Shz"], 4.5)
        far = mf89.fy0(m, 1e7, 4.5)
        bcdz = jax.vmap(lambda f: mf89.macro(m, f)["BCDz"])(loads)
        return mac, ky, kz, far, bcdz

    return run(stacked), np.asarray(loads)


def test_thesis_tables_at_4_5_kN(thesis_results):
    (mac, ky, kz, far, _), _ = thesis_results
    for i, (t, p) in enumerate(SETS):
        j = thesis_sets.PRESSURES.index(p)
        d_ref, k_ref = REFERENCE[t][0][j], REFERENCE[t][1][j]
        # printed to the newton: agreement within rounding (0.5 N, 0.5 N/°)
        assert abs(float(mac["Dy"][i]) - d_ref) <= 0.5, (t, p)
        assert abs(float(mac["BCDy"][i]) - k_ref) <= 0.5, (t, p)
        assert abs(float(mac["BCDz"][i]) - REFERENCE_BCDZ[t][j]) <= 0.05, (t, p)
        # slope at the centre of antisymmetry = BCD (autodiff of the formula), both axes
        np.testing.assert_allclose(ky[i], mac["BCDy"][i], rtol=1e-12)
        np.testing.assert_allclose(kz[i], mac["BCDz"][i], rtol=1e-12)
        # C_y = a0 = 1 (CORRECTIONS 2): D_y is the asymptote, not a peak
        assert float(mac["Cy"][i]) == pytest.approx(1.0, abs=1e-4)
        np.testing.assert_allclose(far[i], mac["Dy"][i] * math.sin(mac["Cy"][i] * math.pi / 2)
                                   + mac["Svy"][i], rtol=1e-6)
        # spec §8.5 ranges: E_y = a7 in 0.36–0.56, S_Hz between −0.11 and +0.02°
        assert 0.36 <= float(mac["Ey"][i]) <= 0.56
        assert -0.11 < float(mac["Shz"][i]) < 0.02


def test_cross_table_annex_g(thesis_results):
    """M_z slip stiffness of Tables 17/21/25/29 against −R·π/180·c_{Mz,δ',1}(F_z) of Annex G, one
    least-squares radius per set (CORRECTIONS 4, 5).

    Measured: the radii are 0.323–0.348 m (over 3–6 kN; 0.326–0.351 m over 1.5–6 kN), but the
    agreement is not "within 2.5 % over 1.5–6 kN" as CORRECTIONS 4 states: the MF's
    c3·F_z² + c4·F_z tends to c4·F_z at low load while the Annex G polynomial (j = 2, 3 only)
    tends to F_z², so the ratio grows from ≈0.33 m at 4.5 kN to 0.40–0.56 m at 1.5 kN (worst
    relative deviation 17–37 % over 1.5–6 kN). Over 3–6 kN every set agrees within 6.1 %; the
    check still separates the sign of Table 55: −99 fits (5.8 %), +99 misfits by 67 %."""
    (_, _, _, _, bcdz), loads = thesis_results
    sel = loads >= 3.0
    radii, worst = [], []
    for i, key in enumerate(SETS):
        b3, b2, b1 = ANNEX_G_MZ[key]
        poly = -(math.pi / 180.0) * (b3 * loads**3 + b2 * loads**2 + b1 * loads)[sel]
        mf = np.asarray(bcdz[i])[sel]
        R = float(poly @ mf / (poly @ poly))
        radii.append(R)
        worst.append((np.abs(R * poly - mf) / np.abs(mf)).max())
    assert 0.32 <= min(radii) and max(radii) <= 0.35, radii
    assert max(worst) < 0.062, dict(zip(SETS, np.round(worst, 4), strict=True))
    # the sign of Table 55: +99 misfits by far
    i = SETS.index(("michelin_r17", 2.0))
    poly = -(math.pi / 180.0) * (99.0 * loads**3 + 1189.0 * loads**2)
    R = float(poly @ np.asarray(bcdz[i]) / (poly @ poly))
    assert (np.abs(R * poly - bcdz[i]) / np.abs(bcdz[i])).max() > 0.5


def test_linear_law_when_D_is_zero():
    """Torsion Table 14 at 2 bar has c1 = c2 = 0: M_z = BCD·(x + S_h) + S_v exactly, with finite
    gradients w.r.t. every coefficient."""
    m = MagicFormula89.from_thesis("dunlop_r16", 2.0, fy=None, mz="torsion_fy")
    x = jnp.linspace(-0.85, 0.85, 7)
    y = mf89.mz0(m, x, 4.5)
    np.testing.assert_allclose(y, 174.04808 * 4.5 * x, rtol=1e-14)
    g = jax.grad(lambda mm: jnp.sum(mf89.mz0(mm, x, 4.5)))(m)
    assert all(np.isfinite(float(v)) for v in g.coefficients.values())
    np.testing.assert_allclose(g.coefficients["c4"], 4.5 * float(jnp.sum(x)), atol=1e-12)


def test_clipping_lambdas_and_combined():
    base = MagicFormula89.from_thesis("michelin_r15", 2.5)
    vals = {k: float(v) for k, v in base.coefficients.items()}
    # E_y = min((a6 F_z + a7)·λ_Ey, 1) (B-14); E_z is not clipped (B-22)
    m = MagicFormula89.from_values({**vals, "a6": 0.5, "c9": 3.0})
    mac = mf89.macro(m, 4.5)
    assert float(mac["Ey"]) == 1.0 and float(mac["Ez"]) == pytest.approx(3.0)
    # λ_μy scales the peak and the vertical shift; λ_Ky the slope only
    m2 = MagicFormula89.from_values({**vals, "l_muy": 0.8, "l_ky": 1.1})
    a, b = mf89.macro(base, 4.5), mf89.macro(m2, 4.5)
    np.testing.assert_allclose(b["Dy"], 0.8 * a["Dy"], rtol=1e-14)
    np.testing.assert_allclose(b["BCDy"], 1.1 * a["BCDy"], rtol=1e-14)
    # combined slip (B-25…B-33): factors = 1 at zero of the other slip (b_m1 = a_m1 = 0)
    mc = MagicFormula89.from_values({**vals, "am0": 1.1, "am2": 0.2, "am3": 0.1, "bm0": 1.2,
                                     "bm2": 0.15, "bm3": 0.05, "b0": 1.6, "b1": -20.0,
                                     "b2": 1300.0, "b3": 30.0, "b4": 400.0, "am5": 0.0})
    fx, fy, _ = mf89.combined(mc, 0.0, 3.0, 4.5)
    np.testing.assert_allclose(fy, mf89.fy0(mc, 3.0, 4.5), rtol=1e-15)
    fx, fy, _ = mf89.combined(mc, 5.0, 0.0, 4.5)
    np.testing.assert_allclose(fx, mf89.fx0(mc, 5.0, 4.5), rtol=1e-15)
    fx, fy, _ = mf89.combined(mc, 5.0, 3.0, 4.5)
    # G_x (B-26) closed form
    BD = 0.15 * math.cos(math.atan(0.05 * 5.0))
    Gx = math.cos(1.2 * math.atan(BD * 3.0))
    np.testing.assert_allclose(fx, Gx * mf89.fx0(mc, 5.0, 4.5), rtol=1e-14)
    # library-unit edge: N, rad → kN, deg; N·m → N·mm
    fxl, fyl, mzl = mf89.evaluate(mc, 4500.0, 5.0, math.radians(3.0))
    np.testing.assert_allclose(fyl, fy, rtol=1e-14)
    np.testing.assert_allclose(mzl, 1000.0 * mf89.mz0(mc, 3.0, 4.5), rtol=1e-14)


def test_transients_steady_state_and_step():
    """Longitudinal (B-34…B-36) and the corrected lateral relaxation: steady states are κ and δ
    of (B-1); a step response is 1 − exp(−|V| t/σ)."""
    m = MagicFormula89.from_values({"sigma_x": 0.3, "sigma_y": 0.5})
    vx, vr, vy = 20.0, 20.6, -1.3
    u_ss = -0.3 * (vx - vr) / abs(vr)
    v_ss = -0.5 * vy / abs(vx)
    np.testing.assert_allclose(mf89.longitudinal_relaxation_rate(m, u_ss, vx, vr), 0.0,
                               atol=1e-15)
    np.testing.assert_allclose(mf89.lateral_relaxation_rate(m, v_ss, vx, vy), 0.0, atol=1e-15)
    k, d = mf89.transient_slips(m, u_ss, v_ss, vx, vr)
    np.testing.assert_allclose(k, vr / vx - 1.0, rtol=1e-13)
    np.testing.assert_allclose(d, math.atan(-vy / vx), rtol=1e-13)
    # step in V_y from rest: exact exponential; integrate with RK4
    def rk4(v, dt):
        f = lambda v: mf89.lateral_relaxation_rate(m, v, vx, vy)  # noqa: E731
        k1 = f(v)
        k2 = f(v + dt / 2 * k1)
        k3 = f(v + dt / 2 * k2)
        k4 = f(v + dt * k3)
        return v + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    v, dt = 0.0, 1e-3
    for _ in range(50):
        v = rk4(v, dt)
    # RK4 with |V|·dt/σ = 0.04: truncation error ~1e-9 relative
    np.testing.assert_allclose(v, v_ss * (1 - math.exp(-vx * 0.05 / 0.5)), rtol=1e-7)


def test_macro_coefficients_roundtrip():
    """(B, C, D, E) ↔ (K, D, x_m, L) with the corrected shape-factor branch (CORRECTIONS 1)."""
    for kind, C in (("force", 1.45), ("moment", 2.4)):
        B, D, E, Sh = 0.31, 5200.0, 0.35, 0.12
        K, D2, xm, L = bcde_to_macro(B, C, D, E, Sh)
        # the curve really has its extremum D at x_m and its asymptote L
        def f(x, B=B, C=C, D=D, E=E, Sh=Sh):
            return magic_formula(x, B, C, D, E, Sh)
        np.testing.assert_allclose(f(xm), D, rtol=1e-12)
        np.testing.assert_allclose(jax.grad(f)(xm), 0.0, atol=1e-9 * D)
        np.testing.assert_allclose(jax.grad(f)(-Sh), K, rtol=1e-12)
        np.testing.assert_allclose(f(1e9), L, rtol=1e-6)
        B2, C2, _, E2 = macro_to_bcde(K, D2, xm, L, Sh, kind=kind)
        np.testing.assert_allclose([B2, C2, E2], [B, C, E], rtol=1e-12)
    # the printed (2-116) would give C in [0, 1]: the corrected branch is in (1, 2)
    assert 1 < float(macro_to_bcde(2000.0, 5000.0, 8.0, 4000.0)[1]) < 2
    assert math.isnan(float(bcde_to_macro(0.3, 1.0, 5000.0, 0.5)[2]))


def test_similarity_collapse():
    """Thesis sets have constant C_y, E_y: normalised F_y curves at 2–6 kN collapse exactly onto
    P_Fy (2-120, 2-123); M̄_z = P_Mz(r·X̄)/r, r = D_t·D_y/D_z (2-121, 2-124, 2-125)."""
    m = MagicFormula89.from_thesis("michelin_r16", 2.5)
    delta = jnp.linspace(-12.0, 12.0, 41)
    for fz in (2.0, 4.5, 6.0):
        mac = mf89.macro(m, fz)
        fy, mz = mf89.fy0(m, delta, fz), mf89.mz0(m, delta, fz)
        X, Fb, Mb, S = similarity(delta, fy, mz, D_y=mac["Dy"], BCD_y=mac["BCDy"],
                                  S_hy=mac["Shy"], S_vy=mac["Svy"], BCD_z=mac["BCDz"],
                                  S_hz=mac["Shz"], S_vz=mac["Svz"])
        np.testing.assert_allclose(Fb, similarity_primitive(X, mac["Cy"], mac["Ey"]),
                                   atol=1e-14)
        Dt = mac["BCDz"] / mac["BCDy"]
        r = Dt * mac["Dy"] / mac["Dz"]
        np.testing.assert_allclose(
            Mb, similarity_primitive(r * X, mac["Cz"], mac["Ez"], r * S) / r, atol=1e-12)


def test_specification_quantities():
    m = MagicFormula89.from_thesis("dunlop_r16", 2.0)
    s = specification(m, jnp.array([3000.0, 4500.0]))
    deg = 180.0 / math.pi
    # cornering stiffness [N/rad] at δ = 0 vs the formula (S_hy = 0 in this set)
    np.testing.assert_allclose(np.asarray(s["cornering_stiffness"])[1] / deg, 1803.4959,
                               rtol=1e-6)
    mac = mf89.macro(m, 3.0)
    np.testing.assert_allclose(s["cornering_stiffness"][0], mac["BCDy"] * deg, rtol=1e-12)
    # aligning stiffness at δ = 0 by the chain rule of (B-17) (S_hz ≠ 0): closed form
    u = mac["Shz"]
    B, C, D, E = mac["Bz"], mac["Cz"], mac["Dz"], mac["Ez"]
    phi = B * (1 - E) * u + E * jnp.arctan(B * u)
    dphi = B * (1 - E) + E * B / (1 + (B * u) ** 2)
    kz = D * jnp.cos(C * jnp.arctan(phi)) * C / (1 + phi**2) * dphi
    np.testing.assert_allclose(s["aligning_stiffness"][0], 1000.0 * kz * deg, rtol=1e-12)
    np.testing.assert_allclose(s["pneumatic_trail"], -np.asarray(s["aligning_stiffness"])
                               / np.asarray(s["cornering_stiffness"]), rtol=1e-15)
    assert np.all(np.asarray(s["pneumatic_trail"]) > 0)     # 30–40 mm
    # C_y = 1: no F_y peak (CORRECTIONS 2); M_z has one (its minimum in PSA signs), = −D_z
    assert np.all(np.isnan(np.asarray(s["fy_peak"])))
    np.testing.assert_allclose(s["mz_peak"][1], -1000.0 * mf89.macro(m, 4.5)["Dz"], rtol=1e-9)


def test_from_specification_recovers_thesis_sets():
    """Step 1 of the polynomial → MF conversion (spec §3.8): the specification quantities of a
    thesis set at 2–7 kN give its coefficients back (TLS of (3-100) exact on exact data)."""
    for tyre, p in (("dunlop_r16", 2.0), ("michelin_r17", 3.0)):
        m = MagicFormula89.from_thesis(tyre, p)
        fz = np.linspace(2.0, 7.0, 6)
        mac = {k: np.asarray(v) for k, v in mf89.macro(m, jnp.asarray(fz)).items()}
        back = MagicFormula89.from_specification(
            fz, cornering_stiffness=mac["BCDy"], fy_peak=mac["Dy"], fy_shift=mac["Shy"],
            aligning_stiffness=mac["BCDz"], mz_peak=mac["Dz"], mz_shift=mac["Shz"],
            a0=float(m["a0"]), c0=float(m["c0"]), a7=float(m["a7"]), c9=float(m["c9"]))
        for k in ("a1", "a2", "a3", "a4", "a9", "a10", "c1", "c2", "c3", "c4", "c12", "c13"):
            assert float(back[k]) == pytest.approx(float(m[k]), rel=1e-8, abs=1e-9), (tyre, k)
    # a stiffness still rising at the highest load (linear range): a4 must be given
    fz = np.array([1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="not concave in load"):
        MagicFormula89.from_specification(fz, cornering_stiffness=400.0 * fz + 1e-3 * fz**2,
                                          fy_peak=1300.0 * fz)
    lin = MagicFormula89.from_specification(fz, cornering_stiffness=400.0 * fz
                                            + 1e-3 * fz**2, fy_peak=1300.0 * fz, a4=8.0)
    assert float(lin["a3"]) == pytest.approx(400.0 * 8.0 / 2.0, rel=1e-4)
