"""Block weights (spec: guaranteed_least_squares §3.4, (1-20)).

Each block i (a load case, a test, a day) gets the weight P_i = 1/σ̂_i with
σ̂_i = ‖ρ(i)_min‖/√(n_i − rank_i) the residual σ of that block's *own* least-squares fit (the
(p+1, p+1) entry of its R_i), so blocks with a large output or model error count less. The thesis
writes √(n_i − p); n_i − rank_i is the same for a full-rank block and stays meaningful for a
rank-deficient one. Guards the thesis does not need (spec §7 item 3): a block with no residual
degree of freedom (n_i ≤ rank_i, e.g. a 7-row load case with 20 unknowns) cannot estimate its own
σ and gets the pooled σ̂ = √(Σρ_i²/Σ(n_i − rank_i)) of the blocks that can; σ̂_i is floored at
1e-6 of the pooled value (a block that fits exactly is trusted a million times more, not
infinitely); when every block fits exactly all weights are 1.
"""

import jax.numpy as jnp
import numpy as np

from ..errors import InputError
from . import core

SIGMA_FLOOR = 1e-6


def pooled_sigmas(rho, dof, *, what="blocks"):
    """σ̂_i per block from (‖ρ_i‖, n_i − rank_i), with the guards described in the module."""
    rho, dof = np.asarray(rho, float), np.asarray(dof, float)
    ok = dof > 0
    if not np.any(ok):
        raise InputError(
            f"weights='auto' needs at least one block with more rows than its rank (its own "
            f"residual estimates its noise); none of the {len(rho)} {what} has one (largest "
            f"n_i − rank_i = {int(dof.max())}). Group rows into larger blocks, or pass "
            "explicit weights (1/σ of each block).")
    pooled = float(np.sqrt(np.sum(rho[ok] ** 2) / np.sum(dof[ok])))
    if pooled == 0.0:
        return np.ones_like(rho)
    sigma = np.where(ok, rho / np.sqrt(np.where(ok, dof, 1.0)), pooled)
    return np.maximum(sigma, SIGMA_FLOOR * pooled)


def block_sigmas(M_blocks, counts, threshold):
    """σ̂_i of equal-sized blocks M_blocks (k, r, p+1) (zero-padded rows are harmless: they do
    not change R_i); returns (σ̂ (k,), R_i (k, p+1, p+1))."""
    q = M_blocks.shape[-1]
    R_blocks = core.block_r(M_blocks)
    rho, dof = core.block_statistics(R_blocks, jnp.asarray(counts), jnp.asarray(threshold,
                                                                               R_blocks.dtype),
                                     p=q - 1)
    return np.asarray(rho), np.asarray(dof), R_blocks


def automatic(W, y, labels, threshold):
    """Per-row weights from the blocks given by `labels` (m,): (row weights (m,), block labels,
    block weights, block σ̂). Blocks of equal size are reduced together (one batched QR)."""
    M = np.concatenate([W, -y[:, None]], axis=1)
    uniq, inverse, counts = np.unique(labels, return_inverse=True, return_counts=True)
    rho = np.empty(len(uniq))
    dof = np.empty(len(uniq))
    order = np.argsort(inverse, kind="stable")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    for size in np.unique(counts):
        blocks = np.nonzero(counts == size)[0]
        rows = order[starts[blocks][:, None] + np.arange(size)[None, :]]
        r, f, _ = block_sigmas(jnp.asarray(M[rows]), counts[blocks].astype(float), threshold)
        rho[blocks], dof[blocks] = r, f
    sigma = pooled_sigmas(rho, dof)
    block_w = 1.0 / sigma
    return block_w[inverse], uniq, block_w, sigma
