"""Combined slip of the 1989 Magic Formula set away from the pure-slip axes (spec: tyre §2.4,
B-9…B-16 and B-25…B-33): G_y at κ ≠ 0, with a_m1 and a_m4 ≠ 0 (the factor's centre and its
δ-dependence), and a non-zero F_yx (a_m5…a_m9, camber ≠ 0), against an independent NumPy
transcription of the annex's formulas; their gradients against central differences."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsusp.tyre import mf89
from diffsusp.tyre.mf89 import MagicFormula89

# Combined-slip coefficients with every term active (Bakker 1989 orders of magnitude: κ in %).
COMBINED = {"am0": 1.15, "am1": 1.5, "am2": 0.09, "am3": 0.12, "am4": 0.8, "am5": -6.0,
            "am6": 0.15, "am7": -0.4, "am8": 0.06, "am9": 0.2,
            "bm0": 1.2, "bm1": 0.3, "bm2": 0.15, "bm3": 0.05,
            "b0": 1.65, "b1": -21.3, "b2": 1144.0, "b3": 49.6, "b4": 226.0, "b5": 0.069,
            "b6": -0.006, "b7": 0.056, "b8": 0.486, "b9": 0.02, "b10": -0.1, "b11": 3.0,
            "b12": -20.0}


@pytest.fixture(scope="module")
def tyre():
    base = MagicFormula89.from_thesis("michelin_r15", 2.5)
    values = {k: float(v) for k, v in base.coefficients.items()}
    return MagicFormula89.from_values({**values, **COMBINED})


def _fy0_numpy(c, delta, fz, gamma):
    """(B-9…B-16) as printed (horizontal shift added to δ), all λ = 1."""
    D = c["a1"] * fz**2 + c["a2"] * fz
    C = c["a0"]
    BCD = c["a3"] * np.sin(2 * np.arctan(fz / c["a4"])) * (1 - c["a5"] * np.abs(gamma))
    B = BCD / (C * D)
    E = np.minimum(c["a6"] * fz + c["a7"], 1.0)
    Sh = c["a8"] * gamma + c["a9"] * fz + c["a10"]
    Sv = c["a12"] * fz + c["a13"] + (c["a112"] * fz**2 + c["a111"] * fz) * gamma
    x = delta + Sh
    return D * np.sin(C * np.arctan(B * (1 - E) * x + E * np.arctan(B * x))) + Sv


def _fx0_numpy(c, kappa, fz):
    """(B-1…B-8), all λ = 1."""
    D = c["b1"] * fz**2 + c["b2"] * fz
    C = c["b0"]
    BCD = (c["b3"] * fz**2 + c["b4"] * fz) * np.exp(-c["b5"] * fz)
    B = BCD / (C * D)
    E = np.minimum(c["b6"] * fz**2 + c["b7"] * fz + c["b8"], 1.0)
    x = kappa + c["b9"] * fz + c["b10"]
    return (D * np.sin(C * np.arctan(B * (1 - E) * x + E * np.arctan(B * x)))
            + c["b11"] * fz + c["b12"])


def _combined_numpy(c, kappa, delta, fz, gamma):
    """(B-25…B-33): F_x = G_x·F_x0, F_y = G_y·F_y0 + F_yx."""
    BD = c["bm2"] * np.cos(np.arctan(c["bm3"] * kappa))
    Gx = (np.cos(c["bm0"] * np.arctan(BD * (delta - c["bm1"])))
          / np.cos(c["bm0"] * np.arctan(-BD * c["bm1"])))
    BG = c["am2"] * np.cos(np.arctan(c["am3"] * (delta - c["am4"])))
    Gy = (np.cos(c["am0"] * np.arctan(BG * (kappa - c["am1"])))
          / np.cos(c["am0"] * np.arctan(-BG * c["am1"])))
    gliss = np.sin(1.9 * np.arctan(c["am8"] * kappa))
    dele = np.cos(np.arctan(c["am9"] * delta))
    Fyx = c["am5"] * fz * (gamma - (c["am6"] * fz + c["am7"])) * gliss * dele
    return Gx * _fx0_numpy(c, kappa, fz), Gy * _fy0_numpy(c, delta, fz, gamma) + Fyx, Gy, Fyx


def test_combined_slip_against_a_numpy_transcription(tyre):
    """Over κ ∈ [−20, 20] %, δ ∈ [−10, 10]°, F_z ∈ {2, 4.5, 7} kN, γ ∈ {−2, 0, 3}°: F_x and
    F_y to 1e-12 relative of their scale; G_y departs from 1 by up to tens of percent and
    F_yx reaches hundreds of newtons (the terms are exercised, not zero)."""
    c = {k: float(v) for k, v in tyre.coefficients.items()}
    k, d, f, g = np.meshgrid(np.linspace(-20, 20, 9), np.linspace(-10, 10, 7),
                             [2.0, 4.5, 7.0], [-2.0, 0.0, 3.0], indexing="ij")
    fx, fy, mz = (np.asarray(a) for a in mf89.combined(tyre, k, d, f, g))
    fx_ref, fy_ref, gy, fyx = _combined_numpy(c, k, d, f, g)
    np.testing.assert_allclose(fx, fx_ref, rtol=0, atol=1e-12 * np.abs(fx_ref).max())
    np.testing.assert_allclose(fy, fy_ref, rtol=0, atol=1e-12 * np.abs(fy_ref).max())
    np.testing.assert_allclose(mz, np.asarray(mf89.mz0(tyre, d, f, g)), rtol=1e-15)
    assert np.abs(gy - 1).max() > 0.1 and np.abs(fyx).max() > 100.0
    # G_y = 1 on κ = 0 whatever δ (its normalisation), F_yx = 0 there (sin(1.9·atan(0)))
    zero = k == 0.0
    np.testing.assert_allclose(gy[zero], 1.0, rtol=1e-15)
    np.testing.assert_allclose(fy[zero], _fy0_numpy(c, d, f, g)[zero], rtol=1e-13)
    # library units at the edge: F_z [N], κ [-] × kappa_scale, α and γ [rad]
    fxl, fyl, _ = mf89.evaluate(tyre, 4500.0, 0.08, math.radians(4.0), math.radians(3.0),
                                kappa_scale=100.0)
    ref = _combined_numpy(c, 8.0, 4.0, 4.5, 3.0)
    np.testing.assert_allclose([fxl, fyl], ref[:2], rtol=1e-13)


def test_combined_slip_gradients(tyre):
    """∂F_y/∂(a_m0…a_m9, κ, δ) of the combined force against central differences."""
    names = [f"am{i}" for i in range(10)]
    point = (7.0, 4.0, 4.5, 2.0)

    def fy(values, kappa, delta):
        coefficients = {**tyre.coefficients, **dict(zip(names, values, strict=True))}
        return mf89.combined(MagicFormula89(coefficients), kappa, delta, *point[2:])[1]

    x0 = jnp.asarray([float(tyre.coefficients[n]) for n in names])
    grad = jax.grad(fy, argnums=(0, 1, 2))(x0, point[0], point[1])
    for i in range(len(names)):
        h = 1e-6 * max(1.0, abs(float(x0[i])))
        e = jnp.zeros_like(x0).at[i].set(h)
        fd = (fy(x0 + e, *point[:2]) - fy(x0 - e, *point[:2])) / (2 * h)
        np.testing.assert_allclose(grad[0][i], fd, rtol=1e-6, atol=1e-6)
    for j, arg in ((1, 0), (2, 1)):
        h = 1e-6
        up, down = list(point[:2]), list(point[:2])
        up[arg] += h
        down[arg] -= h
        fd = (fy(x0, *up) - fy(x0, *down)) / (2 * h)
        np.testing.assert_allclose(grad[j], fd, rtol=1e-6)
