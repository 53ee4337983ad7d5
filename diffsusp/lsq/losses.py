"""The one robust loss of diffsusp's fits (the suspension least squares, the tyre fits).

A robust loss ρ enters a Gauss–Newton / Levenberg–Marquardt fit through the residual
r̃ = sgn(z)·√(2ρ(z)) of each whitened residual z, so that ½Σr̃² = Σρ(z) and the solver stays a
plain least-squares one: Huber ρ = z²/2 (|z| ≤ c), c|z| − c²/2 beyond; Cauchy
ρ = (c²/2)·log(1 + (z/c)²). The loss is a runtime code (`LOSSES`), so every loss shares one
compiled program.
"""

import jax.numpy as jnp

__all__ = ["DEFAULT_LOSS_SCALE", "LOSSES", "robust"]

LOSSES = {"linear": 0, "huber": 1, "cauchy": 2}
"""Loss names → codes (a runtime value: every loss shares one compiled program)."""

DEFAULT_LOSS_SCALE = {"linear": 1.0, "huber": 1.345, "cauchy": 2.385}
"""Default robust-loss scales in units of σ (95 % efficiency under Gaussian noise)."""


def robust(z, kind, c):
    """r̃ = sign(z)·√(2ρ(z)) for ρ linear (`kind` 0), Huber (1) or Cauchy (2) with scale `c`
    (`LOSSES`; traced values: one compiled program for all)."""
    a = jnp.abs(z)
    big = a > c
    a_big = jnp.where(big, a, 2.0 * c)
    huber = jnp.where(big, jnp.sign(z) * jnp.sqrt(2.0 * c * a_big - c * c), z)
    x2 = (z / c) ** 2
    small = x2 < 1e-8
    x2s = jnp.where(small, 1.0, x2)
    cauchy = z * jnp.sqrt(jnp.where(small, 1.0 - 0.5 * x2, jnp.log1p(x2s) / x2s))
    return jnp.where(kind == 0, z, jnp.where(kind == 1, huber, cauchy))
