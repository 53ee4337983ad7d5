"""Primitives fitted to probed points (spec geometry §3.2): exact recovery of known shapes, and the
reported covariances against Monte-Carlo spreads of the same fits (vmapped over noise draws)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsusp.geometry import (
    bushing_frame,
    fit_line,
    fit_plane,
    fit_sphere,
    intersect_line_plane,
)

SIGMA = 0.05
DRAWS = 400
RNG = np.random.default_rng(3)


def _sphere_points():
    # A ball-joint probe: 8 positions of a point 80 mm from the centre, over ±40° of swing.
    centre = np.array([-25.5, -691.2, 233.0])
    a = np.deg2rad(RNG.uniform(-40, 40, size=(8, 2)))
    d = np.stack([np.sin(a[:, 0]) * np.cos(a[:, 1]), np.sin(a[:, 1]),
                  -np.cos(a[:, 0]) * np.cos(a[:, 1])], axis=1)
    return centre, 80.0, centre + 80.0 * d


def _monte_carlo(fn, points):
    keys = jax.random.split(jax.random.PRNGKey(0), DRAWS)
    noisy = points + SIGMA * jax.vmap(lambda k: jax.random.normal(k, points.shape))(keys)
    return jax.jit(jax.vmap(fn))(noisy)


def _assert_sigma(reported_cov, samples, rtol=1.5):
    reported = np.sqrt(np.diag(np.asarray(reported_cov)))
    spread = np.std(np.asarray(samples), axis=0, ddof=1)
    keep = reported > 1e-9
    ratio = spread[keep] / reported[keep]
    assert np.all((ratio > 1 / rtol) & (ratio < rtol)), ratio


def test_sphere_exact_and_sigma():
    centre, radius, pts = _sphere_points()
    fit = fit_sphere(pts, sigma=SIGMA)
    np.testing.assert_allclose(fit.centre, centre, atol=1e-9)
    np.testing.assert_allclose(fit.radius, radius, atol=1e-9)
    assert float(fit.rms) < 1e-9
    samples = _monte_carlo(lambda p: jnp.append(fit_sphere(p).centre, fit_sphere(p).radius),
                           jnp.asarray(pts))
    _assert_sigma(fit.covariance, samples)
    # A narrow swing amplifies the noise along the probe axis: σ_z ≫ σ (lever arm).
    assert np.sqrt(fit.covariance[2, 2]) > 2 * SIGMA


def test_sphere_sigma_estimated_from_residuals():
    _, _, pts = _sphere_points()
    noisy = pts + RNG.normal(scale=SIGMA, size=pts.shape)
    fit = fit_sphere(noisy)
    # n − 4 = 4 degrees of freedom of the radial residuals; the estimate is within a factor 3.
    assert SIGMA / 3 < float(fit.sigma) < 3 * SIGMA


def test_line_and_plane():
    u = np.array([0.636, -0.771, -0.031])
    u /= np.linalg.norm(u)
    a = np.array([1.0, 2.0, 3.0])
    t = np.linspace(-50, 60, 9)
    line_pts = a + t[:, None] * u
    fit = fit_line(line_pts, sigma=SIGMA)
    np.testing.assert_allclose(fit.direction, -u, atol=1e-12)  # largest component positive
    np.testing.assert_allclose(np.cross(fit.point - a, u), 0, atol=1e-9)
    # Closed form: the centroid's σ is σ/√n per coordinate; the direction's transverse σ is
    # σ/√Σt² (t about the centroid).
    n = len(t)
    tc = t - t.mean()
    np.testing.assert_allclose(np.trace(fit.covariance[:3, :3]), 3 * SIGMA**2 / n, rtol=1e-9)
    np.testing.assert_allclose(np.trace(fit.covariance[3:, 3:]), 2 * SIGMA**2 / (tc @ tc),
                               rtol=1e-9)
    samples = _monte_carlo(lambda p: jnp.concatenate(fit_line(p)[:2]), jnp.asarray(line_pts))
    _assert_sigma(fit.covariance, samples)

    normal = np.array([0.1, 0.2, 0.97])
    normal /= np.linalg.norm(normal)
    e1 = np.cross(normal, [1, 0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    uv = RNG.uniform(-30, 30, size=(10, 2))
    plane_pts = a + uv[:, :1] * e1 + uv[:, 1:] * e2
    pf = fit_plane(plane_pts, sigma=SIGMA)
    np.testing.assert_allclose(pf.normal, normal, atol=1e-12)
    np.testing.assert_allclose((pf.point - a) @ normal, 0, atol=1e-9)
    samples = _monte_carlo(lambda p: jnp.concatenate(fit_plane(p)[:2]), jnp.asarray(plane_pts))
    _assert_sigma(pf.covariance, samples)


def test_intersection_closed_form_and_parallel():
    x, cov = intersect_line_plane([0, 0, 0], [1, 1, 0], [5, 0, 0], [1, 0, 0],
                                  covariance=np.eye(12) * 0.01)
    np.testing.assert_allclose(x, [5, 5, 0], atol=1e-12)
    assert cov.shape == (3, 3) and np.all(np.linalg.eigvalsh(cov) >= -1e-15)
    with pytest.raises(eqx.EquinoxRuntimeError, match="parallel"):
        intersect_line_plane([0, 0, 0], [0, 1, 0], [5, 0, 0], [1, 0, 0])


def test_bushing_frame():
    # Sleeve of bushing B (Table 2.2 L1, axis = z of REULER (129.5, 90.22, 181.79)°), 60 mm long.
    from diffsusp.geometry import reuler_deg_to_matrix

    r = np.asarray(reuler_deg_to_matrix(jnp.array([129.5, 90.22, 181.79])))
    centre, z, x = np.array([-294.7, -365.1, 246.1]), r[:, 2], r[:, 0]
    y = np.cross(z, x)
    axis_pts = centre + np.linspace(-25, 25, 6)[:, None] * z
    ang = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    ring = 35 * (np.cos(ang)[:, None] * x + np.sin(ang)[:, None] * y)
    end1, end2 = centre - 30 * z + ring, centre + 30 * z + ring
    fr = bushing_frame(axis_pts, end1, end2, sigma=SIGMA)
    np.testing.assert_allclose(fr.centre, centre, atol=1e-9)
    np.testing.assert_allclose(abs(fr.axis @ z), 1, atol=1e-12)
    np.testing.assert_allclose(fr.length, 60, atol=1e-9)
    keys = jax.random.split(jax.random.PRNGKey(1), DRAWS)

    def draw(k):
        k1, k2, k3 = jax.random.split(k, 3)
        f = bushing_frame(axis_pts + SIGMA * jax.random.normal(k1, axis_pts.shape),
                          end1 + SIGMA * jax.random.normal(k2, end1.shape),
                          end2 + SIGMA * jax.random.normal(k3, end2.shape), sigma=SIGMA)
        return jnp.concatenate([f.centre, f.axis])

    _assert_sigma(fr.covariance, jax.jit(jax.vmap(draw))(keys))


def test_too_few_points():
    with pytest.raises(ValueError, match="at least 4 points"):
        fit_sphere(np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        fit_plane(np.zeros((4, 2)))
