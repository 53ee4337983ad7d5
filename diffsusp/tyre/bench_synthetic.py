"""Synthetic Flat Trac campaign (spec tyre §4.3, §1.6): the PSA ↔ deformation conversions,
the steering-feel test sequences (`steering_feel_segments`, `Segments`), the active-safety
ones with camber varied within runs (`active_safety_segments`) and their simulation
through the state-space model from a known polynomial model and K_y (`synthetic_flat_trac`).
Every public name is importable from `diffsusp.tyre.bench`.
"""

import dataclasses
import functools
import math
from collections.abc import Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..errors import ModelError
from . import relaxation
from .bench_condition import quick_jit
from .poly import PolynomialModel

# --------------------------------------------------------------------------------------------
# Conversions (spec §1.6 (2-96…2-104))


def deformation_from_psa(kappa=0.0, delta=0.0, phi=0.0, phibar=0.0, *, rolling_radius=0.294):
    """The deformations seen by the patch from the PSA inputs, zero longitudinal slip
    (2-101…2-104): κ′ = R_r·(1/(κ+1) − 1), δ′ = −R_r·tan δ, φ̄′ = −R_r·φ̄, φ′ = −R_r·φ.
    κ [-], δ [rad], φ, φ̄ [1/m]; R_r [m] → (κ′ [m], δ′ [m], φ′ [rad], φ̄′ [rad])."""
    r = rolling_radius
    return (r * (1.0 / (jnp.asarray(kappa) + 1.0) - 1.0), -r * jnp.tan(jnp.asarray(delta)),
            -r * jnp.asarray(phi), -r * jnp.asarray(phibar))


def psa_from_deformation(kappa_p=0.0, delta_p=0.0, phi_p=0.0, phibar_p=0.0, *,
                         rolling_radius=0.294):
    """Inverse of `deformation_from_psa`: (κ, δ [rad], φ, φ̄ [1/m])."""
    r = rolling_radius
    return (1.0 / (jnp.asarray(kappa_p) / r + 1.0) - 1.0, jnp.arctan(-jnp.asarray(delta_p) / r),
            -jnp.asarray(phi_p) / r, -jnp.asarray(phibar_p) / r)


# --------------------------------------------------------------------------------------------
# The test sequences of §4.3 A


class Segments(eqx.Module):
    """Stacked steady states with their excitation (one entry per segment), thesis-like units:
    `speed` [km/h], `fz0`, `fz_amp` [kN], `fz_freq` [Hz], `camber` [deg], `slip0`, `sine_amp`
    [deg], `sine_freq` [Hz], `step_amp` [deg], `step_period` [s], `ramp_amp` [deg],
    `ramp_period` [s], `sequence` (1–5, §4.3 A; 6–8, §4.3 B), and the camber excitation of
    the active-safety sequences (§4.3 B): `camber_amp` [deg] smoothed camber steps of period
    `camber_period` [s] around `camber`, `camber_slip` [deg/deg] a camber proportional to the
    slip (B.3: an axle's camber-with-steer law); and a driving/braking excitation that the
    thesis's procedures do not have: `kappa_amp` [mm] smoothed steps of the longitudinal
    deformation κ′ = V_x/ω − R_r (> 0 braking) of period `kappa_period` [s] (F_x then varies
    independently of F_z, which separates the −F_y·F_x coupling of M_z, (3-69)), and a
    sine of κ′ of amplitude `kappa_sine` [mm] at `kappa_freq` [Hz] (the transients of F_x
    that determine the longitudinal compliance, `compliant_flat_trac`)."""

    speed: jax.Array
    fz0: jax.Array
    fz_amp: jax.Array
    fz_freq: jax.Array
    camber: jax.Array
    slip0: jax.Array
    sine_amp: jax.Array
    sine_freq: jax.Array
    step_amp: jax.Array
    step_period: jax.Array
    ramp_amp: jax.Array
    ramp_period: jax.Array
    sequence: jax.Array
    camber_amp: jax.Array
    camber_period: jax.Array
    camber_slip: jax.Array
    kappa_amp: jax.Array
    kappa_period: jax.Array
    kappa_sine: jax.Array
    kappa_freq: jax.Array

    @property
    def n(self) -> int:
        return int(self.speed.shape[0])


def steering_feel_segments(speeds=(40.0, 80.0, 120.0, 160.0), *, sequences=(1, 2, 3, 4, 5),
                           medium_loads=(3.0, 4.5, 6.0)) -> Segments:
    """The steering-feel procedure of §4.3 A at `speeds` [km/h]:

    1. straight line: loads 3, 4.5, 6 kN × cambers −1.5, 0, 1.5°, slip 0;
    2. small slip steps ±1° (smoothed square wave, 2 s period): loads 1.5…6 kN × cambers;
    3. load sine ±0.5 kN around 3 and 4.5 kN at 3 and 6 Hz, camber 0, slip −1° and +1°;
    4. slip sines ±1° at 3, 4.5, 6 Hz: loads 3, 4.5, 6 kN × cambers;
    5. medium slip profile ±4° (smoothed triangle ramps, 4 s period, and steps): `medium_loads`
       × cambers (the thesis also runs 1.5 kN; a polynomial identified on 1.5–6 kN may be past
       its grip peak there at 4°, which the simulation model refuses: spec §3.4).
    """
    rows = []
    cambers = (-1.5, 0.0, 1.5)
    for v in speeds:
        if 1 in sequences:
            rows += [dict(speed=v, fz0=f, camber=c, sequence=1) for f in (3.0, 4.5, 6.0)
                     for c in cambers]
        if 2 in sequences:
            rows += [dict(speed=v, fz0=f, camber=c, step_amp=1.0, step_period=2.0, sequence=2)
                     for f in (1.5, 3.0, 4.5, 6.0) for c in cambers]
        if 3 in sequences:
            rows += [dict(speed=v, fz0=f, fz_amp=0.5, fz_freq=hz, slip0=s, sequence=3)
                     for f in (3.0, 4.5) for hz in (3.0, 6.0) for s in (-1.0, 1.0)]
        if 4 in sequences:
            rows += [dict(speed=v, fz0=f, camber=c, sine_amp=1.0, sine_freq=hz, sequence=4)
                     for f in (3.0, 4.5, 6.0) for c in cambers for hz in (3.0, 4.5, 6.0)]
        if 5 in sequences:
            rows += [dict(speed=v, fz0=f, camber=c, ramp_amp=3.0, ramp_period=4.0, step_amp=1.0,
                          step_period=1.0, sequence=5) for f in medium_loads for c in cambers]
    return make_segments(rows)


def active_safety_segments(loads=(3.0, 4.5, 6.0), *, speed: float = 80.0,
                           slip_amp: float = 1.0, camber_amp: float = 1.5,
                           camber_laws=(-0.3, 0.5), ramp_amp: float = 3.0) -> Segments:
    """The active-safety sequences of §4.3 B (seed 001 §3.2.3.2) at a constant `speed`
    [km/h] (80 km/h in the thesis), at steady `loads` [kN]: the camber varies within runs.

    6. small slip steps ±`slip_amp` [deg] at zero camber (B.1);
    7. camber steps ±`camber_amp` [deg] at zero slip (B.2);
    8. slip ramps ±`ramp_amp` [deg] with steps, the camber proportional to the slip along each
       law of `camber_laws` [deg/deg] (B.3: a standard axle and a twist-beam axle).

    The procedure is confidential: the thesis gives neither the amplitudes nor the laws (and
    runs the slip up to 12°, beyond the grip peak where the simulation model (3-82) is
    unstable); the defaults are chosen, in the steering-feel range. The thesis does not use
    these sequences for its identification (seed 001 §3.2.3.2: the tyre changes during them);
    they are what determines the camber powers γ² … γ⁵ that the steady cambers of §4.3 A
    cannot (`bench.identify_output` reports those as not identifiable)."""
    rows = []
    for f in loads:
        rows.append(dict(speed=speed, fz0=f, step_amp=slip_amp, step_period=1.0, sequence=6))
        rows.append(dict(speed=speed, fz0=f, camber_amp=camber_amp, camber_period=1.0,
                         sequence=7))
        rows += [dict(speed=speed, fz0=f, ramp_amp=ramp_amp, ramp_period=2.0, step_amp=1.0,
                      step_period=1.0, camber_slip=k, sequence=8) for k in camber_laws]
    return make_segments(rows)


def make_segments(rows) -> Segments:
    """Segments from a list of dicts (missing fields: 0, periods 1 s)."""
    fields = [f.name for f in dataclasses.fields(Segments)]
    default = {f: 0.0 for f in fields}
    default.update(step_period=1.0, ramp_period=1.0, camber_period=1.0, kappa_period=1.0)
    cols = {f: jnp.asarray([float(r.get(f, default[f])) for r in rows]) for f in fields}
    return Segments(**cols)


def segment_inputs(seg: Segments, t, rolling_radius: float = 0.294) -> dict:
    """The inputs of one segment at time t [s]: the PSA slip δ [rad], `fz` [kN], `gamma` [rad],
    `speed` [m/s], `omega` [rad/s] (ω = V·cos δ/(R_r + κ′): free rolling, κ′ = 0, unless
    `kappa_amp`), `delta` δ′ [m],
    `phi` φ′ = δ̇/ω [rad], `kappa` [m]."""
    w = 2.0 * math.pi

    def slip(s):
        tri = jnp.arcsin(0.98 * jnp.sin(w * s / seg.ramp_period)) / math.asin(0.98)
        return jnp.deg2rad(seg.slip0 + seg.sine_amp * jnp.sin(w * seg.sine_freq * s)
                           + seg.step_amp * jnp.tanh(3.0 * jnp.sin(w * s / seg.step_period))
                           / math.tanh(3.0) + seg.ramp_amp * tri)

    d, ddot = jax.jvp(slip, (jnp.asarray(t, dtype=float),), (jnp.ones_like(t, dtype=float),))
    v = seg.speed / 3.6
    kap = 1e-3 * (seg.kappa_amp * jnp.tanh(3.0 * jnp.sin(w * t / seg.kappa_period))
                  / math.tanh(3.0) + seg.kappa_sine * jnp.sin(w * seg.kappa_freq * t))
    omega = v * jnp.cos(d) / (rolling_radius + kap)
    gamma = (jnp.deg2rad(seg.camber + seg.camber_amp
                         * jnp.tanh(3.0 * jnp.sin(w * t / seg.camber_period)) / math.tanh(3.0))
             + seg.camber_slip * d)
    return {"slip": d, "fz": seg.fz0 + seg.fz_amp * jnp.sin(w * seg.fz_freq * t),
            "gamma": gamma, "speed": v, "omega": omega,
            "delta": -v * jnp.sin(d) / omega, "phi": ddot / omega,
            "kappa": v * jnp.cos(d) / omega - rolling_radius}


def _simulate_all_impl(fy_model, mz_model, fx_model, k_fy, k_mz, seg, t, rolling_radius):
    def one(s):
        sim = relaxation.simulate(
            fy_model, mz_model, lambda tt: segment_inputs(s, tt, rolling_radius), t,
            k_fy=k_fy, k_mz=k_mz, fx=lambda u: fx_model(u), throw=False)
        u = jax.vmap(lambda tt: segment_inputs(s, tt, rolling_radius))(t)
        return sim.fy, sim.mz, fx_model(u), u, sim.stable
    return jax.vmap(one)(seg)


_simulate_all = quick_jit(_simulate_all_impl)


def _bench_table(t, u, fx, fy, mz, rng, noise) -> dict:
    """The bench's channels (segments × samples, raveled) in its units (N, N·mm, mm/s), with
    white noise of the default σ (`noise` overrides per channel; 0 for none) drawn from
    `rng`."""
    n_seg, n_t = fy.shape
    sig = {"FY": 20.0, "MZ": 2000.0, "FX": 10.0, "FZ": 10.0}
    sig.update(noise or {})
    table = {
        "t": np.tile(np.asarray(t), n_seg),
        "segment": np.repeat(np.arange(n_seg, dtype=float), n_t),
        "steer": np.asarray(u["slip"]).ravel(),
        "camber": np.asarray(u["gamma"]).ravel(),
        "speed": 1e3 * np.asarray(u["speed"]).ravel(),
        "omega": np.asarray(u["omega"]).ravel(),
        "FZ": 1e3 * np.asarray(u["fz"]).ravel(),
        "FX": np.asarray(fx).ravel(),
        "FY": np.asarray(fy).ravel(),
        "MZ": 1e3 * np.asarray(mz).ravel(),
    }
    for c in ("FY", "MZ", "FX", "FZ"):
        table[c] = table[c] + sig[c] * rng.standard_normal(table[c].shape)
    return table


def synthetic_flat_trac(fy_model: PolynomialModel, mz_model: PolynomialModel, *, k_fy: float,
                        k_mz: float, segments: Segments, duration: float = 2.0,
                        rate: float = 200.0, fx_model: PolynomialModel | None = None,
                        noise: Mapping[str, float] | None = None, disturbances: bool = False,
                        seed: int = 0, rolling_radius: float = 0.294) -> dict[str, np.ndarray]:
    """A synthetic Flat Trac campaign: every segment simulated through the state-space model
    (3-82…3-87) for `duration` s sampled at `rate` Hz, as a bench table (library units, see
    `REQUIRED`).

    `noise` is the white measurement noise σ per channel in the table's units (default: FY
    20 N, MZ 2 000 N·mm, FX 10 N, FZ 10 N: the order of the thesis's F_y residuals);
    `disturbances=True` adds the bench's periodic disturbances of §4.2 with random phases:
    wheel non-uniformity at the wheel rotation frequency (30 N on F_y, 3 N·m on M_z), the belt
    roller at 9.29·V/22.225 Hz (20 N), the foundation mode 8.7 Hz (10 N) and the arm mode
    0.53 Hz (15 N). Raises `ModelError` if a segment goes beyond the grip peak of `fy_model`.
    """
    if fx_model is None:
        fx_model = PolynomialModel.create("Fx", {"one": 1})
    t = jnp.arange(int(round(duration * rate))) / rate
    fy, mz, fx, u, stable = _simulate_all(fy_model, mz_model, fx_model, float(k_fy),
                                          float(k_mz), segments, t, rolling_radius)
    if not bool(jnp.all(stable)):
        bad = int(np.flatnonzero(~np.asarray(stable))[0])
        raise ModelError(f"segment {bad} goes beyond the grip peak of the F_y polynomial "
                         "(∂Fy_pneu/∂δ′ ≥ 0): the simulation model is unstable there; reduce "
                         "its slip or load range.")
    n_seg, n_t = fy.shape
    rng = np.random.default_rng(seed)
    table = _bench_table(t, u, fx, fy, mz, rng, noise)
    if disturbances:
        tt = table["t"]
        theta = np.cumsum(table["omega"]) / rate  # wheel angle, per segment up to a constant
        v = table["speed"] / 1e3
        ph = rng.uniform(0, 2 * np.pi, (5, n_seg)).repeat(n_t, axis=1)
        table["FY"] += (30.0 * np.sin(theta + ph[0])
                        + 20.0 * np.sin(2 * np.pi * 9.29 * v / 22.225 * tt + ph[1])
                        + 10.0 * np.sin(2 * np.pi * 8.7 * tt + ph[2])
                        + 15.0 * np.sin(2 * np.pi * 0.53 * tt + ph[3]))
        table["MZ"] += 3000.0 * np.sin(theta + ph[4])
    return table


# --------------------------------------------------------------------------------------------
# The three contact compliances (spec §1.5 (2-37…2-45)): a simulation the identification is
# not written against


class ContactTyre(eqx.Module):
    """A Magic-Formula-shaped interaction law F_pneu(κ′, δ′, φ′, γ, F_z) of the contact patch,
    thesis units (F_z [kN], κ′, δ′ [m], φ′, γ [rad] → F_x, F_y [N], M_z [N·m]): not a
    polynomial, so that a polynomial identification of it is an approximation (the test of a
    method on data from a model it was not written against). Frame of the patch: x forward,
    y left, z up; κ′ > 0 braking; every slope has the stable sign (∂F_x/∂κ′ < 0,
    ∂F_y/∂δ′ < 0, ∂M_z/∂φ′ < 0: each force opposes the deformation rate that creates it).

    F_x = −D_x·sin(C_x·atan(B_x·κ′)) − f_r·F_z, D_x = μ_x·F_z,
    B_x·C_x·D_x = k_x·sin(2·atan(F_z/a_x));
    F_y = D_y·sin(C_y·atan(B_y·δ′)) + k_φ·F_z·a_φ·atan(φ′/a_φ) + k_γ·F_z·γ + s_y·F_z,
    B_y·C_y·D_y = −k_y·sin(2·atan(F_z/a_y)); M_z = D_z·sin(C_z·atan(B_z·δ′)) + m_φ·F_z·a_φ·
    atan(φ′/a_φ) + m_γ·F_z·γ + s_z·F_z, B_z·C_z·D_z = k_z·F_z²·exp(−F_z/a_z). Default values
    near the thesis's Dunlop R16 at 2 bar ((3-78), (3-80)) where it prints them."""

    mu_x: float = 1.1
    c_x: float = 1.6
    k_x: float = 3.6e5
    a_x: float = 8.0
    f_r: float = 12.0
    mu_y: float = 1.0
    c_y: float = 1.3
    k_y: float = 4.5e5
    a_y: float = 8.0
    k_phi: float = 5.0e3
    a_phi: float = 0.1
    k_gamma: float = -1100.0
    s_y: float = -35.0
    d_z: float = 11.0
    c_z: float = 2.3
    k_z: float = 900.0
    a_z: float = 12.0
    m_phi: float = -1000.0
    m_gamma: float = -133.0
    s_z: float = 3.8

    def __call__(self, kappa, delta, phi, gamma, fz):
        """(F_x, F_y, M_z) at the deformation inputs and the load [kN]."""
        def mf(D, C, BCD, x):
            return D * jnp.sin(C * jnp.arctan(BCD / (C * D) * x))

        fx = (-mf(self.mu_x * 1e3 * fz, self.c_x,
                  self.k_x * jnp.sin(2.0 * jnp.arctan(fz / self.a_x)), kappa)
              - self.f_r * fz)
        turn = self.a_phi * jnp.arctan(phi / self.a_phi)
        fy = (mf(self.mu_y * 1e3 * fz, self.c_y,
                 -self.k_y * jnp.sin(2.0 * jnp.arctan(fz / self.a_y)), delta)
              + self.k_phi * fz * turn + self.k_gamma * fz * gamma + self.s_y * fz)
        mz = (mf(self.d_z * fz, self.c_z, self.k_z * fz**2 * jnp.exp(-fz / self.a_z), delta)
              + self.m_phi * fz * turn + self.m_gamma * fz * gamma + self.s_z * fz)
        return jnp.stack([fx, fy, mz])


def _rot(b, v):
    c, s = jnp.cos(b), jnp.sin(b)
    return jnp.stack([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def _contact_rates(tyre, k, u, q, guess, rolling_radius, newton):
    """q̇ = (ẋ, ẏ, β̇) of the contact joints at state q and wheel inputs u, and the patch
    deformation u_AC solving F_pneu(u_AC) = the joint forces (massless patch)."""
    x, y, b = q
    # the joint forces (2-39): K_x·x, K_y·y along R_p, K_β·β the moment at the patch
    f_ac = jnp.concatenate([_rot(-b, jnp.stack([k[0] * x, k[1] * y])), (k[2] * b)[None]])
    g, fz = u["gamma"], u["fz"]

    def resid(v):
        return tyre(v[0], v[1], v[2], g, fz) - f_ac

    v = guess
    for _ in range(newton):
        v = v - jnp.linalg.solve(jax.jacfwd(resid)(v), resid(v))
    w, psi = u["omega"], u["phi"] * u["omega"]
    vx, vy = u["speed"] * jnp.cos(u["slip"]), -u["speed"] * jnp.sin(u["slip"])
    # the patch velocity: R(β)·V_AC = V_P + ψ̇ ẑ × (x, y) + (ẋ, ẏ)  (2-43…2-45, exact)
    vt = _rot(b, jnp.stack([(v[0] + rolling_radius) * w, v[1] * w]))
    qd = jnp.stack([vt[0] - vx + psi * y, vt[1] - vy - psi * x, v[2] * w - psi])
    return qd, v


def _contact_segment(tyre, k, seg, t, rolling_radius, substeps, newton):
    dt = (t[1] - t[0]) / substeps

    def inputs(tt):
        return segment_inputs(seg, tt, rolling_radius)

    u0 = inputs(t[0])
    v0 = jnp.stack([u0["kappa"], u0["delta"], u0["phi"]])

    def steady(q, _):  # q̇ = 0: the joints under the forces of the rigid-patch deformation
        x, y, b = q
        w, psi = u0["omega"], u0["phi"] * u0["omega"]
        vt = jnp.stack([u0["speed"] * jnp.cos(u0["slip"]) - psi * y,
                        -u0["speed"] * jnp.sin(u0["slip"]) + psi * x])
        va = _rot(-b, vt)
        f = tyre(va[0] / w - rolling_radius, va[1] / w, u0["phi"], u0["gamma"], u0["fz"])
        fp = _rot(b, f[:2])
        return jnp.stack([fp[0] / k[0], fp[1] / k[1], (f[2]) / k[2]]), None

    q0, _ = jax.lax.scan(steady, jnp.zeros(3), None, length=40)

    def rk4(carry, tt):
        q, v = carry
        f1, v = _contact_rates(tyre, k, inputs(tt), q, v, rolling_radius, newton)
        f2, v = _contact_rates(tyre, k, inputs(tt + dt / 2), q + dt / 2 * f1, v,
                               rolling_radius, newton)
        f3, v = _contact_rates(tyre, k, inputs(tt + dt / 2), q + dt / 2 * f2, v,
                               rolling_radius, newton)
        f4, v = _contact_rates(tyre, k, inputs(tt + dt), q + dt * f3, v, rolling_radius,
                               newton)
        return (q + dt / 6 * (f1 + 2 * f2 + 2 * f3 + f4), v), None

    def sample(carry, tt):
        q, _ = carry
        carry, _ = jax.lax.scan(rk4, carry, tt + dt * jnp.arange(substeps))
        return carry, q

    _, qs = jax.lax.scan(sample, (q0, v0), t)
    x, y, b = qs.T
    fx, fy = k[0] * x, k[1] * y
    # M_z at the wheel centre's trace: the joint's moment carried from the patch (x, y)
    mz = k[2] * b + x * fy - y * fx
    return fx, fy, mz, jax.vmap(inputs)(t)


@functools.partial(jax.jit, static_argnames=("substeps", "newton"))
def _contact_all(tyre, k, seg, t, rolling_radius, substeps, newton):
    return jax.vmap(lambda s: _contact_segment(tyre, k, s, t, rolling_radius, substeps,
                                               newton))(seg)


def compliance_segments(speeds=(40.0, 80.0), loads=(3.0, 4.5, 6.0)) -> Segments:
    """A Flat Trac programme that excites the three contact compliances, at `speeds` [km/h]
    and `loads` [kN]: slip sines ±1° at 3 and 6 Hz at cambers ±1.5° (F_y, M_z and their
    transients: K_y, and the torsion through M_z), κ′ sines ±3 mm (a slip ratio of ±1 %) at
    4 Hz around slips ±0.5° (F_x transients: K_x; F_x·F_y products: the couplings), and a
    load sine ±0.5 kN at 3 Hz with κ′ steps ±2 mm at slip 1°. The thesis's steering-feel
    procedure is free rolling (κ′ never excited: K_x not identifiable, Table 7); this
    programme is the one a bench user would add for K_x (spec §4.3 is silent on it)."""
    rows = []
    for v in speeds:
        for f in loads:
            rows += [dict(speed=v, fz0=f, camber=c, sine_amp=1.0, sine_freq=hz, sequence=4)
                     for c, hz in ((-1.5, 3.0), (1.5, 6.0))]
            rows += [dict(speed=v, fz0=f, slip0=s, kappa_sine=3.0, kappa_freq=4.0, sequence=9)
                     for s in (-0.5, 0.5)]
            rows.append(dict(speed=v, fz0=f, fz_amp=0.5, fz_freq=3.0, slip0=1.0, kappa_amp=2.0,
                             kappa_period=1.0, sequence=3))
    return make_segments(rows)


def compliant_flat_trac(tyre: ContactTyre | None = None, *, k_x: float = 3.0e5,
                        k_y: float = 1.6e5, k_beta: float = 1.3e4,
                        segments: Segments | None = None, duration: float = 2.0,
                        rate: float = 200.0, substeps: int = 10,
                        noise: Mapping[str, float] | None = None, seed: int = 0,
                        rolling_radius: float = 0.294) -> dict[str, np.ndarray]:
    """A synthetic Flat Trac campaign from the contact model with its three compliances
    (spec §1.5 (2-37…2-45)): the patch on the lateral (K_y [N/m]), longitudinal (K_x [N/m])
    and torsion (K_β [N·m/rad]) joints, massless (the modes of Table 3 are far above the
    band), under the interaction law `tyre` (`ContactTyre`, not a polynomial) of the patch's
    own deformation inputs. Exact in the joint positions (finite rotation β, the patch at
    (x, y)): at each instant the patch deformation u_AC solves F_pneu(u_AC) = the joint
    forces (Newton), the joint rates follow from the patch twist (2-43), and the joints are
    integrated by RK4 (`substeps` per sample); the measured wrench is that of the joints,
    F_x = K_x·x, F_y = K_y·y, M_z = K_β·β + x·F_y − y·F_x. The identification
    (`bench.identify_compliances`) linearises all of this; this simulation does not.

    `segments` (default `compliance_segments()`), each `duration` s at `rate` Hz; `noise`:
    white σ per channel in table units (default FY 20 N, MZ 2 000 N·mm, FX 10 N, FZ 10 N, as
    `synthetic_flat_trac`). Returns a bench table (`REQUIRED` columns, library units)."""
    tyre = ContactTyre() if tyre is None else tyre
    segments = compliance_segments() if segments is None else segments
    t = jnp.arange(int(round(duration * rate))) / rate
    k = jnp.asarray([k_x, k_y, k_beta], dtype=float)
    fx, fy, mz, u = _contact_all(tyre, k, segments, t, rolling_radius, int(substeps), 4)
    if not bool(jnp.all(jnp.isfinite(fy)) & jnp.all(jnp.isfinite(mz))):
        raise ModelError("the contact simulation diverged: a segment is past the grip peak "
                         "or the step is too long for the torsion mode (raise `substeps`).")
    return _bench_table(t, u, fx, fy, mz, np.random.default_rng(seed), noise)
