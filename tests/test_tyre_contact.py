"""diffsusp.tyre.contact: contact-frame kinematics of chapter 2 (spec: tyre_contact_model §1.5,
§1.6, §4.1, §8.7)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsusp import mdh
from diffsusp.tyre import contact as C


def test_rolling_radius_and_slip_conversions():
    """δ′ = ±18 mm ↔ δ = ±3.5° gives R_r = 0.018/tan 3.5° = 0.294 m (spec §0.3, §8.7); the
    (2-101…2-104) conversions invert each other and agree with the twist definitions at zero
    longitudinal slip."""
    rr = float(C.rolling_radius_from_equivalence(0.018, math.radians(3.5)))
    assert rr == pytest.approx(0.018 / math.tan(math.radians(3.5)), rel=1e-14)
    assert round(rr, 3) == 0.294
    assert float(C.delta_prime_from_slip_angle(math.radians(-3.5), rr)) == pytest.approx(0.018)
    d = math.radians(2.0)
    assert float(C.slip_angle_from_delta_prime(C.delta_prime_from_slip_angle(d, rr), rr)) \
        == pytest.approx(d, rel=1e-14)
    assert float(C.slip_from_kappa_prime(C.kappa_prime_from_slip(0.03, rr), rr)) \
        == pytest.approx(0.03, rel=1e-13)
    assert float(C.curvature_from_phi_prime(C.phi_prime_from_curvature(0.2, rr), rr)) \
        == pytest.approx(0.2, rel=1e-14)
    # a twist with V_x = R_r ω (no longitudinal slip): the deformation inputs are the PSA ones
    # converted by (2-101…2-104)
    omega, vy, bd, gamma = 60.0, -0.4, 0.3, 0.02
    twist = jnp.array([rr * omega, vy, 0.0, 0.0, 0.0, bd])
    dfm = C.deformation_inputs(twist, omega, gamma, rr)
    psa = C.psa_inputs(twist, omega, gamma, rr)
    assert float(dfm["kappa_p"]) == pytest.approx(0.0, abs=1e-15)
    assert float(psa["kappa"]) == pytest.approx(0.0, abs=1e-15)
    assert float(dfm["delta_p"]) == pytest.approx(float(C.delta_prime_from_slip_angle(
        psa["delta"], rr)), rel=1e-13)
    assert float(dfm["phi_p"]) == pytest.approx(float(C.phi_prime_from_curvature(psa["phi"], rr)),
                                                rel=1e-13)
    assert float(dfm["phibar_p"]) == pytest.approx(float(dfm["phi_p"]) - gamma)


def test_patch_geometry_trails():
    """(2-60…2-82) for a 195/65 R15 (R_L = 0.317 m) 15 mm deflected: |t_x| ≈ L/6 to within the
    next series term χ0²/15, e_r = t_x (2-82), R_r and t_z match their series, t_y ∝ γ."""
    R_L = 0.0254 * 15 / 2 + 0.65 * 0.195
    g = C.patch_geometry(R_L, R_L - 0.015, width=0.195, camber=0.02)
    chi = float(g["chi0"])
    L = float(g["length"])
    assert L == pytest.approx(2 * math.sqrt(R_L**2 - (R_L - 0.015) ** 2), rel=1e-13)
    assert abs(float(g["t_x"])) == pytest.approx(L / 6, rel=chi**2 / 15 + 1e-3)
    assert abs(abs(float(g["t_x"])) / (L / 6) - 1) < chi**2 / 10  # and not exactly L/6
    assert float(g["e_r"]) == pytest.approx(float(g["t_x"]), rel=1e-14)
    assert float(g["R_r"]) == pytest.approx(R_L * (1 - chi**2 / 6 + chi**4 / 120), rel=1e-6)
    assert float(g["t_z"]) == pytest.approx(R_L * (-chi**2 / 3 + chi**4 / 30), rel=1e-3)
    assert float(g["t_y"]) == pytest.approx(math.sin(0.02) * float(g["t_y_prime"]), rel=1e-14)
    M = C.pneumatic_matrix(1.0, 2.0, 3.0, g)
    assert M.shape == (3, 8)
    assert float(M[1, 2]) == pytest.approx(-float(g["t_x"]) * 2.0)
    # the lateral ("ballant") mode of §8.7: 150 kN/m on a 2 kg belt ≈ 43 Hz
    _, w0, zeta = C.modal(150e3, 20.0, 2.0)
    assert float(w0) / (2 * math.pi) == pytest.approx(43.6, abs=0.05)


@pytest.fixture(scope="module")
def frames():
    """Random wheel configurations (θ, ϕ, ξ, h, γ) → the tyre frame of Table 1's chain, and the
    ground plane it defines in R_pf, plus both estimators on it (one compiled program)."""
    rng = np.random.default_rng(7)
    n = 16
    cfg = np.stack([rng.uniform(-3, 3, n), rng.uniform(-0.05, 0.05, n),
                    rng.uniform(-1.0, 1.0, n), rng.uniform(-0.32, -0.25, n),
                    rng.uniform(-0.1, 0.1, n)], axis=1)

    @jax.jit
    def run(cfg):
        def one(c):
            th, ph, xi, h, g = c
            chain = mdh.tables.contact_chain(0.0)
            chain = mdh.Tree(chain.gamma, chain.b, chain.alpha, chain.d,
                             jnp.asarray(chain.theta).at[1].add(ph), chain.r, chain.antecedent,
                             chain.sigma, chain.variables, chain.labels)
            T = mdh.forward_kinematics(chain, jnp.stack([th, xi, h, g, 0 * h, 0 * h, 0 * h]))
            n, d = C.ground_plane(T[5])
            gen = C.tyre_frame(n, d, th, ph)
            # zero wobble: the same configuration without ϕ
            chain0 = mdh.tables.contact_chain(0.0)
            T0 = mdh.forward_kinematics(chain0, jnp.stack([th, xi, h, g, 0 * h, 0 * h, 0 * h]))
            n0, d0 = C.ground_plane(T0[5])
            zw = C.tyre_frame_zero_wobble(n0, d0, th)
            return T[5], gen, zw, C.wobble_rotation(th, ph), T[1]

        return jax.vmap(one)(cfg)

    return cfg, run(jnp.asarray(cfg))


def test_tyre_frame_estimators_recover_the_plane_and_camber(frames):
    """(2-8…2-22) with wobble and (2-23…2-29) without: ξ, h, γ and the whole ^{pf}T_p exactly
    (1e-12) from the ground plane of a known configuration (noise-free)."""
    cfg, (T, gen, zw, Rtw, T2) = frames
    th, ph, xi, h, g = cfg.T
    np.testing.assert_allclose(np.asarray(gen["gamma"]), g, atol=1e-12)
    np.testing.assert_allclose(np.asarray(gen["h"]), h, atol=1e-12)
    wrap = (np.asarray(gen["xi"]) - xi + np.pi) % (2 * np.pi) - np.pi
    np.testing.assert_allclose(wrap, 0.0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(gen["T_pf_p"]), np.asarray(T), atol=1e-12)
    np.testing.assert_allclose(np.asarray(zw["gamma"]), g, atol=1e-12)
    np.testing.assert_allclose(np.asarray(zw["h"]), h, atol=1e-12)
    wrap = (np.asarray(zw["xi"]) - xi + np.pi) % (2 * np.pi) - np.pi
    np.testing.assert_allclose(wrap, 0.0, atol=1e-12)
    # (2-8) as the chain's rows 1–2 give it (the printed one is not orthonormal)
    np.testing.assert_allclose(np.asarray(Rtw), np.transpose(np.asarray(T2)[:, :3, :3],
                                                             (0, 2, 1)), atol=1e-14)


def test_spec_errors_of_chapter_2(frames):
    """The source's misprints this module corrects (docstrings of `wobble_rotation`,
    `tyre_frame`, `tyre_frame_zero_wobble`): (2-8) as printed is not orthonormal; (2-20) as
    printed, ξ = atan2(s_z, −s_x), returns ξ + π; h is signed (the wheel centre above the
    ground: h < 0 along z_p here, and the estimators return it with its sign)."""
    cfg, (T, gen, zw, Rtw, T2) = frames
    th, ph, xi, h, g = cfg.T
    c, s = np.cos, np.sin
    printed = np.array([[[c(p) * c(t), s(p) * c(t), -s(p)], [-s(p), c(p), 0.0],
                         [c(p) * s(t), s(p) * s(t), c(t)]] for t, p in zip(th, ph, strict=True)])
    gram = np.einsum("kij,kil->kjl", printed, printed)
    assert np.all(np.abs(gram - np.eye(3)).max(axis=(1, 2)) > 1e-3)  # (2-8) not a rotation
    # x_p in R_tw: s = (cos ξ, 0, −sin ξ); (2-20) as printed is off by π, the module's is not
    sv = np.einsum("kij,kj->ki", np.asarray(Rtw), np.asarray(gen["T_pf_p"])[:, :3, 0])
    off = (np.arctan2(sv[:, 2], -sv[:, 0]) - xi) % (2 * np.pi)
    np.testing.assert_allclose(off, np.pi, atol=1e-12)
    assert np.all(h < 0) and np.all(np.asarray(gen["h"]) < 0) and np.all(np.asarray(zw["h"]) < 0)


def test_wrench_transform_and_wheel_inertia():
    """(2-31) as printed = 𝕋ᵀ of ^{pf}T_p (2-36) at zero wobble; the wheel-inertia regressor
    (2-30): a wheel of mass m, spin inertia I at rest under gravity, spinning up at θ̈."""

    @jax.jit
    def run():
        T = C.carrier_to_tyre(0.2, 0.05, -0.3)
        A = mdh.twist_transport(T).T
        B = C.wrench_transform_zero_wobble(0.2, 0.05, -0.3)
        D = C.wheel_inertia_regressor(0.3, 5.0, 2.0)
        return A, B, D

    A, B, D = run()
    np.testing.assert_allclose(np.asarray(A), np.asarray(B), atol=1e-15)
    m, inertia = 20.0, 1.2
    X = np.zeros(20)
    X[5], X[9] = inertia, m  # ZZ1 (spin axis z_1), M1
    wrench = np.asarray(D) @ X
    np.testing.assert_allclose(wrench, [0, 0, m * 9.81, 0, inertia * 2.0, 0], atol=1e-12)
    wp = C.wrench_to_tyre(jnp.array([1.0, 2.0, 3.0, 0.0, 0.0, 0.0]), C.carrier_to_tyre(
        0.0, 0.0, -0.3))
    np.testing.assert_allclose(np.asarray(wp), [1, 2, 3, -0.6, 0.3, 0], atol=1e-15)  # PO × F
    q = C.patch_flexibility(jnp.array([100.0, 200.0, 0, 0, 0, 5.0]), 2e5, 1.5e5, 1.5e4)
    np.testing.assert_allclose(np.asarray(q), [200 / 1.5e5, 100 / 2e5,
                                               (5 + (1 / 2e5 - 1 / 1.5e5) * 2e4) / 1.5e4])


def test_tyre_twist_equals_the_derivative_of_the_tyre_frame():
    """τ_p (2-44/2-46) from the carrier's twist and q̇_p = the twist of R_p obtained by
    differentiating its pose in the road frame (the carrier moving on a flat road)."""

    def carrier(t):  # ^rT_pf(t): a wheel carrier swerving, rolling and pitching
        yaw, roll, pitch = 0.3 * jnp.sin(t), 0.05 * jnp.cos(2 * t), 0.02 * t
        cy, sy, cr, sr, cp, sp = (jnp.cos(yaw), jnp.sin(yaw), jnp.cos(roll), jnp.sin(roll),
                                  jnp.cos(pitch), jnp.sin(pitch))
        Rz = jnp.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1.0]])
        Rx = jnp.array([[1.0, 0, 0], [0, cr, -sr], [0, sr, cr]])
        Ry = jnp.array([[cp, 0, sp], [0, 1.0, 0], [-sp, 0, cp]])
        p = jnp.array([20.0 * t, jnp.sin(t), 0.3 + 0.01 * jnp.sin(3 * t)])
        return Rz @ Ry @ Rx, p

    def tyre_pose(t):
        R, p = carrier(t)
        n = R.T @ jnp.array([0.0, 0, 1])
        d = -p[2] * 1.0  # OP·z_r with the road at z = 0
        d = jnp.dot(n, R.T @ (jnp.array([p[0], p[1], 0.0]) - p))
        f = C.tyre_frame_zero_wobble(n, d)
        qp = jnp.stack([f["xi_hat"], f["h"], f["gamma"]])
        Tp = C.carrier_to_tyre(qp[0], qp[2], qp[1])
        return R @ Tp[:3, :3], p + R @ Tp[:3, 3], qp

    @jax.jit
    def run(t):
        Rp, Pp, qp = tyre_pose(t)
        dR, dP, dq = jax.jacfwd(tyre_pose)(t)
        W = Rp.T @ dR
        expected = jnp.concatenate([Rp.T @ dP, jnp.array([W[2, 1], W[0, 2], W[1, 0]])])
        R, p = carrier(t)
        dRc, dp = jax.jacfwd(carrier)(t)
        Wc = R.T @ dRc
        twist_pf = jnp.concatenate([R.T @ dp, jnp.array([Wc[2, 1], Wc[0, 2], Wc[1, 0]])])
        return C.tyre_twist(twist_pf, qp, dq), expected

    for t in (0.3, 1.7):
        got, expected = run(t)
        np.testing.assert_allclose(np.asarray(got), np.asarray(expected), atol=1e-12)


def test_closed_forms_equal_the_chain():
    """The closed forms the batched pipeline uses = the MDH-chain versions."""
    rng = np.random.default_rng(11)
    tw, qp, qd = rng.normal(size=6), np.array([0.3, -0.29, 0.04]), rng.normal(size=3)
    wrench = rng.normal(size=6)

    @jax.jit
    def run(tw, qp, qd, wrench):
        T = C.carrier_to_tyre(qp[0], qp[2], qp[1])
        R, P = C.carrier_to_tyre_closed(qp[0], qp[2], qp[1])
        return (T, R, P, C.tyre_twist(tw, qp, qd), C.tyre_twist_zero_wobble(tw, qp, qd),
                C.wrench_to_tyre(wrench, T), C.wrench_to_tyre_closed(wrench, R, P))

    T, R, P, t1, t2, w1, w2 = run(tw, qp, qd, wrench)
    np.testing.assert_allclose(np.asarray(R), np.asarray(T[:3, :3]), atol=1e-15)
    np.testing.assert_allclose(np.asarray(P), np.asarray(T[:3, 3]), atol=1e-15)
    np.testing.assert_allclose(np.asarray(t2), np.asarray(t1), atol=1e-13)
    np.testing.assert_allclose(np.asarray(w2), np.asarray(w1), atol=1e-13)
