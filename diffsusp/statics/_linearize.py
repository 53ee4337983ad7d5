"""The linearisation of the equilibrium at a solution: what `kc`, `identify` and `sensitivity`
need to differentiate through it without re-running Newton.

spec: stiffness §1.9 (KKT system), DESIGN.md "Static equilibrium" (implicit differentiation).
At a solution `y* = (q*, λ*)` of `r(y; θ) = 0` the implicit function theorem gives, for a tangent
dθ of any float leaf of the mechanism or the loads, dy = −J⁻¹·∂r/∂θ·dθ with J = ∂r/∂y the KKT
Jacobian: one linear solve, the same (equilibrated) one `solve_statics` uses in its own JVP rule.
Solver coordinates: each part's reference point P (mm) and Gibbs vector b (see `kernel`);
`to_public` converts.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..model.mechanism import Loads, Mechanism
from .kernel import assemble, to_internal


def _ruiz(jac):
    """Row and column scalings (d_r, d_c) with diag(d_r)·J·diag(d_c) equilibrated (one sweep)."""
    a = jnp.abs(jac)
    d_r = 1.0 / jnp.sqrt(jnp.maximum(jnp.max(a, axis=1), 1e-300))
    d_c = 1.0 / jnp.sqrt(jnp.maximum(jnp.max(a * d_r[:, None], axis=0), 1e-300))
    return d_r, d_c


def scaled_solve(jac, rhs):
    """J⁻¹·rhs after a Ruiz row/column equilibration (forces in N, moments in N·mm and
    constraint rows in mm or rad differ by orders of magnitude). `rhs` (k,) or (k, p)."""
    d_r, d_c = _ruiz(jax.lax.stop_gradient(jac))
    scaled = jac * d_r[:, None] * d_c[None, :]
    if rhs.ndim == 1:
        return d_c * jnp.linalg.solve(scaled, d_r * rhs)
    return d_c[:, None] * jnp.linalg.solve(scaled, d_r[:, None] * rhs)


def residual(mech: Mechanism, loads: Loads, y):
    """KKT residual r(y) (n + m,) at solver coordinates and multipliers y, one load case:
    generalised forces Q_ext + Q_int + Φ_qᵀλ (N, N·mm per unit Gibbs vector), then the
    constraint rows Φ − c (mm or rad)."""
    n = mech.topology.n
    return assemble(mech, loads, y[:n], y[n:], with_jacobian=False)[0]


class Linearization(eqx.Module):
    """The equilibrium of one load case, linearised (`linearize`).

    **Fields:** `y` solver coordinates and multipliers (n + m,), `jacobian` the KKT Jacobian
    ∂r/∂y (n + m, n + m). `constraint_jacobian` Φ_q (m, n) and `stiffness` −∂Q/∂q (n, n) (the
    tangent stiffness, constraint Hessian Σλ∂²Φ included) are its blocks.
    """

    mech: Mechanism
    loads: Loads
    y: Float[Array, " k"]
    jacobian: Float[Array, "k k"]

    @property
    def constraint_jacobian(self):
        n = self.mech.topology.n
        return self.jacobian[n:, :n]

    @property
    def stiffness(self):
        n = self.mech.topology.n
        return -self.jacobian[:n, :n]

    def solve(self, rhs):
        """J⁻¹·rhs (equilibrated LU), rhs (n + m,) or (n + m, p)."""
        return scaled_solve(self.jacobian, rhs)

    def tangent(self, d_mech=None, d_loads=None):
        """dy (n + m,) of the equilibrium for a tangent of the mechanism and/or the loads (pytrees
        like them, or None for zero): −J⁻¹·∂r/∂(mech, loads)·(d_mech, d_loads)."""
        if d_mech is None:
            _, dr = jax.jvp(lambda l: residual(self.mech, l, self.y), (self.loads,), (d_loads,))
        elif d_loads is None:
            _, dr = eqx.filter_jvp(lambda m: residual(m, self.loads, self.y), (self.mech,),
                                   (d_mech,))
        else:
            _, dr = eqx.filter_jvp(lambda m, l: residual(m, l, self.y), (self.mech, self.loads),
                                   (d_mech, d_loads))
        return -self.solve(dr)


def linearize(mech: Mechanism, loads: Loads, q, multipliers) -> Linearization:
    """Linearise the equilibrium (q, λ) of one load case (public coordinates q, e.g.
    `sol.q[c]`, `sol.multipliers[c]`); `jax.vmap` it over cases."""
    return linearize_internal(mech, loads, jnp.concatenate([to_internal(mech, q), multipliers]))


def linearize_internal(mech: Mechanism, loads: Loads, y) -> Linearization:
    """`linearize` at solver coordinates and multipliers y (n + m,)."""
    n = mech.topology.n
    _, jac = assemble(mech, loads, y[:n], y[n:])
    return Linearization(mech=mech, loads=loads, y=y, jacobian=jac)
