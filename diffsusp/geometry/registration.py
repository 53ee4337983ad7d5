"""Rigid registration of landmarks: the pose of a part from its landmarks (Arun/Kabsch).

Given landmarks P_a on a part (in the part frame, which for diffsusp is the global frame at
design) and the same landmarks Q_a measured in the global frame, find the rotation R and the
translation T minimising

    C = Σ_a w_a ‖R P_a + T − Q_a‖²                                  (spec: geometry §3.6, 2.18)

Centring on the weighted centroids P̄, Q̄ gives T = Q̄ − R P̄ (2.24) and reduces the problem to
maximising tr(Rᵀ H) with the correlation H = Σ_a w_a (Q_a − Q̄)(P_a − P̄)ᵀ (2.21). Two exact
solvers of that same problem:

- `method="svd"`: Arun, Huang & Blostein (the thesis's Annex A): H = U S Vᵀ,
  R = U diag(1, 1, det(U Vᵀ)) Vᵀ. The diag term is the reflection fix: it keeps det R = +1 when
  the unconstrained optimum is a reflection (coplanar landmarks with noise, large noise).
- `method="quaternion"` (default): Horn's closed form: R is the rotation of the unit quaternion
  that is the dominant eigenvector of a symmetric 4×4 matrix N(H). It gives the same proper
  rotation (the reflection fix is built in: a quaternion is always a rotation), and its
  eigenvector is found by repeated squaring of the shifted matrix, which is a few dozen
  element-wise operations per registration and vectorises over thousands of parts × load
  cases far better than a batched 3×3 SVD.

Both accept any leading batch axes (parts, load cases, noise seeds) and are jit/vmap friendly.
Input checks (at least three non-collinear landmarks, finite values) belong to the caller
(`diffsusp.measure`), which knows the part and case names to put in the message.
"""

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

__all__ = ["Registration", "register_landmarks", "landmark_spread", "QUATERNION_SQUARINGS"]

QUATERNION_SQUARINGS = 26
"""Squarings of the shifted Horn matrix (2^26 ≈ 6.7e7 power-iteration steps). Convergence needs
2^k·(1 − λ₂/λ₁) ≫ 1; for landmarks whose second principal spread is at least 1e-3 of the first
(the collinearity limit `diffsusp.measure` enforces) λ₂/λ₁ < 1 − 5e-7, so the eigenvector is
exact to rounding."""


class Registration(NamedTuple):
    """Result of `register_landmarks`: `measured ≈ rotation @ reference + translation`.

    **Fields:** `rotation` (…, 3, 3), `translation` (…, 3) (mm), `rms` (…,) the weighted
    root-mean-square landmark residual (mm) — about the measurement noise when the part is rigid
    and the landmarks are matched, much larger for a wrong landmark.
    """

    rotation: Float[Array, "*batch 3 3"]
    translation: Float[Array, "*batch 3"]
    rms: Float[Array, "*batch"]


def _centred(reference, measured, weights):
    w = weights / jnp.sum(weights, axis=-1, keepdims=True)
    p_bar = jnp.einsum("...k,...ki->...i", w, reference)
    q_bar = jnp.einsum("...k,...ki->...i", w, measured)
    p = reference - p_bar[..., None, :]
    q = measured - q_bar[..., None, :]
    return w, p_bar, q_bar, p, q


def _rotation_svd(h):
    """Arun/Kabsch with the reflection fix: H = U S Vᵀ, R = U diag(1, 1, d) Vᵀ, d = det(U Vᵀ)."""
    u, _, vt = jnp.linalg.svd(h)
    d = jnp.sign(jnp.linalg.det(u @ vt))
    d = jnp.where(d == 0.0, 1.0, d)
    u = u.at[..., :, 2].multiply(d[..., None])
    return u @ vt


def _rotation_quaternion(h):
    """Horn's method: the dominant eigenvector of N(H) by repeated squaring (batch last)."""
    batch = h.shape[:-2]
    s = jnp.moveaxis(h.reshape(-1, 3, 3), 0, -1)  # (3, 3, B): s[i, j] = Σ q_i p_j
    # Horn writes the correlation as S = Σ p qᵀ (reference first): S_ab = s[b, a].
    sxx, sxy, sxz = s[0, 0], s[1, 0], s[2, 0]
    syx, syy, syz = s[0, 1], s[1, 1], s[2, 1]
    szx, szy, szz = s[0, 2], s[1, 2], s[2, 2]
    n = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ]
    # Shift by a bound of the spectral radius (s1 + s2 + s3 ≤ √3‖S‖_F) so that every eigenvalue
    # is ≥ 0 and the largest one dominates the powers.
    shift = jnp.sqrt(3.0 * jnp.sum(s * s, axis=(0, 1)))
    a = jnp.stack([jnp.stack(row) for row in n]) + shift * jnp.eye(4, dtype=s.dtype)[..., None]
    a = a / jnp.maximum(a[0, 0] + a[1, 1] + a[2, 2] + a[3, 3], 1e-300)

    def square(a, _):
        a2 = sum(a[:, k : k + 1, :] * a[k : k + 1, :, :] for k in range(4))
        return a2 / jnp.maximum(a2[0, 0] + a2[1, 1] + a2[2, 2] + a2[3, 3], 1e-300), None

    a, _ = jax.lax.scan(square, a, None, length=QUATERNION_SQUARINGS)
    # a ≈ v vᵀ: its column with the largest diagonal entry is the best-conditioned copy of v.
    diag = jnp.stack([a[i, i] for i in range(4)])
    col = jnp.argmax(diag, axis=0)
    v = jnp.take_along_axis(a, col[None, None, :], axis=1)[:, 0, :]
    v = v / jnp.sqrt(jnp.sum(v * v, axis=0))
    w, x, y, z = v
    r = jnp.stack(
        [
            jnp.stack([w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)]),
            jnp.stack([2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)]),
            jnp.stack([2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z]),
        ]
    )
    return jnp.moveaxis(r, -1, 0).reshape(*batch, 3, 3)


def register_landmarks(
    reference: Float[ArrayLike, "*batch k 3"],
    measured: Float[ArrayLike, "*batch k 3"],
    weights: Float[ArrayLike, "*batch k"] | None = None,
    *,
    method: str = "quaternion",
) -> Registration:
    """Pose of a rigid part from its landmarks: least-squares rotation and translation.

    Minimises Σ_a w_a ‖R P_a + T − Q_a‖² over proper rotations R (det R = +1) and T
    (spec: geometry §3.6, Annex A; stiffness §5 Annex A). See the module docstring for the two
    methods; they agree to rounding.

    **Arguments:**

    - `reference`: landmarks P in the part frame (mm); for diffsusp parts, their global position
      at design. Leading axes are batch axes (e.g. cases × parts).
    - `measured`: the same landmarks, in the same order, measured in the global frame (mm).
    - `weights`: per-landmark weights ≥ 0 (default 1); 0 excludes a landmark (missing or an
      outlier), so batches of parts with different landmark counts keep one shape. At least
      three non-collinear landmarks need a positive weight.
    - `method`: `"quaternion"` (default, fast) or `"svd"` (Arun's SVD with the reflection fix).

    **Returns:** a `Registration` (rotation, translation in mm, rms residual in mm).
    """
    if method not in ("quaternion", "svd"):
        raise ValueError(f"method must be 'quaternion' or 'svd'; got {method!r}.")
    reference = jnp.asarray(reference)
    measured = jnp.asarray(measured)
    dtype = jnp.result_type(reference, measured, float)
    reference, measured = reference.astype(dtype), measured.astype(dtype)
    if reference.shape[-1:] != (3,) or reference.ndim < 2:
        raise ValueError(
            f"reference must have shape (..., k, 3) (k landmarks); got {reference.shape}."
        )
    shape = jnp.broadcast_shapes(reference.shape, measured.shape)
    reference = jnp.broadcast_to(reference, shape)
    measured = jnp.broadcast_to(measured, shape)
    if weights is None:
        weights = jnp.ones(shape[:-1], dtype)
    weights = jnp.broadcast_to(jnp.asarray(weights, dtype), shape[:-1])
    return _register(reference, measured, weights, method)


@functools.partial(jax.jit, static_argnames="method")
def _register(reference, measured, weights, method):
    w, p_bar, q_bar, p, q = _centred(reference, measured, weights)
    h = jnp.einsum("...k,...ki,...kj->...ij", w, q, p)
    rotation = _rotation_quaternion(h) if method == "quaternion" else _rotation_svd(h)
    translation = q_bar - jnp.einsum("...ij,...j->...i", rotation, p_bar)
    residual = jnp.einsum("...ij,...kj->...ki", rotation, reference) + translation[..., None, :]
    residual = residual - measured
    rms = jnp.sqrt(jnp.einsum("...k,...k->...", w, jnp.sum(residual**2, axis=-1)))
    return Registration(rotation, translation, rms)


def landmark_spread(
    points: Float[ArrayLike, "*batch k 3"], weights: Float[ArrayLike, "*batch k"] | None = None
) -> Float[Array, "*batch 3"]:
    """Principal spreads of a landmark set (mm): the singular values of the weighted, centred
    coordinates, largest first. Three non-collinear landmarks have a second spread well above
    zero; coplanar ones a third spread of zero (which registration handles)."""
    points = jnp.asarray(points, dtype=jnp.result_type(points, float))
    if weights is None:
        weights = jnp.ones(points.shape[:-1], points.dtype)
    weights = jnp.asarray(weights, points.dtype)
    total = jnp.sum(weights, axis=-1, keepdims=True)
    centre = jnp.einsum("...k,...ki->...i", weights, points) / jnp.maximum(total, 1e-300)
    centred = (points - centre[..., None, :]) * jnp.sqrt(weights)[..., None]
    return jnp.linalg.svd(centred, compute_uv=False)
