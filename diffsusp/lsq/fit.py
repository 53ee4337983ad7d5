"""The user-facing least squares: `solve`, `tls`, `eliminate` and the `Fit` report.

spec: guaranteed_least_squares §3 (mathematics), §7 items 1–11 (features). The numerics are in
`core` (JAX); this module validates inputs, names the parameters, prints the base-parameter
relations ("Krx1 + Krx2", "a - 0.07413 b") and formats the report (NumPy/Python).
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

# --------------------------------------------------------------------------------------------
# Report objects


@dataclasses.dataclass(frozen=True)
class Step:
    """One iteration of the elimination loop (spec §3.9)."""

    iteration: int
    removed: str
    reason: str
    confidence: float  # IC of the removed parameter's combination before removal
    sigma_pct: float  # σ% of that combination before removal
    residual_before: float
    residual_after: float
    relations: tuple[str, ...]  # the printed relations after removal

    @property
    def residual_increase_pct(self) -> float:
        if self.residual_before == 0:
            return 0.0 if self.residual_after == 0 else float("inf")
        return 100.0 * (self.residual_after / self.residual_before - 1.0)

    def __str__(self) -> str:
        rel = "; ".join(self.relations) if self.relations else "no regrouping"
        return (f"{self.iteration}. removed {self.removed} ({self.reason}): residual "
                f"{self.residual_before:.6g} -> {self.residual_after:.6g} "
                f"({self.residual_increase_pct:+.3g} %); {rel}")


@dataclasses.dataclass(frozen=True)
class Fit:
    """A least-squares fit with its identifiability report (spec §3.6–3.9, §8.4).

    **Per parameter (p,)**: `x` (original units), `sigma` (nan where not identifiable, fixed or
    at a bound), `sigma_pct` (100·σ/|x|), `confidence` (the confidence index IC of the
    combination the parameter carries; nan where not kept), `identifiable` (individually
    determined by the data), `kept` (a column of the reduced, base-parameter model), `fixed`
    (held at its prior: eliminated or given in `fixed=`), `at_bound` (bounded solves).

    **Relations**: `relations` (list of str) are the identifiable combinations that involve more
    than one parameter, e.g. "Krx1 + Krx2" or "a - 0.07413 b"; `relation_values` and
    `relation_sigma` are aligned with it. `regrouping` (p, p) holds every combination: row j
    (j kept) gives c_j = Σ_k regrouping[j, k]·x_k, with value `combination_values[j]` and σ
    `combination_sigma[j]` (nan where not kept).

    **Whole fit**: `rank`, `n` (rows), `dof`, `residuals` (y − W x, unweighted; None for a
    streamed fit), `residual_norm` (weighted), `residual_sigma` (σ̂ of the weighted residual),
    `residual_norm_full` (‖ρ_min‖ of the full model), `singular_values` (of the weighted W as
    given, the thesis's "100 % / 5.2 %"), `singular_values_scaled` (columns at unit norm) and
    `condition` (of the scaled W: independent of units), `diagonal` (|R_ii|/‖W_i‖) and the
    `threshold` of the identifiability test, `covariance` (p, p), `R` ((p+1)×(p+1) R-factor of
    the weighted [W, −y]), `method`, `block_weights`, `log` (elimination steps).
    """

    names: tuple[str, ...]
    x: np.ndarray
    sigma: np.ndarray
    sigma_pct: np.ndarray
    confidence: np.ndarray
    identifiable: np.ndarray
    kept: np.ndarray
    fixed: np.ndarray
    at_bound: np.ndarray
    rank: int
    relations: list[str]
    relation_values: np.ndarray
    relation_sigma: np.ndarray
    regrouping: np.ndarray
    combination_values: np.ndarray
    combination_sigma: np.ndarray
    covariance: np.ndarray
    n: int
    dof: float
    residuals: np.ndarray | None
    residual_norm: float
    residual_sigma: float
    residual_norm_full: float
    singular_values: np.ndarray
    singular_values_scaled: np.ndarray
    condition: float
    diagonal: np.ndarray
    threshold: float
    scale: np.ndarray
    R: np.ndarray
    method: str
    iterations: int = 0
    converged: bool = True
    block_weights: np.ndarray | None = None
    block_sigma: np.ndarray | None = None
    log: tuple[Step, ...] = ()

    # ---- derived views

    @property
    def p(self) -> int:
        return len(self.names)

    @property
    def essential(self) -> np.ndarray:
        """Kept combinations not below IC = 0.1 (spec §3.8: those can be neglected; an
        undefined IC, e.g. on exact data, does not make a parameter negligible)."""
        return self.kept & ~(self.confidence < core.IC_ESSENTIAL)

    def interval(self, k: float = 1.0) -> np.ndarray:
        """(p, 2) interval x ± k·σ (k = 1: the 68 % Gaussian interval of spec §3.8)."""
        return np.stack([self.x - k * self.sigma, self.x + k * self.sigma], axis=1)

    @property
    def contains_zero(self) -> np.ndarray:
        """The 68 % interval contains 0 (σ% > 100): the parameter may be set to 0."""
        lo, hi = self.interval().T
        return (lo <= 0) & (hi >= 0)

    def value(self, name: str) -> float:
        return float(self.x[self._index(name)])

    def _index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise InputError(f"unknown parameter {name!r}; the fit has {list(self.names)}") \
                from None

    def combination(self, name: str) -> str:
        """The printed combination estimated by the kept parameter `name` (itself if alone)."""
        j = self._index(name)
        if not self.kept[j]:
            raise InputError(f"parameter {name!r} is not kept in the reduced model; its value is "
                             "its prior. Ask for one of the kept parameters.")
        return format_combination(self.regrouping[j], self.names, j)

    def reinject(self, priors: Mapping[str, float]) -> np.ndarray:
        """Parameters consistent with the fit once some are given a-priori values (spec §3.6,
        §7 item 10): every identifiable combination c = Γ x keeps its value, the given
        parameters take their priors and the others change as little as possible (in unit-norm
        column coordinates). E.g. with c = a − 0.0742 b: prior b = 1 gives a = c + 0.0742;
        prior a = 5 gives b = (c − 5)/(−0.0742). Raises InputError if the priors contradict a
        combination (all its parameters given)."""
        given = np.zeros(self.p, bool)
        x = self.x.copy()
        for name, value in priors.items():
            i = self._index(name)
            given[i] = True
            x[i] = float(value)
        G = self.regrouping[self.kept]
        c = self.combination_values[self.kept]
        free = ~given
        r = c - G @ x
        A = G[:, free] * self.scale[free][None, :]
        delta, *_ = np.linalg.lstsq(A, r, rcond=None)
        x[free] += delta * self.scale[free]
        miss = np.abs(G @ x - c)
        tol = 1e-8 * (np.abs(G) @ np.abs(x) + np.abs(c) + 1e-300)
        bad = np.nonzero(miss > tol)[0]
        if len(bad):
            j = np.nonzero(self.kept)[0][bad[0]]
            raise InputError(
                f"the priors {dict(priors)} contradict the identified combination "
                f"{format_combination(self.regrouping[j], self.names, j)} = "
                f"{self.combination_values[j]:.6g}; leave at least one of its parameters free.")
        return x

    # ---- output

    def table(self) -> str:
        """A readable report: parameters, σ, σ%, IC, status; relations; singular values."""
        lines = [
            f"least squares ({self.method}): {self.n} rows, {self.p} parameters, rank "
            f"{self.rank}, dof {self.dof:g}",
            f"residual norm {self.residual_norm:.6g}, residual sigma {self.residual_sigma:.4g}, "
            f"condition (unit-norm columns) {self.condition:.3g}",
        ]
        width = max([9] + [len(n) for n in self.names])
        lines.append(f"{'parameter':<{width}}  {'value':>13}  {'sigma':>10}  {'sigma%':>8}  "
                     f"{'IC':>6}  status")
        for i, name in enumerate(self.names):
            lines.append(f"{name:<{width}}  {self.x[i]:>13.6g}  {_num(self.sigma[i], '.3g'):>10}"
                         f"  {_pct(self.sigma_pct[i]):>8}  {_num(self.confidence[i], '.3f'):>6}"
                         f"  {self._status(i)}")
        if self.relations:
            lines.append("identifiable combinations:")
            for text, v, s in zip(self.relations, self.relation_values, self.relation_sigma,
                                  strict=True):
                spread = (f" +- {s:.3g} ({_pct(100 * s / abs(v)) if v else '-'})"
                          if np.isfinite(s) else "")
                lines.append(f"  {text} = {v:.6g}{spread}")
        sv = self.singular_values / self.singular_values[0] if self.singular_values[0] > 0 \
            else self.singular_values
        lines.append("singular values of W (% of largest): "
                     + ", ".join(f"{100 * s:.3g}" for s in sv))
        for step in self.log:
            lines.append(f"  {step}")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.table()

    def _status(self, i: int) -> str:
        name_rel = None
        for text, j in zip(self.relations, np.nonzero(self._nontrivial())[0], strict=True):
            if self.regrouping[j, i] != 0:
                name_rel = text
        if self.fixed[i]:
            return "fixed at prior" + (f" (in {name_rel})" if name_rel else "")
        if self.at_bound[i]:
            return "at bound"
        if not self.identifiable[i]:
            if name_rel:
                return f"not identifiable: in {name_rel}"
            if not np.any(self.regrouping[:, i]) and self.diagonal[i] == 0:
                return "not identifiable: no effect on the data"
            return "not identifiable"
        if self.kept[i] and not self.essential[i]:
            return "not essential (IC < 0.1)"
        return ""

    def _nontrivial(self) -> np.ndarray:
        off = self.regrouping.copy()
        np.fill_diagonal(off, 0.0)
        return self.kept & np.any(off != 0, axis=1)

    def to_dict(self) -> dict:
        """JSON-ready dictionary (nan → None)."""
        def lst(a):
            return [None if (isinstance(v, float) and not np.isfinite(v)) else v
                    for v in np.asarray(a).tolist()]
        return {
            "method": self.method, "names": list(self.names), "x": lst(self.x),
            "sigma": lst(self.sigma), "sigma_pct": lst(self.sigma_pct),
            "confidence": lst(self.confidence), "identifiable": lst(self.identifiable),
            "kept": lst(self.kept), "fixed": lst(self.fixed), "at_bound": lst(self.at_bound),
            "rank": self.rank, "relations": [
                {"combination": t, "value": float(v), "sigma": _none(s)}
                for t, v, s in zip(self.relations, self.relation_values, self.relation_sigma,
                                   strict=True)],
            "n": self.n, "dof": self.dof, "residual_norm": self.residual_norm,
            "residual_sigma": _none(self.residual_sigma),
            "singular_values": lst(self.singular_values),
            "singular_values_scaled": lst(self.singular_values_scaled),
            "condition": _none(self.condition), "threshold": self.threshold,
            "block_weights": None if self.block_weights is None else lst(self.block_weights),
            "log": [dataclasses.asdict(s) for s in self.log],
        }


def _none(v):
    v = float(v)
    return v if np.isfinite(v) else None


def _num(v, fmt):
    return "-" if not np.isfinite(v) else format(v, fmt)


def _pct(v):
    return "-" if not np.isfinite(v) else f"{v:.3g}%"


def format_combination(coefficients: np.ndarray, names: Sequence[str], j: int) -> str:
    """"a - 0.07413 b", "Krx1 + Krx2": the kept parameter j first (coefficient 1), then the
    regrouped ones in column order with 4 significant digits (±1 printed as a bare sign)."""
    parts = [names[j]]
    for k, c in enumerate(coefficients):
        if k == j or c == 0:
            continue
        mag = format(abs(c), ".4g")
        parts.append(("- " if c < 0 else "+ ") + (names[k] if mag == "1" else f"{mag} {names[k]}"))
    return " ".join(parts)


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


def _names(names, p):
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
        idx = np.nonzero(base._nontrivial())[0]
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
                    i = fit._index(candidate)
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
    names = _names(names, W.shape[1])
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
