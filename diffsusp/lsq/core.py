"""The numerics of the guaranteed least squares, in JAX (spec: guaranteed_least_squares §3).

Everything works on the (p+1)×(p+1) R-factor of the augmented matrix M = [W, −Y] (spec §3.3):

    R_m = [[R_w, −B], [0, ‖ρ_min‖]],   ‖W X − Y‖² = ‖R_w X − B‖² + ‖ρ_min‖²,

so the data are read once (or streamed, block by block, spec §3.5) and every later step (choice of
the identifiable parameters, reduced model, regrouping relations, statistics, elimination) costs
O(p³), independent of the number of rows. Shapes are fixed and the identifiable set is a boolean
mask, so `solve_r` and `solve_arrays` are `jit`-compiled once per shape and `vmap`-able over
many data sets (Monte-Carlo).

Columns are scaled to unit norm inside (a column scaling keeps R triangular: R·diag(d) is the
R-factor of W·diag(d)), so N/mm and N·mm/rad columns are compared on an equal footing; every
result is returned in the original units.
"""

import functools
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

METHODS = ("basic", "min_norm", "tsvd", "tikhonov", "nonneg", "bounded")
DOF_MODES = ("n-rank", "n-p")
TIE = 1e-9  # pivot candidates within this relative norm of the best count as ties: first wins
COEFFICIENT_TOL = 1e-8  # regrouping coefficients (unit-norm columns) below this are zero
IC_ESSENTIAL = 0.1  # spec §3.8: parameters with IC < 0.1 are negligible


class Solution(eqx.Module):
    """The arrays of one linear least-squares solution (original units; see `Fit` for a report).

    **Fields:** `x` (p,), `covariance` (p, p), `sigma` (p,) (nan where not identifiable, fixed or
    at a bound), `sigma_pct` (p,) = 100·σ/|x|, `confidence` (p,) the confidence index IC of the
    estimated combinations (nan where not estimated), `identifiable` (p,) individually determined
    by the data, `kept` (p,) the columns kept in the reduced (base-parameter) model, `rank`,
    `regrouping` (p, p): row j (j kept) holds the coefficients of the combination of the
    original parameters that the kept parameter j estimates (zero rows elsewhere),
    `relation_values` (p,), `relation_sigma` (p,), `residual_norm` (weighted ‖W x − y‖ of the
    returned x), `residual_norm_full` (‖ρ_min‖ of the full model), `residual_sigma`, `dof`,
    `singular_values` (of the weighted W as given), `singular_values_scaled` (columns at unit
    norm), `condition` (of the scaled W), `diagonal` (|R_ii|/‖W_i‖, the thesis's test in column
    order), `threshold`, `scale` (column factors d, W_s = W·diag(d)), `at_bound` (p,),
    `iterations` (active-set steps of the bounded solve), `converged`, `R` the R-factor.
    """

    x: Float[Array, " p"]
    covariance: Float[Array, "p p"]
    sigma: Float[Array, " p"]
    sigma_pct: Float[Array, " p"]
    confidence: Float[Array, " p"]
    identifiable: Bool[Array, " p"]
    kept: Bool[Array, " p"]
    rank: Int[Array, ""]
    regrouping: Float[Array, "p p"]
    relation_values: Float[Array, " p"]
    relation_sigma: Float[Array, " p"]
    residual_norm: Float[Array, ""]
    residual_norm_full: Float[Array, ""]
    residual_sigma: Float[Array, ""]
    dof: Float[Array, ""]
    singular_values: Float[Array, " p"]
    singular_values_scaled: Float[Array, " p"]
    condition: Float[Array, ""]
    diagonal: Float[Array, " p"]
    threshold: Float[Array, ""]
    scale: Float[Array, " p"]
    at_bound: Bool[Array, " p"]
    iterations: Int[Array, ""]
    converged: Bool[Array, ""]
    R: Float[Array, "q q"]


# --------------------------------------------------------------------------------------------
# R-factors


def qr_r(M: Float[Array, "n q"]) -> Float[Array, "q q"]:
    """R-factor of M with a non-negative diagonal, padded with zero rows to q×q.

    spec: guaranteed_least_squares §3.3 (1-16, 1-17); the positive diagonal makes R unique for
    a full-rank M (Prop. 1, §3.5), which is what makes the block recursion exact.
    """
    q = M.shape[1]
    r = jnp.linalg.qr(M, mode="r")
    if r.shape[0] < q:
        r = jnp.concatenate([r, jnp.zeros((q - r.shape[0], q), r.dtype)], axis=0)
    sign = jnp.where(jnp.diagonal(r) < 0, -1.0, 1.0).astype(r.dtype)
    return r * sign[:, None]


def augmented(W: Float[Array, "n p"], y: Float[Array, " n"]) -> Float[Array, "n q"]:
    """M = [W, −Y] (spec §3.3)."""
    return jnp.concatenate([W, -y[:, None]], axis=1)


@jax.jit
def stack_r(R: Float[Array, "q q"], M: Float[Array, "n q"]) -> Float[Array, "q q"]:
    """R-factor of [R; M]: one step of the block recursion (spec §3.5, D-32..D-47)."""
    return qr_r(jnp.concatenate([R, M], axis=0))


def default_threshold(n, p: int, dtype) -> Array:
    """max(n, p+1)·eps: the rank tolerance of LAPACK/MATLAB on unit-norm columns (spec §3.6
    gives no value for ε; this is the convention it suggests)."""
    return jnp.maximum(jnp.asarray(n, dtype), p + 1) * jnp.finfo(dtype).eps


@functools.partial(jax.jit, static_argnames=("p",))
def block_statistics(R_blocks, counts, threshold, *, p: int):
    """Per-block residual norm ‖ρ(i)_min‖ and residual degrees of freedom n_i − rank_i, from each
    block's own R_i (spec §3.4, (1-20)). Rank: diagonal test on unit-norm columns."""

    def one(R, n):
        norms = jnp.linalg.norm(R[:p, :p], axis=0)
        tol = jnp.where(threshold > 0, threshold, default_threshold(n, p, R.dtype))
        rank = jnp.sum(jnp.abs(jnp.diagonal(R)[:p]) > tol * jnp.maximum(norms, 1e-300))
        return jnp.abs(R[p, p]), n - rank

    return jax.vmap(one)(R_blocks, counts)


@jax.jit
def block_r(M_blocks: Float[Array, "k n q"]) -> Float[Array, "k q q"]:
    """The R-factor of every block alone (equal-sized blocks, batched)."""
    return jax.vmap(qr_r)(M_blocks)


# --------------------------------------------------------------------------------------------
# Identifiable set, masked least squares


def select(A, candidates, tol, pivot: bool):
    """Columns of A (unit-norm columns) kept in the reduced model.

    `pivot=False` is the thesis's test (spec §3.6, (1-25)): in column order, a column is kept
    when its part orthogonal to the columns already kept exceeds `tol` (= |R_ii| of the unit-norm
    QR), so the column order sets the priority. `pivot=True` is the column-pivoted (rank-
    revealing, MATLAB-backslash) choice: at each step the remaining column with the largest
    orthogonal part is kept, near-ties (within `TIE`) going to the earlier column, until every
    remaining part is below `tol`. Both stop at the same numerical rank on exactly dependent
    columns; pivoting picks a better-conditioned set when columns are only nearly dependent.
    """
    p = A.shape[1]
    ref = jnp.max(jnp.where(candidates, jnp.linalg.norm(A, axis=0), 0.0))

    def body(i, state):
        A, kept, stop = state
        norms = jnp.linalg.norm(A, axis=0)
        avail = candidates & ~kept
        if pivot:
            masked = jnp.where(avail, norms, -1.0)
            top = jnp.max(masked)
            j = jnp.argmax(masked >= top * (1.0 - TIE))
        else:
            j = i
        ok = avail[j] & (norms[j] > tol * ref) & ~stop
        q = A[:, j] / jnp.where(ok, norms[j], 1.0)
        A = jnp.where(ok, A - jnp.outer(q, q @ A), A)
        kept = kept.at[j].set(kept[j] | ok)
        if pivot:
            stop = stop | ~ok
        return A, kept, stop

    _, kept, _ = jax.lax.fori_loop(0, p, body, (A, jnp.zeros(p, bool), jnp.asarray(False)))
    return kept


def _factor(A, mask):
    """QR of [A·diag(mask); diag(~mask)]: the reduced regressor of the kept columns, with the
    removed parameters pinned by identity rows (fixed shapes; spec §3.6 (D-50..D-56))."""
    m = mask.astype(A.dtype)
    A_aug = jnp.concatenate([A * m[None, :], jnp.diag(1.0 - m)], axis=0)
    return jnp.linalg.qr(A_aug)


def _back(QR, top, bottom):
    Q, Rr = QR
    rhs = jnp.concatenate([top, bottom], axis=0)
    return jax.scipy.linalg.solve_triangular(Rr, Q.T @ rhs, lower=False)


def masked_solve(A, b, mask, x_fixed):
    """argmin ‖A x − b‖ over x[mask], x[~mask] = x_fixed; and the unit-variance covariance
    (R′ᵀR′)⁻¹ of x[mask] (zero elsewhere) (spec §3.7 (1-32), §3.8 (1-37))."""
    p = A.shape[1]
    QR = _factor(A, mask)
    xf = jnp.where(mask, 0.0, x_fixed)
    x = _back(QR, b - A @ xf, xf)
    Rinv = jax.scipy.linalg.solve_triangular(QR[1], jnp.eye(p, dtype=A.dtype), lower=False)
    m = mask.astype(A.dtype)
    cov = (Rinv @ Rinv.T) * m[:, None] * m[None, :]
    return x, cov, QR


def _regrouping(A, QR):
    """Γ = (W′ᵀW′)⁻¹W′ᵀW (p×p, zero rows for removed parameters): the general LS projection of
    the full model onto the kept columns (spec §3.6; exact for any removed set, unlike (D-57))."""
    return _back(QR, A, jnp.zeros_like(A))


def _pinv_apply(A, rtol):
    U, s, Vt = jnp.linalg.svd(A, full_matrices=False)
    keep = s > rtol * jnp.max(s)
    sinv = jnp.where(keep, 1.0 / jnp.where(keep, s, 1.0), 0.0)
    return U, sinv, Vt


def bvls(A, b, lower, upper, x0, max_iter: int):
    """Bounded-variable least squares min ‖A x − b‖, lower ≤ x ≤ upper, by an active-set method
    (Lawson–Hanson NNLS generalised to two-sided bounds, Stark & Parker 1995).

    Start from x0 clipped to the box; each step solves the LS problem on the free set (minimum
    norm, so rank-deficient free sets are allowed); if the solution leaves the box, move to the
    first bound crossed and pin the variables that reach it; otherwise free the bound variable
    with the largest KKT violation, or stop when there is none. Infinite bounds mean "free".
    Returns x, the free mask, the number of steps and a converged flag.
    """
    p = A.shape[1]
    idx = jnp.arange(p)
    movable = lower < upper
    x = jnp.clip(x0, lower, upper)
    free = movable & (x > lower) & (x < upper)
    tol = 1e-11 * jnp.maximum(jnp.linalg.norm(b) * jnp.max(jnp.linalg.norm(A, axis=0)), 1e-300)

    def sub(free, x):
        m = free.astype(A.dtype)
        r = b - A @ jnp.where(free, 0.0, x)
        z = jnp.linalg.lstsq(A * m[None, :], r)[0]
        return jnp.where(free, z, x)

    def body(state):
        x, free, it, done, last = state
        z = sub(free, x)
        below, above = free & (z < lower), free & (z > upper)
        crossing = below | above
        dz = z - x
        safe = jnp.where(crossing, dz, 1.0)
        alphas = jnp.where(below, (lower - x) / safe, jnp.where(above, (upper - x) / safe, jnp.inf))
        i_min = jnp.argmin(alphas)
        alpha = jnp.clip(alphas[i_min], 0.0, 1.0)
        x_step = jnp.where(free, x + alpha * dz, x)
        low_hit = free & ((x_step <= lower) | ((idx == i_min) & below))
        up_hit = free & ((x_step >= upper) | ((idx == i_min) & above))
        x_step = jnp.where(low_hit, lower, jnp.where(up_hit, upper, x_step))
        free_step = free & ~low_hit & ~up_hit
        # The variable freed last wanting straight back (alpha = 0) is round-off: stop there.
        stuck = (i_min == last) & (alpha <= 1e-14)

        g = A.T @ (b - A @ z)
        at_low = movable & ~free & (z <= lower)
        at_up = movable & ~free & (z >= upper)
        violation = jnp.where(at_low, g, jnp.where(at_up, -g, -jnp.inf))
        t = jnp.argmax(violation)
        optimal = violation[t] <= tol
        free_feasible = free.at[t].set(free[t] | ~optimal)

        any_cross = jnp.any(crossing)
        x_new = jnp.where(any_cross, jnp.where(stuck, x, x_step), z)
        free_new = jnp.where(any_cross, jnp.where(stuck, free & (idx != last), free_step),
                             free_feasible)
        done_new = jnp.where(any_cross, stuck, optimal)
        last_new = jnp.where(any_cross, -1, jnp.where(optimal, -1, t))
        return x_new, free_new, it + 1, done_new, last_new

    def cond(state):
        return ~state[3] & (state[2] < max_iter)

    init = (x, free, jnp.asarray(0), jnp.asarray(False), jnp.asarray(-1))
    x, free, it, done, _ = jax.lax.while_loop(cond, body, init)
    return x, free, it, done


# --------------------------------------------------------------------------------------------
# The solve


def solve_r(
    R: Float[Array, "q q"],
    n: Float[Array, ""],
    prior: Float[Array, " p"],
    prior_sigma: Float[Array, " p"],
    lower: Float[Array, " p"],
    upper: Float[Array, " p"],
    fixed: Bool[Array, " p"],
    threshold: Float[Array, ""],
    *,
    method: str = "basic",
    pivot: bool = True,
    dof: str = "n-rank",
) -> Solution:
    """Solve the least-squares problem whose augmented R-factor is `R` (n rows were reduced).

    spec: guaranteed_least_squares §3.3–3.8. Steps: unit-norm column scaling; identifiable
    (kept) columns by `select` with `threshold` (≤ 0: `default_threshold`); reduced model from R
    alone (§3.6); the regrouping relations Γ; the solution by `method`:

    - `basic`: the reduced LS solution, parameters not kept (and `fixed` ones) at `prior`
      (0 by default: the thesis's zeros; a prior gives the a-priori re-injection of §3.6);
    - `min_norm`: the LS solution closest to `prior` in ‖(x − prior)/prior_sigma‖
      (prior_sigma = 1 in the original units if not given);
    - `tsvd`: truncated SVD of the scaled regressor, singular values below
      threshold·σ_max dropped, toward `prior`;
    - `tikhonov`: MAP estimate, min ‖R_w x − B‖²/σ̂² + Σ((x − prior)/prior_sigma)², σ̂ the
      residual σ of the basic fit (σ̂ = 0, exact data: the LS solution nearest the prior);
      the covariance is the posterior one;
    - `nonneg` / `bounded`: lower ≤ x ≤ upper by `bvls` (the caller sets lower = 0 for
      nonneg); σ from the LS restricted to the free parameters.

    Statistics (§3.8): σ̂² = ‖ρ‖²/dof (dof = n − rank, or n − p as in the thesis), covariance
    σ̂²·(R′ᵀR′)⁻¹, σ, σ% = 100·σ/|x|, confidence index IC of the kept combinations.
    Compiled in stages (identifiability, reduced model, method, statistics), so the solution
    modes and the elimination loop share the compiled reduced model.
    """
    method = "bounded" if method == "nonneg" else method
    identifiable = identifiability(R, n, threshold, pivot=pivot)
    base = _base_jit(R, n, prior, fixed, threshold, pivot=pivot, dof=dof)
    if method == "basic":
        step = _basic_step(base)
    else:
        step = _method_jit(base, prior, prior_sigma, lower, upper, fixed, method=method)
    return _finish_jit(base, step, identifiable, fixed)


def scaled_problem(R, n, threshold):
    """The (p, p) block of the QR factor `R` with its columns scaled to unit norm (a zero column
    left as is), the scales and the rank threshold (`threshold`, or `default_threshold(n, p)`
    when not positive)."""
    p = R.shape[0] - 1
    Rw = R[:p, :p]
    norms = jnp.linalg.norm(Rw, axis=0)
    d = jnp.where(norms > 0, 1.0 / jnp.where(norms > 0, norms, 1.0), 1.0)
    tol = jnp.where(threshold > 0, threshold, default_threshold(n, p, R.dtype))
    return Rw * d[None, :], d, tol


def _identifiability(R, n, threshold, pivot):
    A, _, tol = scaled_problem(R, n, threshold)
    p = A.shape[1]
    kept = select(A, jnp.ones(p, bool), tol, pivot)
    gamma = _regrouping(A, _factor(A, kept))
    linked = jnp.any((jnp.abs(gamma) > COEFFICIENT_TOL) & ~kept[None, :], axis=1)
    return kept & ~linked


@functools.partial(jax.jit, static_argnames=("pivot",))
def identifiability(R: Float[Array, "q q"], n: Float[Array, ""], threshold: Float[Array, ""], *,
                    pivot: bool = True) -> Bool[Array, " p"]:
    """Which parameters the data determine individually (spec §3.6): all columns are
    candidates; a parameter is identifiable when its column is kept and no column dropped for
    rank regroups onto it (equivalently: it has no component in the null space of W)."""
    return _identifiability(R, n, threshold, pivot)


class _Base(NamedTuple):
    """The reduced model: everything that does not depend on the solution method."""

    R: Array
    n: Array
    A: Array  # R_w with unit-norm columns
    B: Array
    d: Array  # column scale
    tol: Array
    rho_full: Array
    prior_s: Array
    kept: Array
    x_basic: Array
    cov_basic: Array  # unit-variance covariance of the basic solution (scaled coordinates)
    gamma: Array  # regrouping Γ (scaled coordinates)
    s2_basic: Array
    dof: Array


class _Step(NamedTuple):
    """A method's solution in scaled coordinates."""

    x_s: Array
    cov_unit: Array
    s2_cov: Array  # σ̂² for the covariance (nan: that of x_s's own residual)
    estimated: Array
    at_bound: Array
    iterations: Array
    converged: Array


def _sigma2(base, x_s):
    r2 = jnp.sum((base.A @ x_s - base.B) ** 2) + base.rho_full**2
    ok = base.dof > 0
    return r2, jnp.where(ok, r2 / jnp.where(ok, base.dof, 1.0), jnp.nan)


def _base(R, n, prior, fixed, threshold, pivot, dof) -> _Base:
    p = R.shape[0] - 1
    A, d, tol = scaled_problem(R, n, threshold)
    B = -R[:p, p]
    prior_s = prior / d
    # Fixed (eliminated) parameters are not candidates; they stay at their prior.
    kept = select(A, ~fixed, tol, pivot)
    x_basic, cov_basic, QR = masked_solve(A, B, kept, prior_s)
    gamma = _regrouping(A, QR)
    rank = jnp.sum(kept)
    dof_value = (n - rank if dof == "n-rank" else n - p).astype(R.dtype)
    base = _Base(R, n, A, B, d, tol, jnp.abs(R[p, p]), prior_s, kept, x_basic, cov_basic, gamma,
                 jnp.asarray(jnp.nan, R.dtype), dof_value)
    return base._replace(s2_basic=_sigma2(base, x_basic)[1])


def _basic_step(base) -> _Step:
    p = base.kept.shape[0]
    return _Step(base.x_basic, base.cov_basic, jnp.asarray(jnp.nan, base.A.dtype), base.kept,
                 jnp.zeros(p, bool), jnp.asarray(0), jnp.asarray(True))


def _method(base, prior, prior_sigma, lower, upper, fixed, method) -> _Step:
    A, B, d, prior_s = base.A, base.B, base.d, base.prior_s
    p = A.shape[1]
    dtype = A.dtype
    nan = jnp.asarray(jnp.nan, dtype)
    no_bound = jnp.zeros(p, bool)
    if method == "basic":
        return _basic_step(base)
    if method == "min_norm":
        w = jnp.where(fixed, 0.0, prior_sigma / d)
        U, sinv, Vt = _pinv_apply(base.gamma * w[None, :], 1e-12)
        T = (w[:, None] * Vt.T) @ (sinv[:, None] * U.T)  # x_s = prior_s + T (c − Γ prior_s)
        x_s = prior_s + T @ (base.gamma @ base.x_basic - base.gamma @ prior_s)
        M = T @ base.gamma
        return _Step(x_s, M @ base.cov_basic @ M.T, nan, base.kept, no_bound, jnp.asarray(0),
                     jnp.asarray(True))
    if method == "tsvd":
        m = (~fixed).astype(dtype)
        U, sinv, Vt = _pinv_apply(A * m[None, :], base.tol)
        x_s = prior_s + Vt.T @ (sinv * (U.T @ (B - A @ prior_s)))
        return _Step(x_s, (Vt.T * sinv**2) @ Vt, nan, base.kept, no_bound, jnp.asarray(0),
                     jnp.asarray(True))
    if method == "tikhonov":
        w = jnp.where(fixed, 0.0, prior_sigma / d)
        s2 = base.s2_basic
        sig = jnp.sqrt(jnp.where(jnp.isfinite(s2), s2, 0.0))
        A_aug = jnp.concatenate([A * w[None, :], sig * jnp.eye(p, dtype=dtype)], axis=0)
        rhs = jnp.concatenate([B - A @ prior_s, jnp.zeros(p, dtype)])
        U, sinv, Vt = _pinv_apply(A_aug, 1e-13)
        x_s = prior_s + w * (Vt.T @ (sinv * (U.T @ rhs)))
        # Posterior covariance σ̂²·diag(w)(AᵀA)⁻¹diag(w) = (R_wᵀR_w/σ̂² + diag(1/σ0²))⁻¹.
        cov_unit = (w[:, None] * (Vt.T * sinv**2) @ Vt) * w[None, :]
        return _Step(x_s, cov_unit, s2, ~fixed, no_bound, jnp.asarray(0), jnp.asarray(True))
    if method == "bounded":
        lo = jnp.where(fixed, prior_s, lower / d)
        hi = jnp.where(fixed, prior_s, upper / d)
        x_s, free, iterations, converged = bvls(A, B, lo, hi, base.x_basic, max_iter=4 * p + 20)
        estimated = free & base.kept
        _, cov_unit, _ = masked_solve(A, B, estimated, x_s)
        return _Step(x_s, cov_unit, nan, estimated, ~free & ~fixed, iterations, converged)
    raise ValueError(f"unknown method {method!r}")  # pragma: no cover - the caller validates


def _finish(base, step, identifiable, fixed) -> Solution:
    R, A, d, kept = base.R, base.A, base.d, base.kept
    p = A.shape[1]
    r2, s2 = _sigma2(base, step.x_s)
    s2_cov = jnp.where(jnp.isnan(step.s2_cov), s2, step.s2_cov)
    cov_s = step.cov_unit * s2_cov
    x = step.x_s * d
    cov = cov_s * d[:, None] * d[None, :]
    shown = identifiable & step.estimated & ~fixed & ~step.at_bound
    # Regrouping in original units: c_j = Σ_k Γ_jk x_k with Γ_orig = diag(d) Γ_s diag(1/d).
    gamma = base.gamma
    gamma_o = jnp.where(jnp.abs(gamma) > COEFFICIENT_TOL, gamma * d[:, None] / d[None, :], 0.0)
    sigma, sigma_pct, rel_values, rel_sigma, confidence = _statistics(
        x, cov, shown, kept, gamma_o, step.estimated & ~step.at_bound)
    Rw = R[:p, :p]
    s_raw = jnp.linalg.svd(Rw, compute_uv=False)
    s_scaled = jnp.linalg.svd(A, compute_uv=False)
    ok = s_scaled[-1] > 0
    condition = jnp.where(ok, s_scaled[0] / jnp.where(ok, s_scaled[-1], 1.0), jnp.inf)
    return Solution(
        x=x, covariance=cov, sigma=sigma, sigma_pct=sigma_pct, confidence=confidence,
        identifiable=identifiable, kept=kept, rank=jnp.sum(kept), regrouping=gamma_o,
        relation_values=rel_values, relation_sigma=rel_sigma,
        residual_norm=jnp.sqrt(r2), residual_norm_full=base.rho_full,
        residual_sigma=jnp.sqrt(s2), dof=base.dof,
        singular_values=s_raw, singular_values_scaled=s_scaled, condition=condition,
        diagonal=jnp.abs(jnp.diagonal(Rw)) * d, threshold=base.tol, scale=d,
        at_bound=step.at_bound, iterations=step.iterations, converged=step.converged, R=R,
    )


_base_jit = jax.jit(_base, static_argnames=("pivot", "dof"))
_method_jit = jax.jit(_method, static_argnames=("method",))
_finish_jit = jax.jit(_finish)


def _solve_r(R, n, prior, prior_sigma, lower, upper, fixed, threshold, identifiable, *,
             method, pivot, dof) -> Solution:
    """All stages in one traced function (for `solve_arrays`, under jit/vmap)."""
    base = _base(R, n, prior, fixed, threshold, pivot, dof)
    step = _method(base, prior, prior_sigma, lower, upper, fixed, method)
    return _finish(base, step, identifiable, fixed)


@functools.partial(jax.jit, static_argnames=("method", "pivot", "dof"))
def solve_arrays(
    W: Float[Array, "n p"],
    y: Float[Array, " n"],
    weights: Float[Array, " n"] | None = None,
    prior: Float[Array, " p"] | None = None,
    prior_sigma: Float[Array, " p"] | None = None,
    lower: Float[Array, " p"] | None = None,
    upper: Float[Array, " p"] | None = None,
    fixed: Bool[Array, " p"] | None = None,
    threshold: float | Float[Array, ""] = 0.0,
    *,
    method: str = "basic",
    pivot: bool = True,
    dof: str = "n-rank",
) -> Solution:
    """Pure-array least squares: `solve_r` on the R-factor of [diag(weights)·W, −diag(weights)·y].

    No validation and no names: this is the function to `jax.vmap` over many data sets of the
    same shape (Monte-Carlo), e.g. `jax.vmap(lambda y: lsq.solve_arrays(W, y))(Y)`. Arguments
    as in `lsq.solve` (`weights` per row; `threshold` ≤ 0 for the default; `lower`/`upper`
    default to 0/+inf for `nonneg` and ∓inf otherwise).
    """
    n, p = W.shape
    dtype = jnp.result_type(W, y, float)
    W, y = jnp.asarray(W, dtype), jnp.asarray(y, dtype)
    M = augmented(W, y)
    if weights is not None:
        M = M * jnp.asarray(weights, dtype)[:, None]
    R = qr_r(M)
    prior, prior_sigma, lower, upper, fixed = fill_defaults(
        p, dtype, method, prior, prior_sigma, lower, upper, fixed)
    n = jnp.asarray(n, dtype)
    threshold = jnp.asarray(threshold, dtype)
    identifiable = _identifiability(R, n, threshold, pivot)
    return _solve_r(R, n, prior, prior_sigma, lower, upper, fixed, threshold, identifiable,
                    method="bounded" if method == "nonneg" else method, pivot=pivot, dof=dof)


def _statistics(x, cov, shown, kept, regrouping, free=None):
    """σ (nan where not `shown`), σ% = 100·σ/|x|, the values and σ of the kept combinations
    c = Γ x, and their confidence index IC_j = min_k(σ%_k)/σ%_j (spec §3.8 (1-39..1-41)).

    A combination's σ is nan when none of its parameters is `free` (estimated, not at a bound),
    and its IC is nan when its σ is 0 or undefined (exact data, no residual degree of freedom):
    IC compares noise levels and means nothing without noise."""
    sigma = jnp.where(shown, jnp.sqrt(jnp.abs(jnp.diagonal(cov))), jnp.nan)
    sigma_pct = 100.0 * sigma / jnp.abs(x)
    rel_values = jnp.where(kept, regrouping @ x, jnp.nan)
    if free is not None:
        kept_est = kept & jnp.any((regrouping != 0) & free[None, :], axis=1)
    else:
        kept_est = kept
    rel_var = jnp.einsum("jk,kl,jl->j", regrouping, cov, regrouping)
    rel_sigma = jnp.where(kept_est, jnp.sqrt(jnp.abs(rel_var)), jnp.nan)
    rel_pct = rel_sigma / jnp.abs(rel_values)
    valid = kept_est & (rel_pct > 0)  # also False for nan
    best = jnp.min(jnp.where(valid, rel_pct, jnp.inf))
    confidence = jnp.where(valid, best / jnp.where(valid, rel_pct, 1.0), jnp.nan)
    return sigma, sigma_pct, rel_values, rel_sigma, confidence


statistics = jax.jit(_statistics)


def fill_defaults(p, dtype, method, prior, prior_sigma, lower, upper, fixed):
    """Arrays for the optional arguments of `solve_r`."""
    full = lambda v, default: (jnp.full(p, default, dtype) if v is None  # noqa: E731
                               else jnp.broadcast_to(jnp.asarray(v, dtype), (p,)))
    prior = full(prior, 0.0)
    prior_sigma = full(prior_sigma, 1.0)
    lower = full(lower, 0.0 if method == "nonneg" else -jnp.inf)
    upper = full(upper, jnp.inf)
    fixed = jnp.zeros(p, bool) if fixed is None else jnp.broadcast_to(jnp.asarray(fixed, bool),
                                                                       (p,))
    return prior, prior_sigma, lower, upper, fixed


# --------------------------------------------------------------------------------------------
# Total least squares


def _tls(R: Float[Array, "q q"], n: Float[Array, ""], scale: bool = False):
    """Total least squares from the augmented R-factor of a full-rank [W, −Y] (spec §3.7).

    v = right singular vector of the smallest singular value of R_m (= of [W, −Y]); since
    [W, −Y]·[X; 1] ≈ 0, X = v[:p]/v[p] (the thesis's (1-34) −V12/V22 is Van Huffel's sign for
    [W, Y]; spec §3.7 sign caveat). `scale=True` first scales every column of [W, −Y] to unit
    norm (TLS assumes equal error variance in all columns, so the scaling changes the estimate).
    First-order covariance (errors-in-variables, Van Huffel & Vandewalle 1991):
    σ̂²(1 + ‖x‖²)(R_wᵀR_w − s_min²I)⁻¹, σ̂² = s_min²/(n − p), in the (scaled) coordinates.
    Returns x (p,), covariance (p, p), s_min and the singular values.
    """
    p = R.shape[0] - 1
    norms = jnp.linalg.norm(R, axis=0)
    d = jnp.where(norms > 0, 1.0 / jnp.where(norms > 0, norms, 1.0), 1.0) if scale \
        else jnp.ones(p + 1, R.dtype)
    Rs = R * d[None, :]
    _, s, Vt = jnp.linalg.svd(Rs)
    v = Vt[-1]
    xs = v[:p] / v[p]
    smin = s[-1]
    sigma2 = smin**2 / (n - p)
    Aw = Rs[:p, :p]
    H = Aw.T @ Aw - smin**2 * jnp.eye(p, dtype=R.dtype)
    cov_s = sigma2 * (1.0 + xs @ xs) * jnp.linalg.inv(H)
    # X = diag(d_w / d_y)·X_s: the scaled problem has unknown X_s with X = X_s·d_w/d_y.
    f = d[:p] / d[p]
    return xs * f, cov_s * f[:, None] * f[None, :], smin, s


tls_r = jax.jit(_tls, static_argnames=("scale",))


@functools.partial(jax.jit, static_argnames=("scale",))
def tls_reduced(R, n, columns, kept, identifiable, regrouping, *, scale: bool = False):
    """TLS on the kept columns (`columns`: their indices, then p) of the augmented R-factor:
    x (p,) (0 elsewhere), covariance, s_min and the statistics of `statistics`."""
    p = R.shape[0] - 1
    xk, covk, smin, _ = _tls(qr_r(R[:, columns]), n, scale)
    cols = columns[:-1]
    x = jnp.zeros(p, R.dtype).at[cols].set(xk)
    cov = jnp.zeros((p, p), R.dtype).at[cols[:, None], cols[None, :]].set(covk)
    return x, cov, smin, _statistics(x, cov, identifiable & kept, kept, regrouping)


@jax.jit
def tls_arrays(W: Float[Array, "n p"], y: Float[Array, " n"]):
    """Pure-array, unscaled TLS of a full-rank problem (for `vmap`): (x, covariance)."""
    n = W.shape[0]
    R = qr_r(augmented(W, y))
    x, cov, _, _ = tls_r(R, jnp.asarray(n, R.dtype))
    return x, cov
