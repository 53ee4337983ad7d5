"""The direct (linear) stiffness identification (diffsusp.identify.direct): the thesis's reference
results R1–R3, the assembled equations against an independent NumPy construction, options
(axisymmetric, offsets, solution methods), bad input, and a Monte-Carlo on the noisy
pseudo-McPherson. spec: stiffness §1.8–1.14, §7 R1–R4, Appendix Z.

Equilibria come from the library's solver (R1, the pseudo-McPherson) or from the independent
NumPy oracle (R2, R3: tests/oracle.py), so that the identification is also checked against data
it did not produce itself."""

import dataclasses
import math
import pathlib

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import oracle  # tests/oracle.py
import pytest
from scipy.linalg import null_space
from scipy.spatial.transform import Rotation

import diffsusp
from diffsusp import identify, measure
from diffsusp.errors import InputError, ModelError
from diffsusp.models import (
    crank_slider,
    isolated_bushing,
    pseudo_mcpherson,
    thesis_load_cases,
    two_bushing_coupler,
)

DEG = 180.0 / math.pi  # N·mm/rad per N·mm/deg
MC_DATA = pathlib.Path(__file__).parent / "data" / "identify_direct_mc.npz"


def _oracle_measurements(mech, loads, **kwargs):
    sols = oracle.solve_loads(mech, loads, **kwargs)
    assert all(s.converged for s in sols)
    rot = np.stack([s.R for s in sols])
    trans = np.stack([s.p for s in sols])
    return measure.from_poses(mech.parts, rot, trans, loads)


# ----------------------------------------------------------------------------- R1


@pytest.fixture(scope="module")
def bushing_cases():
    """Three load cases at the arm tip (R1's load point, QP = (−300, 0, 0))."""
    force = np.array([[30.0, -20.0, 50.0], [-12.0, 8.0, 4.0], [6.0, 3.0, -9.0]])
    moment = np.array([[2e4, -1e4, 3e4], [-5e3, 1e4, 2e3], [3e3, 4e3, -6e3]])
    return force, moment


@pytest.mark.parametrize("k_trans", [100.0, 10000.0])
def test_r1_isolated_bushing_one_case(bushing_cases, k_trans):
    """spec §7 R1: one case recovers all six stiffnesses exactly (1e-10 relative), for the
    annex's 100 N/mm and Table 4.1's 10 000 N/mm, with K_T = 10 000 N·mm/deg."""
    mech = isolated_bushing(k_trans=k_trans)
    force, moment = bushing_cases
    loads = mech.loads(forces={"tip": force}, moments={"tip": moment})
    meas = measure.synthesize(mech, loads)
    true = np.array([k_trans] * 3 + [1e4] * 3)
    for c in range(3):
        fitted, report = identify.direct(mech, measure.case_subset(meas, [c]), weighting="none")
        assert report.n_equations == 6 and report.rank == 6
        np.testing.assert_allclose(report.values, true, rtol=1e-10)
        assert report.identified.all()
        np.testing.assert_allclose(fitted.bushings.k_trans, k_trans, rtol=1e-10)
        np.testing.assert_allclose(fitted.bushings.k_rot, 1e4 * DEG, rtol=1e-10)


def test_negative_stiffness_is_not_reported_as_identified(bushing_cases):
    """Loads of the wrong sign give exactly negative stiffnesses, with small σ: the report says
    they are not physical and the model keeps its values."""
    mech = isolated_bushing()
    force, moment = bushing_cases
    meas = measure.synthesize(mech, mech.loads(forces={"tip": force}, moments={"tip": moment}))
    flipped = eqx.tree_at(lambda m: (m.loads.force, m.loads.moment), meas,
                          (-meas.loads.force, -meas.loads.moment))
    fitted, report = identify.direct(mech, flipped, weighting="none")
    np.testing.assert_allclose(report.values, [-100.0] * 3 + [-1e4] * 3, rtol=1e-8)
    assert not report.identified.any()
    assert set(report.status) == {"not physical: negative stiffness"}
    assert any("came out negative" in n for n in report.notes)
    np.testing.assert_array_equal(fitted.bushings.k_trans, mech.bushings.k_trans)


def test_r1_offsets_and_preloads_are_identified(bushing_cases):
    """Offsets δ0 (spec §1.10, 'Offsets'): identified as constants K·δ0 next to K; with three
    cases (18 equations, 12 unknowns) both come out exactly, and the identified model
    reproduces the measured equilibria."""
    base = isolated_bushing()
    offset_t = jnp.array([[0.4, -0.3, 0.2]])
    offset_r = jnp.array([[0.01, -0.02, 0.005]])
    mech = eqx.tree_at(lambda m: (m.bushings.offset_trans, m.bushings.offset_rot), base,
                       (offset_t, offset_r))
    force, moment = bushing_cases
    loads = mech.loads(forces={"tip": force}, moments={"tip": moment})
    meas = measure.synthesize(mech, loads)
    where = lambda m: (m.bushings.k_trans, m.bushings.k_rot, m.bushings.offset_trans,  # noqa: E731
                       m.bushings.offset_rot)
    fitted, report = identify.direct(base, meas, where)
    assert report.names[:6] == ("bush.Ktx", "bush.Kty", "bush.Ktz", "bush.Krx", "bush.Kry",
                                "bush.Krz")
    assert report.names[6:] == ("bush.Fx0", "bush.Fy0", "bush.Fz0", "bush.Mx0", "bush.My0",
                                "bush.Mz0")
    np.testing.assert_allclose(report.values[:6], [100.0] * 3 + [1e4] * 3, rtol=1e-9)
    np.testing.assert_allclose(report.values[6:9], 100.0 * offset_t[0], rtol=1e-8)
    np.testing.assert_allclose(report.values[9:], 1e4 * DEG * offset_r[0], rtol=1e-8)
    np.testing.assert_allclose(fitted.bushings.offset_trans, offset_t, rtol=1e-8)
    np.testing.assert_allclose(fitted.bushings.offset_rot, offset_r, rtol=1e-8)
    assert report.derived["bush.dx0"][0] == pytest.approx(0.4, rel=1e-8)
    assert report.derived["bush.ay0"][0] == pytest.approx(math.degrees(-0.02), rel=1e-8)
    again = diffsusp.solve_statics(fitted, loads)
    np.testing.assert_allclose(again.q, meas.coordinates(base), atol=1e-9)


def test_polish_returns_the_model_it_judges(bushing_cases):
    """Errors in variables: the polish covers the stiffnesses and holds the offsets
    δ0 at the model's values (here the truth's). The model returned is the one whose
    consistency is reported: re-solved independently (`check_consistency`) it gives the
    report's χ² (the code before returned the noisy linear constants K·δ0 with the polished
    stiffnesses, and a verdict on another model); the constants are reported as held, at the
    returned model's K·δ0, their linear estimates kept in `linear_values`; the polished
    stiffnesses reported identified are within 4σ of the truth."""
    from diffsusp.identify.report import check_consistency, check_data

    offset_t, offset_r = np.array([0.4, -0.3, 0.2]), np.array([0.01, -0.02, 0.005])
    mech = eqx.tree_at(lambda m: (m.bushings.offset_trans, m.bushings.offset_rot),
                       isolated_bushing(), (jnp.asarray(offset_t[None]),
                                            jnp.asarray(offset_r[None])))
    force, moment = bushing_cases
    loads = mech.loads(forces={"tip": force}, moments={"tip": moment})
    exact = measure.synthesize(mech, loads, layout=measure.place_landmarks(mech, seed=0))
    noisy = measure.add_noise(exact, measure.GaussianNoise(landmarks=0.01),
                              jax.random.PRNGKey(1209))
    where = lambda m: (m.bushings.k_trans, m.bushings.k_rot, m.bushings.offset_trans,  # noqa: E731
                       m.bushings.offset_rot)
    fitted, report = identify.direct(mech, noisy, where, polish=True)
    # The consistency is the returned model's (the polish's values where it determines them).
    assert report.polished is not None
    again = check_consistency(fitted, check_data(mech, noisy),
                              report.consistency.n_parameters, cases=report.cases)
    assert again.chi2 == pytest.approx(report.consistency.chi2, rel=1e-6)
    assert report.consistent
    # The offsets: held at the model's, reported at the returned model's K·δ0.
    constants = slice(6, 12)
    assert all(st.startswith("held at the model's value in the polish (its offset")
               for st in report.status[constants]), report.status
    assert not report.identified[constants].any()
    np.testing.assert_array_equal(fitted.bushings.offset_trans[0], offset_t)
    np.testing.assert_array_equal(fitted.bushings.offset_rot[0], offset_r)
    k_trans = np.asarray(fitted.bushings.k_trans[0])
    k_rot = np.asarray(fitted.bushings.k_rot[0])
    np.testing.assert_allclose(report.values[constants],
                               np.concatenate([k_trans * offset_t, k_rot * offset_r]),
                               rtol=1e-12)
    assert np.all(report.linear_values[constants] != report.values[constants])
    assert not any(np.isfinite(v) for v, _, _ in report.derived.values())
    # The stiffnesses: the returned model carries the identified ones (table units); the
    # others keep the model's values.
    ok = report.identified[:6]
    model = np.concatenate([k_trans, k_rot / DEG])
    np.testing.assert_allclose(report.values[:6][ok], model[ok], rtol=1e-12)
    start = np.concatenate([np.asarray(mech.bushings.k_trans[0]),
                            np.asarray(mech.bushings.k_rot[0]) / DEG])
    np.testing.assert_array_equal(model[~ok], start[~ok])
    assert ok[2:].all(), report.status
    err = (report.values[:6] - np.array([100.0] * 3 + [1e4] * 3)) / report.sigma[:6]
    assert np.all(np.abs(err[ok]) < 4.0), err
    assert "held at the model's value" in report.table()
    # Verdicts that agree: the same linear estimate with a σ claimed 10× below the noise is
    # inconsistent with the data, and no status (table, rows) then says "identified".
    _, lie = identify.direct(mech, dataclasses.replace(noisy, sigma=0.001), where,
                             polish=False)
    assert lie.consistent is False and lie.determined.all()
    assert set(lie.status) == {identify.direct_report.INCONSISTENT_STATUS}
    assert not any(row["identified"] for row in lie.rows())
    statuses = [line for line in lie.table().splitlines() if line.startswith("bush.")]
    assert len(statuses) == 12 and not any(line.endswith(" identified") for line in statuses)


# ----------------------------------------------------------------------------- R2


@pytest.fixture(scope="module")
def crank():
    mech = crank_slider()
    force = np.array([[100.0, 50.0, 0.0], [-200.0, 30.0, 10.0], [50.0, -80.0, -20.0]])
    loads = mech.loads(forces={"crank_pin": force})
    return mech, _oracle_measurements(mech, loads, rtol=1e-11, atol=1e-12)


def test_r2_crank_slider(crank):
    """spec §7 R2: one equation per case; only the slider-axis stiffness is identifiable,
    recovered exactly; the basic solution has the thesis's zeros; the report says the other five
    are not identifiable."""
    mech, meas = crank
    fitted, report = identify.direct(mech, meas, weighting="none")  # as the thesis
    assert report.n_equations == 3 and report.rank == 1
    assert report.names[0] == "slider_bushing.Ktx"
    assert report.values[0] == pytest.approx(10000.0, rel=1e-8)
    assert report.identified.tolist() == [True] + [False] * 5
    np.testing.assert_array_equal(report.values[1:], 0.0)  # the thesis's Table 4.2
    for status in report.status[1:]:
        assert status.startswith("not identifiable")
    table = report.table()
    assert table.count("—") >= 5 and "not identifiable" in table
    # the model keeps its values where nothing was identified
    np.testing.assert_allclose(fitted.bushings.k_trans, [[10000.0] * 3], rtol=1e-8)


# ----------------------------------------------------------------------------- R3


@pytest.fixture(scope="module")
def coupler():
    mech = two_bushing_coupler()
    rng = np.random.default_rng(0)
    n = 10
    f = rng.normal(size=(n, 3))
    f *= rng.uniform(0.2, 1.0, (n, 1)) * 300.0 / np.linalg.norm(f, axis=1, keepdims=True)
    m = rng.normal(size=(n, 3))
    m *= rng.uniform(0.2, 1.0, (n, 1)) * 1e4 / np.linalg.norm(m, axis=1, keepdims=True)
    loads = mech.loads(forces={"coupler_middle": f}, moments={"coupler_middle": m})
    return mech, _oracle_measurements(mech, loads, rtol=1e-11, atol=1e-12)


def test_r3_two_bushing_coupler(coupler):
    """spec §7 R3: 8 equations per case, rank 10 for 12 unknowns; translations and Krz within
    0.2 %; only Krx1 + Krx2 and Kry1 + Kry2 (= 20 000) are determined."""
    mech, meas = coupler
    _, report = identify.direct(mech, meas)
    assert report.n_equations == 80 and report.rank == 10
    for b in ("bushing_1", "bushing_2"):
        for axis in ("Ktx", "Kty", "Ktz", "Krz"):
            i = report.names.index(f"{b}.{axis}")
            assert report.identified[i]
            assert report.values[i] == pytest.approx(10000.0, rel=2e-3)
    assert sorted(report.combinations) == ["bushing_1.Krx + bushing_2.Krx",
                                           "bushing_1.Kry + bushing_2.Kry"]
    for _, value, _ in report.relations:
        assert value == pytest.approx(20000.0, rel=2e-3)
    for name in ("bushing_1.Krx", "bushing_2.Krx", "bushing_1.Kry", "bushing_2.Kry"):
        i = report.names.index(name)
        assert not report.identified[i]
        assert "not identifiable alone: in bushing_1.Kr" in report.status[i]
    # Basic solution: one of each pair carries the sum, the other is 0 (Table 4.3's pattern).
    krx = [report.value("bushing_1.Krx"), report.value("bushing_2.Krx")]
    assert min(krx) == 0.0 and max(krx) == pytest.approx(20000.0, rel=2e-3)


@pytest.mark.parametrize("method", ["min_norm", "tsvd", "tikhonov", "nonneg"])
def test_r3_solution_methods(coupler, method):
    """Every method determines the same things; min_norm and tikhonov (toward the model's
    10 000) split the parallel rotational stiffnesses evenly."""
    mech, meas = coupler
    fitted, report = identify.direct(mech, meas, method=method)
    for _, value, _ in report.relations:
        assert value == pytest.approx(20000.0, rel=2e-3)
    i = report.names.index("bushing_1.Ktx")
    assert report.values[i] == pytest.approx(10000.0, rel=2e-3)
    if method in ("min_norm", "tikhonov"):
        for name in ("bushing_1.Krx", "bushing_2.Krx", "bushing_1.Kry", "bushing_2.Kry"):
            assert report.value(name) == pytest.approx(10000.0, rel=5e-3)
    if method == "nonneg":
        assert np.all(report.values >= 0)
    if method == "tikhonov":  # the regularised solution is complete: all written to the model
        np.testing.assert_allclose(fitted.bushings.k_rot[:, :2], 1e4 * DEG, rtol=5e-3)


def test_r3_axisymmetric_bushings(coupler):
    """Axisymmetric bushings (spec §1.8, 4.40): 4 unknowns each, columns x + y summed."""
    mech, meas = coupler
    both = ("bushing_1", "bushing_2")
    _, report = identify.direct(mech, meas, axisymmetric=both, weighting="none")
    assert report.names[:4] == ("bushing_1.Ktr", "bushing_1.Ktz", "bushing_1.Krr",
                                "bushing_1.Krz")
    for name in ("bushing_1.Ktr", "bushing_2.Ktr", "bushing_1.Ktz", "bushing_2.Krz"):
        assert report.value(name) == pytest.approx(10000.0, rel=2e-3)
    assert report.combinations == ["bushing_1.Krr + bushing_2.Krr"]
    full = identify.direct_system(mech, meas)
    axi = identify.direct_system(mech, meas, axisymmetric=both)
    for b in range(2):
        np.testing.assert_allclose(axi.W[:, 4 * b], full.W[:, 6 * b] + full.W[:, 6 * b + 1],
                                   rtol=1e-12)
        np.testing.assert_allclose(axi.W[:, 4 * b + 2],
                                   full.W[:, 6 * b + 3] + full.W[:, 6 * b + 4], rtol=1e-12)


# ----------------------------------------------------------------------------- the equations


def _oracle_rows(mech, meas):
    """Independent construction of the equations (Appendix Z's recipe, Adams convention): the
    oracle's generalised forces in (δp, δθ) coordinates for unit values of each unknown (they are
    linear), its finite-difference constraint gradients, SciPy's null space."""
    b, s = mech.bushings, mech.springs
    zero = eqx.tree_at(
        lambda m: (m.bushings.k_trans, m.bushings.k_rot, m.springs.k, m.springs.free_length),
        mech, (jnp.zeros_like(b.k_trans), jnp.zeros_like(b.k_rot), jnp.zeros_like(s.k),
               jnp.zeros_like(s.free_length)))

    def variant(field, e, a, value, free_length=0.0):
        k = np.zeros((len(b.names), 6))
        ks = np.zeros(len(s.names))
        l0 = np.zeros(len(s.names))
        if field == "bushing":
            k[e, a] = value
        else:
            ks[e], l0[e] = value, free_length
        return eqx.tree_at(
            lambda m: (m.bushings.k_trans, m.bushings.k_rot, m.springs.k, m.springs.free_length),
            zero, (jnp.asarray(k[:, :3]), jnp.asarray(k[:, 3:]), jnp.asarray(ks),
                   jnp.asarray(l0)))

    variants = [variant("bushing", e, a, 1.0 if a < 3 else DEG)
                for e in range(len(b.names)) for a in range(6)]
    for e in range(len(s.names)):
        variants += [variant("spring", e, 0, 1.0), (variant("spring", e, 0, 1.0, 1.0),
                                                    variant("spring", e, 0, 1.0))]
    q = np.asarray(meas.coordinates(mech))
    n = mech.n_coordinates
    out = []
    for c in range(meas.n_cases):
        p, rot = oracle.from_q(q[c])
        args = (np.asarray(meas.loads.force[c]), np.asarray(meas.loads.moment[c]),
                np.asarray(meas.loads.driver[c]))

        def forces(m, p=p, rot=rot, args=args):
            orc = oracle._oracle(m)
            return orc.residual(p, rot, np.zeros(orc.n_mult), *args)[0][:n]

        known = forces(zero)
        cols = []
        for v in variants:
            if isinstance(v, tuple):  # K·L0: tension −1 = Q(k=1, L0=1) − Q(k=1, L0=0)
                cols.append(forces(v[0]) - forces(v[1]))
            else:
                cols.append(forces(v) - known)
        _, grad = oracle._oracle(mech).constraints(p, rot, args[2])
        basis = null_space(grad) if grad.size else np.eye(n)
        out.append(np.column_stack([basis.T @ np.column_stack(cols), -basis.T @ known]))
    return out


def test_equations_match_an_independent_construction():
    """The assembled rows [Lᵀ D | −Lᵀ Q] of each case span the same equations as an
    independent NumPy construction (other coordinates, finite-difference constraint gradients):
    equal up to an invertible r×r matrix per case (the choice of L and of coordinates). Poses
    off equilibrium (the equations do not need one), the pseudo-McPherson with its spring."""
    mech = pseudo_mcpherson()
    rng = np.random.default_rng(1)
    n_cases, n_parts = 3, len(mech.parts)
    rot = Rotation.from_rotvec(rng.normal(size=(n_cases * n_parts, 3)) * 0.02).as_matrix()
    rot = rot.reshape(n_cases, n_parts, 3, 3)
    trans = rng.normal(size=(n_cases, n_parts, 3)) * 3.0
    loads = thesis_load_cases(mech, np.array([[4500.0, 0.0, 0.0], [3000.0, 1000.0, 0.0],
                                              [6000.0, 0.0, -1000.0]]))
    meas = measure.from_poses(mech.parts, rot, trans, loads)
    # Every element named: the directions at 0 in the model (left out by default) included.
    system = identify.direct_system(mech, meas,
                                    [*mech.bushings.names, *mech.springs.names])
    r = system.rows_per_case
    assert r == 24 - 12 and system.W.shape == (n_cases * r, 20)
    ours = np.column_stack([system.W, system.y]).reshape(n_cases, r, -1)
    theirs = _oracle_rows(mech, meas)
    for a, b in zip(ours, theirs, strict=True):
        m = a @ np.linalg.pinv(b)
        np.testing.assert_allclose(m @ b, a, atol=1e-6 * np.abs(a).max())
        assert np.linalg.cond(m) < 1e6


# ----------------------------------------------------------------------------- bad input


def test_bad_input(coupler):
    mech, meas = coupler
    missing = measure.from_poses(("link_1", "link_2"), meas.rotation[:, :2],
                                 meas.translation[:, :2], meas.loads)
    with pytest.raises(InputError, match=r"no pose for part\(s\) 'coupler'.*fix its pose"):
        identify.direct(mech, missing)
    with pytest.raises(InputError, match="where= selected something"):
        identify.direct(mech, meas, lambda m: m.markers.position)
    with pytest.raises(InputError, match="params names 'bushing_9'"):
        identify.direct(mech, meas, ("bushing_9",))
    with pytest.raises(InputError, match="method must be"):
        identify.direct(mech, meas, method="qr")
    other = isolated_bushing()
    with pytest.raises(InputError, match="load points"):
        identify.direct(mech, measure.from_poses(
            mech.parts, meas.rotation, meas.translation,
            other.loads(forces={"tip": np.zeros((10, 3))})))
    spline = diffsusp.MechanismBuilder("spline bushing")
    spline.part("arm")
    spline.bushing("bush", parts=("arm", "ground"), at=(0, 0, 0), k_trans=100.0, k_rot=1e5,
                   splines={"tx": ([-1.0, 0.0, 1.0], [100.0, 0.0, -100.0])})
    spline.load_point("tip", part="arm", at=(100.0, 0, 0))
    sm = spline.build()
    one = measure.from_poses(("arm",), np.eye(3)[None, None], np.zeros((1, 1, 3)),
                             sm.loads(forces={"tip": np.ones((1, 3))}))
    with pytest.raises(ModelError, match="spline law on axis tx"):
        identify.direct(sm, one)


def test_unmeasured_part_is_refused_with_the_reason():
    """Issue 12: the pseudo-McPherson with its strut unmeasured. The strut slides in the hub
    carrier (a translational joint: 5 rows), so one coordinate per case is set by the
    equilibrium of bushing F and the spring, i.e. by the unknowns: the report says so and
    points to the methods that fit through the equilibrium."""
    mech = pseudo_mcpherson()
    parts = tuple(p for p in mech.parts if p != "strut")
    loads = thesis_load_cases(mech)
    n = loads.force.shape[0]
    meas = measure.from_poses(parts, np.broadcast_to(np.eye(3), (n, len(parts), 3, 3)),
                              np.zeros((n, len(parts), 3)), loads)
    with pytest.raises(InputError, match=r"no pose for part\(s\) 'strut'.*joints "
                       r"\(strut_slide\) leave it 1 free coordinate.*identify\.least_squares"):
        identify.direct(mech, meas)


def test_report_outputs(coupler, tmp_path):
    import json

    import matplotlib

    matplotlib.use("Agg")
    mech, meas = coupler
    _, report = identify.direct(mech, meas)
    data = json.loads(json.dumps(report.to_dict()))
    assert data["rank"] == 10 and len(data["parameters"]) == 12
    assert len(data["cases"]) == 10 and data["relations"][0]["value"] == pytest.approx(2e4,
                                                                                         rel=2e-3)
    rows = report.rows()
    assert rows[0]["parameter"] == "bushing_1.Ktx" and rows[0]["unit"] == "N/mm"
    fig = report.plot()
    assert len(fig.axes) == 2
    fig.savefig(tmp_path / "report.png")
    assert (tmp_path / "report.png").stat().st_size > 0
    text = str(report)
    assert "identifiable combinations" in text and "bushing_1.Krx + bushing_2.Krx" in text


# ----------------------------------------------------------------------------- Monte-Carlo


@pytest.mark.slow
def test_pseudo_mcpherson_noisy_monte_carlo():
    """The thesis's half axle with its nominal stiffnesses, the 13 load cases of Table 5-1,
    four landmarks per part with σ = 0.05 mm (the measuring arm) over 20 noise realisations
    (shipped: tests/data/identify_direct_mc.npz): the influential unknowns (Ktx of bushings A
    and B, the spring's K and K·L0) are recovered within 5 % on average, the report's σ agrees
    with the Monte-Carlo spread within a factor 1.5, and the unknowns the data cannot
    determine are flagged, not given a number. The noisy-data recipe: the undetermined
    unknowns held at the model's values and eliminated one by one, GLS weighting (the
    default). The linear estimate alone
    (`polish=False`): the polish through the equilibrium, the default, is
    checked on random stiffnesses in test_identify_trust."""
    mech = pseudo_mcpherson()
    loads = thesis_load_cases(mech)
    layout = measure.place_landmarks(mech, seed=0)
    with np.load(MC_DATA) as f:  # written by tests/data/make_identify_trust.py
        data = dict(f)
    np.testing.assert_array_equal(data["layout"], layout.position)
    values, sigmas, identified, tables = [], [], [], []
    for s in range(len(data["rotation"])):
        one = measure.Measurements(
            rotation=jnp.asarray(data["rotation"][s]),
            translation=jnp.asarray(data["translation"][s]), loads=loads,
            landmarks=jnp.asarray(data["landmarks"][s]), weights=jnp.asarray(data["weights"][s]),
            rms=jnp.asarray(data["rms"][s]), layout=layout, parts=layout.parts,
            cases=tuple(str(c + 1) for c in range(loads.force.shape[0])))
        # The consistency check (a re-solve) is test_identify_trust's subject, not this one's.
        _, report = identify.direct(mech, one, hold="model", eliminate=True, polish=False,
                                    check=False)
        values.append(report.values)
        sigmas.append(report.sigma)
        identified.append(report.identified)
        tables.append(report.table())
    values, sigmas, identified = map(np.array, (values, sigmas, identified))
    names = report.names
    true = report.prior  # the model is the truth here
    for name in ("bushing_A.Ktx", "bushing_B.Ktx", "spring.K", "spring.KL0"):
        i = names.index(name)
        assert identified[:, i].all(), name
        err = values[:, i] / true[i] - 1.0
        assert abs(err.mean()) < 0.05, name
        spread = values[:, i].std(ddof=1)
        reported = np.sqrt(np.mean(sigmas[:, i] ** 2))
        assert 1 / 1.5 < reported / spread < 1.5, (name, reported, spread)
        assert np.all(np.abs(values[:, i] - true[i]) < 4 * sigmas[:, i]), name
    # Never determined by these cases: the arms' spin about their own axes (Krx of A and B),
    # B's stiff radial direction. They are flagged and shown without a value.
    for name in ("bushing_A.Krx", "bushing_B.Krx", "bushing_B.Kty"):
        i = names.index(name)
        assert not identified[:, i].any(), name
    for table in tables:
        line = next(ln for ln in table.splitlines() if ln.startswith("bushing_A.Krx "))
        assert "—" in line and "not determined" in line
