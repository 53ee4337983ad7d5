"""Streaming accumulation of the R-factor, block by block (spec: guaranteed_least_squares §3.5).

R̃_j = R([R̃_{j−1}; P_j·M_j]) with M_j = [W_j, −Y_j]: by the uniqueness of the R-factor with a
positive diagonal (Prop. 1) and Prop. 2 of the thesis, the final R̃ equals the R-factor of the
whole weighted stacked [P_i W_i, −P_i Y_i], so the fit is the same as the one-shot fit on the
stacked data, with memory O(p²) (the data of one block at a time).
"""

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..errors import InputError
from . import core
from . import fit as fit_mod
from . import weights as weights_mod


def _bucket(rows: int) -> int:
    """Rows padded to a power of two (≥ 8): zero rows do not change R, and ragged blocks then
    share a few compiled shapes instead of one per block size."""
    return max(8, 1 << (rows - 1).bit_length())


class Accumulator:
    """The R-factor of [W, −y] accumulated over blocks of rows (functional: `add` returns a
    new accumulator and leaves this one unchanged).

    ```python
    acc = lsq.Accumulator(p)
    for W_blk, y_blk in blocks:
        acc = acc.add(W_blk, y_blk, weight="auto")
    fit = acc.solve(names=names, method="basic")   # = lsq.solve on the stacked data
    ```

    **Attributes:** `R` ((p+1)×(p+1) JAX array), `rows` (rows added with a non-zero weight:
    the n of the statistics), `block_weights` and
    `block_sigma` (the weight and, for automatic weights, the σ̂ of every block added, in
    order), `p`.
    """

    __slots__ = ("R", "rows", "p", "threshold", "_history")

    def __init__(self, p: int, *, threshold: float | None = None):
        """`p`: number of parameters. `threshold`: rank threshold for the automatic block
        weights (default as in `lsq.solve`)."""
        if int(p) < 1:
            raise InputError(f"Accumulator(p): p must be a positive number of parameters; got "
                             f"{p!r}.")
        fit_mod.check_x64()
        self.p = int(p)
        self.threshold = threshold
        self.R = jnp.asarray(np.zeros((self.p + 1, self.p + 1)), jnp.result_type(float))
        self.rows = 0
        self._history = None  # (previous history, weights, sigmas): O(1) per add

    def _new(self, R, rows, w, s):
        new = object.__new__(Accumulator)
        new.p, new.threshold, new.R, new.rows = self.p, self.threshold, R, self.rows + rows
        new._history = (self._history, w, s)
        return new

    def _collect(self, which):
        parts, node = [], self._history
        while node is not None:
            parts.append(np.atleast_1d(np.asarray(node[which], float)))
            node = node[0]
        return np.concatenate(parts[::-1]) if parts else np.zeros(0)

    @property
    def block_weights(self) -> np.ndarray:
        return self._collect(1)

    @property
    def block_sigma(self) -> np.ndarray:
        return self._collect(2)

    def _check(self, W, y, batched):
        W = np.asarray(W, float)
        y = np.asarray(y, float)
        nd = 3 if batched else 2
        if W.ndim != nd or W.shape[-1] != self.p or y.shape != W.shape[:-1]:
            want = "(blocks, rows, p) and (blocks, rows)" if batched else "(rows, p) and (rows,)"
            raise InputError(f"expected W and y of shapes {want} with p = {self.p}; got "
                             f"{W.shape} and {y.shape}.")
        if W.shape[-2] == 0:
            raise InputError("a block needs at least one row.")
        if not (np.all(np.isfinite(W)) and np.all(np.isfinite(y))):
            raise InputError("W or y has a non-finite value; remove or fix those rows.")
        return W, y

    def add(self, W: Float[Array, "r p"], y: Float[Array, " r"],
            weight: float | str | None = None) -> "Accumulator":
        """Add one block of rows with weight P (None: 1; "auto": 1/σ̂ of the block's own fit,
        spec §3.4 (1-20) — the block needs more rows than its rank)."""
        W, y = self._check(W, y, batched=False)
        r = W.shape[0]
        M = np.zeros((_bucket(r), self.p + 1))
        M[:r, :-1] = W
        M[:r, -1] = -y
        if isinstance(weight, str):
            if weight != "auto":
                raise InputError(f"weight must be a number, None or 'auto'; got {weight!r}.")
            rho, dof, R_i = weights_mod.block_sigmas(jnp.asarray(M[None]), np.array([float(r)]),
                                                     self.threshold or 0.0)
            if dof[0] <= 0:
                raise InputError(
                    f"weight='auto' needs a block with more rows than its rank: this block has "
                    f"{r} rows and rank {r - int(dof[0])}, so its own residual cannot estimate "
                    "its noise. Use add_blocks(..., weights='auto') for many small blocks (they "
                    "share a pooled σ̂), or pass an explicit weight.")
            sigma = rho[0] / np.sqrt(dof[0])
            if sigma == 0:
                raise InputError("weight='auto': this block fits exactly (zero residual), so "
                                 "its weight would be infinite; pass an explicit weight.")
            P = 1.0 / sigma
            R = core.stack_r(self.R, P * np.asarray(R_i[0]))
            return self._new(R, r, P, sigma)
        P = 1.0 if weight is None else float(weight)
        if not (np.isfinite(P) and P >= 0):
            raise InputError(f"weight must be finite and non-negative; got {weight!r}.")
        if P != 1.0:
            M *= P
        return self._new(core.stack_r(self.R, M), r if P > 0 else 0, P, np.nan)

    def add_blocks(self, W: Float[Array, "k r p"], y: Float[Array, "k r"],
                   weights: Float[Array, " k"] | str | None = None) -> "Accumulator":
        """Add k blocks of r rows each at once (batched QR). `weights`: None, (k,) numbers, or
        "auto" (each block's own σ̂, pooled for blocks with no residual degree of freedom:
        see `weights`)."""
        W, y = self._check(W, y, batched=True)
        k, r, _ = W.shape
        M = np.concatenate([W, -y[..., None]], axis=2)
        if isinstance(weights, str):
            if weights != "auto":
                raise InputError(f"weights must be numbers, None or 'auto'; got {weights!r}.")
            rho, dof, R_i = weights_mod.block_sigmas(jnp.asarray(M), np.full(k, float(r)),
                                                     self.threshold or 0.0)
            sigma = weights_mod.pooled_sigmas(rho, dof)
            P = 1.0 / sigma
            stacked = (P[:, None, None] * np.asarray(R_i)).reshape(-1, self.p + 1)
            return self._new(core.stack_r(self.R, stacked), k * r, P, sigma)
        if weights is None:
            P = np.ones(k)
        else:
            P = np.broadcast_to(np.asarray(weights, float), (k,)).copy()
            if not np.all(np.isfinite(P) & (P >= 0)):
                raise InputError("weights must be finite and non-negative.")
        stacked = (P[:, None, None] * M).reshape(-1, self.p + 1)
        return self._new(core.stack_r(self.R, stacked), int(np.count_nonzero(P)) * r, P,
                         np.full(k, np.nan))

    def merge(self, other: "Accumulator") -> "Accumulator":
        """The accumulator of both sets of rows (for accumulating in parallel, then combining)."""
        if other.p != self.p:
            raise InputError(f"cannot merge accumulators of {self.p} and {other.p} parameters.")
        return self._new(core.stack_r(self.R, other.R), other.rows, other.block_weights,
                         other.block_sigma)

    def __repr__(self) -> str:
        return f"Accumulator(p={self.p}, rows={self.rows}, blocks={len(self.block_weights)})"

    def problem(self, names=None) -> fit_mod.Problem:
        if self.rows == 0:
            raise InputError("the accumulator is empty: add rows before solving.")
        weights, sigma = self.block_weights, self.block_sigma
        w = weights if np.any(weights != 1.0) else None
        s = sigma if np.any(np.isfinite(sigma)) else None
        return fit_mod.Problem(R=self.R, n=self.rows, names=fit_mod.parameter_names(names, self.p),
                               block_weights=w, block_sigma=s)

    def solve(self, *, names=None, **options) -> fit_mod.Fit:
        """The same `Fit` as `lsq.solve` on the stacked data (without `residuals`, the rows are
        not kept); `options` as in `lsq.solve` (method, threshold, prior, ...)."""
        return self.problem(names).fit(**options)

    def tls(self, *, names=None, **options) -> fit_mod.Fit:
        """Total least squares (see `lsq.tls`)."""
        return self.problem(names).tls(**options)

    def eliminate(self, *, names=None, **options):
        """The elimination loop on the accumulated R (see `lsq.eliminate`)."""
        return self.problem(names).eliminate(**options)
