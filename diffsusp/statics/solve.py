"""Static equilibrium: damped Newton on the KKT system, batched, with implicit differentiation.

spec: stiffness §1.9 (Q_ext + Q_int + Φ_qᵀλ = 0, Φ = c); DESIGN.md "Static equilibrium".

Per load case, from the start pose with zero multipliers (the first Newton step estimates them):
each Newton step solves the KKT system of the wrench residual in twist coordinates
(`kernel.assemble_batch`) after a Ruiz row/column equilibration (forces in N, moments in N·mm
and constraint rows in mm or radians differ by orders of magnitude); the step is capped so no
part turns by more than 1 rad at once, applied to each part as a rigid screw motion (see
`kernel.retract`), and backtracked on a scaled merit function (every trial point is assembled
with its Jacobian, which becomes the next step's if the point is accepted). A large batch runs
as a pool of `_POOL` cases at a time: a case that stops hands its slot to the next one waiting.
A case has converged when every force row is below `rtol`·F_s (moment rows `rtol`·F_s·L, with
F_s the load scale and L the model's length scale) and every constraint row below `atol` mm; a
case whose line search makes no progress for several steps, or that has rejected 24 trial points
in all, is stopped as stalled (no equilibrium nearby).

The solution is differentiated implicitly: for a parameter tangent dθ, dy = −J⁻¹ ∂r/∂θ·dθ at the
solution (one more linear solve), in forward and reverse mode; the Newton loop is never unrolled.
"""

import warnings
from collections.abc import Iterator, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ..compilation import filter_jit
from ..errors import ConvergenceError, InputError, ModelError
from ..geometry import projected_angles
from ..model.mechanism import Loads, Mechanism
from ._linearize import linearize_internal, scaled_solve
from .checks import STABILITY_TOLERANCE, kkt_stability_margin, law_validity, warn_law_validity
from .kernel import (
    assemble_batch,
    generalised_residual,
    part_poses_internal,
    retract,
    to_internal,
    to_public,
)
from .status import Status

_STALL_STEPS = 4  # consecutive steps shorter than 1/100 of Newton's before giving up
_MAX_BACKTRACKS = 24  # rejected trial points in all before giving up (each costs an assembly)
_ARMIJO = 1e-4  # sufficient decrease of the merit, relative to the step length
_SHORT_STEP = 0.01  # a step length below this counts towards a stall
_FLOOR_FACTOR = 1e3  # the round-off floor: within this factor of the tolerances ...
_FLOOR_STEP = 1e-13  # ... and a relative step below this
_MAX_TURN = 1.0  # rad: the largest rotation of a part in one Newton step
_POOL = 48  # cases iterated at once; a batch larger than this runs as a pool (see `_newton`)
_LINE_SEARCH = 8  # trial steps (α from 1, each next one 0.1–0.5 of the last) before the last
# one is taken anyway


class StaticSolution(eqx.Module):
    """Equilibria of a table of load cases (leading axis = case, absent for a single case).

    **Fields:** `q` (mm and Gibbs vectors, 6 per part), `multipliers` (one per independent
    constraint row: N for length rows, N·mm for angular rows), `status` (a `Status`
    code: 0 converged, 1 max_steps reached, 2 non-finite, 3 stalled), `iterations`, `residual`
    (largest force row relative to the load scale), `constraint_error` (mm), `stable` (the
    reduced tangent stiffness is positive definite) and `law_valid` (every bushing's projected
    angles within their validity), both False for a case that did not converge
    (`diffsusp.statics.checks`). The two flags are computed in the solve's own program (from
    the Newton's last Jacobian) when `solve_statics` / `solve_sweep` are called with concrete
    arrays; under a transformation (jit, vmap, grad) they are None: call
    `checks.equilibrium_flags` there if they are needed.
    """

    q: Float[Array, "*cases n"]
    multipliers: Float[Array, "*cases m"]
    status: Int[Array, "*cases"]
    iterations: Int[Array, "*cases"]
    residual: Float[Array, "*cases"]
    constraint_error: Float[Array, "*cases"]
    stable: Bool[Array, "*cases"] | None = None
    law_valid: Bool[Array, "*cases"] | None = None

    @property
    def converged(self):
        return self.status == Status.CONVERGED


def _force_scale(mech: Mechanism, loads: Loads, reaction):
    """Load scale F_s (N) of one case: the largest applied force, applied moment / L and joint
    reaction force, plus 1 N."""
    return (
        1.0
        + jnp.max(jnp.abs(loads.force), initial=0.0)
        + jnp.max(jnp.abs(loads.moment), initial=0.0) / mech.length_scale
        + jnp.max(jnp.abs(reaction.reshape(-1, 6)[:, :3]), initial=0.0)
    )


def _measures(mech: Mechanism, r, f_scale):
    """(largest force row / F_s, largest constraint row in mm, scaled merit ½‖r_s‖²): moment
    rows are divided by F_s·L and angular constraint rows multiplied by L."""
    topo = mech.topology
    n, length = topo.n, mech.length_scale
    rot = np.tile(np.r_[np.zeros(3), np.ones(3)], n // 6).astype(bool)
    force = r[:n] / (f_scale * jnp.asarray(np.where(rot, length, 1.0)))
    constraint = r[n:] * jnp.asarray(np.where(topo.angular_live, length, 1.0))
    merit = 0.5 * (jnp.sum(force**2) + jnp.sum((constraint / length) ** 2))
    return (jnp.max(jnp.abs(force), initial=0.0), jnp.max(jnp.abs(constraint), initial=0.0),
            merit)


class _Tolerances(eqx.Module):
    rtol: float = eqx.field(static=True)
    atol: float = eqx.field(static=True)
    max_steps: int = eqx.field(static=True)


class _NewtonState(eqx.Module):
    """The Newton of one load case (one pool slot) between two passes.

    `y` is the last accepted point (solver coordinates and multipliers), `residual` the
    generalised residual there, `step` the capped Newton step from it (twist coordinates) and
    `alpha` the step length of the next trial point retract(y, alpha·step)."""

    y: Float[Array, " k"]
    residual: Float[Array, " k"]
    step: Float[Array, " k"]
    alpha: Float[Array, ""]
    merit: Float[Array, ""]
    force_scale: Float[Array, ""]
    iteration: Int[Array, ""]
    trial: Int[Array, ""]  # trial points rejected since the last accepted one
    stall: Int[Array, ""]  # consecutive accepted steps shorter than _SHORT_STEP
    backtracks: Int[Array, ""]  # trial points rejected in all
    status: Int[Array, ""]  # Status.MAX_STEPS while running
    converged: Bool[Array, ""]


def _init(y0, empty) -> _NewtonState:
    """The state of a case before its first pass: the start point (y0, λ = 0) as the trial
    point with α = 1 and a zero step; `empty` marks a pool slot without a case."""
    zero = jnp.zeros((), y0.dtype)
    count = jnp.zeros((), int)
    return _NewtonState(
        y=y0, residual=jnp.zeros_like(y0), step=jnp.zeros_like(y0), alpha=zero + 1.0,
        merit=zero + jnp.inf, force_scale=zero + 1.0, iteration=count, trial=count,
        stall=count, backtracks=count, status=count + Status.MAX_STEPS, converged=empty)


def _running(s: _NewtonState, tol: _Tolerances):
    return (s.iteration <= tol.max_steps) & (s.status == Status.MAX_STEPS) & ~s.converged


def _done(force, constraint, step, tol: _Tolerances):
    """Converged (the `_measures` of the residual within the tolerances), or at the round-off
    floor: within `_FLOOR_FACTOR` × the tolerances and no longer moving."""
    tight = (force <= tol.rtol) & (constraint <= tol.atol)
    floor = ((force <= _FLOOR_FACTOR * tol.rtol) & (constraint <= _FLOOR_FACTOR * tol.atol)
             & (step <= _FLOOR_STEP))
    return tight | floor


def _step(mech: Mechanism, tol: _Tolerances, s: _NewtonState, loads: Loads, y_try, r_twist, jac,
          dy) -> _NewtonState:
    """The next state of one case, given the wrench residual, its twist Jacobian and the Newton
    step J⁻¹·(−r) at its trial point: accept the point (Armijo on the scaled merit) and take
    the new step, or backtrack."""
    n = mech.topology.n
    length = mech.length_scale
    rot = jnp.asarray(np.r_[np.tile(np.r_[np.zeros(3), np.ones(3)], n // 6),
                            np.zeros(mech.topology.m)])
    # Convergence and the merit are measured on the generalised forces of the Gibbs
    # coordinates (F, G(b)ᵀM), as `residual` reports them; the step uses the twist form.
    r = generalised_residual(y_try[:n], r_twist)
    merit = _measures(mech, r, s.force_scale)[2]
    merit = jnp.where(jnp.isfinite(merit), merit, jnp.inf)
    first = s.iteration == 0
    accept = first | (merit <= (1.0 - _ARMIJO * s.alpha) * s.merit) | (
        s.trial >= _LINE_SEARCH - 1)
    # The next Newton step from the trial point (used only if it is accepted).
    f_scale = _force_scale(mech, loads, jac[:n, n:] @ y_try[n:])
    cap = jnp.max(jnp.abs(dy * rot))
    dy = dy * jnp.minimum(1.0, _MAX_TURN / jnp.maximum(cap, 1e-300))
    moved = jnp.max(jnp.abs(s.alpha * s.step[:n])) / (length + jnp.max(jnp.abs(y_try[:n])))
    # A case whose line search keeps cutting the step to nothing has no equilibrium nearby
    # (e.g. a suspension pulled past its travel): stop it so that it does not hold the whole
    # batch to max_steps.
    stall = jnp.where(first, 0, jnp.where(s.alpha < _SHORT_STEP, s.stall + 1, 0))
    status = jnp.where(jnp.all(jnp.isfinite(r)), Status.MAX_STEPS, Status.NONFINITE)
    status = jnp.where(stall >= _STALL_STEPS, Status.STALLED, status)
    force, constraint, rescaled = _measures(mech, r, f_scale)
    accepted = _NewtonState(
        y=y_try, residual=r, step=dy, alpha=jnp.ones_like(s.alpha), merit=rescaled,
        force_scale=f_scale, iteration=s.iteration + 1, trial=jnp.zeros_like(s.trial),
        stall=stall, backtracks=s.backtracks, status=status,
        converged=_done(force, constraint, jnp.where(first, jnp.inf, moved), tol))
    # Backtrack to the minimum of the quadratic through φ(0), φ'(0) = −2φ(0) (a Newton
    # step on ½‖r‖²) and φ(α), kept within [0.1α, 0.5α]; 0.1α if φ(α) is not finite.
    alpha, phi0 = s.alpha, s.merit
    curvature = (merit - phi0 + 2.0 * alpha * phi0) / alpha**2
    shrink = jnp.where(jnp.isfinite(merit) & (curvature > 0),
                       phi0 / jnp.maximum(curvature * alpha, 1e-300), 0.1)
    backtracks = s.backtracks + 1
    running = _running(s, tol)
    # A stopped case keeps its state; a rejected point changes only the line search's fields.
    kept = eqx.tree_at(
        lambda t: (t.alpha, t.trial, t.backtracks, t.status), s,
        tuple(jnp.where(running, a, b) for a, b in (
            (alpha * jnp.clip(shrink, 0.1, 0.5), s.alpha), (s.trial + 1, s.trial),
            (backtracks, s.backtracks),
            (jnp.where(backtracks >= _MAX_BACKTRACKS, Status.STALLED, s.status), s.status))))
    return jax.tree.map(lambda a, b: jnp.where(running & accept, a, b), accepted, kept)


class _Outcome(eqx.Module):
    """Per-case result of the Newton besides the solution: how it stopped (`Status` codes),
    its measures, and the stability margin from its last Jacobian (None unless asked)."""

    status: Int[Array, " cases"]
    iterations: Int[Array, " cases"]
    residual: Float[Array, " cases"]
    constraint_error: Float[Array, " cases"]
    margin: Float[Array, " cases"] | None = None


def _outcome(mech: Mechanism, s: _NewtonState) -> _Outcome:
    """The `_Outcome` fields of stopped slots (vmapped over them)."""
    force, constraint, _ = jax.vmap(lambda r, f: _measures(mech, r, f))(s.residual,
                                                                         s.force_scale)
    return _Outcome(status=jnp.where(s.converged, Status.CONVERGED, s.status),
                    iterations=s.iteration - 1, residual=force, constraint_error=constraint)


def _newton(mech: Mechanism, loads: Loads, q0, tol: _Tolerances, flags: bool):
    """Damped Newton on the KKT system from (q0, λ = 0), for a batch of load cases (leading
    axis of `loads` and q0): `_init`, then `_step` until not `_running`, per case.

    One evaluation of the residual and its Jacobian per loop pass: a pass evaluates the trial
    point; if the scaled merit decreased enough (Armijo) the point is accepted and the next
    Newton step is solved from the Jacobian just computed, otherwise the step is shortened. So
    a full Newton step costs one assembly and one linear solve, and the program traces the
    assembly once. Every case runs its own iteration (per-case state); only the assembly's
    scatter is done slot-wide (`kernel.assemble_batch`). At most `_POOL` cases are iterated at
    once and a stopped case's slot takes the next case, so a batch costs the sum of its cases'
    passes (about 5 each), not the slowest case's (up to 40 near the envelope's edge) times every
    case; each case's iterates do not depend on the others (vmap = loop).

    With `flags`, the twist Jacobian of the pass where a case stops (the one at its solution
    when it converged) is kept, and its stability margin (`checks.kkt_stability_margin`)
    computed after the loop, in the same program."""
    topo = mech.topology
    n = topo.n
    cases = q0.shape[0]
    size = n + topo.m
    y0 = jnp.concatenate([q0, jnp.zeros((cases, topo.m), q0.dtype)], axis=1)
    slots = min(cases, _POOL)

    def fresh(case):
        return jax.vmap(_init)(y0[jnp.minimum(case, cases - 1)], case >= cases)

    def body(pool):
        # One Newton pass over the slots; a slot whose case has stopped hands its result over
        # and takes the next case waiting (a pool: each case runs its own iteration, so the
        # batch costs the sum of the cases' passes, not the slowest case's times all cases).
        s, case, queue, y_out, out, jac_out = pool
        loads_s = jax.tree.map(lambda a: a[jnp.minimum(case, cases - 1)], loads)
        y_try = jax.vmap(lambda y, d: retract(y, d, n))(s.y, s.alpha[:, None] * s.step)
        r, jac = assemble_batch(mech, loads_s, y_try[:, :n], y_try[:, n:])
        # The slots' systems are factorised one by one (the same CPU time as one batched call):
        # jaxlib's batched CPU LU splits a batch over its intra-op thread pool and waits for
        # it from a pool thread, and two such calls at once (the batch split over two devices)
        # deadlocked this 2-core machine; a single system is factorised inline.
        dy = jax.lax.map(lambda a: scaled_solve(a[0], -a[1]), (jac, r))
        s = jax.vmap(lambda s_, l_, y_, r_, j_, d_: _step(mech, tol, s_, l_, y_, r_, j_, d_))(
            s, loads_s, y_try, r, jac, dy)
        stopped = ~jax.vmap(lambda s_: _running(s_, tol))(s) & (case < cases)
        dest = jnp.where(stopped, case, cases)  # out of range: dropped
        y_out = y_out.at[dest].set(s.y, mode="drop")
        out = jax.tree.map(lambda o, v: o.at[dest].set(v, mode="drop"), out, _outcome(mech, s))
        if flags:
            jac_out = jac_out.at[dest].set(jac, mode="drop")
        new_case = jnp.where(stopped, queue + jnp.cumsum(stopped) - 1, case)
        new_case = jnp.where(stopped & (new_case >= cases), cases, new_case)
        s = jax.tree.map(lambda a, b: jnp.where(stopped.reshape((-1,) + (1,) * (a.ndim - 1)),
                                                a, b), fresh(new_case), s)
        return s, new_case, queue + jnp.sum(stopped), y_out, out, jac_out

    def more(pool):
        s, case = pool[0], pool[1]
        return jnp.any(jax.vmap(lambda s_: _running(s_, tol))(s) & (case < cases))

    first = jnp.arange(slots)
    zero, count = jnp.zeros(cases, y0.dtype), jnp.zeros(cases, int)
    out = _Outcome(status=count, iterations=count, residual=zero, constraint_error=zero)
    jac_out = jnp.zeros((cases, size, size) if flags else (0,), y0.dtype)
    pool = (fresh(first), first, jnp.asarray(slots), y0, out, jac_out)
    _, _, _, y, out, jac_out = jax.lax.while_loop(more, body, pool)
    if flags:
        converged = out.status == Status.CONVERGED
        # Case after case (lax.map): each QR and eigen-decomposition is one small LAPACK call
        # run inline (see `scaled_solve` on batched CPU calls).
        margin = jax.lax.map(lambda j: kkt_stability_margin(mech, j), jac_out)
        out = eqx.tree_at(lambda o: o.margin, out, jnp.where(converged, margin, jnp.nan),
                          is_leaf=lambda x: x is None)
    return y, out


@eqx.filter_custom_jvp
def _equilibrium(mech, loads, q0, *, tol, flags):
    """Solver coordinates and multipliers (cases, n + m) and the `_Outcome` of a batch of load
    cases."""
    return _newton(mech, loads, q0, tol, flags)


@_equilibrium.def_jvp
def _equilibrium_jvp(primals, tangents, *, tol, flags):
    # Implicit function theorem, case by case: J·dy = −∂r/∂(mech, loads)·t (`linearize`).
    # Everything here stays differentiable (y through this same rule, J and ∂r through
    # autodiff), so derivatives of derivatives — e.g. the sensitivity of bump steer to a
    # stiffness — are exact too.
    mech, loads, q0 = primals
    t_mech, t_loads, _ = tangents
    y, out = _equilibrium(mech, loads, q0, tol=tol, flags=flags)

    def tangent(loads_, y_, t_loads_):
        return linearize_internal(mech, loads_, y_).tangent(t_mech, t_loads_)

    if t_loads is None:
        dy = jax.vmap(lambda l, y_: tangent(l, y_, None))(loads, y)
    else:
        dy = jax.vmap(tangent)(loads, y, t_loads)

    def zero(a):
        if jnp.issubdtype(a.dtype, jnp.inexact):
            return jnp.zeros_like(a)
        return np.zeros(a.shape, jax.dtypes.float0)

    return (y, out), (dy, jax.tree.map(zero, out))


def _bushing_angles(mech: Mechanism, y):
    """Projected angles (bushings, 3) (rad) of every bushing at solver coordinates y (n,): the
    rotation of its I marker's axes in its J marker's, AX, AY, AZ (spec stiffness §0); the
    angles of `bushing_states` without its deformations and forces."""
    b = mech.bushings
    part = np.asarray(mech.topology.marker_part)
    i, j = np.asarray(b.i_marker, dtype=int), np.asarray(b.j_marker, dtype=int)
    rot = part_poses_internal(y)[1]
    axes = mech.markers.orientation
    ai = jnp.einsum("eij,ejk->eik", rot[part[i]], axes[i])
    aj = jnp.einsum("eij,ejk->eik", rot[part[j]], axes[j])
    return jax.vmap(projected_angles)(jnp.einsum("eji,ejk->eik", aj, ai))


def _solve_batch_cases(mech, loads, q0, tol, flags):
    """Public-coordinate solutions of a batch of cases (leading axis), and with `flags` the
    bushings' projected angles (cases, bushings, 3) for the validity warning."""
    y0 = jax.vmap(lambda q: to_internal(mech, q))(q0)
    y, out = _equilibrium(mech, loads, y0, tol=tol, flags=flags)
    n = mech.topology.n
    q = jax.vmap(lambda y_: to_public(mech, y_))(y[:, :n])
    sol = StaticSolution(q=q, multipliers=y[:, n:], status=out.status,
                         iterations=out.iterations, residual=out.residual,
                         constraint_error=out.constraint_error)
    if not flags:
        return sol, None
    converged = out.status == Status.CONVERGED
    # The angles of every case with finite coordinates (the warning names a case that did not
    # converge too, as its pose may be why); the flag only for converged ones.
    finite = jnp.all(jnp.isfinite(y[:, :n]), axis=1)
    m_, y_ = jax.lax.stop_gradient((mech, jnp.where(finite[:, None], y[:, :n], 0.0)))
    if mech.bushings.names:
        angles = jax.vmap(lambda y1: _bushing_angles(m_, y1))(y_)
        ratio = jax.vmap(lambda a: law_validity(m_, None, angles=a))(angles)
    else:
        angles, ratio = None, jnp.zeros(q.shape[0], q.dtype)
    sol = eqx.tree_at(lambda s: (s.stable, s.law_valid), sol,
                      (converged & (out.margin > STABILITY_TOLERANCE), converged & (ratio <= 1.0)),
                      is_leaf=lambda x: x is None)
    return sol, angles


def _solve_cases(mech, loads, q0, tol, flags, chunk):
    n_cases = loads.force.shape[0]
    if chunk is None or n_cases <= chunk:
        return _solve_batch_cases(mech, loads, q0, tol, flags)
    # Chunks of `chunk` cases one after the other (the last one padded by repeating a case).
    n_chunks = -(-n_cases // chunk)
    pad = n_chunks * chunk - n_cases

    def split(a):
        a = jnp.concatenate([a, jnp.repeat(a[-1:], pad, axis=0)]) if pad else a
        return a.reshape(n_chunks, chunk, *a.shape[1:])

    out = jax.lax.map(lambda args: _solve_batch_cases(mech, *args, tol, flags),
                      jax.tree.map(split, (loads, q0)))
    return jax.tree.map(lambda a: a.reshape(n_chunks * chunk, *a.shape[2:])[:n_cases], out)


@filter_jit
def _solve_batch(mech, loads, q0, tol, flags, chunk, single, mesh=None):
    """The whole of a `solve_statics` call in one program: (solution, bushing angles or None).
    `single`: one case without a case axis (added and removed here); q0 is per case or
    shared."""
    if single:
        loads = jax.tree.map(lambda a: a[None], loads)
    q0 = jnp.broadcast_to(q0, (loads.force.shape[0], q0.shape[-1]))
    if mesh is None:
        out = _solve_cases(mech, loads, q0, tol, flags, chunk)
    else:
        # One share of the cases per device, each solved by its own pool, no communication;
        # the case count is padded to a multiple of the devices by repeating the last case.
        # (On the CPU this needs `compilation.CPU_OPTIONS`: see there.)
        n_cases, k = loads.force.shape[0], mesh.size
        pad = -n_cases % k

        def padded(a):
            return jnp.concatenate([a, jnp.repeat(a[-1:], pad, axis=0)]) if pad else a

        cases = jax.sharding.PartitionSpec("cases")
        solve = jax.shard_map(
            lambda l, q: _solve_cases(mech, l, q, tol, flags, chunk),
            mesh=mesh, in_specs=(cases, cases), out_specs=cases, check_vma=False)
        out = jax.tree.map(lambda a: a[:n_cases], solve(*jax.tree.map(padded, (loads, q0))))
    if single:
        out = jax.tree.map(lambda a: a[0], out)
    return out


def _solve_one(mech, loads, q0, tol, flags):
    out = _solve_batch_cases(mech, jax.tree.map(lambda a: a[None], loads), q0[None], tol, flags)
    return jax.tree.map(lambda a: a[0], out)


@filter_jit
def _solve_path(mech, loads, q0, tol, flags):
    def step(q, loads_):
        sol, angles = _solve_one(mech, loads_, q, tol, flags)
        return jnp.where(sol.status == Status.CONVERGED, sol.q, q), (sol, angles)

    _, out = jax.lax.scan(step, q0, loads)
    return out


def _is_traced(tree) -> bool:
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(tree))


def _check_inputs(mech: Mechanism, loads: Loads):
    """Value checks on concrete inputs (traced inputs are checked by `eqx.error_if`)."""
    leaves = [(path, leaf) for path, leaf in jax.tree_util.tree_leaves_with_path((mech, loads))
              if eqx.is_inexact_array(leaf) and not isinstance(leaf, jax.core.Tracer)]
    # One transfer for every leaf (a copy per leaf cost a warm call a millisecond).
    values = jax.device_get([leaf for _, leaf in leaves])
    for (path, _), value in zip(leaves, values, strict=True):
        if not np.all(np.isfinite(value)):
            where = jax.tree_util.keystr(path)
            owner = "mechanism" if path[0].idx == 0 else "loads"
            raise ModelError(
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
                raise ModelError(
                    f"bushing '{mech.bushings.names[e]}' has {field}[{'xyz'[a]}] = {k[e, a]} < 0; "
                    "stiffness must be ≥ 0."
                )
    if not _is_traced(mech.springs.k) and mech.springs.names:
        k = np.asarray(mech.springs.k)
        for e, name in enumerate(mech.springs.names):
            if not mech.springs.tabulated[e] and k[e] <= 0:
                raise ModelError(f"spring '{name}' has k = {k[e]} ≤ 0; k must be positive.")


def _report(sol: StaticSolution, throw: bool, what: str):
    if _is_traced(sol.status):
        return sol
    status = np.atleast_1d(np.asarray(sol.status))
    bad = np.flatnonzero(status != Status.CONVERGED)
    if bad.size and throw:
        c = int(bad[0])
        res = float(np.atleast_1d(np.asarray(sol.residual))[c])
        con = float(np.atleast_1d(np.asarray(sol.constraint_error))[c])
        raise ConvergenceError(
            f"{what}: load case {c} did not converge ({Status(int(status[c])).text}, relative "
            f"force residual {res:.3g}, constraint error {con:.3g} mm; {bad.size} of "
            f"{status.size} cases failed). Check that the loads are within what the model can "
            "carry (stops, stiffness), raise max_steps, solve the path as a sweep with "
            "solve_sweep, or pass throw=False to get per-case statuses."
        )
    if bad.size:
        warnings.warn(f"{what}: {bad.size} of {status.size} cases did not converge.", stacklevel=3)
    return sol


def _start(mech, q0):
    """The start coordinates as given (per case or shared), checked on the host: broadcasting
    happens in the solve's program."""
    n = mech.n_coordinates
    if q0 is None:
        return np.zeros(n)
    if not isinstance(q0, jax.Array):
        q0 = np.asarray(q0, dtype=float)
    if q0.shape[-1:] != (n,) or q0.ndim > 2:
        raise InputError(f"q0 must have {n} coordinates per case; got shape {q0.shape}.")
    return q0


def _mesh(devices):
    """A one-axis ("cases") mesh over `devices` (see `solve_statics`), None for one device."""
    local = jax.local_devices()
    if isinstance(devices, str):
        if devices != "all":
            raise InputError(
                f'devices must be a count, "all" or a list of devices; got {devices!r}.')
        devices = local
    elif isinstance(devices, (int, np.integer)):
        if not 1 <= devices <= len(local):
            raise InputError(f"devices={devices}: {len(local)} local device(s) are available "
                             "(on the CPU, ask JAX for more with jax_num_cpu_devices).")
        devices = local[:devices]
    devices = tuple(devices)
    if len(devices) <= 1:
        return None
    return jax.sharding.Mesh(np.array(devices), ("cases",))


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
    devices: "int | str | Sequence[jax.Device] | None" = None,
    checks: bool = True,
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
    - `devices`: split a table of cases over several devices (`jax.shard_map` over the case
      axis; each device solves its share with its own pool, and the result is the same as on
      one device, gathered on the default device): a count of local devices, "all", or a list
      of devices. Default (None): one device. Calls inside jit / vmap / grad run on one device.
    - `checks`: compute the `stable` / `law_valid` flags and warn about bushing laws beyond
      their validity. They are computed in the solve's own program (one compiled program and
      one dispatch per call): stability from the Newton's last Jacobian at each solution,
      validity from the bushings' projected angles (`diffsusp.statics.checks`). False leaves
      the flags None, for a caller that checks in its own program (`kc.evaluate`).

    **Returns:** a `StaticSolution`, differentiable (implicitly) with respect to every float
    leaf of `mech` and `loads`.
    """
    _check_x64()
    _check_inputs(mech, loads)
    n_cases = loads.n_cases
    q0 = _start(mech, q0)
    if n_cases is None and q0.ndim != 1:
        raise InputError(f"q0 must be one start ({mech.n_coordinates},) for a single load case; "
                         f"got shape {q0.shape}.")
    tol = _Tolerances(rtol=float(rtol), atol=float(atol), max_steps=int(max_steps))
    traced = _is_traced((mech, loads, q0))
    flags = checks and not traced
    mesh = None
    if n_cases is not None and not traced and devices is not None:
        mesh = _mesh(devices)
        if mesh is not None and n_cases < mesh.size:
            mesh = None
    sol, angles = _solve_batch(mech, loads, q0, tol, flags, chunk, n_cases is None, mesh)
    if mesh is not None:  # later programs run on one device, as for an unsplit batch
        sol = jax.device_put(sol, jax.devices()[0])
    if angles is not None:
        warn_law_validity(mech, angles, stacklevel=2)
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
    the previous solution (`lax.scan`), with the `stable` / `law_valid` flags computed in the
    same program (as `solve_statics`). Arguments as `solve_statics`; `loads` must have a case
    axis, in path order."""
    _check_x64()
    _check_inputs(mech, loads)
    if loads.n_cases is None:
        raise InputError("solve_sweep needs loads with a leading case axis (the path).")
    q0 = _start(mech, q0)
    if q0.ndim != 1:
        raise InputError(f"solve_sweep starts from one q0 ({mech.n_coordinates},); got shape "
                         f"{q0.shape}.")
    tol = _Tolerances(rtol=float(rtol), atol=float(atol), max_steps=int(max_steps))
    flags = not _is_traced((mech, loads, q0))
    sol, angles = _solve_path(mech, loads, q0, tol, flags)
    if angles is not None:
        warn_law_validity(mech, angles, stacklevel=2)
    return _report(sol, throw, "solve_sweep")


def solve_statics_chunks(
    mech: Mechanism, loads: Loads, chunk: int = 256, **solve_kwargs
) -> Iterator[tuple[int, int, StaticSolution]]:
    """`solve_statics` over a table of load cases, `chunk` cases at a time, for a caller that
    streams results (writes each chunk's rows as it completes, shows progress, can stop).

    **Arguments:** `mech`, `loads` (with a leading case axis); `chunk`: cases per solve (the
    last chunk is padded with copies of the last case, so every chunk runs one compiled
    program); `solve_kwargs`: passed to `solve_statics` (`max_steps`, `throw`, ...).

    **Yields:** `(start, stop, solution)` in case order: the `StaticSolution` of cases
    `start:stop` (the padding dropped).
    """
    n = loads.n_cases
    if n is None:
        raise InputError("solve_statics_chunks needs loads with a leading case axis.")
    if chunk < 1:
        raise InputError(f"chunk must be at least 1; got {chunk}.")
    chunk = min(chunk, max(n, 1))
    for start in range(0, n, chunk):
        stop = min(start + chunk, n)
        index = np.minimum(np.arange(start, start + chunk), n - 1)
        sol = solve_statics(mech, jax.tree.map(lambda a, i=index: a[i], loads), **solve_kwargs)
        yield start, stop, jax.tree.map(lambda a, k=stop - start: a[:k], sol)
