"""The 30-DOF vehicle's input kinematics from K&C tables (`diffsusp.tyre.vehicle_kc`; spec
tyre §5.2, Table 30): the shipped tables against a fresh `kc` computation on the library's
pseudo-McPherson, the interpolated poses against direct `kc` evaluations at points off the grid,
and the poses continuous and differentiable (gradients against finite differences, C¹ across
the knots). One K&C program compiled for the module (grid and off-grid cases together)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsusp.errors import InputError
from diffsusp.models import pseudo_mcpherson
from diffsusp.tyre import vehicle_kc as K
from diffsusp.tyre.vehicle import Vehicle

OFF_T = np.array([-0.052, -0.041, -0.017, 0.008, 0.023, 0.044, 0.057, 0.012])
OFF_F = np.array([2400.0, -1300.0, 600.0, -2700.0, 1900.0, -450.0, 2900.0, -2100.0])


@pytest.fixture(scope="module")
def fresh():
    tt, ff = K.grid_cases(K.TRAVEL_GRID, K.LATERAL_GRID)
    cases = K.kc_cases(pseudo_mcpherson(), np.r_[tt, OFF_T], np.r_[ff, OFF_F])
    n = tt.size
    grid = {k: v[:n] for k, v in cases.items()}
    off = {k: v[n:] for k, v in cases.items()}
    return K.tables_from_cases(K.TRAVEL_GRID, K.LATERAL_GRID, grid), off


def test_shipped_tables_are_kc_and_interpolate_off_grid(fresh):
    """The shipped tables are what `kc` computes (to 1e-9), and at 8 points off the coarse 5×3
    grid (travel ±60 mm, lateral ±3 kN) the C¹ interpolant is within 2 % of each quantity's range
    over the grid of the direct `kc` evaluation (toe within 0.15 mrad, camber 0.5 mrad, track
    and wheelbase 0.4 mm) — and better than the bilinear interpolation of the same grid."""
    tables, off = fresh
    shipped = K.load_tables()
    np.testing.assert_allclose(shipped.values, tables.values, rtol=1e-9, atol=1e-12)
    got = np.asarray(jax.jit(jax.vmap(lambda t, f: tables.lookup(0, t, f)))(
        jnp.asarray(OFF_T), jnp.asarray(OFF_F)))
    want = np.stack([off[k] for k in K.QUANTITIES], axis=1)
    err = np.abs(got - want)
    span = np.ptp(np.asarray(tables.values[0]).reshape(-1, 4), axis=0)
    assert np.all(err.max(axis=0) < 0.02 * span), (err.max(axis=0), span)
    assert np.all(err.max(axis=0) < [1.5e-4, 5e-4, 4e-4, 4e-4]), err.max(axis=0)
    # bilinear interpolation of the same knots, for comparison
    v = np.asarray(tables.values[0])
    tg, fg = np.asarray(K.TRAVEL_GRID), np.asarray(K.LATERAL_GRID)

    def bilinear(t, f):
        i = np.clip(np.searchsorted(tg, t) - 1, 0, len(tg) - 2)
        j = np.clip(np.searchsorted(fg, f) - 1, 0, len(fg) - 2)
        a, b = (t - tg[i]) / (tg[i + 1] - tg[i]), (f - fg[j]) / (fg[j + 1] - fg[j])
        return ((1 - a) * (1 - b) * v[i, j] + a * (1 - b) * v[i + 1, j]
                + (1 - a) * b * v[i, j + 1] + a * b * v[i + 1, j + 1])

    lin = np.abs(np.array([bilinear(t, f) for t, f in zip(OFF_T, OFF_F, strict=True)]) - want)
    assert np.sum(err) < np.sum(lin)


def test_poses_continuous_and_differentiable():
    """`wheel_poses` from travel and lateral load: gradients (jax) against central finite
    differences (relative 2e-4: a step across a knot meets the next cubic) at points inside,
    across a knot and beyond the grid; value and slope continuous
    across the knots (C¹); the right wheels the mirror image of the left ones; the default
    12-DOF car unchanged by the option's absence. Two compiled programs (the poses and their
    Jacobian), each evaluated in batches."""
    tables = K.load_tables()
    corners = Vehicle().corners
    assert Vehicle().kinematics is None  # the 12-DOF car by default

    def pose(z, f):
        R, O, toe, camber = K.wheel_poses(tables, corners, z, f)
        return jnp.concatenate([R.reshape(-1), O.reshape(-1), toe, camber])

    poses = jax.jit(jax.vmap(pose))
    jac = jax.jit(jax.vmap(jax.jacfwd(pose, argnums=(0, 1))))
    rng = np.random.default_rng(3)
    z0 = np.stack([rng.uniform(-0.05, 0.05, 4), np.full(4, 0.03 + 1e-7),  # inside, at knots
                   np.full(4, 0.07)])  # beyond the grid
    f0 = np.stack([rng.uniform(-2500, 2500, 4), np.full(4, -1e-4), np.full(4, 3500.0)])
    jz, jf = (np.asarray(a) for a in jac(jnp.asarray(z0), jnp.asarray(f0)))
    h_z, h_f = 1e-6, 1e-2
    eye = np.eye(4)
    # every point's ± steps in z and in f for every wheel: one batch
    zs = np.concatenate([z0[:, None] + s * h_z * eye for s in (1, -1)] +
                        [np.repeat(z0[:, None], 4, axis=1)] * 2, axis=1)
    fs = np.concatenate([np.repeat(f0[:, None], 4, axis=1)] * 2 +
                        [f0[:, None] + s * h_f * eye for s in (1, -1)], axis=1)
    out = np.asarray(poses(jnp.asarray(zs.reshape(-1, 4)), jnp.asarray(fs.reshape(-1, 4))))
    out = out.reshape(3, 4, 4, -1)  # point, (z+, z−, f+, f−), wheel, value
    fd_z = (out[:, 0] - out[:, 1]) / (2 * h_z)
    fd_f = (out[:, 2] - out[:, 3]) / (2 * h_f)
    np.testing.assert_allclose(np.swapaxes(jz, 1, 2), fd_z, rtol=2e-4, atol=1e-8)
    np.testing.assert_allclose(np.swapaxes(jf, 1, 2), fd_f, rtol=2e-4, atol=1e-11)

    # C¹ across every knot of the travel and the lateral grid: the poses (toe and camber are the
    # tables' values) and their slopes each side, by the same two programs
    knots = np.asarray(K.TRAVEL_GRID[1:-1])
    k = knots.size
    t = np.repeat(np.r_[knots - 1e-9, knots + 1e-9, 0.01, 0.01][:, None], 4, axis=1)
    f = np.repeat(np.r_[np.full(2 * k, 500.0), -1e-7, 1e-7][:, None], 4, axis=1)
    val = np.asarray(poses(jnp.asarray(t), jnp.asarray(f)))
    d_t, d_f = (np.asarray(a) for a in jac(jnp.asarray(t), jnp.asarray(f)))
    np.testing.assert_allclose(val[:k], val[k:2 * k], atol=1e-9)
    np.testing.assert_allclose(d_t[:k], d_t[k:2 * k], rtol=1e-5, atol=1e-12)
    np.testing.assert_allclose(d_f[-2], d_f[-1], rtol=1e-6, atol=1e-15)
    # mirror: a left and a right wheel at the same travel with mirrored forces
    p = np.asarray(poses(jnp.full((1, 4), 0.02), jnp.array([[800.0, -800.0, 500.0, -500.0]])))[0]
    O, toe, camber = p[36:48].reshape(4, 3), p[48:52], p[52:56]
    np.testing.assert_allclose(toe[0], -toe[1], rtol=1e-12)
    np.testing.assert_allclose(camber[2], -camber[3], rtol=1e-12)
    np.testing.assert_allclose(O[0, 1] - corners[0, 1], -(O[1, 1] - corners[1, 1]), rtol=1e-12)
    # body motion to travel: heave up extends every wheel, roll left-up extends the left ones
    z = K.corner_travel(corners, 0.01, 0.0, 0.0)
    np.testing.assert_allclose(z, -0.01)
    z = K.corner_travel(corners, 0.0, 0.01, 0.0)
    assert z[0] < 0 < z[1] and z[2] < 0 < z[3]
    with pytest.raises(InputError):
        K.KCTables(tables.travel[::-1], tables.lateral, tables.values)
