"""Mirroring (diffsusp.model.mirror) and combining (diffsusp.model.combine) mechanisms.

The references are the NumPy oracle's equilibria (tests/oracle.py), which read the mechanisms'
arrays directly: the mirrored model under mirrored loads must settle in the mirror image of the
original's equilibrium (R' = M R M, p' = M p with M = diag(1, −1, 1)), for the thesis half axle
and for a small model that exercises every mirrored field (bushing offsets, preloads, cubic
terms, splines on the flipped axes, a tilted driver, a load in a marker frame); a combined axle
settles in each side's own equilibrium. No JAX solve here (the JAX side is in test_kc.py's axle
events), so nothing is compiled but one model's validation.
"""

import jax
import jax.numpy as jnp
import numpy as np
import oracle
import pytest

from diffsusp import MechanismBuilder
from diffsusp.errors import ModelError
from diffsusp.kc import add_driver
from diffsusp.model.combine import combine, component_names
from diffsusp.model.mirror import mirror, mirror_coordinates, mirror_loads
from diffsusp.models import TABLE_5_1, double_wishbone, pseudo_mcpherson, thesis_load_cases

M = np.diag([1.0, -1.0, 1.0])


def featureful():
    """Two parts with every field that mirroring must transform."""
    b = MechanismBuilder("mirror test")
    b.part("arm")
    b.part("link")
    b.bushing("bush", parts=("arm", "ground"), at=(100.0, 50.0, 20.0), reuler_deg=(30, 20, 10),
              k_trans=(1000.0, 2000.0, 300.0), k_rot=(4e5, 2e5, 1e5),
              cubic_trans=(1.0, 2.0, 3.0), offset_trans=(0.1, -0.2, 0.3),
              offset_rot=(0.01, 0.02, -0.03), preload_force=(10.0, -20.0, 30.0),
              preload_torque=(1e3, -2e3, 3e3),
              splines={"ty": ([-2.0, -0.5, 0.0, 1.0, 3.0], [4500.0, 900.0, 0.0, -2100.0, -7000.0]),
                       "rz": ([-0.2, 0.0, 0.1, 0.3, 0.5], [3e4, 0.0, -1.2e4, -4.5e4, -8e4])})
    b.joint("ball", "spherical", parts=("link", "arm"), at=(200.0, 80.0, 0.0))
    b.bushing("bush2", parts=("link", "ground"), at=(260.0, 140.0, 40.0), z=(0.2, 1.0, 0.3),
              k_trans=(800.0, 500.0, 900.0), k_rot=(3e5, 3e5, 2e5))
    b.spring("spring", parts=("ground", "arm"), at=((90.0, 40.0, 300.0), (120.0, 60.0, 30.0)),
             k=25.0, free_length=300.0)
    b.marker("tip", "arm", (160.0, 90.0, 10.0), z=(0.3, -0.5, 0.8), x=(1.0, 0.0, 0.0))
    b.load_point("tip_local", marker="tip", frame="tip")
    b.load_point("end", part="link", at=(240.0, 120.0, 30.0))
    b.driver("drive", "tip", direction=(0.2, 0.9, 0.4))
    return b.build()


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


def test_every_mirrored_field():
    mech = featureful()
    mirrored = mirror(mech, suffix="_r")
    assert mirrored.name == "mirror test (mirrored)"
    assert mirrored.markers.names[0].endswith("_r") and mirrored.parts == ("arm_r", "link_r")
    loads = mech.loads(forces={"tip_local": jnp.array([[150.0, -80.0, 60.0]] * 2),
                               "end": jnp.array([[-40.0, 120.0, 90.0]] * 2)},
                       moments={"tip_local": jnp.array([[2e3, 3e3, -1e3]] * 2)},
                       drivers={"drive": jnp.array([1.5, -2.0])})
    for c in range(2):
        sol = solve(mech, loads, c)
        sol_m = solve(mirrored, mirror_loads(loads), c)
        assert sol.converged and sol_m.converged
        assert_mirror_image(sol, sol_m)
        # The bushing works on its spline and preloaded axes (not a trivial equilibrium).
        dt, dr = oracle.bushing_deformations(mech, sol.p, sol.R)
        assert np.abs(dt[0, 1]) > 1e-3 and np.abs(dr[0, 2]) > 1e-4


def test_mirror_twice_is_the_identity(pm):
    twice = mirror(mirror(pm), name=pm.name)
    for a, b in zip(*(jax.tree_util.tree_leaves(m) for m in (pm, twice)), strict=True):
        np.testing.assert_array_equal(a, b)
    assert twice.reference_points == pm.reference_points


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
