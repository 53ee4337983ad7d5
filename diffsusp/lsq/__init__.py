"""Guaranteed linear least squares (spec: guaranteed_least_squares; DESIGN.md "lsq").

The one linear least-squares engine of diffsusp, for any linear-in-parameter model y = W x + ρ
(direct stiffness identification, polynomial tyre models, diagnostics of nonlinear fits):

- the R-factor of [W, −y] with a positive diagonal, one-shot or streamed block by block
  (`Accumulator`, memory O(p²)), with per-block weights, automatic from each block's residual;
- identifiability from R alone: kept (base) columns, rank, singular values, condition number,
  which parameters are individually identifiable, and the identifiable combinations printed
  symbolically ("Krx1 + Krx2", "a - 0.07413 b");
- solutions: basic (non-identifiable parameters at 0 or their prior), minimum norm, truncated
  SVD, Tikhonov toward a prior, non-negative / box-bounded (own active-set BVLS), TLS;
- σ, σ%, confidence index, intervals; the elimination loop with its log; a-priori re-injection;
- the one robust loss of the nonlinear fits (`robust`, `LOSSES`).

```python
from diffsusp import lsq
fit = lsq.solve(W, y, names=names)      # lsq.Fit; print(fit.table())
fit, log = lsq.eliminate(W, y, names=names, prior={"b": 1.0})
sol = jax.vmap(lambda y: lsq.solve_arrays(W, y))(Y)   # pure arrays, batched (Monte-Carlo)
```
"""

from .accumulate import Accumulator
from .core import METHODS, Solution, qr_r, solve_arrays, solve_r, tls_arrays
from .fit import Fit, Problem, Step, eliminate, format_combination, problem, solve, tls
from .losses import DEFAULT_LOSS_SCALE, LOSSES, robust

__all__ = [
    "DEFAULT_LOSS_SCALE", "LOSSES", "METHODS", "Accumulator", "Fit", "Problem", "Solution",
    "Step", "eliminate", "format_combination", "problem", "qr_r", "robust", "solve",
    "solve_arrays", "solve_r", "tls", "tls_arrays",
]
