"""Least-squares identification through the equilibrium: spec stiffness §6 item 8 (gradient-based
identification, covariance, equivalent solutions), §2.8 (σ = 0.05 mm landmarks), §3
perspective 2 (joint stiffness + hardpoint identification), §7 R5 (the pseudo-McPherson from
10⁴ N/mm and 10⁴ N·mm/deg, the 13 cases of Table 5-1).

Compiled programs are shared: every pseudo-McPherson fit of ≤ 16 parameters reuses one
equilibrium program (the costly one), the batched fits one more.
"""

import math
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffsusp
from diffsusp.errors import InputError
from diffsusp.identify import (
    least_squares,
    least_squares_batch,
    predict,
    whitened_residuals,
)
from diffsusp.identify.data import Channel, Deformations, Landmarks, Poses
from diffsusp.identify.params import AXES, Params
from diffsusp.lsq import robust as _robust
from diffsusp.models import isolated_bushing, pseudo_mcpherson, thesis_load_cases

DEG = math.pi / 180
SIGMA = 0.05  # mm: the thesis's portable-arm landmark noise (spec stiffness §2.8)
A_B = ("bushing_A", "bushing_B")
R5_START = (1e4,) * 3 + (1e4 / DEG,) * 3  # spec §2.6: 10⁴ N/mm and 10⁴ N·mm/deg


def _landmark_points(mech):
    """Four targets on each measured part (the thesis measures 4 markers per part; the strut is
    not measured): two along the part's hardpoint line and two off it."""
    pos = np.asarray(mech.markers.position)
    lines = {"front_arm": ("L1_front_arm_bushing", "L8_front_arm_ball"),
             "rear_arm": ("L2_rear_arm_bushing", "L7_rear_arm_ball"),
             "hub_carrier": ("L5_strut_base", "wheel_centre")}
    parts, points = [], []
    for part, (a, b) in lines.items():
        pa, pb = pos[mech.markers.index(a)], pos[mech.markers.index(b)]
        mid = 0.5 * (pa + pb)
        for p in (0.8 * pa + 0.2 * pb, 0.2 * pa + 0.8 * pb, mid + [0.0, 0.0, 40.0],
                  mid + [40.0, 0.0, 0.0]):
            parts.append(part)
            points.append(p)
    return tuple(parts), np.array(points)


@pytest.fixture(scope="module")
def mcpherson():
    ref = pseudo_mcpherson()
    loads = thesis_load_cases(ref)
    parts, points = _landmark_points(ref)
    template = Landmarks(loads, parts, points, np.zeros((13, len(parts), 3)), SIGMA)
    true = np.asarray(predict(ref, template)["landmarks"])
    params = Params.bushing_stiffness(ref, A_B)
    start = params.with_start(np.tile(R5_START, 2))

    def landmarks(measured, mask=None):
        return Landmarks(loads, parts, points, measured, SIGMA, mask=mask)

    return SimpleNamespace(ref=ref, loads=loads, parts=parts, points=points, true=true,
                           params=params, start=start, truth=np.asarray(params.values(ref)),
                           landmarks=landmarks)


@pytest.fixture(scope="module")
def r5(mcpherson):
    """Spec §7 R5 start, noiseless landmarks of the reference model."""
    m = mcpherson
    records = []
    fitted, report = least_squares(m.ref, m.landmarks(m.true), m.start,
                                   callback=lambda k, r: records.append((k, r)))
    return fitted, report, records


# ----------------------------------------------------------------------------- R5, noiseless


def test_r5_noiseless_recovers_every_identifiable_stiffness_and_names_the_rest(mcpherson, r5):
    m = mcpherson
    fitted, report, _ = r5
    assert report.converged, report.message
    assert report.chi2 < 1e-12
    ok = report.identifiable
    rel = np.abs(report.estimate / m.truth - 1.0)
    assert np.all(rel[ok] < 1e-6), dict(zip(np.array(report.names)[ok], rel[ok], strict=True))
    # The thesis's findings (§2.7): Ktx of A and B, along the arms, are the influential
    # parameters, determined best; Krx of both is never identified.
    for name in ("bushing_A.Ktx", "bushing_B.Ktx"):
        assert report.sigma_percent[report.names.index(name)] < 2.0
    assert {"bushing_A.Krx", "bushing_B.Krx"} <= set(report.unidentifiable)
    assert len(report.unidentifiable) < len(report.names)
    # Each unidentifiable parameter belongs to a named combination the data cannot see.
    assert report.null_space
    named = " ".join(d.text for d in report.null_space)
    assert all(n in named for n in report.unidentifiable)
    assert all(d.sigma > 1.0 for d in report.null_space)
    # The fitted mechanism carries the estimates; the table marks the unidentifiable ones.
    # ... except a parameter the data do not see, which keeps its start value
    seen = ~np.isin(report.names, report.unidentifiable)
    np.testing.assert_array_equal(np.asarray(Params.bushing_stiffness(fitted, A_B).start),
                                  np.where(seen, report.estimate, report.start))
    table = report.table()
    rows = {line.split()[0]: line for line in table.splitlines()[1:1 + len(report.names)]}
    for name, verdict in zip(report.names, report.verdicts, strict=True):
        seen = name not in report.unidentifiable
        assert rows[name].endswith("not determined: not seen by the data") != seen
        assert rows[name].endswith(" identified") == (verdict == "identified")
    assert "not seen by the data (σ of the combination)" in table


def test_r5_trial_steps_without_equilibrium_are_rejected(mcpherson, r5):
    """The first Gauss–Newton steps from 10⁴ overshoot to stiffnesses where some load cases
    have no equilibrium: those trials get 1e8 residuals, are rejected, and the fit goes on."""
    m = mcpherson
    _, report, records = r5
    failed = [r for r in report.history if r.failed_cases > 0]
    assert failed and not any(r.accepted for r in failed)
    assert report.converged
    # Independent check of one such trial: the model there really has no equilibrium.
    with pytest.raises(InputError, match="no equilibrium"):
        predict(m.params.apply(m.ref, jnp.asarray(failed[0].trial)), m.landmarks(m.true))
    # The callback saw every step, in order.
    assert [k for k, _ in records] == list(range(len(report.history)))
    assert records[-1][1] == report.history[-1]


# ----------------------------------------------------------------------------- noise


def _noisy(m, seed, n_sets=None):
    rng = np.random.default_rng(seed)
    shape = m.true.shape if n_sets is None else (n_sets, *m.true.shape)
    return m.true + SIGMA * rng.normal(size=shape)


def _well_determined(report, limit=0.3):
    """Log-scaled parameters whose relative σ is below `limit` (the prior has no say)."""
    return np.asarray(report.sigma / report.estimate < limit)


def test_robust_loss_rejects_a_gross_outlier_that_ruins_the_plain_fit(mcpherson):
    m = mcpherson
    measured = _noisy(m, seed=7)
    case, point = 9, 1  # near bushing B on the front arm, under a braking load
    clean_measured = measured.copy()
    measured[case, point, 0] += 5.0  # a 5 mm gross error (100 σ)
    # Nominal stiffnesses as a weak prior (σ 100 %): the unidentifiable ones stay bounded.
    kw = dict(prior=m.truth, prior_sigma=m.truth)
    start = m.params.with_start(m.truth)
    _, clean = least_squares(m.ref, m.landmarks(clean_measured), start, **kw)
    _, plain = least_squares(m.ref, m.landmarks(measured), start, **kw)
    _, robust = least_squares(m.ref, m.landmarks(measured), start, loss="cauchy", **kw)
    mask = np.ones(m.true.shape[:2], bool)
    mask[case, point] = False
    _, masked = least_squares(m.ref, m.landmarks(measured, mask=mask), start, **kw)
    assert plain.converged and robust.converged and masked.converged
    good = _well_determined(clean)
    # The prior holds what the data cannot see: B's Krx stays within its prior σ of the
    # nominal value, and its posterior σ is at most the prior's.
    k = clean.names.index("bushing_B.Krx")
    assert not clean.identifiable[k]
    assert abs(math.log(clean.estimate[k] / m.truth[k])) < 1.0
    assert clean.sigma[k] / clean.estimate[k] <= 1.0 + 1e-9

    def shift(report):  # distance from the outlier-free fit, in σ of log θ
        sig = clean.sigma / clean.estimate
        return np.abs(np.log(report.estimate / clean.estimate))[good] / sig[good]

    assert shift(plain).max() > 3.0  # ruined
    assert shift(robust).max() < 0.5  # rejected
    assert shift(masked).max() < 0.5  # missing value
    # The report points at the outlier: ~100 σ, the largest residual of the robust fit.
    outliers = robust.outliers(threshold=10.0)
    assert [(o[0], o[1]) for o in outliers] == [("landmarks", (case, point, 0))]
    assert 90 < -outliers[0][2] < 110  # model − measured: the point was measured 5 mm high
    assert masked.n_residuals == clean.n_residuals - 3
    assert masked.residuals["landmarks"].whitened[case, point].tolist() == [0.0, 0.0, 0.0]


def test_batched_monte_carlo_spread_matches_the_reported_sigma(mcpherson):
    """50 noise draws of σ = 0.05 mm identified in one vmapped program per LM step: the spread
    of the estimates matches the linearised σ within a factor 1.5. The parameters are the six
    stiffnesses the landmarks determine well (the others held at their nominal values, so no
    prior is needed and σ is the data's alone); the batch equals a single fit of one set."""
    m = mcpherson
    n_sets = 50
    params = (Params.bushing_stiffness(m.ref, ["bushing_A"], axes=("Ktx", "Ktz", "Kry", "Krz"))
              + Params.bushing_stiffness(m.ref, ["bushing_B"], axes=("Ktx", "Krz")))
    truth = np.asarray(params.values(m.ref))
    data = m.landmarks(_noisy(m, seed=100, n_sets=n_sets))
    batch = least_squares_batch(m.ref, data, params)
    assert batch.converged.all()
    assert batch.estimates.shape == batch.sigma.shape == (n_sets, len(params))
    assert all(r.identifiable.all() for r in batch.reports)
    log_sigma = (batch.sigma / batch.estimates).mean(axis=0)
    spread = np.log(batch.estimates).std(axis=0, ddof=1)
    ratio = spread / log_sigma
    assert np.all((ratio > 1 / 1.5) & (ratio < 1.5)), dict(zip(params.names, ratio, strict=True))
    # Unbiased to within the Monte-Carlo error of the mean.
    bias = np.abs(np.log(batch.estimates).mean(axis=0) - np.log(truth))
    assert np.all(bias < 4 * log_sigma / math.sqrt(n_sets))
    # χ² per degree of freedom ≈ 1 with the true σ.
    chi2 = np.array([r.chi2 / r.dof for r in batch.reports])
    assert 0.9 < chi2.mean() < 1.1
    # vmap equals the loop: data set 3 alone.
    _, single = least_squares(m.ref, data.select(3), params)
    np.testing.assert_allclose(single.estimate, batch.estimates[3], rtol=1e-6)


# ----------------------------------------------------------------------------- joint fit


def test_joint_stiffness_and_bushing_centre_fit(mcpherson):
    """Spec §3 perspective 2: bushing centres displaced by 3 mm, identified together with the
    stiffnesses the landmarks determine, from noiseless data."""
    m = mcpherson
    params = (Params.bushing_stiffness(m.ref, ["bushing_A"], axes=("Ktx", "Ktz", "Kry", "Krz"))
              + Params.bushing_stiffness(m.ref, ["bushing_B"], axes=("Ktx", "Krz"))
              + Params.bushing_centres(m.ref, A_B))
    assert params.names[-6:] == ("bushing_A.x", "bushing_A.y", "bushing_A.z",
                                 "bushing_B.x", "bushing_B.y", "bushing_B.z")
    truth = np.asarray(params.values(m.ref))
    rng = np.random.default_rng(3)
    shift = rng.normal(size=(2, 3))
    shift = 3.0 * shift / np.linalg.norm(shift, axis=1, keepdims=True)
    start = truth.copy()
    start[:6] = np.r_[R5_START[0], R5_START[2], R5_START[4], R5_START[5], R5_START[0],
                      R5_START[5]]
    start[6:] += shift.ravel()
    fitted, report = least_squares(m.ref, m.landmarks(m.true), params.with_start(start))
    assert report.converged, report.message
    centres = report.estimate[6:].reshape(2, 3)
    assert np.abs(centres - truth[6:].reshape(2, 3)).max() < 0.1
    np.testing.assert_allclose(report.estimate[:6], truth[:6], rtol=1e-6)
    # Both markers of each bushing moved together: the bushing stays undeformed at design.
    pos = np.asarray(fitted.markers.position)
    for name in A_B:
        b = fitted.bushings.index(name)
        np.testing.assert_allclose(pos[fitted.bushings.i_marker[b]],
                                   pos[fitted.bushings.j_marker[b]], atol=1e-12)
    assert np.isnan(report.sigma_percent[6:]).all() and np.all(report.sigma[6:] < 1.0)


# ----------------------------------------------------------------------------- gradients


@pytest.fixture(scope="module")
def arm():
    """The isolated bushing (spec §7 R1) under 4 load cases, with every measurement type, its
    six stiffnesses and its centre as parameters; measured values from other parameters."""
    mech = isolated_bushing()
    rng = np.random.default_rng(5)
    loads = mech.loads(forces={"tip": rng.uniform(-300, 300, size=(4, 3))},
                       moments={"tip": rng.uniform(-2e4, 2e4, size=(4, 3))})
    points = np.array([[-300.0, 0, 0], [-150, 40, 0], [-100, 0, 50]])
    sigmas = (0.01, 0.01, 0.01, 1e-4, 1e-4, 1e-4)

    def arm_travel(m, q):
        return diffsusp.part_poses(m, q)[1][:, 0]

    def measurements(pred=None, mask=None):
        if pred is None:
            pred = dict(landmarks=np.zeros((4, 3, 3)), poses=(np.tile(np.eye(3), (4, 1, 1, 1)),
                                                             np.zeros((4, 1, 3))),
                        deformations=np.zeros((4, 1, 6)), arm_travel=np.zeros((4, 3)))
        return (Landmarks(loads, ("arm",) * 3, points, pred["landmarks"], SIGMA, mask=mask),
                Poses(loads, ("arm",), *pred["poses"], SIGMA, 1e-4),
                Deformations(loads, ("bush",), pred["deformations"], sigmas),
                Channel(loads, arm_travel, pred["arm_travel"], 0.1, name="arm_travel"))

    params = Params.bushing_stiffness(mech) + Params.bushing_centres(mech, ("bush",))
    theta = np.asarray(params.start) * np.r_[np.linspace(0.8, 1.2, 6), np.ones(3)]
    theta[6:] += [1.0, -0.5, 0.3]
    pred = predict(params.apply(mech, jnp.asarray(theta)), measurements())
    mask = np.ones((4, 3), bool)
    mask[2, 1] = False
    return SimpleNamespace(mech=mech, data=measurements(pred, mask), params=params,
                           theta_other=theta)


@pytest.mark.parametrize("loss", ["linear", "cauchy"])
def test_residual_jacobian_matches_finite_differences(arm, loss):
    """Implicit forward-mode Jacobian of the whitened residuals (every measurement type,
    stiffnesses and a bushing centre) against 4th-order central differences."""
    c = arm
    theta = np.asarray(c.params.start)
    z, jac = whitened_residuals(c.mech, c.data, c.params, theta, loss=loss)
    z, jac = np.asarray(z), np.asarray(jac)
    assert np.abs(z).max() > 3.0  # a real residual, some beyond the Cauchy scale

    def at(t):
        return np.asarray(whitened_residuals(c.mech, c.data, c.params, t, loss=loss)[0])

    fd = np.empty_like(jac)
    for j in range(theta.size):
        h = 1e-4 * abs(theta[j]) if j < 6 else 1e-3
        e = np.zeros_like(theta)
        e[j] = h
        fd[:, j] = (8 * (at(theta + e) - at(theta - e)) - (at(theta + 2 * e)
                                                            - at(theta - 2 * e))) / (12 * h)
    scale = np.abs(fd).max(axis=0)
    assert np.all(scale > 0)
    assert np.max(np.abs(jac - fd) / scale) < 1e-6
    # Masked entries are not residuals: zero rows.
    assert np.count_nonzero(np.abs(jac).sum(axis=1) == 0) >= 3


def test_small_model_fit_recovers_the_generating_parameters(arm):
    """Every measurement type at once; stiffnesses started up to 20 % off, the centre 1.2 mm
    off and kept in a ±5 mm box (bounds by reparametrisation)."""
    c = arm
    params = c.params.with_bounds({f"bush.{a}": (-5.0, 5.0) for a in "xyz"})
    _, report = least_squares(c.mech, c.data, params)
    assert report.converged and report.chi2 < 1e-10
    assert report.identifiable.all() and not report.null_space
    np.testing.assert_allclose(report.estimate, c.theta_other, rtol=1e-6, atol=1e-6)
    assert set(report.residuals) == {"landmarks", "poses", "deformations", "arm_travel"}
    assert report.residuals["poses"].raw.shape == (4, 1, 6)
    assert report.n_residuals == 4 * (9 + 6 + 6 + 3) - 3
    # The fit starts from the values of the mechanism it is given, not from those of the one
    # `params` was built from: at the generating values it has nothing left to do.
    start = params.apply(c.mech, jnp.asarray(c.theta_other))
    _, again = least_squares(start, c.data, params)
    np.testing.assert_array_equal(again.start, c.theta_other)
    assert again.converged and again.accepted_steps <= 1 and again.chi2 < 1e-10
    # Values set with with_start are the exception: they win over the mechanism's.
    given = params.with_start({"bush.Ktx": 123.0})
    chosen = np.asarray(given.starting_from(start).start)
    assert chosen[0] == 123.0 and np.array_equal(chosen[1:], c.theta_other[1:])
    more = (Params.bushing_stiffness(c.mech).with_start({"bush.Ktx": 123.0})
            + Params.bushing_centres(c.mech, ("bush",)))  # `+` keeps what was given
    np.testing.assert_array_equal(more.starting_from(start).start, chosen)


# ----------------------------------------------------------------------------- parts


def test_params_names_apply_and_coordinates():
    mech = pseudo_mcpherson()
    p = Params.leaves(mech, lambda m: (m.bushings.k_trans, m.springs.k))
    assert p.names[:3] == ("bushing_B.Ktx", "bushing_B.Kty", "bushing_B.Ktz")
    assert p.names[-1] == "spring.k" and len(p) == 10
    assert np.all(p.log_scaled)
    masked = Params.leaves(mech, lambda m: m.springs.free_length, mask=np.array([True]))
    assert masked.names == ("spring.free_length",) and not masked.log_scaled.any()
    theta = np.asarray(p.start) * 1.5
    moved = p.apply(mech, jnp.asarray(theta))
    np.testing.assert_allclose(np.asarray(p.values(moved)), theta)
    assert float(moved.springs.k[0]) == pytest.approx(1.5 * float(mech.springs.k[0]))
    assert list(Params.bushing_stiffness(mech, ["bushing_F"], axes=("Kry", "Ktx")).names) == [
        "bushing_F.Kry", "bushing_F.Ktx"]
    assert AXES == ("Ktx", "Kty", "Ktz", "Krx", "Kry", "Krz")
    # Coordinates: log for positive, identity for free, logistic in a box; exact round trips.
    q = (Params.bushing_stiffness(mech, ["bushing_A"], axes=("Ktx",))
         + Params.bushing_centres(mech, ["bushing_A"])).with_bounds(
             {"bushing_A.x": (60.0, 62.0), "bushing_A.y": (None, -380.0)})
    u = q.to_internal(q.start)
    np.testing.assert_allclose(np.asarray(q.to_physical(u)), np.asarray(q.start), rtol=1e-14)
    assert float(u[0]) == pytest.approx(math.log(13875.0))
    far = np.asarray(q.to_physical(u + 50.0))
    assert 60.0 < far[1] <= 62.0 and far[2] < -380.0
    d = np.asarray(q.derivative(u))
    fd = (np.asarray(q.to_physical(u + 1e-6)) - np.asarray(q.to_physical(u - 1e-6))) / 2e-6
    np.testing.assert_allclose(d, fd, rtol=1e-6)


def test_params_errors_name_the_parameter():
    mech = pseudo_mcpherson()
    with pytest.raises(InputError, match="bushing_F.Krz.*above 0"):
        Params.bushing_stiffness(mech, ["bushing_F"])  # Krz = 0 cannot be log-scaled
    with pytest.raises(InputError, match="selected twice"):
        p = Params.bushing_stiffness(mech, ["bushing_A"])
        _ = p + p
    with pytest.raises(InputError, match="unknown parameter 'bushing_A.Kzz'"):
        Params.bushing_stiffness(mech, ["bushing_A"]).with_bounds({"bushing_A.Kzz": (0, 1)})
    with pytest.raises(InputError, match="unknown bushing"):
        Params.bushing_stiffness(mech, ["bushing_Q"])
    with pytest.raises(InputError, match="strictly inside"):
        Params.bushing_centres(mech, ["bushing_A"]).with_bounds({"bushing_A.x": (0.0, 10.0)})
    with pytest.raises(InputError, match="array leaves"):
        Params.leaves(mech, lambda m: m.bushings.names)


@pytest.mark.parametrize("kind, rho", [
    (1, lambda r, c: np.where(np.abs(r) <= c, 0.5 * r**2, c * (np.abs(r) - 0.5 * c))),
    (2, lambda r, c: 0.5 * c**2 * np.log1p((r / c) ** 2)),
])
def test_robust_residuals_square_to_the_loss(kind, rho):
    r = np.linspace(-30.0, 30.0, 241)
    c = 1.7
    out = np.asarray(_robust(jnp.asarray(r), kind, c))
    np.testing.assert_allclose(0.5 * out**2, rho(r, c), rtol=1e-12, atol=1e-300)
    assert np.all(np.sign(out) == np.sign(r))
    slope = np.asarray(jax.vmap(jax.grad(lambda x: _robust(x, kind, c)))(jnp.asarray(r)))
    assert np.all(np.isfinite(slope)) and slope[120] == pytest.approx(1.0)


def test_measurement_input_errors(mcpherson):
    m = mcpherson
    with pytest.raises(InputError, match="shape"):
        m.landmarks(m.true[:5])
    bad = m.true.copy()
    bad[2, 3, 1] = np.nan
    with pytest.raises(InputError, match=r"index \(2, 3, 1\).*mask"):
        m.landmarks(bad)
    mask = np.ones(m.true.shape[:2], bool)
    mask[2, 3] = False
    assert float(m.landmarks(bad, mask=mask).weight[2, 3, 1]) == 0.0
    with pytest.raises(InputError, match="sigma"):
        Landmarks(m.loads, m.parts, m.points, m.true, 0.0)
    with pytest.raises(InputError, match="unknown loss"):
        least_squares(m.ref, m.landmarks(m.true), m.params, loss="tukey")
    with pytest.raises(InputError, match="prior_sigma"):
        least_squares(m.ref, m.landmarks(m.true), m.params, prior=m.truth)
    with pytest.raises(InputError, match="least_squares_batch"):
        least_squares(m.ref, m.landmarks(np.stack([m.true, m.true])), m.params)
    with pytest.raises(InputError, match="distinct name"):
        least_squares(m.ref, [m.landmarks(m.true), m.landmarks(m.true)], m.params)
    wrong = Landmarks(m.loads, ("front_arm", "wishbone"), m.points[:2], m.true[:, :2], SIGMA)
    with pytest.raises(InputError, match="unknown part 'wishbone'"):
        least_squares(m.ref, wrong, m.params)
    one_point = diffsusp.Loads(force=jnp.zeros((13, 1, 3)), moment=jnp.zeros((13, 1, 3)),
                               driver=jnp.zeros((13, 0)))
    with pytest.raises(InputError, match="load table has 1 load points"):
        least_squares(m.ref, Landmarks(one_point, m.parts, m.points, m.true, SIGMA), m.params)
