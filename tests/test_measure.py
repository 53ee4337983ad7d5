"""Measurements (diffsusp.measure): landmark layouts, distance-table re-ordering with outliers
and ambiguity, noise, synthetic measurements, poses → deformations, and bad input.
spec: geometry §3.3–3.7, stiffness §1.1, §2.8."""

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import diffsusp
from diffsusp import measure
from diffsusp.errors import InputError
from diffsusp.geometry import reuler_deg_to_matrix
from diffsusp.models import isolated_bushing
from diffsusp.models._isolated_bushing import ISOLATED_BUSHING_REULER_DEG

ASYMMETRIC = np.array([[0.0, 0.0, 0.0], [180.0, 10.0, 0.0], [40.0, 95.0, 5.0],
                       [130.0, 60.0, 70.0]])


# ----------------------------------------------------------------------------- re-ordering


def test_distance_table():
    d = measure.distance_table(ASYMMETRIC)
    assert d.shape == (4, 4)
    np.testing.assert_allclose(d, d.T)
    assert d[0, 1] == pytest.approx(np.hypot(180.0, 10.0))
    upper = d[np.triu_indices(4, 1)]
    assert len(np.unique(np.round(upper, 6))) == 6  # all distinct (spec geometry §3.3 rule 3)


def test_reorder_finds_every_permutation():
    rng = np.random.default_rng(0)
    rot = Rotation.random(random_state=1).as_matrix()
    moved = ASYMMETRIC @ rot.T + np.array([5.0, -300.0, 40.0])
    for perm in itertools.permutations(range(4)):
        probed = moved[list(perm)] + rng.normal(size=(4, 3)) * 0.05
        result = measure.reorder_landmarks(ASYMMETRIC, probed)
        assert not result.ambiguous and result.outlier is None and result.message == ""
        # measured[order[a]] is landmark a
        np.testing.assert_array_equal(np.asarray(perm)[result.order], np.arange(4))
        assert result.max_error < 0.5


def test_reorder_reports_a_symmetric_layout_as_ambiguous():
    rectangle = np.array([[0.0, 0, 0], [100, 0, 0], [100, 50, 0], [0, 50, 0]])
    result = measure.reorder_landmarks(rectangle, rectangle[[2, 3, 0, 1]])
    assert result.ambiguous
    assert len(result.candidates) == 4  # the rectangle's symmetry group
    assert "ambiguous" in result.message
    layout = measure.LandmarkLayout(position=jnp.asarray(rectangle)[None], parts=("arm",),
                                    names=(("a", "b", "c", "d"),))
    notes = measure.check_layout(layout)
    assert len(notes) == 1 and "symmetric" in notes[0]


def test_reorder_excludes_one_wrong_landmark():
    probed = ASYMMETRIC[[3, 1, 0, 2]].copy()
    probed[1] += np.array([0.0, 2.0, 0.0])  # landmark 1 measured 2 mm off (> ε = 0.5 mm)
    result = measure.reorder_landmarks(ASYMMETRIC, probed)
    assert result.outlier == 1  # the measured point that fits nothing
    assert result.order[1] == -1  # reference landmark 1 is unmeasured
    np.testing.assert_array_equal(result.order[[0, 2, 3]], [2, 3, 0])
    assert "excluded" in result.message


def test_reorder_gives_up_with_two_wrong_landmarks():
    probed = ASYMMETRIC.copy()
    probed[0] += 3.0
    probed[2] -= 3.0
    result = measure.reorder_landmarks(ASYMMETRIC, probed)
    assert result.order is None and "more than one landmark" in result.message


# ----------------------------------------------------------------------------- layouts


@pytest.fixture(scope="module")
def bushing():
    return isolated_bushing()


def test_place_landmarks_follows_the_thesis_rules(bushing):
    from diffsusp.models import pseudo_mcpherson

    mech = pseudo_mcpherson()
    layout = measure.place_landmarks(mech, seed=3)
    assert layout.parts == mech.parts and layout.position.shape == (4, 4, 3)
    for i in range(4):
        pts = np.asarray(layout.position[i])
        d = measure.distance_table(pts)[np.triu_indices(4, 1)]
        gaps = np.abs(d[:, None] - d[None, :])[np.triu_indices(6, 1)]
        assert gaps.min() > 2.0 and d.min() > 5.0
        s = np.linalg.svd(pts - pts.mean(0), compute_uv=False)
        assert s[1] > 0.2 * s[0]
        # near the part: within the markers' extent plus the offset
        markers = np.asarray(mech.markers.position)[np.asarray(mech.markers.part) == i]
        assert np.min(np.linalg.norm(pts[:, None] - markers[None], axis=-1)) < 400.0
    assert measure.check_layout(layout) == []
    again = measure.place_landmarks(mech, seed=3)
    np.testing.assert_array_equal(again.position, layout.position)  # deterministic


def test_layout_errors():
    with pytest.raises(InputError, match="at least three non-collinear"):
        measure.make_layout({"arm": {"a": (0, 0, 0), "b": (100, 0, 0)}})
    with pytest.raises(InputError, match="on one line"):
        measure.make_layout({"arm": {"a": (0, 0, 0), "b": (100, 0, 0), "c": (250, 0, 0)}})
    with pytest.raises(InputError, match="finite"):
        measure.make_layout({"arm": {"a": (0, 0, np.nan), "b": (1, 0, 0), "c": (0, 1, 0)}})
    with pytest.raises(InputError, match="per_part"):
        measure.place_landmarks(isolated_bushing(), per_part=2)


# ----------------------------------------------------------------------------- synthesis


@pytest.fixture(scope="module")
def synthetic(bushing):
    """Three load cases on the isolated bushing, at its centre (closed form) and at the tip."""
    force = jnp.array([[300.0, -200.0, 500.0], [0.0, 100.0, 0.0], [-50.0, 0.0, 20.0]])
    moment = jnp.array([[2e4, -1e4, 3e4], [0.0, 0.0, 5e3], [1e3, 2e3, 0.0]])
    loads = bushing.loads(forces={"centre": force}, moments={"centre": moment})
    return loads, measure.synthesize(bushing, loads, seed=0)


def test_synthesize_registers_the_solver_poses(bushing, synthetic):
    loads, meas = synthetic
    sol = diffsusp.solve_statics(bushing, loads)
    rot, trans = diffsusp.part_poses(bushing, sol.q)
    assert meas.parts == ("arm",) and meas.n_cases == 3 and meas.cases == ("1", "2", "3")
    np.testing.assert_allclose(meas.rotation, rot, atol=1e-13)
    np.testing.assert_allclose(meas.translation, trans, atol=1e-12)
    again = measure.reregister(meas)  # registration of the exact landmarks
    np.testing.assert_allclose(again.rotation, rot, atol=1e-13)
    np.testing.assert_allclose(again.translation, trans, atol=1e-10)
    assert float(jnp.max(again.rms)) < 1e-9
    np.testing.assert_allclose(meas.coordinates(bushing), sol.q, atol=1e-12)


def test_deformations_from_poses_closed_form(bushing, synthetic):
    """Load at the bushing centre: δ_T = R_Jᵀ F / K exactly (isolated_bushing docstring)."""
    loads, meas = synthetic
    delta_t, delta_r = measure.bushing_deformations(bushing, meas)
    r_j = np.asarray(reuler_deg_to_matrix(jnp.asarray(ISOLATED_BUSHING_REULER_DEG)))
    force = np.asarray(loads.force[:, 1])  # 'centre' is the second load point
    np.testing.assert_allclose(delta_t[:, 0], force @ r_j / 100.0, atol=1e-10)
    moment = np.asarray(loads.moment[:, 1])
    np.testing.assert_allclose(delta_r[:, 0], moment @ r_j / (1e4 * 180 / np.pi), atol=1e-12)


def test_noise_statistics_and_vmap(bushing, synthetic):
    _, meas = synthetic
    noise = measure.GaussianNoise(landmarks=0.05, force=2.0)
    keys = jax.random.split(jax.random.PRNGKey(0), 64)
    batch = jax.jit(jax.vmap(lambda k: measure.add_noise(meas, noise, k)))(keys)
    dev = np.asarray(batch.landmarks - meas.landmarks)
    assert dev.std() == pytest.approx(0.05, rel=0.05) and abs(dev.mean()) < 0.005
    dforce = np.asarray(batch.loads.force - meas.loads.force)
    assert dforce[:, :, 1].std() == pytest.approx(2.0, rel=0.1)  # the used load point
    assert np.all(dforce[:, :, 0] == 0.0)  # 'tip' carries no load: stays exactly 0
    # The registration rms of 4 landmarks with σ = 0.05: √((3·4 − 6)/4)·σ ≈ 0.061 mm.
    assert float(jnp.mean(batch.rms)) == pytest.approx(0.05 * np.sqrt(6 / 4), rel=0.1)
    one = measure.add_noise(meas, noise, keys[5])  # vmap equals a single call
    np.testing.assert_allclose(batch.rotation[5], one.rotation, atol=1e-13)


def test_from_landmarks_reorders_and_excludes(bushing, synthetic):
    _, meas = synthetic
    layout = meas.layout
    probed = np.array(meas.landmarks)
    probed[0, 0] = probed[0, 0, [2, 0, 3, 1]]  # case 1 probed in another order
    probed[1, 0, 3] = np.nan  # case 2: one landmark not measured
    out = measure.from_landmarks(layout, probed, meas.loads, reorder=True)
    np.testing.assert_allclose(out.rotation, meas.rotation, atol=1e-12)
    np.testing.assert_allclose(out.translation, meas.translation, atol=1e-9)
    assert float(out.weights[1, 0, 3]) == 0.0
    assert any("case 2" in n and "excluded" in n for n in out.notes)
    # a wrong point is found and left out
    wrong = np.array(meas.landmarks)
    wrong[2, 0, 1] += 3.0
    out = measure.from_landmarks(layout, wrong, meas.loads, reorder=True)
    assert float(out.weights[2, 0, 1]) == 0.0
    np.testing.assert_allclose(out.rotation[2], meas.rotation[2], atol=1e-12)
    assert any("outlier" in n for n in out.notes)


def test_from_landmarks_bad_input(bushing, synthetic):
    _, meas = synthetic
    layout, landmarks = meas.layout, np.array(meas.landmarks)
    two_left = landmarks.copy()
    two_left[2, 0, :2] = np.nan
    with pytest.raises(InputError, match=r"case 3, part 'arm': 2 usable landmark"):
        measure.from_landmarks(layout, two_left, meas.loads)
    with pytest.raises(InputError, match="3 cases but the loads have 2"):
        measure.from_landmarks(layout, landmarks, jax.tree.map(lambda a: a[:2], meas.loads))
    with pytest.raises(InputError, match="shape"):
        measure.from_landmarks(layout, landmarks[:, :, :3], meas.loads)


def test_poses_for_the_wrong_parts(bushing, synthetic):
    _, meas = synthetic
    other = measure.from_poses(("hub",), meas.rotation, meas.translation, meas.loads)
    with pytest.raises(InputError, match="no pose for part 'arm'"):
        other.coordinates(bushing)
    extra = measure.from_poses(("arm", "hub"), jnp.concatenate([meas.rotation] * 2, axis=1),
                               jnp.concatenate([meas.translation] * 2, axis=1), meas.loads)
    with pytest.raises(InputError, match="'hub' that model"):
        extra.coordinates(bushing)
    bad = np.array(meas.rotation)
    bad[1, 0] *= 1.01
    with pytest.raises(InputError, match="not a rotation matrix"):
        measure.from_poses(("arm",), bad, meas.translation, meas.loads)
    nan = np.array(meas.translation)
    nan[0, 0, 1] = np.nan
    with pytest.raises(InputError, match="translation of part 'arm' in case 1 is not finite"):
        measure.from_poses(("arm",), meas.rotation, nan, meas.loads)


def test_deformations_of_bushings_between_measured_parts_only():
    """With the strut unmeasured, the deformations of the bushings between measured parts are
    those of the full measurement; a bushing on the strut is refused by name."""
    from diffsusp.geometry import gibbs_to_matrix
    from diffsusp.models import pseudo_mcpherson

    mech = pseudo_mcpherson()
    rng = np.random.default_rng(0)
    rot = np.asarray(jax.vmap(gibbs_to_matrix)(jnp.asarray(rng.normal(0, 0.02, (8, 3)))))
    rot, trans = rot.reshape(2, 4, 3, 3), rng.normal(0, 2.0, (2, 4, 3))
    loads = mech.loads(forces={"contact_patch": jnp.zeros((2, 3))})
    full = measure.from_poses(mech.parts, rot, trans, loads)
    keep = [p for p in range(4) if mech.parts[p] != "strut"]
    part = measure.from_poses(tuple(mech.parts[p] for p in keep), rot[:, keep], trans[:, keep],
                              loads)
    ref = measure.bushing_deformations(mech, full)
    names = ("bushing_A", "bushing_B")
    got = measure.bushing_deformations(mech, part, names)
    idx = [mech.bushings.index(n) for n in names]
    for a, b in zip(got, ref, strict=True):
        np.testing.assert_allclose(a, np.asarray(b)[:, idx], atol=1e-12)
    strut_bushings = [n for n in mech.bushings.names if n not in names]
    with pytest.raises(InputError, match="has no measured pose"):
        measure.bushing_deformations(mech, part, strut_bushings)
    with pytest.raises(InputError, match="no pose for part 'strut'"):
        measure.bushing_deformations(mech, part)


def test_case_subset(synthetic):
    _, meas = synthetic
    sub = measure.case_subset(meas, [2, 0])
    assert sub.cases == ("3", "1") and sub.n_cases == 2
    np.testing.assert_array_equal(sub.rotation[0], meas.rotation[2])
    np.testing.assert_array_equal(sub.loads.force[1], meas.loads.force[0])


# ----------------------------------------------------------------------------- tables


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_tables_round_trip(bushing, synthetic, tmp_path, suffix):
    _, meas = synthetic
    marks = tmp_path / f"landmarks{suffix}"
    measure.write_measurements(meas, marks, bushing)
    back = measure.read_measurements(marks, bushing)
    assert back.cases == meas.cases and back.parts == meas.parts
    np.testing.assert_allclose(back.landmarks, meas.landmarks, atol=1e-12)
    np.testing.assert_allclose(back.rotation, meas.rotation, atol=1e-13)
    np.testing.assert_allclose(back.loads.force, meas.loads.force, atol=1e-12)
    np.testing.assert_allclose(back.loads.moment, meas.loads.moment, atol=1e-9)
    poses = measure.from_poses(meas.parts, meas.rotation, meas.translation, meas.loads)
    pose_path = tmp_path / f"poses{suffix}"
    measure.write_measurements(poses, pose_path, bushing)
    back = measure.read_measurements(pose_path, bushing)
    np.testing.assert_allclose(back.rotation, meas.rotation, atol=1e-13)
    np.testing.assert_allclose(back.translation, meas.translation, atol=1e-12)


def _csv(tmp_path, text):
    path = tmp_path / "table.csv"
    path.write_text(text)
    return path


def test_table_conventions_and_errors(bushing, tmp_path):
    from diffsusp.errors import ModelFileError

    header = "case,part,landmark,x,y,z,x0,y0,z0,tip.fz [kN]\n"
    rows = ["A,arm,p1,0,0,0,0,0,0,1.5", "A,arm,p2,100,0,0,100,0,0,", "A,arm,p3,0,80,5,0,80,5,",
            "A,arm,p4,40,30,90,40,30,90,", "B,arm,p1,1,0,0,0,0,0,2", "B,arm,p2,101,0,0,100,0,0,2",
            "B,arm,p3,1,80,5,0,80,5,2"]  # B lacks p4: not measured
    meas = measure.read_measurements(_csv(tmp_path, header + "\n".join(rows)), bushing)
    assert meas.cases == ("A", "B")
    np.testing.assert_allclose(meas.loads.force[:, 0, 2], [1500.0, 2000.0])  # kN, repeated
    np.testing.assert_allclose(meas.translation[:, 0], [[0, 0, 0], [1, 0, 0]], atol=1e-12)
    assert float(meas.weights[1, 0, 3]) == 0.0 and any("p4" in n for n in meas.notes)
    bad = rows.copy()
    bad[5] = "B,arm,p2,101,0,0,100,0,0,3"
    with pytest.raises(ModelFileError, match="has 2 and 3 in case 'B'"):
        measure.read_measurements(_csv(tmp_path, header + "\n".join(bad)), bushing)
    bad = [*rows, "B,arm,p1,1,0,0,0,0,0,2"]
    with pytest.raises(ModelFileError, match="appears twice in case 'B'"):
        measure.read_measurements(_csv(tmp_path, header + "\n".join(bad)), bushing)
    bad = rows.copy()
    bad[4] = "B,arm,p1,1,0,0,0,0,7,2"
    with pytest.raises(ModelFileError, match="same on every row"):
        measure.read_measurements(_csv(tmp_path, header + "\n".join(bad)), bushing)
    no_loads = "\n".join(",".join(r.split(",")[:-1]) for r in [header.strip(), *rows])
    with pytest.raises(ModelFileError, match="no load columns"):
        measure.read_measurements(_csv(tmp_path, no_loads), bushing)
    with pytest.raises(ModelFileError, match="unknown table format"):
        measure.read_measurements(tmp_path / "table.xlsx", bushing)
    poses = "case,part,x,y,z,psi,theta,phi [rad],fz\n1,arm,0,0,1,90,0,0,10\n2,hub,0,0,0,0,0,0,5\n"
    with pytest.raises(InputError, match="no pose of part 'hub' in case '1'"):
        measure.read_measurements(_csv(tmp_path, poses), bushing)
