"""Rotation parametrisations: Gibbs (Rodrigues) vectors, rotation vectors, axis-angle,
Adams body-3-1-3 Euler angles (REULER) and Adams projected angles.

Every function acts on ONE rotation (no batch axis; use `jax.vmap` to batch), uses only
`jax.numpy`, and is `jit`/`vmap`/`grad` friendly: there is no Python branching on traced values,
and every `jnp.where` selects between branches whose inputs are themselves made safe, so that
gradients are finite everywhere the represented quantity is differentiable.

Conventions (see `shared/DESIGN.md`):

- Angles are in radians (the `*_deg` helpers exist only for the I/O edge).
- A rotation matrix `R = R_{1/2}` maps components in frame 1 to components in frame 2; its
  columns are the axes of frame 1 expressed in frame 2 (active rotation, right-handed).
- `skew(u) @ v = cross(u, v)`.
"""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

__all__ = [
    "DEG",
    "NEG_LEVI_CIVITA",
    "matrix_to_quaternion",
    "skew",
    "vee",
    "gibbs_to_matrix",
    "matrix_to_gibbs",
    "gibbs_angular_jacobian",
    "gibbs_compose",
    "rotvec_to_matrix",
    "matrix_to_rotvec",
    "axis_angle_to_matrix",
    "matrix_to_axis_angle",
    "reuler_to_matrix",
    "matrix_to_reuler",
    "reuler_deg_to_matrix",
    "matrix_to_reuler_deg",
    "projected_angles",
    "projected_angles_validity",
    "GIBBS_SINGULARITY_TOL",
    "REULER_GIMBAL_LOCK_TOL",
    "PROJECTED_ANGLE_LIMITS",
]

DEG = math.pi / 180.0
"""One degree in radians, the library's one angle conversion: degrees × DEG = radians,
radians / DEG = degrees (display units are degrees, internal units radians)."""

# `matrix_to_gibbs` refuses rotations with 1 + tr R below this (4·cos²(θ/2)), i.e. angles within
# about 1e-6 rad (5.7e-5°) of 180°, where |b| = tan(θ/2) exceeds ~2e6.
GIBBS_SINGULARITY_TOL = 1e-12
# `matrix_to_reuler` treats sin(theta) below this as gimbal lock (theta = 0 or pi).
REULER_GIMBAL_LOCK_TOL = 1e-12
# Validity limits of the projected angles (AX, AY, AZ) as a bushing deformation measure, in rad
# (spec stiffness §0, geometry §2.6: |AX|, |AY| < 15°, |AZ| < 90°).
PROJECTED_ANGLE_LIMITS = (15.0 * DEG, 15.0 * DEG, 90.0 * DEG)

_GIBBS_LIMIT_DEG = 180.0 - 2.0 * math.sqrt(GIBBS_SINGULARITY_TOL / 4.0) / DEG
_GIBBS_SINGULAR_MESSAGE = (
    f"matrix_to_gibbs: rotation of more than {_GIBBS_LIMIT_DEG:.5f}° is too close to 180°, "
    "where Gibbs vectors are singular (|b| = tan(θ/2) -> inf); use rotation vectors "
    "(matrix_to_rotvec) or express the rotation relative to a nearer reference orientation."
)


_NEG_LEVI_CIVITA = np.zeros((3, 3, 3))
for _i, _j, _k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
    _NEG_LEVI_CIVITA[_i, _k, _j] = 1.0  # skew(v)[i, j] = −ε_ijk v_k
    _NEG_LEVI_CIVITA[_i, _j, _k] = -1.0
NEG_LEVI_CIVITA = _NEG_LEVI_CIVITA
"""−ε_ijk arranged so that `NEG_LEVI_CIVITA @ v` is skew(v) (the cross-product matrix); public
for the kernels that build skew matrices by one contraction."""


def _safe_atan2(y: Float[Array, "*s"], x: Float[Array, "*s"]) -> Float[Array, "*s"]:
    """`atan2(y, x)` returning 0 with zero (not NaN) gradient at the undefined point (0, 0)."""
    undefined = (x == 0.0) & (y == 0.0)
    return jnp.arctan2(jnp.where(undefined, 0.0, y), jnp.where(undefined, 1.0, x))


def skew(v: Float[ArrayLike, "3"]) -> Float[Array, "3 3"]:
    """Skew-symmetric (cross-product) matrix of a 3-vector: `skew(u) @ v == cross(u, v)`.

    spec: stiffness §0 (notation `u×`).

    **Arguments:**

    - `v`: 3-vector (any unit; any frame).

    **Returns:**

    The 3x3 matrix `[[0, -v3, v2], [v3, 0, -v1], [-v2, v1, 0]]`, in the same frame as `v`.
    """
    v = jnp.asarray(v)
    # One contraction with the (negated) Levi-Civita tensor: a small traced program.
    return jnp.asarray(_NEG_LEVI_CIVITA, dtype=v.dtype) @ v


def cross(a: Float[ArrayLike, "3"], b: Float[ArrayLike, "3"]) -> Float[Array, "3"]:
    """`a × b` as `skew(a) @ b` (two contractions; a smaller traced program than `jnp.cross`)."""
    return skew(a) @ jnp.asarray(b)


def vee(m: Float[ArrayLike, "3 3"]) -> Float[Array, "3"]:
    """Inverse of `skew`: the 3-vector of the antisymmetric part of a 3x3 matrix.

    `vee(skew(v)) == v`; for a general matrix it returns the vector of `(m - mᵀ)/2`.

    **Arguments:**

    - `m`: 3x3 matrix.

    **Returns:**

    `[m32 - m23, m13 - m31, m21 - m12] / 2` (1-based indices).
    """
    m = jnp.asarray(m)
    return 0.5 * jnp.stack([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])


def matrix_to_quaternion(r: Float[Array, "3 3"]) -> Float[Array, "4"]:
    """Unnormalised quaternion `(w, x, y, z)` of a rotation matrix, Shepperd's method.

    Of the four algebraically equivalent formulas, the one with the largest
    `4w² = 1 + tr R`, `4x² = 1 + 2 R11 − tr R`, ... is used. Near 180° this is the
    symmetric-part (eigen-column) method: the axis comes from the largest column of
    `R + Rᵀ − (tr R − 1) I`, and `w` from the antisymmetric part, both well conditioned.
    For an exact rotation matrix the result is a unit quaternion; in general it is
    proportional to one. Non-selected branches get safe inputs (double `where`) so gradients
    are finite.
    """
    trace = r[0, 0] + r[1, 1] + r[2, 2]
    # 4 q_k² for k = w, x, y, z.
    four_sq = jnp.stack(
        [
            1.0 + trace,
            1.0 + 2.0 * r[0, 0] - trace,
            1.0 + 2.0 * r[1, 1] - trace,
            1.0 + 2.0 * r[2, 2] - trace,
        ]
    )
    pick = jnp.argmax(four_sq)
    # Sums and differences of off-diagonal pairs: 4 q_i q_j.
    wx = r[2, 1] - r[1, 2]
    wy = r[0, 2] - r[2, 0]
    wz = r[1, 0] - r[0, 1]
    xy = r[0, 1] + r[1, 0]
    xz = r[0, 2] + r[2, 0]
    yz = r[1, 2] + r[2, 1]
    rows = jnp.stack(
        [
            jnp.stack([four_sq[0], wx, wy, wz]),
            jnp.stack([wx, four_sq[1], xy, xz]),
            jnp.stack([wy, xy, four_sq[2], yz]),
            jnp.stack([wz, xz, yz, four_sq[3]]),
        ]
    )
    # Row k of `rows` is 4 q_k q; dividing by 2 sqrt(4 q_k²) = 4 |q_k| gives q (up to sign).
    safe_sq = jnp.where(jnp.arange(4) == pick, four_sq, 1.0)
    quats = rows / (2.0 * jnp.sqrt(safe_sq))[:, None]
    return quats[pick]


def gibbs_to_matrix(b: Float[ArrayLike, "3"]) -> Float[Array, "3 3"]:
    """Rotation matrix of a Gibbs (Rodrigues) vector.

    `R = ((1 − b·b) I + 2 b bᵀ + 2 skew(b)) / (1 + b·b)`, with `b = u·tan(θ/2)` for a rotation
    of angle θ (rad) about the unit axis u. spec: stiffness §1.3 eqs. 4.4, 4.6–4.7; geometry §2.3.

    **Arguments:**

    - `b`: Gibbs vector (dimensionless). For a part's generalised coordinates, the rotation from
      the design orientation with u in the global frame.

    **Returns:**

    The 3x3 rotation matrix (columns: rotated axes in the reference frame). Smooth for every
    finite `b`; `|b| -> inf` approaches a 180° rotation.
    """
    b = jnp.asarray(b)
    bb = jnp.dot(b, b)
    eye = jnp.eye(3, dtype=b.dtype)
    return ((1.0 - bb) * eye + 2.0 * jnp.outer(b, b) + 2.0 * skew(b)) / (1.0 + bb)


def matrix_to_gibbs(r: Float[ArrayLike, "3 3"]) -> Float[Array, "3"]:
    """Gibbs (Rodrigues) vector `b = u·tan(θ/2)` of a rotation matrix (inverse of
    `gibbs_to_matrix`).

    Mathematically `b = vee(R − Rᵀ) / (1 + tr R)` (spec: stiffness §1.3 eq. 4.5, standard
    form). It is computed as `b = q_xyz / q_w` from the quaternion by Shepperd's method, which
    keeps full relative accuracy up to angles close to 180°.

    Gibbs vectors are singular at θ = 180°. This function raises a runtime error
    (`eqx.error_if`; an `EquinoxRuntimeError`/`RuntimeError` when called eagerly or under
    `eqx.filter_jit`) when `1 + tr R < GIBBS_SINGULARITY_TOL` (1e-12), i.e. when the angle is
    within ~5.7e-5° of 180°. Below that threshold it returns the (large, accurate) vector.

    **Arguments:**

    - `r`: 3x3 rotation matrix.

    **Returns:**

    The Gibbs vector b (dimensionless), axis in the frame in which `r` is expressed.
    """
    r = jnp.asarray(r)
    trace = r[0, 0] + r[1, 1] + r[2, 2]
    r = eqx.error_if(r, 1.0 + trace < GIBBS_SINGULARITY_TOL, _GIBBS_SINGULAR_MESSAGE)
    q = matrix_to_quaternion(r)
    w = q[0]
    # The error above guarantees w ≠ 0 for valid inputs; keep the division safe regardless.
    w_safe = jnp.where(w == 0.0, 1.0, w)
    return q[1:] / w_safe


def gibbs_angular_jacobian(b: Float[ArrayLike, "3"]) -> Float[Array, "3 3"]:
    """Angular-velocity Jacobian of Gibbs vectors, in the reference (global) frame.

    `ω = G(b) ḃ` with `G(b) = 2/(1 + b·b) (I + skew(b))`, where `skew(ω) = Ṙ Rᵀ` and
    `R = gibbs_to_matrix(b)`. The body-frame version is `Rᵀ G = 2/(1 + b·b) (I − skew(b))`.
    spec: stiffness §1.4 ("Closed form", eq. 4.9–4.12).

    **Arguments:**

    - `b`: Gibbs vector (dimensionless).

    **Returns:**

    3x3 matrix G (rad per unit of b), rows in the reference frame.
    """
    b = jnp.asarray(b)
    bb = jnp.dot(b, b)
    return 2.0 / (1.0 + bb) * (jnp.eye(3, dtype=b.dtype) + skew(b))


def gibbs_compose(b1: Float[ArrayLike, "3"], b2: Float[ArrayLike, "3"]) -> Float[Array, "3"]:
    """Gibbs vector of the product `gibbs_to_matrix(b1) @ gibbs_to_matrix(b2)`.

    `b = (b1 + b2 + b1 × b2) / (1 − b1·b2)` (from the Hamilton product of the quaternions
    `(1, b1)(1, b2)`; the `+ b1 × b2` sign is for `R(b1) @ R(b2)`, i.e. b2 applied first in the
    frame of b1). spec: stiffness §1.3 (Gibbs vectors, eq. 4.4).

    The composite rotation is 180° when `b1·b2 = 1`; there the result is not finite (this
    function does not check; use rotation matrices or rotation vectors for large rotations).

    **Arguments:**

    - `b1`, `b2`: Gibbs vectors (dimensionless).

    **Returns:**

    The Gibbs vector of the composite rotation.
    """
    b1 = jnp.asarray(b1)
    b2 = jnp.asarray(b2)
    return (b1 + b2 + jnp.cross(b1, b2)) / (1.0 - jnp.dot(b1, b2))


# Taylor branches are used below these squared angles; truncation errors are then < 1e-20.
_ROTVEC_SMALL_SQ = 1e-4
_QUAT_SMALL_SQ = 1e-6


def rotvec_to_matrix(v: Float[ArrayLike, "3"]) -> Float[Array, "3 3"]:
    """Rotation matrix of a rotation vector (Rodrigues' formula).

    `R = I + (sin θ/θ) K + ((1 − cos θ)/θ²) K²`, `K = skew(v)`, `θ = |v|`. A Taylor series is
    used for `θ < 1e-2` rad, so the function and all its derivatives are exact and finite at
    `v = 0` (where the Jacobian of `vee(R)` is the identity).

    **Arguments:**

    - `v`: rotation vector `u·θ` (rad), unit axis u in the reference frame, any θ.

    **Returns:**

    The 3x3 rotation matrix.
    """
    v = jnp.asarray(v)
    t = jnp.dot(v, v)
    small = t < _ROTVEC_SMALL_SQ
    t_safe = jnp.where(small, 1.0, t)
    theta = jnp.sqrt(t_safe)
    half = 0.5 * theta
    # sin θ/θ and (1 − cos θ)/θ² = ½ (sin(θ/2)/(θ/2))², without cancellation.
    a_exact = jnp.sin(theta) / theta
    b_exact = 0.5 * (jnp.sin(half) / half) ** 2
    a_taylor = 1.0 - t / 6.0 * (1.0 - t / 20.0 * (1.0 - t / 42.0))
    b_taylor = 0.5 - t / 24.0 * (1.0 - t / 30.0 * (1.0 - t / 56.0))
    a = jnp.where(small, a_taylor, a_exact)
    b = jnp.where(small, b_taylor, b_exact)
    k = skew(v)
    return jnp.eye(3, dtype=v.dtype) + a * k + b * (k @ k)


def matrix_to_rotvec(r: Float[ArrayLike, "3 3"]) -> Float[Array, "3"]:
    """Rotation vector `u·θ`, θ ∈ [0, π], of a rotation matrix (inverse of `rotvec_to_matrix`).

    Robust for every angle: the quaternion is obtained by Shepperd's method (near 180° this is
    the symmetric-part / eigen-column method), then `θ = 2 atan2(|q_xyz|, q_w)` with `q_w ≥ 0`.
    Near the identity (θ < 2e-3 rad) a Taylor series of `θ/sin(θ/2)` is used, so the function is
    smooth with finite, exact gradients at `R = I`. At exactly 180° the sign of the axis is
    arbitrary (both `±π u` represent the rotation).

    **Arguments:**

    - `r`: 3x3 rotation matrix.

    **Returns:**

    Rotation vector (rad), axis in the frame of `r`, norm in [0, π].
    """
    r = jnp.asarray(r)
    q = matrix_to_quaternion(r)
    q = q / jnp.sqrt(jnp.dot(q, q))
    q = jnp.where(q[0] < 0.0, -q, q)
    w = q[0]
    xyz = q[1:]
    s2 = jnp.dot(xyz, xyz)
    small = s2 < _QUAT_SMALL_SQ
    s = jnp.sqrt(jnp.where(small, 1.0, s2))
    # θ/|q_xyz| = 2 atan2(s, w)/s; near s = 0 (w ≈ 1): (2/w)(1 − r²/3 + r⁴/5 − r⁶/7), r = s/w.
    w_safe = jnp.where(small, w, 1.0)
    ratio2 = jnp.where(small, s2, 0.0) / (w_safe * w_safe)
    factor_taylor = 2.0 / w_safe * (1.0 - ratio2 * (1.0 / 3.0 - ratio2 * (0.2 - ratio2 / 7.0)))
    factor_exact = 2.0 * jnp.arctan2(s, w) / s
    return jnp.where(small, factor_taylor, factor_exact) * xyz


def axis_angle_to_matrix(
    axis: Float[ArrayLike, "3"], angle: Float[ArrayLike, ""]
) -> Float[Array, "3 3"]:
    """Rotation matrix of a rotation by `angle` about `axis`.

    **Arguments:**

    - `axis`: rotation axis (any non-zero length; it is normalised), in the reference frame.
      A zero axis raises a runtime error (`eqx.error_if`).
    - `angle`: rotation angle (rad), right-hand rule about `axis`.

    **Returns:**

    The 3x3 rotation matrix `rotvec_to_matrix(angle · axis/|axis|)`.
    """
    axis = jnp.asarray(axis)
    angle = jnp.asarray(angle, dtype=axis.dtype)
    n2 = jnp.dot(axis, axis)
    axis = eqx.error_if(
        axis, n2 == 0.0, "axis_angle_to_matrix: `axis` has zero length; give a non-zero axis."
    )
    unit = axis / jnp.sqrt(jnp.where(n2 == 0.0, 1.0, n2))
    return rotvec_to_matrix(angle * unit)


def matrix_to_axis_angle(
    r: Float[ArrayLike, "3 3"],
) -> tuple[Float[Array, "3"], Float[Array, ""]]:
    """Unit axis and angle θ ∈ [0, π] of a rotation matrix.

    Computed from the quaternion (Shepperd's method), robust for every angle. At the identity
    the axis is undefined and `(0, 0, 1)` is returned; at exactly 180° its sign is arbitrary.

    **Arguments:**

    - `r`: 3x3 rotation matrix.

    **Returns:**

    `(axis, angle)`: unit axis in the frame of `r`, and the angle in rad.
    """
    r = jnp.asarray(r)
    q = matrix_to_quaternion(r)
    q = q / jnp.sqrt(jnp.dot(q, q))
    q = jnp.where(q[0] < 0.0, -q, q)
    xyz = q[1:]
    s2 = jnp.dot(xyz, xyz)
    zero = s2 == 0.0
    s = jnp.sqrt(jnp.where(zero, 1.0, s2))
    angle = 2.0 * jnp.arctan2(jnp.where(zero, 0.0, s), q[0])
    axis = jnp.where(zero, jnp.array([0.0, 0.0, 1.0], dtype=r.dtype), xyz / s)
    return axis, angle


def _rot_z(a: Float[Array, ""]) -> Float[Array, "3 3"]:
    c, s = jnp.cos(a), jnp.sin(a)
    zero, one = jnp.zeros_like(a), jnp.ones_like(a)
    return jnp.stack(
        [jnp.stack([c, -s, zero]), jnp.stack([s, c, zero]), jnp.stack([zero, zero, one])]
    )


def _rot_x(a: Float[Array, ""]) -> Float[Array, "3 3"]:
    c, s = jnp.cos(a), jnp.sin(a)
    zero, one = jnp.zeros_like(a), jnp.ones_like(a)
    return jnp.stack(
        [jnp.stack([one, zero, zero]), jnp.stack([zero, c, -s]), jnp.stack([zero, s, c])]
    )


def reuler_to_matrix(angles: Float[ArrayLike, "3"]) -> Float[Array, "3 3"]:
    """Rotation matrix of Adams body-3-1-3 Euler angles (REULER, "z-x-z") `(psi, theta, phi)`.

    `R = Rz(psi) @ Rx(theta) @ Rz(phi)`: the columns of R are the marker's axes expressed in
    the parent (part or global) frame. spec: geometry §2.2 eq. 2.7; stiffness §0.

    **Arguments:**

    - `angles`: `(psi, theta, phi)` in rad.

    **Returns:**

    The 3x3 rotation matrix `R_{marker/parent}`.
    """
    angles = jnp.asarray(angles)
    return _rot_z(angles[0]) @ _rot_x(angles[1]) @ _rot_z(angles[2])


def matrix_to_reuler(r: Float[ArrayLike, "3 3"]) -> Float[Array, "3"]:
    """Adams body-3-1-3 Euler angles `(psi, theta, phi)` of a rotation matrix (inverse of
    `reuler_to_matrix`).

    Mathematically (1-based indices) `theta = atan2(sqrt(R13² + R23²), R33)`,
    `psi = atan2(R13, −R23)`, `phi = atan2(R31, R32)` (spec: geometry §2.2). To reproduce R
    to rounding error even close to gimbal lock, phi is computed from the first row of
    `Rz(psi)ᵀ R = Rx(theta) Rz(phi)`, i.e. `phi = atan2(−M12, M11)`, which is well conditioned
    and compensates any error in psi.

    Ranges: `theta ∈ [0, π]`, `psi, phi ∈ (−π, π]`.

    Gimbal lock: when `sqrt(R13² + R23²) < REULER_GIMBAL_LOCK_TOL` (1e-12), theta is set to
    exactly 0 or π, `phi = 0`, and the whole rotation about z goes into
    `psi = atan2(R21, R11)` (valid for both theta = 0 and theta = π). Gradients there are zero
    (the decomposition is not differentiable at gimbal lock), never NaN.

    **Arguments:**

    - `r`: 3x3 rotation matrix, columns = marker axes in the parent frame.

    **Returns:**

    `(psi, theta, phi)` in rad.
    """
    r = jnp.asarray(r)
    n2 = r[0, 2] ** 2 + r[1, 2] ** 2
    lock = n2 < REULER_GIMBAL_LOCK_TOL**2
    # The selected pair is never (0, 0): |(R21, R11)| ≈ 1 in lock, |(R13, R23)| ≥ tol otherwise.
    psi = jnp.arctan2(jnp.where(lock, r[1, 0], r[0, 2]), jnp.where(lock, r[0, 0], -r[1, 2]))
    c, s = jnp.cos(psi), jnp.sin(psi)
    # First row of Rz(psi)ᵀ R, = (cos phi, −sin phi, 0).
    m11 = c * r[0, 0] + s * r[1, 0]
    m12 = c * r[0, 1] + s * r[1, 1]
    phi = jnp.where(lock, 0.0, _safe_atan2(-m12, m11))
    theta_free = jnp.arctan2(jnp.sqrt(jnp.where(lock, 1.0, n2)), r[2, 2])
    theta_lock = jnp.where(r[2, 2] >= 0.0, 0.0, jnp.pi)
    theta = jnp.where(lock, theta_lock, theta_free)
    return jnp.stack([psi, theta, phi])


def reuler_deg_to_matrix(angles_deg: Float[ArrayLike, "3"]) -> Float[Array, "3 3"]:
    """`reuler_to_matrix` with `(psi, theta, phi)` in degrees (I/O edge: Adams files, thesis
    Table 2.2). spec: geometry §2.2.

    **Arguments:**

    - `angles_deg`: `(psi, theta, phi)` in degrees.

    **Returns:**

    The 3x3 rotation matrix (columns = marker axes in the parent frame).
    """
    return reuler_to_matrix(jnp.deg2rad(jnp.asarray(angles_deg)))


def matrix_to_reuler_deg(r: Float[ArrayLike, "3 3"]) -> Float[Array, "3"]:
    """`matrix_to_reuler` returning degrees: `theta ∈ [0, 180]`, `psi, phi ∈ (−180, 180]`.

    **Arguments:**

    - `r`: 3x3 rotation matrix.

    **Returns:**

    `(psi, theta, phi)` in degrees.
    """
    return jnp.rad2deg(matrix_to_reuler(r))


def projected_angles(r: Float[ArrayLike, "3 3"]) -> Float[Array, "3"]:
    """Adams projected angles `(AX, AY, AZ)` of a relative rotation `R = R_{I/J}`.

    With R's columns the I-marker axes expressed in the J-marker frame (0-based indices):
    `AX = atan2(−R[1,2], R[2,2])`, `AY = atan2(R[0,2], R[2,2])`, `AZ = atan2(R[1,0], R[0,0])`,
    i.e. `atan2(−z_i·y_j, z_i·z_j)`, `atan2(z_i·x_j, z_i·z_j)`, `atan2(x_i·y_j, x_i·x_j)`.
    They are the rotational deformation of a bushing; valid only for |AX|, |AY| < 15° and
    |AZ| < 90° (see `projected_angles_validity`). spec: stiffness §0; geometry §2.6 eq. 2.29.

    **Arguments:**

    - `r`: 3x3 rotation `R_{I/J}`.

    **Returns:**

    `(AX, AY, AZ)` in rad, each in (−π, π] (0 with zero gradient if undefined).
    """
    r = jnp.asarray(r)
    y = r[jnp.array([1, 0, 1]), jnp.array([2, 2, 0])] * jnp.array([-1.0, 1.0, 1.0], r.dtype)
    x = r[jnp.array([2, 2, 0]), jnp.array([2, 2, 0])]
    return _safe_atan2(y, x)


def projected_angles_validity(angles: Float[ArrayLike, "3"]) -> Float[Array, "3"]:
    """Ratio of projected angles to their validity limits (15°, 15°, 90°).

    A value ≥ 1 means the projected angle no longer represents the deformation (spec:
    stiffness §0, geometry §2.6); Adams already warns at about 10° (ratio 2/3). Meant for
    warnings upstream.

    **Arguments:**

    - `angles`: `(AX, AY, AZ)` in rad, as from `projected_angles`.

    **Returns:**

    `(|AX|/15°, |AY|/15°, |AZ|/90°)`, dimensionless.
    """
    angles = jnp.asarray(angles)
    return jnp.abs(angles) / jnp.asarray(PROJECTED_ANGLE_LIMITS, dtype=angles.dtype)
