"""Tests of diffsusp.geometry: rotations (Gibbs, rotation vectors, axis-angle, REULER,
projected angles) and poses. Oracles: closed forms, scipy's Rotation, the thesis Table 2.2
digest check, and finite differences."""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from jaxtyping import Array, Float
from scipy.spatial.transform import Rotation

from diffsusp import geometry as g

PROPERTY = settings(max_examples=50, deadline=None)

# jit once at module level: hypothesis loops call these many times.
skew = jax.jit(g.skew)
vee = jax.jit(g.vee)
gibbs_to_matrix = jax.jit(g.gibbs_to_matrix)
matrix_to_gibbs = jax.jit(g.matrix_to_gibbs)
gibbs_angular_jacobian = jax.jit(g.gibbs_angular_jacobian)
gibbs_compose = jax.jit(g.gibbs_compose)
rotvec_to_matrix = jax.jit(g.rotvec_to_matrix)
matrix_to_rotvec = jax.jit(g.matrix_to_rotvec)
axis_angle_to_matrix = jax.jit(g.axis_angle_to_matrix)
matrix_to_axis_angle = jax.jit(g.matrix_to_axis_angle)
reuler_to_matrix = jax.jit(g.reuler_to_matrix)
matrix_to_reuler = jax.jit(g.matrix_to_reuler)
projected_angles = jax.jit(g.projected_angles)

DEG = np.pi / 180.0

# XLA flushes subnormal numbers to zero: keep them out of the generated inputs.
floats = functools.partial(st.floats, allow_subnormal=False)
unit_component = floats(-1.0, 1.0, allow_nan=False)
raw_vector = st.tuples(unit_component, unit_component, unit_component)


@st.composite
def unit_vectors(draw):
    v = np.array(draw(raw_vector))
    n = np.linalg.norm(v)
    assume(n > 0.1)
    return v / n


@st.composite
def rotation_matrices(draw):
    """Rotations from random quaternions, including angles near and at 180° (w ≈ 0)."""
    w = draw(st.one_of(floats(-1.0, 1.0), st.sampled_from([0.0, 1e-12, 1e-9, 1e-5])))
    xyz = draw(raw_vector)
    q = np.array([*xyz, w])
    n = np.linalg.norm(q)
    assume(n > 0.1)
    return Rotation.from_quat(q / n).as_matrix()  # scipy quaternion order: (x, y, z, w)


def assert_rotation(r, atol=1e-13):
    r = np.asarray(r)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=atol)
    assert abs(np.linalg.det(r) - 1.0) < atol


def rot_x(a):
    return Rotation.from_rotvec([a, 0.0, 0.0]).as_matrix()


def rot_y(a):
    return Rotation.from_rotvec([0.0, a, 0.0]).as_matrix()


def rot_z(a):
    return Rotation.from_rotvec([0.0, 0.0, a]).as_matrix()


# ---------------------------------------------------------------------------------------------
# skew / vee


@PROPERTY
@given(raw_vector, raw_vector)
def test_skew_is_cross_product(u, v):
    u, v = np.array(u), np.array(v)
    np.testing.assert_allclose(skew(u) @ v, np.cross(u, v), atol=1e-15)
    np.testing.assert_allclose(vee(skew(u)), u, atol=0.0)
    np.testing.assert_allclose(skew(u), -skew(u).T, atol=0.0)


# ---------------------------------------------------------------------------------------------
# Gibbs vectors


@PROPERTY
@given(unit_vectors(), floats(-179.0, 179.0))
def test_gibbs_round_trip_and_oracle(axis, angle_deg):
    theta = angle_deg * DEG
    b = axis * np.tan(theta / 2.0)
    r = gibbs_to_matrix(b)
    assert_rotation(r)
    np.testing.assert_allclose(r, Rotation.from_rotvec(axis * theta).as_matrix(), atol=1e-13)
    b_back = matrix_to_gibbs(r)
    np.testing.assert_allclose(b_back, b, rtol=0.0, atol=1e-12 * max(1.0, np.linalg.norm(b)))


@PROPERTY
@given(rotation_matrices())
def test_matrix_gibbs_matrix_round_trip(r):
    assume(1.0 + np.trace(r) > 1e-6)  # beyond ~179.9°, see the error test below
    np.testing.assert_allclose(gibbs_to_matrix(matrix_to_gibbs(r)), r, atol=1e-12)


def test_gibbs_closed_form_spec_eq_4_7():
    b1, b2, b3 = 0.3, -0.2, 0.5
    delta = 1 + b1**2 + b2**2 + b3**2
    expected = np.array(
        [
            [1 + b1**2 - b2**2 - b3**2, 2 * (b1 * b2 - b3), 2 * (b1 * b3 + b2)],
            [2 * (b1 * b2 + b3), 1 - b1**2 + b2**2 - b3**2, 2 * (b2 * b3 - b1)],
            [2 * (b1 * b3 - b2), 2 * (b2 * b3 + b1), 1 - b1**2 - b2**2 + b3**2],
        ]
    ) / delta
    np.testing.assert_allclose(gibbs_to_matrix(np.array([b1, b2, b3])), expected, atol=1e-15)
    # b = u tan(θ/2): 90° about z.
    np.testing.assert_allclose(gibbs_to_matrix(np.array([0.0, 0.0, 1.0])), rot_z(np.pi / 2),
                               atol=1e-15)


@pytest.mark.parametrize("offset", [0.0, 1e-9, 1e-7])
def test_matrix_to_gibbs_raises_near_180_degrees(offset):
    axis = np.array([1.0, 2.0, -2.0]) / 3.0
    r = Rotation.from_rotvec(axis * (np.pi - offset)).as_matrix()
    message = "too close to 180°.*Gibbs vectors are singular.*rotation vectors"
    with pytest.raises(RuntimeError, match=message):
        g.matrix_to_gibbs(r)
    with pytest.raises(RuntimeError, match=message):
        eqx.filter_jit(g.matrix_to_gibbs)(r)
    with pytest.raises(RuntimeError, match=message):
        eqx.filter_jit(jax.vmap(g.matrix_to_gibbs))(np.stack([np.eye(3), r]))


def test_matrix_to_gibbs_accurate_just_inside_the_limit():
    axis = np.array([1.0, 2.0, -2.0]) / 3.0
    theta = np.pi - 1e-5  # |b| = tan(θ/2) ≈ 2e5
    b = axis * np.tan(theta / 2.0)
    r = Rotation.from_rotvec(axis * theta).as_matrix()
    np.testing.assert_allclose(g.matrix_to_gibbs(r), b, rtol=1e-9)


@PROPERTY
@given(st.tuples(*[floats(-3.0, 3.0)] * 3), raw_vector)
def test_gibbs_angular_jacobian_vs_finite_differences(b, bdot):
    b, bdot = np.array(b), np.array(bdot)
    assume(np.linalg.norm(bdot) > 0.1)
    h = 1e-6
    r = np.asarray(gibbs_to_matrix(b))
    r_dot = (np.asarray(gibbs_to_matrix(b + h * bdot)) - np.asarray(gibbs_to_matrix(b - h * bdot)))
    r_dot /= 2.0 * h
    omega_cross = r_dot @ r.T
    np.testing.assert_allclose(omega_cross, -omega_cross.T, atol=1e-8)  # skew, to FD accuracy
    omega_fd = np.asarray(vee(omega_cross))
    omega = np.asarray(gibbs_angular_jacobian(b)) @ bdot
    np.testing.assert_allclose(omega, omega_fd, rtol=0.0, atol=1e-7 * np.linalg.norm(omega))
    # Body-frame form quoted in spec stiffness §1.4: Rᵀ G = 2/Δ (I − b×).
    body = r.T @ np.asarray(gibbs_angular_jacobian(b))
    np.testing.assert_allclose(body, 2.0 / (1.0 + b @ b) * (np.eye(3) - skew(b)), atol=1e-14)


@PROPERTY
@given(unit_vectors(), floats(-120.0, 120.0), unit_vectors(), floats(-120.0, 120.0))
def test_gibbs_compose_matches_matrix_product(axis1, deg1, axis2, deg2):
    b1 = axis1 * np.tan(deg1 * DEG / 2.0)
    b2 = axis2 * np.tan(deg2 * DEG / 2.0)
    assume(abs(1.0 - b1 @ b2) > 1e-2)  # composite rotation not near 180°
    product = np.asarray(gibbs_to_matrix(b1)) @ np.asarray(gibbs_to_matrix(b2))
    b = gibbs_compose(b1, b2)
    np.testing.assert_allclose(gibbs_to_matrix(b), product, atol=1e-12)
    np.testing.assert_allclose(b, matrix_to_gibbs(product), atol=1e-10 * max(1, np.linalg.norm(b)))


def test_gibbs_compose_sign_of_cross_term():
    b1, b2 = np.array([0.3, 0.0, 0.0]), np.array([0.0, 0.4, 0.0])
    product = np.asarray(gibbs_to_matrix(b1)) @ np.asarray(gibbs_to_matrix(b2))
    plus = (b1 + b2 + np.cross(b1, b2)) / (1.0 - b1 @ b2)
    minus = (b1 + b2 - np.cross(b1, b2)) / (1.0 - b1 @ b2)
    np.testing.assert_allclose(matrix_to_gibbs(product), plus, atol=1e-15)
    assert not np.allclose(plus, minus)
    np.testing.assert_allclose(gibbs_compose(b1, b2), plus, atol=1e-15)


# ---------------------------------------------------------------------------------------------
# Rotation vectors and axis-angle


@PROPERTY
@given(unit_vectors(), st.one_of(floats(0.0, np.pi - 1e-9), st.sampled_from(
    [0.0, 1e-300, 1e-12, 1e-8, 9.9e-3, 1.01e-2, 1.9e-3, 2.1e-3, np.pi - 1e-6, np.pi - 1e-9])))
def test_rotvec_round_trip(axis, angle):
    v = axis * angle
    r = rotvec_to_matrix(v)
    assert_rotation(r)
    np.testing.assert_allclose(r, Rotation.from_rotvec(v).as_matrix(), atol=1e-14)
    np.testing.assert_allclose(matrix_to_rotvec(r), v, rtol=0.0, atol=1e-12)


@PROPERTY
@given(unit_vectors())
def test_rotvec_exactly_180_degrees(axis):
    v = axis * np.pi
    r = rotvec_to_matrix(v)
    assert_rotation(r)
    back = np.asarray(matrix_to_rotvec(r))
    # At exactly π both ±π·u are valid; the matrix must be reproduced exactly.
    assert min(np.abs(back - v).max(), np.abs(back + v).max()) < 1e-12
    np.testing.assert_allclose(rotvec_to_matrix(back), r, atol=1e-13)


@pytest.mark.parametrize(
    "r",
    [np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0]),
     2.0 * np.outer([0.6, 0.0, 0.8], [0.6, 0.0, 0.8]) - np.eye(3)],
)
def test_matrix_to_rotvec_exact_half_turns(r):
    v = np.asarray(matrix_to_rotvec(r))
    assert abs(np.linalg.norm(v) - np.pi) < 1e-15
    np.testing.assert_allclose(rotvec_to_matrix(v), r, atol=1e-15)
    assert np.all(np.isfinite(jax.jacobian(g.matrix_to_rotvec)(jnp.asarray(r))))


@PROPERTY
@given(rotation_matrices())
def test_matrix_rotvec_matrix_round_trip(r):
    v = np.asarray(matrix_to_rotvec(r))
    assert np.linalg.norm(v) <= np.pi + 1e-15
    np.testing.assert_allclose(rotvec_to_matrix(v), r, atol=1e-13)


@PROPERTY
@given(raw_vector, floats(0.1, 10.0), floats(1e-6, np.pi - 1e-6))
def test_axis_angle_round_trip(direction, length, angle):
    direction = np.array(direction)
    assume(np.linalg.norm(direction) > 0.1)
    unit = direction / np.linalg.norm(direction)
    r = axis_angle_to_matrix(direction * length, angle)
    assert_rotation(r)
    np.testing.assert_allclose(r, Rotation.from_rotvec(unit * angle).as_matrix(), atol=1e-14)
    axis_back, angle_back = matrix_to_axis_angle(r)
    assert abs(angle_back - angle) < 1e-12
    np.testing.assert_allclose(axis_back, unit, atol=1e-9)  # axis error ~ 1e-16 / sin(θ/2)
    np.testing.assert_allclose(axis_angle_to_matrix(axis_back, angle_back), r, atol=1e-13)


def test_axis_angle_special_cases():
    axis, angle = matrix_to_axis_angle(np.eye(3))
    np.testing.assert_array_equal(axis, [0.0, 0.0, 1.0])
    assert angle == 0.0
    # Negative angle: same rotation as the opposite axis with a positive angle.
    r = axis_angle_to_matrix(np.array([0.0, 1.0, 0.0]), -0.7)
    axis, angle = matrix_to_axis_angle(r)
    np.testing.assert_allclose(axis, [0.0, -1.0, 0.0], atol=1e-15)
    assert abs(angle - 0.7) < 1e-15
    with pytest.raises(RuntimeError, match="`axis` has zero length"):
        g.axis_angle_to_matrix(np.zeros(3), 0.3)


def test_rotvec_gradients_at_identity():
    # d R / d v_i at v = 0 is skew(e_i) exactly; finite and exact, not NaN.
    jac = jax.jacobian(g.rotvec_to_matrix)(jnp.zeros(3))
    for i in range(3):
        np.testing.assert_allclose(jac[:, :, i], skew(np.eye(3)[i]), atol=1e-15)
    # matrix_to_rotvec at R = I against central finite differences in all 9 entries.
    jac_inv = np.asarray(jax.jacobian(g.matrix_to_rotvec)(jnp.eye(3)))
    h = 1e-6
    fd = np.zeros((3, 3, 3))
    for i in range(3):
        for j in range(3):
            e = np.zeros((3, 3))
            e[i, j] = h
            fd[:, i, j] = (np.asarray(matrix_to_rotvec(np.eye(3) + e))
                           - np.asarray(matrix_to_rotvec(np.eye(3) - e))) / (2 * h)
    np.testing.assert_allclose(jac_inv, fd, atol=1e-9)
    # The expected value: d vee(R − Rᵀ)/2 / dR.
    np.testing.assert_allclose(jac_inv, np.asarray(jax.jacobian(g.vee)(jnp.eye(3))), atol=1e-15)


@pytest.mark.parametrize("scale", [0.0, 1e-7, 5e-3, 9.9e-3, 1.01e-2, 0.3, 2.0, 3.0])
def test_rotvec_gradients_vs_finite_differences(scale):
    v0 = scale * np.array([0.48, -0.6, 0.64])
    jac = np.asarray(jax.jacfwd(g.rotvec_to_matrix)(jnp.asarray(v0)))
    h = 1e-6
    for i in range(3):
        e = np.eye(3)[i] * h
        fd = (np.asarray(rotvec_to_matrix(v0 + e)) - np.asarray(rotvec_to_matrix(v0 - e))) / (2 * h)
        np.testing.assert_allclose(jac[:, :, i], fd, atol=1e-9)
    # The composition matrix_to_rotvec ∘ rotvec_to_matrix is the identity (θ < π).
    comp = jax.jacrev(lambda v: g.matrix_to_rotvec(g.rotvec_to_matrix(v)))(jnp.asarray(v0))
    np.testing.assert_allclose(comp, np.eye(3), atol=1e-12)


# ---------------------------------------------------------------------------------------------
# Adams REULER (body 3-1-3) angles


@pytest.mark.parametrize(
    ("angles_deg", "column", "expected"),
    [
        ((129.5, 90.22, 181.79), 0, (0.636, -0.771, -0.031)),  # L1 bushing B x axis
        ((321.5, 166.7, 53.68), 2, (-0.143, -0.180, -0.973)),  # L4 strut top z axis
        ((-28.84, 168.1, 0.0), 2, (-0.100, -0.181, -0.979)),  # L5 strut base z axis
        ((-0.26, 90.69, 0.0), 2, (-0.0045, -0.9999, -0.012)),  # L9 wheel spin axis
    ],
)
def test_reuler_digest_check_table_2_2(angles_deg, column, expected):
    r = g.reuler_deg_to_matrix(np.array(angles_deg))
    assert_rotation(r)
    np.testing.assert_allclose(r[:, column], expected, atol=6e-4)


def test_reuler_bushing_b_axis_points_to_front_arm_ball_joint():
    # Spec geometry §2.2: bushing B's x axis is the unit vector from L1 to L8.
    l1, l8 = np.array([-294.7, -365.1, 246.1]), np.array([-25.5, -691.2, 233.0])
    x_axis = np.asarray(g.reuler_deg_to_matrix(np.array([129.5, 90.22, 181.79])))[:, 0]
    assert np.degrees(np.arccos(x_axis @ (l8 - l1) / np.linalg.norm(l8 - l1))) < 0.5


@PROPERTY
@given(floats(-np.pi, np.pi), floats(1e-2, np.pi - 1e-2), floats(-np.pi, np.pi))
def test_reuler_round_trip_and_oracle(psi, theta, phi):
    assume(abs(abs(psi) - np.pi) > 1e-9 and abs(abs(phi) - np.pi) > 1e-9)  # ±π wrap
    angles = np.array([psi, theta, phi])
    r = reuler_to_matrix(angles)
    assert_rotation(r)
    oracle = Rotation.from_euler("ZXZ", angles).as_matrix()  # intrinsic z-x'-z''
    np.testing.assert_allclose(r, oracle, atol=1e-14)
    np.testing.assert_allclose(matrix_to_reuler(r), angles, atol=1e-12)


@PROPERTY
@given(
    floats(-np.pi, np.pi),
    st.one_of(
        st.sampled_from([0.0, 1e-300, 1e-14, 1e-13, 2e-12, 1e-10, 1e-8, 1e-4]),
        floats(0.0, np.pi),
    ),
    st.booleans(),
    floats(-np.pi, np.pi),
)
def test_reuler_reproduces_matrix_everywhere_including_gimbal_lock(psi, theta, flip, phi):
    theta = np.pi - theta if flip else theta
    r = np.asarray(reuler_to_matrix(np.array([psi, theta, phi])))
    angles = np.asarray(matrix_to_reuler(r))
    assert 0.0 <= angles[1] <= np.pi
    assert np.all(np.abs(angles[[0, 2]]) <= np.pi)
    np.testing.assert_allclose(reuler_to_matrix(angles), r, atol=1e-12)


@pytest.mark.parametrize("theta", [0.0, np.pi])
def test_reuler_gimbal_lock_puts_rotation_into_psi(theta):
    psi, phi = 0.5, 0.3
    r = g.reuler_to_matrix(np.array([psi, theta, phi]))
    angles = np.asarray(g.matrix_to_reuler(r))
    expected_psi = psi + phi if theta == 0.0 else psi - phi
    np.testing.assert_allclose(angles, [expected_psi, theta, 0.0], atol=1e-15)
    assert angles[2] == 0.0
    np.testing.assert_allclose(g.reuler_to_matrix(angles), r, atol=1e-15)
    jac = jax.jacobian(g.matrix_to_reuler)(r)
    assert np.all(np.isfinite(jac))


def test_reuler_degrees_helpers():
    angles_deg = np.array([129.5, 90.22, -178.21])  # = (129.5, 90.22, 181.79) wrapped
    r = g.reuler_deg_to_matrix(angles_deg)
    np.testing.assert_allclose(g.reuler_deg_to_matrix(np.array([129.5, 90.22, 181.79])), r,
                               atol=1e-15)
    np.testing.assert_allclose(g.matrix_to_reuler_deg(r), angles_deg, atol=1e-11)


def test_reuler_gradient_vs_finite_differences():
    angles = np.array([0.4, 1.1, -2.0])
    r0 = np.asarray(reuler_to_matrix(angles))
    jac = np.asarray(jax.jacobian(g.matrix_to_reuler)(jnp.asarray(r0)))
    h = 1e-6
    for i in range(3):
        for j in range(3):
            e = np.zeros((3, 3))
            e[i, j] = h
            fd = (np.asarray(matrix_to_reuler(r0 + e)) - np.asarray(matrix_to_reuler(r0 - e)))
            np.testing.assert_allclose(jac[:, i, j], fd / (2 * h), atol=1e-8)


# ---------------------------------------------------------------------------------------------
# Projected angles


@pytest.mark.parametrize("a", [-0.2, 0.05, 0.26, 1.2])
def test_projected_angles_single_axis(a):
    np.testing.assert_allclose(projected_angles(rot_x(a)), [a, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(projected_angles(rot_y(a)), [0.0, a, 0.0], atol=1e-15)
    np.testing.assert_allclose(projected_angles(rot_z(a)), [0.0, 0.0, a], atol=1e-15)


@PROPERTY
@given(raw_vector)
def test_projected_angles_first_order_equal_rotation_vector(direction):
    v = 1e-4 * np.array(direction)
    np.testing.assert_allclose(projected_angles(rotvec_to_matrix(v)), v, atol=1e-8)


def test_projected_angles_of_bushing_deformation():
    # I marker rotated by 5° about J's x axis and moved 1 mm along J's y axis.
    r_j = np.asarray(g.reuler_deg_to_matrix(np.array([30.0, 80.0, -10.0])))
    t_j = np.array([10.0, -400.0, 250.0])
    r_i = r_j @ rot_x(5 * DEG)
    t_i = t_j + r_j @ np.array([0.0, 1.0, 0.0])
    r_rel, t_rel = g.relative_pose(r_i, t_i, r_j, t_j)
    np.testing.assert_allclose(t_rel, [0.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(g.projected_angles(r_rel), [5 * DEG, 0.0, 0.0], atol=1e-14)


def test_projected_angles_validity():
    ratio = g.projected_angles_validity(np.array([15.0, -7.5, 45.0]) * DEG)
    np.testing.assert_allclose(ratio, [1.0, 0.5, 0.5], atol=1e-15)


def test_projected_angles_gradient_finite_when_undefined():
    # z_i ⟂ z_j makes AX, AY undefined: value 0 with a finite gradient, never NaN.
    r = rot_x(np.pi / 2) @ rot_y(np.pi / 2)
    r[np.abs(r) < 1e-15] = 0.0
    assert np.all(np.isfinite(jax.jacobian(g.projected_angles)(jnp.asarray(r))))


# ---------------------------------------------------------------------------------------------
# Poses


def random_pose(seed):
    rng = np.random.default_rng(seed)
    return Rotation.random(random_state=rng).as_matrix(), rng.normal(scale=300.0, size=3)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_homogeneous_invert_compose(seed):
    (r1, t1), (r2, t2) = random_pose(seed), random_pose(seed + 100)
    a1, a2 = np.asarray(g.homogeneous(r1, t1)), np.asarray(g.homogeneous(r2, t2))
    np.testing.assert_array_equal(a1[3], [0.0, 0.0, 0.0, 1.0])
    r_back, t_back = g.split_homogeneous(a1)
    np.testing.assert_array_equal(r_back, r1)
    np.testing.assert_array_equal(t_back, t1)
    np.testing.assert_allclose(g.homogeneous(*g.invert_pose(r1, t1)), np.linalg.inv(a1),
                               atol=1e-12)
    np.testing.assert_allclose(g.homogeneous(*g.compose_poses((r1, t1), (r2, t2))), a1 @ a2,
                               atol=1e-12)
    r_id, t_id = g.compose_poses(g.invert_pose(r1, t1), (r1, t1))
    np.testing.assert_allclose(r_id, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(t_id, np.zeros(3), atol=1e-12)
    # relative_pose(a, b) = A_b⁻¹ A_a.
    np.testing.assert_allclose(g.homogeneous(*g.relative_pose(r1, t1, r2, t2)),
                               np.linalg.inv(a2) @ a1, atol=1e-12)


def test_transform_points_batch_shapes():
    r, t = random_pose(3)
    points = np.random.default_rng(4).normal(size=(2, 5, 3))
    out = np.asarray(g.transform_points(r, t, points))
    assert out.shape == (2, 5, 3)
    a = np.asarray(g.homogeneous(r, t))
    expected = (np.concatenate([points, np.ones((2, 5, 1))], axis=-1) @ a.T)[..., :3]
    np.testing.assert_allclose(out, expected, atol=1e-12)
    np.testing.assert_allclose(g.transform_points(r, t, points[0, 0]), expected[0, 0], atol=1e-12)


@pytest.mark.parametrize("seed", [5, 6])
def test_thesis_operator_layout(seed):
    (r1, t1), (r2, t2) = random_pose(seed), random_pose(seed + 100)
    op1, op2 = np.asarray(g.to_thesis_operator(r1, t1)), np.asarray(g.to_thesis_operator(r2, t2))
    np.testing.assert_array_equal(op1[0], [1.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(op1[1:, 0], t1)
    np.testing.assert_array_equal(op1[1:, 1:], r1)
    r_back, t_back = g.from_thesis_operator(op1)
    np.testing.assert_array_equal(r_back, r1)
    np.testing.assert_array_equal(t_back, t1)
    # [1, x] through the thesis operator is [x, 1] through the ordinary one.
    x = np.array([12.0, -40.0, 7.5])
    ordinary = np.asarray(g.homogeneous(r1, t1)) @ np.append(x, 1.0)
    np.testing.assert_allclose(op1 @ np.insert(x, 0, 1.0), np.insert(ordinary[:3], 0, 1.0),
                               atol=1e-12)
    # Composition (right to left) and inverse [[1, 0], [−RᵀT, Rᵀ]] agree with the poses.
    composed = g.compose_poses((r1, t1), (r2, t2))
    np.testing.assert_allclose(op1 @ op2, g.to_thesis_operator(*composed), atol=1e-12)
    inverse = np.zeros((4, 4))
    inverse[0, 0] = 1.0
    inverse[1:, 0] = -r1.T @ t1
    inverse[1:, 1:] = r1.T
    np.testing.assert_allclose(np.linalg.inv(op1), inverse, atol=1e-12)
    np.testing.assert_allclose(g.to_thesis_operator(*g.invert_pose(r1, t1)), inverse, atol=1e-12)


# ---------------------------------------------------------------------------------------------
# jit, vmap, annotations


def _sample_inputs():
    r, t = random_pose(7)
    return {
        "gibbs_to_matrix": (np.array([0.1, -0.4, 0.3]),),
        "matrix_to_gibbs": (r,),
        "rotvec_to_matrix": (np.array([0.1, -0.4, 0.3]),),
        "matrix_to_rotvec": (r,),
        "matrix_to_reuler": (r,),
        "reuler_to_matrix": (np.array([0.3, 1.0, -2.0]),),
        "projected_angles": (r,),
        "gibbs_angular_jacobian": (np.array([0.1, -0.4, 0.3]),),
        "transform_points": (r, t, np.ones((4, 3))),
        "relative_pose": (r, t, r.T, -t),
    }


@pytest.mark.parametrize("name", sorted(_sample_inputs()))
def test_jit_equals_eager(name):
    fn = getattr(g, name)
    args = _sample_inputs()[name]
    eager, jitted = fn(*args), jax.jit(fn)(*args)
    for a, b in zip(jax.tree.leaves(eager), jax.tree.leaves(jitted), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-14, atol=1e-15)


@pytest.mark.parametrize(
    "name", ["matrix_to_rotvec", "matrix_to_reuler", "matrix_to_gibbs", "projected_angles"]
)
def test_vmap_equals_loop_matrices(name):
    fn = getattr(g, name)
    rs = Rotation.random(6, random_state=np.random.default_rng(8)).as_matrix()
    rs[0] = np.eye(3)
    batched = np.asarray(jax.vmap(fn)(rs))
    for k in range(len(rs)):
        np.testing.assert_allclose(batched[k], fn(rs[k]), rtol=1e-14, atol=1e-15)


@pytest.mark.parametrize("name", ["rotvec_to_matrix", "gibbs_to_matrix", "reuler_to_matrix"])
def test_vmap_equals_loop_vectors(name):
    fn = getattr(g, name)
    vs = np.random.default_rng(9).normal(size=(6, 3))
    vs[0] = 0.0
    batched = np.asarray(jax.vmap(fn)(vs))
    for k in range(len(vs)):
        np.testing.assert_allclose(batched[k], fn(vs[k]), rtol=1e-14, atol=1e-15)


def test_outputs_are_float64_with_annotated_shapes():
    r, t = random_pose(10)
    b = np.array([0.1, 0.2, 0.3])
    checks = [
        (g.skew(b), Float[Array, "3 3"]),
        (g.gibbs_to_matrix(b), Float[Array, "3 3"]),
        (g.matrix_to_gibbs(r), Float[Array, "3"]),
        (g.gibbs_compose(b, b), Float[Array, "3"]),
        (g.matrix_to_rotvec(r), Float[Array, "3"]),
        (g.matrix_to_axis_angle(r)[1], Float[Array, ""]),
        (g.matrix_to_reuler_deg(r), Float[Array, "3"]),
        (g.projected_angles_validity(g.projected_angles(r)), Float[Array, "3"]),
        (g.homogeneous(r, t), Float[Array, "4 4"]),
        (g.to_thesis_operator(r, t), Float[Array, "4 4"]),
        (g.invert_pose(r, t)[1], Float[Array, "3"]),
    ]
    for value, annotation in checks:
        assert isinstance(value, annotation)
        assert value.dtype == jnp.float64
