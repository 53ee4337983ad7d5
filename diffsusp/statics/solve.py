"""Static equilibrium: damped Newton on the KKT system, batched, with implicit differentiation.

spec: stiffness §1.9 (Q_ext + Q_int + Φ_qᵀλ = 0, Φ = c); DESIGN.md "Static equilibrium".

Per load case: multipliers initialised by weighted least squares at the start pose; each Newton
step solves the KKT system after a Ruiz row/column equilibration (forces in N, moments in N·mm and
constraint rows in mm or radians differ by orders of magnitude); the step is capped so no Gibbs
vector moves by more than 0.5 at once, applied to each part as a rigid screw motion (see
`kernel.retract`), and backtracked on a scaled merit function. A case has converged when every
force row is below `rtol`·F_s (moment rows `rtol`·F_s·L, with F_s the load scale and L the
model's length scale) and every constraint row below `atol` mm; a case whose line search makes no
progress for several steps is stopped as stalled (no equilibrium nearby).

The solution is differentiated implicitly: for a parameter tangent dθ, dy = −J⁻¹ ∂r/∂θ·dθ at the
solution (one more linear solve), in forward and reverse mode; the Newton loop is never unrolled.
"""

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ..errors import ConvergenceError, ModelWarning
from ..model.mechanism import Loads, Mechanism
from .kernel import (
    assemble,
    constraint_values,
    get_layout,
    retract,
    to_internal,
    to_public,
)

SUCCESS, MAX_STEPS, NONFINITE, STALLED = 0, 1, 2, 3
STATUS_TEXT = {
    SUCCESS: "converged",
    MAX_STEPS: "max_steps reached",
    NONFINITE: "non-finite",
    STALLED: "stalled: no descent in the last steps",
}
_STALL_STEPS = 4  # consecutive steps shorter than 1/100 of Newton's before giving up


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


def _ruiz(jac, sweeps: int = 1):
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


def _weights(mech: Mechanism, loads: Loads, reaction):
    lay = get_layout(mech)
    n, m = lay.n, lay.m
    length = mech.length_scale
    rot_col = np.tile(np.r_[np.zeros(3), np.ones(3)], n // 6).astype(bool)
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
    return _Weights(force=force_w, constraint=constraint_w)


def _measures(r, w: _Weights, length):
    force = jnp.max(jnp.abs(r * w.force), initial=0.0)
    constraint = jnp.max(jnp.abs(r * w.constraint), initial=0.0)
    merit = 0.5 * (jnp.sum((r * w.force) ** 2) + jnp.sum((r * w.constraint / length) ** 2))
    return force, constraint, merit


def _initial_multipliers(a, r, n, length, angular):
    """Weighted least squares for λ at the start pose: min ‖W(Q + Φ_qᵀλ)‖ (W: moments / L)."""
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
    rot = jnp.asarray(np.r_[np.tile(np.r_[np.zeros(3), np.ones(3)], n // 6), np.zeros(m)])

    def evaluate(y):
        return assemble(mech, loads, y[:n], y[n:])

    def residual(y):
        return assemble(mech, loads, y[:n], y[n:], with_jacobian=False)[0]

    # Multipliers: least squares against the generalised forces at the start pose.
    r0 = residual(jnp.concatenate([q0, jnp.zeros(m, q0.dtype)]))
    if m:
        live = np.asarray(mech.independent_rows)
        phi_q = jax.jacfwd(lambda q: constraint_values(mech, loads, q)[live])(q0)
        lam0 = _initial_multipliers(phi_q, r0, n, length, lay.angular_live)
        reaction = phi_q.T @ lam0
    else:
        lam0, reaction = jnp.zeros(0, q0.dtype), jnp.zeros(n, q0.dtype)
    w = _weights(mech, loads, reaction)
    y0 = jnp.concatenate([q0, lam0])
    r_start = r0 + jnp.concatenate([reaction, jnp.zeros(m, q0.dtype)])

    def done(r, step):
        # Converged, or at the round-off floor: within 1000× the tolerances and no longer moving.
        force, constraint, _ = _measures(r, w, length)
        tight = (force <= rtol) & (constraint <= atol)
        floor = (force <= 1e3 * rtol) & (constraint <= 1e3 * atol) & (step <= 1e-13)
        return tight | floor

    def cond(state):
        y, r, it, status, step, _ = state
        return (it < max_steps) & (status == MAX_STEPS) & ~done(r, step)

    def body(state):
        y, _, it, status, _, stall = state
        r, jac = evaluate(y)
        dy = _scaled_solve(jac, -r)
        cap = jnp.max(jnp.abs(dy * rot))
        dy = dy * jnp.minimum(1.0, 0.5 / jnp.maximum(cap, 1e-300))
        merit0 = _measures(r, w, length)[2]

        # Backtracking from α = 1 (the first pass of the loop evaluates the full step).
        def ls_cond(carry):
            alpha, _, merit, k = carry
            return (k < 13) & ~(merit <= (1.0 - 1e-4 * alpha) * merit0)

        def ls_body(carry):
            alpha, _, _, k = carry
            alpha = jnp.where(k == 0, 1.0, 0.5 * alpha)
            r_try = residual(retract(y, alpha * dy, n))
            merit = _measures(r_try, w, length)[2]
            return alpha, r_try, jnp.where(jnp.isfinite(merit), merit, jnp.inf), k + 1

        init = (jnp.asarray(1.0), r, jnp.asarray(jnp.inf), jnp.asarray(0))
        alpha, r_new, _, _ = jax.lax.while_loop(ls_cond, ls_body, init)
        status = jnp.where(jnp.all(jnp.isfinite(r_new)), status, NONFINITE)
        # A case whose line search keeps cutting the step to nothing has no equilibrium
        # nearby (e.g. a suspension pulled past its travel): stop it so that it does not hold
        # the whole vmapped batch to max_steps.
        stall = jnp.where(alpha < 0.01, stall + 1, 0)
        status = jnp.where(stall >= _STALL_STEPS, STALLED, status)
        step = jnp.max(jnp.abs(alpha * dy[:n])) / (length + jnp.max(jnp.abs(y[:n])))
        return retract(y, alpha * dy, n), r_new, it + 1, status, step, stall

    state = (y0, r_start, jnp.asarray(0), jnp.asarray(MAX_STEPS), jnp.asarray(jnp.inf),
             jnp.asarray(0))
    y, r, it, status, step, _ = jax.lax.while_loop(cond, body, state)
    force, constraint, _ = _measures(r, w, length)
    status = jnp.where(done(r, step), SUCCESS,
                       jnp.where(jnp.all(jnp.isfinite(r)), status, NONFINITE))
    info = jnp.stack([status.astype(float), it.astype(float), force, constraint])
    return y, info


@eqx.filter_custom_jvp
def _equilibrium(mech, loads, q0, *, rtol, atol, max_steps):
    return _newton(mech, loads, q0, rtol=rtol, atol=atol, max_steps=max_steps)


@_equilibrium.def_jvp
def _equilibrium_jvp(primals, tangents, *, rtol, atol, max_steps):
    # Implicit function theorem: J·dy = −∂r/∂(mech, loads)·t. Everything here stays
    # differentiable (y through this same rule, J and ∂r through autodiff), so derivatives of
    # derivatives — e.g. the sensitivity of bump steer to a stiffness — are exact too.
    mech, loads, q0 = primals
    t_mech, t_loads, _ = tangents
    y, info = _equilibrium(mech, loads, q0, rtol=rtol, atol=atol, max_steps=max_steps)
    n = get_layout(mech).n

    def residual(mech_, loads_):
        return assemble(mech_, loads_, y[:n], y[n:], with_jacobian=False)[0]

    _, jac = assemble(mech, loads, y[:n], y[n:])
    _, dr = eqx.filter_jvp(residual, (mech, loads), (t_mech, t_loads))
    dy = -_scaled_solve(jac, dr)
    return (y, info), (dy, jnp.zeros_like(info))


def _solve_one(mech, loads, q0, rtol, atol, max_steps):
    y0 = to_internal(mech, q0)
    y, info = _equilibrium(mech, loads, y0, rtol=rtol, atol=atol, max_steps=max_steps)
    n = get_layout(mech).n
    return StaticSolution(
        q=to_public(mech, y[:n]),
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
            if not np.all(np.isfinite(np.asarray(leaf))):
                where = jax.tree_util.keystr(path)
                owner = "mechanism" if path[0].idx == 0 else "loads"
                raise ValueError(
                    f"{owner}{where[3:]} contains non-finite values (NaN or inf); every number "
                    "of a model and its loads must be finite."
                )
    if mech.bushings.names:
        for field in ("k_trans", "k_rot"):
            if _is_traced(getattr(mech.bushings, field)):
                continue
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


@eqx.filter_jit
def _bushing_angles(mech, q):
    from .outputs import bushing_states

    return bushing_states(mech, q)[1]


def _check_validity(mech: Mechanism, sol: StaticSolution):
    """Warn when a bushing's projected angles leave their validity (|AX|, |AY| < 15°,
    |AZ| < 90°; spec stiffness §0)."""
    if not mech.bushings.names or _is_traced(sol.q):
        return
    angles = np.abs(np.asarray(_bushing_angles(mech, sol.q)))
    angles = angles.reshape(-1, len(mech.bushings.names), 3)
    b = mech.bushings
    carries = (np.asarray(b.k_rot) != 0) | (np.asarray(b.cubic_rot) != 0) | np.asarray(
        b.spline_axes, dtype=bool).reshape(-1, 6)[:, 3:]
    angles = np.where(carries, angles, 0.0)  # an axis with no law has no validity to leave
    limits = np.radians([15.0, 15.0, 90.0])
    ratio = angles / limits
    if np.any(ratio > 1.0):
        c, e, a = np.unravel_index(np.argmax(ratio), ratio.shape)
        warnings.warn(
            f"bushing '{mech.bushings.names[e]}' is rotated by {np.degrees(angles[c, e, a]):.1f}° "
            f"about its {'xyz'[a]} axis (case {c}), beyond the projected angles' validity "
            f"(|AX|, |AY| < 15°, |AZ| < 90°): its law is not meaningful there. Check the loads "
            "or model a joint instead of the bushing.",
            ModelWarning,
            stacklevel=3,
        )


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
    rtol: float = 1e-12,
    atol: float = 1e-10,
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
    _check_validity(mech, sol)
    return _report(sol, throw, "solve_statics")


def solve_sweep(
    mech: Mechanism,
    loads: Loads,
    *,
    q0: Float[Array, " n"] | None = None,
    rtol: float = 1e-12,
    atol: float = 1e-10,
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
    _check_validity(mech, sol)
    return _report(sol, throw, "solve_sweep")
