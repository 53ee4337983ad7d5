"""The tyre on the K&C rig (`diffsusp.tyre.rig`).

References:
- a wheel held at its contact point by one six-axis bushing (axes along the global ones): a
  contact-patch force then only translates the wheel, and an aligning torque M_z turns it by
  exactly M_z/K_rz about the vertical (the load acts at the bushing's I marker; no small-angle
  approximation). With the tyre's M_x, M_y switched off (λ_Mx = λ_My = 0) the coupled
  equilibrium is the scalar equation α = α_cmd − M_z(α)/K_rz, solved here by bracketing with
  the independent NumPy transcription of the Magic Formula (tests/test_tyre_oracle.py);
- its derivative with respect to K_rz from the implicit function theorem on that scalar
  equation; finite differences of the whole coupled solve; zero sensitivity to the bushing's
  other stiffnesses;
- the small-slip linear regime with the wheel's aligning-torque compliance steer;
- the pseudo-McPherson: the rigid-suspension limit (bushings ×10⁸: the tyre's own force at the
  commanded slip and the design camber) and the sensitivities of F_y and M_z to every bushing
  stiffness (one forward-mode program) against central differences of the same solve.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import brentq
from test_tyre_oracle import mf_numpy

from diffsusp import InputError, kc
from diffsusp.io.tir import read_tir
from diffsusp.model import MechanismBuilder
from diffsusp.models import pseudo_mcpherson
from diffsusp.tyre import MagicFormula6, example_path
from diffsusp.tyre import rig as R


def quick_jit(fn):
    """`eqx.filter_jit`'s semantics (arrays traced, everything else static) compiled with
    XLA's backend (LLVM) optimisation off: this file's two programs (the coupled solve with its
    forward derivatives, on the bushing wheel and on the pseudo-McPherson) run in well under a
    second in all but cost most of the file's CPU to compile."""
    from diffsusp.compilation import CPU_OPTIONS

    compiled = {}

    def call(*args):
        dynamic, static = eqx.partition(args, eqx.is_array)
        leaves, treedef = jax.tree.flatten(static)
        key = (treedef, tuple(leaves))
        if key not in compiled:
            options = {"xla_backend_optimization_level": 0}
            if jax.default_backend() == "cpu":
                options.update(CPU_OPTIONS)
            compiled[key] = jax.jit(lambda d: fn(*eqx.combine(d, static)),
                                    compiler_options=options)
        return compiled[key](dynamic)
    return call


K_T = 500.0  # N/mm
K_RZ = 4.0e7  # N·mm/rad: about 0.7 kN·m/deg
R_L = 300.0
WHEEL_Y = -800.0  # a left wheel in the Adams/Car frame (x rearward, y right, z up)


def bushing_wheel(k_rz=K_RZ, stiffen=1.0, k_rot=None):
    """`k_rot` (3): the bushing's rotational stiffnesses instead of (10⁸, 10⁸, k_rz)·stiffen;
    the structure (hence the compiled programs) is the same for every value."""
    b = MechanismBuilder("tyre test wheel on one bushing")
    b.part("hub")
    b.marker("wheel_centre", "hub", (0.0, WHEEL_Y, R_L), z=(0.0, -1.0, 0.0), x=(1.0, 0.0, 0.0))
    b.bushing("bush", parts=("hub", "ground"), at=(0.0, WHEEL_Y, 0.0), reuler_deg=(0.0, 0.0, 0.0),
              k_trans=K_T * stiffen,
              k_rot=k_rot or (1.0e8 * stiffen, 1.0e8 * stiffen, k_rz * stiffen))
    b.load_point("contact_patch", part="hub", at=(0.0, WHEEL_Y, 0.0))
    b.load_point("wheel_centre", marker="wheel_centre")
    return b.build()


CORNER = kc.Corner(wheel_centre="wheel_centre", contact_point="contact_patch",
                   wheel_centre_load="wheel_centre", frame="adams", loaded_radius=R_L,
                   design_load=4000.0)


@pytest.fixture(scope="module")
def tir():
    return read_tir(example_path("mf61"))


@pytest.fixture(scope="module")
def tyre(tir):
    # M_x and M_y off: the closed form needs a pure aligning torque at the bushing point.
    return MagicFormula6.from_tir(tir).replace(LMX=0.0, LMY=0.0)


def oracle(tir, fz, kappa, alpha, gamma):
    """(F_x, F_y [N], M_z [N·mm]) of the NumPy transcription at LONGVL, INFLPRES."""
    fx, fy, _, _, mz = mf_numpy(tir, fz, kappa, alpha, gamma, float(tir["LONGVL"]),
                                float(tir["INFLPRES"]))
    return float(fx), float(fy), 1000.0 * float(mz)


def scalar_root(tir, fz, kappa, alpha_cmd, gamma, k_rz):
    """α solving α = α_cmd − M_z(α)/K_rz."""
    def h(a):
        return a - alpha_cmd + oracle(tir, fz, kappa, a, gamma)[2] / k_rz

    return brentq(h, alpha_cmd - 0.3, alpha_cmd + 0.3, xtol=1e-15, rtol=1e-15)


CASES = dict(  # F_z, α_cmd, κ, camber offset (K&C sense)
    fz=np.array([4000.0, 4000.0, 6000.0, 3000.0, 4000.0, 4000.0]),
    slip_angle=np.array([0.0, 0.03, -0.06, 0.12, 0.02, 2e-4]),
    slip_ratio=np.array([0.0, 0.0, 0.05, -0.03, 0.0, 0.0]),
    camber_offset=np.array([0.0, 0.0, 0.0, 0.0, 0.02, 0.0]),
)


@pytest.fixture(scope="module")
def wheel_rig(tyre):
    return R.tyre_rig(bushing_wheel(), tyre, corner=CORNER)


@pytest.fixture(scope="module")
def wheel_jvp(wheel_rig):
    """Solution and its forward derivative along a tangent of the bushing stiffnesses (a
    mechanism-shaped tangent of which only `bushings.k_trans`, `k_rot` are used; default K_rz), one
    program for every bushing-wheel variant and both modes (`driven` 0: contact patch, 1: wheel
    centre); values reused for FD. Outputs: F_x, F_y, M_z, α, γ, steer, status, and the arm from
    the contact point to the wheel centre (3)."""
    from diffsusp.statics import marker_poses

    tangent = jax.tree.map(jnp.zeros_like, eqx.filter(wheel_rig.mech, eqx.is_inexact_array))
    tangent = eqx.tree_at(lambda m: m.bushings.k_rot, tangent,
                          jnp.zeros_like(wheel_rig.mech.bushings.k_rot).at[0, 2].set(1.0))
    lp, rc = wheel_rig.mech.load_points, wheel_rig.corner

    @quick_jit
    def program(mech, d_stiffness, driven):
        def f(k_trans, k_rot):
            m = eqx.tree_at(lambda m: (m.bushings.k_trans, m.bushings.k_rot), mech,
                            (k_trans, k_rot))
            sol = R.solve(eqx.tree_at(lambda r: (r.mech, r.driven), wheel_rig, (m, driven)),
                          **CASES, throw=False)
            pos = jax.vmap(lambda q: marker_poses(m, q)[0])(sol.q)
            arm = (pos[:, lp.marker[rc.wheel_centre_load]] - pos[:, lp.marker[rc.contact_point]])
            return (sol.forces.fx, sol.forces.fy, sol.forces.mz, sol.slip_angle,
                    sol.inclination, sol.steer, sol.status.astype(float), arm)

        # only the stiffnesses carry a tangent (the tests' directions): a smaller program
        # than a tangent on every leaf of the mechanism
        b = mech.bushings
        return jax.jvp(f, (b.k_trans, b.k_rot), d_stiffness)

    def run(mech, d_mech, driven=0.0):
        d = (d_mech.bushings.k_trans, d_mech.bushings.k_rot)
        return program(mech, d, jnp.asarray(driven))

    return run, tangent


def test_bushing_wheel_matches_the_scalar_closed_form(wheel_rig, wheel_jvp, tir):
    run, tangent = wheel_jvp
    (fx, fy, mz, alpha, gamma, steer, status, _), _ = run(wheel_rig.mech, tangent)
    assert np.all(np.asarray(status) == 0)
    for c in range(CASES["fz"].size):
        g = -CASES["camber_offset"][c]  # left wheel: ISO inclination = −camber
        a = scalar_root(tir, CASES["fz"][c], CASES["slip_ratio"][c], CASES["slip_angle"][c], g,
                        K_RZ)
        want = oracle(tir, CASES["fz"][c], CASES["slip_ratio"][c], a, g)
        np.testing.assert_allclose(float(alpha[c]), a, rtol=0, atol=1e-12)
        np.testing.assert_allclose(float(gamma[c]), g, rtol=0, atol=1e-13)
        np.testing.assert_allclose(float(steer[c]), want[2] / K_RZ, rtol=1e-9, atol=1e-14)
        np.testing.assert_allclose([float(fx[c]), float(fy[c]), float(mz[c])], want,
                                   rtol=1e-9, atol=1e-7)
    # the aligning torque turns the wheel toward smaller |α| (compliance understeer)
    assert abs(float(alpha[3])) < CASES["slip_angle"][3]


def test_bushing_wheel_sensitivity_to_k_rz(wheel_rig, wheel_jvp, tir):
    run, tangent = wheel_jvp
    _, (dfx, dfy, dmz, dalpha, *_) = run(wheel_rig.mech, tangent)
    h = 1e-4 * K_RZ
    plus = run(bushing_wheel(K_RZ + h), tangent)[0]
    minus = run(bushing_wheel(K_RZ - h), tangent)[0]
    for c in range(CASES["fz"].size):
        fz, kappa, a_cmd = (CASES[k][c] for k in ("fz", "slip_ratio", "slip_angle"))
        g = -CASES["camber_offset"][c]
        a = scalar_root(tir, fz, kappa, a_cmd, g, K_RZ)
        e = 1e-6
        d_fy, d_mz = ((oracle(tir, fz, kappa, a + e, g)[i] - oracle(tir, fz, kappa, a - e, g)[i])
                      / (2 * e) for i in (1, 2))
        mz = oracle(tir, fz, kappa, a, g)[2]
        da = (mz / K_RZ**2) / (1.0 + d_mz / K_RZ)  # implicit function theorem
        np.testing.assert_allclose(float(dalpha[c]), da, rtol=1e-6, atol=1e-22)
        np.testing.assert_allclose(float(dfy[c]), d_fy * da, rtol=1e-6, atol=1e-18)
        for k, d in ((0, dfx), (1, dfy), (2, dmz), (3, dalpha)):
            fd = (float(plus[k][c]) - float(minus[k][c])) / (2 * h)
            assert abs(float(d[c]) - fd) <= 1e-6 * max(abs(fd), 1e-14) + 1e-15, (c, k)


def test_bushing_wheel_only_k_rz_matters_and_rigid_limit(wheel_rig, wheel_jvp, tir):
    run, tangent = wheel_jvp
    # translations and the other rotations carry no torque here: zero derivatives
    zero = jnp.zeros((1, 3))
    for field, axis in (("k_trans", 0), ("k_trans", 1), ("k_trans", 2), ("k_rot", 0),
                        ("k_rot", 1)):
        unit = zero.at[0, axis].set(1.0)
        t = eqx.tree_at(lambda m: (m.bushings.k_trans, m.bushings.k_rot), tangent,
                        (unit, zero) if field == "k_trans" else (zero, unit))
        _, d = run(wheel_rig.mech, t)
        assert np.all(np.abs(np.asarray(d[1])) < 1e-12), (field, axis)
        assert np.all(np.abs(np.asarray(d[3])) < 1e-18), (field, axis)
    # rigid limit: the tyre's own force at the commanded slip
    (fx, fy, mz, alpha, *_), _ = run(bushing_wheel(stiffen=1e8), tangent)
    for c in range(CASES["fz"].size):
        want = oracle(tir, CASES["fz"][c], CASES["slip_ratio"][c], CASES["slip_angle"][c],
                      -CASES["camber_offset"][c])
        np.testing.assert_allclose([float(fx[c]), float(fy[c]), float(mz[c])], want, rtol=1e-8,
                                   atol=1e-6)


def test_linear_regime_with_the_compliance_steer(wheel_rig, wheel_jvp, tir):
    """F_y = F_y0 + C_α·α, M_z = M_z0 + C_M·α, α = α_cmd − Δψ with Δψ = σ·c·M_z and c the
    aligning-torque compliance steer in the K&C sense (toe per toe-out torque; the left wheel's
    toe-out axis is up and σ = −1), c = −1/K_rz here (what `kc.aligning_torque` reports for
    this wheel): α = (α_cmd − σ·c·M_z0)/(1 + σ·c·C_M)."""
    c = -1.0 / K_RZ
    sigma = -1.0
    e = 1e-6
    f0 = oracle(tir, 4000.0, 0.0, 0.0, 0.0)
    c_a = (oracle(tir, 4000.0, 0.0, e, 0.0)[1] - oracle(tir, 4000.0, 0.0, -e, 0.0)[1]) / (2 * e)
    c_m = (oracle(tir, 4000.0, 0.0, e, 0.0)[2] - oracle(tir, 4000.0, 0.0, -e, 0.0)[2]) / (2 * e)
    a_cmd = CASES["slip_angle"][5]
    run, tangent = wheel_jvp
    (_, fy, _, got, *_), _ = run(wheel_rig.mech, tangent)
    alpha = (a_cmd - sigma * c * f0[2]) / (1.0 + sigma * c * c_m)
    np.testing.assert_allclose(float(got[5]), alpha, rtol=2e-3)
    np.testing.assert_allclose(float(fy[5]), f0[1] + c_a * alpha, rtol=2e-3)
    # the compliance matters at this scale: the rigid answer is off by more than the tolerance
    assert abs(alpha - a_cmd) > 1e-2 * abs(a_cmd)


# ------------------------------------------------- wheel-centre mode (a driven wheel)

K_RY = 2.0e7  # N·mm/rad: the pitch stiffness of the wheel-centre test's bushing


def test_wheel_centre_mode_pitches_a_driven_wheel(wheel_jvp, tir):
    """`longitudinal_at='wheel_centre'` (a drive shaft reacts the torque about the spin axis):
    the carrier receives the tyre force at the wheel centre, so a bushing at the contact point
    sees the pitch moment of F_x at the height R_l, and of F_z once the wheel centre has moved
    forward: with roll and yaw held (10¹⁴), the forward tilt θ of the hub solves
    K_ry·θ = R_l·(F_x·cos θ − F_z·sin θ) exactly (F_x of the tyre at the commanded κ and at the
    equilibrium α ≈ α_cmd, γ = −camber offset, which the pitch does not change: the spin axis
    stays put); dθ/dK_ry = −θ/(K_ry + R_l(F_x sin θ + F_z cos θ)) (implicit function theorem).
    The same wheel in contact-patch mode does not pitch: the brake torque is reacted by the
    carrier and the pitch moment about the contact point is M_y = 0 (λ_My = 0 here)."""
    run, tangent = wheel_jvp
    mech = bushing_wheel(k_rot=(1.0e14, K_RY, 1.0e14))
    d_ky = eqx.tree_at(lambda m: m.bushings.k_rot, tangent,
                       jnp.zeros_like(mech.bushings.k_rot).at[0, 1].set(1.0))
    rig = R.tyre_rig(mech, MagicFormula6.from_tir(tir), corner=CORNER,
                     longitudinal_at="wheel_centre")
    assert rig.longitudinal_at == "wheel_centre" and float(rig.driven) == 1.0
    (fx, fy, mz, alpha, gamma, _, status, arm), (*_, d_arm) = run(mech, d_ky, 1.0)
    assert np.all(np.asarray(status) == 0)
    arm, d_arm = np.asarray(arm), np.asarray(d_arm)
    forward = np.asarray(CORNER_RESOLVED(mech).forward)  # the vehicle's forward unit vector
    pitched = 0
    for c in range(CASES["fz"].size):
        fz, a_cmd, kappa, offset = (CASES[k][c] for k in ("fz", "slip_angle", "slip_ratio",
                                                            "camber_offset"))
        a, g = float(alpha[c]), float(gamma[c])
        assert abs(a - a_cmd) < 1e-9 and abs(g + offset) < 1e-9  # yaw and roll held
        want = oracle(tir, fz, kappa, a, g)
        np.testing.assert_allclose([float(fx[c]), float(fy[c]), float(mz[c])], want,
                                   rtol=1e-9, atol=1e-7)
        theta = brentq(lambda t, fx=want[0], fz=fz: K_RY * t - R_L * (fx * np.cos(t)
                                                                      - fz * np.sin(t)),
                       -0.5, 0.5, xtol=1e-15, rtol=1e-15)
        pitched += abs(theta) > 0.01  # a real pitch, with a real F_z·sin θ term
        np.testing.assert_allclose(np.linalg.norm(arm[c]), R_L, rtol=1e-12)
        np.testing.assert_allclose(arm[c] @ forward / R_L, np.sin(theta), rtol=0, atol=1e-10)
        dtheta = -theta / (K_RY + R_L * (want[0] * np.sin(theta) + fz * np.cos(theta)))
        np.testing.assert_allclose(d_arm[c] @ forward / R_L, np.cos(theta) * dtheta,
                                   rtol=1e-6, atol=1e-18)
    assert pitched >= 2
    # contact-patch mode, same wheel and program: no pitch
    (*_, status, arm), _ = run(mech, d_ky, 0.0)
    assert np.all(np.asarray(status) == 0)
    np.testing.assert_allclose(np.asarray(arm) @ forward, 0.0, atol=1e-9)


def CORNER_RESOLVED(mech):  # noqa: N802
    return R.tyre_rig(mech, MagicFormula6.from_tir(read_tir(example_path("mf61"))),
                      corner=CORNER).corner


# ---------------------------------------------------------------------- pseudo-McPherson


@pytest.fixture(scope="module")
def pm_jvp(tir):
    """F_y, M_z on the pseudo-McPherson at three commanded slip angles and their derivatives
    with respect to all 18 bushing stiffnesses (forward mode), one compiled program."""
    rig = R.tyre_rig(pseudo_mcpherson(), MagicFormula6.from_tir(tir))
    alphas = jnp.radians(jnp.array([-3.0, 1.0, 2.0]))

    @quick_jit
    def run(k_trans, k_rot, spring):
        def f(kt, kr):
            m = eqx.tree_at(lambda m: (m.bushings.k_trans, m.bushings.k_rot, m.springs.k,
                                       m.springs.free_length), rig.mech, (kt, kr, *spring))
            sol = R.solve(eqx.tree_at(lambda r: r.mech, rig, m), alphas, fz=4500.0,
                          throw=False)
            return jnp.stack([sol.forces.fy, sol.forces.mz, sol.slip_angle,
                              sol.inclination, sol.status.astype(float)])

        # the value as jacfwd's aux: f traced once (the program is half the size)
        jac, value = jax.jacfwd(lambda kt, kr: (f(kt, kr),) * 2, argnums=(0, 1),
                                has_aux=True)(k_trans, k_rot)
        return value, jac

    return rig, alphas, run


def test_pm_rigid_limit_is_the_tyre_at_the_command(pm_jvp, tir):
    rig, alphas, run = pm_jvp
    b = rig.mech.bushings
    sp = rig.mech.springs
    pos = rig.mech.markers.position
    length = jnp.linalg.norm(pos[sp.i_marker[0]] - pos[sp.j_marker[0]])
    # a spring 10⁵ times stiffer with the same force at design (free length moved)
    stiff = (sp.k * 1e5, length - (length - sp.free_length) / 1e5)
    (value, _) = run(b.k_trans * 1e5, b.k_rot * 1e5, stiff)
    value = np.asarray(value)
    assert np.all(value[4] == 0)
    camber0 = float(kc.corner_geometry(rig.mech, rig.corner,
                                       jnp.zeros(rig.mech.n_coordinates))["camber"])
    # left wheel: γ = −camber; what is left of the compliance (×10⁻⁵) is ~1e-7 rad
    np.testing.assert_allclose(value[3], -camber0, atol=1e-6)
    for c, a in enumerate(np.asarray(alphas)):
        np.testing.assert_allclose(value[2, c], a, atol=1e-7)
        want = oracle(tir, 4500.0, 0.0, a, -camber0)
        np.testing.assert_allclose(value[:2, c], want[1:], rtol=1e-4)


def test_pm_sensitivities_to_bushing_stiffnesses_match_differences(pm_jvp):
    rig, alphas, run = pm_jvp
    b = rig.mech.bushings
    spring = (rig.mech.springs.k, rig.mech.springs.free_length)
    value, (d_kt, d_kr) = run(b.k_trans, b.k_rot, spring)
    value = np.asarray(value)
    assert np.all(value[4] == 0)
    # compliance steer and camber change the force: F_y differs from the rigid one
    assert np.all(np.abs(value[2] - np.asarray(alphas)) > 1e-5)
    checked = 0
    for field, d in (("k_trans", d_kt), ("k_rot", d_kr)):
        k0 = np.asarray(getattr(b, field))
        d = np.asarray(d)  # (5, cases, bushings, 3)
        for e in range(k0.shape[0]):
            for a in range(3):
                if k0[e, a] == 0.0:
                    continue
                h = 1e-4 * k0[e, a]
                kp, km = (jnp.asarray(k0).at[e, a].add(s) for s in (h, -h))
                if field == "k_trans":
                    vp, vm = run(kp, b.k_rot, spring)[0], run(km, b.k_rot, spring)[0]
                else:
                    vp, vm = run(b.k_trans, kp, spring)[0], run(b.k_trans, km, spring)[0]
                fd = (np.asarray(vp) - np.asarray(vm))[:2] / (2 * h)
                got = d[:2, :, e, a]
                scale = np.abs(value[:2]).max(axis=1, keepdims=True) / k0[e, a]
                np.testing.assert_allclose(got, fd, rtol=1e-4, atol=1e-7 * scale.max())
                checked += 1
    assert checked >= 15


def test_bad_inputs_are_named(wheel_rig, tyre):
    with pytest.raises(InputError, match="fz must be a positive"):
        R.solve(wheel_rig, 0.01, fz=-10.0)
    with pytest.raises(InputError, match="finite"):
        R.solve(wheel_rig, math.nan)
    with pytest.raises(InputError, match="MagicFormula6"):
        R.tyre_rig(bushing_wheel(), object(), corner=CORNER)
    with pytest.raises(InputError, match="longitudinal_at"):
        R.tyre_rig(bushing_wheel(), tyre, corner=CORNER, longitudinal_at="hub")
