"""Contact-patch compliance and relaxation: q_AC, the just-necessary model, the simulation model.

spec: tyre §1.5 (2-37…2-41), §3.4 (3-48…3-52), §3.5 (3-76, 3-77), §3.6 (3-82…3-87), §7 D items 8
and 20. Units of the thesis (as `poly`): F_z kN, δ′ m, F N, M_z N·m, stiffnesses K_y, K_x in
N/m and K_β in N·m/rad, ω in rad/s, t in s.

- `contact_deflection` (2-41): q_AC = (y, x, β) of the flexible contact joints under the tyre
  wrench, static (the wheel-in-air modes of Table 3 are far above 15 Hz);
- `relaxation_gain` (3-50, 3-52): L_F = (∂F_pneu/∂δ′)·K_y⁻¹, the dimensionless relaxation
  "angle"; the relaxation length is σ = R_r·|L_Fy| (spec §3.6 digest check);
- `lateral_mode_frequency`: the lateral ("ballant") mode √(K_y/m)/2π of the belt mass (§3.4);
- `simulate` (3-82…3-87): the direct simulation model with one state F_y,
  Ḟy = ω·K_{Fy,y}·(∂Fy_pneu/∂δ′)⁻¹·(F_y − Fy_pneu), M_z = C·F_y + D·u, with **separate**
  K_{Fy,y} and K_{Mz,y}, integrated by diffrax (Tsit5, adaptive steps); **stability** needs
  ∂Fy_pneu/∂δ′ < 0 along the inputs (beyond peak grip the model is unstable: an error, or a
  flag with `throw=False`).

**The descriptor model** (2-52…2-57), restricted to (F_x, F_y, M_z) and (V_x, V_y, β̇) as in
§3.3.1 (3-9…3-15): the contact joints q = (y, x, β) of stiffnesses K_y, K_x, K_β (any of them
locked with `math.inf`, §3.4), the patch twist τ_AC = T(q)·(J(q)·q̇ + τ_p) (2-43), F_AC =
A(q)·F_p (2-42) and F_AC = F_pneu(τ_p) + G·Δτ_AC (2-50), G = ∂F_pneu/∂τ_AC (3-32):

    A(q)·F_p = F_pneu(τ_p) + G·T(q)·J(q)·q̇ + G·(T(q) − I)·τ_p,   J(q)ᵀ·F_p = K·q  (2-39)

- `twist_transform` T = ^{RAC}T_{Rp} (2-45), `joint_jacobian` J = ^pJ_p (2-38),
  `wrench_transform` A = ^{Rp}T_{RAC}ᵀ = T⁻ᵀ (the power F·τ is the same in both frames);
  `small_displacement_matrices` their first-order forms (3-34), (3-35);
- `PolynomialPneu`: F_pneu from the interaction polynomials; `patch_inputs`: their inputs;
- `DescriptorModel`: the model of one wheel; `matrices` gives the thesis's E, A, B·u, C at a
  force (2-53…2-57); `rate` the state derivative; `state_jacobian` its Jacobian (automatic
  differentiation): the local relaxation dynamics; `steady_state`; `linearise` the
  small-signal model (its frequency response);
- `simulate_descriptor`: the model integrated by diffrax.

*State.* The thesis writes the model on x = F_p, E·Ḟ_p = A·F_p + B·u (2-53), but E = G·T·J·K⁻¹·Jᵀ
(2-55) has the rank of the number of flexible joints (rank 1 for the just-necessary model, K_y
alone): it is a differential-algebraic system. The state here is the joints' positions q; at
each time F_p and q̇ solve the equation above and (2-39) on the flexible joints (q̇ = 0 on the
locked ones), which are **linear** in (F_p, q̇) at a given q: one 6-square solve, an index-1
system where that matrix is regular — every flexible joint must be driven by a column of G (K_x
with F_x independent of κ′ is not: `ModelError`). (2-39) is kept exactly, so q̇ is the exact
derivative of (2-41), where the thesis's (2-51) drops the (K_x⁻¹ − K_y⁻¹)·F_x·F_y term; E·Ḟ_p and
G·T·J·q̇ agree to first order. With K_x = K_β = ∞ and γ = 0 (or β̇ = 0) the model is the
first-order model (3-49…3-52) that `simulate` integrates, with K_{Fy,y} = K_{Mz,y} = K_y.

*Signs* (the thesis's misprints). (2-49) and (2-52) print Δτ_AC with T(q)ᵀ; (2-43), (2-55),
(3-13) and (3-14) have T(q): this module uses T(q). (3-34) prints the moment row of
^{Rp}T_{RAC}ᵀ as (−y, −x, 1); the transposed inverse of (2-45) is (y, x, 1) to first order, and
with (2-52) it gives M_z = Mz_pneu − F_y·F_x/K_y − F_x·F_y/K_x, the −K_y⁻¹·F_y·F_x of (3-51) —
the printed row would give +K_y⁻¹·F_y·F_x. (3-15) writes P_Fp = A − I where (2-52) gives I − A,
so that (3-38), (3-15) with the printed (3-34), has the sign of (3-51) in its third row and the
opposite sign of (2-45)'s rotation in its first two (to first order F_x = Fx_pneu − β·F_y).
"""

import math
from collections.abc import Callable, Mapping

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..compilation import CPU_OPTIONS
from ..errors import ModelError
from .poly import PolynomialModel, parse_name

__all__ = ["contact_deflection", "relaxation_gain", "relaxation_length", "lateral_mode_frequency",
           "stability_margin", "Simulation", "simulate", "output_equation", "twist_transform",
           "joint_jacobian", "wrench_transform", "small_displacement_matrices", "patch_inputs",
           "PolynomialPneu", "DescriptorModel", "DescriptorSimulation", "simulate_descriptor"]


def contact_deflection(fx: ArrayLike, fy: ArrayLike, mz: ArrayLike, *, k_y: ArrayLike,
                       k_x: ArrayLike, k_beta: ArrayLike) -> Float[Array, "... 3"]:
    """q_AC = (y, x, β) = (F_y/K_y, F_x/K_x, (M_z + (1/K_x − 1/K_y)·F_x·F_y)/K_β) (2-41).

    Forces [N], M_z [N·m], K_y, K_x [N/m], K_β [N·m/rad] → y, x [m], β [rad]. An infinite
    stiffness (a locked joint, §3.4) gives zero deflection."""
    fx, fy, mz = (jnp.asarray(v, dtype=float) for v in (fx, fy, mz))
    cx, cy, cb = (1.0 / jnp.asarray(k, dtype=float) for k in (k_x, k_y, k_beta))
    return jnp.stack([fy * cy, fx * cx, (mz + (cx - cy) * fx * fy) * cb], axis=-1)


def relaxation_gain(model: PolynomialModel, u: Mapping[str, ArrayLike], k_y: ArrayLike
                    ) -> Float[Array, " n"]:
    """L = (∂F_pneu/∂δ′)/K_y (3-50, 3-52), dimensionless (N/m over N/m)."""
    return model.pneu().derivative(u, "delta") / jnp.asarray(k_y, dtype=float)


def relaxation_length(model: PolynomialModel, fz: ArrayLike, k_y: ArrayLike,
                      rolling_radius: float = 0.294) -> Float[Array, " n"]:
    """σ = R_r·|L_Fy| at δ′ = 0 [m] (spec §3.6 digest check, §8 item 8); F_z [kN]."""
    fz = jnp.atleast_1d(jnp.asarray(fz, dtype=float))
    return rolling_radius * jnp.abs(relaxation_gain(model, {"fz": fz}, k_y))


def lateral_mode_frequency(k_y: float, mass: float) -> float:
    """√(K_y/m)/2π [Hz] of the lateral ("ballant") mode: K_y [N/m], belt mass m [kg] (§3.4)."""
    return math.sqrt(k_y / mass) / (2.0 * math.pi)


def stability_margin(fy_model: PolynomialModel, u: Mapping[str, ArrayLike]) -> Float[Array, " n"]:
    """∂Fy_pneu/∂δ′ [N/m] along the inputs: the simulation model is stable where it is < 0
    (spec §3.4: equivalently ∂F_y/∂δ > 0)."""
    return fy_model.pneu().derivative(u, "delta")


def output_equation(fy: ArrayLike, u: Mapping[str, ArrayLike], fy_model: PolynomialModel,
                    mz_model: PolynomialModel, k_fy: ArrayLike, k_mz: ArrayLike,
                    fx: ArrayLike = 0.0) -> Float[Array, " n"]:
    """M_z = C·F_y + D·u (3-82, the printed Ṁz is a typo, spec §0.5.6) with (3-86, 3-87):
    M_z = Mz_pneu + (K_Fy/K_Mz)·(∂Mz/∂δ′)/(∂Fy/∂δ′)·(F_y − Fy_pneu) − F_x·F_y/K_Mz."""
    fyp, mzp = fy_model.pneu(), mz_model.pneu()
    dfy = fyp.derivative(u, "delta")
    dmz = mzp.derivative(u, "delta")
    ratio = k_fy / k_mz * dmz / dfy
    return mzp(u) + ratio * (fy - fyp(u)) - jnp.asarray(fx) * fy / k_mz


class Simulation(eqx.Module):
    """The output of `simulate`: `t` [s], `fy` [N], `mz` [N·m], `fy_pneu`, `mz_pneu` (the
    steady-state values), `margin` (∂Fy_pneu/∂δ′ [N/m] at the saved times), `stable` (margin
    < 0 everywhere), `steps` (accepted solver steps), `ok` (the solver succeeded)."""

    t: Array
    fy: Array
    mz: Array
    fy_pneu: Array
    mz_pneu: Array
    margin: Array
    stable: Array
    steps: Array
    ok: Array


def simulate(fy_model: PolynomialModel, mz_model: PolynomialModel,
             inputs: Callable[[Array], dict], t: Float[Array, " n"], *, k_fy: ArrayLike,
             k_mz: ArrayLike, fx: Callable[[dict], Array] | None = None, rtol: float = 1e-8,
             atol: float = 1e-6, max_steps: int = 100_000, throw: bool = True) -> Simulation:
    """Integrate the simulation model (3-82…3-87) over the times `t` [s].

    **Arguments:** `fy_model`, `mz_model`: the interaction polynomials F_pneu (their Ly/P2
    columns, if any, are ignored); `inputs(t)` → dict with `fz` [kN], `delta` [m], `phi`,
    `gamma` [rad] and `omega` [rad/s] at a scalar time (smooth: the solver is adaptive);
    `k_fy`, `k_mz` [N/m] the lateral stiffnesses identified on F_y and on M_z; `fx(u)` the
    longitudinal force [N] (default 0; the just-necessary F_x = Fx_pneu(F_z), (3-48)).

    The state starts at its steady state F_y(t₀) = Fy_pneu(u(t₀)). With `throw=True` an input
    trajectory where ∂Fy_pneu/∂δ′ ≥ 0 (beyond the grip peak, spec §3.4) raises `ModelError`
    (and so does a failed solve); with `throw=False` the result carries `stable = False` (its
    values are then meaningless) and `ok`. Under `jit`/`vmap`, call with `throw=False`.
    """
    t = jnp.asarray(t, dtype=float)
    if isinstance(t, jax.core.Tracer) or not throw:
        return _simulate(fy_model, mz_model, inputs, t, k_fy, k_mz, fx, rtol, atol, max_steps)
    # One compiled program (the inputs are a Python function: one program per call), with
    # XLA's backend optimisation off (the solver's loop compiles 3× faster, runs once).
    options = {"xla_backend_optimization_level": 0}
    if jax.default_backend() == "cpu":
        options.update(CPU_OPTIONS)
    # the stability check first (a small program): no integration beyond the grip peak
    margin = jax.jit(lambda m, tt: m.pneu().derivative(jax.vmap(inputs)(tt), "delta"),
                     compiler_options=options)(fy_model, t)
    if bool(jnp.any(margin >= 0)):
        k = int(jnp.argmax(margin >= 0))
        u = inputs(t[k])
        raise ModelError(
            f"the simulation model is unstable: ∂Fy_pneu/∂δ′ = {float(margin[k]):.4g} N/m ≥ "
            f"0 at t = {float(t[k]):.4g} s (F_z = {float(u['fz']):.4g} kN, δ′ = "
            f"{1e3 * float(u['delta']):.4g} mm): the inputs go beyond the grip peak of "
            "the polynomial. Reduce the slip, or model the belt mass (spec §3.4).")
    sim = jax.jit(lambda a, b, c, d, e: _simulate(a, b, inputs, c, d, e, fx, rtol, atol,
                                                  max_steps),
                  compiler_options=options)(fy_model, mz_model, t, k_fy, k_mz)
    if not bool(sim.ok):
        raise ModelError(f"the simulation model's solver failed (max_steps = {max_steps} "
                         "reached?): loosen rtol/atol or raise max_steps.")
    return sim


def _simulate(fy_model, mz_model, inputs, t, k_fy, k_mz, fx, rtol, atol, max_steps):
    fyp, mzp = fy_model.pneu(), mz_model.pneu()
    u_all = jax.vmap(inputs)(t)
    margin = fyp.derivative(u_all, "delta")
    stable = jnp.all(margin < 0)

    def vector_field(s, y, args):
        u = _scalar_inputs(inputs(s))
        d = fyp.derivative(u, "delta")[0]
        # Beyond the grip peak the state is frozen: a finite, cheap (flagged) result.
        rate = u["omega"][0] * k_fy / jnp.where(d < 0, d, -1.0) * (y - fyp(u)[0])
        return jnp.where(d < 0, rate, 0.0)

    y0 = fyp(_scalar_inputs(inputs(t[0])))[0]
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(vector_field), diffrax.Tsit5(), t0=t[0], t1=t[-1], dt0=None, y0=y0,
        saveat=diffrax.SaveAt(ts=t), stepsize_controller=diffrax.PIDController(rtol=rtol,
                                                                              atol=atol),
        max_steps=max_steps, throw=False)
    fy = sol.ys
    fx_v = jnp.zeros_like(fy) if fx is None else jnp.broadcast_to(fx(u_all), fy.shape)
    mz = output_equation(fy, u_all, fyp, mzp, k_fy, k_mz, fx_v)
    return Simulation(t, fy, mz, fyp(u_all), mzp(u_all), margin, stable,
                      sol.stats["num_accepted_steps"], sol.result == diffrax.RESULTS.successful)


def _scalar_inputs(u):
    return {k: jnp.reshape(jnp.asarray(v, dtype=float), (1,)) for k, v in u.items()}


# ---- the descriptor model (2-52…2-57) ---------------------------------------------------------

_JOINTS = ("K_y", "K_x", "K_β")


def twist_transform(q: ArrayLike) -> Float[Array, "3 3"]:
    """T = ^{RAC}T_{Rp} (2-45) restricted to (V_x, V_y, β̇) (§3.3.1): the patch twist from the
    tyre frame's, at the joint positions q = (y, x, β) [m, m, rad], exact in β."""
    y, x, b = (jnp.asarray(q, dtype=float)[k] for k in range(3))
    c, s = jnp.cos(b), jnp.sin(b)
    return jnp.array([[c, s, -y * c + x * s], [-s, c, -x * c + y * s], [0.0, 0.0, 1.0]])


def joint_jacobian(q: ArrayLike) -> Float[Array, "3 3"]:
    """J = ^pJ_p (2-38) restricted to (V_x, V_y, β̇), one column per joint (y, x, β): the twist
    of the joints' motion. Linear in q: it is (3-35) exactly."""
    y, x, _ = (jnp.asarray(q, dtype=float)[k] for k in range(3))
    return jnp.array([[0.0, 1.0, -y], [1.0, 0.0, x], [0.0, 0.0, 1.0]])


def wrench_transform(q: ArrayLike) -> Float[Array, "3 3"]:
    """A = ^{Rp}T_{RAC}ᵀ (2-42, 2-54): F_AC = A·F_p on (F_x, F_y, M_z), the transposed inverse
    of `twist_transform` (the power F·τ is the same in both frames), exact in β."""
    tm = twist_transform(q)
    r, c = tm[:2, :2], tm[:2, 2]       # T = [[R, c], [0, 1]]: T⁻ᵀ = [[R, 0], [−cᵀR, 1]]
    return jnp.concatenate([jnp.concatenate([r, jnp.zeros((2, 1))], axis=1),
                            jnp.concatenate([-(c @ r), jnp.ones(1)])[None]])


def small_displacement_matrices(q: ArrayLike) -> tuple[Float[Array, "3 3"], Float[Array, "3 3"],
                                                        Float[Array, "3 3"]]:
    """The small-displacement forms (A, T, J) of (3-34), (3-35): the first-order terms in q of
    `wrench_transform`, `twist_transform` and `joint_jacobian` (J is linear),

        A = [[1, β, 0], [−β, 1, 0], [y, x, 1]],  T = [[1, β, −y], [−β, 1, −x], [0, 0, 1]],
        J = [[0, 1, −y], [1, 0, x], [0, 0, 1]].

    The moment row of A is printed (−y, −x, 1) in (3-34): that sign contradicts (2-45) and the
    −K_y⁻¹·F_y·F_x of (3-51) (module docstring)."""
    y, x, b = (jnp.asarray(q, dtype=float)[k] for k in range(3))
    a = jnp.array([[1.0, b, 0.0], [-b, 1.0, 0.0], [y, x, 1.0]])
    tm = jnp.array([[1.0, b, -y], [-b, 1.0, -x], [0.0, 0.0, 1.0]])
    return a, tm, joint_jacobian(q)


def patch_inputs(tau: ArrayLike, u: Mapping[str, ArrayLike], rolling_radius: float = 0.294
                 ) -> dict:
    """The polynomial model's inputs from a twist τ = (V_x, V_y, β̇) [m/s, m/s, rad/s] and `u`
    (`fz` [kN], `gamma` [rad], `omega` [rad/s]): κ′ = V_x/ω − R_r, δ′ = V_y/ω, φ′ = β̇/ω
    (2-92…2-95) and the camber products π(γ,V_x), π(γ,β̇), π(γ²,β̇) (spec §3.2)."""
    vx, vy, bd = (jnp.asarray(tau, dtype=float)[k] for k in range(3))
    w = jnp.asarray(u["omega"], dtype=float)
    g = jnp.asarray(u.get("gamma", 0.0), dtype=float)
    return {"fz": jnp.asarray(u["fz"], dtype=float), "kappa": vx / w - rolling_radius,
            "delta": vy / w, "phi": bd / w, "gamma": g, "pi_gamma_vx": g * vx / w,
            "pi_gamma_bdot": g * bd / w, "pi_gamma2_bdot": g * g * bd / w}


class PolynomialPneu(eqx.Module):
    """F_pneu(u) = (Fx_pneu, Fy_pneu, Mz_pneu) [N, N, N·m] at scalar inputs `u` (the keys of
    `patch_inputs`) from the interaction polynomials (3-16…3-18) (their Ly/P2 columns are
    ignored); `fx = None`: F_x = 0. A pytree: its coefficients are differentiable."""

    fy: PolynomialModel
    mz: PolynomialModel
    fx: PolynomialModel | None = None

    def __call__(self, u: Mapping[str, ArrayLike]) -> Float[Array, " 3"]:
        fx = jnp.zeros(()) if self.fx is None else _evaluate(self.fx, u)
        return jnp.stack([fx, _evaluate(self.fy, u), _evaluate(self.mz, u)])


def _evaluate(model, u):
    """Σ b·X^i·F_z^j over the interaction columns (3-22) at scalar inputs: the same value as
    `model.pneu()(u)`, written per block so that it traces in a few operations (the solver
    traces it once per stage)."""
    fz = jnp.asarray(u["fz"], dtype=float)
    blocks: dict[str, list[tuple[int, int, int]]] = {}
    for k, name in enumerate(model.names):
        _, block, i, j = parse_name(name)
        if block not in ("Ly", "P2"):
            blocks.setdefault(block, []).append((k, i, j))
    load = jnp.stack([jnp.ones_like(fz), fz, fz * fz, fz * fz * fz])
    total = jnp.zeros(())
    for block, cols in blocks.items():
        k, i, j = (np.array(c) for c in zip(*cols, strict=True))
        # c_i(F_z) = Σ_j b_ij·F_z^j, then Horner in X (products only: smooth to any order at
        # X = 0, where X**i's derivative rule is not)
        c = jnp.zeros(int(i.max()) + 1).at[i].add(model.b[k] * load[j])
        x = jnp.ones(()) if block == "one" else jnp.asarray(u.get(block, 0.0), dtype=float)
        value = jnp.zeros(())
        for ci in c[::-1]:
            value = value * x + ci
        total = total + value
    return total


class DescriptorModel(eqx.Module):
    """The descriptor relaxation model (2-52…2-57) of one wheel (module docstring).

    **Fields:** `pneu(u)` → (Fx, Fy, Mz)_pneu [N, N, N·m] at scalar inputs u (the keys of
    `patch_inputs`; e.g. `PolynomialPneu`); `stiffness` (K_y, K_x, K_β) [N/m, N/m, N·m/rad],
    `inf` for a locked joint (§3.4); `small_displacement` (a boolean array: the matrices of
    (3-34), (3-35) instead of the exact (2-45)); static: `rolling_radius` R_r [m] (τ_p =
    ω·(κ′ + R_r, δ′, φ′)). Which joints are locked and which matrices are used are data, not
    structure: one compiled program serves every configuration. Build with `create`.

    The state is q = (y, x, β) [m, m, rad]; a locked joint stays at 0 (q̇ = 0 replaces its
    row of (2-39)). The inputs `u` of the methods: `fz` [kN], `omega` [rad/s], and `kappa` κ′,
    `delta` δ′ [m], `phi` φ′, `gamma` [rad] (0 when absent), scalars.
    """

    pneu: Callable
    stiffness: Float[Array, " 3"]
    small_displacement: Array
    rolling_radius: float = eqx.field(static=True, default=0.294)

    @classmethod
    def create(cls, pneu: Callable, *, k_y: ArrayLike, k_x: ArrayLike = math.inf,
               k_beta: ArrayLike = math.inf, rolling_radius: float = 0.294,
               small_displacement: bool = False) -> "DescriptorModel":
        """The model with stiffnesses K_y, K_x [N/m], K_β [N·m/rad] (`math.inf` locks a joint);
        at least one finite, each > 0 (checked where they are concrete)."""
        ks = (k_y, k_x, k_beta)
        concrete = [None if isinstance(k, jax.core.Tracer) else float(np.asarray(k)) for k in ks]
        if all(k is not None and math.isinf(k) for k in concrete):
            raise ModelError("the descriptor model needs at least one finite contact "
                             "stiffness: with all three locked, F_p = F_pneu and E = 0 (2-55), "
                             "there are no dynamics")
        for name, k in zip(_JOINTS, concrete, strict=True):
            if k is not None and not k > 0:
                raise ModelError(f"{name} = {k!r}: a contact stiffness must be > 0 (math.inf "
                                 "locks the joint)")
        return cls(pneu, jnp.stack([jnp.asarray(k, dtype=float) for k in ks]),
                   jnp.asarray(bool(small_displacement)), float(rolling_radius))

    @property
    def flexible(self) -> Array:
        """Which joints of (y, x, β) have a finite stiffness."""
        return jnp.isfinite(self.stiffness)

    def twist(self, u: Mapping) -> Float[Array, " 3"]:
        """τ_p = ω·(κ′ + R_r, δ′, φ′) = (V_x, V_y, β̇) [m/s, m/s, rad/s] (2-92…2-95)."""
        get = lambda k: jnp.asarray(u.get(k, 0.0), dtype=float)  # noqa: E731
        return get("omega") * jnp.stack([get("kappa") + self.rolling_radius, get("delta"),
                                         get("phi")])

    def interaction(self, u: Mapping) -> tuple[Float[Array, " 3"], Float[Array, "3 3"]]:
        """F_pneu(τ_p) and G = ∂F_pneu/∂τ_AC at τ_p (3-32), by automatic differentiation of
        `pneu` (so with the camber-product columns of (3-33) where `pneu` has them)."""
        def f(tau):
            return self.pneu(patch_inputs(tau, u, self.rolling_radius))
        tau = self.twist(u)
        return f(tau), jax.jacfwd(f)(tau)

    def transforms(self, q: ArrayLike) -> tuple[Array, Array, Array]:
        """(A, T, J) at q = (y, x, β): exact (2-45), or (3-34), (3-35) with
        `small_displacement`."""
        exact = (wrench_transform(q), twist_transform(q), joint_jacobian(q))
        small = small_displacement_matrices(q)
        return tuple(jnp.where(self.small_displacement, b, a)
                     for a, b in zip(exact, small, strict=True))

    def deflection(self, f_p: ArrayLike) -> Float[Array, " 3"]:
        """q = (y, x, β) under F_p = (F_x, F_y, M_z) (2-41) (0 on a locked joint)."""
        fx, fy, mz = (jnp.asarray(f_p, dtype=float)[k] for k in range(3))
        return contact_deflection(fx, fy, mz, k_y=self.stiffness[0], k_x=self.stiffness[1],
                                  k_beta=self.stiffness[2])

    def _system(self, q, u):
        """The 6-square linear system in (F_p, q̇) at q and its right-hand side."""
        fpn, g = self.interaction(u)
        a, tm, jm = self.transforms(q)
        flex = self.flexible
        k = jnp.where(flex, self.stiffness, 1.0)
        # rows of (2-39) for the flexible joints, q̇_j = 0 for the locked ones
        joints = jnp.where(flex[:, None], jnp.concatenate([jm.T, jnp.zeros((3, 3))], axis=1),
                           jnp.concatenate([jnp.zeros((3, 3)), jnp.eye(3)], axis=1))
        mat = jnp.concatenate([jnp.concatenate([a, -g @ tm @ jm], axis=1), joints])
        rhs = jnp.concatenate([fpn + g @ (tm - jnp.eye(3)) @ self.twist(u),
                               jnp.where(flex, k * q, 0.0)])
        return mat, rhs

    def solve(self, q: ArrayLike, u: Mapping) -> tuple[Float[Array, " 3"], Float[Array, " 3"]]:
        """F_p [N, N, N·m] and q̇ at the joint positions q and inputs u: A·F_p − G·T·J·q̇ =
        F_pneu + G·(T − I)·τ_p (2-52) and (Jᵀ·F_p)_j = K_j·q_j (2-39) on the flexible joints."""
        mat, rhs = self._system(jnp.asarray(q, dtype=float), u)
        z = jnp.linalg.solve(mat, rhs)
        return z[:3], z[3:]

    def rate(self, q: ArrayLike, u: Mapping) -> Float[Array, " 3"]:
        """q̇, the state derivative [m/s, m/s, rad/s] (0 on a locked joint)."""
        return self.solve(q, u)[1]

    def state_jacobian(self, q: ArrayLike, u: Mapping) -> Float[Array, "3 3"]:
        """∂q̇/∂q [1/s] at (q, u): the local relaxation dynamics, whose eigenvalues on the
        flexible joints are −1/(time constants); with K_y alone, ω·K_y/(∂Fy_pneu/∂δ′) (3-84).
        Rows and columns of locked joints are 0."""
        jac = jax.jacfwd(self.rate)(jnp.asarray(q, dtype=float), u)
        return jnp.where(self.flexible[:, None] & self.flexible[None, :], jac, 0.0)

    def condition(self, q: ArrayLike, u: Mapping) -> Array:
        """Condition number of the algebraic step's matrix at (q, u), columns scaled to unit
        norm: moderate where the system is of index 1 (every flexible joint driven by a column
        of G), huge where it is not (e.g. K_x finite and F_x independent of κ′)."""
        mat, _ = self._system(jnp.asarray(q, dtype=float), u)
        mat = mat / jnp.maximum(jnp.linalg.norm(mat, axis=0), 1e-300)
        sv = jnp.linalg.svd(mat, compute_uv=False)
        return sv[0] / sv[-1]

    def steady_state(self, u: Mapping, iterations: int = 5) -> tuple[Float[Array, " 3"], Array]:
        """q with q̇ = 0 at the inputs u, and whether it converged (last Newton step below
        1e-9 of q, or below 1e-15).

        Newton from the deflection (2-41) under F_pneu, a fixed count of steps: the equations
        are linear in F_p and depend on q only through the small displacements of (2-45), so
        Newton converges quadratically from there (to the last digits in 3 steps); a fixed loop
        traces once and compiles in a fraction of a general root finder's time, and its
        derivative (unrolled) converges with it."""
        fpn, _ = self.interaction(u)
        q0 = self.deflection(fpn)
        locked = jnp.diag(jnp.where(self.flexible, 0.0, 1.0))   # q̇ ≡ 0 there: keep q = 0

        def step(_, carry):
            q, _ = carry
            dq = -jnp.linalg.solve(self.state_jacobian(q, u) + locked, self.rate(q, u))
            return q + dq, dq
        q, dq = jax.lax.fori_loop(0, iterations, step, (q0, jnp.full_like(q0, jnp.inf)))
        return q, jnp.all(jnp.abs(dq) <= 1e-9 * jnp.abs(q) + 1e-15)

    def matrices(self, f_p: ArrayLike, u: Mapping) -> dict[str, Array]:
        """The thesis's matrices at F_p (2-53…2-57), q from (2-41): `E` = G·T·J·K⁻¹·Jᵀ, `A`,
        `Bu` = B·[F_pneu; τ_p] = −F_pneu − G·(T − I)·τ_p (so E·Ḟ_p = A·F_p + Bu), `C` = [I;
        K⁻¹·Jᵀ] (6 × 3: F_p and q from F_p), and `G`, `T`, `J`, `q`."""
        f_p = jnp.asarray(f_p, dtype=float)
        fpn, g = self.interaction(u)
        q = self.deflection(f_p)
        a, tm, jm = self.transforms(q)
        comp = 1.0 / self.stiffness
        return {"E": g @ tm @ jm @ jnp.diag(comp) @ jm.T, "A": a,
                "Bu": -fpn - g @ (tm - jnp.eye(3)) @ self.twist(u),
                "C": jnp.concatenate([jnp.eye(3), comp[:, None] * jm.T]), "G": g, "T": tm,
                "J": jm, "q": q}

    def linearise(self, u: Mapping, keys: tuple[str, ...] = ("kappa", "delta", "phi")
                  ) -> dict[str, Array]:
        """The small-signal model at the steady state of the inputs u (by automatic
        differentiation): δq̇ = `state`·δq + `input`·δu, δF_p = `output`·δq + `feedthrough`·δu,
        δu the inputs `keys`; with `q`, `F` the operating point and `ok`. Its transfer function
        `output`·(sI − `state`)⁻¹·`input` + `feedthrough` (on the flexible joints) is the
        frequency response of the relaxation; with `small_displacement` it is the linear model
        of (3-34), (3-35)."""
        q, ok = self.steady_state(u)

        def with_inputs(v):
            return {**u, **dict(zip(keys, v, strict=True))}
        v0 = jnp.stack([jnp.asarray(u.get(k, 0.0), dtype=float) for k in keys])
        return {"q": q, "F": self.solve(q, u)[0], "ok": ok,
                "state": self.state_jacobian(q, u),
                "input": jax.jacfwd(lambda v: self.rate(q, with_inputs(v)))(v0),
                "output": jax.jacfwd(lambda qq: self.solve(qq, u)[0])(q),
                "feedthrough": jax.jacfwd(lambda v: self.solve(q, with_inputs(v))[0])(v0)}


class DescriptorSimulation(eqx.Module):
    """The output of `simulate_descriptor`: `t` [s], `fx`, `fy` [N], `mz` [N·m] (F_p), `q` (n, 3)
    the joint positions (y, x, β) [m, m, rad], `fpneu` (n, 3) the interaction forces,
    `state_jacobian` (n, 3, 3) ∂q̇/∂q [1/s] along the trajectory, `flexible` (3,) the joints
    not locked, `condition` of the algebraic step at t₀ (huge: not of index 1), `steps`, `ok`
    (solver, steady start and index-1 check succeeded). `max_eigenvalue` (NumPy) the largest
    real part of the eigenvalues of ∂q̇/∂q on the flexible joints over the times, `stable`
    (< 0)."""

    t: Array
    fx: Array
    fy: Array
    mz: Array
    q: Array
    fpneu: Array
    state_jacobian: Array
    flexible: Array
    condition: Array
    steps: Array
    ok: Array

    @property
    def max_eigenvalue(self) -> float:
        idx = np.flatnonzero(np.asarray(self.flexible))
        jac = np.asarray(self.state_jacobian)[:, idx][:, :, idx]
        return float(np.max(np.real(np.linalg.eigvals(jac))))

    @property
    def stable(self) -> bool:
        return self.max_eigenvalue < 0


def simulate_descriptor(pneu: Callable, inputs: Callable[[Array], dict], t: Float[Array, " n"],
                        *, k_y: ArrayLike, k_x: ArrayLike = math.inf,
                        k_beta: ArrayLike = math.inf, rolling_radius: float = 0.294,
                        small_displacement: bool = False, rtol: float = 1e-8,
                        atol: float = 1e-12, max_steps: int = 100_000, throw: bool = True,
                        adjoint: diffrax.AbstractAdjoint | None = None
                        ) -> DescriptorSimulation:
    """Integrate the descriptor relaxation model (2-52…2-57) over the times `t` [s] (module
    docstring) by diffrax (Tsit5, adaptive steps; the state is the joints' positions).

    **Arguments:** `pneu(u)` → (Fx, Fy, Mz)_pneu [N, N, N·m] (e.g. `PolynomialPneu`); `inputs(t)`
    → dict `fz` [kN], `omega` [rad/s], `kappa` κ′, `delta` δ′ [m], `phi` φ′, `gamma` [rad] at a
    scalar time (smooth: the solver is adaptive). One compiled program serves every call with
    the same `pneu` structure, the same `inputs` (an `eqx.Module` with array fields is data:
    new values do not recompile) and the same number of times; the stiffnesses are data too.
    `k_y`, `k_x` [N/m], `k_beta` [N·m/rad] the contact stiffnesses (`math.inf` locks a joint:
    K_x = K_β = ∞ is the first-order model (3-49…3-52)); `rolling_radius` R_r [m];
    `small_displacement`: the matrices of (3-34), (3-35). `atol` is on the joint positions [m,
    rad]; `adjoint`: diffrax's, for derivatives through the solver (`diffrax.ForwardMode()`
    for `jax.jvp`/`jax.jacfwd`, as a Levenberg–Marquardt Jacobian builds them; the default,
    `RecursiveCheckpointAdjoint`, for `jax.grad`). The state starts at its steady state at t₀.

    With `throw=True`: a system that is not of index 1 at t₀ (a flexible joint that no column
    of G drives, e.g. K_x finite with F_x independent of κ′), a failed solve and an unstable
    result (∂q̇/∂q with an eigenvalue ≥ 0: beyond the grip peak) raise `ModelError`. Under
    `jit`/`grad` call with `throw=False` and read `ok` and `stable`.
    """
    t = jnp.asarray(t, dtype=float)
    model = DescriptorModel.create(pneu, k_y=k_y, k_x=k_x, k_beta=k_beta,
                                   rolling_radius=rolling_radius,
                                   small_displacement=small_displacement)
    traced = any(isinstance(v, jax.core.Tracer) for v in jax.tree.leaves((model, inputs, t)))
    if throw and not traced:
        # the index-1 check first, at the deflection under F_pneu (a small program): a
        # singular system is reported before the solver runs
        condition = float(_initial_condition(model, inputs, t[0]))
        if not condition < 1e12:
            names = [n for n, f in zip(_JOINTS, np.asarray(model.flexible), strict=True) if f]
            raise ModelError(
                f"the descriptor model with flexible joints {names} is not of index 1 at t = "
                f"{float(t[0]):.4g} s (condition {condition:.3g}): a flexible joint is not "
                "driven by the interaction model's Jacobian G (e.g. K_x with F_x independent "
                "of κ′). Lock that joint (math.inf), as the thesis does (Table 7, §3.4).")
    sim = _simulate_descriptor(model, inputs, t, float(rtol), float(atol), int(max_steps),
                               diffrax.RecursiveCheckpointAdjoint() if adjoint is None
                               else adjoint)
    if not throw or traced:
        return sim
    if not bool(sim.ok):
        raise ModelError(f"the descriptor model's solver failed (max_steps = {max_steps} "
                         "reached, or no steady state at t₀): loosen rtol/atol, raise "
                         "max_steps, or start the inputs inside the grip peak.")
    if not sim.stable:
        raise ModelError(
            f"the descriptor model is unstable: ∂q̇/∂q has an eigenvalue {sim.max_eigenvalue:.4g}"
            " 1/s ≥ 0 along the inputs (beyond the grip peak, spec §3.4): reduce the slip, or "
            "model the belt mass.")
    return sim


@eqx.filter_jit
def _initial_condition(model, inputs, t0):
    u0 = inputs(t0)
    return model.condition(model.deflection(model.interaction(u0)[0]), u0)


@eqx.filter_jit
def _simulate_descriptor(model, inputs, t, rtol, atol, max_steps, adjoint):
    u0 = inputs(t[0])
    q0, steady = model.steady_state(u0)
    condition = model.condition(q0, u0)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(lambda s, q, _: model.rate(q, inputs(s))), diffrax.Tsit5(), t0=t[0],
        t1=t[-1], dt0=None, y0=q0, saveat=diffrax.SaveAt(ts=t),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
        max_steps=max_steps, adjoint=adjoint, throw=False)
    u_all = jax.vmap(inputs)(t)
    f, _ = jax.vmap(model.solve)(sol.ys, u_all)
    fpn = jax.vmap(lambda u: model.interaction(u)[0])(u_all)
    # the stability diagnostic carries no derivative (a derivative through the solver would
    # otherwise trace ∂F_pneu/∂τ to third order)
    still = jax.lax.stop_gradient((model, sol.ys, u_all))
    jac = jax.vmap(still[0].state_jacobian)(still[1], still[2])
    ok = ((sol.result == diffrax.RESULTS.successful) & steady & (condition < 1e12)
          & jnp.all(jnp.isfinite(f)))
    return DescriptorSimulation(t, f[:, 0], f[:, 1], f[:, 2], sol.ys, fpn, jac, model.flexible,
                                condition, sol.stats["num_accepted_steps"], ok)
