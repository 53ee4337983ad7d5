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
"""

import math
from collections.abc import Callable, Mapping

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..compilation import CPU_OPTIONS
from ..errors import ModelError
from .poly import PolynomialModel

__all__ = ["contact_deflection", "relaxation_gain", "relaxation_length", "lateral_mode_frequency",
           "stability_margin", "Simulation", "simulate", "output_equation"]


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
