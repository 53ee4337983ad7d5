"""Rigid poses (rotation + translation) and homogeneous operators.

A pose of frame a in frame b, `A_{a/b}`, is the pair `(R, T)`: `R = R_{a/b}` has the axes of a
as columns, expressed in b; `T = T_{a/b}` is the origin of a expressed in b (mm). It maps
coordinates in a to coordinates in b: `x_b = R x_a + T`. Internally the ordinary 4x4 layout
`[[R, T], [0, 1]]` acting on `[x, y, z, 1]` is used. The thesis writes the homogeneous
coordinate FIRST, `[[1, 0], [T, R]]` acting on `[1, x, y, z]` (spec: geometry §2.1,
stiffness §0); `to_thesis_operator`/`from_thesis_operator` convert at the I/O edge only.

Every function acts on ONE pose (no batch axis; use `jax.vmap`), and is jit/vmap/grad
friendly.
"""

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

__all__ = [
    "homogeneous",
    "split_homogeneous",
    "invert_pose",
    "compose_poses",
    "relative_pose",
    "transform_points",
    "to_thesis_operator",
    "from_thesis_operator",
]

Pose = tuple[Float[Array, "3 3"], Float[Array, "3"]]
PoseLike = tuple[Float[ArrayLike, "3 3"], Float[ArrayLike, "3"]]


def homogeneous(r: Float[ArrayLike, "3 3"], t: Float[ArrayLike, "3"]) -> Float[Array, "4 4"]:
    """Ordinary 4x4 homogeneous matrix `[[R, T], [0, 0, 0, 1]]` of a pose.

    **Arguments:**

    - `r`: rotation `R_{a/b}` (columns: axes of a in b).
    - `t`: translation `T_{a/b}` (mm): origin of a in b.

    **Returns:**

    The 4x4 matrix mapping `[x_a, 1]` to `[x_b, 1]`.
    """
    r = jnp.asarray(r)
    t = jnp.asarray(t, dtype=r.dtype)
    bottom = jnp.zeros((1, 4), dtype=r.dtype).at[0, 3].set(1.0)
    return jnp.concatenate([jnp.concatenate([r, t[:, None]], axis=1), bottom], axis=0)


def split_homogeneous(a: Float[ArrayLike, "4 4"]) -> Pose:
    """Rotation and translation of an ordinary 4x4 homogeneous matrix `[[R, T], [0, 1]]`.

    **Arguments:**

    - `a`: 4x4 homogeneous matrix (the bottom row is not checked).

    **Returns:**

    `(R, T)`: 3x3 rotation and translation (mm).
    """
    a = jnp.asarray(a)
    return a[:3, :3], a[:3, 3]


def invert_pose(r: Float[ArrayLike, "3 3"], t: Float[ArrayLike, "3"]) -> Pose:
    """Inverse of a pose: `A_{b/a}` from `A_{a/b}`, i.e. `(Rᵀ, −Rᵀ T)`.

    spec: geometry §2.1 (`A⁻¹ = [[1, 0], [−RᵀT, Rᵀ]]` in the thesis layout).

    **Arguments:**

    - `r`: rotation `R_{a/b}` (must be orthonormal; its transpose is used as inverse).
    - `t`: translation `T_{a/b}` (mm).

    **Returns:**

    `(R_{b/a}, T_{b/a})`.
    """
    r = jnp.asarray(r)
    t = jnp.asarray(t, dtype=r.dtype)
    return r.T, -(r.T @ t)


def compose_poses(pose1: PoseLike, pose2: PoseLike) -> Pose:
    """Composition of two poses, read right to left like the matrix product `A1 @ A2`.

    With `pose1 = A_{b/c}` and `pose2 = A_{a/b}`, returns `A_{a/c} = (R1 R2, R1 T2 + T1)`.
    spec: geometry §2.1 (`[A_Ri/Rg] = [A_Rs/Rg][A_Ri/Rs]`).

    **Arguments:**

    - `pose1`: `(R1, T1)`, pose of b in c (T in mm).
    - `pose2`: `(R2, T2)`, pose of a in b (T in mm).

    **Returns:**

    `(R, T)`, pose of a in c.
    """
    r1, t1 = jnp.asarray(pose1[0]), jnp.asarray(pose1[1])
    r2, t2 = jnp.asarray(pose2[0]), jnp.asarray(pose2[1])
    return r1 @ r2, r1 @ t2 + t1


def relative_pose(
    r_a: Float[ArrayLike, "3 3"],
    t_a: Float[ArrayLike, "3"],
    r_b: Float[ArrayLike, "3 3"],
    t_b: Float[ArrayLike, "3"],
) -> Pose:
    """Pose of frame a expressed in frame b, both given in a common frame g.

    `A_{a/b} = A_{b/g}⁻¹ A_{a/g}`: `R = R_bᵀ R_a`, `T = R_bᵀ (T_a − T_b)`. For a bushing
    (a = I marker, b = J marker) this is the deformation operator `A_{Ri/Rj}`: T is the
    translational deformation and `projected_angles(R)` the rotational one. spec: geometry §2.6
    eq. 2.28; stiffness §0.

    **Arguments:**

    - `r_a`, `t_a`: pose of a in g (rotation; translation in mm).
    - `r_b`, `t_b`: pose of b in g (rotation; translation in mm).

    **Returns:**

    `(R_{a/b}, T_{a/b})`, translation in mm, components in b.
    """
    r_a = jnp.asarray(r_a)
    r_b = jnp.asarray(r_b)
    t_a = jnp.asarray(t_a, dtype=r_a.dtype)
    t_b = jnp.asarray(t_b, dtype=r_b.dtype)
    return r_b.T @ r_a, r_b.T @ (t_a - t_b)


def transform_points(
    r: Float[ArrayLike, "3 3"], t: Float[ArrayLike, "3"], points: Float[ArrayLike, "*batch 3"]
) -> Float[Array, "*batch 3"]:
    """Map points from frame a to frame b with the pose `A_{a/b}`: `x_b = R x_a + T`.

    **Arguments:**

    - `r`: rotation `R_{a/b}`.
    - `t`: translation `T_{a/b}` (mm).
    - `points`: array of shape `(..., 3)`, coordinates in a (mm).

    **Returns:**

    Array of the same shape, coordinates in b (mm).
    """
    r = jnp.asarray(r)
    t = jnp.asarray(t, dtype=r.dtype)
    points = jnp.asarray(points)
    return points @ r.T + t


def to_thesis_operator(
    r: Float[ArrayLike, "3 3"], t: Float[ArrayLike, "3"]
) -> Float[Array, "4 4"]:
    """Thesis-layout homogeneous operator `[[1, 0, 0, 0], [T, R]]` (homogeneous coordinate
    FIRST; it maps `[1, x_a, y_a, z_a]` to `[1, x_b, y_b, z_b]`). For I/O with thesis tables
    and MATLAB code (`Operateur = [1 0 0 0; Translation, Rotation]`). spec: geometry §2.1;
    stiffness §0.

    **Arguments:**

    - `r`: rotation `R_{a/b}`.
    - `t`: translation `T_{a/b}` (mm).

    **Returns:**

    The 4x4 thesis operator `A_{a/b}`.
    """
    r = jnp.asarray(r)
    t = jnp.asarray(t, dtype=r.dtype)
    top = jnp.zeros((1, 4), dtype=r.dtype).at[0, 0].set(1.0)
    return jnp.concatenate([top, jnp.concatenate([t[:, None], r], axis=1)], axis=0)


def from_thesis_operator(a: Float[ArrayLike, "4 4"]) -> Pose:
    """Rotation and translation of a thesis-layout operator `[[1, 0], [T, R]]`.

    spec: geometry §2.1 (MATLAB: translation `A(2:4,1)`, rotation `A(2:4,2:4)`).

    **Arguments:**

    - `a`: 4x4 thesis operator (the first row is not checked).

    **Returns:**

    `(R, T)`: 3x3 rotation and translation (mm).
    """
    a = jnp.asarray(a)
    return a[1:, 1:], a[1:, 0]
