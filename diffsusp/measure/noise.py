"""Measurement noise models for synthetic data.

The thesis's portable measuring arm is accurate to about ±0.05 mm (calibrated-length test,
spec geometry §3.4); its numerical tests add Gaussian noise of σ = 0.05 mm to every landmark
coordinate (spec stiffness §2.8, R6). Load cells of a K&C bench can be given a noise too.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

ARM_SIGMA = 0.05
"""Standard deviation (mm) per landmark coordinate of the thesis's portable measuring arm."""


class GaussianNoise(eqx.Module):
    """Independent zero-mean Gaussian noise on measured quantities.

    **Fields:** `landmarks` σ per landmark coordinate (mm; default 0.05, the thesis's arm),
    `force` σ per load force component (N; default 0), `moment` σ per load moment component
    (N·mm; default 0).
    """

    landmarks: float = ARM_SIGMA
    force: float = 0.0
    moment: float = 0.0

    def __check_init__(self):
        for name in ("landmarks", "force", "moment"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and value >= 0):
                raise ValueError(f"GaussianNoise.{name} must be a number ≥ 0; got {value!r}.")

    def perturb_landmarks(
        self, key: PRNGKeyArray, positions: Float[Array, "*shape 3"]
    ) -> Float[Array, "*shape 3"]:
        """`positions` + N(0, σ²) on every coordinate (mm)."""
        return positions + self.landmarks * jax.random.normal(key, positions.shape,
                                                              positions.dtype)

    def perturb_loads(self, key: PRNGKeyArray, loads):
        """`loads` with N(0, σ²) added to every force (N) and moment (N·mm) component of every
        load point that carries a load in some case (an unused load point stays exactly 0)."""
        k1, k2 = jax.random.split(key)
        used_f = jnp.any(loads.force != 0, axis=tuple(range(loads.force.ndim - 2)) + (-1,))
        used_m = jnp.any(loads.moment != 0, axis=tuple(range(loads.moment.ndim - 2)) + (-1,))
        force = loads.force + self.force * used_f[:, None] * jax.random.normal(
            k1, loads.force.shape, loads.force.dtype)
        moment = loads.moment + self.moment * used_m[:, None] * jax.random.normal(
            k2, loads.moment.shape, loads.moment.dtype)
        return eqx.tree_at(lambda l: (l.force, l.moment), loads, (force, moment))
