"""Synthetic Flat Trac campaign (spec tyre §4.3, §1.6): the PSA ↔ deformation conversions,
the steering-feel test sequences (`steering_feel_segments`, `Segments`), the active-safety
ones with camber varied within runs (`active_safety_segments`) and their simulation
through the state-space model from a known polynomial model and K_y (`synthetic_flat_trac`).
Every public name is importable from `diffsusp.tyre.bench`.
"""

import dataclasses
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
    independently of F_z, which separates the −F_y·F_x coupling of M_z, (3-69))."""

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
    kap = (1e-3 * seg.kappa_amp * jnp.tanh(3.0 * jnp.sin(w * t / seg.kappa_period))
           / math.tanh(3.0))
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
