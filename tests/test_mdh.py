"""diffsusp.mdh: MDH trees, Newton–Euler vs closed-form Lagrange, regressor, base parameters,
the thesis's tables (spec: tyre_contact_model §6, §1.4, §4.1, §5.2)."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsusp import mdh
from diffsusp.errors import ModelError

FK = eqx.filter_jit(mdh.forward_kinematics)
G = 9.81
GRAV = jnp.array([0.0, -G, 0.0])  # planar tests: gravity along −y_0, joint axes along z_0


def _params(n, rows):
    p = np.zeros((n, 14))
    for j, values in rows.items():
        for name, v in values.items():
            p[j, mdh.PER_JOINT.index(name)] = v
    return jnp.asarray(p)


def test_transform_closed_form_f2_corrected_sign():
    """(F-2) with the corrected row 2, column 1 (CORRECTIONS 9) = the product (F-1)."""
    g, b, a, d, t, r = 0.3, 0.2, -0.7, 0.4, 1.1, -0.25

    def rz(x):
        return np.array([[np.cos(x), -np.sin(x), 0, 0], [np.sin(x), np.cos(x), 0, 0],
                         [0, 0, 1, 0], [0, 0, 0, 1]])

    def rx(x):
        return np.array([[1, 0, 0, 0], [0, np.cos(x), -np.sin(x), 0],
                         [0, np.sin(x), np.cos(x), 0], [0, 0, 0, 1]])

    def tz(x):
        m = np.eye(4)
        m[2, 3] = x
        return m

    def tx(x):
        m = np.eye(4)
        m[0, 3] = x
        return m

    ref = rz(g) @ tz(b) @ rx(a) @ tx(d) @ rz(t) @ tz(r)
    T = np.asarray(mdh.transform(g, b, a, d, t, r))
    np.testing.assert_allclose(T, ref, atol=1e-15)
    assert T[1, 0] == pytest.approx(np.sin(g) * np.cos(t) + np.cos(g) * np.cos(a) * np.sin(t))


def test_pendulum_newton_euler_equals_lagrange():
    """One revolute joint, COM at l on x_1: Γ = ZZ q̈ + MX g cos q + k q + h q̇ + fs sign q̇ +
    off (Lagrange, gravity along −y_0)."""
    tree = mdh.from_rows([mdh.Row(1, 0, mdh.REVOLUTE, 0, 0, 0, 0, 0, 0, "q", "pendulum")])
    m, l, ig = 2.3, 0.7, 0.11
    k, h, fs, off = 3.0, 0.4, 0.25, -0.6
    params = _params(1, {0: {"ZZ": ig + m * l * l, "MX": m * l, "M": m, "XX": 0.3,
                             "YY": 0.5, "k": k, "h": h, "fs": fs, "off": off}})
    states = np.random.default_rng(1).uniform(-2, 2, (5, 3, 1))
    tau = jax.jit(jax.vmap(lambda s: mdh.inverse_dynamics(tree, params, *s, gravity=GRAV)))(
        jnp.asarray(states))[:, 0]
    q, qd, qdd = states[:, :, 0].T
    ref = ((ig + m * l * l) * qdd + m * G * l * np.cos(q) + k * q + h * qd
           + fs * np.sign(qd) + off)
    np.testing.assert_allclose(np.asarray(tau), ref, rtol=0, atol=1e-10)


def test_two_link_newton_euler_equals_lagrange():
    """Planar two-link chain with COMs off the links' axes (MX, MY ≠ 0) against its closed-form
    Lagrange equations (Christoffel terms written out)."""
    l1 = 0.9
    tree = mdh.from_rows([mdh.Row(1, 0, mdh.REVOLUTE, 0, 0, 0, 0, 0, 0, "q1"),
                          mdh.Row(2, 1, mdh.REVOLUTE, 0, 0, 0, l1, 0, 0, "q2")])
    m1, m2 = 3.0, 1.7
    mx1, my1, mx2, my2 = 1.2, -0.3, 0.8, 0.25
    zz1, zz2 = 0.9, 0.6
    params = _params(2, {0: {"ZZ": zz1, "MX": mx1, "MY": my1, "M": m1, "XX": 0.2, "XZ": 0.05},
                         1: {"ZZ": zz2, "MX": mx2, "MY": my2, "M": m2, "YZ": -0.04}})
    states = np.random.default_rng(2).uniform(-2, 2, (6, 3, 2))
    taus = jax.jit(jax.vmap(lambda s: mdh.inverse_dynamics(tree, params, *s, gravity=GRAV)))(
        jnp.asarray(states))
    for ((q1, q2), (d1, d2), (a1, a2)), tau in zip(states, taus, strict=True):
        c2, s2 = np.cos(q2), np.sin(q2)
        ma = l1 * (mx2 * c2 - my2 * s2)  # m2·a(q2)
        mb = -l1 * (mx2 * s2 + my2 * c2)  # m2·a'(q2)
        M11 = zz1 + zz2 + m2 * l1**2 + 2 * ma
        M12 = zz2 + ma
        M22 = zz2
        q12 = q1 + q2
        g1 = G * (mx1 * np.cos(q1) - my1 * np.sin(q1) + m2 * l1 * np.cos(q1)
                  + mx2 * np.cos(q12) - my2 * np.sin(q12))
        g2 = G * (mx2 * np.cos(q12) - my2 * np.sin(q12))
        ref = np.array([M11 * a1 + M12 * a2 + mb * (2 * d1 * d2 + d2**2) + g1,
                        M12 * a1 + M22 * a2 - mb * d1**2 + g2])
        np.testing.assert_allclose(np.asarray(tau), ref, rtol=0, atol=1e-10)


@pytest.fixture(scope="module")
def chain():
    return mdh.tables.contact_chain(wobble=0.02)


def test_regressor_reproduces_torques(chain):
    """W·X = Γ on random states and parameters (contact chain, Table 1, with gravity)."""
    rng = np.random.default_rng(3)
    Q = jnp.asarray(rng.uniform(-1.0, 1.0, (3, 80, 7)))  # the shape base_parameters uses
    X = jnp.asarray(rng.normal(size=(chain.n, 14)))
    W = mdh.regressor_batch(chain, *Q, jnp.array([0.0, 0.0, -9.81]))
    tau = jax.jit(jax.vmap(lambda q, qd, qdd: mdh.inverse_dynamics(chain, X, q, qd, qdd)))(*Q)
    np.testing.assert_allclose(np.asarray(W @ X.ravel()), np.asarray(tau), rtol=1e-12,
                               atol=1e-11)


def test_regressor_with_loads_affine_part():
    """With external loads Γ = W·X + Γ_0: Γ_0 = −Jᵀ·(applied wrench) for a load on the leaf."""
    tree = mdh.from_rows([mdh.Row(1, 0, mdh.REVOLUTE, 0, 0, 0, 0, 0, 0, "q1"),
                          mdh.Row(2, 1, mdh.REVOLUTE, 0, 0, 0, 0.5, 0, 0, "q2")])
    q = jnp.array([0.3, -0.4])
    load = jnp.zeros((2, 6)).at[1, :3].set(jnp.array([1.0, 2.0, 0.0]))  # in frame 2

    @jax.jit
    def run(q, load):
        W, tau0 = mdh.regressor(tree, q, q, q, loads=load)
        return W, tau0, mdh.forward_kinematics(tree, q)[1, :3, :3], mdh.jacobian(tree, q, 2)

    W, tau0, R2, J = run(q, load)
    f0 = R2 @ load[1, :3]
    np.testing.assert_allclose(np.asarray(tau0), -np.asarray(J[:3].T @ f0), atol=1e-14)
    assert W.shape == (2, 28)


def test_jacobian_and_forward_recursion_velocities(chain):
    """(F-8) columns = autodiff of the geometric model; the Newton–Euler forward recursion's
    body twist equals J·q̇ (rotated into the body frame)."""
    q = jnp.array([0.3, -0.2, -0.28, 0.04, 0.01, -0.02, 0.05])
    qd = jnp.array([30.0, 0.5, 0.1, -0.2, 0.3, 0.1, -0.4])

    @jax.jit
    def run(q, qd):
        out = []
        for body in (6, 10):
            J = mdh.jacobian(chain, q, body)
            pos = jax.jacfwd(lambda x, b=body: mdh.forward_kinematics(chain, x)[b - 1, :3, 3])(q)
            motion = mdh.newton_euler(chain, jnp.zeros((10, 14)), q, qd, 0 * q).motion
            R = mdh.forward_kinematics(chain, q)[body - 1, :3, :3]
            out.append((J, pos, motion, R))
        return out

    for body, (J, pos, motion, R) in zip((6, 10), run(q, qd), strict=True):
        np.testing.assert_allclose(np.asarray(J[:3]), np.asarray(pos), atol=1e-13)
        twist = J @ qd
        np.testing.assert_allclose(np.asarray(R @ motion.velocity[body - 1]),
                                   np.asarray(twist[:3]), atol=1e-12)
        np.testing.assert_allclose(np.asarray(R @ motion.omega[body - 1]),
                                   np.asarray(twist[3:]), atol=1e-12)


def test_twist_wrench_transport_power_and_point_change():
    """Transport of twists (2-34) and wrenches (2-36) keeps the power 𝔽ᵀ𝒱; M_BA (2-71)."""
    T = mdh.transform(0.2, 0.1, 0.7, 0.3, -0.4, 0.5)
    rng = np.random.default_rng(4)
    v_j, f_i = jnp.asarray(rng.normal(size=6)), jnp.asarray(rng.normal(size=6))
    TT = mdh.twist_transport(T)
    v_i = TT @ v_j
    f_j = TT.T @ f_i
    assert float(f_i @ v_i) == pytest.approx(float(f_j @ v_j), rel=1e-13)
    back = mdh.twist_transport(mdh.inverse_transform(T)) @ v_i
    np.testing.assert_allclose(np.asarray(back), np.asarray(v_j), atol=1e-14)
    BA = jnp.array([0.1, -0.2, 0.3])
    vb = mdh.change_of_point(BA) @ v_j
    np.testing.assert_allclose(np.asarray(vb[:3]),
                               np.asarray(v_j[:3] + jnp.cross(BA, v_j[3:])), atol=1e-15)


def test_forward_dynamics_inverts_inverse_dynamics():
    """q̈ from forward_dynamics reproduces Γ through the inverse model (driven joint too)."""
    tree = mdh.tables.flat_trac(bench_locked=True)
    rng = np.random.default_rng(5)
    X = jnp.asarray(rng.uniform(0.5, 1.5, (tree.n, 14)))
    X = X.at[:, 1:3].set(0.0).at[:, 4].set(0.0)  # XY, XZ, YZ = 0: positive inertia
    q, qd = jnp.asarray(rng.normal(size=4)), jnp.asarray(rng.normal(size=4))
    tau = jnp.asarray(rng.normal(size=4))

    @jax.jit
    def run(X, q, qd, tau):
        qdd = mdh.forward_dynamics(tree, X, q, qd, tau, free=(0, 1, 3),
                                   qdd_given=jnp.array([0.0, 0.0, 0.7, 0.0]))
        return qdd, mdh.inverse_dynamics(tree, X, q, qd, qdd)

    qdd, back = run(X, q, qd, tau)
    np.testing.assert_allclose(np.asarray(back)[[0, 1, 3]], np.asarray(tau)[[0, 1, 3]],
                               atol=1e-10)
    assert float(qdd[2]) == 0.7


def test_tables_dof_and_typos_resolved():
    """7, 58, 30, 12 DOF; Table 1 joint 7 slides along y_p (lateral, 'ballant') and joint 8 along
    x_p (longitudinal, 'avance'); Table 4's belt joints prismatic, R_pf→belt plane = (3-1, 3-2)."""
    c = mdh.tables.contact_chain()
    assert (c.dof, c.n) == (7, 10)
    assert [c.variables[j] for j in c.mobile] == ["theta", "xi", "h", "gamma", "y", "x", "beta"]
    T = FK(c, jnp.zeros(7))
    Rp = T[5, :3, :3]
    np.testing.assert_allclose(np.asarray(Rp.T @ T[6, :3, 2]), [0, 1, 0], atol=1e-15)  # y
    np.testing.assert_allclose(np.asarray(Rp.T @ T[7, :3, 2]), [1, 0, 0], atol=1e-15)  # x
    np.testing.assert_allclose(np.asarray(Rp.T @ T[8, :3, 2]), [0, 0, 1], atol=1e-15)  # β
    for dof in (58, 30, 12):
        assert mdh.tables.vehicle(dof).dof == dof
    v12 = mdh.tables.vehicle(12)
    assert sorted(v12.variables[j] for j in v12.mobile)[:4] == ["FL_steer", "FL_z", "FR_steer",
                                                               "FR_z"]
    # the body frame is the ground frame at q = 0; wheel carriers at (L, l, z), axes of the body
    Tv = FK(v12, jnp.zeros(12))
    np.testing.assert_allclose(np.asarray(Tv[mdh.tables.body_index(v12) - 1]), np.eye(4),
                               atol=1e-15)
    for wheel, body in mdh.tables.carrier_bodies(v12).items():
        l, L, z = mdh.tables.default_geometry()[wheel]
        np.testing.assert_allclose(np.asarray(Tv[body - 1, :3, 3]), [L, l, z], atol=1e-15)
        np.testing.assert_allclose(np.asarray(Tv[body - 1, :3, :3]), np.eye(3), atol=1e-15)
    ft = mdh.tables.flat_trac()
    assert ft.dof == 6 and [ft.sigma[j] for j in (4, 5, 6, 7)] == [0, 1, 1, 2]
    assert mdh.tables.flat_trac_with_wheel().dof == 4 + 7
    b, g, h = 0.1, 0.05, 0.3
    ftl = mdh.tables.flat_trac(bench_locked=True)
    Tf = np.asarray(FK(ftl, jnp.array([g, h, b, 0.7])))
    pf_base = np.linalg.inv(Tf[3])
    ref = np.array([[np.cos(b), np.sin(b) * np.cos(g), np.sin(b) * np.sin(g), 0],
                    [-np.sin(b), np.cos(b) * np.cos(g), np.cos(b) * np.sin(g), 0],
                    [0, -np.sin(g), np.cos(g), -h], [0, 0, 0, 1]])  # (3-1), translation −h
    np.testing.assert_allclose(pf_base, ref, atol=1e-15)
    pf_road = pf_base @ Tf[7]
    n, d = pf_road[:3, 2], pf_road[:3, 2] @ pf_road[:3, 3]
    n_ref = [np.sin(b) * np.sin(g), np.cos(b) * np.sin(g), np.cos(g)]  # (3-2)
    d_ref = -h * np.cos(g)
    np.testing.assert_allclose(n, n_ref, atol=1e-15)
    assert d == pytest.approx(d_ref, abs=1e-15)


def test_base_parameters_of_the_contact_chain():
    """Base parameters of Table 1's chain (all 10 bodies' inertial parameters and the 7 mobile
    joints' k, h, fs, off): 59 of 128, with a clean numerical gap and Khalil's regroupings, e.g.
    the wheel's ZZ1 + YY2 (the wobble body turns with the wheel), the masses M8 + M9 + M10
    carried by the longitudinal joint x, the patch body's ZZ9 + ZZ10."""
    fit, names = mdh.base_parameters(mdh.tables.contact_chain(), 0)
    assert len(names) == 10 * 10 + 7 * 4
    assert fit.rank == 59
    sv = np.sort(fit.singular_values_scaled)[::-1]
    assert sv[58] > 1e-2 and sv[59] < 1e-13
    rel = set(fit.relations)
    assert {"ZZ1 + YY2", "MX1 + MX2", "M4 + M5 + M6", "M8 + M9 + M10", "ZZ9 + ZZ10",
            "ZZ3 + XX4 + YY5 + ZZ6 + XX7 + YY8"} <= rel
    assert all("e+" not in r and "e-" not in r for r in fit.relations)  # no rounding noise
    kept = {n for n, k in zip(fit.names, fit.kept, strict=True) if k}
    assert {"k4", "h4", "off4", "k9", "fs1"} <= kept


def test_bad_trees_and_inputs():
    with pytest.raises(ModelError, match="antecedent"):
        mdh.from_rows([mdh.Row(1, 1, 0, 0, 0, 0, 0, 0, 0)])
    with pytest.raises(ModelError, match="sigma"):
        mdh.from_rows([mdh.Row(1, 0, 3, 0, 0, 0, 0, 0, 0)])
    c = mdh.tables.contact_chain()
    with pytest.raises(ModelError, match=r"shape \(7,\)"):
        mdh.forward_kinematics(c, jnp.zeros(10))
    with pytest.raises(ModelError, match="params must have shape"):
        mdh.inverse_dynamics(c, jnp.zeros((10, 13)), jnp.zeros(7), jnp.zeros(7), jnp.zeros(7))
    with pytest.raises(ModelError, match="no mobile joint"):
        c.with_locked(["nope"])
    assert math.isclose(float(c.index("gamma")), 3)
