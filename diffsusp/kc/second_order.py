"""Second-order sensitivities of K&C metrics: gradients and Hessian-vector products with respect
to model parameters (stiffnesses, hardpoints, ...) through the equilibrium.

spec: stiffness §2.7 and §3 (sensitivities: which parameters move which metric, perspective 3);
DESIGN.md "Static equilibrium" (implicit differentiation).

For a metric m_c(θ) of load case c (bump steer, wheel rate, compliance steer: the derivative
metrics are themselves derivatives of the equilibrium with respect to the rig inputs),
`hessian_vector_product` returns the value, the exact gradient ∇m_c and the product ∇²m_c·v
for a direction v of the parameters — with v a unit vector on a bushing stiffness, the row
∂²m_c/∂θ_j∂k says how the sensitivity of m_c to every parameter θ_j (e.g. a hardpoint) changes
with that stiffness; with v a design step, the curvature a Newton step of a design optimisation
needs. Forward over reverse: the gradient by reverse mode (one pass per metric and case), its
directional derivative by forward mode.

How the equilibrium is differentiated. The cases are solved once by `solve_statics` (the
ordinary batched program, shared with every other solve of that model). The derivatives are
then taken at that solution y* of r(y; θ) = 0 through `_pinned`, a function of θ whose value is
y* and whose JVP rule is the implicit function theorem dy = −J(y, θ)⁻¹·∂r/∂θ(y, θ)·dθ with y
the same pinned function: the rule is itself differentiable, so derivatives of every order at θ
are exact, and the Newton loop is never traced inside a derivative (forward-over-reverse through
`solve_statics`'s own custom JVP re-traces the Newton loop under each transformation). The value
is only correct at the solved point: the function is never evaluated elsewhere.

Cost: the program holds third derivatives of the element assembly (a derivative metric is
already a derivative of the equilibrium): about 25 000 jaxpr equations for three metrics of the
pseudo-McPherson's travel rig, one to several minutes of tracing and compilation on a loaded
2-core machine, once per rig structure, number of cases, parameter selection and metric names.
"""

import dataclasses
from collections.abc import Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..compilation import filter_jit
from ..errors import InputError
from ..model import Loads, Mechanism
from ..statics import (
    StaticSolution,
    Status,
    linearize_internal,
    solve_statics,
    to_internal,
    to_public,
)
from .events import metrics_at
from .metrics import flagged

__all__ = ["HessianVectorProducts", "Selection", "hessian_vector_product", "pinned_solution",
           "select"]


# ----------------------------------------------------------------------------- selections


class _Tag:
    """Stands in for leaf `index` of a mechanism while a `where` selector runs."""

    def __init__(self, index: int):
        self.index = index


class Selection(eqx.Module):
    """Array leaves of a mechanism chosen by a `where` selector (the equinox idiom, as
    `identify.Params.leaves`), as one flat parameter vector θ (the leaves raveled in the order
    `where` returns them). Hashable: two selections of the same leaves of mechanisms of the
    same structure are equal, so programs that take one are compiled once whatever lambda
    made it.

    **Fields:** `indices` (positions of the leaves in `jax.tree.leaves(mech)`), `shapes`,
    `names` (one per entry of θ, e.g. `'.bushings.k_trans[0,2]'`).
    """

    indices: tuple[int, ...] = eqx.field(static=True)
    shapes: tuple[tuple[int, ...], ...] = eqx.field(static=True)
    names: tuple[str, ...] = eqx.field(static=True)

    def __len__(self) -> int:
        return len(self.names)

    def values(self, mech: Mechanism) -> Float[Array, " p"]:
        """θ of `mech`: the selected leaves, raveled and concatenated."""
        leaves = jax.tree.leaves(mech)
        return jnp.concatenate([jnp.ravel(leaves[i]) for i in self.indices])

    def leaves(self, mech: Mechanism) -> tuple:
        """The selected leaves of `mech`, in the order of `indices` (any leading axes kept)."""
        leaves = jax.tree.leaves(mech)
        return tuple(leaves[i] for i in self.indices)

    def apply(self, mech: Mechanism, theta: Float[Array, " p"]) -> Mechanism:
        """`mech` with the selected leaves set from θ."""
        leaves, treedef = jax.tree.flatten(mech)
        start = 0
        for i, shape in zip(self.indices, self.shapes, strict=True):
            size = int(np.prod(shape, dtype=int))
            leaves[i] = jnp.reshape(theta[start:start + size], shape).astype(leaves[i].dtype)
            start += size
        return jax.tree.unflatten(treedef, leaves)


def select(mech: Mechanism, where: Callable) -> Selection:
    """The `Selection` of the leaves `where(mech)` returns (one leaf or a tuple/list of them,
    e.g. `lambda m: (m.bushings.k_trans, m.springs.k)`).

    **Raises:** `InputError` when `where` returns something other than float array leaves of
    `mech`, or a leaf twice."""
    paths_leaves, treedef = jax.tree_util.tree_flatten_with_path(mech)
    tagged = jax.tree.unflatten(treedef, [_Tag(i) for i in range(len(paths_leaves))])
    try:
        picked = where(tagged)
    except Exception as err:
        raise InputError(f"the `where` selector failed on the mechanism: {err}") from err
    tags = jax.tree.leaves(picked, is_leaf=lambda x: isinstance(x, _Tag))
    if not tags or not all(isinstance(t, _Tag) for t in tags):
        raise InputError("`where` must return array leaves of the mechanism "
                         "(e.g. lambda m: (m.bushings.k_trans, m.springs.k)).")
    indices = tuple(t.index for t in tags)
    if len(set(indices)) != len(indices):
        raise InputError("`where` selects a leaf twice; select each leaf once.")
    shapes, names = [], []
    for i in indices:
        path, leaf = paths_leaves[i]
        leaf = np.asarray(leaf)
        if not np.issubdtype(leaf.dtype, np.floating):
            raise InputError(f"{jax.tree_util.keystr(path)} is not a float leaf; only real "
                             "parameters can be differentiated.")
        shapes.append(leaf.shape)
        key = jax.tree_util.keystr(path)
        names += [f"{key}[{','.join(map(str, ix))}]" if leaf.ndim else key
                  for ix in np.ndindex(*leaf.shape)]
    return Selection(indices=indices, shapes=tuple(shapes), names=tuple(names))


def _chart(mech: Mechanism, params):
    """(an object with `apply(mech, θ)`, θ, names) for a `where` selector, a `Selection` or a
    parametrisation with `apply`, `values` and `names` (such as `identify.Params`)."""
    if isinstance(params, Selection):
        chart = params
    elif all(hasattr(params, a) for a in ("apply", "values", "names")):
        chart = params
    elif callable(params):
        chart = select(mech, params)
    else:
        raise InputError("params must be a `where` selector (lambda m: m.bushings.k_trans), a "
                         "kc.Selection or an identify.Params.")
    return chart, jnp.asarray(chart.values(mech), dtype=float), tuple(chart.names)


# ----------------------------------------------------------------------------- the equilibrium


@eqx.filter_custom_jvp
def _pinned(mech: Mechanism, loads: Loads, y):
    """The equilibrium y* (solver coordinates and multipliers, one case) of (mech, loads), as
    a function of them: its value is `y` (solved beforehand), its derivatives of every order
    those of the implicit function at that point (see the module docstring)."""
    return y


@_pinned.def_jvp
def _pinned_jvp(primals, tangents):
    mech, loads, y = primals
    t_mech, t_loads, _ = tangents
    y = _pinned(mech, loads, y)  # differentiable again: the rule holds at every order
    if t_mech is None and t_loads is None:
        return y, jnp.zeros_like(y)
    return y, linearize_internal(mech, loads, y).tangent(t_mech, t_loads)


def pinned_solution(mech: Mechanism, loads: Loads, sol: StaticSolution) -> StaticSolution:
    """`sol` (equilibria of `mech` under `loads`, leading case axis, from `solve_statics`) with
    q and multipliers as functions of `mech` and `loads` whose derivatives of every order at
    this point are the implicit function's (forward and reverse mode, nested), with no Newton
    in the traced program. Its values are `sol`'s whatever `mech` is: differentiate it at the
    mechanism it was solved for, never evaluate it elsewhere."""
    n = mech.n_coordinates
    y_star = jax.lax.stop_gradient(jnp.concatenate(
        [jax.vmap(lambda q: to_internal(mech, q))(sol.q), sol.multipliers], axis=1))
    y = jax.vmap(lambda l_, y_: _pinned(mech, l_, y_))(loads, y_star)
    q = jax.vmap(lambda y_: to_public(mech, y_[:n]))(y)
    return dataclasses.replace(sol, q=q, multipliers=y[:, n:])


# ----------------------------------------------------------------------------- the products


@filter_jit
def _products(rig, loads: Loads, sol: StaticSolution, chart, theta, direction,
              names: tuple[str, ...]):
    def metrics(th):
        mech = chart.apply(rig.mech, th)
        r = eqx.tree_at(lambda r_: r_.mech, rig, mech)
        m = metrics_at(r, loads, pinned_solution(mech, loads, sol))[0]
        return {k: m[k] for k in names}

    def with_values(th):  # the values ride along as aux: the metrics are traced once
        m = metrics(th)
        return m, m

    (grad, values), (hvp, _) = jax.jvp(jax.jacrev(with_values, has_aux=True), (theta,),
                                       (direction,))
    ok = (sol.status == Status.CONVERGED)[:, None]  # a failed case has no derivative either
    grad = {k: jnp.where(ok, v, jnp.nan) for k, v in grad.items()}
    hvp = {k: jnp.where(ok, v, jnp.nan) for k, v in hvp.items()}
    return values, grad, hvp


@dataclasses.dataclass(frozen=True)
class HessianVectorProducts:
    """Result of `hessian_vector_product`.

    - `params`: one name per parameter θ_j; `theta` `(p,)` their values; `direction` v `(p,)`.
    - `values`: metric → `(cases,)`; `gradient`: metric → `(cases, p)` ∂m_c/∂θ;
      `hvp`: metric → `(cases, p)` ∇²m_c·v = Σ_k ∂²m_c/∂θ_j∂θ_k v_k, the change of the
      gradient per unit step along v. Internal units (mm, N, rad; bump steer rad/mm) per
      parameter unit. NaN at cases that did not converge (`solution.status`).
    - `solution`: the equilibria (`StaticSolution`).
    """

    params: tuple[str, ...]
    theta: np.ndarray
    direction: np.ndarray
    values: dict
    gradient: dict
    hvp: dict
    solution: StaticSolution


_AVAILABLE: dict = {}  # rig structure → its public metric names


def _metric_names(rig, loads, sol, metrics):
    """The metric names to differentiate, checked against those `metrics_at` gives for `rig`
    (read from its output shapes: traced once per rig structure, not per call)."""
    key = jax.tree.structure(rig)
    if key not in _AVAILABLE:
        shapes = jax.eval_shape(lambda: metrics_at(rig, loads, sol)[0])
        _AVAILABLE[key] = tuple(sorted(k for k in shapes
                                       if not k.rsplit("/", 1)[-1].startswith("_")))
    available = _AVAILABLE[key]
    if metrics is None:
        chosen = flagged("sensitivity")
        return tuple(k for k in available if k.rsplit("/", 1)[-1] in chosen)
    metrics = (metrics,) if isinstance(metrics, str) else tuple(metrics)
    unknown = sorted(set(metrics) - set(available))
    if unknown:
        raise InputError(f"unknown metric(s) {unknown}; available: {', '.join(available)}.")
    return metrics


def hessian_vector_product(event, params, direction, *, loads: Loads | None = None,
                           metrics: str | Sequence[str] | None = None, rtol: float = 1e-12,
                           atol: float = 1e-10, max_steps: int = 50) -> HessianVectorProducts:
    """Values, exact gradients and Hessian-vector products of K&C metrics with respect to
    model parameters, at every case of an event.

    **Arguments:**
    - `event`: a `KCEvent` (its rig and load cases), or a rig (`travel_rig`, `force_rig`)
      with `loads` (leading case axis).
    - `params`: which numbers of the rig's mechanism θ is: a `where` selector
      (`lambda m: (m.bushings.k_trans, m.markers.position)`: every entry of those leaves), a
      `Selection` (`kc.select`), or an `identify.Params` (named scalars, shared entries).
    - `direction`: v, `(p,)` in θ's order (`HessianVectorProducts.params`), or a parameter
      name for the unit vector on it.
    - `metrics`: a name or names (e.g. `("bump_steer", "wheel_rate")`); default: the metrics
      the registry marks for sensitivity studies (`flagged('sensitivity')`).
    - solver tolerances as `solve_statics` (the equilibria are solved once, then pinned).

    **Returns:** a `HessianVectorProducts`. One compiled program per rig structure, number of
    cases, parameter selection and metric names: new values of the mechanism, the loads or v
    reuse it.

    **Raises:** `InputError` for an unknown metric or parameter name or a direction of the
    wrong length.
    """
    rig = getattr(event, "rig", event)
    loads = getattr(event, "loads", None) if loads is None else loads
    if loads is None or loads.n_cases is None:
        raise InputError("hessian_vector_product of a rig needs `loads` with a leading case "
                         "axis (or pass a KCEvent).")
    chart, theta, names = _chart(rig.mech, params)
    if isinstance(direction, str):
        if direction not in names:
            raise InputError(f"unknown parameter '{direction}'; the parameters are "
                             f"{', '.join(names)}.")
        direction = np.eye(len(names))[names.index(direction)]
    direction = jnp.asarray(direction, dtype=float)
    if direction.shape != theta.shape:
        raise InputError(f"direction must have shape {theta.shape} (one entry per parameter); "
                         f"got {direction.shape}.")
    sol = solve_statics(rig.mech, loads, rtol=rtol, atol=atol, max_steps=max_steps,
                        throw=False, checks=False)
    chosen = _metric_names(rig, loads, sol, metrics)
    values, grad, hvp = _products(rig, loads, sol, chart, theta, direction, chosen)
    return HessianVectorProducts(
        params=names, theta=np.asarray(theta), direction=np.asarray(direction),
        values={k: np.asarray(v) for k, v in values.items()},
        gradient={k: np.asarray(v) for k, v in grad.items()},
        hvp={k: np.asarray(v) for k, v in hvp.items()}, solution=sol)
