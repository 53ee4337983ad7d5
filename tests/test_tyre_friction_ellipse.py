"""MF-Tyre's friction ellipse (FE_METHOD = 'YES') on the FEDA truck tyre.

Reference: an independent NumPy transcription (below, SI, from the .tir file) of the MF 5.2
pure-slip functions and of the ellipse as Chrono's ChPac02Tire writes it (β, tan β, μ_act,
μ_max, μ_c), not the library's cancelled form. One compiled program for the grid.
"""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsusp.errors import ModelFileError, ModelWarning
from diffsusp.io.tir import read_tir, tir_from_text
from diffsusp.tyre import MagicFormula6, check_limits, evaluate, examples

FEDA70 = examples.DATA / "335_65R22_5_G275MSA_70psi.tir"


def _ellipse_numpy(tir, FZ, SL, SA, IA):
    """F_x, F_y [N], M_z [N·m] of an MF 5.2 file with the friction ellipse, limits off, α* off,
    V_x = LONGVL (Chrono's ChPac02Tire USE_MODE 4 equations in the library's MF 5.2 pure slip)."""
    g = lambda n, d=0.0: float(tir[n]) if n in tir else d  # noqa: E731
    lam = lambda n: g(n, 1.0)  # noqa: E731
    sg = lambda x: np.where(x < 0, -1.0, 1.0)  # noqa: E731
    mf = lambda B, C, E, x: np.sin(C * np.arctan(B * x - E * (B * x - np.arctan(B * x))))  # noqa
    eps = 1e-6
    R0, FNOMIN = g("UNLOADED_RADIUS"), g("FNOMIN")
    Fz0p = FNOMIN * lam("LFZO")
    dfz = (FZ - Fz0p) / Fz0p
    # pure longitudinal
    Cx = g("PCX1") * lam("LCX")
    Dx = (g("PDX1") + g("PDX2") * dfz) * (1 - g("PDX3") * IA ** 2) * lam("LMUX") * FZ
    Kx = FZ * (g("PKX1") + g("PKX2") * dfz) * np.exp(g("PKX3") * dfz) * lam("LKX")
    Bx = Kx / (Cx * Dx + eps * sg(Dx))
    SHx = (g("PHX1") + g("PHX2") * dfz) * lam("LHX")
    SVx = FZ * (g("PVX1") + g("PVX2") * dfz) * lam("LVX") * lam("LMUX")
    kx = SL + SHx
    Ex = (g("PEX1") + g("PEX2") * dfz + g("PEX3") * dfz ** 2) * (1 - g("PEX4") * np.sign(kx)) \
        * lam("LEX")
    Fx0 = Dx * mf(Bx, Cx, Ex, kx) + SVx
    # pure lateral (MF 5.2)
    Ky = (g("PKY1") * Fz0p * np.sin(g("PKY4", 2.0) * np.arctan(FZ / (g("PKY2") * Fz0p)))
          * (1 - g("PKY3") * np.abs(IA)) * lam("LKY"))
    SHy = (g("PHY1") + g("PHY2") * dfz) * lam("LHY") + g("PHY3") * IA * lam("LKYC")
    SVy = FZ * ((g("PVY1") + g("PVY2") * dfz) * lam("LVY")
                + (g("PVY3") + g("PVY4") * dfz) * IA * lam("LKYC")) * lam("LMUY")
    ay = SA + SHy
    Cy = g("PCY1") * lam("LCY")
    Dy = (g("PDY1") + g("PDY2") * dfz) * (1 - g("PDY3") * IA ** 2) * lam("LMUY") * FZ
    Ey = ((g("PEY1") + g("PEY2") * dfz)
          * (1 + g("PEY5") * IA ** 2 - (g("PEY3") + g("PEY4") * IA) * sg(ay)) * lam("LEY"))
    By = Ky / (Cy * Dy + eps * sg(Dy))
    Fy0 = Dy * mf(By, Cy, Ey, ay) + SVy
    # pure trail and residual moment
    ar = SA + SHy + SVy / Ky
    at = SA + g("QHZ1") + g("QHZ2") * dfz + (g("QHZ3") + g("QHZ4") * dfz) * IA
    Dt = ((g("QDZ1") + g("QDZ2") * dfz) * (1 + g("QDZ3") * IA + g("QDZ4") * IA ** 2)
          * FZ * (R0 / Fz0p) * lam("LTR"))
    Bt = ((g("QBZ1") + g("QBZ2") * dfz + g("QBZ3") * dfz ** 2)
          * (1 + g("QBZ4") * IA + g("QBZ5") * np.abs(IA)) * lam("LKY") / lam("LMUY"))
    Ct = g("QCZ1")
    Et = (g("QEZ1") + g("QEZ2") * dfz + g("QEZ3") * dfz ** 2) * (
        1 + (g("QEZ4") + g("QEZ5") * IA) * (2 / np.pi) * np.arctan(Bt * Ct * at))
    VX = g("LONGVL")
    cosap = VX / (np.sqrt(VX ** 2 + (np.tan(SA) * VX) ** 2) + eps)
    t = Dt * np.cos(Ct * np.arctan(Bt * at - Et * (Bt * at - np.arctan(Bt * at)))) * cosap
    Dr = (FZ * R0 * ((g("QDZ6") + g("QDZ7") * dfz) * lam("LRES")
                     + ((g("QDZ8") + g("QDZ9") * dfz) + (g("QDZ10") + g("QDZ11") * dfz)
                        * np.abs(IA)) * IA * lam("LKZC")) * lam("LMUY") * np.cos(SA))
    Br = g("QBZ9") * lam("LKY") / lam("LMUY") + g("QBZ10") * By * Cy
    Mzr = Dr * np.cos(np.arctan(Br * ar)) * cosap
    # the ellipse as Chrono writes it
    with np.errstate(divide="ignore", invalid="ignore"):
        kc = SL + SHx + SVx / Kx
        s = np.sin(SA + SHy + SVy / Ky)
        beta = np.arccos(np.abs(kc) / np.hypot(kc, s))
        mux_act, muy_act = np.abs((Fx0 - SVx) / FZ), np.abs((Fy0 - SVy) / FZ)
        mux_max, muy_max = Dx / FZ, Dy / FZ
        mux_c = 1 / np.hypot(1 / mux_act, np.tan(beta) / muy_max)
        muy_c = np.tan(beta) / np.hypot(1 / mux_max, np.tan(beta) / muy_act)
        # μ_x,act = 0 only where F_x0 = S_Vx = 0 on this file (κ = 0): F_x = 0 there
        Fx = np.where(mux_act > 0, Fx0 * mux_c / mux_act, Fx0)
        Fy = Fy0 * muy_c / muy_act
    return Fx, Fy, -t * Fy + Mzr, Fy0


@jax.jit
def _forces(model, fz, sl, sa, ia):
    f = evaluate(model, fz, sl, sa, ia, limits=False)
    return jnp.stack([f.fx, f.fy, f.mz / 1000.0])


def test_friction_ellipse_against_numpy_and_derivatives():
    """Grid κ ∈ [−0.3, 0.3], α ∈ [−0.2, 0.2] (0 included), three loads, γ = 0 and 0.05 rad:
    F_x, F_y, M_z to 1e-10 of max(|value|, F_z0 (·R0)); braking at κ = −0.2 lowers |F_y| below
    the pure-slip value (it did not before: RBY1 = 0); derivatives in κ and α at 0 finite and
    equal to central differences; the same file without FE_METHOD unchanged (R* coefficients)."""
    tir = read_tir(FEDA70)
    m = MagicFormula6.from_tir(tir)
    assert m.friction_ellipse
    fnom, r0 = float(tir["FNOMIN"]), float(tir["UNLOADED_RADIUS"])
    k, a, fz, ia = np.meshgrid(np.linspace(-0.3, 0.3, 13), np.linspace(-0.2, 0.2, 9),
                               fnom * np.array([0.6, 1.0, 1.4]), [0.0, 0.05], indexing="ij")
    k, a, fz, ia = (x.ravel() for x in (k, a, fz, ia))
    ours = np.asarray(_forces(m, fz, k, a, ia))
    fx, fy, mz, fy0 = _ellipse_numpy(tir, fz, k, a, ia)
    ref = np.stack([fx, fy, mz])
    assert np.all(np.isfinite(ours)) and np.all(np.isfinite(ref))
    scale = np.array([[fnom], [fnom], [fnom * r0]])
    err = np.abs(ours - ref) / np.maximum(np.abs(ref), scale)
    assert err.max() < 1e-10, err.max(axis=1)
    # braking reduces the lateral force: at κ = −0.2, |F_y| < |F_y0| wherever F_y0 is sizeable
    brake = (k == -0.2) & (np.abs(fy0) > 0.05 * fz)
    assert brake.sum() >= 30
    assert np.all(np.abs(ours[1][brake]) < 0.9 * np.abs(fy0[brake]))
    # the same inputs with the ellipse off: the pure-slip F_y exactly (RBY1 = 0, as before)
    off = np.asarray(_forces(m.replace(friction_ellipse=False), fz, k, a, ia))
    np.testing.assert_allclose(off[1], fy0, rtol=1e-10, atol=1e-6 * fnom)
    assert np.abs(off[1][brake] - ours[1][brake]).min() > 1000.0

    # derivatives at κ = 0 (κ_c = 0 and F_x0 = S_Vx = 0: the 0/0 point), α = 0, both (limits
    # off: KPUMAX = 0 would saturate κ > 0)
    def f(x):
        fo = evaluate(m, fnom, x[0], x[1], limits=False)
        return jnp.stack([fo.fx, fo.fy, fo.mx / 1000.0, fo.my / 1000.0, fo.mz / 1000.0])

    jac, fj = jax.jit(jax.jacfwd(f)), jax.jit(f)
    for x0 in ((0.0, 0.0), (0.0, 0.05), (-0.1, 0.0), (-0.1, -0.08)):
        x0 = np.array(x0)
        J = np.asarray(jac(x0))
        assert np.all(np.isfinite(J)) and np.all(np.isfinite(np.asarray(fj(x0))))
        for i in range(2):
            e = np.eye(2)[i] * 1e-6
            fd = (np.asarray(fj(x0 + e)) - np.asarray(fj(x0 - e))) / 2e-6
            np.testing.assert_allclose(J[:, i], fd, rtol=1e-5, atol=1e-2,
                                       err_msg=f"{x0}, d/d{'κα'[i]}")
    assert abs(float(jac(np.zeros(2))[0, 0])) > 1e4   # F_x rises with κ at the 0/0 point

    # the same file without FE_METHOD: the flag is off and the R* combination is used
    text = FEDA70.read_text()
    plain = MagicFormula6.from_tir(tir_from_text(
        "\n".join(ln for ln in text.splitlines() if not ln.startswith("FE_METHOD")), "p.tir"))
    assert not plain.friction_ellipse
    np.testing.assert_array_equal(np.asarray(_forces(plain, fz, k, a, ia)), off)


def test_flag_read_written_and_announced(tmp_path):
    """FE_METHOD read ('yes'/'NO' any case; a bad value an error naming file, line, field),
    kept by `replace`, written by `to_tir` only where it changes; `check_limits` says once that
    the ellipse is used when the inputs combine slips, and nothing for pure slip."""
    text = FEDA70.read_text()
    tir = read_tir(FEDA70)
    m = MagicFormula6.from_tir(tir)
    assert m.replace(PDY1=-0.9).friction_ellipse and not m.replace(friction_ellipse=False) \
        .friction_ellipse
    assert not MagicFormula6.from_tir(read_tir(examples.DATA / "MagicFormula52_Paramerters.tir")
                                      ).friction_ellipse
    lower = text.replace("'YES'", "'yes'", 1)
    assert MagicFormula6.from_tir(tir_from_text(lower, "a.tir")).friction_ellipse
    no = MagicFormula6.from_tir(tir_from_text(text.replace("'YES'", "'NO'", 1), "a.tir"))
    assert not no.friction_ellipse
    line = 1 + next(i for i, ln in enumerate(text.splitlines()) if ln.startswith("FE_METHOD"))
    with pytest.raises(ModelFileError, match=rf"bad.tir:{line}: FE_METHOD: FE_METHOD = 'MAYBE'"):
        MagicFormula6.from_tir(tir_from_text(text.replace("'YES'", "'MAYBE'", 1), "bad.tir"))
    # to_tir: unchanged flag leaves the line alone; a changed one is written and read back
    assert m.to_tir(tir)["FE_METHOD"] == "YES"
    out = m.replace(friction_ellipse=False).to_tir(tir)
    assert out["FE_METHOD"] == "NO"
    assert not MagicFormula6.from_tir(out).friction_ellipse
    plain = tir_from_text("\n".join(ln for ln in text.splitlines()
                                    if not ln.startswith("FE_METHOD")), "p.tir")
    assert MagicFormula6.from_tir(m.to_tir(plain)).friction_ellipse
    # the announcement
    with pytest.warns(ModelWarning, match=r"rig.csv: FE_METHOD = 'YES': combined slip by the "
                                          r"friction ellipse") as rec:
        assert check_limits(m, fz=[20000.0, 20000.0], kappa=[-0.1, 0.0], alpha=[0.05, 0.0],
                            where="rig.csv: ") == {}
    assert len(rec) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_limits(m, fz=[20000.0], kappa=[0.0], alpha=[0.05])      # pure lateral slip
        check_limits(m, fz=[20000.0], kappa=[-0.1], alpha=[0.05], combined=False)
        check_limits(no, fz=[20000.0], kappa=[-0.1], alpha=[0.05])
