"""Geometric identification from relative motion (spec geometry §4, chapter 3) on synthetic data
of the tie-rod pseudo-McPherson (`pseudo_mcpherson_steering`): one batched equilibrium solve of
the 25 steering cases (5 vertical loads × 5 rack positions) and the 17 Table 4.4 force cases.

Protocol choices (CORRECTIONS 15: the thesis does not give its amplitudes): the 5 "wheel
heights" are the vertical loads 1500–7500 N (wheel travel from about −138 to +102 mm) and the 5
rack positions −20, −10, 0, 10, 20 mm; four landmarks per measured part (front arm, rear arm,
tie rod, hub carrier; the strut and rack are not measured)."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsusp import solve_statics
from diffsusp.errors import InputError
from diffsusp.geometry import reuler_deg_to_matrix
from diffsusp.identify.geometric import GeometricJoint, correct_geometry, locate_joints
from diffsusp.measure import place_landmarks
from diffsusp.measure.measurements import from_landmarks
from diffsusp.model import Loads
from diffsusp.models import TABLE_4_4, pseudo_mcpherson_steering
from diffsusp.models._pseudo_mcpherson import PSEUDO_MCPHERSON_JOINTS as L
from diffsusp.models._pseudo_mcpherson import PSEUDO_MCPHERSON_REULER_DEG
from diffsusp.statics import part_poses

MEASURED = ("front_arm", "rear_arm", "tie_rod", "hub_carrier")
SIGMA = 0.05
SEEDS = 24

JOINTS = (  # in the order of joints_from_model (the notebook's list: one compiled program)
    GeometricJoint("tie_rod_inner", "ball_known_slide", ("ground", "tie_rod"),
                   slide=(0.0, 1.0, 0.0), elements=("tie_rod_inner",)),
    GeometricJoint("tie_rod_outer", "ball", ("tie_rod", "hub_carrier"),
                   elements=("tie_rod_outer",)),
    GeometricJoint("rear_ball_joint", "ball", ("rear_arm", "hub_carrier"),
                   elements=("rear_ball_joint",)),
    GeometricJoint("front_ball_joint", "ball", ("front_arm", "hub_carrier"),
                   elements=("front_ball_joint",)),
    GeometricJoint("bushing_B", "compliant_bushing", ("ground", "front_arm"),
                   link_ball="front_ball_joint", elements=("bushing_B",)),
    GeometricJoint("bushing_A", "ball", ("ground", "rear_arm"), elements=("bushing_A",)),
    # the strut top (bushing F) seen from the hub carrier: a ball on the chassis sliding along
    # the strut axis of the hub carrier; initial estimate 30 mm off in every coordinate
    GeometricJoint("bushing_F", "ball_unknown_slide", ("hub_carrier", "ground"),
                   prior=(L["L4"][0] - 30.0, L["L4"][1] + 30.0, L["L4"][2] - 30.0),
                   elements=("bushing_F",)),
)
TRUTH = {"front_ball_joint": L["L8"], "rear_ball_joint": L["L7"], "tie_rod_outer": L["L6"],
         "tie_rod_inner": L["L3"], "bushing_A": L["L2"], "bushing_B": L["L1"],
         "bushing_F": L["L4"]}


def _loads(n):
    return Loads(force=np.zeros((n, 1, 3)), moment=np.zeros((n, 1, 3)),
                 driver=np.zeros((n, 0)))


@pytest.fixture(scope="module")
def solved():
    """The 42 equilibria of the truth model (one batched solve)."""
    mech = pseudo_mcpherson_steering()
    fz, rack = np.meshgrid([1500.0, 3000, 4500, 6000, 7500], [-20.0, -10, 0, 10, 20],
                           indexing="ij")
    force = np.zeros((42, 3))
    force[:25, 2] = fz.ravel()
    force[25:] = np.asarray(TABLE_4_4)[:, [2, 1, 0]]
    rack_travel = np.concatenate([rack.ravel(), np.zeros(17)])
    loads = mech.loads(forces={"contact_patch": force}, drivers={"rack_travel": rack_travel})
    sol = solve_statics(mech, loads)
    rot, trans = part_poses(mech, sol.q)
    return mech, loads, np.asarray(rot), np.asarray(trans)


@pytest.fixture(scope="module")
def data(solved):
    """Landmarks of the 42 equilibria."""
    mech, _, rot, trans = solved
    index = [mech.parts.index(p) for p in MEASURED]
    layout = place_landmarks(mech, 4, parts=MEASURED, seed=0)
    landmarks = np.einsum("cpij,pkj->cpki", np.asarray(rot)[:, index],
                          np.asarray(layout.position)) + np.asarray(trans)[:, index, None]
    return layout, landmarks


@pytest.fixture(scope="module")
def steering(data):
    layout, landmarks = data
    meas = from_landmarks(layout, landmarks[:25], _loads(25))
    return layout, landmarks[:25], locate_joints(meas, JOINTS)


def _error(report, name):
    return float(np.linalg.norm(report[name].estimate - np.asarray(TRUTH[name])))


def test_noise_free_kinematic_joints_exact(steering):
    _, _, report = steering
    for name in ("front_ball_joint", "rear_ball_joint", "tie_rod_outer", "tie_rod_inner"):
        assert report[name].observable, report[name].note
        assert _error(report, name) < 1e-6, (name, _error(report, name))
        assert report[name].residual < 1e-9
    np.testing.assert_allclose(report["tie_rod_inner"].axis, [0, 1, 0], atol=1e-15)


def test_noise_free_bushings_within_a_few_mm(steering):
    """Table 3.1 (thesis: A 0.99 mm, B 3.20 mm, F 6.95 mm with the strut axis 2.7 mm off).
    Measured here: A 3.98 mm (a stiff bushing taken as a ball: its 1370 N/mm axial direction
    deflects under the arm load), B 0.67 mm (axial-only compliant link with R^c·u; σ up to
    6.2 mm from 25 cases, observable within the 10 mm tolerance; its equations fit, χ²/E
    0.02),
    F 4.82 mm with the axis 0.28° from the strut slide and the located line 1.78 mm from the
    true slide axis (thesis: 2.7 mm); the located centre is 2.09 mm off the slide axis through
    L5 (Table 2.2 puts L4 itself 2.38 mm off it)."""
    _, _, report = steering
    errors = {n: _error(report, n) for n in ("bushing_A", "bushing_B", "bushing_F")}
    assert errors["bushing_A"] == pytest.approx(3.98, abs=0.05)
    assert errors["bushing_B"] == pytest.approx(0.67, abs=0.05)
    assert errors["bushing_F"] == pytest.approx(4.82, abs=0.05)
    assert report["bushing_B"].observable and report["bushing_B"].chi2 < 0.1
    assert report["bushing_A"].chi2 > 1.5  # the stiff bushing deflects: a lack of fit
    strut = report["bushing_F"]
    assert strut.observable
    z5 = np.asarray(reuler_deg_to_matrix(np.array(PSEUDO_MCPHERSON_REULER_DEG["L5"])))[:, 2]
    angle = np.degrees(np.arccos(abs(strut.axis @ z5)))
    assert angle < 0.5
    # the identified strut line against the true slide axis through L5
    d = strut.centre - np.asarray(L["L5"])
    assert np.linalg.norm(d - (d @ z5) * z5) == pytest.approx(2.09, abs=0.02)
    n = np.cross(strut.axis, z5)
    assert abs(d @ n) / np.linalg.norm(n) == pytest.approx(1.78, abs=0.02)


def test_sigma_against_monte_carlo(steering):
    """σ = 0.05 mm on every landmark coordinate, 24 seeds: the Monte-Carlo spread of every
    located coordinate agrees with the reported σ (closed form, `_uncertainty`) within a factor
    1.5, and the noisy equations of the kinematic joints fit at the noise level (χ²/E ≈ 1)."""
    layout, landmarks, report = steering
    rng = np.random.default_rng(7)
    draws, chi2 = [], []
    for _ in range(SEEDS):
        noisy = landmarks + rng.normal(scale=SIGMA, size=landmarks.shape)
        rep = locate_joints(from_landmarks(layout, noisy, _loads(25)), JOINTS)
        draws.append([j.estimate for j in rep.joints])
        chi2.append([j.chi2 for j in rep.joints[:4]])
    spread = np.std(np.array(draws), axis=0, ddof=1)
    sigma = np.array([j.sigma for j in report.joints])
    ratio = spread / sigma
    assert np.all((ratio > 1 / 1.5) & (ratio < 1.5)), ratio
    np.testing.assert_allclose(np.mean(chi2, axis=0), 1.0, atol=0.15)


def test_strut_top_not_observable_without_steering(data):
    """Table 4.4's 17 force cases, no steering: the strut top is not observable (the thesis
    found it 175 mm off, spec geometry §4.8); the kinematic joints still are."""
    layout, landmarks = data
    meas = from_landmarks(layout, landmarks[25:], _loads(17))
    report = locate_joints(meas, JOINTS)
    strut = report["bushing_F"]
    assert not strut.observable and strut.centre is None
    assert "not observable" in str(report) and "lack of fit" in strut.note
    # noise-free, 15 mm off: its equations fit 5.5 times worse than landmark noise would
    # explain (bushing F deflects), which inflates its σ (8.4 mm) beyond the 10 mm tolerance
    assert strut.chi2 > 3 and 5 < strut.sigma.max() < 10 and _error(report, "bushing_F") > 10
    for name in ("front_ball_joint", "rear_ball_joint", "tie_rod_outer"):
        assert report[name].observable and _error(report, name) < 1e-6


def test_bushing_pair_axis_on_a_model():
    """The bushing-pair solver (3.14–3.16) on simulated landmarks of a model whose arms sit on
    two bushings each (`double_wishbone_bushing_pairs`, wheel travel −60…+60 mm): noise-free,
    each pair's axis is the line through its two bushing centres to < 1e-6 rad and the point
    with the prior's x is that bushing's centre (the pair cannot be told apart along the
    axis: CORRECTIONS 17); with 0.05 mm noise (20 seeds) the reported σ of the point and of
    the axis agree with the Monte-Carlo spread within a factor 1.5."""
    from diffsusp.models import double_wishbone_bushing_pairs
    from diffsusp.models._double_wishbone import HARDPOINTS as P

    mech = double_wishbone_bushing_pairs()
    # structure as documented: n = 18, 7 joint rows and the driver, each pair's frames along
    # front − back
    assert 6 * len(mech.parts) == 18 and mech.joints.n_rows + len(mech.drivers.names) == 8
    ori = np.asarray(mech.markers.orientation)
    for k, name in enumerate(mech.bushings.names):
        arm = name.split("_")[0]
        axis = np.subtract(P[f"{arm}_chassis_front"], P[f"{arm}_chassis_back"])
        np.testing.assert_allclose(ori[mech.bushings.j_marker[k]][:, 2],
                                   axis / np.linalg.norm(axis), atol=1e-15)
    travel = np.array([-60.0, -40, -20, 0, 20, 40, 60])
    loads = mech.loads(drivers={"wheel_travel": travel})
    rot, trans = (np.asarray(a) for a in part_poses(mech, solve_statics(mech, loads).q))
    parts = ("upper_control_arm", "lower_control_arm")
    layout = place_landmarks(mech, 4, parts=parts, seed=2)
    index = [mech.parts.index(p) for p in parts]
    marks = np.einsum("cpij,pkj->cpki", rot[:, index], np.asarray(layout.position))
    marks += trans[:, index, None]
    joints = [GeometricJoint(f"{arm}_{end}", "revolute", ("ground", part),
                             prior=P[f"{arm}_chassis_{end}"], prior_coordinate="x")
              for arm, part, end in (("lca", "lower_control_arm", "front"),
                                     ("lca", "lower_control_arm", "back"),
                                     ("uca", "upper_control_arm", "front"))]
    n = len(travel)
    report = locate_joints(from_landmarks(layout, marks, _loads(n)), joints)
    for j in report.joints:
        arm, end = j.name.split("_")
        truth = np.subtract(P[f"{arm}_chassis_front"], P[f"{arm}_chassis_back"])
        assert j.observable, j.note
        assert np.linalg.norm(np.cross(j.axis, truth / np.linalg.norm(truth))) < 1e-6
        np.testing.assert_allclose(j.centre, P[f"{arm}_chassis_{end}"], atol=1e-6)
        assert j.singular_values[2] < 1e-9 * j.singular_values[0]  # the axis: the null one
    rng = np.random.default_rng(5)
    draws = []
    for _ in range(20):
        noisy = marks + rng.normal(scale=SIGMA, size=marks.shape)
        rep = locate_joints(from_landmarks(layout, noisy, _loads(n)), joints)
        draws.append([np.concatenate([j.estimate[1:], j.axis]) for j in rep.joints])
    spread = np.std(np.array(draws), axis=0, ddof=1)
    sigma = np.array([np.concatenate([j.sigma[1:], j.sigma_axis]) for j in report.joints])
    assert np.all(report.joints[0].sigma[0] == 0.0)  # x is the prior's
    ratio = spread / sigma
    assert np.all((ratio > 1 / 1.5) & (ratio < 1.5)), ratio


def test_revolute_axis_and_prior():
    """A part turning about a known axis (a wishbone on its two bushings taken as a revolute,
    Table 3.3's axis and point): axis to 1e-12 rad (1e-6 rad required), the point
    along the axis from the prior's x (as the thesis fixed X = 177.00)."""
    axis = np.array([0.997, 0.081, 0.009])
    axis /= np.linalg.norm(axis)
    point = np.array([177.00, -351.03, 195.11])
    layout_points = point + np.array([[0, -300, -10], [40, -250, 20], [-60, -200, 5],
                                      [10, -320, 40.0]])
    from diffsusp.geometry import axis_angle_to_matrix
    from diffsusp.measure.landmarks import LandmarkLayout

    angles = np.radians([-8.0, -4.0, 0.0, 3.0, 6.0, 9.0])
    rots = np.stack([np.asarray(axis_angle_to_matrix(axis, a)) for a in angles])
    measured = np.einsum("cij,kj->cki", rots, layout_points - point) + point
    layout = LandmarkLayout(position=np.asarray(layout_points)[None], parts=("wishbone",),
                            names=(("a1", "a2", "a3", "a4"),))
    meas = from_landmarks(layout, measured[:, None], _loads(len(angles)))
    joint = GeometricJoint("wishbone_pivot", "revolute", ("ground", "wishbone"),
                           prior=(177.0, 0.0, 0.0), prior_coordinate="x")
    rep = locate_joints(meas, [joint], with_sigma=False)  # (a smaller program to compile)
    j = rep["wishbone_pivot"]
    assert j.observable
    assert np.linalg.norm(np.cross(j.axis, axis)) < 1e-12  # sine of the angle
    np.testing.assert_allclose(j.centre, point, atol=1e-9)
    # without the coordinate: the point of the axis nearest to the prior
    prior = point + 25.0 * axis + np.array([0.0, 3.0, -4.0])
    rep = locate_joints(meas, [GeometricJoint("p", "revolute", ("ground", "wishbone"),
                                              prior=tuple(prior))], with_sigma=False)
    nearest = point + axis * (axis @ (prior - point))
    np.testing.assert_allclose(rep["p"].centre, nearest, atol=1e-9)
    # from poses instead of landmarks (no σ then), and the report's rows
    from diffsusp.measure import from_poses

    trans = point - np.einsum("cij,j->ci", rots, point)
    posed = from_poses(("wishbone",), rots[:, None], trans[:, None], _loads(len(angles)))
    rep = locate_joints(posed, [joint])
    assert np.linalg.norm(np.cross(rep["wishbone_pivot"].axis, axis)) < 1e-12
    np.testing.assert_allclose(rep["wishbone_pivot"].centre, point, atol=1e-9)
    assert np.all(np.isnan(rep["wishbone_pivot"].sigma))
    (row,) = rep.joint_rows()
    assert row["joint"] == "wishbone_pivot" and row["observable"] and row["x"] == 177.0
    # the report base's rows: the line cut at the prior's x, x itself the prior's
    # (not determined), the axis' y and z components; poses only: consistency not checked
    rows = {r["parameter"]: r for r in rep.rows()}
    assert list(rows) == [f"wishbone_pivot.{c}" for c in ("x", "y", "z", "axis_y", "axis_z")]
    assert rows["wishbone_pivot.x"]["status"] == "not determined"
    assert "along the axis not observable" in rows["wishbone_pivot.x"]["reason"]
    assert rows["wishbone_pivot.y"]["estimate"] == pytest.approx(point[1], abs=1e-9)
    assert rows["wishbone_pivot.axis_z"]["estimate"] == pytest.approx(axis[2], abs=1e-12)
    assert rep.consistency is None and "not checked" in rep.fit_verdict


def test_bad_input(data):
    layout, landmarks = data
    meas = from_landmarks(layout, landmarks[:3], _loads(3))
    with pytest.raises(InputError, match="part 'strut', which has no measured pose"):
        locate_joints(meas, [GeometricJoint("top", "ball", ("strut", "ground"))])
    with pytest.raises(InputError, match="unknown kind"):
        GeometricJoint("x", "hinge", ("ground", "tie_rod"))
    with pytest.raises(InputError, match="needs prior"):
        GeometricJoint("x", "revolute", ("ground", "tie_rod"))
    with pytest.raises(InputError, match="link_ball 'nope' is not in the joint list"):
        locate_joints(meas, [GeometricJoint("b", "compliant_bushing", ("ground", "front_arm"),
                                            link_ball="nope")])
    # parts that never move relative to each other: explicit "not observable" (25 cases: the
    # compiled program of the other tests)
    still = np.broadcast_to(layout.position, landmarks[:25].shape)
    rep = locate_joints(from_landmarks(layout, still, _loads(25)), JOINTS)
    for j in rep.joints:
        assert not j.observable and j.centre is None
        assert "never move" in j.note, j.note
    # a part with fewer than 3 landmarks, or collinear ones: the registration refuses it
    bad = landmarks[:3].copy()
    bad[1, 0, 1:] = np.nan
    with pytest.raises(InputError, match="case 2, part 'front_arm': 1 usable landmark"):
        from_landmarks(layout, bad, _loads(3))
    line = np.array(layout.position)
    line[0] = line[0, 0] + np.arange(4)[:, None] * np.array([10.0, 2.0, -3.0])
    collinear = eqx.tree_at(lambda lay: lay.position, layout, jnp.asarray(line))
    with pytest.raises(InputError, match="part 'front_arm' has 4 landmark.s. on one line"):
        from_landmarks(collinear, landmarks[:3], _loads(3))


# ---------------------------------------------------------------- chapter 2: correction

RACK_ZERO = [2, 7, 12, 17, 22]  # the 5 vertical loads 1500–7500 N at rack 0 in the 42 cases
REFERENCE = 12  # 4500 N, rack 0


def _toe(mech, rot):
    """Toe (deg) of the wheel spin axis (z of L9) from the hub carrier's rotations."""
    z9 = np.asarray(reuler_deg_to_matrix(np.array(PSEUDO_MCPHERSON_REULER_DEG["L9"])))[:, 2]
    spin = np.asarray(rot)[:, mech.parts.index("hub_carrier")] @ z9
    return np.degrees(np.arctan2(spin[:, 0], -spin[:, 1]))


def test_correction_reproduces_measured_poses_and_improves_toe(solved, data):
    """Bolted-side (I) markers of every joint and bushing displaced by 0.5–1 mm; corrected
    against the measured poses at 4500 N (spec geometry §3.8): the pose error goes below
    1e-3 mm after a few re-solve/re-correct passes (one pass is not exact), and the toe curve
    over 1500–7500 N moves toward the truth (measured: RMS 0.26° → 0.004°)."""
    truth, loads, rot, _ = solved
    layout, landmarks = data
    # all 42 measured cases (the batched solve of each pass is the fixture's program)
    meas = from_landmarks(layout, landmarks, loads)
    rng = np.random.default_rng(1)
    pos = np.array(truth.markers.position)
    for group in (truth.joints, truth.bushings):
        for i in group.i_marker:
            v = rng.normal(size=3)
            pos[i] += v / np.linalg.norm(v) * rng.uniform(0.5, 1.0)
    perturbed = eqx.tree_at(lambda m: m.markers.position, truth, jnp.asarray(pos))
    # the default stop (tol=None): below 1e-4 mm on these exact poses, as the former tol
    corrected, report = correct_geometry(perturbed, meas, case=REFERENCE)
    assert report.converged and report.pose_errors[-1] < 1e-4 and not report.notes
    assert report.pose_errors[0] > 1.0 and report.pose_errors[1] > 1e-3  # one pass: not exact
    assert report.iterations <= 8
    assert "bushing_A.i" in report.moves and 0.4 < report.moves["bushing_A.i"] < 1.2
    # away from the reference case the corrected model is not exact, but far better than the
    # perturbed one (whose error at the reference was 1.4 mm)
    assert report.case_errors[REFERENCE] < 1e-3
    assert 1e-3 < max(report.case_errors) < 0.5
    # an independent check of the corrected model: its equilibria
    q = solve_statics(corrected, loads).q[REFERENCE]
    r_c, t_c = part_poses(corrected, q)
    for k, part in enumerate(MEASURED):
        p = corrected.parts.index(part)
        pts = np.asarray(layout.position[k])
        err = pts @ (np.asarray(r_c[p]) - np.asarray(meas.rotation[REFERENCE, k])).T + (
            np.asarray(t_c[p]) - np.asarray(meas.translation[REFERENCE, k]))
        assert np.max(np.linalg.norm(err, axis=1)) < 1e-3
    toe = {}
    for name, mech in (("perturbed", perturbed), ("corrected", corrected)):
        r, _ = part_poses(mech, solve_statics(mech, loads).q)
        toe[name] = _toe(mech, r)[RACK_ZERO]
    toe_truth = _toe(truth, rot)[RACK_ZERO]
    rms = {k: float(np.sqrt(np.mean((v - toe_truth) ** 2))) for k, v in toe.items()}
    assert rms["corrected"] < 0.1 * rms["perturbed"], rms
    # Noisy landmarks (σ = 0.05 mm) on every part, the strut too: its ideal joints cannot
    # match noisy poses of all four, so 1e-4 mm is out of reach. By default the correction
    # stops when a pass no longer lowers the error (the noise floor), converged, and says so;
    # an absolute tol keeps correcting noise and reports NOT converged.
    parts = MEASURED + ("strut",)
    index = [truth.parts.index(p) for p in parts]
    every = place_landmarks(truth, 4, parts=parts, seed=0)
    marks = np.einsum("cpij,pkj->cpki", rot[:, index], np.asarray(every.position)) + np.asarray(
        solved[3])[:, index, None]
    noise = np.random.default_rng(7).normal(scale=0.05, size=marks.shape)
    noisy = dataclasses.replace(from_landmarks(every, marks + noise, loads), sigma=0.05)
    _, rep = correct_geometry(perturbed, noisy, case=REFERENCE, max_iterations=8)
    err = rep.pose_errors
    assert rep.converged and rep.iterations < 8 and 1e-4 < err[-1] < 10 * 0.05 < err[0], err
    assert err[-2] - err[-1] < 0.1 * 0.05 and "noise floor" in rep.notes[0], rep
    _, strict = correct_geometry(perturbed, noisy, case=REFERENCE, tol=1e-4,
                                 max_iterations=rep.iterations)
    assert not strict.converged and "tol 0.0001 mm" in strict.notes[0]


def test_correction_bad_input(solved, data):
    truth, loads, _, _ = solved
    layout, landmarks = data
    meas = from_landmarks(layout, landmarks[:3], jax.tree.map(lambda a: a[:3], loads))
    with pytest.raises(InputError, match="case 5 is out of range"):
        correct_geometry(truth, meas, case=5)
    with pytest.raises(InputError, match="element 'nope' is not a joint or bushing"):
        correct_geometry(truth, meas, ["nope"])


def test_design_of_cases(solved, data):
    """The stiffness design's greedy search (`design_experiment`, criterion "sigma") picks among
    the 42 candidate load cases (25 steering + 17 force cases) of the model: four cases with
    steering make every joint observable (measured: cases 4, 1, 20, 36; largest σ 4.5 mm, the
    tie rod's inner joint; bushing B 4.3 mm). After 17 greedy steps, the design's σ (the
    generalised least-squares bound) agrees with what `locate_joints` reports from the same 17
    cases within a factor 1.5 for every joint but the strut top (the design leaves out the
    design position, which the localisation puts on the strut line: it is pessimistic
    there, 2.8 mm against 1.6 mm after four cases)."""
    from diffsusp.identify.geometric import design_geometry_cases, element_table

    mech, loads, _, _ = solved
    layout, landmarks = data
    design = design_geometry_cases(mech, loads, JOINTS, layout, budget=17)
    assert design.complete and len(design.cases) <= 4
    assert any(c < 25 and c % 5 != 2 for c in design.cases)  # a case with the rack moved
    assert all(s <= 10.0 for s in design.sigma.values())
    assert list(design.history) == sorted(design.history, reverse=True)
    report = design.report
    assert report.chosen[: len(design.cases)] == design.cases and len(report.chosen) == 17
    cases = list(report.chosen)
    located = locate_joints(from_landmarks(layout, landmarks[cases], _loads(17)), JOINTS)
    table = element_table(mech)
    for j, joint in zip(located.joints, JOINTS, strict=True):
        if j.kind != "ball_unknown_slide":
            centre = mech.markers.names[table[joint.elements[0]][4]]
            cols = [t for t, name in enumerate(report.targets) if name.startswith(centre + ".")]
            ratio = j.sigma.max() / np.max(report.sigma[16][cols])
            assert 1 / 1.5 < ratio < 1.5, (j.name, ratio)


def test_joint_files_and_figure(solved, steering, tmp_path):
    """`write_joints` (CSV and JSON), `read_joints` (the joint list round trip and its errors)
    and `GeometricReport.plot` on the located joints of the steering cases."""
    import csv
    import json

    from diffsusp.errors import ModelFileError
    from diffsusp.identify.geometric import read_joints, write_joints

    mech, report = solved[0], steering[2]
    write_joints(report, tmp_path / "joints.csv")
    with open(tmp_path / "joints.csv", newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert [r["joint"] for r in rows] == [j.name for j in report.joints]
    for row, j in zip(rows, report.joints, strict=True):
        if j.centre is None:
            assert row["x"] == ""
        else:
            np.testing.assert_allclose([float(row[c]) for c in "xyz"], j.centre, rtol=1e-12)
    write_joints(report, tmp_path / "joints.json")
    assert json.loads((tmp_path / "joints.json").read_text()) == json.loads(report.to_json())

    listed = [{k: list(v) if isinstance(v, tuple) else v
               for k, v in dataclasses.asdict(j).items()} for j in JOINTS]
    (tmp_path / "list.json").write_text(json.dumps(listed))
    assert read_joints(tmp_path / "list.json") == tuple(JOINTS)
    (tmp_path / "bad.json").write_text(json.dumps([listed[0], {"name": "x", "kind": "hinge",
                                                               "parts": ["a", "b"]}]))
    with pytest.raises(ModelFileError, match="joint 2"):
        read_joints(tmp_path / "bad.json")
    (tmp_path / "obj.json").write_text("{}")
    with pytest.raises(ModelFileError, match="JSON list"):
        read_joints(tmp_path / "obj.json")

    fig = report.plot(mech, JOINTS)
    located = sum(j.centre is not None for j in report.joints)
    modelled = sum(len(j.elements) for j in JOINTS)
    for ax in fig.axes:
        assert len(ax.containers) == located
        assert sum(len(line.get_xdata()) for line in ax.lines
                   if line.get_marker() == "o") == modelled


def test_compliant_bushing_taken_as_a_ball(solved, steering):
    """The stiff bushing A located as a ball is 3.98 mm off (its axial direction
    deflects under the arm load) with a noise σ of 0.06 mm. Without the model it is flagged
    "not determined (compliant: …)"; with the model (its own equilibria at the 25 steering
    cases located the same way: the compliance bias) its σ carries the bias and the truth is
    within 3σ of every coordinate called identified — and the ideal ball joints keep their
    noise σ (zero bias, identified). The registration of exact landmarks is consistent."""
    mech, loads = solved[0], solved[1]
    layout, landmarks, report = steering
    rows = {r["parameter"]: r for r in report.rows()}
    for c in "xyz":
        row = rows[f"bushing_A.{c}"]
        assert row["status"] == "not determined" and row["reason"].startswith("compliant"), row
        assert rows[f"front_ball_joint.{c}"]["status"] == "identified"
    assert report.consistency.consistent and report.consistency.chi2 < 1e-6
    n = 25
    cases = jax.tree.map(lambda a: a[:n], loads)
    meas = from_landmarks(layout, landmarks, _loads(n))
    carried = locate_joints(meas, JOINTS, model=mech, loads=cases)
    est = {r["parameter"]: r for r in carried.rows()}
    truth = np.asarray(TRUTH["bushing_A"])
    error = np.array([est[f"bushing_A.{c}"]["estimate"] for c in "xyz"]) - truth
    sigma = np.array([est[f"bushing_A.{c}"]["sigma"] for c in "xyz"])
    assert np.linalg.norm(error) > 3.5  # the bias is real
    for c, e, s in zip("xyz", error, sigma, strict=True):
        if est[f"bushing_A.{c}"]["status"] == "identified":
            assert abs(e) <= 3 * s, (c, e, s)
    assert np.all(np.abs(error) <= 3 * sigma), (error, sigma)
    for c in "xyz":
        row = est[f"front_ball_joint.{c}"]
        assert row["status"] == "identified" and row["sigma"] == pytest.approx(
            rows[f"front_ball_joint.{c}"]["sigma"], rel=1e-6)
