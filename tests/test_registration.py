"""Rigid registration of landmarks (diffsusp.geometry.registration): Horn's quaternion and Arun's
SVD against SciPy's Rotation.align_vectors and closed forms, the reflection case, weights, and
batches equal to loops. spec: geometry §3.6 (Annex A)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from diffsusp.geometry.registration import landmark_spread, register_landmarks

METHODS = ("quaternion", "svd")


def _rigid(rng, n, k, spread=150.0):
    """n random landmark sets of k points, random rotations and translations."""
    p = rng.normal(size=(n, k, 3)) * spread
    r = Rotation.random(n, random_state=int(rng.integers(1 << 30))).as_matrix()
    t = rng.normal(size=(n, 3)) * 300.0
    q = np.einsum("nij,nkj->nki", r, p) + t[:, None, :]
    return p, q, r, t


def _scipy(p, q, w=None):
    """Reference: SciPy's weighted Kabsch about the weighted centroids."""
    w = np.ones(len(p)) if w is None else np.asarray(w, float)
    pc = p - (w @ p) / w.sum()
    qc = q - (w @ q) / w.sum()
    rot, _ = Rotation.align_vectors(qc, pc, weights=w)
    r = rot.as_matrix()
    return r, (w @ q) / w.sum() - r @ ((w @ p) / w.sum())


@pytest.mark.parametrize("method", METHODS)
def test_exact_rigid_motion_is_recovered(method):
    rng = np.random.default_rng(0)
    p, q, r, t = _rigid(rng, 30, 4)
    reg = register_landmarks(p, q, method=method)
    np.testing.assert_allclose(reg.rotation, r, atol=1e-12)
    np.testing.assert_allclose(reg.translation, t, atol=1e-9)
    assert np.max(np.asarray(reg.rms)) < 1e-9


@pytest.mark.parametrize("method", METHODS)
def test_noisy_landmarks_match_scipy(method):
    rng = np.random.default_rng(1)
    p, q, _, _ = _rigid(rng, 30, 4)
    q = q + rng.normal(size=q.shape) * 0.05
    reg = register_landmarks(p, q, method=method)
    for i in range(len(p)):
        r_ref, t_ref = _scipy(p[i], q[i])
        np.testing.assert_allclose(reg.rotation[i], r_ref, atol=1e-12)
        np.testing.assert_allclose(reg.translation[i], t_ref, atol=1e-9)
    # The rms is the landmark residual: about the noise (σ·sqrt((3k − 6)/(3k)) per coordinate).
    rms = np.asarray(reg.rms)
    assert 0.02 < np.median(rms) < 0.09


@pytest.mark.parametrize("method", METHODS)
def test_reflection_is_fixed(method):
    """Mirrored landmarks: the unconstrained SVD optimum is a reflection (det U Vᵀ = −1); the
    registration returns the best proper rotation, as SciPy does."""
    rng = np.random.default_rng(2)
    p = rng.normal(size=(4, 3)) * 100.0
    q = p * np.array([1.0, 1.0, -1.0]) + np.array([10.0, -5.0, 3.0])
    pc, qc = p - p.mean(0), q - q.mean(0)
    u, _, vt = np.linalg.svd(qc.T @ pc)
    assert np.linalg.det(u @ vt) < 0  # the case is real
    reg = register_landmarks(p, q, method=method)
    r = np.asarray(reg.rotation)
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-12)
    np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
    r_ref, t_ref = _scipy(p, q)
    np.testing.assert_allclose(r, r_ref, atol=1e-12)
    np.testing.assert_allclose(reg.translation, t_ref, atol=1e-9)


@pytest.mark.parametrize("method", METHODS)
def test_coplanar_landmarks_with_noise(method):
    """Four coplanar landmarks (the correlation matrix is singular, so the sign of det U Vᵀ is
    arbitrary): a proper rotation, equal to SciPy's and to Arun's U diag(1, 1, d) Vᵀ."""
    rng = np.random.default_rng(3)
    p = np.array([[0.0, 0.0, 0.0], [120.0, 0.0, 0.0], [0.0, 70.0, 0.0], [90.0, 85.0, 0.0]])
    r_true = Rotation.from_rotvec([0.2, -0.1, 0.4]).as_matrix()
    q = p @ r_true.T + rng.normal(size=(30, 4, 3)) * 0.5
    reg = register_landmarks(p, q, method=method)
    for i in range(len(q)):
        r = np.asarray(reg.rotation[i])
        assert np.linalg.det(r) == pytest.approx(1.0, abs=1e-12)
        np.testing.assert_allclose(r, _scipy(p, q[i])[0], atol=1e-12)
        u, _, vt = np.linalg.svd((q[i] - q[i].mean(0)).T @ (p - p.mean(0)))
        d = np.sign(np.linalg.det(u @ vt))
        np.testing.assert_allclose(r, u @ np.diag([1.0, 1.0, d]) @ vt, atol=1e-12)


def test_methods_agree_on_a_batch_and_batch_equals_loop():
    rng = np.random.default_rng(4)
    p, q, _, _ = _rigid(rng, 6 * 5, 5)
    q = q + rng.normal(size=q.shape) * 0.05
    p, q = p.reshape(6, 5, 5, 3), q.reshape(6, 5, 5, 3)  # cases × parts × landmarks
    quat = register_landmarks(p, q)
    svd = register_landmarks(p, q, method="svd")
    np.testing.assert_allclose(quat.rotation, svd.rotation, atol=1e-12)
    np.testing.assert_allclose(quat.translation, svd.translation, atol=1e-9)
    assert quat.rotation.shape == (6, 5, 3, 3) and quat.rms.shape == (6, 5)
    jitted = jax.jit(register_landmarks)
    for c in range(6):
        for k in range(5):
            one = jitted(p[c, k], q[c, k])
            np.testing.assert_allclose(one.rotation, quat.rotation[c, k], atol=1e-13)
            np.testing.assert_allclose(one.translation, quat.translation[c, k], atol=1e-10)


def test_shared_reference_broadcasts_over_cases():
    rng = np.random.default_rng(5)
    p, q, r, t = _rigid(rng, 1, 4)
    q_cases = np.stack([q[0], q[0] + 1.0])  # second case translated by (1, 1, 1)
    reg = register_landmarks(p[0], q_cases)
    np.testing.assert_allclose(reg.rotation[1], r[0], atol=1e-12)
    np.testing.assert_allclose(reg.translation[1] - reg.translation[0], np.ones(3), atol=1e-9)


@pytest.mark.parametrize("method", METHODS)
def test_zero_weight_excludes_a_landmark(method):
    rng = np.random.default_rng(6)
    p, q, _, _ = _rigid(rng, 1, 5)
    p, q = p[0], q[0] + rng.normal(size=(5, 3)) * 0.05
    q_bad = q.copy()
    q_bad[2] += 40.0  # a wrong point, excluded by its weight
    w = np.array([1.0, 1.0, 0.0, 1.0, 1.0])
    reg = register_landmarks(p, q_bad, w, method=method)
    keep = w > 0
    sub = register_landmarks(p[keep], q[keep], method=method)
    np.testing.assert_allclose(reg.rotation, sub.rotation, atol=1e-12)
    np.testing.assert_allclose(reg.translation, sub.translation, atol=1e-9)
    np.testing.assert_allclose(reg.rms, sub.rms, rtol=1e-9)
    r_ref, _ = _scipy(p, q_bad, w)
    np.testing.assert_allclose(reg.rotation, r_ref, atol=1e-12)


def test_weighted_registration_matches_scipy():
    rng = np.random.default_rng(7)
    p, q, _, _ = _rigid(rng, 1, 6)
    p, q = p[0], q[0] + rng.normal(size=(6, 3)) * 0.5
    w = rng.uniform(0.2, 3.0, 6)
    reg = register_landmarks(p, q, w)
    r_ref, t_ref = _scipy(p, q, w)
    np.testing.assert_allclose(reg.rotation, r_ref, atol=1e-12)
    np.testing.assert_allclose(reg.translation, t_ref, atol=1e-9)


def test_large_rotations_near_180_degrees():
    p = np.random.default_rng(8).normal(size=(4, 3)) * 100.0
    for angle in (np.pi - 1e-6, np.pi, 3.0):
        r = Rotation.from_rotvec(angle * np.array([0.0, 0.6, 0.8])).as_matrix()
        reg = register_landmarks(p, p @ r.T)
        np.testing.assert_allclose(reg.rotation, r, atol=1e-12)


def test_landmark_spread():
    pts = jnp.array([[0.0, 0, 0], [100, 0, 0], [200, 0, 0], [300, 0, 0]])
    s = np.asarray(landmark_spread(pts))
    assert s[0] > 100 and s[1] < 1e-12  # collinear
    s = np.asarray(landmark_spread(pts.at[1, 1].set(50.0)))
    assert s[1] > 10 and s[2] < 1e-12  # coplanar


def test_bad_method_and_shape():
    with pytest.raises(ValueError, match="method must be"):
        register_landmarks(np.zeros((4, 3)), np.zeros((4, 3)), method="kabsch")
    with pytest.raises(ValueError, match="shape"):
        register_landmarks(np.zeros((4, 2)), np.zeros((4, 2)))
