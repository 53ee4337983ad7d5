"""Least-squares identification through the differentiable static equilibrium.

spec: stiffness §6 item 8 (gradient-based alternative: minimise model − measured residuals
through the equilibrium; covariance from marker noise; the equivalent-solution manifold), §3
perspectives 2–4 (joint geometric + stiffness identification, sensitivities, uncertainty), §2.8
(σ = 0.05 mm landmark noise), §7 R5; DESIGN.md "Identification"; STYLE.md "Identification:
select, partition, solve, combine".

Problem: with θ(u) the parameters (`Params`: log scale for stiffnesses, bounds by
reparametrisation), q_c(θ) the equilibrium of load case c, and the measurements' whitened
residuals r = mask·(model(θ, q_c) − measured)/σ,

    minimise  ½ Σ ρ(r_i)  +  ½ Σ_j ((u_j − u_prior,j)·w_j)²          (Tikhonov prior, optional)

with ρ the plain square, Huber or Cauchy loss (applied as r̃ = sign(r)·√(2ρ(r)), so the
Gauss–Newton model of the robust cost is exact at r = 0 and down-weights outliers). The
minimiser is optimistix's Levenberg–Marquardt (damped Newton descent, classical trust region).
The Jacobian is forward mode through `solve_statics`, whose custom JVP differentiates the
equilibrium implicitly (one more linear solve per direction; the Newton loop is never unrolled).

How it runs. The LM iteration is driven from Python one step at a time, which records the
history, calls the progress callback, and warm-starts each step's equilibria from the last
accepted ones. Each step is four compiled calls: the mechanism at the trial point and its
parameter tangents; the equilibria of all load cases and their tangents (the program that holds
the Newton loop, costly to compile: it depends only on the model, the load table and the number
of parameters padded to `TANGENT_BLOCK`, so every fit of one model shares it); the whitened
residuals and their Jacobian; and the optimistix step itself, handed the residual's first-order
model about the trial point (its value and Jacobian there are all a Gauss–Newton step asks of
the function). Losses, priors and data values are runtime arrays: they never recompile.
`least_squares_batch` vmaps the same four calls over many data sets.

Stopping: at an accepted point, when a full Gauss–Newton step would lower χ² (prior
rows included) by less than `gtol` + `ftol`·χ² — a test on what the data can still give, not on
the size of the step, which stays large along directions the data barely see. A weak default
prior on log stiffness keeps those directions where they started (see `least_squares`). The
first damping is λ0 = 10⁻³·max diag(JᵀJ) (optimistix starts at λ = 1, negligible for whitened
residuals). `FitReport.message` gives the stop reason.

Inner non-convergence: every residual of a load case whose equilibrium fails at a trial point
is set to 1e8 (finite), so the trust region rejects the step and shrinks; the history records
the trial and its failed cases. The start point must converge in every case.

**Size.** About 790 lines, one piece on purpose: the problem set-up, the four compiled step
programs, the Python driver of the LM iteration (single and batched) and the batched variant
share `_Problem` and its compiled programs; splitting them would scatter one algorithm over
modules that import each other's private programs. The report (`FitReport`, `StepRecord`,
`NullDirection`, the covariance and null-space analysis) is in `identify.least_squares_report`
and importable from here.
"""

import dataclasses
from collections.abc import Callable, Mapping, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from ..errors import InputError
from ..kc.second_order import pinned_solution
from ..lsq import DEFAULT_LOSS_SCALE, LOSSES, robust
from ..measure.data import Measurement, as_fit_data
from ..model.mechanism import Loads, Mechanism
from ..statics import Status, solve_statics
from .least_squares_report import (
    FitReport,
    LMRun,
    NullDirection,
    StepRecord,
    curvature_check,
    fit_report,
)
from .params import Params

__all__ = ["BatchFitReport", "FitReport", "NullDirection", "StepRecord", "least_squares",
           "least_squares_batch", "predict", "whitened_residuals"]


FAILED_RESIDUAL = 1e8
"""Whitened residual given to every entry of a load case whose equilibrium failed."""

_TAGS = frozenset()


# ----------------------------------------------------------------------------- problem


TANGENT_BLOCK = 16
"""Parameter directions are padded to a multiple of this, so that fits of up to 16 parameters
of one model (and 17–32, and so on) share the compiled equilibrium program, the one that is
costly to compile."""

INITIAL_DAMPING = 1e-3
"""First LM damping λ0 = this × max diag(JᵀJ) at the start (Madsen, Nielsen & Tingleff's τ)."""


class _Problem(eqx.Module):
    """Everything the residual needs; arrays are traced, structure static."""

    mech: Mechanism
    params: Params
    data: tuple[Measurement, ...]
    loads: Loads
    loss: Array
    loss_scale: Array
    prior_u: Array
    prior_w: Array
    slices: tuple[tuple[int, int], ...] = eqx.field(static=True)
    inner_max_steps: int = eqx.field(static=True)

    @property
    def n_tangents(self) -> int:
        return TANGENT_BLOCK * max(1, -(-len(self.params) // TANGENT_BLOCK))


# The residual is evaluated in three separately compiled pieces, so that the costly one (the
# equilibria and their tangents, which contains the Newton loop) depends only on the model, the
# load table and the padded number of parameters, and is shared by every fit of that model:
#   setup:      u -> mechanism at θ(u) and its tangents ∂mech/∂u_j (Params.apply is linear)
#   equilibria: mechanism, tangents -> q, status and ∂q/∂u_j (implicit, forward mode)
#   rows:       whitened robust residuals and their Jacobian (measurement models, prior)
# The LM step itself is a fourth, small program.


def _setup_impl(problem: _Problem, u, n_tangents: int):
    params = problem.params

    def mech_of(v):
        return params.apply(problem.mech, params.to_physical(v))

    basis = jnp.eye(n_tangents, len(params), dtype=u.dtype)
    tangents = jax.vmap(lambda e: jax.jvp(mech_of, (u,), (e,))[1])(basis)
    return mech_of(u), tangents


def _equilibria_impl(mech, loads, q0, tangents, max_steps: int):
    def solve(m):
        sol = solve_statics(m, loads, q0=q0, max_steps=max_steps, throw=False)
        return sol.q, sol.status.astype(sol.q.dtype)

    (q, status), (dq, _) = jax.vmap(lambda t: jax.jvp(solve, (mech,), (t,)))(tangents)
    return q[0], status[0].astype(int), dq


def _rows_impl(problem: _Problem, u, mech, q, status, dq, tangents, prior_scale=1.0):
    ok = status == Status.CONVERGED

    def rows(m, qq):
        zs, raws = [], []
        for meas, (a, b) in zip(problem.data, problem.slices, strict=True):
            raw = meas.residual(m, qq[a:b])
            z = robust(raw * meas.weight, problem.loss, problem.loss_scale)
            good = ok[a:b].reshape((-1,) + (1,) * (raw.ndim - 1)) & jnp.isfinite(z)
            zs.append(jnp.where(good, z, FAILED_RESIDUAL).reshape(-1))
            raws.append(raw.reshape(-1))
        return jnp.concatenate(zs), jnp.concatenate(raws)

    z, jz, raw = jax.vmap(lambda t, d: jax.jvp(rows, (mech, q), (t, d), has_aux=True))(
        tangents, dq)
    p = len(problem.params)
    w = problem.prior_w * prior_scale
    z_prior = (u - problem.prior_u) * w
    residual = jnp.concatenate([z[0], z_prior])
    jacobian = jnp.concatenate([jz[:p].T, jnp.diag(w)])
    return residual, jacobian, raw[0]


def _predict_impl(data, mech, q, slices):
    return tuple(m.predict(mech, q[a:b]) for m, (a, b) in zip(data, slices, strict=True))


@eqx.filter_jit
def _curvature(problem: _Problem, u, sol, z_bar):
    """Σᵢ z̄ᵢ∇²zᵢ(u) (p, p) of the whitened data residuals z at u (the fit's equilibria `sol`
    pinned: `kc.second_order.pinned_solution`), z̄ their values there: p Hessian-vector products,
    forward mode over the reverse-mode gradient of z·z̄."""
    def data_rows(v):
        mech = problem.params.apply(problem.mech, problem.params.to_physical(v))
        q = pinned_solution(mech, problem.loads, sol).q
        zs = []
        for meas, (a, b) in zip(problem.data, problem.slices, strict=True):
            z = robust(meas.residual(mech, q[a:b]) * meas.weight, problem.loss,
                       problem.loss_scale)
            zs.append(jnp.where(jnp.isfinite(z), z, 0.0).reshape(-1))
        return jnp.concatenate(zs)

    return jax.jacfwd(jax.grad(lambda v: data_rows(v) @ z_bar))(u)


def _curvature_check(problem: _Problem, run: LMRun):
    """The Gauss–Newton-vs-full-Hessian check at the fit's estimate (`CurvatureCheck`)."""
    params = problem.params
    u = jnp.asarray(run.u[0])
    z, jac, _ = (np.asarray(a[0], dtype=float) for a in run.last)
    n_data = z.size - len(params)
    mech = params.apply(problem.mech, params.to_physical(u))
    sol = solve_statics(mech, problem.loads, q0=run.q_last[0], max_steps=problem.inner_max_steps,
                        throw=False, checks=False)
    if np.any(np.asarray(sol.status) != Status.CONVERGED):
        raise InputError("the curvature check needs every equilibrium at the estimate.")
    s_term = np.asarray(_curvature(problem, u, sol, jnp.asarray(z[:n_data])))
    return curvature_check(params.names, jac, s_term, np.asarray(params.derivative(u)))


def _quiet(**kwargs):
    pass


class _Damping(eqx.Module):
    """The state of `_TrustRegion`: the step size 1/λ of the damped Newton descent, and
    whether its last step accepted the point evaluated."""

    step_size: Array
    accepted: Array


class _TrustRegion(optx.ClassicalTrustRegion):
    """optimistix's classical trust region, grown after any step that achieves 3/4 of its
    predicted reduction (the default, 0.99, keeps a far start crawling for dozens of steps),
    and started at the damping λ0 = `INITIAL_DAMPING`·max diag(JᵀJ) of the first point's
    Jacobian (Madsen, Nielsen & Tingleff's τ) instead of optimistix's λ = 1, far too little
    damping for residuals whitened by 0.05 mm. The first step is always accepted, so the step
    size is only used after it."""

    high_cutoff: float = 0.75

    def init(self, y, f_info_struct) -> _Damping:
        del y, f_info_struct
        return _Damping(step_size=jnp.array(1.0), accepted=jnp.array(False))

    def step(self, first_step, y, y_eval, f_info, f_eval_info, state: _Damping):
        jacobian = f_eval_info.jac.as_matrix()
        lam0 = INITIAL_DAMPING * jnp.max(jnp.sum(jacobian ** 2, axis=0))
        start = _Damping(step_size=jnp.where(first_step, 1.0 / jnp.maximum(lam0, 1e-300),
                                             state.step_size), accepted=state.accepted)
        step_size, accept, result, _ = super().step(first_step, y, y_eval, f_info,
                                                    f_eval_info, start)
        return step_size, accept, result, _Damping(step_size=step_size, accepted=accept)


class _LevenbergMarquardt(optx.AbstractGaussNewton):
    """optimistix's Levenberg–Marquardt (damped Newton descent) with `_TrustRegion` as its
    search."""

    rtol: float
    atol: float
    norm: Callable = optx.max_norm
    descent: optx.DampedNewtonDescent = optx.DampedNewtonDescent()
    search: _TrustRegion = _TrustRegion()
    verbose: Callable = _quiet


def _model(y, args):
    """The residual's first-order model about the point it was evaluated at: exact value and
    Jacobian there, which is all a Gauss–Newton step asks of the function."""
    residual, jacobian, y0 = args
    return residual + jacobian @ (y - y0), None


def _lm_state(solver, u, n_rows: int):
    args = (jnp.zeros(n_rows, u.dtype), jnp.zeros((n_rows, u.size), u.dtype), u)
    f_struct, aux_struct = eqx.filter_eval_shape(_model, u, args)
    return solver.init(_model, u, args, {}, f_struct, aux_struct, _TAGS)


def _lm_init_impl(u, n_rows: int, rtol: float, atol: float):
    return eqx.filter(_lm_state(_LevenbergMarquardt(rtol, atol), u, n_rows), eqx.is_array)


def _lm_step_impl(u, dyn_state, residual, jacobian, active, rtol: float, atol: float,
                  ftol: float, gtol: float):
    """One LM step, given the residual and Jacobian at the state's trial point `y_eval`."""
    solver = _LevenbergMarquardt(rtol, atol)
    static = eqx.filter(_lm_state(solver, u, residual.size), eqx.is_array, inverse=True)
    state = eqx.combine(dyn_state, static)
    args = (residual, jacobian, state.y_eval)
    new_u, new_state, _ = solver.step(_model, u, args, {}, state, _TAGS)
    _, result = solver.terminate(_model, new_u, args, {}, new_state, _TAGS)
    damping = new_state.search_state  # `_TrustRegion`'s own state
    accepted = damping.accepted
    # The stop does not look at the step in u (optimistix's Cauchy test): along a direction
    # the data barely see, steps stay large long after the fit has settled, and a parameter
    # there may wander. It asks what the data can still give: at an accepted point,
    # the decrease of Σr² a full Gauss–Newton step would bring, ‖Qᵀr‖² (QR of the Jacobian,
    # prior rows included), below gtol + ftol·Σr² (in χ² units: far below a change anyone
    # could see in the data).
    basis, _ = jnp.linalg.qr(jacobian)
    loss_after = jnp.sum(residual ** 2)
    predicted = jnp.sum((basis.T @ residual) ** 2)
    # (A small decrease of the loss over an accepted step is no test: a heavily damped step
    # is small wherever it is taken.)
    flat = accepted & (predicted <= gtol + ftol * loss_after)
    terminate = flat
    reason = jnp.where(flat, 1, 0)
    new_dyn = eqx.filter(new_state, eqx.is_array)
    new_u, new_dyn = jax.tree.map(lambda n, o: jnp.where(active, n, o), (new_u, new_dyn),
                                  (u, dyn_state))
    record = dict(accepted=active & accepted,
                  step_size=damping.step_size, terminate=terminate,
                  failed=result != optx.RESULTS.successful, reason=reason,
                  predicted=predicted)
    return new_u, new_dyn, record


_setup = eqx.filter_jit(_setup_impl)
_setup_batch = eqx.filter_jit(
    lambda problem, u, n: jax.vmap(lambda v: _setup_impl(problem, v, n))(u))
_equilibria = eqx.filter_jit(_equilibria_impl)
_equilibria_batch = eqx.filter_jit(
    lambda mech, loads, q0, tangents, max_steps: jax.vmap(
        lambda m, q, t: _equilibria_impl(m, loads, q, t, max_steps))(mech, q0, tangents))
_rows = eqx.filter_jit(_rows_impl)
_rows_batch = eqx.filter_jit(
    lambda problem, values, u, mech, q, status, dq, tangents, scale: jax.vmap(
        lambda v, *a: _rows_impl(_with_values(problem, v), *a))(
            values, u, mech, q, status, dq, tangents, scale))
_predict = eqx.filter_jit(_predict_impl)
_lm_init = eqx.filter_jit(
    lambda u, n_rows, rtol, atol: jax.vmap(lambda v: _lm_init_impl(v, n_rows, rtol, atol))(u))
_lm_step = eqx.filter_jit(
    lambda u, dyn, residual, jacobian, active, rtol, atol, ftol, gtol: jax.vmap(
        lambda *a: _lm_step_impl(*a, rtol, atol, ftol, gtol))(u, dyn, residual, jacobian,
                                                              active))


@eqx.filter_jit
def _bookkeep(params, accepted, trial_u, u, new, last, q, status, q0):
    """After an LM step: keep the evaluation of accepted trials, warm starts, physical values."""
    last = new if last is None else _select(accepted, new, last)
    q0 = _select(accepted, jnp.where((status == Status.CONVERGED)[..., None], q, q0), q0)
    to_physical = jax.vmap(params.to_physical)
    loss = 0.5 * jnp.sum(new[0] ** 2, axis=1)
    failed = jnp.sum(status != Status.CONVERGED, axis=1)
    return last, q0, to_physical(trial_u), to_physical(u), loss, failed


def _values_of(data: Sequence[Measurement]):
    return tuple(tuple(getattr(m, f) for f in m.value_fields) for m in data)


def _with_values(problem: _Problem, values) -> _Problem:
    data = tuple(eqx.tree_at(lambda m: tuple(getattr(m, f) for f in m.value_fields), m, v)
                 for m, v in zip(problem.data, values, strict=True))
    return dataclasses.replace(problem, data=data)


def _evaluate(problem: _Problem, values, u, q0, batched: bool, prior_scale=None):
    """Residuals, Jacobian (internal coordinates), raw residuals, q and status at u; the prior
    rows weighted by `prior_scale` (per data set when batched; default 1)."""
    n = problem.n_tangents
    if batched:
        scale = jnp.ones(u.shape[0]) if prior_scale is None else jnp.asarray(prior_scale)
        mech, tangents = _setup_batch(problem, u, n)
        q, status, dq = _equilibria_batch(mech, problem.loads, q0, tangents,
                                          problem.inner_max_steps)
        z, jac, raw = _rows_batch(problem, values, u, mech, q, status, dq, tangents, scale)
    else:
        scale = jnp.asarray(1.0 if prior_scale is None else prior_scale, dtype=float)
        mech, tangents = _setup(problem, u, n)
        q, status, dq = _equilibria(mech, problem.loads, q0, tangents, problem.inner_max_steps)
        z, jac, raw = _rows(problem, u, mech, q, status, dq, tangents, scale)
    return z, jac, raw, q, status


# ----------------------------------------------------------------------------- setup


def _as_data(data) -> tuple[Measurement, ...]:
    return as_fit_data(data)


def _combined_loads(data) -> tuple[Loads, tuple[tuple[int, int], ...]]:
    tables, slices, seen, start = [], [], {}, 0
    for m in data:
        key = id(m.loads)
        if key not in seen:
            n = m.loads.n_cases
            seen[key] = (start, start + n)
            tables.append(m.loads)
            start += n
        slices.append(seen[key])
    if len(tables) == 1:
        return tables[0], tuple(slices)
    shapes = {(t.force.shape[1:], t.driver.shape[1:]) for t in tables}
    if len(shapes) != 1:
        raise InputError("the measurements' load tables have different load points or drivers; "
                         "build them all with the same mechanism's Mechanism.loads.")
    return jax.tree.map(lambda *a: jnp.concatenate(a), *tables), tuple(slices)


def _as_params(mech, params) -> Params:
    if isinstance(params, Params):
        # `mech`'s values, unless set with with_start; `given` cleared once resolved, so that
        # a selection with or without given starts compiles to the same programs.
        return dataclasses.replace(params.starting_from(mech), given=())
    if callable(params):
        return Params.leaves(mech, params)
    raise InputError("params must be a Params or a `where` function selecting leaves of the "
                     "mechanism, e.g. lambda m: (m.bushings.k_trans, m.bushings.k_rot).")


def _per_param(value, params: Params, what: str, default=None) -> np.ndarray:
    p = len(params)
    if value is None:
        return np.full(p, np.nan if default is None else default)
    if isinstance(value, Mapping):
        out = np.full(p, np.nan if default is None else default)
        for name, v in value.items():
            out[params.index(name)] = float(v)
        return out
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        return np.full(p, float(arr))
    if arr.shape != (p,):
        raise InputError(f"{what} must be a scalar, a ({p},) array in the order of "
                         f"params.names, or a mapping name → value; got shape {arr.shape}.")
    return arr


def _prior(params: Params, prior, prior_sigma):
    """(u_prior, w) with prior rows (u − u_prior)·w: w = dθ/du at the prior / σ (physical σ;
    for a log-scaled parameter that is a relative σ/θ_prior on log θ). No prior: w = 0."""
    p = len(params)
    if isinstance(prior, str):
        if prior != "weak":
            raise InputError(f"prior must be 'weak' (the default), None, a Mechanism, a (p,) "
                             f"array or a mapping name → value; got {prior!r}.")
        if prior_sigma is not None:  # the start values, with the caller's σ
            return _prior(params, np.asarray(params.start), prior_sigma)
        start = np.asarray(params.start)
        sigma = np.where(params.log_scaled, DEFAULT_LOG_PRIOR_SIGMA * np.abs(start), np.inf)
        return _prior(params, start, sigma)
    if prior is None:
        if prior_sigma is not None:
            raise InputError("prior_sigma given without a prior; pass prior= (a Mechanism, a "
                             "(p,) array or a mapping name → value).")
        return jnp.zeros(p), jnp.zeros(p)
    if prior_sigma is None:
        raise InputError("a prior needs prior_sigma (physical units, one per parameter or a "
                         "scalar or a mapping name → σ).")
    if isinstance(prior, Mechanism):
        theta = np.asarray(params.values(prior))
    elif isinstance(prior, np.ndarray) and prior.shape == (p,):
        theta = prior
    else:
        theta = _per_param(prior, params, "prior")
        theta = np.where(np.isnan(theta), np.asarray(params.start), theta)
    sigma = _per_param(prior_sigma, params, "prior_sigma", default=np.inf)
    if np.any(~(sigma > 0)):
        raise InputError("prior_sigma must be > 0 (use inf for no prior on a parameter).")
    checked = params.with_start(theta)  # checks bounds and positivity
    u = checked.to_internal(checked.start)
    w = jnp.abs(checked.derivative(u)) / jnp.asarray(sigma)
    return u, jnp.where(jnp.isfinite(w), w, 0.0)


def _is_weak(prior, prior_sigma) -> bool:
    return isinstance(prior, str) and prior == "weak" and prior_sigma is None


def _problem(mech, data, params, loss, loss_scale, prior, prior_sigma, inner_max_steps):
    if loss not in LOSSES:
        raise InputError(f"unknown loss '{loss}'; use one of {', '.join(LOSSES)}.")
    scale = DEFAULT_LOSS_SCALE[loss] if loss_scale is None else float(loss_scale)
    if not scale > 0:
        raise InputError("loss_scale must be > 0 (in units of the measurements' σ).")
    for meas in data:
        meas.check(mech)
    loads, slices = _combined_loads(data)
    prior_u, prior_w = _prior(params, prior, prior_sigma)
    return _Problem(mech=mech, params=params, data=data, loads=loads,
                    loss=jnp.asarray(LOSSES[loss]), loss_scale=jnp.asarray(scale),
                    prior_u=prior_u, prior_w=prior_w, slices=slices,
                    inner_max_steps=int(inner_max_steps))


# ----------------------------------------------------------------------------- driver


def _select(mask, new, old):
    """Per data set (leading axis): new where mask, else old."""
    return jax.tree.map(
        lambda n, o: jnp.where(jnp.reshape(mask, (-1,) + (1,) * (n.ndim - 1)), n, o), new, old)


def _run(problem: _Problem, values, u0, *, batched, max_steps, rtol, atol, ftol, gtol,
         callback, prior_scale=None, step0=0, q_start=None, active0=None):
    """Step the LM of every data set until each terminates. Returns the final u `(sets, p)`,
    the last accepted (residual, Jacobian, raw residual) per set, histories, and per set
    (converged, steps, accepted steps, message)."""
    n_sets, p = u0.shape
    if prior_scale is None:
        prior_scale = np.ones(n_sets)
    n_rows = sum(int(np.prod(m.weight.shape)) for m in problem.data) + p
    q0 = (jnp.zeros((n_sets, problem.loads.n_cases, problem.mech.n_coordinates))
          if q_start is None else q_start)
    dyn = _lm_init(u0, n_rows, rtol, atol)
    u, last = u0, None
    active = np.ones(n_sets, bool) if active0 is None else np.array(active0, bool)
    histories = [[] for _ in range(n_sets)]
    steps = np.zeros(n_sets, int)
    accepted_steps = np.zeros(n_sets, int)
    converged = np.zeros(n_sets, bool)
    failed = np.zeros(n_sets, bool)
    reasons = np.zeros(n_sets, int)
    rejected = np.zeros(n_sets, int)
    last_predicted = np.full(n_sets, np.inf)
    first_jac = None
    for k in range(max_steps + 1):
        trial_u = dyn.y_eval
        if batched:
            z, jac, raw, q, status = _evaluate(problem, values, trial_u, q0, True,
                                               prior_scale)
        else:
            out = _evaluate(problem, values, trial_u[0], q0[0], False, prior_scale[0])
            z, jac, raw, q, status = (a[None] for a in out)
        if k == 0:
            first_jac = jac
            status_np = np.asarray(status)
            bad = np.flatnonzero(np.any(status_np != Status.CONVERGED, axis=1) & active)
            if bad.size:
                cases = np.flatnonzero(status_np[bad[0]] != Status.CONVERGED)
                raise InputError(
                    "the start parameters give no equilibrium in load case(s) "
                    f"{cases.tolist()} (numbered across the measurements' load tables"
                    f"{'' if n_sets == 1 else f', data set {int(bad[0])}'}); start from "
                    "values closer to plausible ones or drop those cases.")
        u, dyn, rec = _lm_step(u, dyn, z, jac, jnp.asarray(active), rtol, atol, ftol, gtol)
        last, q0, trial, estimate, trial_loss, failed_cases = (
            _bookkeep(problem.params, rec["accepted"], trial_u, u, (z, jac, raw), last, q,
                      status, q0))
        accepted, trial, estimate, trial_loss, failed_cases, step_size = (
            np.asarray(a) for a in (rec["accepted"], trial, estimate, trial_loss, failed_cases,
                                    rec["step_size"]))
        for b in np.flatnonzero(active):
            steps[b] = k
            accepted_steps[b] += int(accepted[b] and k > 0)
            histories[b].append(StepRecord(
                step=step0 + k, trial=trial[b], trial_loss=float(trial_loss[b]),
                failed_cases=int(failed_cases[b]), accepted=bool(accepted[b]),
                estimate=estimate[b], step_size=float(step_size[b])))
        if callback is not None:
            callback(step0 + k, histories[0][-1] if n_sets == 1 else
                     dict(active=active.copy(), trial_loss=trial_loss, accepted=accepted))
        terminate, bad_solve = np.asarray(rec["terminate"]), np.asarray(rec["failed"])
        reason = np.asarray(rec["reason"])
        predicted = np.asarray(rec["predicted"])
        last_predicted = np.where(accepted, predicted, last_predicted)
        rejected = np.where(accepted, 0, rejected + 1)
        # Every trial rejected for a while at a point where a full step would gain nothing
        # visible: the loss is at the precision of the equilibria (noise-free data).
        stalled = active & (rejected >= MAX_REJECTED) & (last_predicted <= STALL_CHI2)
        reason = np.where(stalled & ~terminate, 3, reason)
        terminate = terminate | stalled
        for b in np.flatnonzero(active & terminate & ~bad_solve):
            reasons[b] = int(reason[b])
        converged |= active & terminate & ~bad_solve
        failed |= active & bad_solve
        active &= ~(terminate | bad_solve)
        if not active.any():
            break
    messages = [
        STOP_REASONS[reasons[b]].format(gtol=gtol, ftol=ftol) if converged[b] else
        ("the LM linear solve failed" if failed[b] else
         f"max_steps={max_steps} reached") for b in range(n_sets)]
    return LMRun(u=u, last=last, histories=histories, converged=converged, steps=steps,
                 accepted_steps=accepted_steps, messages=messages, first_jacobian=first_jac,
                 q_last=q0)


STOP_REASONS = {
    1: "converged: a full Gauss–Newton step would lower χ² by less than {gtol:g} + {ftol:g}·χ²",
    3: "converged: the loss is at the precision of the equilibria (every trial rejected while "
       "a full step would lower χ² by less than 1e-6)",
    0: "converged",
}
"""The stop reasons of a converged fit (`FitReport.message`)."""

MAX_REJECTED = 12
STALL_CHI2 = 1e-6
"""A fit whose last `MAX_REJECTED` trials were all rejected, at a point where a full
Gauss–Newton step would lower χ² by less than `STALL_CHI2`, has converged: the loss cannot be
lowered at the precision of the equilibria (noise-free data reach it)."""

MAX_STEPS = 200
"""Default LM steps of `least_squares` and `least_squares_batch`. Most fits stop in 13–50; 100
was too few for 2 of 100 noise draws of `tests/test_identify_trust.py`'s truth
(`benchmarks/identify_trust.py --extra 100`): every step accepted but creeping along a curved,
weakly determined valley (A.Krx ×3.8 or A.Kty ×3.8 of the truth, σ 76 % / 126 % at the start),
the loss unchanged to 8 digits over the last 15 steps while a full Gauss–Newton step still
promised more than ftol·χ²; they converge in 113 and 112 steps, to the same χ²."""

DEFAULT_LOG_PRIOR_SIGMA = 3.0
"""σ of the default weak prior on log stiffness (log-scaled parameters), centred on the start:
a factor e³ ≈ 20 at one σ (see `least_squares`, `prior`)."""

ADAPTIVE_PRIOR_ROUNDS = 4
"""Refits of the default prior at the noise level the residuals show (see `least_squares`)."""


def _run_adaptive(problem: _Problem, values, u0, *, adaptive: bool, max_steps, **kw):
    """`_run`, then, for the data sets whose whitened data residual is below the stated noise
    (RMS ŝ < 1: nearly noise-free data), refit with the prior rows scaled by ŝ, up to
    `ADAPTIVE_PRIOR_ROUNDS` times (see `least_squares`, `prior`)."""
    run = _run(problem, values, u0, max_steps=max_steps, **kw)
    if not adaptive:
        return run
    u, last, hist = run.u, run.last, run.histories
    conv, steps, acc, msg = run.converged, run.steps, run.accepted_steps, run.messages
    n_sets, p = u.shape
    n_data = [int(np.count_nonzero(np.asarray(m.weight))) for m in problem.data]
    dof = max(sum(n_data) - p, 1)
    scale = np.ones(n_sets)
    q_last = run.q_last
    for _ in range(ADAPTIVE_PRIOR_ROUNDS):
        z = np.asarray(last[0])[:, :-p] if p else np.asarray(last[0])
        rms = np.sqrt(np.sum(z ** 2, axis=1) / dof)
        again = conv & (rms < 0.1 * scale) & (rms > 1e-9) & (steps < max_steps)
        if not again.any():
            break
        scale = np.where(again, np.maximum(rms, 1e-12), scale)
        refit = _run(problem, values, u, max_steps=max_steps, prior_scale=scale,
                     step0=int(steps.max()) + 1, q_start=q_last, active0=again, **kw)
        q_last = refit.q_last
        for b in np.flatnonzero(again):
            u = u.at[b].set(refit.u[b])
            last = tuple(a.at[b].set(a2[b]) for a, a2 in zip(last, refit.last, strict=True))
            hist[b] = hist[b] + refit.histories[b]
            conv[b], steps[b] = refit.converged[b], steps[b] + 1 + refit.steps[b]
            acc[b] = acc[b] + refit.accepted_steps[b]
            msg[b] = refit.messages[b]
    return dataclasses.replace(run, u=u, last=last, q_last=q_last)


def least_squares(
    mech: Mechanism,
    data: Measurement | Sequence[Measurement],
    params: Params | Callable[[Mechanism], object] | None = None,
    *,
    loss: str = "linear",
    loss_scale: float | None = None,
    prior: Mechanism | Float[Array, " p"] | Mapping[str, float] | str | None = "weak",
    prior_sigma: float | Float[Array, " p"] | Mapping[str, float] | None = None,
    max_steps: int = MAX_STEPS,
    rtol: float = 1e-6,
    atol: float = 1e-6,
    ftol: float = 1e-10,
    gtol: float = 1e-16,
    inner_max_steps: int = 50,
    identifiable_sigma: float = 1.0,
    max_sigma_pct: float = 10.0,
    callback: Callable[[int, StepRecord], None] | None = None,
    curvature: bool = False,
) -> tuple[Mechanism, FitReport]:
    """Identify parameters of `mech` by nonlinear least squares through the equilibrium.

    **Arguments:**
    - `mech`: the model, holding the start values and every parameter not identified. The fit
      starts from `mech`'s values even when `params` was built from another model
      (`Params.starting_from`); only values set with `params.with_start(...)` override them.
    - `data`: one measurement or several (`Landmarks`, `Poses`, `Deformations`, `Channel`, or
      a `measure.Measurements`: its landmarks, or its poses, whitened by its own σ), each with
      its own load table; one data set each (see `least_squares_batch` for many).
    - `params`: the selection every identification method takes: a `Params`, or a `where` function
      (`lambda m: (m.bushings.k_trans, ...)`, every entry of the selected leaves; stiffnesses
      log-scaled).
    - `loss`: `'linear'`, `'huber'` or `'cauchy'`; `loss_scale` in units of σ (default 1.345
      Huber, 2.385 Cauchy).
    - `prior`, `prior_sigma`: Tikhonov prior θ_prior (a Mechanism, a `(p,)` array or a mapping
      name → value; missing names: the start) with σ in physical units (scalar, `(p,)`, or a
      mapping; inf = none). For a log-scaled parameter it acts on log θ with relative σ/θ_prior.
      Default `"weak"` (a parameter the data cannot see must not wander by orders of
      magnitude): every log-scaled parameter (stiffness) gets a prior at its start value with
      σ = `DEFAULT_LOG_PRIOR_SIGMA` = 3 on log θ (a factor e³ ≈ 20); positions get none. Chosen
      over steps restricted to the identifiable subspace because it is one objective (the LM's
      acceptance and the covariance stay those of a least-squares problem), it holds directions
      the data see a little as firmly as those they do not see at all, and the reported σ is the
      posterior one. Its price is a pull towards the start of the parameters the data determine
      (a shrinkage σ_data²/9 of their distance from the start, on log θ), which would spoil
      noise-free data: so when the data residual is below the stated noise (RMS ŝ < 0.1), the
      prior is expressed at the noise level the residuals show — the fit is repeated with the
      prior rows scaled by ŝ (`ADAPTIVE_PRIOR_ROUNDS` at most; noise-free data: the pull falls
      as ŝ² each round, to rounding). `prior=None`: no prior (the pre-issue-12 behaviour);
      `prior_sigma` alone: a prior at the start values with that σ (not rescaled).
    - `max_steps`: LM steps (default `MAX_STEPS` = 200). The stop does not depend on
      directions the data cannot see: it converges when, at an accepted point, a full
      Gauss–Newton step would lower χ² (prior
      rows included) by less than `gtol` + `ftol`·χ² (`gtol` absolute, in χ² units), or when
      every trial is rejected at a point where such a step would gain less than `STALL_CHI2`
      (the precision of the equilibria); `report.message` says which. `rtol`, `atol`: kept
      for compatibility (optimistix's solver arguments); the stop no longer uses the size of
      the step in u.
    - `inner_max_steps`: Newton iterations of each equilibrium (a case that needs more fails,
      and the step that led there is rejected).
    - `identifiable_sigma`: a parameter (or combination) whose σ from the data alone exceeds
      this, in internal units (relative for log-scaled parameters, mm for positions), is
      reported as not identifiable.
    - `max_sigma_pct`: a log-scaled parameter with a larger σ% is not reported identified
      (`is_identified`, `rows()`), however identifiable (default 10 %, as `direct`).
    - `callback(step, record)`: called after every LM step with its `StepRecord`.
    - `curvature`: also check the Gauss–Newton covariance against the full Hessian
      JᵀJ + Σ rᵢ∇²rᵢ at the estimate (`report.curvature`, a `CurvatureCheck`: does the
      residual curvature change σ by more than `CURVATURE_THRESHOLD`? It does with large
      residuals, i.e. model mismatch). Exact second derivatives through the equilibrium (p
      Hessian-vector products, one more compiled program: off by default).

    **Returns:** `(mech', report)`: the mechanism at the estimate (a parameter the data do not
    see keeps its start value, `returned_values`) and a `FitReport`.
    """
    data = _as_data(data)
    if {m.n_sets for m in data} != {None}:
        raise InputError("the measured values have a data-set axis: use least_squares_batch.")
    params = _as_params(mech, params)
    problem = _problem(mech, data, params, loss, loss_scale, prior, prior_sigma, inner_max_steps)
    u0 = params.to_internal(params.start)[None]
    run = _run_adaptive(
        problem, None, u0, adaptive=_is_weak(prior, prior_sigma), batched=False,
        max_steps=max_steps, rtol=rtol, atol=atol, ftol=ftol, gtol=gtol, callback=callback)
    # The first evaluation is at the start values: the identifiability gate's information.
    report = fit_report(params, problem, run, 0, loss, identifiable_sigma)
    report = dataclasses.replace(report, max_sigma_pct=float(max_sigma_pct))
    if curvature:
        report = dataclasses.replace(report, curvature=_curvature_check(problem, run))
    return params.apply(mech, jnp.asarray(returned_values(report))), report


def returned_values(report) -> np.ndarray:
    """The values the returned model carries: the estimate, except a parameter the data do not
    see (`identifiable` False: it lies in a direction of `null_space`) keeps its start value —
    the optimiser's drift along a direction the data cannot see is not a result, and the
    report calls it "not seen"."""
    return np.where(np.asarray(report.identifiable, bool), report.estimate, report.start)


@dataclasses.dataclass(frozen=True)
class BatchFitReport:
    """Result of `least_squares_batch`: `estimates` and linearised `sigma` `(sets, p)`,
    `converged` and `steps` `(sets,)`, and the full `FitReport` of every data set."""

    names: tuple[str, ...]
    estimates: np.ndarray
    sigma: np.ndarray
    converged: np.ndarray
    steps: np.ndarray
    reports: tuple[FitReport, ...]


def least_squares_batch(
    mech: Mechanism,
    data: Measurement | Sequence[Measurement],
    params: Params | Callable[[Mechanism], object] | None = None,
    *,
    start: Float[Array, "sets p"] | None = None,
    loss: str = "linear",
    loss_scale: float | None = None,
    prior="weak",
    prior_sigma=None,
    max_steps: int = MAX_STEPS,
    rtol: float = 1e-6,
    atol: float = 1e-6,
    ftol: float = 1e-10,
    gtol: float = 1e-16,
    inner_max_steps: int = 50,
    identifiable_sigma: float = 1.0,
    max_sigma_pct: float = 10.0,
    callback: Callable[[int, dict], None] | None = None,
) -> BatchFitReport:
    """Identify the same parameters from many data sets at once (e.g. 100 axles of one design,
    or 100 noise draws for a Monte-Carlo check of the reported σ).

    The measured values of every measurement carry a leading data-set axis (same loads, σ and
    mask); each LM step of all data sets is one compiled, vmapped call. Arguments as
    `least_squares`, plus `start` `(sets, p)` physical start values (default: `params.start`
    for every set). `callback(step, arrays)` gets the per-set step arrays.

    **Returns:** a `BatchFitReport`.
    """
    data = _as_data(data)
    sets = {m.n_sets for m in data}
    if len(sets) != 1 or None in sets:
        raise InputError("every measurement needs the same leading data-set axis for a batch; "
                         f"got {sorted(str(s) for s in sets)}.")
    n_sets = sets.pop()
    params = _as_params(mech, params)
    problem = _problem(mech, data, params, loss, loss_scale, prior, prior_sigma, inner_max_steps)
    if start is None:
        u0 = jnp.broadcast_to(params.to_internal(params.start), (n_sets, len(params)))
    else:
        start = np.asarray(start, dtype=float)
        if start.shape != (n_sets, len(params)):
            raise InputError(f"start must have shape ({n_sets}, {len(params)}); got "
                             f"{start.shape}.")
        for row in start:
            params.with_start(row)
        u0 = jax.vmap(params.to_internal)(jnp.asarray(start))
    values = _values_of(data)
    run = _run_adaptive(
        problem, values, u0, adaptive=_is_weak(prior, prior_sigma), batched=True,
        max_steps=max_steps, rtol=rtol, atol=atol, ftol=ftol, gtol=gtol, callback=callback)
    jac0 = run.first_jacobian
    if start is not None:
        # The identifiability gate's information at `params.start` (the same for every set:
        # see `FitReport.determined`), not at the given starts (e.g. the direct method's
        # linear estimates, which carry the data's noise): one more batched evaluation.
        u_gate = jnp.broadcast_to(params.to_internal(params.start), (n_sets, len(params)))
        q_gate = jnp.zeros((n_sets, problem.loads.n_cases, problem.mech.n_coordinates))
        jac0 = _evaluate(problem, values, u_gate, q_gate, True, jnp.ones(n_sets))[1]
    reports = []
    for b in range(n_sets):
        one_problem = _with_values(problem, jax.tree.map(lambda a, b=b: a[b], values))
        reports.append(dataclasses.replace(
            fit_report(params, one_problem, run, b, loss, identifiable_sigma, jac0[b]),
            max_sigma_pct=float(max_sigma_pct)))
    return BatchFitReport(
        names=params.names, estimates=np.stack([r.estimate for r in reports]),
        sigma=np.stack([r.sigma for r in reports]), converged=run.converged.copy(),
        steps=run.steps.copy(),
        reports=tuple(reports))


def whitened_residuals(
    mech: Mechanism,
    data: Measurement | Sequence[Measurement],
    params: Params,
    theta: Float[Array, " p"],
    *,
    loss: str = "linear",
    loss_scale: float | None = None,
) -> tuple[Float[Array, " n"], Float[Array, "n p"]]:
    """The residual vector the fit minimises (one data set, without prior rows) at physical
    parameters θ, and its Jacobian with respect to θ (implicit differentiation through the
    equilibria, forward mode). Uses the same compiled programs as `least_squares`."""
    data = _as_data(data)
    params = _as_params(mech, params)
    problem = _problem(mech, data, params, loss, loss_scale, None, None, 50)
    u = params.to_internal(jnp.asarray(theta, dtype=float))
    q0 = jnp.zeros((problem.loads.n_cases, mech.n_coordinates))
    z, jac, _, _, status = _evaluate(problem, None, u, q0, False)
    failed = np.flatnonzero(np.asarray(status) != Status.CONVERGED)
    if failed.size:
        raise InputError(f"no equilibrium in load case(s) {failed.tolist()} at these "
                         "parameters.")
    n = z.size - len(params)
    return z[:n], jac[:n] / params.derivative(u)[None, :]


def predict(mech: Mechanism, data: Measurement | Sequence[Measurement],
            *, inner_max_steps: int = 50) -> dict[str, Array]:
    """What the model predicts for each measurement (its measured shape and units, one data
    set): e.g. synthetic landmarks. Uses the equilibrium program of `least_squares`.

    **Raises:** `InputError` if a load case has no equilibrium.
    """
    data = _as_data(data)
    for meas in data:
        meas.check(mech)
    loads, slices = _combined_loads(data)
    tangents = jax.tree.map(lambda a: jnp.zeros((TANGENT_BLOCK, *a.shape), a.dtype), mech)
    q0 = jnp.zeros((loads.n_cases, mech.n_coordinates))
    q, status, _ = _equilibria(mech, loads, q0, tangents, int(inner_max_steps))
    if np.any(np.asarray(status) != Status.CONVERGED):
        raise InputError(f"no equilibrium in load case(s) "
                         f"{np.flatnonzero(np.asarray(status) != Status.CONVERGED).tolist()}.")
    single = tuple(m.select(0) if m.n_sets else m for m in data)
    out = _predict(single, mech, q, slices)
    return {m.name: v for m, v in zip(data, out, strict=True)}
