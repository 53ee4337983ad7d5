"""Core solver: closed forms, balance checks, implicit gradients, batching, retracing, errors."""

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import central_fd

import diffsusp as ds
from diffsusp.geometry import gibbs_to_matrix, projected_angles, reuler_deg_to_matrix
from diffsusp.statics import solve as solve_module

REULER = (28.18678543, 33.2259422, 350.8538915)  # spec stiffness §4.1, markers 7 and 8
K_ROT = 10000 * 180 / np.pi  # 10 000 N·mm/deg in N·mm/rad


def isolated(k_trans=100.0, reuler=REULER):
    b = ds.MechanismBuilder("isolated bushing")
    b.part("arm")
    b.bushing("bush", parts=("arm", "ground"), at=(0, 0, 0), reuler_deg=reuler,
              k_trans=k_trans, k_rot=K_ROT)
    b.load_point("centre", part="arm", at=(0, 0, 0))
    b.load_point("tip", part="arm", at=(-300, 0, 0))
    return b.build()


def ball_mount():
    """A part on a spherical joint, held by a rotated bushing and a spring (cf. spec App. Z)."""
    b = ds.MechanismBuilder("ball mount")
    b.part("link")
    b.joint("ball", "spherical", parts=("link", "ground"), at=(0, 0, 0))
    b.bushing("bush", parts=("link", "ground"), at=(120, 40, -10), reuler_deg=(30, 20, 10),
              k_trans=(1000, 2000, 300), k_rot=np.array([4000, 1500, 800]) * 180 / np.pi)
    b.spring("spring", parts=("ground", "link"), at=((0, 0, 300), (200, 0, 0)), k=25.0,
             free_length=320.0)
    b.marker("tip", "link", (250, 30, 20))
    b.load_point("load", marker="tip")
    return b.build()


@pytest.fixture(scope="module")
def iso():
    return isolated()


@pytest.fixture(scope="module")
def mount():
    return ball_mount()


@pytest.mark.parametrize("k_trans", [100.0, 10000.0])
def test_isolated_bushing_closed_form(k_trans):
    """spec §7 R1: δ_T = F/K and projected angles = M/K_T, in the J (bushing) frame."""
    mech = isolated(k_trans)
    force = jnp.array([300.0, -200.0, 500.0])
    moment = jnp.array([2e4, -1e4, 3e4])
    sol = ds.solve_statics(mech, mech.loads(forces={"centre": force}, moments={"centre": moment}))
    delta, angles, f, t = ds.bushing_states(mech, sol.q)
    rj = reuler_deg_to_matrix(jnp.asarray(REULER))
    np.testing.assert_allclose(delta[0], rj.T @ force / k_trans, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(angles[0], rj.T @ moment / K_ROT, rtol=1e-12, atol=1e-15)
    assert int(sol.status) == 0


def test_isolated_bushing_identity_frame_exact():
    mech = isolated(100.0, reuler=(0.0, 0.0, 0.0))
    sol = ds.solve_statics(mech, mech.loads(forces={"centre": [300.0, -200.0, 500.0]}))
    np.testing.assert_allclose(sol.q[:3], [3.0, -2.0, 5.0], rtol=1e-12)


def test_isolated_bushing_lever_arm_balance(iso):
    """Load at (−300, 0, 0): the bushing wrench balances the load exactly (force and moment)."""
    force = jnp.array([100.0, 180.0, -160.0])
    moment = jnp.array([1000.0, -2000.0, 500.0])
    sol = ds.solve_statics(iso, iso.loads(forces={"tip": force}, moments={"tip": moment}))
    _, _, f, t = ds.bushing_states(iso, sol.q)
    pos, rot = ds.marker_poses(iso, sol.q)
    i = iso.markers.index("bush.i")
    j = iso.markers.index("bush.j")
    tip = iso.markers.index("tip.m")
    rj = rot[j]
    f_on_arm, t_on_arm = rj @ f[0], rj @ t[0]
    np.testing.assert_allclose(f_on_arm + force, 0.0, atol=1e-9)
    lever = jnp.cross(pos[tip] - pos[i], force)
    np.testing.assert_allclose(t_on_arm + moment + lever, 0.0, atol=1e-6)
    # The arm turns by several degrees (lever moment ~5e4 N·mm against 5.7e5 N·mm/rad), so the
    # lever arm itself moves: a genuinely nonlinear case.
    assert float(jnp.max(jnp.abs(sol.q[3:]))) > 0.02


def _tip_position(mech, loads):
    sol = ds.solve_statics(mech, loads)
    pos, _ = ds.marker_poses(mech, sol.q)
    return pos[mech.markers.index("tip")]


@pytest.fixture(scope="module")
def mount_loads(mount):
    return mount.loads(forces={"load": [50.0, -100.0, 150.0]}, moments={"load": [0, 2e3, 0]})


@pytest.fixture(scope="module")
def mount_jacobians(mount, mount_loads):
    """Forward-mode Jacobian of the tip position w.r.t. every leaf of the mechanism and the
    loads (one compilation), and the reverse-mode gradient of a weighted sum of it (one more)."""
    weights = jnp.array([0.3, -1.1, 0.7])

    def f(args):
        return _tip_position(*args)

    fwd = eqx.filter_jit(eqx.filter_jacfwd(f))((mount, mount_loads))
    rev = eqx.filter_jit(eqx.filter_grad(lambda a: weights @ f(a)))((mount, mount_loads))
    return fwd, rev, weights


@pytest.mark.parametrize(
    "where, h",
    [
        (lambda m: m.bushings.k_trans, 1e-2),
        (lambda m: m.bushings.k_rot, 1.0),
        (lambda m: m.springs.free_length, 1e-4),
        (lambda m: m.springs.k, 1e-5),
        (lambda m: m.markers.position, 1e-4),
    ],
    ids=["k_trans", "k_rot", "free_length", "spring_k", "marker_position"],
)
def test_gradients_match_central_differences(mount, mount_loads, mount_jacobians, where, h):
    fwd_all, rev_all, weights = mount_jacobians
    x0 = where(mount)

    def f(x):
        return _tip_position(eqx.tree_at(where, mount, x), mount_loads)

    # Jacobian leaves have shape (3, *leaf.shape): the output axis comes first.
    fwd = where(fwd_all[0]).reshape(3, -1)
    rev = where(rev_all[0]).reshape(-1)
    fd = central_fd(f, x0, h).reshape(3, -1)
    scale = jnp.max(jnp.abs(fd))
    np.testing.assert_allclose(weights @ fwd, rev, rtol=1e-10, atol=1e-12 * scale)
    np.testing.assert_allclose(fwd, fd, rtol=1e-6, atol=1e-6 * scale)


def test_gradient_wrt_loads(mount, mount_loads, mount_jacobians):
    fwd_all, rev_all, weights = mount_jacobians

    def f(force):
        return _tip_position(mount, eqx.tree_at(lambda l: l.force, mount_loads, force))

    fwd = fwd_all[1].force.reshape(3, -1)
    rev = rev_all[1].force.reshape(-1)
    fd = central_fd(f, mount_loads.force, 1e-2).reshape(3, -1)
    np.testing.assert_allclose(weights @ fwd, rev, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(fwd, fd, rtol=1e-6, atol=1e-10)


def test_vmap_equals_loop_and_no_retrace(mount):
    rng = np.random.default_rng(1)
    forces = jnp.asarray(rng.uniform(-150, 150, (6, 3)))
    batch = ds.solve_statics(mount, mount.loads(forces={"load": forces}))
    for c in range(6):
        one = ds.solve_statics(mount, mount.loads(forces={"load": forces[c]}))
        np.testing.assert_allclose(batch.q[c], one.q, rtol=1e-12, atol=1e-12)

    traces = []
    newton = solve_module._newton

    def counting(*args, **kwargs):
        traces.append(1)
        return newton(*args, **kwargs)

    solve_module._newton = counting
    try:
        for scale in (1.0, 1.3, 0.7):
            k = mount.bushings.k_trans * scale
            stiffer = eqx.tree_at(lambda m: m.bushings.k_trans, mount, k)
            ds.solve_statics(stiffer, mount.loads(forces={"load": forces}))
    finally:
        solve_module._newton = newton
    assert len(traces) <= 1  # traced at most once (the first call may hit the existing cache)


def test_jit_equals_eager_outputs(mount, mount_loads):
    sol = ds.solve_statics(mount, mount_loads)
    eager = ds.spring_states(mount, sol.q)
    jitted = jax.jit(lambda q: ds.spring_states(mount, q))(sol.q)
    np.testing.assert_allclose(eager[0], jitted[0], rtol=1e-14)
    # Tension follows the linear law at the solved length.
    np.testing.assert_allclose(eager[1], 25.0 * (eager[0] - 320.0), rtol=1e-12)


def test_sweep_matches_independent_solves(mount):
    forces = jnp.stack([jnp.zeros(20), jnp.zeros(20), jnp.linspace(-300, 300, 20)], axis=1)
    loads = mount.loads(forces={"load": forces})
    path = ds.solve_sweep(mount, loads)
    batch = ds.solve_statics(mount, loads)
    np.testing.assert_allclose(path.q, batch.q, atol=1e-9)
    assert int(jnp.max(path.iterations)) <= int(jnp.max(batch.iterations))


def test_joint_reaction_balances_the_part(mount, mount_loads):
    """Sum of all wrenches on the link about the ball centre vanishes (reaction included)."""
    sol = ds.solve_statics(mount, mount_loads)
    force, _ = ds.joint_reactions(mount, sol)
    _, _, fb, _ = ds.bushing_states(mount, sol.q)
    pos, rot = ds.marker_poses(mount, sol.q)
    length, tension = ds.spring_states(mount, sol.q)
    mk = mount.markers
    seat = pos[mk.index("spring.j")] - pos[mk.index("spring.i")]
    f_spring = -tension[0] * seat / length[0]
    f_bush = rot[mk.index("bush.j")] @ fb[0]
    total = force[0] + f_bush + f_spring + mount_loads.force[0]
    np.testing.assert_allclose(total, 0.0, atol=1e-8)


# ------------------------------------------------------------------------------- bad input


def test_unknown_marker_is_named():
    b = ds.MechanismBuilder()
    b.part("arm")
    b.marker("a", "arm", (0, 0, 0))
    with pytest.raises(ds.ModelError, match="unknown marker 'nope'"):
        b.joint("j", "spherical", "a", "nope")


def test_joint_on_a_single_part():
    b = ds.MechanismBuilder()
    b.part("arm")
    with pytest.raises(ds.ModelError, match="both markers on part 'arm'"):
        b.joint("j", "revolute", parts=("arm", "arm"), at=(0, 0, 0))


def test_negative_and_nonfinite_stiffness():
    b = ds.MechanismBuilder()
    b.part("arm")
    with pytest.raises(ds.ModelError, match="k_trans of bushing 'b' is negative"):
        b.bushing("b", parts=("arm", "ground"), at=(0, 0, 0), k_trans=-1.0, k_rot=1.0)
    mech = isolated()
    bad = eqx.tree_at(lambda m: m.bushings.k_rot, mech, mech.bushings.k_rot.at[0, 1].set(jnp.nan))
    with pytest.raises(ValueError, match="bushings.k_rot contains non-finite"):
        ds.solve_statics(bad, bad.loads())
    neg = eqx.tree_at(lambda m: m.bushings.k_trans, mech, -mech.bushings.k_trans)
    with pytest.raises(ValueError, match="bushing 'bush' has k_trans"):
        ds.solve_statics(neg, neg.loads())


def test_zero_length_spring():
    b = ds.MechanismBuilder()
    b.part("arm")
    with pytest.raises(ds.ModelError, match="spring 's' has zero length"):
        b.spring("s", parts=("arm", "ground"), at=(0, 0, 0), k=10.0, free_length=5.0)


def test_free_part_is_named():
    b = ds.MechanismBuilder()
    b.part("arm")
    b.part("rod")
    b.bushing("b", parts=("arm", "ground"), at=(0, 0, 0), k_trans=100.0, k_rot=1e5)
    b.joint("b1", "spherical", parts=("rod", "arm"), at=(100, 0, 0))
    b.joint("b2", "spherical", parts=("rod", "ground"), at=(100, 200, 0))
    with pytest.raises(ds.ModelError, match="part 'rod' is free: rotation about axis"):
        b.build()
    report = ds.validate(b.build(check=False))
    assert len(report.free_modes) == 1 and "(0.000, 1.000, 0.000)" in report.free_modes[0]


def test_redundant_constraints_reported_not_fatal():
    """Two coaxial revolutes on one part: 10 rows, rank 5 + ... → redundancy reported, solves."""
    b = ds.MechanismBuilder()
    b.part("door")
    b.joint("hinge_top", "revolute", parts=("door", "ground"), at=(0, 0, 100), z=(0, 0, 1))
    b.joint("hinge_bottom", "revolute", parts=("door", "ground"), at=(0, 0, -100), z=(0, 0, 1))
    b.bushing("torsion", parts=("door", "ground"), at=(0, 0, 0), k_rot=1e5)
    b.load_point("handle", part="door", at=(500, 0, 0))
    mech = b.build()
    report = ds.validate(mech)
    assert report.dof == 1 and report.rank == 5 and len(report.redundant) == 5
    sol = ds.solve_statics(mech, mech.loads(forces={"handle": [0.0, 100.0, 0.0]}))
    # Torsion spring: K·AZ = 100 N × 500 mm·cos(θ) (the handle swings): solve for θ directly.
    theta = float(jnp.arctan2(gibbs_to_matrix(sol.q[3:])[1, 0], gibbs_to_matrix(sol.q[3:])[0, 0]))
    assert abs(1e5 * theta - 100.0 * 500.0 * np.cos(theta)) < 1e-6


def test_unassembled_joint_is_reported():
    b = ds.MechanismBuilder()
    b.part("arm")
    b.marker("a", "arm", (0, 0, 0))
    b.marker("g", "ground", (0, 3, 0))
    b.joint("ball", "spherical", "a", "g")
    with pytest.raises(ds.ModelError, match="joint 'ball' .* violated by 3 mm"):
        b.build()


def test_nonconvergence_names_the_case(mount):
    # Case 1 has no equilibrium: the link turns about its ball joint, so the bushing and the
    # spring can only resist a bounded moment (≈ 1e8 N·mm), far below 1e12 N·mm. (A huge force
    # does have one: the link turns until the force passes through the ball.)
    loads = mount.loads(forces={"load": jnp.array([[0.0, 0.0, 100.0], [0.0, 0.0, 0.0]])},
                        moments={"load": jnp.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1e12]])})
    warnings.simplefilter("ignore", ds.ModelWarning)  # the failed case is far out of range
    with pytest.raises(ds.ConvergenceError, match="load case 1 did not converge"):
        ds.solve_statics(mount, loads, max_steps=8)
    with pytest.warns(UserWarning, match="1 of 2 cases did not converge"):
        sol = ds.solve_statics(mount, loads, max_steps=8, throw=False)
    assert list(np.asarray(sol.status != 0)) == [False, True]
    status = [ds.statics.Status(int(c)) for c in np.asarray(sol.status)]
    assert status[0] is ds.statics.Status.CONVERGED and status[1] is not status[0]
    with pytest.raises(ds.ConvergenceError, match=status[1].text):
        ds.solve_statics(mount, loads, max_steps=8)


def test_split_over_devices_gives_the_one_device_result(mount):
    # 5 cases over 2 CPU devices (padded to 6), one of them without an equilibrium: the same
    # bits as on one device, statuses and flags included.
    jz = jnp.array([[0.0, 0.0, 0.0]] * 4 + [[0.0, 0.0, 1e12]])
    loads = mount.loads(forces={"load": jnp.linspace(-1.0, 1.0, 15).reshape(5, 3) * 200.0},
                        moments={"load": jz})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        one = ds.solve_statics(mount, loads, max_steps=8, throw=False, devices=1)
        two = ds.solve_statics(mount, loads, max_steps=8, throw=False, devices=2)
    assert list(np.asarray(one.status != 0)) == [False] * 4 + [True]
    for a, b in zip(jax.tree.leaves(one), jax.tree.leaves(two), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    with pytest.raises(ValueError, match="local device"):
        ds.solve_statics(mount, loads, devices=64)


def test_bushing_rotated_past_validity_warns(iso):
    small = iso.loads(moments={"centre": [2.0e5, 0.0, 0.0]})  # ≈ 20° about x in the J frame
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        with pytest.warns(ds.ModelWarning, match="bushing 'bush' is rotated by"):
            ds.solve_statics(iso, small, throw=False)


def test_projected_angle_convention_matches_adams():
    r = reuler_deg_to_matrix(jnp.array([0.0, 10.0, 0.0]))  # 10° about x
    np.testing.assert_allclose(projected_angles(r), [np.radians(10.0), 0.0, 0.0], atol=1e-15)


@pytest.mark.slow
def test_pseudo_mcpherson_gradients_match_central_differences():
    """Wheel-centre position under the 13 thesis cases: ∂/∂(bushing stiffness, hardpoint, spring
    free length, loads) by the implicit forward mode against central differences."""
    from diffsusp.models import pseudo_mcpherson, thesis_load_cases

    mech = pseudo_mcpherson()
    loads = thesis_load_cases(mech)
    wc = mech.markers.index("wheel_centre")
    # The rear ball joint's hardpoint: both of its markers move together.
    l7 = np.array([mech.markers.index("L7_rear_arm_ball"), mech.markers.index("L7_hub_rear_ball")])

    def params_of(m, l):
        return (m.bushings.k_trans[1, 0], m.markers.position[l7[0], 2], m.springs.free_length[0],
                l.force[:, 0, 1])

    def centre(theta):
        k, z7, free, lateral = theta
        m = eqx.tree_at(
            lambda m: (m.bushings.k_trans, m.markers.position, m.springs.free_length), mech,
            (mech.bushings.k_trans.at[1, 0].set(k), mech.markers.position.at[l7, 2].set(z7),
             mech.springs.free_length.at[0].set(free)),
        )
        l = eqx.tree_at(lambda l: l.force, loads, loads.force.at[:, 0, 1].set(lateral))
        pos, _ = ds.marker_poses(m, ds.solve_statics(m, l).q)
        return pos[:, wc]

    theta = params_of(mech, loads)
    jac = eqx.filter_jit(jax.jacfwd(centre))(theta)
    for k, h in zip(range(3), (1.0, 1e-3, 1e-3), strict=True):
        plus = list(theta)
        minus = list(theta)
        plus[k] = theta[k] + h
        minus[k] = theta[k] - h
        fd = (centre(tuple(plus)) - centre(tuple(minus))) / (2 * h)
        scale = float(jnp.max(jnp.abs(fd)))
        np.testing.assert_allclose(jac[k], fd, rtol=1e-6, atol=1e-6 * scale)
    # Loads: the lateral force of case 7 (index 6) moves only case 7.
    e = jnp.zeros(13).at[6].set(1.0)
    fd = (centre(theta[:3] + (theta[3] + e,)) - centre(theta[:3] + (theta[3] - e,))) / 2.0
    np.testing.assert_allclose(jac[3][:, :, 6], fd, rtol=1e-6, atol=1e-9)


def test_pool_gives_each_case_its_own_iterates(mount, monkeypatch):
    """A batch larger than the solver's pool (cases iterated a few at a time, a stopped case's
    slot taken by the next) returns bit for bit what the whole batch solved at once does, the
    failed case included, in input order."""
    rng = np.random.default_rng(3)
    forces = rng.uniform(-300.0, 300.0, (10, 3))
    moments = np.zeros((10, 3))
    moments[6, 2] = 1e12  # no equilibrium (see test_nonconvergence_names_the_case)
    loads = mount.loads(forces={"load": forces}, moments={"load": moments})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the failed case
        whole = ds.solve_statics(mount, loads, throw=False)
        monkeypatch.setattr(solve_module, "_POOL", 3)
        pooled = ds.solve_statics(mount, loads, throw=False)
    assert list(np.flatnonzero(np.asarray(whole.status))) == [6]
    for a, b in zip(jax.tree.leaves(whole), jax.tree.leaves(pooled), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
