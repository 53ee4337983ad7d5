"""Geometric location of bushings free about one axis (spec geometry §4.3, stiffness §1.8) on
the Chrono double wishbone with torsion-free arm bushings (tests/data/DoubleWishbone_bushings
.json): each bushing is located as a revolute, its axis line within 3σ of the model's, its
position along the axis reported not observable, noise-free and at landmark noise 0.05 mm. The
arms also twist on their finite rotational stiffness (1e8 N·mm/rad) under the ±2000 N cases:
that compliance bias must be inside the reported σ."""

import pathlib

import jax
import numpy as np
import pytest

import diffsusp
from diffsusp import load_model
from diffsusp.identify.geometric import joints_from_model, locate_joints
from diffsusp.kc.corner import equilibrium_load
from diffsusp.measure import place_landmarks
from diffsusp.measure.measurements import from_landmarks
from diffsusp.model import Loads

MODEL = pathlib.Path(__file__).parent / "data" / "DoubleWishbone_bushings.json"


@pytest.fixture(scope="module")
def located():
    mech = load_model(str(MODEL))
    f0 = equilibrium_load(mech, "contact_patch")
    force = np.array([[x, y, z] for z in (0.5 * f0, 0.8 * f0, 1.1 * f0, 1.4 * f0)
                      for y in (-2000.0, 0.0, 2000.0) for x in (-1500.0, 1500.0)])
    n = len(force)
    sol = diffsusp.solve_statics(mech, mech.loads(forces={"contact_patch": force}))
    rot, trans = jax.vmap(lambda q: diffsusp.part_poses(mech, q))(sol.q)
    joints, notes = joints_from_model(mech, mech.parts)
    measured = tuple(sorted({p for j in joints for p in j.parts if p != "ground"}))
    index = [mech.parts.index(p) for p in measured]
    layout = place_landmarks(mech, 4, parts=measured, seed=0)
    points = (np.einsum("cpij,pkj->cpki", np.asarray(rot)[:, index],
                        np.asarray(layout.position)) + np.asarray(trans)[:, index, None])
    loads = Loads(force=np.zeros((n, 1, 3)), moment=np.zeros((n, 1, 3)),
                  driver=np.zeros((n, 0)))
    rng = np.random.default_rng(3)
    reports = {noise: locate_joints(from_landmarks(
        layout, points + noise * rng.standard_normal(points.shape), loads), joints)
        for noise in (0.0, 0.05)}
    return mech, joints, notes, reports


def test_torsion_free_bushing_is_a_revolute(located):
    mech, joints, notes, reports = located
    kinds = {j.name: j.kind for j in joints}
    assert kinds["uca_bushing"] == kinds["lca_bushing"] == "revolute"
    assert kinds["uca_ball_joint"] == kinds["lca_ball_joint"] == "ball"
    assert any("uca_bushing" in n and "free about its z axis" in n for n in notes)
    b = mech.bushings
    for noise, report in reports.items():
        for name in ("uca_bushing", "lca_bushing"):
            e = report[name]
            assert e.observable, (noise, name, e.note)
            assert "along the axis not observable" in e.note
            m = int(b.i_marker[b.names.index(name)])
            p = np.asarray(mech.markers.position[m])
            a = np.asarray(mech.markers.orientation[m])[:, 2]
            axis = e.axis * np.sign(e.axis @ a)
            # the axis components and the centre's offset across the true line within 3σ
            assert np.all(np.abs(axis - a) <= 3 * e.sigma_axis), (noise, name, axis - a,
                                                                  e.sigma_axis)
            d = e.centre - p
            across = d - (d @ a) * a
            assert np.all(np.abs(across) <= 3 * e.sigma), (noise, name, across, e.sigma)
            # the point along the axis is the model's (the prior's), not a measured value
            assert abs(d @ a) < 0.05
