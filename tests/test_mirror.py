"""Mirroring (diffsusp.model.mirror) and combining (diffsusp.model.combine) mechanisms.

The references are the NumPy oracle's equilibria (tests/oracle.py), which read the mechanisms'
arrays directly: the mirrored model under mirrored loads must settle in the mirror image of the
original's equilibrium (R' = M R M, p' = M p with M = diag(1, −1, 1)), for the thesis half axle
and for the same axle with every mirrored field set (bushing offsets, preloads, cubic terms,
splines on the flipped axes, a tilted driver, a load in a marker frame); a combined axle
settles in each side's own equilibrium. No JAX solve here (the JAX side is in test_kc.py's axle
events), and the featureful model is edited in place, so nothing is compiled but the two
built-in models' validation.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import oracle
import pytest

from diffsusp.errors import ModelError
from diffsusp.kc import add_driver
from diffsusp.model.combine import combine, component_names
from diffsusp.model.mirror import mirror, mirror_coordinates, mirror_loads
from diffsusp.models import TABLE_5_1, double_wishbone, pseudo_mcpherson, thesis_load_cases

M = np.diag([1.0, -1.0, 1.0])


def featureful(pm):
    """The half axle with every field that mirroring must transform, set directly on its arrays
    (no new build, so nothing is compiled): bushing offsets, preloads and cubic terms, Akima
    splines on bushing B's ty and rz axes (the axes whose deformation changes sign), a driver
    along a tilted direction and a load point whose components are in a marker's frame."""
    b = pm.bushings
    n = len(b.names)
    x = np.tile(np.linspace(-1.0, 1.0, 5), (n, 6, 1))
    y = np.zeros((n, 6, 5))
    k = b.names.index("bushing_B")
    x[k, 1] = [-3.0, -1.0, 0.0, 0.5, 2.0]  # ty (mm → N, A/Car: force on I = −k·x)
    y[k, 1] = [9000.0, 2600.0, 0.0, -1200.0, -5500.0]
    x[k, 5] = [-0.2, -0.05, 0.0, 0.1, 0.3]  # rz (rad → N·mm)
    y[k, 5] = [6e4, 1.4e4, 0.0, -3.1e4, -1.0e5]
    axes = [[False] * 6 for _ in range(n)]
    axes[k][1] = axes[k][5] = True
    bushings = dataclasses.replace(
        b, cubic_trans=b.cubic_trans + 2.0,
        offset_trans=b.offset_trans + jnp.array([0.1, -0.2, 0.3]),
        offset_rot=b.offset_rot + jnp.array([0.002, 0.004, -0.003]),
        preload_force=b.preload_force + jnp.array([30.0, -50.0, 20.0]),
        preload_torque=b.preload_torque + jnp.array([2e3, -1e3, 3e3]),
        spline_x=jnp.asarray(x), spline_y=jnp.asarray(y),
        spline_axes=tuple(tuple(a) for a in axes))
    lp = pm.load_points
    wc = pm.markers.index("wheel_centre")
    load_points = dataclasses.replace(lp, frame=tuple(
        wc if name == "wheel_centre" else f for name, f in zip(lp.names, lp.frame, strict=True)))
    mech = dataclasses.replace(pm, bushings=bushings, load_points=load_points)
    return add_driver(mech, "tilted", "L8_front_arm_ball", (0.2, 0.9, 0.4))


def solve(mech, loads, c):
    return oracle.solve(mech, np.asarray(loads.force[c]), np.asarray(loads.moment[c]),
                        np.asarray(loads.driver[c]))


def assert_mirror_image(sol, sol_m):
    np.testing.assert_allclose(sol_m.p, sol.p @ M, rtol=0, atol=1e-9)
    np.testing.assert_allclose(sol_m.R, M @ sol.R @ M, rtol=0, atol=1e-12)
    np.testing.assert_allclose(mirror_coordinates(sol.q()), sol_m.q(), rtol=0, atol=1e-9)


@pytest.fixture(scope="module")
def pm():
    return pseudo_mcpherson()


@pytest.mark.parametrize("case", [0, 5, 9])
def test_mirrored_half_axle_settles_in_the_mirror_image(pm, case):
    """Table 5-1 cases (vertical, lateral, longitudinal) on the left half axle and the mirrored
    loads on its mirror image."""
    loads = thesis_load_cases(pm, TABLE_5_1)
    mirrored = mirror(pm)
    sol = solve(pm, loads, case)
    sol_m = solve(mirrored, mirror_loads(loads), case)
    assert sol.converged and sol_m.converged
    assert_mirror_image(sol, sol_m)
    # The wheel moved: the test is not trivially at design.
    assert np.abs(sol.p).max() > 1.0


def test_every_mirrored_field(pm):
    mech = featureful(pm)
    mirrored = mirror(mech, suffix="_r")
    assert mirrored.name == "pseudo-McPherson half axle (mirrored)"
    assert mirrored.markers.names[0].endswith("_r") and mirrored.parts[0] == "front_arm_r"
    loads = mech.loads(forces={"contact_patch": jnp.array([[800.0, 1500.0, 4500.0]] * 2),
                               "wheel_centre": jnp.array([[150.0, -300.0, 60.0]] * 2)},
                       moments={"wheel_centre": jnp.array([[2e4, 3e4, -1e4]] * 2)},
                       drivers={"tilted": jnp.array([1.5, -2.0])})
    k = mech.bushings.names.index("bushing_B")
    for c in range(2):
        sol = solve(mech, loads, c)
        sol_m = solve(mirrored, mirror_loads(loads), c)
        assert sol.converged and sol_m.converged
        assert_mirror_image(sol, sol_m)
        # Bushing B works on its spline axes (not a trivial equilibrium).
        dt, dr = oracle.bushing_deformations(mech, sol.p, sol.R)
        assert np.abs(dt[k, 1]) > 1e-2 and np.abs(dr[k, 2]) > 1e-4, (dt[k], dr[k])


def test_mirror_twice_is_the_identity(pm):
    twice = mirror(mirror(pm), name=pm.name)
    for a, b in zip(*(jax.tree_util.tree_leaves(m) for m in (pm, twice)), strict=True):
        np.testing.assert_array_equal(a, b)
    assert twice.reference_points == pm.reference_points
    # mirrored loads keep their road-contact radii (the tyre force at the wheel plane's lowest
    # point mirrors with the wheel); they were dropped, moving the force to the marker
    loads = thesis_load_cases(pm)
    loads = dataclasses.replace(loads, contact_radius=jnp.full(loads.force.shape[:-1], 330.0))
    back = mirror_loads(mirror_loads(loads))
    np.testing.assert_array_equal(back.contact_radius, loads.contact_radius)
    np.testing.assert_array_equal(back.force, loads.force)


def test_combined_axle_settles_side_by_side():
    """combine({'left': dw, 'right': mirror(dw)}) with a wheel-travel driver on each side: the
    axle's equilibrium is each half axle's own (the two share only the ground)."""
    left = add_driver(double_wishbone(bushings=True), "wheel_travel", "wheel_centre")
    right = mirror(left)
    axle = combine({"left": left, "right": right})
    assert component_names(axle) == {"left/": left.name, "right/": right.name}
    assert axle.parts[:3] == tuple("left/" + p for p in left.parts)
    assert axle.drivers.names == ("left/wheel_travel", "right/wheel_travel")
    n_joint_rows = left.joints.n_rows
    assert axle.n_rows == 2 * left.n_rows
    # Joint rows of each side, then the two driver rows.
    assert axle.independent_rows == tuple(range(2 * n_joint_rows)) + (
        2 * n_joint_rows, 2 * n_joint_rows + 1)
    force = np.array([800.0, 1500.0, 9000.0])
    loads = axle.loads(forces={"left/contact_patch": force,
                               "right/contact_patch": force @ M * np.array([1, 1, 1.2])},
                       drivers={"left/wheel_travel": 20.0, "right/wheel_travel": -10.0})
    sol = oracle.solve(axle, np.asarray(loads.force), np.asarray(loads.moment),
                       np.asarray(loads.driver))
    assert sol.converged
    for side, mech, k in (("left/", left, slice(0, 3)), ("right/", right, slice(3, 6))):
        sub = mech.loads(forces={"contact_patch": loads.force[
            axle.load_points.index(side + "contact_patch")]},
            drivers={"wheel_travel": loads.driver[axle.drivers.names.index(
                side + "wheel_travel")]})
        ref = oracle.solve(mech, np.asarray(sub.force), np.asarray(sub.moment),
                           np.asarray(sub.driver))
        np.testing.assert_allclose(sol.p[k], ref.p, rtol=0, atol=1e-9)
        np.testing.assert_allclose(sol.R[k], ref.R, rtol=0, atol=1e-12)


def test_combine_rejects_bad_keys(pm):
    with pytest.raises(ModelError, match="plain name"):
        combine({"a/b": pm})
    with pytest.raises(ModelError, match="not a Mechanism"):
        combine({"left": "pm"})
