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

import enum
import os
import warnings
from collections.abc import Iterator, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ..compilation import filter_jit
from ..errors import ConvergenceError
from ..model.mechanism import Loads, Mechanism
from ._linearize import linearize_internal, scaled_solve
from .checks import warn_law_validity, with_flags
from .kernel import assemble_batch, generalised_residual, retract, to_internal, to_public
from .outputs import bushing_states


class Status(enum.IntEnum):
    """Why the Newton of a load case stopped: the per-case `StaticSolution.status` codes.

    The arrays hold the integer codes (they live inside compiled programs); compare them with
    the members (`sol.status == Status.CONVERGED`) and read a code's meaning with
    `Status(code).text`.
    """

    CONVERGED = 0
    MAX_STEPS = 1
    NONFINITE = 2
    STALLED = 3

    @property
    def text(self) -> str:
        return _STATUS_TEXTS[self]


_STATUS_TEXTS = {
    Status.CONVERGED: "converged",
    Status.MAX_STEPS: "max_steps reached",
    Status.NONFINITE: "non-finite",
    Status.STALLED: "stalled: no descent in the last steps",
}
STATUS_TEXT = {int(s): s.text for s in Status}  # code → text (kept for callers of the codes)
_STALL_STEPS = 4  # consecutive steps shorter than 1/100 of Newton's before giving up
_MAX_BACKTRACKS = 24  # rejected trial points in all before giving up (each costs an assembly)


class StaticSolution(eqx.Module):
    """Equilibria of a table of load cases (leading axis = case, absent for a single case).

    **Fields:** `q` (mm and Gibbs vectors, 6 per part), `multipliers` (one per independent
    constraint row: N for length rows, N·mm for angular rows), `status` (a `Status`
    code: 0 converged, 1 max_steps reached, 2 non-finite, 3 stalled), `iterations`, `residual`
    (largest force row relative to the load scale), `constraint_error` (mm), `stable` (the
    reduced tangent stiffness is positive definite) and `law_valid` (every bushing's projected
    angles within their validity), both False for a case that did not converge
    (`diffsusp.statics.checks`). The two flags are computed when `solve_statics` /
    `solve_sweep` are called with concrete arrays; under a transformation (jit, vmap, grad)
    they are None: call `checks.equilibrium_flags` there if they are needed.
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


_MAX_TURN = 1.0  # rad: the largest rotation of a part in one Newton step
_POOL = 48  # cases iterated at once; a batch larger than this runs as a pool (see `_newton`)
_LINE_SEARCH = 8  # trial steps (α from 1, each next one 0.1–0.5 of the last) before the last
# one is taken anyway


def _newton(mech: Mechanism, loads: Loads, q0, *, rtol, atol, max_steps):
    """Damped Newton on the KKT system from (q0, λ = 0), for a batch of load cases (leading
    axis of `loads` and q0).

    One evaluation of the residual and its Jacobian per loop pass: a pass evaluates the trial
    point; if the scaled merit decreased enough (Armijo) the point is accepted and the next
    Newton step is solved from the Jacobian just computed, otherwise the step is halved. So a
    full Newton step costs one assembly and one linear solve, and the program traces the
    assembly once. Every case runs its own iteration (per-case state); only the assembly's
    scatter is done slot-wide (`kernel.assemble_batch`). At most `_POOL` cases are iterated at
    once and a stopped case's slot takes the next case, so a batch costs the sum of its cases'
    passes (about 5 each), not the slowest case's (up to 40 near the envelope's edge) times every
    case; each case's iterates do not depend on the others (vmap = loop)."""
    topo = mech.topology
    n = topo.n
    length = mech.length_scale
    rot = jnp.asarray(np.r_[np.tile(np.r_[np.zeros(3), np.ones(3)], n // 6), np.zeros(topo.m)])
    cases = q0.shape[0]
    y0 = jnp.concatenate([q0, jnp.zeros((cases, topo.m), q0.dtype)], axis=1)

    def done(r, f_scale, step):
        # Converged, or at the round-off floor: within 1000× the tolerances and no longer moving.
        force, constraint, _ = _measures(mech, r, f_scale)
        tight = (force <= rtol) & (constraint <= atol)
        floor = (force <= 1e3 * rtol) & (constraint <= 1e3 * atol) & (step <= 1e-13)
        return tight | floor

    def running(s):
        return (s["it"] <= max_steps) & (s["status"] == Status.MAX_STEPS) & ~s["done"]

    def update(s, loads_, y_try, r_twist, jac, dy):
        """The next state of one case, given the residual, the Jacobian and the Newton step
        J⁻¹·(−r) at its trial point."""
        # Convergence and the merit are measured on the generalised forces of the Gibbs
        # coordinates (F, G(b)ᵀM), as `residual` reports them; the step uses the twist form.
        r = generalised_residual(y_try[:n], r_twist)
        merit = _measures(mech, r, s["f_scale"])[2]
        merit = jnp.where(jnp.isfinite(merit), merit, jnp.inf)
        first = s["it"] == 0
        accept = first | (merit <= (1.0 - 1e-4 * s["alpha"]) * s["merit"]) | (
            s["trial"] >= _LINE_SEARCH - 1)
        # The next Newton step from the trial point (used only if it is accepted).
        f_scale = _force_scale(mech, loads_, jac[:n, n:] @ y_try[n:])
        cap = jnp.max(jnp.abs(dy * rot))
        dy = dy * jnp.minimum(1.0, _MAX_TURN / jnp.maximum(cap, 1e-300))
        step = jnp.max(jnp.abs(s["alpha"] * s["dy"][:n])) / (length + jnp.max(jnp.abs(y_try[:n])))
        # A case whose line search keeps cutting the step to nothing has no equilibrium nearby
        # (e.g. a suspension pulled past its travel): stop it so that it does not hold the whole
        # batch to max_steps.
        stall = jnp.where(first, 0, jnp.where(s["alpha"] < 0.01, s["stall"] + 1, 0))
        status = jnp.where(jnp.all(jnp.isfinite(r)), Status.MAX_STEPS, Status.NONFINITE)
        status = jnp.where(stall >= _STALL_STEPS, Status.STALLED, status)
        accepted = dict(
            y=y_try, r=r, dy=dy, alpha=jnp.ones_like(s["alpha"]),
            merit=_measures(mech, r, f_scale)[2], f_scale=f_scale, it=s["it"] + 1,
            trial=jnp.zeros_like(s["trial"]), status=status, stall=stall,
            backtracks=s["backtracks"],
            done=done(r, f_scale, jnp.where(first, jnp.inf, step)),
        )
        # Backtrack to the minimum of the quadratic through φ(0), φ'(0) = −2φ(0) (a Newton
        # step on ½‖r‖²) and φ(α), kept within [0.1α, 0.5α]; 0.1α if φ(α) is not finite.
        alpha, phi0 = s["alpha"], s["merit"]
        curvature = (merit - phi0 + 2.0 * alpha * phi0) / alpha**2
        shrink = jnp.where(jnp.isfinite(merit) & (curvature > 0),
                           phi0 / jnp.maximum(curvature * alpha, 1e-300), 0.1)
        backtracks = s["backtracks"] + 1
        rejected = dict(s, alpha=alpha * jnp.clip(shrink, 0.1, 0.5), trial=s["trial"] + 1,
                        backtracks=backtracks,
                        status=jnp.where(backtracks >= _MAX_BACKTRACKS, Status.STALLED,
                                         s["status"]))
        new = jax.tree.map(lambda a, b: jnp.where(accept, a, b), accepted, rejected)
        return jax.tree.map(lambda a, b: jnp.where(running(s), a, b), new, s)

    size = n + topo.m
    slots = min(cases, _POOL)

    def fresh(case):
        """The start state of the cases `case` (slots,)."""
        zero = jnp.zeros(case.shape, y0.dtype)
        count = jnp.zeros(case.shape, int)
        return dict(
            y=y0[jnp.minimum(case, cases - 1)], r=jnp.zeros(case.shape + (size,), y0.dtype),
            dy=jnp.zeros(case.shape + (size,), y0.dtype), alpha=zero + 1.0,
            merit=zero + jnp.inf, f_scale=zero + 1.0, it=count, trial=count,
            status=count + Status.MAX_STEPS, stall=count, backtracks=count,
            done=case >= cases,  # an empty slot
        )

    def result(s):
        force, constraint, _ = jax.vmap(lambda r, f: _measures(mech, r, f))(s["r"], s["f_scale"])
        status = jnp.where(s["done"], Status.CONVERGED, s["status"])
        return jnp.stack([status.astype(float), (s["it"] - 1).astype(float), force, constraint,
                          s["backtracks"].astype(float)], 1)

    def body(pool):
        # One Newton pass over the slots; a slot whose case has stopped hands its result over
        # and takes the next case waiting (a pool: each case runs its own iteration, so the
        # batch costs the sum of the cases' passes, not the slowest case's times all cases).
        s, case, queue, y_out, info_out = pool
        loads_s = jax.tree.map(lambda a: a[jnp.minimum(case, cases - 1)], loads)
        y_try = jax.vmap(lambda y, d: retract(y, d, n))(s["y"], s["alpha"][:, None] * s["dy"])
        r, jac = assemble_batch(mech, loads_s, y_try[:, :n], y_try[:, n:])
        # The slots' systems are factorised one by one (the same CPU time as one batched call):
        # jaxlib's batched CPU LU splits a batch over its intra-op thread pool and waits for
        # it from a pool thread, and two such calls at once (the batch split over two devices)
        # deadlocked this 2-core machine; a single system is factorised inline.
        dy = jax.lax.map(lambda a: scaled_solve(a[0], -a[1]), (jac, r))
        s = jax.vmap(update)(s, loads_s, y_try, r, jac, dy)
        stopped = ~jax.vmap(running)(s) & (case < cases)
        dest = jnp.where(stopped, case, cases)  # out of range: dropped
        y_out = y_out.at[dest].set(s["y"], mode="drop")
        info_out = info_out.at[dest].set(result(s), mode="drop")
        new_case = jnp.where(stopped, queue + jnp.cumsum(stopped) - 1, case)
        new_case = jnp.where(stopped & (new_case >= cases), cases, new_case)
        s = jax.tree.map(lambda a, b: jnp.where(stopped.reshape((-1,) + (1,) * (a.ndim - 1)),
                                                a, b), fresh(new_case), s)
        return s, new_case, queue + jnp.sum(stopped), y_out, info_out

    def more(pool):
        s, case = pool[0], pool[1]
        return jnp.any(jax.vmap(running)(s) & (case < cases))

    first = jnp.arange(slots)
    pool = (fresh(first), first, jnp.asarray(slots), y0, jnp.zeros((cases, 5), y0.dtype))
    _, _, _, y, info = jax.lax.while_loop(more, body, pool)
    return y, info


@eqx.filter_custom_jvp
def _equilibrium(mech, loads, q0, *, rtol, atol, max_steps):
    """Solver coordinates and multipliers (cases, n + m) and (status, iterations, residual,
    constraint error) (cases, 4) of a batch of load cases."""
    return _newton(mech, loads, q0, rtol=rtol, atol=atol, max_steps=max_steps)


@_equilibrium.def_jvp
def _equilibrium_jvp(primals, tangents, *, rtol, atol, max_steps):
    # Implicit function theorem, case by case: J·dy = −∂r/∂(mech, loads)·t (`linearize`).
    # Everything here stays differentiable (y through this same rule, J and ∂r through
    # autodiff), so derivatives of derivatives — e.g. the sensitivity of bump steer to a
    # stiffness — are exact too.
    mech, loads, q0 = primals
    t_mech, t_loads, _ = tangents
    y, info = _equilibrium(mech, loads, q0, rtol=rtol, atol=atol, max_steps=max_steps)

    def tangent(loads_, y_, t_loads_):
        return linearize_internal(mech, loads_, y_).tangent(t_mech, t_loads_)

    if t_loads is None:
        dy = jax.vmap(lambda l, y_: tangent(l, y_, None))(loads, y)
    else:
        dy = jax.vmap(tangent)(loads, y, t_loads)
    return (y, info), (dy, jnp.zeros_like(info))


def _solve_batch_cases(mech, loads, q0, rtol, atol, max_steps):
    """Public-coordinate solutions of a batch of cases (leading axis)."""
    y0 = jax.vmap(lambda q: to_internal(mech, q))(q0)
    y, info = _equilibrium(mech, loads, y0, rtol=rtol, atol=atol, max_steps=max_steps)
    n = mech.topology.n
    return StaticSolution(
        q=jax.vmap(lambda y_: to_public(mech, y_))(y[:, :n]),
        multipliers=y[:, n:],
        status=info[:, 0].astype(int),
        iterations=info[:, 1].astype(int),
        residual=info[:, 2],
        constraint_error=info[:, 3],
    )


def _solve_one(mech, loads, q0, rtol, atol, max_steps):
    sol = _solve_batch_cases(mech, jax.tree.map(lambda a: a[None], loads), q0[None], rtol, atol,
                             max_steps)
    return jax.tree.map(lambda a: a[0], sol)


def _solve_cases(mech, loads, q0, rtol, atol, max_steps, chunk):
    n_cases = loads.force.shape[0]
    if chunk is None or n_cases <= chunk:
        return _solve_batch_cases(mech, loads, q0, rtol, atol, max_steps)
    # Chunks of `chunk` cases one after the other (the last one padded by repeating a case).
    n_chunks = -(-n_cases // chunk)
    pad = n_chunks * chunk - n_cases

    def split(a):
        a = jnp.concatenate([a, jnp.repeat(a[-1:], pad, axis=0)]) if pad else a
        return a.reshape(n_chunks, chunk, *a.shape[1:])

    sol = jax.lax.map(lambda args: _solve_batch_cases(mech, *args, rtol, atol, max_steps),
                      jax.tree.map(split, (loads, q0)))
    return jax.tree.map(lambda a: a.reshape(n_chunks * chunk, *a.shape[2:])[:n_cases], sol)


@filter_jit
def _solve_batch(mech, loads, q0, rtol, atol, max_steps, chunk, mesh=None):
    if mesh is None:
        return _solve_cases(mech, loads, q0, rtol, atol, max_steps, chunk)
    # One share of the cases per device, each solved by its own pool, no communication; the
    # case count is padded to a multiple of the devices by repeating the last case. (On the
    # CPU this needs `compilation.CPU_OPTIONS`: see there.)
    n_cases, k = loads.force.shape[0], mesh.size
    pad = -n_cases % k

    def padded(a):
        return jnp.concatenate([a, jnp.repeat(a[-1:], pad, axis=0)]) if pad else a

    cases = jax.sharding.PartitionSpec("cases")
    solve = jax.shard_map(
        lambda l, q: _solve_cases(mech, l, q, rtol, atol, max_steps, chunk),
        mesh=mesh, in_specs=(cases, cases), out_specs=cases, check_vma=False)
    sol = solve(*jax.tree.map(padded, (loads, q0)))
    return jax.tree.map(lambda a: a[:n_cases], sol)


@filter_jit
def _solve_path(mech, loads, q0, rtol, atol, max_steps):
    def step(q, loads_):
        sol = _solve_one(mech, loads_, q, rtol, atol, max_steps)
        return jnp.where(sol.status == Status.CONVERGED, sol.q, q), sol

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


@filter_jit
def _bushing_angles(mech, q):
    return bushing_states(mech, q)[1]


def _check_validity(mech: Mechanism, sol: StaticSolution):
    """Warn when a bushing's projected angles leave their validity (|AX|, |AY| < 15°,
    |AZ| < 90°; spec stiffness §0)."""
    if not mech.bushings.names or _is_traced(sol.q):
        return
    warn_law_validity(mech, _bushing_angles(mech, sol.q), stacklevel=3)


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


def _mesh(devices):
    """A one-axis ("cases") mesh over `devices` (see `solve_statics`), None for one device."""
    if devices is None:
        devices = os.environ.get("DIFFSUSP_DEVICES", "1")
        devices = int(devices) if devices.isdigit() else devices
    local = jax.local_devices()
    if isinstance(devices, str):
        if devices != "all":
            raise ValueError(
                f'devices must be a count, "all" or a list of devices; got {devices!r}.')
        devices = local
    elif isinstance(devices, int):
        if not 1 <= devices <= len(local):
            raise ValueError(f"devices={devices}: {len(local)} local device(s) are available "
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
      of devices. Default: `$DIFFSUSP_DEVICES`, else 1 (the CLI sets "all" and, on the CPU,
      one device per core). Calls inside jit / vmap / grad run on one device.
    - `checks`: compute the `stable` / `law_valid` flags and warn about bushing laws beyond
      their validity (one more compiled program per model); False leaves the flags None, for
      a caller that checks in its own program (`kc.evaluate`).

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
        mesh = None if _is_traced((mech, loads, q0)) else _mesh(devices)
        if mesh is not None and n_cases < mesh.size:
            mesh = None
        sol = _solve_batch(mech, loads, q0, rtol, atol, max_steps, chunk, mesh)
        if mesh is not None:  # later programs run on one device, as for an unsplit batch
            sol = jax.device_put(sol, jax.devices()[0])
    if checks:
        sol = with_flags(mech, loads, sol)
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
    sol = with_flags(mech, loads, sol)
    _check_validity(mech, sol)
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
        raise ValueError("solve_statics_chunks needs loads with a leading case axis.")
    if chunk < 1:
        raise ValueError(f"chunk must be at least 1; got {chunk}.")
    chunk = min(chunk, max(n, 1))
    for start in range(0, n, chunk):
        stop = min(start + chunk, n)
        index = np.minimum(np.arange(start, start + chunk), n - 1)
        sol = solve_statics(mech, jax.tree.map(lambda a, i=index: a[i], loads), **solve_kwargs)
        yield start, stop, jax.tree.map(lambda a, k=stop - start: a[:k], sol)
