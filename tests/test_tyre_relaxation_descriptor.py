"""The descriptor relaxation model (2-52…2-57) and the small-displacement matrices (3-34),
(3-35): against the first-order model where they coincide (closed-form step, an independent
SciPy integration of (3-84) on an Annex G tyre), against a NumPy linearisation written from
(3-34)/(3-35) (state, input and frequency response; a small step of the nonlinear model), and
its gradients against finite differences (spec: tyre §1.5, §3.1, §3.6).

Two solver programs (one flexible joint, three flexible joints), each compiled once for the
module and shared by the tests that use it."""

import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate
import scipy.linalg

from diffsusp.errors import ModelError
from diffsusp.tyre import annex_g, poly, relaxation

K_Y = annex_g.lateral_stiffness("dunlop_r16", 2.0, "Fy")          # 157 kN/m (Table 11)
K_X, K_BETA = 3.0e5, 5.0e3                                         # N/m, N·m/rad
OMEGA, FZ, R_R = 60.0, 4.5, 0.294
T_STEP, WIDTH = 0.01, 2e-4                                         # a smoothed step [s]


def _smooth_step(s):
    return 0.5 * (1.0 + jnp.tanh((s - T_STEP) / WIDTH))


def _lag_step(t, tau):
    """The response of a first-order lag of time constant τ to `_smooth_step`, in closed form
    after the step: the step's derivative is a logistic density of scale WIDTH/2, whose
    moment-generating function at 1/τ is πa/sin(πa), a = WIDTH/(2τ)."""
    a = WIDTH / (2 * tau)
    return 1.0 - jnp.exp(-(t - T_STEP) / tau) * jnp.pi * a / jnp.sin(jnp.pi * a)


class Step(eqx.Module):
    """Constant inputs and a smoothed step of δ′ at T_STEP; its numbers are data: one compiled
    program for every step of the module."""

    kappa: jax.Array = eqx.field(converter=jnp.asarray)
    delta: jax.Array = eqx.field(converter=jnp.asarray)
    phi: jax.Array = eqx.field(converter=jnp.asarray)
    step: jax.Array = eqx.field(converter=jnp.asarray)

    def __call__(self, s):
        return {"fz": FZ, "omega": OMEGA, "kappa": self.kappa,
                "delta": self.delta + self.step * _smooth_step(s), "phi": self.phi}


T = np.linspace(0.0, 0.12, 25)
DEGREES = {"Fy": {"delta": 7, "phi": 1, "one": 1}, "Mz": {"delta": 7, "phi": 1, "one": 1},
           "Fx": {"kappa": 1, "one": 1}}                  # one compiled shape for the module


def _pneu(values):
    return relaxation.PolynomialPneu(*(
        poly.PolynomialModel.create(o, DEGREES[o], values=values.get(o, {}))
        for o in ("Fy", "Mz", "Fx")))


# ---- one flexible joint: the first-order model ------------------------------------------------

STEP_Y = -0.004                                                     # δ′ step [m]
FX_OFFSET = -200.0                       # F_x = −200·F_z [N]: the F_x·F_y coupling of (3-51)
inputs_y = Step(0.0, 0.0, 0.0, STEP_Y)


def _linear_pneu(c_fy, c_mz):
    """F_pneu = c·F_z·δ′, and a constant F_x."""
    return _pneu({"Fy": {"b_Fy_delta_1_1": c_fy}, "Mz": {"b_Mz_delta_1_1": c_mz},
                  "Fx": {"b_Fx_one_1_1": FX_OFFSET}})


def _annex_g_pneu(tyre, pressure):
    """An Annex G model's δ′ response and offset (its whole response at φ′ = γ = 0), F_x = 0."""
    return _pneu({o: {k: v for k, v in annex_g.coefficients(tyre, pressure, o).items()
                      if poly.parse_name(k)[1] in ("delta", "one")} for o in ("Fy", "Mz")})


@pytest.fixture(scope="module")
def linear_y():
    c_fy, c_mz = -8e4, -500.0
    return c_fy, c_mz, relaxation.simulate_descriptor(_linear_pneu(c_fy, c_mz), inputs_y, T,
                                                      k_y=K_Y)


def test_one_joint_is_the_first_order_model(linear_y):
    """K_x = K_β = ∞, γ = 0: the descriptor model is (3-49…3-52). A step of δ′ on F_pneu =
    c·F_z·δ′ gives the first-order lag of time constant |L_Fy|/ω (3-50) in closed form; M_z is
    the first-order model's output (3-86, 3-87) with K_{Fy,y} = K_{Mz,y} = K_y, including the
    −K_y⁻¹·F_y·F_x of (3-51) (F_x ≠ 0 here); the state Jacobian is ω·K_y/(∂Fy_pneu/∂δ′), the A
    of (3-84); E of (2-55) has rank 1 and E·Ḟ_p = A·F_p + B·u (2-53)."""
    c_fy, c_mz, sim = linear_y
    assert bool(sim.ok) and sim.stable
    tau = abs(c_fy * FZ) / (OMEGA * K_Y)
    later = T > T_STEP + 20 * WIDTH
    ref = c_fy * FZ * STEP_Y * _lag_step(T[later], tau)
    np.testing.assert_allclose(sim.fy[later], ref, rtol=1e-7, atol=1e-6)
    delta = np.asarray(jax.vmap(inputs_y)(jnp.asarray(T))["delta"])
    fy_m = poly.PolynomialModel.create("Fy", {"delta": 1}, values={"b_Fy_delta_1_1": c_fy})
    mz_m = poly.PolynomialModel.create("Mz", {"delta": 1}, values={"b_Mz_delta_1_1": c_mz})
    np.testing.assert_allclose(sim.fx, FX_OFFSET * FZ, rtol=1e-12)
    mz_ref = relaxation.output_equation(sim.fy, {"fz": np.full(T.size, FZ), "delta": delta},
                                        fy_m, mz_m, K_Y, K_Y, fx=sim.fx)
    np.testing.assert_allclose(sim.mz, mz_ref, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(sim.q[:, 0], sim.fy / K_Y, rtol=1e-12)       # (2-41)
    np.testing.assert_allclose(sim.q[:, 1:], 0.0)
    np.testing.assert_allclose(sim.state_jacobian[:, 0, 0], OMEGA * K_Y / (c_fy * FZ),
                               rtol=1e-12)
    # the thesis's matrices (2-54…2-57) at a saved time of the transient
    model = relaxation.DescriptorModel.create(_linear_pneu(c_fy, c_mz), k_y=K_Y)
    k = 4
    f = jnp.array([sim.fx[k], sim.fy[k], sim.mz[k]])
    m, qdot = jax.jit(lambda f, q, s: (model.matrices(f, inputs_y(s)),
                                       model.rate(q, inputs_y(s))))(f, sim.q[k], T[k])
    e = np.asarray(m["E"])
    assert np.linalg.matrix_rank(e, tol=1e-12) == 1
    assert e[1, 1] == pytest.approx(c_fy * FZ / K_Y / OMEGA, rel=1e-12)    # L_Fy/ω (3-13)
    assert e[2, 1] == pytest.approx(c_mz * FZ / K_Y / OMEGA, rel=1e-12)    # L_Mz/ω
    fdot = np.array([0.0, float(qdot[0]) * K_Y, 0.0])
    np.testing.assert_allclose(e @ fdot, np.asarray(m["A"] @ f + m["Bu"]), atol=1e-6)
    np.testing.assert_allclose(np.asarray(m["C"][3:] @ f), np.asarray(m["q"]), atol=1e-15)


def test_one_joint_on_an_annex_g_tyre_against_scipy():
    """The Dunlop R16 at 2 bar (Annex G, nonlinear in δ′ with an offset): the descriptor model
    against an independent SciPy integration of the first-order model (3-84) in NumPy, F_y and
    M_z ((3-86), (3-87) with F_x = 0)."""
    pneu = _annex_g_pneu("dunlop_r16", 2.0)
    fy_m, mz_m = pneu.fy, pneu.mz
    sim = relaxation.simulate_descriptor(pneu, inputs_y, T, k_y=K_Y)
    assert bool(sim.ok) and sim.stable

    def response(model):         # F_pneu(δ′) at F_z, γ = φ′ = 0: the δ′ block and the offset
        c = model.input_polynomial(FZ, "delta")
        return np.polynomial.Polynomial(c) + model.input_polynomial(FZ, "one")[1]

    pf, pm = response(fy_m), response(mz_m)
    def delta(s):
        return STEP_Y * 0.5 * (1.0 + np.tanh((s - T_STEP) / WIDTH))

    def rhs(s, f):
        d = delta(s)
        return OMEGA * K_Y / pf.deriv()(d) * (f - pf(d))

    ref = scipy.integrate.solve_ivp(rhs, (0.0, T[-1]), [pf(0.0)], t_eval=T, rtol=1e-10,
                                    atol=1e-8, method="LSODA").y[0]
    np.testing.assert_allclose(sim.fy, ref, rtol=0, atol=1e-5 * np.max(np.abs(ref)))
    d = delta(T)
    mz_ref = pm(d) + pm.deriv()(d) / pf.deriv()(d) * (ref - pf(d))
    np.testing.assert_allclose(sim.mz, mz_ref, rtol=0, atol=1e-5 * np.max(np.abs(mz_ref)))
    # the time constant at δ′ = 0: the relaxation length over R_r·ω (spec §3.6)
    assert -1.0 / float(sim.state_jacobian[0, 0, 0]) == pytest.approx(
        float(relaxation.relaxation_length(fy_m, FZ, K_Y)[0]) / R_R / OMEGA, rel=1e-9)


def test_one_joint_gradients_against_finite_differences(linear_y):
    """∂F_y(t)/∂K_y and ∂F_y(t)/∂b_Fy_δ′_1_1 through the solver (forward mode, as a
    Levenberg–Marquardt Jacobian is built), against central differences of the compiled model
    and against the closed form."""
    c_fy, c_mz, _ = linear_y
    k = 6  # t = 0.03 s, inside the transient
    pneu = _linear_pneu(c_fy, c_mz)
    col = pneu.fy.names.index("b_Fy_delta_1_1")

    def fy_at(k_y, c, adjoint=None):
        p = eqx.tree_at(lambda p: p.fy.b, pneu, pneu.fy.b.at[col].set(c))
        return relaxation.simulate_descriptor(p, inputs_y, T, k_y=k_y, throw=False,
                                              adjoint=adjoint).fy[k]

    # one forward-mode pass along the direction (K_y, c) = (1, r): both partials from two
    # directions would be two passes; the closed form splits them (below)
    r = 3.0
    _, slope = jax.jvp(lambda k_y, c: fy_at(k_y, c, diffrax.ForwardMode()),
                       (jnp.asarray(K_Y), jnp.asarray(c_fy)), (jnp.asarray(1.0), jnp.asarray(r)))
    hk, hc = 1e-4 * K_Y, 1e-4 * abs(c_fy)
    fd_k = (fy_at(K_Y + hk, c_fy) - fy_at(K_Y - hk, c_fy)) / (2 * hk)
    fd_c = (fy_at(K_Y, c_fy + hc) - fy_at(K_Y, c_fy - hc)) / (2 * hc)
    assert float(slope) == pytest.approx(float(fd_k + r * fd_c), rel=1e-5)
    # and the closed form's, F = c·F_z·δ′·(1 − e^{−s/τ}·…), τ = |c·F_z|/(ω·K_y)
    closed = jax.grad(lambda k_y, c: c * FZ * STEP_Y * _lag_step(T[k], -c * FZ / (OMEGA * k_y)),
                      argnums=(0, 1))(K_Y, c_fy)
    np.testing.assert_allclose([float(fd_k), float(fd_c)], [float(g) for g in closed], rtol=1e-5)
    assert float(slope) == pytest.approx(float(closed[0] + r * closed[1]), rel=1e-5)


def test_beyond_the_grip_peak_and_not_index_one(linear_y):
    """∂Fy_pneu/∂δ′ > 0 (beyond the peak, spec §3.4): an error naming the instability (the
    same compiled program); K_x finite with F_x independent of κ′: the algebraic step is
    singular, reported before the solver is compiled; bad stiffnesses."""
    with pytest.raises(ModelError, match="unstable"):
        relaxation.simulate_descriptor(_linear_pneu(8e4, -500.0), inputs_y, T, k_y=K_Y)
    with pytest.raises(ModelError, match="not of index 1"):
        relaxation.simulate_descriptor(_linear_pneu(-8e4, -500.0), inputs_y, T, k_y=K_Y,
                                       k_x=K_X)
    with pytest.raises(ModelError, match="at least one finite"):
        relaxation.DescriptorModel.create(_linear_pneu(-8e4, -500.0), k_y=math.inf)
    with pytest.raises(ModelError, match="must be > 0"):
        relaxation.DescriptorModel.create(_linear_pneu(-8e4, -500.0), k_y=-1.0)


# ---- the small-displacement matrices ----------------------------------------------------------

def test_small_displacement_matrices_are_the_first_order_terms():
    """(3-34), (3-35): the first-order Taylor terms of the exact (2-45) transforms (jacfwd at
    q = 0), which they leave at second order; A = T⁻ᵀ keeps the power F·τ; the moment row of A
    is (y, x, 1), not the printed (−y, −x, 1) (the −K_y⁻¹·F_y·F_x of (3-51) follows from it,
    previous tests)."""
    exact = (relaxation.wrench_transform, relaxation.twist_transform, relaxation.joint_jacobian)

    @jax.jit
    def taylor(q):
        first = [e(jnp.zeros(3)) + jnp.einsum("ijk,k->ij", jax.jacfwd(e)(jnp.zeros(3)), q)
                 for e in exact]
        return first, [e(q) for e in exact], relaxation.small_displacement_matrices(q)

    q = jnp.array([0.004, -0.002, 0.003])
    first, full, small = taylor(q)
    for k in range(3):
        np.testing.assert_allclose(small[k], first[k], atol=1e-15)
        assert np.abs(np.asarray(full[k] - first[k])).max() < np.abs(np.asarray(q)).max() ** 2
    np.testing.assert_allclose(small[0][2], [0.004, -0.002, 1.0])
    f, tau = np.array([-800.0, 1400.0, 30.0]), np.array([17.6, -0.24, 0.05])
    assert (np.asarray(full[0]) @ f) @ (np.asarray(full[1]) @ tau) == pytest.approx(f @ tau,
                                                                                  rel=1e-14)


# ---- three flexible joints: the linearisation from (3-34), (3-35) ------------------------------

C_FX, C_FY, C_FY_PHI, C_MZ, C_MZ_PHI = -9e4, -8e4, 3e3, -500.0, -2e3       # per kN
U0 = {"fz": FZ, "kappa": 0.002, "delta": -0.004, "phi": 0.001, "omega": OMEGA}
STEP_3 = -2e-4                                                              # δ′ step [m]


def _three_pneu():
    return _pneu({"Fy": {"b_Fy_delta_1_1": C_FY, "b_Fy_phi_1_1": C_FY_PHI},
                  "Mz": {"b_Mz_delta_1_1": C_MZ, "b_Mz_phi_1_1": C_MZ_PHI},
                  "Fx": {"b_Fx_kappa_1_1": C_FX}})


inputs_3 = Step(U0["kappa"], U0["delta"], U0["phi"], STEP_3)


def _numpy_linear_model(q, f, steady=True):
    """The small-signal model at the steady state (q, F_p), written by hand from (3-34),
    (3-35) and G of (3-32) for the linear polynomials: δq̇ = 𝒜·δq + ℬ·δδ′, δF_p = 𝒞·δq, from
    A(q)·F − F_pneu − G·T(q)·J(q)·q̇ − G·(T(q) − I)·τ = 0 and J(q)ᵀ·F − K·q = 0. `steady`:
    check that (q, F_p) satisfies them with q̇ = 0."""
    y, x, b = q
    fx, fy, _ = f
    a = np.array([[1, b, 0], [-b, 1, 0], [y, x, 1]])                        # (3-34), corrected
    tm = np.array([[1, b, -y], [-b, 1, -x], [0, 0, 1]])
    jm = np.array([[0, 1, -y], [1, 0, x], [0, 0, 1]])                       # (3-35)
    g = np.array([[C_FX, 0, 0], [0, C_FY, C_FY_PHI], [0, C_MZ, C_MZ_PHI]]) * FZ / OMEGA
    tau = OMEGA * np.array([U0["kappa"] + R_R, U0["delta"], U0["phi"]])
    k = np.diag([K_Y, K_X, K_BETA])
    f_pneu = g @ (tau - [OMEGA * R_R, 0.0, 0.0])
    if steady:
        np.testing.assert_allclose(a @ f, f_pneu + g @ (tm - np.eye(3)) @ tau, atol=1e-8)
        np.testing.assert_allclose(jm.T @ f, k @ q, rtol=0, atol=1e-8)
    d_af = np.array([[0, 0, fy], [0, 0, -fx], [fx, fy, 0]])                 # ∂(A·F)/∂q
    d_tt = np.array([[-tau[2], 0, tau[1]], [0, -tau[2], -tau[0]], [0, 0, 0]])  # ∂(T·τ)/∂q
    d_jf = np.array([[0, 0, 0], [0, 0, 0], [-fx, fy, 0]])                   # ∂(Jᵀ·F)/∂q
    c = np.linalg.solve(jm.T, k - d_jf)                                      # δF = 𝒞·δq
    m = np.linalg.inv(g @ tm @ jm)
    state = m @ (a @ c + d_af - g @ d_tt)
    dp = np.array([0.0, C_FY, C_MZ]) * FZ + g @ (tm - np.eye(3)) @ [0.0, OMEGA, 0.0]
    return state, -m @ dp, c


@pytest.fixture(scope="module")
def three():
    """The small-signal models (exact and small-displacement) and a small δ′ step simulated
    with the small-displacement matrices."""
    out = {}
    linearise = eqx.filter_jit(lambda m: m.linearise(U0))     # one program for both
    for small in (False, True):
        model = relaxation.DescriptorModel.create(_three_pneu(), k_y=K_Y, k_x=K_X, k_beta=K_BETA,
                                                  small_displacement=small)
        out[small] = {k: np.asarray(v) for k, v in linearise(model).items()}
    out["sim"] = relaxation.simulate_descriptor(_three_pneu(), inputs_3, T, k_y=K_Y, k_x=K_X,
                                                k_beta=K_BETA, small_displacement=True)
    return out


def test_three_joints_jacobian_against_the_small_displacement_linearisation(three):
    """All three joints flexible (K_y, K_x, K_β): the descriptor model's state, input and output
    Jacobians (jax.jacfwd) at a steady state against the linear model written from (3-34),
    (3-35) in NumPy — exactly with the small-displacement matrices, within the size of q
    (1 %) with the exact (2-45) — and so their frequency responses; three stable modes."""
    for small, tol in ((True, 1e-9), (False, 1e-2)):
        lin = three[small]
        assert bool(lin["ok"])
        # the exact model's steady state differs at second order (β²·V_x·∂F_x/∂V_x ≈ 1 N)
        ref_state, ref_inp, ref_out = _numpy_linear_model(lin["q"], lin["F"], steady=small)
        state, inp, out = lin["state"], lin["input"][:, 1], lin["output"]
        np.testing.assert_allclose(state, ref_state, rtol=0, atol=tol * np.abs(ref_state).max())
        np.testing.assert_allclose(inp, ref_inp, rtol=0, atol=tol * np.abs(ref_inp).max())
        np.testing.assert_allclose(out, ref_out, rtol=0, atol=tol * np.abs(ref_out).max())
        np.testing.assert_allclose(lin["feedthrough"], 0.0, atol=1e-9)   # F_p = J⁻ᵀ·K·q
        for hz in (0.5, 3.0, 15.0):
            s = 2j * np.pi * hz
            h = out @ np.linalg.solve(s * np.eye(3) - state, inp)
            h_ref = ref_out @ np.linalg.solve(s * np.eye(3) - ref_state, ref_inp)
            np.testing.assert_allclose(h, h_ref, rtol=0, atol=tol * np.abs(h_ref).max())
        assert np.all(np.linalg.eigvals(state).real < 0)
    # the operating point is the thesis's small displacements: mm and mrad
    q = three[False]["q"]
    assert np.abs(q[:2]).max() < 0.02 and abs(q[2]) < 0.01


def test_three_joints_small_step_against_the_linear_model(three):
    """A step of −0.2 mm of δ′ at the operating point: the descriptor model integrated by
    diffrax (small-displacement matrices) against the step response of the NumPy linear model
    (scipy's expm) — F_x, F_y and M_z all relax, on the three modes."""
    sim, lin = three["sim"], three[True]
    assert bool(sim.ok) and sim.stable
    np.testing.assert_allclose(sim.state_jacobian[0], lin["state"], rtol=1e-9)
    f0 = lin["F"]
    state, inp, out = _numpy_linear_model(lin["q"], f0)
    np.testing.assert_allclose(np.array([sim.fx[0], sim.fy[0], sim.mz[0]]), f0, rtol=1e-9)
    later = T > T_STEP + 20 * WIDTH
    ref = np.array([f0 + out @ np.linalg.solve(state, scipy.linalg.expm(state * s) - np.eye(3))
                    @ inp * STEP_3 for s in T[later] - T_STEP])
    got = np.stack([sim.fx, sim.fy, sim.mz], axis=1)[later]
    change = np.abs(ref - f0).max(axis=0)
    assert np.all(change > [0.2, 20.0, 0.2])          # every component moves
    # to second order in the step (β·F_y: 1 % of F_x's small change)
    np.testing.assert_allclose(got[:, :2], ref[:, :2], rtol=0, atol=2e-4 * change[1])
    np.testing.assert_allclose(got[:, 2], ref[:, 2], rtol=0, atol=2e-3 * change[2])
