"""K&C events and metrics (diffsusp.kc) against independent computations.

References: the NumPy oracle's equilibria (tests/oracle.py) with the metrics recomputed here from
their definitions (written independently of diffsusp.kc.metrics: heading from up × spin axis,
outboard from the side the wheel centre is on), central finite differences of the oracle's
equilibria for every derivative metric (bump steer, wheel rate, roll centre, compliances,
compliance matrix, roll stiffness, steer gain; 1e-5 relative), hand-computed design angles
and pure rotations of the wheel carrier for the sign conventions on left and right corners.

Compile budget: every event uses 13 cases and one of three rig structures, each built once per
module: the pseudo-McPherson with its tie rod on a rack (parallel travel with the rack held at
0, and steering), the double wishbone in force events, and a double-wishbone axle in travel
(opposite and parallel travel: the travel pattern is data). The pseudo-McPherson's force events
(Table 5-1, vertical-force sweep, compliance matrix) are tested in test_cli_kc.py, next to the
command-line runs that compile the same program (pytest-xdist gives each file to one worker).
"""

import jax.numpy as jnp
import numpy as np
import oracle
import pytest

from diffsusp import kc, solve_statics
from diffsusp.errors import ConvergenceError, InputError
from diffsusp.model.combine import combine
from diffsusp.model.mirror import mirror
from diffsusp.models import (
    DOUBLE_WISHBONE_DESIGN_LOAD,
    double_wishbone,
    pseudo_mcpherson,
)
from diffsusp.models._double_wishbone import HARDPOINTS
from diffsusp.models._pseudo_mcpherson import PSEUDO_MCPHERSON_JOINTS, PSEUDO_MCPHERSON_REULER_DEG

N = 13
TRAVEL = np.linspace(-60.0, 60.0, N)
UP = np.array([0.0, 0.0, 1.0])
FORWARD = {"adams": np.array([-1.0, 0.0, 0.0]), "iso": np.array([1.0, 0.0, 0.0])}
GEOMETRIC = ("toe", "steer", "camber", "caster", "kingpin_inclination", "scrub_radius",
             "mechanical_trail", "wheel_centre_x", "wheel_centre_y", "wheel_centre_z",
             "contact_patch_x", "contact_patch_y", "contact_patch_z", "spin_axis_x",
             "spin_axis_y", "spin_axis_z", "wheel_travel", "half_track_change",
             "wheelbase_change", "vertical_force", "lateral_force", "longitudinal_force",
             "aligning_torque")
ANGLES = {"toe", "steer", "camber", "caster", "kingpin_inclination", "spin_axis_x",
          "spin_axis_y", "spin_axis_z"}


# ----------------------------------------------------------------------------- references


def _pm_lower_pivot():
    """Midpoint of the common perpendicular of the lower links L1–L8 and L2–L7 (least squares
    on the two line parameters), global Adams/Car position of the left model."""
    p = {k: np.array(v) for k, v in PSEUDO_MCPHERSON_JOINTS.items()}
    u, v = p["L8"] - p["L1"], p["L7"] - p["L2"]
    (s, t), *_ = np.linalg.lstsq(np.column_stack([u, -v]), p["L2"] - p["L1"], rcond=None)
    return 0.5 * (p["L1"] + s * u + p["L2"] + t * v)


class Spec:
    """What the test knows about a corner, independently of diffsusp.kc: marker names, frame
    (forward direction), loaded radius, steering axis points (marker name, or (part, global
    design position))."""

    def __init__(self, frame, radius, kingpin, prefix=""):
        self.forward, self.radius, self.kingpin, self.prefix = FORWARD[frame], radius, kingpin, \
            prefix


def pm_spec(mirrored=False, prefix=""):
    low = _pm_lower_pivot() * (np.array([1.0, -1.0, 1.0]) if mirrored else 1.0)
    return Spec("adams", 305.0, ("L4_strut_top", ("hub_carrier", low)), prefix)


def dw_spec(prefix=""):
    return Spec("iso", 330.0, ("uca_upright", "lca_upright"), prefix)


def reference_metrics(mech, spec, p, R, force, moment, lam=None, travel_driver=None):
    """Metrics of one corner from an oracle equilibrium (p, R per part), from the definitions:
    toe-in, camber top outboard, caster top rearward, KPI top inboard, scrub radius (axis meets
    the ground inboard +), trail (ahead +), per-side loads."""
    pre = spec.prefix
    names = mech.markers.names
    x, rm = oracle.marker_poses(mech, p, R)
    x0, _ = oracle.marker_poses(mech, np.zeros_like(p), np.tile(np.eye(3), (len(p), 1, 1)))
    k = names.index(pre + "wheel_centre")
    w, w0 = x[k], x0[k]
    out_dir = np.sign(w0[1]) * np.array([0.0, 1.0, 0.0])  # the side the wheel is on
    fwd = spec.forward

    def wheel(xw, s):
        s = s if s @ out_dir > 0 else -s
        h = np.cross(UP, s)
        h /= np.linalg.norm(h)
        h = h if h @ fwd > 0 else -h
        u = UP - (UP @ s) * s
        u /= np.linalg.norm(u)
        oh = s - (s @ UP) * UP
        oh /= np.linalg.norm(oh)
        return s, h, u, oh, xw - spec.radius * u

    s, h, u, oh, c = wheel(w, rm[k][:, 2])
    *_, c0 = wheel(w0, mech.markers.orientation[k][:, 2])
    m = dict(toe=np.arctan2(h @ -out_dir, h @ fwd), camber=np.arctan2(u @ oh, u @ UP))
    m["steer"] = np.arctan2(np.cross(fwd, h) @ UP, h @ fwd)  # heading, counter-clockwise
    m.update(wheel_centre_x=w[0], wheel_centre_y=w[1], wheel_centre_z=w[2], contact_patch_x=c[0],
             contact_patch_y=c[1], contact_patch_z=c[2], spin_axis_x=s[0], spin_axis_y=s[1],
             spin_axis_z=s[2], wheel_travel=w[2] - w0[2], half_track_change=(c - c0) @ out_dir,
             wheelbase_change=(w - w0) @ -fwd)

    def point(ref):
        if isinstance(ref, str):
            return x[names.index(pre + ref)]
        part, pos = ref
        j = mech.parts.index(pre + part)
        return R[j] @ pos + p[j]

    upper, lower = (point(r) for r in spec.kingpin)
    kp = upper - lower
    m["caster"] = np.arctan2(kp @ -fwd, kp @ UP)
    m["kingpin_inclination"] = np.arctan2(kp @ -out_dir, kp @ UP)
    ground = lower + kp * (c[2] - lower[2]) / kp[2]
    m["scrub_radius"] = (ground - c) @ -oh
    m["mechanical_trail"] = (ground - c) @ h
    lp = mech.load_points.names
    contact = [lp.index(n) for n in (pre + "contact_patch", pre + "road_contact") if n in lp]
    f = force[contact].sum(0) + force[lp.index(pre + "wheel_centre")]
    toe_out = UP if np.cross(UP, fwd) @ out_dir > 0 else -UP
    m.update(vertical_force=f[2], lateral_force=f @ -out_dir, longitudinal_force=f @ -fwd,
             aligning_torque=moment[contact].sum(0) @ toe_out)
    if travel_driver is not None:
        m["vertical_force"] += lam[travel_driver]
    m["_out"], m["_fwd"], m["_toe_out"], m["_c"] = out_dir, fwd, toe_out, c
    return m


def case_arrays(ev, c):
    return (np.asarray(ev.loads.force[c]).copy(), np.asarray(ev.loads.moment[c]).copy(),
            np.asarray(ev.loads.driver[c]).copy())


def oracle_metrics(ev, c, spec, corner=0, base=None, dforce=None, dmoment=None, ddriver=None):
    """(metrics, oracle solution) of case c of event `ev`, optionally with perturbed loads."""
    rig = ev.rig
    force, moment, driver = case_arrays(ev, c)
    if dforce is not None:
        force = force + dforce
    if dmoment is not None:
        moment = moment + dmoment
    if ddriver is not None:
        driver = driver + ddriver
    radius = ev.loads.contact_radius
    sol = oracle.solve(rig.mech, force, moment, driver, q0=base,
                       contact_radius=None if radius is None else np.asarray(radius[c]))
    td = rig.travel_drivers[corner]
    lam_index = rig.multiplier_index(td) if td >= 0 else None
    return reference_metrics(rig.mech, spec, sol.p, sol.R, force, moment, sol.lam,
                             lam_index), sol


def assert_geometry(ev, cases, spec, prefix="", corner=0):
    for c in cases:
        ref, _ = oracle_metrics(ev, c, spec, corner)
        for name in GEOMETRIC:
            got = float(ev.metrics[prefix + name][c])
            tol = 1e-9 if name in ANGLES else 1e-6 * max(1.0, abs(ref[name]))
            assert abs(got - ref[name]) < tol, (name, c, got, ref[name])


def fd(ev, c, spec, direction, h, corner=0):
    """Central differences of the reference metrics of case c along a load or driver
    direction: dict (dforce, dmoment, ddriver) of unit perturbations."""
    base, sol = oracle_metrics(ev, c, spec, corner)
    plus, _ = oracle_metrics(ev, c, spec, corner, sol, *(None if d is None else h * d
                                                         for d in direction))
    minus, _ = oracle_metrics(ev, c, spec, corner, sol, *(None if d is None else -h * d
                                                          for d in direction))
    diff = {k: (np.asarray(plus[k]) - np.asarray(minus[k])) / (2 * h) for k in plus
            if not k.startswith("_")}
    diff["_c_plus"], diff["_c_minus"] = plus["_c"], minus["_c"]
    return base, diff


def directions(ev, c, base, corner=0, prefix=""):
    """Unit perturbations (dforce, dmoment, ddriver) of the rig inputs, built from the test's
    own axes: primary (travel driver or vertical force), lateral inboard, longitudinal
    rearward, aligning torque toe-out, at the corner's contact point."""
    rig = ev.rig
    force, moment, driver = case_arrays(ev, c)
    names = rig.mech.load_points.names
    # the force events' loads act at the ground contact point (kc.force_rig: road_contact)
    lp = names.index(prefix + ("road_contact" if prefix + "road_contact" in names
                               else "contact_patch"))

    def at(vec, which):
        arr = np.zeros_like(force if which == "f" else moment)
        arr[lp] = vec
        return arr

    primary = (None, None, np.eye(driver.size)[rig.travel_drivers[corner]]) \
        if rig.mode == "travel" else (at(UP, "f"), None, None)
    return {
        "primary": primary,
        "lateral": (at(-base["_out"], "f"), None, None),
        "longitudinal": (at(-base["_fwd"], "f"), None, None),
        "aligning_torque": (None, at(base["_toe_out"], "m"), None),
    }


def close(got, want, scale, rtol=1e-5):
    """|got − want| ≤ rtol·max(|want|, scale): relative to the value, or to the metric's size
    over the event where the value crosses zero."""
    got, want = float(got), float(want)
    return abs(got - want) <= rtol * max(abs(want), scale)


def assert_derivatives(ev, c, spec, prefix="", corner=0):
    """Every derivative metric of case c against central differences of the oracle."""
    base, _ = oracle_metrics(ev, c, spec, corner)
    dirs = directions(ev, c, base, corner, prefix)
    steps = {"primary": 0.05 if ev.rig.mode != "force" else 2.0, "lateral": 2.0,
             "longitudinal": 2.0, "aligning_torque": 2e3}
    d = {name: fd(ev, c, spec, dirs[name], steps[name], corner)[1] for name in dirs}

    def check(name, want):
        values = np.asarray(ev.metrics[prefix + name])
        scale = float(np.nanmax(np.abs(values)))
        assert close(values[c], want, scale), (name, c, float(values[c]), float(want))

    dz = d["primary"]["wheel_travel"]
    check("bump_steer", d["primary"]["toe"] / dz)
    check("bump_camber", d["primary"]["camber"] / dz)
    check("wheel_rate", d["primary"]["vertical_force"] / dz)
    v = d["primary"]["_c_plus"] - d["primary"]["_c_minus"]
    out = base["_out"]
    check("roll_centre_height", (base["_c"] @ out) * (v @ out) / (v @ UP))
    check("contact_recession_rate", (v @ -base["_fwd"]) / (2 * steps["primary"]) / dz)
    check("wheel_centre_recession_rate",
          (np.array([d["primary"][f"wheel_centre_{a}"] for a in "xyz"]) @ -base["_fwd"]) / dz)
    for what in ("lateral", "longitudinal", "aligning_torque"):
        check(f"{what}_compliance_steer", d[what]["toe"])
        check(f"{what}_compliance_camber", d[what]["camber"])


def assert_compliance_matrix(ev, c, spec, prefix=""):
    """The 6×6 wheel-centre compliance against central differences (forces 10 N, moments
    10 N·m); the rotation from rotvec(R₊ R₋ᵀ)/(2h)."""
    rig = ev.rig
    force, moment, _ = case_arrays(ev, c)
    wc_lp = rig.mech.load_points.names.index(prefix + "wheel_centre")
    k = rig.mech.markers.names.index(prefix + "wheel_centre")
    _, base = oracle_metrics(ev, c, spec)
    want = np.zeros((6, 6))
    for j in range(6):
        h = 10.0 if j < 3 else 1e4
        poses = []
        for sign in (1.0, -1.0):
            df, dm = np.zeros_like(force), np.zeros_like(moment)
            (df if j < 3 else dm)[wc_lp, j % 3] = sign * h
            _, sol = oracle_metrics(ev, c, spec, 0, base, df, dm)
            poses.append(oracle.marker_poses(rig.mech, sol.p, sol.R))
        (xp, rp), (xm, rmm) = poses
        want[:3, j] = (xp[k] - xm[k]) / (2 * h)
        rel = rp[k] @ rmm[k].T
        angle = oracle.rotation_angle(rel)
        axis = np.array([rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0], rel[1, 0] - rel[0, 1]])
        want[3:, j] = axis / (2 * np.sin(angle)) * angle / (2 * h)
    got = np.asarray(kc.compliance_matrix(ev, prefix)[c])
    scale = np.abs(want).max(axis=0)  # per column (mm/N, rad/N, mm/(N·mm), rad/(N·mm) blocks)
    for block in (slice(0, 3), slice(3, 6)):
        for col in range(6):
            s = np.abs(want[block, col]).max()
            np.testing.assert_allclose(got[block, col], want[block, col], rtol=0,
                                       atol=1e-5 * s + 1e-12 * scale[col])
    # A conservative system (potential energy): the compliance matrix is symmetric.
    np.testing.assert_allclose(got, got.T, rtol=0, atol=1e-6 * np.abs(got).max())


# ----------------------------------------------------------------------------- events


@pytest.fixture(scope="module")
def pm():
    return pseudo_mcpherson()


@pytest.fixture(scope="module")
def pm_rack(pm):
    """The half axle with its tie rod on a rack: held at 0 it is the same suspension, and
    parallel travel and steering then share one compiled solve."""
    return kc.with_rack(pm)


@pytest.fixture(scope="module")
def pm_travel(pm_rack):
    return kc.parallel_travel(pm_rack, TRAVEL)


@pytest.fixture(scope="module")
def dw():
    return double_wishbone(bushings=True)


@pytest.fixture(scope="module")
def dw_vertical(dw):
    return kc.vertical_force(dw, DOUBLE_WISHBONE_DESIGN_LOAD * np.linspace(0.7, 1.3, N))


@pytest.fixture(scope="module")
def axle(dw):
    return combine({"left": dw, "right": mirror(dw)})


@pytest.fixture(scope="module")
def axle_opposite(axle):
    return kc.opposite_travel(axle, TRAVEL)


@pytest.fixture(scope="module")
def pm_steering(pm_rack):
    return kc.steering(pm_rack, np.linspace(-20.0, 20.0, N))


# ----------------------------------------------------------------------------- pseudo-McPherson


def test_pm_parallel_travel_metrics_match_oracle(pm_travel):
    assert pm_travel.converged.all()
    np.testing.assert_allclose(pm_travel.metrics["wheel_travel"], TRAVEL, atol=1e-9)
    assert_geometry(pm_travel, (0, 6, 12), pm_spec())


def test_pm_parallel_travel_derivatives_match_oracle_differences(pm_travel):
    assert_derivatives(pm_travel, 9, pm_spec())


def test_pm_design_angles_by_hand(pm_travel):
    """At q = 0: toe = −ψ and camber = θ − 90° of the wheel-centre REULER angles (L9), caster
    and KPI from the steering axis L4 → lower pivot in the Adams/Car frame (x rearward, y right;
    left wheel: inboard is +y)."""
    rig = pm_travel.rig
    rc = rig.corners[0]
    geo = kc.corner_geometry(rig.mech, rc, jnp.zeros(rig.mech.n_coordinates))
    psi, theta, _ = PSEUDO_MCPHERSON_REULER_DEG["L9"]
    assert abs(np.degrees(float(geo["toe"])) - (-psi)) < 1e-10
    assert abs(np.degrees(float(geo["camber"])) - (theta - 90.0)) < 1e-10
    k = np.array(PSEUDO_MCPHERSON_JOINTS["L4"]) - _pm_lower_pivot()
    assert abs(float(geo["caster"]) - np.arctan2(k[0], k[2])) < 1e-12
    assert abs(float(geo["kingpin_inclination"]) - np.arctan2(k[1], k[2])) < 1e-12
    assert np.degrees(float(geo["caster"])) > 7.0 and np.degrees(
        float(geo["kingpin_inclination"])) > 12.0


def _rotate_part(mech, part, angle, axis, centre):
    """Public coordinates with one part turned by `angle` about `axis` through `centre`."""
    q = np.zeros(mech.n_coordinates)
    axis = np.asarray(axis) / np.linalg.norm(axis)
    b = np.tan(angle / 2) * axis
    r = oracle.gibbs_to_matrix(b)
    q[6 * part:6 * part + 3] = centre - r @ centre
    q[6 * part + 3:6 * part + 6] = b
    return jnp.asarray(q)


@pytest.mark.parametrize("which", ["pm_left", "pm_right", "dw_left_iso"])
def test_pure_rotations_give_the_documented_signs(pm, dw, which):
    """Turning the wheel carrier about the vertical through the wheel centre so that the front
    of the wheel moves outboard lowers toe by exactly the angle (toe-in positive); turning it
    about its heading so that the top moves outboard raises camber by the angle (camber top
    outboard positive); on a left wheel (Adams/Car and ISO frames) and a mirrored right one."""
    mech = {"pm_left": pm, "pm_right": mirror(pm), "dw_left_iso": dw}[which]
    frame = "iso" if which.startswith("dw") else "adams"
    rc = kc.default_corner(mech).resolve(mech)
    assert rc.side == ("right" if which == "pm_right" else "left")
    k = mech.markers.index("wheel_centre")
    w0 = np.asarray(mech.markers.position[k])
    out_dir = np.sign(w0[1]) * np.array([0.0, 1.0, 0.0])
    fwd = FORWARD[frame]
    part = mech.markers.part[k]
    theta = np.radians(2.0)
    g0 = kc.corner_geometry(mech, rc, jnp.zeros(mech.n_coordinates))
    toe_out_axis = UP if np.cross(UP, fwd) @ out_dir > 0 else -UP
    g = kc.corner_geometry(mech, rc, _rotate_part(mech, part, theta, toe_out_axis, w0))
    assert abs(float(g["toe"] - g0["toe"]) + theta) < 1e-12
    assert abs(float(g["camber"] - g0["camber"])) < 1e-12
    s = np.asarray(mech.markers.orientation[k][:, 2])
    heading = np.cross(UP, s)
    heading /= np.linalg.norm(heading)
    top_out_axis = heading if np.cross(heading, UP) @ out_dir > 0 else -heading
    g = kc.corner_geometry(mech, rc, _rotate_part(mech, part, theta, top_out_axis, w0))
    assert abs(float(g["camber"] - g0["camber"]) - theta) < 1e-12
    assert abs(float(g["toe"] - g0["toe"])) < 1e-12
    assert abs(float(g["steer"]) - rc.sigma * float(g["toe"])) < 1e-15


def test_pm_steering_matches_oracle_and_sign(pm_steering):
    """Rack travel toward the vehicle's left pushes the tie rod's outer end (ahead of the wheel
    centre, L6) outboard on this left wheel: the wheel turns left (steer > 0, toe-out)."""
    ev = pm_steering
    assert ev.converged.all()
    assert_geometry(ev, (0, 12), pm_spec())
    steer = np.asarray(ev.metrics["steer"])
    assert np.all(np.diff(steer) > 0) and steer[-1] > 0 > steer[0]
    # L6 ahead (x rearward)
    assert PSEUDO_MCPHERSON_JOINTS["L6"][0] < PSEUDO_MCPHERSON_JOINTS["L9"][0]
    for c in (3, 9):
        rig = ev.rig
        unit = np.eye(len(rig.mech.drivers.names))[rig.rack_driver]
        _, diff = fd(ev, c, pm_spec(), (None, None, unit), 0.05)
        assert close(ev.metrics["steer_gain"][c], diff["steer"], 0.0)
        assert close(ev.metrics["camber_steer_gain"][c], diff["camber"],
                     float(np.abs(ev.metrics["camber_steer_gain"]).max()))


def test_anti_pitch_from_recession(pm_travel):
    """Front axle: a contact point moving rearward in bump (recession > 0) gives pro-dive
    (negative anti-dive): anti-dive % = −rate · L/h · β · 100."""
    out = kc.anti_pitch(pm_travel, cg_height=550.0, wheelbase=2600.0, brake_front_fraction=0.7)
    rate = np.asarray(pm_travel.metrics["contact_recession_rate"])
    np.testing.assert_allclose(out["anti_dive"], -rate * 2600.0 / 550.0 * 0.7 * 100.0)
    assert rate[6] > 0 and out["anti_dive"][6] < 0


# ----------------------------------------------------------------------------- double wishbone


def test_dw_vertical_force_metrics_match_oracle(dw_vertical):
    assert dw_vertical.converged.all()
    assert_geometry(dw_vertical, (0, 6, 12), dw_spec())
    # The flags, computed inside the metrics program, are solve_statics's.
    sol = solve_statics(dw_vertical.rig.mech, dw_vertical.loads)
    np.testing.assert_array_equal(np.asarray(dw_vertical.solution.stable), np.asarray(sol.stable))
    np.testing.assert_array_equal(np.asarray(dw_vertical.solution.law_valid),
                                  np.asarray(sol.law_valid))
    assert np.asarray(sol.stable).all()


def test_dw_derivatives_and_compliance_matrix(dw_vertical):
    assert_derivatives(dw_vertical, 4, dw_spec())
    assert_compliance_matrix(dw_vertical, 4, dw_spec())


def test_dw_design_angles_by_hand(dw_vertical):
    """ISO frame (x forward, y left), left wheel: inboard is −y, rearward −x; the spin axis is
    +y, so toe and camber are 0 at design."""
    rig = dw_vertical.rig
    geo = kc.corner_geometry(rig.mech, rig.corners[0], jnp.zeros(rig.mech.n_coordinates))
    k = np.array(HARDPOINTS["uca_upright"]) - np.array(HARDPOINTS["lca_upright"])
    assert abs(float(geo["toe"])) < 1e-15 and abs(float(geo["camber"])) < 1e-15
    assert abs(float(geo["caster"]) - np.arctan2(-k[0], k[2])) < 1e-12
    assert abs(float(geo["kingpin_inclination"]) - np.arctan2(-k[1], k[2])) < 1e-12


# ----------------------------------------------------------------------------- axle


def test_axle_opposite_travel_matches_half_axle_oracle(dw, axle_opposite):
    """Left wheel +t, right −t on combine(dw, mirror(dw)): each corner equals the oracle's
    half-axle equilibrium (left model at +t, mirrored model at −t); roll angle and roll
    stiffness against the oracle's wheel loads: K = −(T/2) d(F_L − F_R)/dφ."""
    ev = axle_opposite
    assert ev.converged.all()
    left = kc.travel_rig(dw)
    right = kc.travel_rig(mirror(dw))
    track = 2 * HARDPOINTS["spindle"][1]
    for c in (2, 10):
        for rig, prefix, sign in ((left, "left/", 1.0), (right, "right/", -1.0)):
            driver = np.array([sign * TRAVEL[c]])
            n_l = len(rig.mech.load_points.names)
            sol = oracle.solve(rig.mech, np.zeros((n_l, 3)), np.zeros((n_l, 3)), driver)
            ref = reference_metrics(rig.mech, dw_spec(), sol.p, sol.R, np.zeros((n_l, 3)),
                                    np.zeros((n_l, 3)), sol.lam, rig.multiplier_index(0))
            for name in GEOMETRIC:
                got = float(ev.metrics[prefix + name][c])
                tol = 1e-9 if name in ANGLES else 1e-6 * max(1.0, abs(ref[name]))
                assert abs(got - ref[name]) < tol, (prefix, name, c, got, ref[name])
        np.testing.assert_allclose(ev.metrics["roll_angle"][c],
                                   np.arctan2(-2 * TRAVEL[c], track), rtol=0, atol=1e-10)
        # Finite differences: forces and heights of the two half axles at t ± h.
        h = 0.1
        loads, heights = {}, {}
        for rig, name, sign in ((left, "L", 1.0), (right, "R", -1.0)):
            for step in (h, -h):
                n_l = len(rig.mech.load_points.names)
                sol = oracle.solve(rig.mech, np.zeros((n_l, 3)), np.zeros((n_l, 3)),
                                   np.array([sign * (TRAVEL[c] + step)]))
                loads[name, step] = sol.lam[rig.multiplier_index(0)]
                heights[name, step] = sign * (TRAVEL[c] + step)
        phi = {s: np.arctan2(heights["R", s] - heights["L", s], track) for s in (h, -h)}
        dload = (loads["L", h] - loads["R", h]) - (loads["L", -h] - loads["R", -h])
        want = -0.5 * track * dload / (phi[h] - phi[-h])
        assert close(ev.metrics["roll_stiffness"][c], want, 0.0)
        # Independent corners: K = k_L·T²/4 + k_R·T²/4 (wheel rates along each wheel's travel).
        k_l, k_r = (float(ev.metrics[p + "wheel_rate"][c]) for p in ("left/", "right/"))
        assert close(ev.metrics["roll_stiffness"][c],
                     (k_l + k_r) * track**2 / 4 * (1 + (2 * TRAVEL[c] / track) ** 2), 0.0)


def test_axle_left_and_mirrored_right_agree_per_side(axle, axle_opposite):
    """Per-side conventions: in parallel travel the left corner and its mirror image give the
    same toe, camber, caster, ..., and opposite y coordinates; in opposite travel the right
    wheel at −t equals the left at +t (same compiled program: the travel pattern is data)."""
    ev = kc.parallel_travel(axle, TRAVEL)
    assert "roll_stiffness" not in ev.metrics
    assert not any(k.rsplit("/", 1)[-1] in ("roll_stiffness", "roll_steer") for k in ev.metrics)
    np.testing.assert_allclose(ev.metrics["roll_angle"], 0.0, atol=1e-12)
    # Steer is signed for the vehicle (left turn +): opposite on the two sides for a toe-in.
    np.testing.assert_allclose(ev.metrics["right/steer"], -ev.metrics["left/steer"], atol=1e-12)
    per_side = [k for k in ev.corner_metrics("left") if not k.endswith("_y") and k != "steer"]
    for name in per_side:
        a, b = np.asarray(ev.metrics["left/" + name]), np.asarray(ev.metrics["right/" + name])
        scale = max(1e-12, float(np.abs(a).max()))
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-9 * scale, err_msg=name)
    for name in ("wheel_centre_y", "contact_patch_y", "spin_axis_y"):
        np.testing.assert_allclose(ev.metrics["right/" + name], -ev.metrics["left/" + name],
                                   rtol=0, atol=1e-9)
    op = axle_opposite
    for name in ("toe", "camber", "half_track_change", "bump_steer", "wheel_rate"):
        np.testing.assert_allclose(op.metrics["right/" + name][::-1], op.metrics["left/" + name],
                                   rtol=0, atol=1e-9 * float(np.abs(op.metrics["left/" + name])
                                                             .max()), err_msg=name)


def test_axle_roll_steer_is_steer_per_roll_angle(dw, axle_opposite):
    """roll_steer (per corner, opposite travel): d(steer)/d(roll angle), against central
    differences of the oracle's half-axle equilibria (left at t ± h, mirrored right at
    −(t ± h)), steer from the definitions here and φ = atan2(z_R − z_L, T); none in parallel
    travel, where the body does not roll."""
    ev = axle_opposite
    track = 2 * HARDPOINTS["spindle"][1]
    h = 0.1
    for c in (2, 10):
        dphi = (np.arctan2(-2 * (TRAVEL[c] + h), track)
                - np.arctan2(-2 * (TRAVEL[c] - h), track))
        for mech, prefix, sign in ((dw, "left/", 1.0), (mirror(dw), "right/", -1.0)):
            rig = kc.travel_rig(mech)
            zero = np.zeros((len(rig.mech.load_points.names), 3))
            steer = []
            for step in (h, -h):
                sol = oracle.solve(rig.mech, zero, zero, np.array([sign * (TRAVEL[c] + step)]))
                steer.append(reference_metrics(rig.mech, dw_spec(), sol.p, sol.R, zero, zero,
                                               sol.lam, rig.multiplier_index(0))["steer"])
            want = (steer[0] - steer[1]) / dphi
            assert close(ev.metrics[prefix + "roll_steer"][c], want, 1e-4), (prefix, c)
    assert kc.METRICS["roll_steer"].per_roll and "roll_steer" in kc.DERIVATIVE_METRICS


# ----------------------------------------------------------------------------- errors


def test_unknown_marker_is_named(pm):
    with pytest.raises(InputError, match="Corner.wheel_centre: the model has no marker 'hub'"):
        kc.parallel_travel(pm, TRAVEL, corner=kc.Corner(wheel_centre="hub"))
    with pytest.raises(InputError, match="no default K&C corner"):
        kc.default_corner(combine({"a": pm}, name="my model"))
    with pytest.raises(InputError, match="Corner.frame"):
        kc.Corner(frame="sae")


def test_opposite_travel_needs_two_sides_and_steering_needs_a_rack(pm):
    with pytest.raises(InputError, match="one left and one right corner"):
        kc.opposite_travel(pm, TRAVEL)
    with pytest.raises(InputError, match="rack driver 'rack_travel'"):
        kc.steering(pm, TRAVEL)
    with pytest.raises(InputError, match="distance joint"):
        kc.with_rack(pm, tie_rod="strut_slide")


def test_non_converging_case_raises_or_gives_nan(dw, dw_vertical):
    """100 kN (11 times the design load) has no equilibrium within the double wishbone's
    travel: the event names the case; with throw=False the metrics are NaN and a warning says
    how many failed, the other cases are unaffected."""
    fz = np.full(N, DOUBLE_WISHBONE_DESIGN_LOAD)
    fz[4] = 1e5
    with pytest.raises(ConvergenceError, match=r"vertical_force: case 4 \(vertical_force = "
                                               r"100000 N\) did not converge"):
        kc.vertical_force(dw, fz)
    with pytest.warns(UserWarning, match="1 of 13 cases did not converge"):
        ev = kc.vertical_force(dw, fz, throw=False)
    assert np.isnan(ev.metrics["toe"][4]) and np.isnan(ev.metrics["bump_steer"][4])
    assert np.isnan(kc.compliance_matrix(ev)[4]).all()
    np.testing.assert_allclose(ev.metrics["toe"][5], dw_vertical.metrics["toe"][6], atol=1e-12)


def test_corner_loads_per_side_table_without_an_event(pm, axle):
    """`kc.corner_loads`: a per-side (vertical, lateral, longitudinal) table as Loads, no
    event run. Adams/Car left wheel (x rearward): exactly the thesis's load cases; the ISO
    frame's left wheel (x forward, the Chrono strut): (−F_long, −F_lat, F_vert), the guides'
    hand-made vectors; a mirrored right wheel: lateral inboard is −y; load_table applies the
    same loads."""
    from diffsusp import load_model
    from diffsusp.models import thesis_load_cases
    from diffsusp.models.loadcases import TABLE_5_1

    got = kc.corner_loads(pm, TABLE_5_1)
    ref = thesis_load_cases(pm)
    np.testing.assert_array_equal(got.force, ref.force)
    np.testing.assert_array_equal(got.moment, ref.moment)
    f_vert, f_lat, f_long = TABLE_5_1.T
    strut = load_model("docs/data/MacPhersonStrut_bushings.json")
    iso = kc.corner_loads(strut, vertical=f_vert, lateral=f_lat, longitudinal=f_long)
    cp = strut.load_points.names.index("contact_patch")
    np.testing.assert_allclose(iso.force[:, cp], np.stack([-f_long, -f_lat, f_vert], 1),
                               rtol=0, atol=1e-9)
    assert float(jnp.abs(iso.force).sum()) == pytest.approx(float(np.abs(TABLE_5_1).sum()))
    both = kc.corner_loads(axle, vertical=4000.0, lateral=[1000.0, -500.0], aligning=2e4)
    left, right = (axle.load_points.names.index(f"{s}/contact_patch") for s in ("left", "right"))
    np.testing.assert_allclose(both.force[:, right], both.force[:, left] * np.array([1, -1, 1]),
                               atol=1e-9)
    assert both.force.shape[0] == 2 and float(both.force[0, left, 2]) == 4000.0
    np.testing.assert_allclose(both.moment[:, right, 2], -both.moment[:, left, 2], atol=1e-9)
    with pytest.raises(InputError, match="table must be"):
        kc.corner_loads(pm, TABLE_5_1[:, :2])
    with pytest.raises(InputError, match="one length"):
        kc.corner_loads(pm, vertical=[1.0, 2.0], lateral=[1.0, 2.0, 3.0])
