"""The user-facing least squares: `solve`, `tls`, `eliminate` and the `Fit` report.

spec: guaranteed_least_squares §3 (mathematics), §7 items 1–11 (features). The numerics are in
`core` (JAX); this module validates inputs, names the parameters, prints the base-parameter
relations ("Krx1 + Krx2", "a - 0.07413 b") and formats the report (NumPy/Python).
The report objects (`Fit`, `Step`, `format_combination`) are in `diffsusp.lsq.report`.
"""

import dataclasses
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence

import jax
import numpy as np
from jaxtyping import ArrayLike

from ..errors import InputError
from . import core
from . import weights as weights_mod
from .report import Fit, Step, format_combination

# --------------------------------------------------------------------------------------------
# Input checks


def _data(W, y):
    W = np.asarray(W, dtype=float)
    y = np.asarray(y, dtype=float)
    if W.ndim != 2:
        raise InputError(f"W must be a 2-D regressor matrix (rows × parameters); got shape "
                         f"{W.shape}.")
    if y.ndim != 1 or y.shape[0] != W.shape[0]:
        raise InputError(f"y must be a vector with one value per row of W ({W.shape[0]}); got "
                         f"shape {y.shape}.")
    if W.shape[0] == 0 or W.shape[1] == 0:
        raise InputError(f"W has shape {W.shape}: need at least one row and one parameter.")
    for name, a in (("W", W), ("y", y)):
        if not np.all(np.isfinite(a)):
            idx = np.argwhere(~np.isfinite(a))[0]
            raise InputError(f"{name} has a non-finite value at index {tuple(idx.tolist())}; "
                             "remove or fix that row.")
    return W, y


def parameter_names(names, p: int) -> tuple[str, ...]:
    """`names` checked against `p` columns (distinct, as many as columns), or x0, x1, … when
    None."""
    if names is None:
        return tuple(f"x{i}" for i in range(p))
    names = tuple(str(n) for n in names)
    if len(names) != p:
        raise InputError(f"names has {len(names)} entries but W has {p} columns.")
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise InputError(f"names must be unique; repeated: {sorted(dup)}.")
    return names


def _vector(value, names, field, default, *, positive=False, allow_inf=False):
    p = len(names)
    if value is None:
        return np.full(p, default, float)
    if isinstance(value, Mapping):
        out = np.full(p, default, float)
        for k, v in value.items():
            if k not in names:
                raise InputError(f"{field}: unknown parameter {k!r}; known: {list(names)}.")
            out[names.index(k)] = float(v)
    else:
        a = np.asarray(value, dtype=float)
        if a.ndim == 0:
            out = np.full(p, float(a))
        elif a.shape == (p,):
            out = a.copy()
        else:
            raise InputError(f"{field} must be a scalar, a ({p},) array or a dict by name; got "
                             f"shape {a.shape}.")
    bad = np.isnan(out) | (~allow_inf & ~np.isfinite(out))
    if positive:
        bad |= ~(out > 0)
    if np.any(bad):
        i = int(np.nonzero(bad)[0][0])
        need = "positive and finite" if positive else "finite"
        raise InputError(f"{field}[{names[i]!r}] = {out[i]} must be {need}.")
    return out


def _mask(value, names, field):
    p = len(names)
    if value is None:
        return np.zeros(p, bool)
    if isinstance(value, str):
        value = [value]
    value = list(value)
    if all(isinstance(v, (bool, np.bool_)) for v in value) and len(value) == p:
        return np.asarray(value, bool)
    out = np.zeros(p, bool)
    for v in value:
        if v not in names:
            raise InputError(f"{field}: unknown parameter {v!r}; known: {list(names)}.")
        out[names.index(v)] = True
    return out


def _options(method, threshold, dof):
    if method not in core.METHODS:
        raise InputError(f"method must be one of {list(core.METHODS)}; got {method!r}.")
    if threshold is not None and not (np.isfinite(threshold) and 0 < threshold < 1):
        raise InputError(f"threshold must be in (0, 1) (relative, on unit-norm columns); got "
                         f"{threshold!r}.")
    if dof not in core.DOF_MODES:
        raise InputError(f"dof must be one of {list(core.DOF_MODES)}; got {dof!r}.")


def _row_weights(W, y, weights, blocks, threshold):
    m = W.shape[0]
    if blocks is None:
        if isinstance(weights, str):
            raise InputError("weights='auto' needs blocks= (a block label per row, e.g. "
                             "np.repeat(np.arange(cases), rows_per_case)).")
        if weights is None:
            return None, None, None
        w = np.asarray(weights, float)
        if w.ndim == 0:
            w = np.full(m, float(w))
        if w.shape != (m,):
            raise InputError(f"weights must be a scalar or one weight per row ({m}); got shape "
                             f"{w.shape}. For per-block weights pass blocks= as well.")
        if not np.all(np.isfinite(w) & (w >= 0)):
            raise InputError("weights must be finite and non-negative.")
        return w, None, None
    labels = np.asarray(blocks)
    if labels.shape != (m,):
        raise InputError(f"blocks must give a block label for each of the {m} rows; got shape "
                         f"{labels.shape}.")
    uniq, inverse = np.unique(labels, return_inverse=True)
    if weights is None:
        return None, None, None
    if isinstance(weights, str):
        if weights != "auto":
            raise InputError(f"weights must be 'auto', None, or numbers; got {weights!r}.")
        row_w, _, block_w, block_sigma = weights_mod.automatic(
            W, y, labels, 0.0 if threshold is None else threshold)
        return row_w, block_w, block_sigma
    w = np.asarray(weights, float)
    if w.ndim == 0:
        w = np.full(len(uniq), float(w))
    if w.shape != (len(uniq),):
        raise InputError(f"with blocks=, weights must have one entry per block ({len(uniq)}, "
                         f"in the order of np.unique(blocks)); got shape {w.shape}.")
    if not np.all(np.isfinite(w) & (w >= 0)):
        raise InputError("weights must be finite and non-negative.")
    return w[inverse], w, None


# --------------------------------------------------------------------------------------------
# The reduced problem (shared by one-shot and streamed fits)


CHUNK = 4096  # rows reduced per QR for tall problems


def _bucket(m: int) -> int:
    """The power of two ≥ m (at least 8)."""
    return max(8, 1 << (m - 1).bit_length())


@jax.jit
def _weighted_r(W, y, w):
    return core.qr_r(core.augmented(W, y) * w[:, None])


@jax.jit
def _stack_weighted(R, W, y, w):
    return core.stack_r(R, core.augmented(W, y) * w[:, None])


def weighted_r(W: np.ndarray, y: np.ndarray, w: np.ndarray) -> jax.Array:
    """R-factor of diag(w)·[W, −y]. Zero rows do not change R, so rows are padded to a power of
    two (up to CHUNK) and taller data are reduced CHUNK rows at a time (spec §3.5): a handful of
    compiled shapes serve every row count, at the cost of one QR over all rows."""
    m = W.shape[0]

    def padded(lo, hi, size):
        pad = size - (hi - lo)
        return (np.concatenate([a[lo:hi], np.zeros((pad,) + a.shape[1:])]) for a in (W, y, w))

    if m <= CHUNK:
        return _weighted_r(*padded(0, m, _bucket(m)))
    R = _weighted_r(*padded(0, CHUNK, CHUNK))
    for lo in range(CHUNK, m, CHUNK):
        R = _stack_weighted(R, *padded(lo, min(lo + CHUNK, m), CHUNK))
    return R


@dataclasses.dataclass(frozen=True)
class Problem:
    """An R-factor with its row count, parameter names and (if kept) the data."""

    R: jax.Array
    n: int
    names: tuple[str, ...]
    W: np.ndarray | None = None
    y: np.ndarray | None = None
    block_weights: np.ndarray | None = None
    block_sigma: np.ndarray | None = None

    def fit(self, *, method="basic", threshold=None, prior=None, prior_sigma=None, lower=None,
            upper=None, fixed=None, pivot=True, dof="n-rank") -> Fit:
        _options(method, threshold, dof)
        names = self.names
        prior_v = _vector(prior, names, "prior", 0.0)
        if method == "tikhonov" and prior_sigma is None:
            raise InputError("method='tikhonov' needs prior_sigma (the a-priori σ of each "
                             "parameter, in its units; a scalar, array or dict by name).")
        sigma_v = _vector(prior_sigma, names, "prior_sigma", 1.0, positive=True)
        if (lower is not None or upper is not None) and method not in ("nonneg", "bounded"):
            raise InputError(f"lower/upper bounds need method='bounded' (or 'nonneg'); got "
                             f"method={method!r}.")
        lo = _vector(lower, names, "lower", 0.0 if method == "nonneg" else -np.inf,
                     allow_inf=True)
        hi = _vector(upper, names, "upper", np.inf, allow_inf=True)
        if np.any(lo > hi):
            i = int(np.nonzero(lo > hi)[0][0])
            raise InputError(f"lower[{names[i]!r}] = {lo[i]} > upper = {hi[i]}.")
        fixed_m = _mask(fixed, names, "fixed")
        # NumPy arrays straight into the compiled functions (no eager conversions).
        sol = core.solve_r(self.R, np.float64(self.n), prior_v, sigma_v, lo, hi, fixed_m,
                           np.float64(0.0 if threshold is None else threshold),
                           method=method, pivot=pivot, dof=dof)
        return self._to_fit(sol, method, fixed_m)

    def _to_fit(self, sol: core.Solution, method: str, fixed: np.ndarray) -> Fit:
        s = jax.device_get(sol)
        x = s.x + 0.0  # no -0 in reports
        residuals = None if self.W is None else self.y - self.W @ x
        kept = s.kept.astype(bool)
        off = s.regrouping.copy()
        np.fill_diagonal(off, 0.0)
        nontrivial = kept & np.any(off != 0, axis=1)
        rel_idx = np.nonzero(nontrivial)[0]
        return Fit(
            names=self.names, x=x, sigma=s.sigma, sigma_pct=s.sigma_pct,
            confidence=s.confidence, identifiable=s.identifiable.astype(bool), kept=kept,
            fixed=fixed, at_bound=s.at_bound.astype(bool), rank=int(s.rank),
            relations=[format_combination(s.regrouping[j], self.names, j) for j in rel_idx],
            relation_values=s.relation_values[rel_idx], relation_sigma=s.relation_sigma[rel_idx],
            regrouping=s.regrouping, combination_values=s.relation_values,
            combination_sigma=s.relation_sigma, covariance=s.covariance, n=int(self.n),
            dof=float(s.dof),
            residuals=residuals, residual_norm=float(s.residual_norm),
            residual_sigma=float(s.residual_sigma),
            residual_norm_full=float(s.residual_norm_full),
            singular_values=s.singular_values, singular_values_scaled=s.singular_values_scaled,
            condition=float(s.condition), diagonal=s.diagonal, threshold=float(s.threshold),
            scale=s.scale, R=s.R, method=method, iterations=int(s.iterations),
            converged=bool(s.converged), block_weights=self.block_weights,
            block_sigma=self.block_sigma,
        )

    def tls(self, *, threshold=None, scale=False, pivot=True) -> Fit:
        base = self.fit(method="basic", threshold=threshold, pivot=pivot)
        keep = np.nonzero(base.kept)[0]
        p, c = self.R.shape[0] - 1, len(keep)
        if c == 0:
            raise InputError("TLS: no parameter is identifiable (W is zero).")
        if self.n <= c:
            raise InputError(f"TLS needs more rows than identifiable parameters ({self.n} ≤ {c}).")
        x, cov, _, stats = jax.device_get(core.tls_reduced(
            self.R, np.float64(self.n), np.append(keep, p), base.kept, base.identifiable,
            base.regrouping, scale=scale))
        sigma, sigma_pct, rv, rs, ic = stats
        idx = np.nonzero(base.nontrivial())[0]
        # ‖W x − y‖ = ‖R_m [x; 1]‖ (spec §3.3).
        resid = float(np.linalg.norm(np.asarray(self.R) @ np.append(x, 1.0)))
        return dataclasses.replace(
            base, x=x, covariance=cov, sigma=sigma, sigma_pct=sigma_pct, confidence=ic,
            relation_values=rv[idx], relation_sigma=rs[idx], combination_values=rv,
            combination_sigma=rs, method="tls",
            residuals=None if self.W is None else self.y - self.W @ x,
            residual_norm=resid, residual_sigma=resid / np.sqrt(self.n - c), dof=float(self.n - c))

    def eliminate(self, *, ic_threshold=core.IC_ESSENTIAL, sigma_pct_threshold=None,
                  check=None, keep=(), fixed=None, max_steps=None, **options):
        """See `eliminate`."""
        names = self.names
        keep_m = _mask(keep, names, "keep")
        fixed_m = _mask(fixed, names, "fixed")
        fit = self.fit(fixed=fixed_m, **options)
        log = []
        for it in range(1, (max_steps if max_steps is not None else len(names)) + 1):
            candidate = reason = None
            if check is not None:
                candidate = check(fit)
                if candidate is not None:
                    i = fit.index(candidate)
                    if fixed_m[i]:
                        raise InputError(f"check returned {candidate!r}, which is already "
                                         "removed; return None when the behaviour is fine.")
                    reason = "behaviour check"
            if candidate is None:
                rel_pct = 100 * np.abs(fit.combination_sigma / fit.combination_values)
                ic = np.where(np.isnan(fit.confidence), np.inf, fit.confidence)
                bad = fit.kept & ~keep_m & (ic < ic_threshold)
                if sigma_pct_threshold is not None:
                    bad |= fit.kept & ~keep_m & (np.nan_to_num(rel_pct) > sigma_pct_threshold)
                if np.any(bad):
                    i = int(np.argmin(np.where(bad, ic, np.inf)))
                    if not np.isfinite(ic[i]):  # IC undefined (no dof): largest σ% instead
                        i = int(np.argmax(np.where(bad, np.nan_to_num(rel_pct), -np.inf)))
                    candidate = names[i]
                    reason = (f"IC {ic[i]:.3g} < {ic_threshold:g}" if ic[i] < ic_threshold
                              else f"sigma% {rel_pct[i]:.3g} > {sigma_pct_threshold:g}")
            if candidate is None:
                break
            i = names.index(candidate)
            fixed_m = fixed_m.copy()
            fixed_m[i] = True
            new = self.fit(fixed=fixed_m, **options)
            log.append(Step(
                iteration=it, removed=candidate, reason=reason,
                confidence=float(fit.confidence[i]),
                sigma_pct=float(100 * abs(fit.combination_sigma[i] / fit.combination_values[i])),
                residual_before=fit.residual_norm, residual_after=new.residual_norm,
                relations=tuple(f"{t} = {v:.6g}" for t, v in zip(
                    new.relations, new.relation_values, strict=True))))
            fit = new
        fit = dataclasses.replace(fit, log=tuple(log))
        return fit, list(log)


def check_x64():
    if not jax.config.jax_enable_x64:
        warnings.warn(
            "jax_enable_x64 is off: lsq's rank decisions and statistics assume float64. Call "
            "jax.config.update('jax_enable_x64', True) first.", stacklevel=3)


def problem(W, y, *, names=None, weights=None, blocks=None, threshold=None) -> Problem:
    """Validate the data, apply the row/block weights and reduce to the R-factor (one QR)."""
    check_x64()
    W, y = _data(W, y)
    names = parameter_names(names, W.shape[1])
    if threshold is not None:
        _options("basic", threshold, "n-rank")
    row_w, block_w, block_sigma = _row_weights(W, y, weights, blocks, threshold)
    R = weighted_r(W, y, np.ones(W.shape[0]) if row_w is None else row_w)
    # Rows of zero weight are not observations: they do not count in the dof.
    n = W.shape[0] if row_w is None else int(np.count_nonzero(row_w))
    return Problem(R=R, n=n, names=names, W=W, y=y, block_weights=block_w,
                   block_sigma=block_sigma)


# --------------------------------------------------------------------------------------------
# Public functions


def solve(
    W: ArrayLike,
    y: ArrayLike,
    *,
    names: Sequence[str] | None = None,
    weights: ArrayLike | str | None = None,
    blocks: ArrayLike | None = None,
    method: str = "basic",
    threshold: float | None = None,
    prior: ArrayLike | Mapping[str, float] | None = None,
    prior_sigma: ArrayLike | Mapping[str, float] | None = None,
    lower: ArrayLike | Mapping[str, float] | None = None,
    upper: ArrayLike | Mapping[str, float] | None = None,
    fixed: Iterable[str] | None = None,
    pivot: bool = True,
    dof: str = "n-rank",
) -> Fit:
    """Linear least squares W x ≈ y with its identifiability report (spec: guaranteed_least_
    squares §3, §7 items 1–10).

    One QR of the weighted [W, −y] (spec §3.3); columns scaled to unit norm inside; the
    identifiable columns chosen on that R (relative `threshold`, default max(n, p+1)·eps, spec
    §3.6); the reduced model, the regrouping (base-parameter) relations, the solution and its
    statistics from R alone.

    **Arguments:**
    - `W` (n, p), `y` (n,): the linear-in-parameter model y = W x + ρ.
    - `names`: parameter names (default x0, x1, ...), used in relations and reports.
    - `weights`: None; one weight per row; with `blocks`, one per block (order of
      np.unique(blocks)) or "auto" (1/σ̂ of each block's own fit, spec §3.4 (1-20)).
    - `blocks`: a block label per row (e.g. the load case).
    - `method`: "basic" (parameters not kept at their prior, 0 by default: the thesis's
      zeros), "min_norm", "tsvd", "tikhonov" (needs `prior_sigma`), "nonneg", "bounded"
      (see `core.solve_r`).
    - `threshold`: relative identifiability threshold on unit-norm columns (also the relative
      singular-value cut of "tsvd").
    - `prior`, `prior_sigma`: a-priori values and σ (scalar, (p,) array or dict by name).
    - `lower`, `upper`: bounds for "bounded"/"nonneg".
    - `fixed`: names of parameters held at their prior (removed from the model).
    - `pivot`: column-pivoted choice of the kept columns (default; MATLAB backslash's basic
      solution) or False: the thesis's column order as priority.
    - `dof`: "n-rank" (default) or "n-p" (the thesis's (1-36)) for σ̂² = ‖ρ‖²/dof.

    **Returns:** a `Fit`.
    """
    return problem(W, y, names=names, weights=weights, blocks=blocks, threshold=threshold).fit(
        method=method, threshold=threshold, prior=prior, prior_sigma=prior_sigma, lower=lower,
        upper=upper, fixed=fixed, pivot=pivot, dof=dof)


def tls(
    W: ArrayLike,
    y: ArrayLike,
    *,
    names: Sequence[str] | None = None,
    weights: ArrayLike | str | None = None,
    blocks: ArrayLike | None = None,
    threshold: float | None = None,
    scale: bool = False,
    pivot: bool = True,
) -> Fit:
    """Total least squares (spec §3.7, (1-33, 1-34) with the sign for [W, −Y]): for a
    regressor that contains the output (errors in W as well as in y). The identifiable columns
    are chosen as in `solve`; TLS is solved on the reduced [W′, −y] from its R-factor.
    `scale=True` scales every column of [W, −y] to unit norm first (TLS assumes equal error
    variance in all columns, so this changes the estimate). σ is the first-order
    errors-in-variables approximation."""
    return problem(W, y, names=names, weights=weights, blocks=blocks, threshold=threshold).tls(
        threshold=threshold, scale=scale, pivot=pivot)


def eliminate(
    W: ArrayLike,
    y: ArrayLike,
    *,
    names: Sequence[str] | None = None,
    weights: ArrayLike | str | None = None,
    blocks: ArrayLike | None = None,
    ic_threshold: float = core.IC_ESSENTIAL,
    sigma_pct_threshold: float | None = None,
    check: Callable[[Fit], str | None] | None = None,
    keep: Iterable[str] = (),
    fixed: Iterable[str] | None = None,
    max_steps: int | None = None,
    **options,
) -> tuple[Fit, list[Step]]:
    """The elimination loop (spec §3.9): fit, then repeatedly remove the least significant
    parameter and refit from R alone (no data re-read), until every kept combination is
    essential.

    Each step removes one parameter: the one returned by `check(fit)` (a behavioural test,
    e.g. a concavity check; return None when the behaviour is fine), else the kept parameter
    with the smallest confidence index IC < `ic_threshold` (0.1, spec §3.8), or with a σ% above
    `sigma_pct_threshold`. Removed parameters are held at their prior (`prior=` in `options`,
    default 0: the a-priori re-injection of spec §3.6, §7 item 10); the regrouping relations
    show how the kept ones absorb them. `keep` names parameters never removed. `options` are
    those of `solve` (method, prior, prior_sigma, threshold, pivot, dof, bounds).

    **Returns:** (the final `Fit` with `fit.log`, the list of `Step`s).
    """
    return problem(W, y, names=names, weights=weights, blocks=blocks,
                   threshold=options.get("threshold")).eliminate(
        ic_threshold=ic_threshold, sigma_pct_threshold=sigma_pct_threshold, check=check,
        keep=keep, fixed=fixed, max_steps=max_steps, **options)
