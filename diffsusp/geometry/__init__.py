"""Geometry: rotation parametrisations (Gibbs vectors, rotation vectors, axis-angle, Adams
REULER z-x-z Euler angles, projected angles), rigid poses, and primitives fitted to probed
points with their covariances (`fit`: sphere, line, plane, line–plane intersection, bushing
frame).

Units: mm and rad (degree helpers only at the I/O edge). Every function acts on one input;
batch with `jax.vmap`. See `rotations` and `poses` for conventions.
"""

from .fit import (
    BushingFrame,
    LineFit,
    PlaneFit,
    SphereFit,
    bushing_frame,
    fit_line,
    fit_plane,
    fit_sphere,
    intersect_line_plane,
)
from .poses import (
    compose_poses,
    from_thesis_operator,
    homogeneous,
    invert_pose,
    relative_pose,
    split_homogeneous,
    to_thesis_operator,
    transform_points,
)
from .rotations import (
    DEG,
    GIBBS_SINGULARITY_TOL,
    PROJECTED_ANGLE_LIMITS,
    REULER_GIMBAL_LOCK_TOL,
    axis_angle_to_matrix,
    gibbs_angular_jacobian,
    gibbs_compose,
    gibbs_to_matrix,
    matrix_to_axis_angle,
    matrix_to_gibbs,
    matrix_to_reuler,
    matrix_to_reuler_deg,
    matrix_to_rotvec,
    projected_angles,
    projected_angles_validity,
    reuler_deg_to_matrix,
    reuler_to_matrix,
    rotvec_to_matrix,
    skew,
    vee,
)

__all__ = [
    "BushingFrame", "DEG", "GIBBS_SINGULARITY_TOL", "LineFit", "PROJECTED_ANGLE_LIMITS",
    "PlaneFit", "REULER_GIMBAL_LOCK_TOL", "SphereFit", "axis_angle_to_matrix", "bushing_frame",
    "compose_poses", "fit_line", "fit_plane", "fit_sphere", "from_thesis_operator",
    "gibbs_angular_jacobian", "gibbs_compose", "gibbs_to_matrix", "homogeneous",
    "intersect_line_plane", "invert_pose", "matrix_to_axis_angle", "matrix_to_gibbs",
    "matrix_to_reuler", "matrix_to_reuler_deg", "matrix_to_rotvec", "projected_angles",
    "projected_angles_validity", "relative_pose", "reuler_deg_to_matrix", "reuler_to_matrix",
    "rotvec_to_matrix", "skew", "split_homogeneous", "to_thesis_operator", "transform_points",
    "vee",
]
