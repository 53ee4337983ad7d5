"""MF 5.2 / 6.1 / 6.2 from the shipped .tir files (docs/reference/tyre.md).

References: an independent NumPy transcription (tests/test_tyre_oracle.py, SI, different code
path) to 1e-10 relative; closed forms of the slope and asymptote; exact symmetries of the
symmetric book file; combined-slip factors equal to 1; central finite differences.
"""

import math
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import test_tyre_oracle as oracle

from diffsusp.errors import ModelFileError, ModelWarning
from diffsusp.io.tir import read_tir, tir_from_text, to_text, write_tir
from diffsusp.tyre import MagicFormula6, check_limits, evaluate, examples

DATA = examples.DATA  # the example .tir files shipped in diffsusp/tyre/data
FILES = ["MagicFormula61_Paramerters.tir", "MagicFormula62_Paramerters.tir",
         "MagicFormula52_Paramerters.tir", "PacejkaBook_Defaults.tir",
         "335_65R22_5_G275MSA_60psi.tir", "335_65R22_5_G275MSA_70psi.tir"]


@jax.jit
def _eval_si(model, fz, sl, sa, ia, vx, p):
    """Library evaluation with SI in and out (vx m/s → mm/s, moments N·mm → N·m)."""
    out = []
    for combined in (True, False):
        f = evaluate(model, fz, sl, sa, ia, vx * 1000.0, p, combined=combined)
        out.append(jnp.stack([f.fx, f.fy, f.mx / 1000.0, f.my / 1000.0, f.mz / 1000.0]))
    return out


def _grid(tir, n=1500, seed=0):
    rng = np.random.default_rng(seed)
    fnom = float(tir["FNOMIN"])
    p0 = float(tir.get("NOMPRES", 0) or tir.get("INFLPRES", 2.2e5) or 2.2e5)
    fz = rng.uniform(0.05, 2.2, n) * fnom          # includes loads beyond FZMAX / below FZMIN
    sl = rng.uniform(-0.4, 0.4, n)
    sa = rng.uniform(-0.35, 0.35, n)
    ia = rng.uniform(-0.12, 0.12, n)
    vx = rng.uniform(5.0, 40.0, n)
    p = rng.uniform(0.75, 1.3, n) * p0
    # exact zeros (sign branches) on a few rows
    sl[:50] = 0.0
    sa[50:100] = 0.0
    ia[100:150] = 0.0
    return fz, sl, sa, ia, vx, p


@pytest.fixture(scope="module")
def files():
    return {name: read_tir(DATA / name) for name in FILES}


@pytest.mark.parametrize("name", FILES)
def test_oracle_agreement(files, name):
    tir = files[name]
    # the oracle is MFeval's equations, which ignore FE_METHOD (the FEDA files' 'YES'): the
    # friction ellipse is tested in test_tyre_friction_ellipse.py
    model = MagicFormula6.from_tir(tir).replace(friction_ellipse=False)
    args = _grid(tir)
    ours = [np.asarray(a) for a in _eval_si(model, *args)]
    scale = np.array([1.0, 1.0, 1.0, 1.0, 1.0])[:, None] * float(tir["FNOMIN"])
    scale[2:] *= float(tir["UNLOADED_RADIUS"])
    for k, combined in enumerate((True, False)):
        ref = np.stack(oracle.mf_numpy(tir, *args, combined=combined))
        assert np.all(np.isfinite(ours[k]))
        err = np.abs(ours[k] - ref) / np.maximum(np.abs(ref), scale)
        # relative to the value, or to FNOMIN (·R0 for moments) where the value crosses zero
        assert err.max() < 1e-10, (name, combined, err.max(axis=1))
    # the pure and combined paths do differ (the test sees the coupling)
    assert np.abs(ours[0][1] - ours[1][1]).max() > 1.0 or name.startswith("335")


@pytest.mark.parametrize("name", ["MagicFormula61_Paramerters.tir",
                                  "MagicFormula52_Paramerters.tir"])
def test_oracle_agreement_of_large_batches(files, name):
    """Batches of FAST_MATH_POINTS or more use the vectorised functions of tyre.fast_math: the same
    1e-10 agreement with the NumPy oracle (MF 6.1 and MF 5.2 code paths)."""
    from diffsusp.tyre.mf6 import FAST_MATH_POINTS

    tir = files[name]
    model = MagicFormula6.from_tir(tir)
    args = _grid(tir, n=FAST_MATH_POINTS, seed=4)
    ours = [np.asarray(a) for a in _eval_si(model, *args)]
    scale = np.full((5, 1), float(tir["FNOMIN"]))
    scale[2:] *= float(tir["UNLOADED_RADIUS"])
    for k, combined in enumerate((True, False)):
        ref = np.stack(oracle.mf_numpy(tir, *args, combined=combined))
        err = np.abs(ours[k] - ref) / np.maximum(np.abs(ref), scale)
        assert err.max() < 1e-10, (name, combined, err.max(axis=1))


def test_mf62_forces_equal_mf61(files):
    m61 = MagicFormula6.from_tir(files["MagicFormula61_Paramerters.tir"])
    m62 = MagicFormula6.from_tir(files["MagicFormula62_Paramerters.tir"])
    assert (m61.version, m62.version) == ("6.1", "6.2")
    args = _grid(files["MagicFormula61_Paramerters.tir"], n=200, seed=3)
    a, b = _eval_si(m61, *args)[0], _eval_si(m62, *args)[0]
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@pytest.fixture(scope="module")
def book(files):
    return MagicFormula6.from_tir(files["PacejkaBook_Defaults.tir"])


def test_book_invariants(book):
    """Symmetric file: closed-form slopes at the centre, asymptotes, exact antisymmetries and
    combined factors = 1 at zero of the other slip. One jitted batch answers all of them."""
    c = {k: float(v) for k, v in book.coefficients.items()}
    fz = jnp.array([1500.0, 4000.0, 7000.0])

    @jax.jit
    def run(m):
        ky = jax.vmap(jax.grad(lambda a, f: evaluate(m, f, 0.0, a, combined=False).fy))(
            jnp.zeros(3), fz)
        kx = jax.vmap(jax.grad(lambda k, f: evaluate(m, f, k, 0.0, combined=False).fx))(
            jnp.zeros(3), fz)
        kg = jax.vmap(jax.grad(lambda g, f: evaluate(m, f, 0.0, 0.0, g, combined=False).fy))(
            jnp.zeros(3), fz)
        far = evaluate(m, fz, 0.0, 1e9, combined=False, limits=False).fy
        farx = evaluate(m, fz, 1e9, 0.0, combined=False, limits=False).fx
        s, a, g = 0.13, 0.07, 0.04
        sym = [evaluate(m, fz, s, a, g), evaluate(m, fz, s, -a, -g), evaluate(m, fz, -s, a, g),
               evaluate(m, fz, -s, -a, -g)]
        comb_k0 = evaluate(m, fz, 0.0, a, g)
        pure_a = evaluate(m, fz, 0.0, a, g, combined=False)
        comb_a0 = evaluate(m, fz, s, 0.0, 0.0)
        pure_k = evaluate(m, fz, s, 0.0, 0.0, combined=False)
        return ky, kx, kg, far, farx, sym, comb_k0, pure_a, comb_a0, pure_k

    ky, kx, kg, far, farx, sym, comb_k0, pure_a, comb_a0, pure_k = run(book)
    f = np.asarray(fz)
    fz0 = c["FNOMIN"]
    dfz = (f - fz0) / fz0
    # K_yα (4.E25) at γ = 0, dp = 0 and K_xκ (4.E15); K_yγ = K_yγ0 = F_z·p_Ky6 (S_Vyγ = 0 here)
    ky_ref = c["PKY1"] * fz0 * np.sin(c["PKY4"] * np.arctan(f / fz0 / c["PKY2"]))
    kx_ref = f * c["PKX1"]
    np.testing.assert_allclose(ky, ky_ref, rtol=1e-6)   # ε_y = 1e-6 N in B_y's denominator
    np.testing.assert_allclose(kx, kx_ref, rtol=1e-6)
    mu_y = c["PDY1"] + c["PDY2"] * dfz
    # camber stiffness: dF_y/dγ = −K_yα·dS_Hy/dγ·… = K_yγ0 exactly at α = 0 (4.E27 with S_V = 0)
    np.testing.assert_allclose(kg, f * c["PKY6"], rtol=1e-6)
    # asymptotes: sgn(B_y)·D_y·sin(C_y·π/2) (E = 0)
    np.testing.assert_allclose(far, -mu_y * f * np.sin(c["PCY1"] * np.pi / 2), rtol=1e-8)
    mu_x = c["PDX1"] + c["PDX2"] * dfz
    np.testing.assert_allclose(farx, mu_x * f * np.sin(c["PCX1"] * np.pi / 2), rtol=1e-8)
    # antisymmetries (exact to rounding)
    p, q, r, t = sym
    for x, y in ((p.fy, -q.fy), (p.mz, -q.mz), (p.fx, q.fx), (p.fy, r.fy), (p.fx, -r.fx),
                 (p.fy, -t.fy), (p.fx, -t.fx)):
        np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-9)
    # combined factors = 1 at zero of the other slip
    np.testing.assert_allclose(comb_k0.fy, pure_a.fy, rtol=1e-14)
    np.testing.assert_allclose(comb_a0.fx, pure_k.fx, rtol=1e-14)
    assert np.abs(np.asarray(p.fy) - np.asarray(pure_a.fy)).min() > 10.0  # κ reduces F_y


def test_centre_of_antisymmetry_61(files):
    """The 6.1 file has shifts: at α = −S_Hy the pure F_y equals S_Vy and its slope K_yα; the
    centre comes from the oracle's own formulas (4.E27–4.E29) at γ = 0, dp = 0."""
    tir = files["MagicFormula61_Paramerters.tir"]
    m = MagicFormula6.from_tir(tir)
    g = lambda n: float(tir[n])  # noqa: E731
    fz = 4500.0
    fz0 = g("FNOMIN")
    dfz = (fz - fz0) / fz0
    kya = g("PKY1") * fz0 * np.sin(g("PKY4") * np.arctan(fz / fz0 / g("PKY2")))
    shy = g("PHY1") + g("PHY2") * dfz
    svy = fz * (g("PVY1") + g("PVY2") * dfz)
    fy = jax.jit(lambda a: evaluate(m, fz, 0.0, a, 0.0, combined=False).fy)
    assert abs(float(fy(-shy)) - svy) < 1e-9 * fz
    np.testing.assert_allclose(float(jax.grad(fy)(-shy)), kya, rtol=1e-6)


def test_gradients_match_finite_differences(files):
    tir = files["MagicFormula61_Paramerters.tir"]
    m = MagicFormula6.from_tir(tir)
    names = ["PDY1", "PKY1", "PEY1", "QDZ1", "QBZ1", "RBX1", "RBY1", "RVY1", "SSZ1", "PPY1",
             "QSX3", "PKX1"]
    x = jnp.array([float(m[n]) for n in names])
    inputs = (5200.0, 0.04, 0.06, 0.02, 20000.0, 2.4e5)

    def out(v, fz, sl, sa, ia):
        mm = m.replace(**{n: v[i] for i, n in enumerate(names)})
        f = evaluate(mm, fz, sl, sa, ia, inputs[4], inputs[5])
        return jnp.stack([f.fx, f.fy, f.mx / 1000, f.my / 1000, f.mz / 1000])

    jac = jax.jit(jax.jacfwd(out, argnums=(0, 1, 2, 3, 4)))
    J = jac(x, *inputs[:4])
    f = jax.jit(out)
    for i in range(len(names)):
        h = 1e-6 * max(1.0, abs(float(x[i])))
        fd = (f(x.at[i].add(h), *inputs[:4]) - f(x.at[i].add(-h), *inputs[:4])) / (2 * h)
        np.testing.assert_allclose(J[0][:, i], fd, rtol=2e-6, atol=1e-5)
    for k, h in enumerate((1e-2, 1e-7, 1e-7, 1e-7)):
        args = list(inputs[:4])
        up, dn = list(args), list(args)
        up[k] += h
        dn[k] -= h
        fd = (f(x, *up) - f(x, *dn)) / (2 * h)
        np.testing.assert_allclose(J[k + 1], fd, rtol=2e-5, atol=1e-4)


def test_limits_saturate_and_warn(files):
    tir = files["PacejkaBook_Defaults.tir"]
    m = MagicFormula6.from_tir(tir)
    fz = np.array([3000.0, 12000.0])
    sa = np.array([0.1, 1.7])
    with pytest.warns(ModelWarning) as record:
        counts = check_limits(m, fz=fz, alpha=sa, where="bench.csv: ")
    messages = sorted(str(r.message) for r in record)
    assert messages[0].startswith("bench.csv: 1 value(s) of FZ beyond FZMAX = 10000 "
                                  "[VERTICAL_FORCE_RANGE] (first at row 1)")
    assert "SA beyond ALPMAX = 1.5 [SLIP_ANGLE_RANGE]" in messages[1]
    assert counts == {"FZMAX": 1, "ALPMAX": 1}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert check_limits(m, fz=[3000.0], alpha=[0.1]) == {}
    with pytest.warns(ModelWarning, match="FZMAX = 10000 .* SA beyond ALPMAX") as record:
        a = evaluate(m, fz, 0.0, sa)   # announced once per call
    assert len(record) == 1
    b = evaluate(m, np.minimum(fz, 10000.0), 0.0, np.minimum(sa, 1.5))
    for k in ("fx", "fy", "mx", "mz"):
        np.testing.assert_array_equal(np.asarray(getattr(a, k)), np.asarray(getattr(b, k)))
    # M_y uses the unsaturated load (MF-Tyre): ratio (12000/10000)^QSY7
    np.testing.assert_allclose(float(a.my[1]) / float(b.my[1]),
                               1.2 ** float(tir["QSY7"]), rtol=1e-12)


def test_read_errors(files, tmp_path):
    text = (DATA / "MagicFormula61_Paramerters.tir").read_text()
    missing = "\n".join(ln for ln in text.splitlines() if not ln.startswith("PCY1"))
    with pytest.raises(ModelFileError, match=r"missing coefficient PCY1 in "
                                             r"\[LATERAL_COEFFICIENTS\]"):
        MagicFormula6.from_tir(tir_from_text(missing, "car.tir"))
    bad = text.replace("PDY1                      \t = 1.0184", "PDY1 = 1.0x84")
    with pytest.raises(ModelFileError, match=r"car.tir:\d+: PDY1: PDY1 in "
                                             r"\[LATERAL_COEFFICIENTS\] must be a number"):
        MagicFormula6.from_tir(tir_from_text(bad, "car.tir"))
    unknown = text.replace("= 61              \t $Magic", "= 44 $Magic")
    with pytest.raises(ModelFileError, match=r"car.tir:\d+: FITTYP: FITTYP = 44 is not"):
        MagicFormula6.from_tir(tir_from_text(unknown, "car.tir"))
    with pytest.raises(ModelFileError, match=r"car.tir:3: cannot read 'garbage here'"):
        tir_from_text("[MODEL]\nFITTYP = 61\ngarbage here\n", "car.tir")
    with pytest.raises(ModelFileError, match=r"LENGTH = 'mm' is not supported"):
        tir_from_text("[UNITS]\nLENGTH = 'mm'\n[MODEL]\nFITTYP = 61\n", "car.tir")
    with pytest.raises(ModelFileError, match=r"cannot read the file"):
        read_tir(tmp_path / "absent.tir")


def test_model_to_tir_roundtrip_exact(files, tmp_path):
    tir = files["MagicFormula61_Paramerters.tir"]
    m = MagicFormula6.from_tir(tir)
    m2 = m.replace(PCY1=1.2345678901234567, PKY1=-21.000000000000004, QSX12=0.1 + 0.2,
                   UNLOADED_RADIUS=401.23456789)
    out = m2.to_tir(tir)
    write_tir(out, tmp_path / "fitted.tir")
    back = MagicFormula6.from_tir(read_tir(tmp_path / "fitted.tir"))
    for n in m2.coefficients:
        if n == "UNLOADED_RADIUS":  # m → mm → m: exact to one rounding
            assert float(back[n]) == pytest.approx(float(m2[n]), rel=1e-15)
        else:
            assert float(back[n]) == float(m2[n]), n
    # unchanged lines are written back byte for byte
    again = to_text(read_tir(DATA / "PacejkaBook_Defaults.tir"))
    assert again.splitlines() == (DATA / "PacejkaBook_Defaults.tir").read_text().splitlines()


def test_no_retrace_on_new_values(files):
    m = MagicFormula6.from_tir(files["MagicFormula61_Paramerters.tir"])

    @eqx.filter_jit
    @eqx.debug.assert_max_traces(max_traces=1)
    def f(m, fz):
        return evaluate(m, fz, 0.01, 0.02).fy

    f(m, jnp.ones(4) * 4000.0)
    f(m.replace(PDY1=1.1), jnp.ones(4) * 3000.0)


def test_vectorised_transcendentals_match_numpy():
    """diffsusp.tyre.fast_math (Cephes arctan, sin, cos, tan; Newton sqrt and cos∘arctan), which
    the MF 6.x evaluation uses instead of XLA's scalar float64 calls: values to a few ulps over the
    Magic Formula's range and beyond, exact derivatives (custom JVPs)."""
    import jax

    from diffsusp.tyre import fast_math

    rng = np.random.default_rng(3)
    x = np.concatenate([rng.uniform(-1, 1, 4000), rng.uniform(-50, 50, 4000),
                        rng.uniform(-1e6, 1e6, 2000), np.logspace(-12, 7.9, 200),
                        [0.0, 0.66, 2.414213562373095, math.pi / 4, 3 * math.pi / 4, -math.pi]])
    xj = jnp.asarray(x)
    for f, ref in ((fast_math.arctan, np.arctan), (fast_math.sin, np.sin), (fast_math.cos, np.cos)):
        np.testing.assert_allclose(np.asarray(f(xj)), ref(x), rtol=2e-15, atol=3e-16)
    small = x[np.abs(x) < 1.4]  # away from the poles of tan
    np.testing.assert_allclose(np.asarray(fast_math.tan(jnp.asarray(small))), np.tan(small),
                               rtol=3e-15, atol=3e-16)
    # Its range is [1e-30, 1e30]; np.logspace(-30, ...)[0] is 1 ulp below 1e-30 (0 there).
    pos = np.concatenate([np.abs(x), np.logspace(-30, 30, 300)[1:], [1e-30]])
    np.testing.assert_allclose(np.asarray(fast_math.sqrt(jnp.asarray(pos))), np.sqrt(pos),
                               rtol=5e-16, atol=0)
    assert float(fast_math.sqrt(np.nextafter(1e-30, 0.0))) == 0.0
    assert float(fast_math.sqrt(0.0)) == 0.0
    g = jnp.asarray(rng.uniform(-3, 3, 50))
    for f, d in ((fast_math.arctan, lambda v: 1 / (1 + v * v)), (fast_math.sin, np.cos),
                 (fast_math.cos, lambda v: -np.sin(v)),
                 (fast_math.tan, lambda v: 1 / np.cos(v) ** 2)):
        np.testing.assert_allclose(np.asarray(jax.vmap(jax.grad(f))(g)), d(np.asarray(g)),
                                   rtol=1e-14)
    h = jnp.asarray(rng.uniform(0.1, 100, 50))
    np.testing.assert_allclose(np.asarray(jax.vmap(jax.grad(fast_math.sqrt))(h)),
                               0.5 / np.sqrt(np.asarray(h)), rtol=1e-14)
    # cos(atan x) = 1/√(1 + x²), to |x| = 1e15
    np.testing.assert_allclose(np.asarray(fast_math.cos_arctan(xj)), 1 / np.sqrt(1 + x * x),
                               rtol=5e-16, atol=0)
    big = np.logspace(8, 15, 50)
    np.testing.assert_allclose(np.asarray(fast_math.cos_arctan(jnp.asarray(big))),
                               1 / np.sqrt(1 + big * big), rtol=5e-16, atol=0)
    np.testing.assert_allclose(np.asarray(jax.vmap(jax.grad(fast_math.cos_arctan))(g)),
                               -np.asarray(g) / (1 + np.asarray(g) ** 2) ** 1.5, rtol=1e-14)
