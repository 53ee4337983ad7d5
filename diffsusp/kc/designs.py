"""The design batch: many designs of one suspension × the same load cases, every K&C metric, its
derivative metrics and the compliance matrices, in one compiled program.

spec: stiffness §2.7 (the Table 5-1 cases), §3 (perspective 3: what a parameter changes);
DESIGN.md "Static equilibrium" (batched, differentiable).

`design_batch(event, where, values)` sets the leaves `where` selects (bushing stiffnesses,
spring rates, hardpoints... — a `kc.Selection`) to each design's values, solves each design's
cases by the batched Newton inside one compiled loop over the designs (`jax.lax.map`), then
computes the metrics, their derivatives through the equilibrium and the flags of every design
and case at once (`metrics_at`, vmapped over the designs): what `evaluate` does per design, in
one program. The program depends on the rig's structure, the number of designs and cases and
which leaves are selected — not on the values, nor on which lambda selected them: a new set of
designs of the same shape runs the compiled program again.

Why a loop for the Newton and not `jax.vmap` over the designs: the Newton is batched over its
cases already (the case axis is the one its assembly and its pool of unconverged cases are laid
out for); a design axis on top makes every leaf of the mechanism batched, the assembly a
vmapped scatter, and the loop run until the slowest case of all designs stops. The metrics
have no loop: vmapped over designs × cases they run as large batched kernels, where a loop of
`evaluate` would run them 13 cases at a time. Measured on the pseudo-McPherson, 200 designs ×
the 13 cases of Table 5-1, in one process on a loaded 2-core machine (±30 % between runs): the
Newton 3.8 s as a loop against 12.9 s vmapped; Newton and metrics 7.9 s split so, 10.1 s as a
loop of `evaluate` (7.4 s of it the Newton). `batch_size` vmaps that many designs per step of
the Newton's loop (`jax.lax.map`'s), for accelerators.
"""

import dataclasses
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..compilation import filter_jit
from ..errors import InputError
from ..model import Loads
from ..statics import StaticSolution, Status, solve_statics
from .events import metrics_at
from .second_order import Selection, select

__all__ = ["DesignBatch", "design_batch"]


@dataclasses.dataclass(frozen=True)
class DesignBatch:
    """Result of `design_batch`, every array with a leading design axis.

    - `params`: the names of θ (`Selection.names`); `theta` `(designs, p)`.
    - `metrics`: name → `(designs, cases)` (internal units; NaN where a case did not
      converge); `compliance`: corner prefix → `(designs, cases, 6, 6)` (force rigs).
    - `solution`: the `StaticSolution` `(designs, cases, ...)`: status, and the `stable` and
      `law_valid` flags (as `kc.evaluate` computes them), per design and case.
    """

    params: tuple[str, ...]
    theta: np.ndarray
    metrics: dict
    compliance: dict
    solution: StaticSolution

    @property
    def converged(self) -> np.ndarray:
        """`(designs, cases)`: the case reached equilibrium."""
        return np.asarray(self.solution.status) == Status.CONVERGED

    @property
    def usable(self) -> np.ndarray:
        """`(designs, cases)`: converged, stable (positive definite reduced stiffness) and
        every bushing inside its law's validity: the cases whose metrics describe the design."""
        return (self.converged & np.asarray(self.solution.stable)
                & np.asarray(self.solution.law_valid))


@filter_jit
def _batch(rig, loads: Loads, selection: Selection, theta, q0, rtol: float, atol: float,
           max_steps: int, batch_size: int | None):
    def design(th):
        return eqx.tree_at(lambda r_: r_.mech, rig, selection.apply(rig.mech, th))

    def solve(th):
        return solve_statics(design(th).mech, loads, q0=q0, rtol=rtol, atol=atol,
                             max_steps=max_steps, throw=False, checks=False)

    sol = jax.lax.map(solve, theta, batch_size=batch_size)
    metrics, compliance, (stable, law_valid), _ = jax.vmap(
        lambda th, s: metrics_at(design(th), loads, s))(theta, sol)
    return dataclasses.replace(sol, stable=stable, law_valid=law_valid), metrics, compliance


def design_batch(event, where: Callable | Selection, values, *, loads: Loads | None = None,
                 q0=None, rtol: float = 1e-12, atol: float = 1e-10, max_steps: int = 50,
                 batch_size: int | None = None) -> DesignBatch:
    """Every K&C metric, derivative metric and compliance matrix of many designs under the
    same load cases, in one compiled call.

    **Arguments:**
    - `event`: a `KCEvent` (its rig and load cases, e.g. `kc.load_table(mech)`), or a rig
      (`force_rig`, `travel_rig`) with `loads`.
    - `where`: the leaves of the rig's mechanism that vary (`lambda m: (m.bushings.k_trans,
      m.springs.k)`) or a `Selection` (`kc.select`).
    - `values`: the designs: `(designs, p)` in the selection's order, or a tuple with one
      array per selected leaf, each with a leading design axis (`(designs, *leaf.shape)`).
    - `q0`: start coordinates of the cases (default: design); tolerances and `max_steps` as
      `solve_statics`.
    - `batch_size`: designs solved together (vmapped) per step of the Newton's loop over
      designs (default: one at a time, the fastest on a CPU; see the module docstring).

    **Returns:** a `DesignBatch`.

    **Raises:** `InputError` for values of the wrong shape.
    """
    rig = getattr(event, "rig", event)
    loads = getattr(event, "loads", None) if loads is None else loads
    if loads is None or loads.n_cases is None:
        raise InputError("design_batch of a rig needs `loads` with a leading case axis (or "
                         "pass a KCEvent).")
    selection = where if isinstance(where, Selection) else select(rig.mech, where)
    p = len(selection)
    if isinstance(values, (tuple, list)):
        if len(values) != len(selection.shapes):
            raise InputError(f"values: one array per selected leaf ({len(selection.shapes)}); "
                             f"got {len(values)}.")
        arrays = [np.asarray(v, dtype=float) for v in values]
        n = {a.shape[0] if a.ndim else -1 for a in arrays}
        if len(n) != 1 or any(a.shape[1:] != s for a, s in
                              zip(arrays, selection.shapes, strict=True)):
            raise InputError("values: each array must be (designs, *leaf shape) with the same "
                             f"number of designs; leaf shapes {list(selection.shapes)}.")
        theta = np.concatenate([a.reshape(a.shape[0], -1) for a in arrays], axis=1)
    else:
        theta = np.asarray(values, dtype=float)
    if theta.ndim != 2 or theta.shape[1] != p:
        raise InputError(f"values must be (designs, {p}) (one row per design, the selection's "
                         f"order: {', '.join(selection.names[:4])}...); got {theta.shape}.")
    n = rig.mech.n_coordinates
    q0 = jnp.zeros((loads.n_cases, n)) if q0 is None else jnp.broadcast_to(
        jnp.asarray(q0, dtype=float), (loads.n_cases, n))
    sol, metrics, compliance = _batch(rig, loads, selection, jnp.asarray(theta), q0,
                                      float(rtol), float(atol), int(max_steps),
                                      None if batch_size is None else int(batch_size))
    return DesignBatch(params=selection.names, theta=theta,
                       metrics={k: np.asarray(v) for k, v in metrics.items()},
                       compliance={k: np.asarray(v) for k, v in compliance.items()},
                       solution=sol)
