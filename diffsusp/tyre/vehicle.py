"""A synthetic 12-DOF vehicle on a flat road with a known tyre model and its sensors.

spec: tyre_contact_model §5.2 (the 12-DOF model: body 6 DOF, four suspension travels, two front
steers), §5.3–5.4 (sensors, the steering-wheel sine), §5.5 (4-16…4-18, the tyre model). It is
the test bench of `diffsusp.tyre.onboard`: the identification runs on its sensor record and is
compared with the tyre parameters it was driven with.

The model is the tree `diffsusp.mdh.tables.vehicle(12)` with point unsprung masses, written in
closed form for speed (a 10×10 linear solve per step instead of a Newton–Euler pass per column
of the mass matrix; no test compares it with the generic `mdh.forward_dynamics` of the tree
yet).
Units SI (m, kg, N, s, rad), as the thesis's chapter 4 (the dynamics needs one consistent mass
unit; the library's mm would need tonnes); tyre polynomials in F_z [kN] as (4-17, 4-18).

Road frame: x forward, y left, z up, road at z = 0. Body frame R_c at the body's centre of mass
(x forward, y left, z up). Corner i (FL, FR, RL, RR) has its wheel carrier R_pf at
(L_i, l_i, z0_i + z_i) in the body frame, turned by the steer β_i about z; the tyre frame from
the road plane by `contact` (zero wobble). The wheel rolls freely: ω = V_x/R_r at the contact.

Tyre lateral force, per wheel (4-16): F_y + (−L_R/ω)·Ḟ_y = F_pneu with
F_pneu = K_δ(F_z) δ′ + K_φ(F_z) φ′ + K_γ(F_z) γ, K_δ = b_δ2 F_z² + b_δ1 F_z + b_δ0,
K_φ = b_φ1 F_z, K_γ = b_γ1 F_z, L_R = b_L2 F_z² + b_L1 F_z + b_L0 (F_z in kN). With
δ′ = V_y/ω (m) the physical K_δ is negative (the force opposes the sliding) and the camber
stiffness has the opposite sign (thrust towards the lean; γ > 0 leans the wheel's top to +y).
"""

import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..mdh import tables as mdh_tables
from .vehicle_kc import KCTables, wheel_poses

WHEELS = mdh_tables.WHEELS
GRAVITY = 9.81
TYRE_NAMES = ("b_delta_2", "b_delta_1", "b_delta_0", "b_phi_1", "b_gamma_1", "b_L_2", "b_L_1",
              "b_L_0")


class TyreTruth(eqx.Module):
    """The reduced tyre model (4-16…4-18) the synthetic vehicle drives with (F_z in kN, δ′ in m,
    φ′ and γ in rad, F_y in N; L_R dimensionless)."""

    b_delta_2: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(3000.0))
    b_delta_1: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(-55000.0))
    b_delta_0: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(0.0))
    b_phi_1: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(8000.0))
    b_gamma_1: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(1500.0))
    b_L_2: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(0.0))
    b_L_1: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(-0.12))
    b_L_0: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(0.0))

    def vector(self) -> Array:
        return jnp.stack([getattr(self, n) for n in TYRE_NAMES])

    def stiffnesses(self, fz_kn):
        """(K_δ, K_φ, K_γ, L_R) at F_z [kN]."""
        k_d = self.b_delta_2 * fz_kn**2 + self.b_delta_1 * fz_kn + self.b_delta_0
        l_r = self.b_L_2 * fz_kn**2 + self.b_L_1 * fz_kn + self.b_L_0
        return k_d, self.b_phi_1 * fz_kn, self.b_gamma_1 * fz_kn, l_r


class MagicTyre(eqx.Module):
    """A tyre the reduced model (4-16…4-18) was not written against, for rehearsing the
    identifications: the small-slip behaviour of a Magic Formula tyre (spec tyre §2.2; the
    1989 set's cornering-stiffness law BCD = a3·sin(2·atan(F_z/a4))), the brush model's
    torsion stiffness (proportional to the cornering stiffness times the squared contact
    half-length, ∝ F_z), a camber stiffness ∝ F_z, and the relaxation length of a stretched
    string, σ = K/C_y (cornering stiffness over the carcass's lateral stiffness). Units as
    `TyreTruth` (K_δ in N/m of δ′, negative; F_z in kN); the defaults are close to
    `TyreTruth`'s at 4 kN."""

    a3: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(-186000.0))
    a4: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(6.0))
    torsion: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(-0.0465))
    camber: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(1500.0))
    carcass: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(358000.0))

    def stiffnesses(self, fz_kn):
        """(K_δ, K_φ, K_γ, L_R) at F_z [kN]."""
        k_d = self.a3 * jnp.sin(2.0 * jnp.arctan(fz_kn / self.a4))
        return k_d, self.torsion * k_d * fz_kn, self.camber * fz_kn, k_d / self.carcass


class Vehicle(eqx.Module):
    """Masses, geometry, suspension and tyre of the synthetic car (a mid-size saloon; the
    thesis gives none of these numbers for its Peugeot 406). Corners in `WHEELS` order;
    `corners` (4, 3) = (L_i, l_i, z0_i) in the body frame (m).

    `kinematics`: None for the 12-DOF car (travel along the body's z, steer about it), or the
    K&C tables of the 30-DOF model (`vehicle_kc.kc_tables`, spec tyre §5.2): each carrier's
    toe, camber, half-track and wheelbase changes from its travel and the tyre's lateral force
    (the compliance), the steer added to the toe. The unsprung masses still move along the
    body's z (the tables' few-mm horizontal shifts are left out of the mass matrix)."""

    mass: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(1350.0))
    inertia: Float[Array, "3"] = eqx.field(
        default_factory=lambda: jnp.asarray([450.0, 1900.0, 2100.0]))
    unsprung: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(40.0))
    corners: Float[Array, "4 3"] = eqx.field(default_factory=lambda: jnp.asarray(
        [[L, l, z] for l, L, z in (mdh_tables.default_geometry()[w] for w in WHEELS)]))
    spring: Float[Array, "4"] = eqx.field(
        default_factory=lambda: jnp.asarray([32e3, 32e3, 26e3, 26e3]))
    damper: Float[Array, "4"] = eqx.field(
        default_factory=lambda: jnp.asarray([3200.0, 3200.0, 2800.0, 2800.0]))
    tyre_radius: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(0.30))
    tyre_stiffness: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(2.2e5))
    tyre_damping: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(300.0))
    rolling_radius: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(0.294))
    speed_gain: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(3000.0))
    tyre: TyreTruth | MagicTyre = eqx.field(default_factory=TyreTruth)
    kinematics: KCTables | None = None

    def static_loads(self):
        """Static wheel loads (N) from the weight distribution over the axles."""
        m = self.mass + 4 * self.unsprung
        xf, xr = self.corners[0, 0], self.corners[2, 0]
        front = m * GRAVITY * (-xr) / (xf - xr) / 2
        rear = m * GRAVITY * xf / (xf - xr) / 2
        return jnp.stack([front, front, rear, rear])


def rotation(yaw, pitch, roll) -> Float[Array, "3 3"]:
    """Road ← body rotation, ZYX (yaw ψ about z, pitch about y, roll ϕ about x), as the free
    body of `mdh.tables.free_body`."""
    cy, sy, cp, sp, cr, sr = (jnp.cos(yaw), jnp.sin(yaw), jnp.cos(pitch), jnp.sin(pitch),
                              jnp.cos(roll), jnp.sin(roll))
    return jnp.stack([
        jnp.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr]),
        jnp.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr]),
        jnp.stack([-sp, cp * sr, cp * cr])])


def euler_rates(pitch, roll, omega) -> Float[Array, "3"]:
    """(ψ̇, θ̇, ϕ̇) from the body angular velocity ω (body frame), ZYX."""
    cp, tp, cr, sr = jnp.cos(pitch), jnp.tan(pitch), jnp.cos(roll), jnp.sin(roll)
    p, q, r = omega
    return jnp.stack([(q * sr + r * cr) / cp, q * cr - r * sr, p + (q * sr + r * cr) * tp])


def rot_z(a) -> Float[Array, "3 3"]:
    c, s = jnp.cos(a), jnp.sin(a)
    z, o = jnp.zeros_like(c), jnp.ones_like(c)
    return jnp.stack([jnp.stack([c, -s, z]), jnp.stack([s, c, z]), jnp.stack([z, z, o])])


def corner_poses(vehicle: Vehicle, travel: Float[Array, "4"], steer: Float[Array, "4"],
                 fy: Float[Array, "4"] | None = None):
    """Wheel-carrier frames in the body frame: (R (4, 3, 3), O (4, 3)) — Table 30's chain: of
    the 12-DOF tree (travel along the body z, steer about it) without `vehicle.kinematics`, of
    the 30-DOF model with them (`vehicle_kc.wheel_poses`, `fy` the tyres' lateral forces, N)."""
    if vehicle.kinematics is not None:
        fy = jnp.zeros(4) if fy is None else fy
        R, O, _, _ = wheel_poses(vehicle.kinematics, vehicle.corners, travel, fy, steer)
        return R, O
    O = vehicle.corners + jnp.stack([0 * travel, 0 * travel, travel], axis=1)
    return jax.vmap(rot_z)(steer), O


AMPLITUDE = math.radians(1.2)


def steering_sine(t, *, duration, f0=0.2, f1=6.0, amplitude=AMPLITUDE, start=0.0):
    """The front road-wheel angle of the steering-wheel sine (§5.4): constant amplitude, the
    frequency swept linearly from f0 to f1 over `duration` (starting at `start`), and its rate."""
    tau = jnp.clip(t - start, 0.0, duration)
    active = (t >= start) & (t <= start + duration)
    phase = 2 * jnp.pi * (f0 * tau + (f1 - f0) * tau**2 / (2 * duration))
    freq = f0 + (f1 - f0) * tau / duration
    return (jnp.where(active, amplitude * jnp.sin(phase), 0.0),
            jnp.where(active, amplitude * 2 * jnp.pi * freq * jnp.cos(phase), 0.0))


def _unpack(y):
    return y[:3], y[3:6], y[6:9], y[9:12], y[12:16], y[16:20], y[20:24]


def tyre_kinematics(vehicle: Vehicle, p, angles, v, w, travel, travel_rate, steer, steer_rate,
                    fy=None, fy_rate=None):
    """Per corner (4,): the tyre frame and its inputs from the body state (all in the road
    frame except where said): contact point P, axes x_p y_p, camber γ, loaded radius, V_x, V_y
    of the tyre frame's origin, its yaw rate β̇, and the carrier pose (R, O in the body).
    `fy`, `fy_rate`: the tyres' lateral forces and their rates (the K&C compliance; default
    0)."""
    R = rotation(*angles)
    fy = jnp.zeros(4) if fy is None else fy
    fy_rate = jnp.zeros(4) if fy_rate is None else fy_rate
    # the carriers' poses and their rates relative to the body (first order in time)
    (Rc, Oc), (dRc, dOc) = jax.jvp(lambda z, b, f: corner_poses(vehicle, z, b, f),
                                   (travel, steer, fy), (travel_rate, steer_rate, fy_rate))

    ez = jnp.array([0.0, 0.0, 1.0])

    def one(Rci, Oci, dRci, dOci):
        def frame(t):
            # pose of the corner at time t to first order (for the frame's own velocities)
            pos = p + t * (R @ v)
            Rb = R + t * (R @ _skew(w))
            Oi = Oci + t * dOci
            Ri = Rci + t * dRci
            O_world = pos + Rb @ Oi
            y_w = Rb @ Ri @ jnp.array([0.0, 1.0, 0.0])
            x_p = jnp.cross(y_w, ez)
            x_p = x_p / jnp.linalg.norm(x_p)
            z_cr = jnp.cross(x_p, y_w)
            P = O_world - (O_world[2] / z_cr[2]) * z_cr
            return P, x_p, y_w, O_world

        (P, x_p, y_w, O_w), (dP, dx, _, dO) = jax.jvp(frame, (0.0,), (1.0,))
        y_p = jnp.cross(ez, x_p)
        gamma = jnp.arcsin(-jnp.dot(y_w, ez))
        radius = jnp.linalg.norm(P - O_w)
        return {"P": P, "x_p": x_p, "y_p": y_p, "gamma": gamma, "radius": radius,
                "radius_rate": jnp.dot(P - O_w, dP - dO) / radius,
                "vx": jnp.dot(dP, x_p), "vy": jnp.dot(dP, y_p), "yaw_rate": jnp.dot(dx, y_p),
                "O": O_w}

    return jax.vmap(one)(Rc, Oc, dRc, dOc)


def _skew(a):
    return jnp.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def tyre_forces(vehicle: Vehicle, kin, fy, speed_error):
    """Tyre wrench components (F_x, F_y, F_z) per corner and the relaxation rate Ḟ_y."""
    fz = jnp.maximum(vehicle.tyre_stiffness * (vehicle.tyre_radius - kin["radius"])
                     - vehicle.tyre_damping * kin["radius_rate"], 0.0)
    omega = kin["vx"] / vehicle.rolling_radius
    delta_p = kin["vy"] / omega
    phi_p = kin["yaw_rate"] / omega
    k_d, k_phi, k_g, l_r = vehicle.tyre.stiffnesses(fz / 1000.0)
    pneu = k_d * delta_p + k_phi * phi_p + k_g * kin["gamma"]
    fy_dot = omega * (fy - pneu) / l_r
    fx = jnp.array([0.0, 0.0, 1.0, 1.0]) * (-vehicle.speed_gain * speed_error / 2.0)
    return fx, fz, fy_dot, omega


def dynamics(t, y, args):
    """d/dt of the state (p, angles, v_body, ω_body, z, ż, F_y) (24,)."""
    vehicle, steer_fn, speed = args
    p, ang, v, w, z, zd, fy = _unpack(y)
    beta, beta_rate = steer_fn(t)
    steer = jnp.stack([beta, beta, 0.0 * beta, 0.0 * beta])
    steer_rate = jnp.stack([beta_rate, beta_rate, 0.0 * beta, 0.0 * beta])
    kin = tyre_kinematics(vehicle, p, ang, v, w, z, zd, steer, steer_rate, fy)
    fx, fz, fy_dot, _ = tyre_forces(vehicle, kin, fy, v[0] - speed)
    if vehicle.kinematics is not None:
        # the compliance moves the carriers at the rate of F_y, which the carriers' motion
        # sets: one fixed-point pass (the coupling is ~1e-6 rad/N, its square negligible)
        kin = tyre_kinematics(vehicle, p, ang, v, w, z, zd, steer, steer_rate, fy, fy_dot)
        fx, fz, fy_dot, _ = tyre_forces(vehicle, kin, fy, v[0] - speed)
    R = rotation(*ang)
    # tyre forces in the body frame, applied at the contact points (body-frame lever arms)
    f_world = (fx[:, None] * kin["x_p"] + fy[:, None] * kin["y_p"]
               + fz[:, None] * jnp.array([0.0, 0.0, 1.0]))
    f = f_world @ R  # rows: Rᵀ f
    P_body = (kin["P"] - p) @ R
    g = R.T @ jnp.array([0.0, 0.0, -GRAVITY])
    m, mu = vehicle.mass, vehicle.unsprung
    r = vehicle.corners + jnp.stack([0 * z, 0 * z, z], axis=1)
    ez = jnp.array([0.0, 0.0, 1.0])
    # unknowns: v̇ (3), ω̇ (3), z̈ (4); a_i = v̇ + ω×v + ω̇×r_i + ω×(ω×r_i) + z̈_i e_z + 2ω×ż_i e_z
    base = (jnp.cross(w, v)[None, :] + jnp.cross(w[None, :], jnp.cross(w[None, :], r))
            + 2.0 * jnp.cross(w[None, :], zd[:, None] * ez[None, :]))
    A = jnp.zeros((10, 10))
    b = jnp.zeros(10)
    eye = jnp.eye(3)
    # translation of the whole car
    A = A.at[:3, :3].set((m + 4 * mu) * eye)
    A = A.at[:3, 3:6].set(-mu * jnp.sum(jax.vmap(_skew)(r), axis=0))
    A = A.at[:3, 6:].set(mu * jnp.tile(ez[:, None], (1, 4)))
    b = b.at[:3].set(f.sum(0) + (m + 4 * mu) * g - m * jnp.cross(w, v) - mu * base.sum(0))
    # rotation about the centre of mass
    I = jnp.diag(vehicle.inertia)
    Sr = jax.vmap(_skew)(r)
    A = A.at[3:6, :3].set(mu * Sr.sum(0))
    A = A.at[3:6, 3:6].set(I - mu * jnp.einsum("kij,kjl->il", Sr, Sr))
    A = A.at[3:6, 6:].set(mu * jnp.einsum("kij,j->ik", Sr, ez))
    b = b.at[3:6].set(jnp.cross(P_body, f).sum(0) + mu * jnp.cross(r, g[None, :]).sum(0)
                      - jnp.cross(w, I @ w) - mu * jnp.cross(r, base).sum(0))
    # each unsprung mass along the body z: m_u a_i·e_z = F_i·e_z + m_u g·e_z − spring
    spring = vehicle.spring * z + vehicle.damper * zd + _preload(vehicle)
    rows = jnp.concatenate([mu * jnp.tile(ez[None, :], (4, 1)),
                            -mu * jnp.einsum("j,kjl->kl", ez, Sr),
                            mu * jnp.eye(4)], axis=1)
    A = A.at[6:].set(rows)
    b = b.at[6:].set(f[:, 2] + mu * g[2] - spring - mu * base[:, 2])
    acc = jnp.linalg.solve(A, b)
    vd, wd, zdd = acc[:3], acc[3:6], acc[6:]
    return jnp.concatenate([R @ v, euler_rates(ang[1], ang[2], w), vd, wd, zd, zdd, fy_dot])


def _preload(vehicle: Vehicle):
    """Spring preloads (N, pushing the body up and the unsprung mass down) that hold the car at
    z = 0 statically: the corner's sprung share of the weight."""
    return vehicle.static_loads() - vehicle.unsprung * GRAVITY


def initial_state(vehicle: Vehicle, speed) -> Float[Array, "24"]:
    """Straight running at `speed` (m/s), body at the height where the static tyre loads
    balance the weight (before settling)."""
    loads = vehicle.static_loads()
    deflection = loads / vehicle.tyre_stiffness
    height = -vehicle.corners[:, 2] + vehicle.tyre_radius - deflection
    y = jnp.zeros(24)
    return y.at[2].set(jnp.mean(height)).at[6].set(speed)


class Record(eqx.Module):
    """A simulated run: time (n,) and the true state and tyre quantities per sample."""

    time: Float[Array, " n"]
    state: Float[Array, "n 24"]
    steer: Float[Array, " n"]
    steer_rate: Float[Array, " n"]


@eqx.filter_jit
def simulate(vehicle: Vehicle, *, duration: float, rate: float = 1000.0, speed: float = 25.0,
             settle: float = 1.0, f0: float = 0.2, f1: float = 6.0,
             amplitude: float = AMPLITUDE) -> Record:
    """Drive the steering-wheel sine at constant speed (§5.4): `settle` s straight, then the sine
    swept f0 → f1 over `duration` s; states sampled at `rate` Hz over the sine (diffrax, Tsit5 at
    the sampling step).

    **Returns:** `Record` (n = duration·rate samples).
    """
    n = int(round(duration * rate))
    dt = 1.0 / rate

    def steer_fn(t):
        return steering_sine(t, duration=duration, f0=f0, f1=f1, amplitude=amplitude,
                             start=settle)

    ts = settle + dt * jnp.arange(n)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(dynamics), diffrax.Tsit5(), t0=0.0, t1=float(settle + dt * (n - 1)),
        dt0=dt, y0=initial_state(vehicle, speed), args=(vehicle, steer_fn, speed),
        saveat=diffrax.SaveAt(ts=ts), max_steps=int((settle + duration) * rate) + 10)
    beta, beta_rate = jax.vmap(steer_fn)(ts)
    return Record(ts, sol.ys, beta, beta_rate)


# --------------------------------------------------------------------------------------------
# Sensors


class Sensors(eqx.Module):
    """Where the sensors sit on the body (body frame, m) and their noise (1σ).

    Lasers at the four corners (`lasers` (4, 3)) measure the distance to the road along −z_c;
    the optical speed sensor (Correvit) at `correvit` measures the velocity of its ground
    projection in body x, y, `delay` s late; the inertial unit at `imu` gives the angular
    velocity, the velocity and the specific force of its point in the body frame. Per wheel:
    travel, steer, spin rate and the wheel-carrier wrench (dynamometric wheel)."""

    lasers: Float[Array, "4 3"] = eqx.field(default_factory=lambda: jnp.asarray(
        [[1.9, 0.7, -0.25], [1.9, -0.7, -0.25], [-2.1, 0.7, -0.25], [-2.1, -0.7, -0.25]]))
    correvit: Float[Array, "3"] = eqx.field(
        default_factory=lambda: jnp.asarray([-2.2, 0.0, -0.2]))
    imu: Float[Array, "3"] = eqx.field(default_factory=lambda: jnp.asarray([0.2, 0.0, 0.1]))
    sigma_laser: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(2e-4))
    sigma_correvit: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(0.02))
    sigma_gyro: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(2e-3))
    sigma_imu_velocity: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(0.3))
    sigma_accelerometer: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(0.05))
    sigma_travel: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(2e-4))
    sigma_steer: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(2e-4))
    sigma_spin: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(0.05))
    sigma_force: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(20.0))
    sigma_moment: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(2.0))


def _truth_channels(vehicle: Vehicle, sensors: Sensors, y, t, beta, beta_rate, speed, yd):
    """Noise-free sensor values at one sample; `yd` the state's time derivative (the inertial
    unit's accelerations)."""
    p, ang, v, w, z, zd, fy = _unpack(y)
    R = rotation(*ang)
    steer = jnp.stack([beta, beta, 0.0 * beta, 0.0 * beta])
    steer_rate = jnp.stack([beta_rate, beta_rate, 0.0 * beta, 0.0 * beta])
    kin = tyre_kinematics(vehicle, p, ang, v, w, z, zd, steer, steer_rate, fy, yd[20:24])
    fx, fz, _, omega = tyre_forces(vehicle, kin, fy, v[0] - speed)
    zg = R[:, 2]
    heights = p[2] + sensors.lasers @ R[2]
    lasers = heights / zg[2]
    # Correvit: the body point at the ground projection of C5 along −z_c
    d5 = (p[2] + sensors.correvit @ R[2]) / zg[2]
    B5 = sensors.correvit - d5 * jnp.array([0.0, 0.0, 1.0])
    correvit = (v + jnp.cross(w, B5))[:2]
    vd, wd = yd[6:9], yd[9:12]
    g = R.T @ jnp.array([0.0, 0.0, -GRAVITY])
    a_imu = vd + jnp.cross(w, v) + jnp.cross(wd, sensors.imu) + jnp.cross(
        w, jnp.cross(w, sensors.imu))
    imu = {"omega": w, "velocity": v + jnp.cross(w, sensors.imu), "specific_force": a_imu - g}
    # wheel-carrier wrench (massless wheel): tyre wrench carried to O, in R_pf
    Rc, _ = corner_poses(vehicle, z, steer, fy)
    f_world = (fx[:, None] * kin["x_p"] + fy[:, None] * kin["y_p"]
               + fz[:, None] * jnp.array([0.0, 0.0, 1.0]))
    Rpf = jnp.einsum("ij,kjl->kil", R, Rc)  # road ← carrier
    force = jnp.einsum("kji,kj->ki", Rpf, f_world)
    moment = jnp.einsum("kji,kj->ki", Rpf, jnp.cross(kin["P"] - kin["O"], f_world))
    return {"lasers": lasers, "correvit": correvit, "imu_omega": imu["omega"],
            "imu_velocity": imu["velocity"], "imu_specific_force": imu["specific_force"],
            "travel": z, "steer": steer, "spin": omega,
            "wrench": jnp.concatenate([force, moment], axis=1),
            "true_fz": fz, "true_fy": fy, "true_gamma": kin["gamma"]}


@eqx.filter_jit
def channels(vehicle: Vehicle, sensors: Sensors, record: Record, *, speed: float = 25.0) -> dict:
    """The noise-free sensor values of a run (see `measure` for the keys and units)."""
    # accelerations by central differences of the sampled state (O(dt²): 2e-4 relative at
    # 6 Hz and 1 kHz, below the accelerometer's noise) rather than a second copy of the model
    yd = jnp.gradient(record.state, record.time, axis=0)
    ch = jax.vmap(lambda y, t, b, br, d: _truth_channels(vehicle, sensors, y, t, b, br, speed,
                                                         d))(
        record.state, record.time, record.steer, record.steer_rate, yd)
    ch.update(time=record.time, laser_positions=sensors.lasers,
              correvit_position=sensors.correvit, imu_position=sensors.imu,
              corners=vehicle.corners, rolling_radius=vehicle.rolling_radius)
    return ch


def load_channels(path, vehicle: Vehicle, sensors: Sensors) -> dict:
    """The noise-free channels of a recorded run saved as an .npz (per-sample channels as
    `channels` gives them, with `t0` and `rate` for the time axis), completed with the sensor
    positions and the vehicle's corners as `channels` adds them: what `add_noise` takes."""
    with np.load(path) as z:
        ch = {k: jnp.asarray(z[k], float) for k in z.files if k not in ("t0", "rate")}
        n = z["lasers"].shape[0]
        ch["time"] = jnp.asarray(float(z["t0"]) + np.arange(n) / float(z["rate"]))
    ch.update(laser_positions=sensors.lasers, correvit_position=sensors.correvit,
              imu_position=sensors.imu, corners=vehicle.corners,
              rolling_radius=vehicle.rolling_radius)
    return ch


NOISY = ("correvit", "imu_omega", "imu_specific_force", "imu_velocity", "lasers", "spin",
         "steer", "travel")


def add_noise(truth: dict, sensors: Sensors, key, *, delay=0.0) -> dict:
    """A noisy, delayed copy of `channels`' output: Gaussian white noise of `sensors`' σ on
    every measured channel, the Correvit late by `delay` s (the value of t − delay, the first
    samples repeated). Pure JAX: `jax.vmap` it over keys for a Monte-Carlo."""
    n = truth["time"].shape[0]
    dt = truth["time"][1] - truth["time"][0]
    shift = jnp.round(delay / dt).astype(int)
    out = dict(truth)
    out["correvit"] = truth["correvit"][jnp.clip(jnp.arange(n) - shift, 0, n - 1)]
    sig = {"lasers": sensors.sigma_laser, "correvit": sensors.sigma_correvit,
           "imu_omega": sensors.sigma_gyro, "imu_velocity": sensors.sigma_imu_velocity,
           "imu_specific_force": sensors.sigma_accelerometer, "travel": sensors.sigma_travel,
           "steer": sensors.sigma_steer, "spin": sensors.sigma_spin}
    # one draw for every channel (one random-bits program to compile, not one per shape)
    sizes = [math.prod(out[name].shape) for name in NOISY + ("wrench",)]
    z = jax.random.normal(key, (sum(sizes),))
    parts = jnp.split(z, np.cumsum(sizes)[:-1])
    for part, name in zip(parts, NOISY, strict=False):
        out[name] = out[name] + sig[name] * part.reshape(out[name].shape)
    scale = jnp.concatenate([jnp.full(3, sensors.sigma_force), jnp.full(3, sensors.sigma_moment)])
    out["wrench"] = truth["wrench"] + scale * parts[-1].reshape(truth["wrench"].shape)
    return out


def measure(vehicle: Vehicle, sensors: Sensors, record: Record, key, *, delay: float = 0.0,
            speed: float = 25.0, noise: bool = True) -> dict:
    """The sensor record of a run: a dict of arrays (n, …) with `time`, `lasers` (n, 4) [m],
    `correvit` (n, 2) [m/s] (late by `delay` s), `imu_omega`, `imu_velocity`,
    `imu_specific_force` (n, 3), and per wheel (n, 4, …) `travel` [m], `steer` [rad], `spin`
    [rad/s], `wrench` (n, 4, 6) [N, N·m] (the wheel-carrier wrench of a massless wheel, R_pf);
    the sensor positions (`laser_positions`, `correvit_position`, `imu_position`), the
    vehicle's `corners` and `rolling_radius`; and the truth `true_fz`, `true_fy`, `true_gamma`
    (n, 4). Gaussian white noise of `sensors`' σ unless `noise=False`."""
    truth = channels(vehicle, sensors, record, speed=speed)
    if not noise:
        return add_noise(truth, eqx.tree_at(
            lambda s: [getattr(s, f) for f in _SIGMAS], sensors,
            [jnp.asarray(0.0)] * len(_SIGMAS)), key, delay=delay)
    return jax.jit(add_noise)(truth, sensors, key, delay=delay)


_SIGMAS = ("sigma_laser", "sigma_correvit", "sigma_gyro", "sigma_imu_velocity",
           "sigma_accelerometer", "sigma_travel", "sigma_steer", "sigma_spin", "sigma_force",
           "sigma_moment")


__all__ = ["MagicTyre", "NOISY", "Record", "Sensors", "TYRE_NAMES", "TyreTruth", "Vehicle",
           "WHEELS", "add_noise", "channels", "corner_poses", "dynamics", "initial_state",
           "load_channels", "measure", "rotation", "simulate", "steering_sine"]
