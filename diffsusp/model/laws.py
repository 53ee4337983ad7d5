"""Scalar force laws: Akima splines with linear extrapolation (Adams AKISPL + LINEAR_EXTRAPOLATE).

spec: stiffness §4.3 (A/Car bushing splines: Y = force on the I part, X = deformation).
"""

import jax.numpy as jnp
from jaxtyping import Array, Float


def akima_slopes(x: Float[Array, " k"], y: Float[Array, " k"]) -> Float[Array, " k"]:
    """Knot derivatives of the Akima interpolant through (x, y).

    Akima's weights |m_{i+1} − m_i| are made smooth (an epsilon under a square root) so the
    slopes, and so the forces, are differentiable with respect to the table values.
    For fewer than three knots the law is linear.
    """
    m = jnp.diff(y) / jnp.diff(x)
    if m.shape[0] == 1:
        return jnp.concatenate([m, m])
    # Akima's end extension: two ghost secant slopes on each side.
    m_left2 = 3 * m[0] - 2 * m[1]
    m_left1 = 2 * m[0] - m[1]
    m_right1 = 2 * m[-1] - m[-2]
    m_right2 = 3 * m[-1] - 2 * m[-2]
    me = jnp.concatenate([jnp.stack([m_left2, m_left1]), m, jnp.stack([m_right1, m_right2])])
    scale = jnp.max(jnp.abs(m)) + 1.0
    dm = jnp.sqrt(jnp.diff(me) ** 2 + (1e-9 * scale) ** 2)
    w1 = dm[2:]  # |m_{i+1} - m_i|
    w2 = dm[:-2]  # |m_{i-1} - m_{i-2}|
    return (w1 * me[1:-2] + w2 * me[2:-1]) / (w1 + w2)


def akima_eval(
    x: Float[Array, " k"], y: Float[Array, " k"], t: Float[Array, ""]
) -> Float[Array, ""]:
    """Evaluate the Akima spline through (x, y) at t, linear beyond the end knots.

    The extrapolation continues the end knot's slope (A/Car ``LINEAR_EXTRAPOLATE``), so the law
    stays C¹ everywhere.
    """
    s = akima_slopes(x, y)
    k = x.shape[0]
    i = jnp.clip(jnp.searchsorted(x, t, side="right") - 1, 0, k - 2)
    x0, x1, y0, y1, s0, s1 = x[i], x[i + 1], y[i], y[i + 1], s[i], s[i + 1]
    h = x1 - x0
    u = jnp.clip((t - x0) / h, 0.0, 1.0)
    h00 = (1 + 2 * u) * (1 - u) ** 2
    h10 = u * (1 - u) ** 2
    h01 = u**2 * (3 - 2 * u)
    h11 = u**2 * (u - 1)
    inside = h00 * y0 + h10 * h * s0 + h01 * y1 + h11 * h * s1
    below = y[0] + s[0] * (t - x[0])
    above = y[-1] + s[-1] * (t - x[-1])
    return jnp.where(t < x[0], below, jnp.where(t > x[-1], above, inside))
