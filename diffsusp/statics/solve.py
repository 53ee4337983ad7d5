"""Static equilibrium: damped Newton on the KKT system, batched, with implicit differentiation.

spec: stiffness §1.9 (Q_ext + Q_int + Φ_qᵀλ = 0, Φ = c); DESIGN.md "Static equilibrium".

Per load case: multipliers initialised by weighted least squares at the start pose; each Newton
step solves the KKT system after Ruiz row/column equilibration (forces in N, moments in N·mm and
constraint rows in mm or radians differ by orders of magnitude); the step is capped so no Gibbs
vector moves by more than 0.5 at once and backtracked on a scaled merit function. A case has
converged when every force row is below `rtol`·F_s (moment rows `rtol`·F_s·L, with F_s the load
scale and L the model's length scale) and every constraint row below `atol` mm.

The solution is differentiated implicitly: for a parameter tangent dθ, dy = −J⁻¹ ∂r/∂θ·dθ at the
solution (one more linear solve), in forward and reverse mode; the Newton loop is never unrolled.
"""

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ..errors import ConvergenceError
from ..model.mechanism import Loads, Mechanism
from .kernel import assemble, get_layout

SUCCESS, MAX_STEPS, NONFINITE = 0, 1, 2
STATUS_TEXT = {SUCCESS: "converged", MAX_STEPS: "max_steps reached", NONFINITE: "non-finite"}


class StaticSolution(eqx.Module):
    """Equilibria of a table of load cases (leading axis = case, absent for a single case).

    **Fields:** `q` (mm and Gibbs vectors, 6 per part), `multipliers` (one per independent
    constraint row: N for length rows, N·mm for angular rows), `status` (0 converged,
    1 max_steps reached, 2 non-finite), `iterations`, `residual` (largest force row relative to
    the load scale), `constraint_error` (mm).
    """

    q: Float[Array, "*cases n"]
    multipliers: Float[Array, "*cases m"]
    status: Int[Array, "*cases"]
    iterations: Int[Array, "*cases"]
    residual: Float[Array, "*cases"]
    constraint_error: Float[Array, "*cases"]

    @property
    def converged(self):
        return self.status == SUCCESS


def _ruiz(jac, sweeps: int = 3):
    """Row and column scalings (d_r, d_c) with diag(d_r)·J·diag(d_c) equilibrated."""
    d_r = jnp.ones(jac.shape[0], jac.dtype)
    d_c = jnp.ones(jac.shape[1], jac.dtype)
    a = jnp.abs(jac)
    for _ in range(sweeps):
        s = a * d_r[:, None] * d_c[None, :]
        d_r = d_r / jnp.sqrt(jnp.maximum(jnp.max(s, axis=1), 1e-300))
        s = a * d_r[:, None] * d_c[None, :]
        d_c = d_c / jnp.sqrt(jnp.maximum(jnp.max(s, axis=0), 1e-300))
    return d_r, d_c


def _scaled_solve(jac, rhs):
    d_r, d_c = _ruiz(jax.lax.stop_gradient(jac))
    return d_c * jnp.linalg.solve(jac * d_r[:, None] * d_c[None, :], d_r * rhs)


class _Weights(eqx.Module):
    """Per-row scales of the residual: tolerances and the merit function derive from these."""

    force: Array  # (n + m,) multiply the residual to get "relative force" rows (forces only)
    constraint: Array  # (n + m,) multiply to get constraint rows in mm
    is_force: Array


def _weights(mech: Mechanism, loads: Loads, lam0, jac0):
    lay = get_layout(mech)
    n, m = lay.n, lay.m
    length = mech.length_scale
    rot_col = np.tile(np.r_[np.zeros(3), np.ones(3)], n // 6).astype(bool)
    reaction = jac0[n:, :n].T @ lam0
    f_scale = (
        1.0
        + jnp.max(jnp.abs(loads.force), initial=0.0)
        + jnp.max(jnp.abs(loads.moment), initial=0.0) / length
        + jnp.max(jnp.abs(jnp.where(rot_col, 0.0, reaction)), initial=0.0)
    )
    force_w = jnp.concatenate([jnp.where(rot_col, 1.0 / (f_scale * length), 1.0 / f_scale),
                              jnp.zeros(m)])
    constraint_w = jnp.concatenate(
        [jnp.zeros(n), jnp.asarray(np.where(lay.angular_live, length, 1.0))]
    )
    return _Weights(force=force_w, constraint=constraint_w,
                    is_force=jnp.asarray(np.r_[np.ones(n), np.zeros(m)].astype(bool)))


def _measures(r, w: _Weights, length):
    force = jnp.max(jnp.abs(r * w.force), initial=0.0)
    constraint = jnp.max(jnp.abs(r * w.constraint), initial=0.0)
    merit = 0.5 * (jnp.sum((r * w.force) ** 2) + jnp.sum((r * w.constraint / length) ** 2))
    return force, constraint, merit


def _initial_multipliers(jac, r, n, length, angular):
    """Weighted least squares for λ at the start pose: min ‖W(Q + Φ_qᵀλ)‖ (W: moments / L)."""
    a = jac[n:, :n]  # Φ_q (m, n)
    col_w = jnp.asarray(np.tile(np.r_[np.ones(3), np.full(3, 1.0 / length)], n // 6))
    row_s = jnp.asarray(np.where(angular, 1.0 / length, 1.0))  # λ in N for every row
    a_s = a * row_s[:, None] * col_w[None, :]
    rhs = -(r[:n] * col_w)
    normal = a_s @ a_s.T
    d = 1.0 / jnp.sqrt(jnp.maximum(jnp.diag(normal), 1e-300))
    lam_s = d * jnp.linalg.solve(normal * d[:, None] * d[None, :], d * (a_s @ rhs))
    return lam_s * row_s


def _newton(mech: Mechanism, loads: Loads, q0, *, rtol, atol, max_steps):
    lay = get_layout(mech)
    n, m = lay.n, lay.m
    length = mech.length_scale
    r0, jac0 = assemble(mech, loads, q0, jnp.zeros(m, q0.dtype))
    lam0 = (
        _initial_multipliers(jac0, r0, n, length, lay.angular_live) if m else jnp.zeros(0)
    )
    w = _weights(mech, loads, lam0, jac0)
    rot = jnp.asarray(np.r_[np.tile(np.r_[np.zeros(3), np.ones(3)], n // 6), np.zeros(m)])

    def evaluate(y):
        return assemble(mech, loads, y[:n], y[n:])

    def residual(y):
        return assemble(mech, loads, y[:n], y[n:], with_jacobian=False)[0]

    y0 = jnp.concatenate([q0, lam0])
    r, jac = evaluate(y0)

    def done(r):
        force, constraint, _ = _measures(r, w, length)
        return (force <= rtol) & (constraint <= atol)

    def cond(state):
        y, r, jac, it, status = state
        return (it < max_steps) & (status == MAX_STEPS) & ~done(r)

    def body(state):
        y, r, jac, it, status = state
        dy = _scaled_solve(jac, -r)
        cap = jnp.max(jnp.abs(dy * rot))
        dy = dy * jnp.minimum(1.0, 0.5 / jnp.maximum(cap, 1e-300))
        _, _, merit0 = _measures(r, w, length)

        def ls_cond(carry):
            alpha, merit_new, k = carry
            return (k < 12) & ~(merit_new <= (1.0 - 1e-4 * alpha) * merit0)

        def ls_body(carry):
            alpha, _, k = carry
            alpha = 0.5 * alpha
            return alpha, _measures(residual(y + alpha * dy), w, length)[2], k + 1

        merit1 = _measures(residual(y + dy), w, length)[2]
        merit1 = jnp.where(jnp.isfinite(merit1), merit1, jnp.inf)
        alpha, _, _ = jax.lax.while_loop(ls_cond, ls_body, (jnp.asarray(1.0), merit1, 0))
        y_new = y + alpha * dy
        r_new, jac_new = evaluate(y_new)
        finite = jnp.all(jnp.isfinite(r_new)) & jnp.all(jnp.isfinite(jac_new))
        status = jnp.where(finite, status, NONFINITE)
        return y_new, r_new, jac_new, it + 1, status

    state = (y0, r, jac, jnp.asarray(0), jnp.asarray(MAX_STEPS))
    y, r, jac, it, status = jax.lax.while_loop(cond, body, state)
    force, constraint, _ = _measures(r, w, length)
    status = jnp.where(done(r), SUCCESS, jnp.where(jnp.all(jnp.isfinite(r)), status, NONFINITE))
    info = jnp.stack([status.astype(float), it.astype(float), force, constraint])
    return y, info


@eqx.filter_custom_jvp
def _equilibrium(mech, loads, q0, *, rtol, atol, max_steps):
    return _newton(mech, loads, q0, rtol=rtol, atol=atol, max_steps=max_steps)


@_equilibrium.def_jvp
def _equilibrium_jvp(primals, tangents, *, rtol, atol, max_steps):
    mech, loads, q0 = primals
    t_mech, t_loads, _ = tangents
    y, info = _newton(mech, loads, q0, rtol=rtol, atol=atol, max_steps=max_steps)
    n = get_layout(mech).n
    y = jax.lax.stop_gradient(y)

    def residual(mech_, loads_):
        return assemble(mech_, loads_, y[:n], y[n:], with_jacobian=False)[0]

    _, jac = assemble(jax.lax.stop_gradient(mech), jax.lax.stop_gradient(loads), y[:n], y[n:])
    _, dr = eqx.filter_jvp(residual, (mech, loads), (t_mech, t_loads))
    dy = -_scaled_solve(jax.lax.stop_gradient(jac), dr)
    return (y, info), (dy, jnp.zeros_like(info))


def _solve_one(mech, loads, q0, rtol, atol, max_steps):
    y, info = _equilibrium(mech, loads, q0, rtol=rtol, atol=atol, max_steps=max_steps)
    n = get_layout(mech).n
    return StaticSolution(
        q=y[:n],
        multipliers=y[n:],
        status=info[0].astype(int),
        iterations=info[1].astype(int),
        residual=info[2],
        constraint_error=info[3],
    )


@eqx.filter_jit
def _solve_batch(mech, loads, q0, rtol, atol, max_steps, chunk):
    def one(args):
        loads_, q0_ = args
        return _solve_one(mech, loads_, q0_, rtol, atol, max_steps)

    n_cases = loads.force.shape[0]
    if chunk is None or n_cases <= chunk:
        return jax.vmap(lambda l, q: one((l, q)))(loads, q0)
    return jax.lax.map(one, (loads, q0), batch_size=chunk)


@eqx.filter_jit
def _solve_path(mech, loads, q0, rtol, atol, max_steps):
    def step(q, loads_):
        sol = _solve_one(mech, loads_, q, rtol, atol, max_steps)
        return jnp.where(sol.status == SUCCESS, sol.q, q), sol

    _, sols = jax.lax.scan(step, q0, loads)
    return sols


def _is_traced(tree) -> bool:
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(tree))


def _check_inputs(mech: Mechanism, loads: Loads):
    """Value checks on concrete inputs (traced inputs are checked by `eqx.error_if`)."""
    for path, leaf in jax.tree_util.tree_leaves_with_path((mech, loads)):
        if eqx.is_inexact_array(leaf) and not _is_traced(leaf):
            if not bool(jnp.all(jnp.isfinite(leaf))):
                where = jax.tree_util.keystr(path)
                owner = "mechanism" if path[0].idx == 0 else "loads"
                raise ValueError(
                    f"{owner}{where[3:]} contains non-finite values (NaN or inf); every number "
                    "of a model and its loads must be finite."
                )
    if not _is_traced(mech.bushings.k_trans) and mech.bushings.names:
        for field in ("k_trans", "k_rot"):
            k = np.asarray(getattr(mech.bushings, field))
            if np.any(k < 0):
                e, a = np.argwhere(k < 0)[0]
                raise ValueError(
                    f"bushing '{mech.bushings.names[e]}' has {field}[{'xyz'[a]}] = {k[e, a]} < 0; "
                    "stiffness must be ≥ 0."
                )
    if not _is_traced(mech.springs.k) and mech.springs.names:
        k = np.asarray(mech.springs.k)
        for e, name in enumerate(mech.springs.names):
            if not mech.springs.tabulated[e] and k[e] <= 0:
                raise ValueError(f"spring '{name}' has k = {k[e]} ≤ 0; k must be positive.")


def _report(sol: StaticSolution, throw: bool, what: str):
    if _is_traced(sol.status):
        return sol
    status = np.atleast_1d(np.asarray(sol.status))
    bad = np.flatnonzero(status != SUCCESS)
    if bad.size and throw:
        c = int(bad[0])
        res = float(np.atleast_1d(np.asarray(sol.residual))[c])
        con = float(np.atleast_1d(np.asarray(sol.constraint_error))[c])
        raise ConvergenceError(
            f"{what}: load case {c} did not converge ({STATUS_TEXT[int(status[c])]}, relative "
            f"force residual {res:.3g}, constraint error {con:.3g} mm; {bad.size} of "
            f"{status.size} cases failed). Check that the loads are within what the model can "
            "carry (stops, stiffness), raise max_steps, solve the path as a sweep with "
            "solve_sweep, or pass throw=False to get per-case statuses."
        )
    if bad.size:
        warnings.warn(f"{what}: {bad.size} of {status.size} cases did not converge.", stacklevel=3)
    return sol


def _start(mech, loads, q0, n_cases):
    n = mech.n_coordinates
    if q0 is None:
        q0 = jnp.zeros(n)
    q0 = jnp.asarray(q0, dtype=float)
    if q0.shape[-1:] != (n,):
        raise ValueError(f"q0 must have {n} coordinates per case; got shape {q0.shape}.")
    if n_cases is not None and q0.ndim == 1:
        q0 = jnp.broadcast_to(q0, (n_cases, n))
    return q0


def _check_x64():
    if not jax.config.jax_enable_x64:
        warnings.warn(
            "jax_enable_x64 is off: diffsusp's tolerances assume float64. Call "
            "jax.config.update('jax_enable_x64', True) before building models.",
            stacklevel=3,
        )


def solve_statics(
    mech: Mechanism,
    loads: Loads,
    *,
    q0: Float[Array, "*cases n"] | None = None,
    rtol: float = 1e-10,
    atol: float = 1e-9,
    max_steps: int = 50,
    chunk: int | None = 4096,
    throw: bool = True,
) -> StaticSolution:
    """Static equilibria of `mech` under each load case of `loads`.

    **Arguments:**
    - `mech`: the mechanism (q = 0 is its design position).
    - `loads`: one case, or a table with a leading case axis (see `Mechanism.loads`).
    - `q0`: start coordinates (default: the design position), per case or shared.
    - `rtol`: force rows below rtol·(load scale); `atol`: constraint rows below atol (mm).
    - `max_steps`: Newton iterations per case.
    - `chunk`: cases solved at once (larger tables are mapped in chunks to bound memory).
    - `throw`: raise `ConvergenceError` naming the first failed case; otherwise return the
      per-case `status`.

    **Returns:** a `StaticSolution`, differentiable (implicitly) with respect to every float
    leaf of `mech` and `loads`.
    """
    _check_x64()
    _check_inputs(mech, loads)
    n_cases = loads.n_cases
    q0 = _start(mech, loads, q0, n_cases)
    if n_cases is None:
        sol = _solve_batch(mech, jax.tree.map(lambda a: a[None], loads), q0[None], rtol, atol,
                           max_steps, chunk)
        sol = jax.tree.map(lambda a: a[0], sol)
    else:
        sol = _solve_batch(mech, loads, q0, rtol, atol, max_steps, chunk)
    return _report(sol, throw, "solve_statics")


def solve_sweep(
    mech: Mechanism,
    loads: Loads,
    *,
    q0: Float[Array, " n"] | None = None,
    rtol: float = 1e-10,
    atol: float = 1e-9,
    max_steps: int = 50,
    throw: bool = True,
) -> StaticSolution:
    """Equilibria along a path of load cases (wheel travel, load ramp), each case started from
    the previous solution (`lax.scan`). Arguments as `solve_statics`; `loads` must have a case
    axis, in path order."""
    _check_x64()
    _check_inputs(mech, loads)
    if loads.n_cases is None:
        raise ValueError("solve_sweep needs loads with a leading case axis (the path).")
    q0 = _start(mech, loads, q0, None)
    sol = _solve_path(mech, loads, q0, rtol, atol, max_steps)
    return _report(sol, throw, "solve_sweep")
