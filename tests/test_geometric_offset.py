"""Offset versus pre-deformed bushing (spec geometry §3.9, eqs. 2.36–2.43): property test on the
isolated bushing with random equilibrium deformations and random other configurations."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from diffsusp.geometry import rotvec_to_matrix
from diffsusp.identify.geometric import offset_equivalent
from diffsusp.models import isolated_bushing
from diffsusp.statics import bushing_states

MECH = isolated_bushing()
STATES = jax.jit(bushing_states)
K = np.asarray(MECH.bushings.k_trans[0])

_vec = st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3).map(np.array)


def _q(trans, rotvec):
    """Public coordinates of the arm: translation and Gibbs vector of a rotation vector."""
    angle = np.linalg.norm(rotvec)
    gibbs = rotvec / angle * np.tan(angle / 2) if angle > 0 else np.zeros(3)
    return jnp.asarray(np.concatenate([trans, gibbs]))


@settings(max_examples=12, deadline=None, derandomize=True)
@given(t_eq=_vec, r_eq=_vec, t_c=_vec, r_c=_vec, move=_vec)
def test_offset_differs_from_predeformed_by_2_42(t_eq, r_eq, t_c, r_c, move):
    # the pre-deformed model: I drawn at a deformation D_eq (up to 3 mm, 5°) from J at design
    d_rot = np.asarray(rotvec_to_matrix(np.radians(5.0) * r_eq))
    j_ori = np.asarray(MECH.markers.orientation[1])
    i_ori = j_ori @ d_rot
    i_pos = j_ori @ (3.0 * t_eq)
    pre = eqx.tree_at(lambda m: (m.markers.position, m.markers.orientation), MECH,
                      (MECH.markers.position.at[0].set(i_pos),
                       MECH.markers.orientation.at[0].set(i_ori)))
    q_ref = _q(2.0 * move, np.radians(3.0) * move)
    off = offset_equivalent(pre, q_ref)
    dt_pre, _, f_pre, tq_pre = (np.asarray(a)[0] for a in STATES(pre, q_ref))
    dt_off, _, f_off, tq_off = (np.asarray(a)[0] for a in STATES(off, q_ref))
    # same force and torque on I at the reference; the offset model is undeformed there
    np.testing.assert_allclose(f_off, f_pre, atol=1e-9)
    np.testing.assert_allclose(tq_off, tq_pre, rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(dt_off, 0.0, atol=1e-10)
    # at another configuration: (2.41) and (2.42)
    q_c = _q(2.0 * t_c, np.radians(4.0) * r_c)
    dt_c, _, f_c, _ = (np.asarray(a)[0] for a in STATES(pre, q_c))
    dt_oc, _, f_oc, _ = (np.asarray(a)[0] for a in STATES(off, q_c))
    r_eq_model = _relative_rotation(pre, q_ref)
    r_c_model = _relative_rotation(pre, q_c)
    expected = dt_c - r_c_model @ r_eq_model.T @ dt_pre  # (2.41)
    np.testing.assert_allclose(dt_oc, expected, atol=1e-9)
    np.testing.assert_allclose(f_c, -K * dt_c, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(f_oc, -K * (expected + dt_pre), rtol=1e-9, atol=1e-9)  # (2.42)
    gap = np.linalg.norm(r_c_model @ r_eq_model.T @ dt_pre - dt_pre)  # (2.43)
    np.testing.assert_allclose(np.linalg.norm(f_oc - f_c), K * gap, rtol=1e-6, atol=1e-9)


def _relative_rotation(mech, q):
    """R of I in J (from the markers' global orientations at q)."""
    from diffsusp.statics import marker_poses

    _, ori = marker_poses(mech, q)
    ori = np.asarray(ori)
    return ori[1].T @ ori[0]


def test_not_equivalent_for_a_rotation():
    """(2.43) is not zero for a non-trivial relative rotation and a deformation off its axis."""
    t_eq = np.array([1.0, 0.0, 0.0])
    r_c = np.asarray(rotvec_to_matrix(np.array([0.0, 0.0, np.radians(10.0)])))
    assert np.linalg.norm(r_c @ t_eq - t_eq) > 0.17
