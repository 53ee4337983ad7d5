"""diffsusp.solve_statics against the independent NumPy oracle (tests/oracle.py).

The oracle keeps rotation matrices, differences the constraints numerically and balances forces
and moments about each part's origin; diffsusp uses Gibbs vectors, autodiff and generalised
forces. Agreement required: part origins and markers to 1e-8 mm, rotations to 1e-10 rad (angle
of R_jaxᵀ R_oracle), reactions Σλ∇Φ and multipliers to 1e-9 of the load scale. Small
mechanisms first (all in one Mechanism, so diffsusp compiles once; closed forms where there is
one), then the zoo of `diffsusp.models` over the thesis load envelope and a ±80 mm wheel-travel
sweep (marked slow: one diffsusp compile per model). `pytest -s` prints the agreement measured.

Almost all of the runtime is diffsusp's build-time validation and XLA compile (the oracle takes
about 2 s for the small mechanisms and 10 s for the whole zoo).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import oracle  # tests/oracle.py (pytest puts tests/ on sys.path)
import pytest
from helpers import tree_allclose
from scipy.spatial.transform import Rotation
from zoo import TRAVEL_SWEEP, zoo_case, zoo_solution  # noqa: F401  (fixtures)

import diffsusp
from diffsusp import MechanismBuilder

POS_TOL = 1e-8  # mm
ROT_TOL = 1e-10  # rad
DEG = math.pi / 180.0


def rot(*zyx_deg):
    return Rotation.from_euler("zyx", zyx_deg, degrees=True).as_matrix()


# ----------------------------------------------------------------------------- small mechanisms
#
# Each function adds one small, independent mechanism to a builder, naming everything with the
# prefix `n("...")`, and returns its load cases (dicts of `Mechanism.loads` keyword arguments).
# They are all built into ONE Mechanism (the sub-mechanisms share no element, so their
# equilibria are independent): diffsusp then compiles once for all of them, which is most of
# the cost of this file.

R_BUSH = rot(30.0, 20.0, 10.0)
K_T = np.array([100.0, 200.0, 300.0])
K_R = np.array([1.0e5, 2.0e5, 3.0e5])
CENTRE = np.array([100.0, 50.0, 20.0])


def isolated_bushing(b, n):
    """One part held by one bushing (rotated frame) to ground: loads at its centre and a tip."""
    b.part(n("arm"))
    b.bushing(n("bush"), parts=(n("arm"), "ground"), at=CENTRE, orientation=R_BUSH,
              k_trans=K_T, k_rot=K_R)
    b.load_point(n("centre"), part=n("arm"), at=CENTRE)
    b.load_point(n("tip"), part=n("arm"), at=(-200.0, 50.0, 20.0))
    return [
        dict(forces={n("centre"): [100.0, -50.0, 30.0]}),  # closed form: pure translation
        dict(moments={n("centre"): 2.0e4 * R_BUSH[:, 2]}),  # closed form: rotation about z_J
        dict(forces={n("tip"): [100.0, -50.0, 30.0]}, moments={n("centre"): [1e3, 2e3, -5e3]}),
    ]


def spherical_bushing_spring(b, n):
    """Appendix Z test 2: a part on a spherical joint, a bushing in a rotated frame and a
    spring; stiffness [1000, 2000, 300 N/mm; 4000, 1500, 800 N·mm/deg], K = 25 N/mm,
    L0 = 320 mm; 8 random load cases."""
    b.part(n("arm"))
    b.joint(n("ball"), "spherical", parts=(n("arm"), "ground"), at=(0.0, -300.0, 200.0))
    b.bushing(n("bush"), parts=(n("arm"), "ground"), at=(250.0, -350.0, 180.0),
              orientation=rot(40.0, -15.0, 25.0), k_trans=(1000.0, 2000.0, 300.0),
              k_rot=np.array([4000.0, 1500.0, 800.0]) / DEG)
    b.marker(n("seat_arm"), n("arm"), (150.0, -500.0, 250.0))
    b.marker(n("seat_body"), "ground", (120.0, -420.0, 540.0))
    b.spring(n("spring"), n("seat_arm"), n("seat_body"), k=25.0, free_length=320.0)
    b.load_point(n("tip"), part=n("arm"), at=(200.0, -700.0, 150.0))
    rng = np.random.default_rng(2)
    return [dict(forces={n("tip"): f}, moments={n("tip"): m})
            for f, m in zip(rng.uniform(-400.0, 400.0, (8, 3)), rng.uniform(-1e4, 1e4, (8, 3)),
                            strict=True)]


AXIS = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])


def revolute_torsion(b, n):
    """An arm on a revolute joint (tilted axis) held by a torsion bushing on the same axis."""
    b.part(n("arm"))
    b.joint(n("hinge"), "revolute", parts=(n("arm"), "ground"), at=(10.0, 20.0, 30.0), z=AXIS)
    b.bushing(n("torsion"), parts=(n("arm"), "ground"), at=(10.0, 20.0, 30.0), z=AXIS,
              k_rot=(0.0, 0.0, 5.0e5))
    b.load_point(n("hub"), part=n("arm"), at=(10.0, 20.0, 30.0))
    b.load_point(n("tip"), part=n("arm"), at=(310.0, 20.0, -60.0))
    return [
        dict(moments={n("hub"): 3.0e4 * AXIS}),  # closed form: θ = M / k about the axis
        dict(forces={n("tip"): [50.0, 300.0, -200.0]}),
        dict(forces={n("tip"): [-100.0, -250.0, 100.0]}, moments={n("hub"): [1e4, -3e4, 2e4]}),
    ]


SLIDE = np.array([1.0, 1.0, 0.5]) / np.linalg.norm([1.0, 1.0, 0.5])


def translational_spring_stop(b, n):
    """A slider on a translational joint, a (preloaded) spring along the guide, a bump stop."""
    b.part(n("slider"))
    b.joint(n("guide"), "translational", parts=(n("slider"), "ground"), at=(0.0, 0.0, 0.0),
            z=SLIDE)
    base = -300.0 * SLIDE
    b.marker(n("seat"), n("slider"), (0.0, 0.0, 0.0))
    b.marker(n("anchor"), "ground", base)
    b.spring(n("spring"), n("seat"), n("anchor"), k=30.0, free_length=280.0)
    b.marker(n("pad"), n("slider"), 10.0 * SLIDE)
    b.marker(n("buffer"), "ground", base + 5.0 * SLIDE)
    b.stop(n("bump"), n("pad"), n("buffer"), kind="bump", length=250.0, k=500.0, cubic=0.02)
    b.load_point(n("head"), part=n("slider"), at=(0.0, 0.0, 0.0))
    return [
        dict(forces={n("head"): 1000.0 * SLIDE}),  # stop open
        dict(forces={n("head"): -3000.0 * SLIDE + np.array([200.0, -100.0, 50.0])}),  # engaged
        dict(forces={n("head"): -8000.0 * SLIDE}, moments={n("head"): [5e3, -2e3, 1e4]}),
    ]


TRAVEL = (-60.0, 0.0, 40.0, 80.0)


def trailing_arm_driver(b, n):
    """A trailing arm on a revolute joint with a spring, its wheel centre driven vertically."""
    b.part(n("arm"))
    b.joint(n("pivot"), "revolute", parts=(n("arm"), "ground"), at=(0.0, 0.0, 0.0),
            z=(0, 1, 0))
    b.marker(n("seat"), n("arm"), (300.0, 0.0, 20.0))
    b.marker(n("tower"), "ground", (320.0, 0.0, 350.0))
    b.spring(n("spring"), n("seat"), n("tower"), k=40.0, free_length=360.0)
    b.bushing(n("pivot_bush"), parts=(n("arm"), "ground"), at=(0.0, 0.0, 0.0), k_trans=1e3,
              k_rot=(1e6, 1e6, 1e6))
    b.marker(n("wheel_centre"), n("arm"), (450.0, 0.0, 0.0))
    b.driver(n("travel"), n("wheel_centre"), direction=(0.0, 0.0, 1.0))
    b.load_point(n("wheel"), n("wheel_centre"))
    return [dict(drivers={n("travel"): v}, forces={n("wheel"): [f, 0.0, 0.0]})
            for v, f in zip(TRAVEL, (0.0, 500.0, -800.0, 200.0), strict=True)]


def follower_load(b, n):
    """A load whose components are in the axes of a marker on the moving part (Adams RM)."""
    b.part(n("arm"))
    b.joint(n("ball"), "spherical", parts=(n("arm"), "ground"), at=(0.0, 0.0, 0.0))
    b.bushing(n("bush"), parts=(n("arm"), "ground"), at=(0.0, 0.0, 0.0),
              orientation=rot(10, 5, 0), k_rot=(2e6, 3e6, 1e6))
    b.marker(n("tool"), n("arm"), (0.0, 0.0, 400.0), orientation=rot(-20.0, 35.0, 60.0))
    b.load_point(n("push"), n("tool"), frame=n("tool"))
    return [dict(forces={n("push"): f}, moments={n("push"): m})
            for f, m in (([300.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
                         ([0.0, -250.0, 100.0], [2e4, 0.0, 0.0]),
                         ([150.0, 150.0, -400.0], [0.0, -1e4, 3e4]))]


def nonlinear_bushings(b, n):
    """A cubic bushing law, and a bushing with preloads and offsets, in a chain of two parts."""
    b.part(n("link"))
    b.part(n("carrier"))
    b.bushing(n("cubic"), parts=(n("link"), "ground"), at=(0.0, 0.0, 0.0),
              orientation=rot(15, -10, 5), k_trans=(200.0, 150.0, 400.0),
              k_rot=(2e6, 1e6, 3e6), cubic_trans=(2.0, 5.0, 3.0), cubic_rot=(2e8, 4e8, 1e8))
    b.bushing(n("preloaded"), parts=(n("carrier"), n("link")), at=(250.0, 0.0, 50.0),
              orientation=rot(-30, 0, 20), k_trans=(800.0, 600.0, 900.0),
              k_rot=(4e6, 4e6, 2e6), offset_trans=(1.5, -0.5, 2.0),
              offset_rot=(0.01, -0.02, 0.015), preload_force=(100.0, -50.0, 200.0),
              preload_torque=(1e3, -2e3, 5e2))
    b.load_point(n("end"), part=n("carrier"), at=(400.0, 30.0, 60.0))
    return [dict(forces={n("end"): f}) for f in
            ([0.0, 0.0, 0.0], [500.0, -800.0, 300.0], [-900.0, 300.0, 600.0])]


def joint_kinds(b, n):
    """The remaining joint kinds: cylindrical, universal, fixed, inline, inplane,
    perpendicular, distance; every part also held by a bushing so it is determined."""
    for name in ("sleeve", "yoke", "block", "shoe", "rod"):
        b.part(n(name))
    axis = np.array([0.2, 0.1, 1.0]) / np.linalg.norm([0.2, 0.1, 1.0])
    b.joint(n("cyl"), "cylindrical", parts=(n("sleeve"), "ground"), at=(0.0, 0.0, 0.0), z=axis)
    b.bushing(n("sleeve_b"), parts=(n("sleeve"), "ground"), at=(0.0, 0.0, 100.0),
              k_trans=500.0, k_rot=1e6)
    b.marker(n("u_i"), n("yoke"), (0.0, 0.0, 200.0), z=(1.0, 0.0, 0.0))
    b.marker(n("u_j"), n("sleeve"), (0.0, 0.0, 200.0), z=(0.0, 1.0, 0.0))
    b.joint(n("cross"), "universal", n("u_i"), n("u_j"))
    b.bushing(n("yoke_b"), parts=(n("yoke"), "ground"), at=(100.0, 0.0, 250.0), k_trans=800.0,
              k_rot=1e6)
    b.joint(n("weld"), "fixed", parts=(n("block"), n("yoke")), at=(150.0, 50.0, 250.0),
            orientation=rot(20.0, 10.0, -5.0))
    b.bushing(n("block_b"), parts=(n("block"), "ground"), at=(200.0, 80.0, 260.0),
              k_trans=1200.0, k_rot=3e6)
    b.joint(n("rail"), "inline", parts=(n("shoe"), "ground"), at=(-200.0, 100.0, 0.0),
            orientation=rot(0.0, 30.0, 0.0))
    b.joint(n("floor"), "inplane", parts=(n("shoe"), "ground"), at=(-200.0, 100.0, 50.0),
            orientation=rot(0.0, 0.0, 90.0))
    b.marker(n("perp_i"), n("shoe"), (-200.0, 150.0, 0.0), z=(1.0, 0.0, 0.0))
    b.marker(n("perp_j"), "ground", (-200.0, 150.0, 0.0), z=(0.0, 0.0, 1.0))
    b.joint(n("square"), "perpendicular", n("perp_i"), n("perp_j"))
    b.bushing(n("shoe_b"), parts=(n("shoe"), "ground"), at=(-220.0, 120.0, 10.0),
              k_trans=600.0, k_rot=2e6)
    b.marker(n("rod_end"), n("rod"), (-100.0, 300.0, 100.0))
    b.marker(n("sleeve_pt"), n("sleeve"), (0.0, 40.0, 120.0))
    b.joint(n("link"), "distance", n("rod_end"), n("sleeve_pt"))
    b.bushing(n("rod_b"), parts=(n("rod"), "ground"), at=(-100.0, 300.0, 100.0),
              k_trans=900.0, k_rot=1e6)
    loads = {n(k): None for k in ("p_sleeve", "p_block", "p_shoe", "p_rod")}
    b.load_point(n("p_sleeve"), part=n("sleeve"), at=(0.0, 0.0, 150.0))
    b.load_point(n("p_block"), part=n("block"), at=(250.0, 50.0, 300.0))
    b.load_point(n("p_shoe"), part=n("shoe"), at=(-180.0, 100.0, 20.0))
    b.load_point(n("p_rod"), part=n("rod"), at=(-120.0, 350.0, 100.0))
    rng = np.random.default_rng(7)
    return [dict(forces={k: rng.uniform(-800.0, 800.0, 3) for k in loads},
                 moments={n("p_block"): rng.uniform(-3e4, 3e4, 3)}) for _ in range(3)]


def spline_laws(b, n):
    """Akima-spline bushing axes (tx, rz) and a tabulated spring (force-deflection table)."""
    b.part(n("arm"))
    x_t = np.array([-12.0, -6.0, -2.0, 0.0, 2.0, 6.0, 12.0])
    x_r = np.array([-0.4, -0.2, -0.05, 0.0, 0.05, 0.2, 0.4])
    b.bushing(n("bush"), parts=(n("arm"), "ground"), at=(0.0, 0.0, 0.0),
              orientation=rot(25.0, 10.0, -15.0), k_trans=(0.0, 400.0, 500.0),
              k_rot=(3e6, 3e6, 0.0),
              splines={"tx": (x_t, -(150.0 * x_t + 1.5 * x_t**3 + 4.0 * x_t**2)),
                       "rz": (x_r, -(2e5 * x_r + 3e6 * x_r**3))})
    b.marker(n("seat_arm"), n("arm"), (300.0, 0.0, 0.0))
    b.marker(n("seat_body"), "ground", (300.0, 0.0, 250.0))
    b.spring(n("spring"), n("seat_arm"), n("seat_body"), free_length=240.0,
             table=([-60.0, -20.0, 0.0, 20.0, 60.0], [-2500.0, -700.0, 0.0, 600.0, 2000.0]))
    b.load_point(n("tip"), part=n("arm"), at=(400.0, 50.0, 0.0))
    return [dict(forces={n("tip"): f}) for f in
            ([800.0, 0.0, 0.0], [-1500.0, 400.0, -900.0], [2500.0, -300.0, 1200.0])]


SMALL = {
    "isolated_bushing": isolated_bushing,
    "spherical_bushing_spring": spherical_bushing_spring,
    "revolute_torsion": revolute_torsion,
    "translational_spring_stop": translational_spring_stop,
    "trailing_arm_driver": trailing_arm_driver,
    "follower_load": follower_load,
    "nonlinear_bushings": nonlinear_bushings,
    "joint_kinds": joint_kinds,
    "spline_laws": spline_laws,
}


def build_small():
    """All small mechanisms in one Mechanism; returns it and the merged load cases (case c of
    every sub-mechanism at once; a sub-mechanism with fewer cases is unloaded in the rest)."""
    b = MechanismBuilder("small mechanisms")
    per_sub = {}
    for name, add in SMALL.items():
        per_sub[name] = add(b, lambda s, name=name: f"{name}/{s}")
    n_cases = max(len(c) for c in per_sub.values())
    cases = []
    for c in range(n_cases):
        merged = dict(forces={}, moments={}, drivers={})
        for sub in per_sub.values():
            for key, value in (sub[c] if c < len(sub) else {}).items():
                merged[key].update(value)
        cases.append(merged)
    return b.build(), cases, {k: len(v) for k, v in per_sub.items()}


# ----------------------------------------------------------------------------- comparison


def stack_loads(mech, cases):
    one = [mech.loads(**case) for case in cases]
    return jax.tree.map(lambda *a: jnp.stack(a), *one)


def load_arrays(loads, c):
    """Case c of a batched `Loads` as NumPy (force, moment, driver)."""
    return (np.asarray(loads.force[c]), np.asarray(loads.moment[c]),
            np.asarray(loads.driver[c]))


def row_owners(mech):
    """Name of the joint or driver of every live constraint row."""
    names = [name for name, kind in zip(mech.joints.names, mech.joints.kind, strict=True)
             for _ in range(diffsusp.model.JOINT_ROWS[kind])] + list(mech.drivers.names)
    return [names[r] for r in mech.independent_rows]


def compare(mech, q_jax, lam_jax, sols, prefix=""):
    """Largest differences over the cases between diffsusp (q, multipliers per case) and the
    oracle's solutions, over the parts and rows whose names start with `prefix`:
    part origins and markers (mm), rotations (rad, angle of R_jaxᵀ R_oracle), reactions
    Σλ∇Φ per part (relative to F_s, moments to F_s·L) and multipliers (relative)."""
    parts = np.array([k for k, name in enumerate(mech.parts) if name.startswith(prefix)])
    markers = np.array([k for k, part in enumerate(mech.markers.part) if part in parts])
    rows = np.array([k for k, name in enumerate(row_owners(mech)) if name.startswith(prefix)],
                    dtype=int)
    angular = oracle._oracle(mech).model.angular_live
    L = mech.length_scale
    out = dict(position=0.0, rotation=0.0, marker=0.0, reaction=0.0, multiplier=0.0)
    for c, so in enumerate(sols):
        p, r = oracle.from_q(np.asarray(q_jax[c]))
        out["position"] = max(out["position"], float(np.max(np.abs(p - so.p)[parts])))
        out["rotation"] = max(out["rotation"], float(np.max(
            oracle.rotation_angle(np.swapaxes(r, -1, -2) @ so.R)[parts])))
        xj, _ = oracle.marker_poses(mech, p, r)
        xo, _ = oracle.marker_poses(mech, so.p, so.R)
        out["marker"] = max(out["marker"], float(np.max(np.abs(xj - xo)[markers])))
        if rows.size:
            lam = np.asarray(lam_jax[c])
            diff = np.abs(oracle.reactions(mech, so.p, so.R, lam)
                          - oracle.reactions(mech, so.p, so.R, so.lam))[parts] / so.load_scale
            diff[:, 3:] /= L
            out["reaction"] = max(out["reaction"], float(diff.max()))
            scale = np.where(angular, so.load_scale * L, so.load_scale)
            out["multiplier"] = max(out["multiplier"],
                                    float(np.max((np.abs(lam - so.lam) / scale)[rows])))
    return out


def solve_oracle(mech, loads, *, chain=True):
    """Oracle solutions of every case of `loads` (with `chain`, warm-started along them)."""
    return oracle.solve_loads(mech, loads, chain=chain)


def check_agreement(diff):
    assert diff["position"] < POS_TOL, diff
    assert diff["rotation"] < ROT_TOL, diff
    assert diff["marker"] < POS_TOL, diff
    assert diff["reaction"] < 1e-9, diff
    assert diff["multiplier"] < 1e-9, diff


@pytest.fixture(scope="module")
def small():
    """The small mechanisms (one Mechanism) solved by diffsusp and by the oracle, once."""
    mech, cases, n_cases = build_small()
    loads = stack_loads(mech, cases)
    sol = diffsusp.solve_statics(mech, loads)
    sols = solve_oracle(mech, loads, chain=False)
    return mech, loads, sol, sols, n_cases


AGREEMENT: dict[str, dict] = {}  # filled by the tests; printed with `pytest -s` at the end


@pytest.mark.parametrize("name", list(SMALL))
def test_small_agrees_with_oracle(small, name):
    mech, _, sol, sols, n_cases = small
    assert np.all(np.asarray(sol.status) == 0)
    assert all(s.converged for s in sols)
    c = n_cases[name]
    diff = compare(mech, np.asarray(sol.q)[:c], np.asarray(sol.multipliers)[:c], sols[:c],
                   prefix=f"{name}/")
    AGREEMENT[name] = diff
    check_agreement(diff)


# ----------------------------------------------------------------------------- closed forms


def part_pose(mech, so, name):
    k = mech.parts.index(name)
    return so.p[k], so.R[k]


def marker_position(mech, so, name):
    x, _ = oracle.marker_poses(mech, so.p, so.R)
    return x[mech.markers.index(name)]


def test_isolated_bushing_closed_form(small):
    mech, _, _, sols, _ = small
    n = "isolated_bushing/"
    # Force at the centre: pure translation p = R_J K⁻¹ R_Jᵀ F.
    p, r = part_pose(mech, sols[0], n + "arm")
    f = np.array([100.0, -50.0, 30.0])
    np.testing.assert_allclose(p, R_BUSH @ ((R_BUSH.T @ f) / K_T), rtol=0, atol=1e-12)
    assert oracle.rotation_angle(r) < 1e-14
    # Moment M about the bushing's z axis at its centre: rotation M / k_rz about that axis.
    p, r = part_pose(mech, sols[1], n + "arm")
    exact = Rotation.from_rotvec(2.0e4 / K_R[2] * R_BUSH[:, 2]).as_matrix()
    assert oracle.rotation_angle(exact.T @ r) < 1e-14
    np.testing.assert_allclose(marker_position(mech, sols[1], n + "bush.i"), CENTRE, atol=1e-11)


def test_revolute_torsion_closed_form(small):
    mech, _, _, sols, _ = small
    n = "revolute_torsion/"
    _, r = part_pose(mech, sols[0], n + "arm")
    exact = Rotation.from_rotvec(3.0e4 / 5.0e5 * AXIS).as_matrix()
    assert oracle.rotation_angle(exact.T @ r) < 1e-14
    # The hinge carries no moment about its (current) axis: the torsion bushing takes it all.
    so = sols[1]
    k = mech.parts.index(n + "arm")
    react = oracle.reactions(mech, so.p, so.R, so.lam)[k]
    hinge = marker_position(mech, so, n + "hinge.i")
    moment_at_hinge = react[3:] - np.cross(hinge - so.p[k], react[:3])
    assert abs(moment_at_hinge @ (so.R[k] @ AXIS)) < 1e-9 * so.load_scale * mech.length_scale


def test_translational_spring_stop_closed_form(small):
    mech, _, _, sols, _ = small
    n = "translational_spring_stop/"
    # Stop open: the spring (preloaded by 20 mm at design) alone balances the axial load.
    p, r = part_pose(mech, sols[0], n + "slider")
    s = p @ SLIDE
    np.testing.assert_allclose(s, 1000.0 / 30.0 - 20.0, rtol=1e-13)
    np.testing.assert_allclose(p, s * SLIDE, atol=1e-12)
    assert oracle.rotation_angle(r) < 1e-14
    # Bump stop engaged (pad-to-buffer length 305 + s below 250 mm): spring + stop balance it.
    p, _ = part_pose(mech, sols[1], n + "slider")
    s = p @ SLIDE
    pen = 250.0 - (305.0 + s)
    assert pen > 0
    axial = -3000.0 + np.array([200.0, -100.0, 50.0]) @ SLIDE
    np.testing.assert_allclose(30.0 * (300.0 + s - 280.0) - (500.0 * pen + 0.02 * pen**3),
                               axial, rtol=1e-12)


def test_driver_prescribes_wheel_centre(small):
    mech, _, _, sols, _ = small
    n = "trailing_arm_driver/"
    for so, travel in zip(sols, TRAVEL, strict=False):
        assert abs(marker_position(mech, so, n + "wheel_centre")[2] - travel) < 1e-11


# ----------------------------------------------------------------------------- oracle itself


def test_constraint_gradients_match_closed_form(small):
    """Spherical rows: ∂d/∂δp = I, ∂d/∂δθ = −skew(x_I − p): the finite differences are exact
    to round-off."""
    mech, _, _, sols, _ = small
    so = sols[3]
    k = mech.parts.index("spherical_bushing_spring/arm")
    owners = row_owners(mech)
    rows = [i for i, o in enumerate(owners) if o == "spherical_bushing_spring/ball"]
    jac = oracle.constraint_jacobian(mech, so.p, so.R)[rows][:, 6 * k:6 * k + 6]
    arm = marker_position(mech, so, "spherical_bushing_spring/ball.i") - so.p[k]
    exact = np.hstack([np.eye(3), -oracle.skew(arm)])
    np.testing.assert_allclose(jac, exact, rtol=0, atol=1e-12 * np.abs(exact).max())


def test_warm_start_and_root_agree(small):
    mech, loads, _, sols, _ = small
    args = load_arrays(loads, 5)
    warm = oracle.solve(mech, *args, q0=sols[4])
    root = oracle.solve(mech, *args, method="root")
    for other in (warm, root):
        assert np.max(np.abs(other.p - sols[5].p)) < 1e-10
        assert np.max(oracle.rotation_angle(np.swapaxes(other.R, 1, 2) @ sols[5].R)) < 1e-12


def test_gibbs_round_trip():
    rng = np.random.default_rng(0)
    r = Rotation.from_rotvec(rng.uniform(-2.0, 2.0, (5, 3))).as_matrix()
    p = rng.normal(size=(5, 3))
    p2, r2 = oracle.from_q(oracle.to_q(p, r))
    np.testing.assert_allclose(p2, p)
    np.testing.assert_allclose(r2, r, atol=1e-14)
    v = rng.normal(size=(4, 3))
    np.testing.assert_allclose(oracle.expm_so3(v), Rotation.from_rotvec(v).as_matrix(),
                               atol=1e-15)
    np.testing.assert_allclose(oracle.expm_so3(1e-7 * v), Rotation.from_rotvec(1e-7 * v)
                               .as_matrix(), atol=1e-16)


# ----------------------------------------------------------------------------- the zoo
#
# Every (model, load set) of `tests/zoo.py` solved by diffsusp (the zoo's one program per entry)
# and by the oracle (warm-started along a travel sweep, from design for the envelope).


@pytest.fixture(scope="module")
def zoo_oracle(zoo_solution):  # noqa: F811  (the zoo fixture)
    case, sol = zoo_solution
    return case, sol, solve_oracle(case.mech, case.loads, chain=case.load_set == "travel")


@pytest.mark.slow
def test_zoo_agrees_with_oracle(zoo_oracle):
    case, sol, sols = zoo_oracle
    mech = case.mech
    assert np.all(np.asarray(sol.status) == 0)
    assert all(s.converged for s in sols)
    if case.load_set == "travel":
        k = mech.drivers.names.index("wheel_travel")
        m, direction = mech.drivers.marker[k], np.asarray(mech.drivers.direction[k])
        x0 = np.asarray(mech.markers.position[m])
        travel = [(oracle.marker_poses(mech, s.p, s.R)[0][m] - x0) @ direction for s in sols]
        np.testing.assert_allclose(travel, TRAVEL_SWEEP, rtol=0, atol=1e-10)
    diff = compare(mech, np.asarray(sol.q), np.asarray(sol.multipliers), sols)
    AGREEMENT[f"zoo {case.model} {case.load_set}"] = diff
    check_agreement(diff)


@pytest.mark.slow
def test_zoo_batch_equals_loop(zoo_solution):  # noqa: F811  (the zoo fixture)
    """vmap = loop over the zoo: every case of the batch is solved as if alone (no cross-talk
    between the cases of a batch: the batch reversed, the same compiled program, gives every
    case the same solution)."""
    case, sol = zoo_solution
    flipped = diffsusp.solve_statics(case.mech, jax.tree.map(lambda a: a[::-1], case.loads))
    tree_allclose((flipped.q[::-1], flipped.multipliers[::-1], flipped.status[::-1]),
                  (sol.q, sol.multipliers, sol.status), rtol=0, atol=1e-10)


@pytest.fixture(scope="module", autouse=True)
def _print_agreement():
    """With `pytest -s`, print the agreement measured on every mechanism."""
    yield
    if AGREEMENT:
        print("\nagreement diffsusp vs oracle (max over cases):")
        for key, d in AGREEMENT.items():
            print(f"  {key:42s} position {d['position']:.1e} mm, rotation "
                  f"{d['rotation']:.1e} rad, markers {d['marker']:.1e} mm, reactions "
                  f"{d['reaction']:.1e}, multipliers {d['multiplier']:.1e}")
