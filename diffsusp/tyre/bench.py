"""Flat Trac bench identification of the polynomial tyre model (thesis chapter 3).

spec: tyre §3.3–3.5, §4.1–4.3, §7 D items 16–19, §7 F item 23, §8 items 4 and 8; CORRECTIONS 3.

**Bench table** (library units, one row per sample): `t` [s], `segment` (a run: one steady
state with its excitation; time restarts and filters run per segment), `steer` β_FT = δ [rad,
PSA], `camber` γ [rad], `speed` V_T [mm/s] (belt), `omega` ω [rad/s] (wheel spin), `FZ`, `FX`,
`FY` [N], `MZ` [N·mm]. `REQUIRED` lists them.

**Conditioning** (`condition`, spec §3.4, §7 D item 17): every channel low-pass filtered at
25 Hz with zero phase (Butterworth, 2nd order, run forward and backward, odd padding: SciPy's
`filtfilt` convention), Ḟ_y by centred differences, the deformation inputs from the bench
kinematics (small-angle Flat Trac, (3-3…3-8): V_x = V·cos β, V_y = −V·sin β, β̇ = δ̇):
κ′ = V_x/ω − R_r, δ′ = V_y/ω, φ′ = β̇/ω (2-92…2-95), and the rows thinned to about 2·f_c
(`decimate`) so that the residual of the regression is close to white and σ is honest.
Converted to the polynomial's units (kN, m, N, N·m) at this edge.

**Identification** (`identify`): the two-step procedure (3-40…3-46) on F_y and on M_z:
step 1 the LIP model [W_pneu | W_Ly (| W_P2)] by the guaranteed least squares, with the
structure search (`lsq.eliminate`: IC < 0.1 or σ % > 100, and the behaviour rules of §7 item 19
as `check=` rules, `structure_rules`); step 2 K_y⁻¹ from F − F̂_pneu = ((∂F̂_pneu/∂δ′)·Ḟ_y/ω
(− F_y·F_x)) K_y⁻¹ (3-76, 3-77) with F̂_pneu fixed. The σ of K_y⁻¹ printed by the thesis is
that of this one-parameter regression; it ignores step 1's uncertainty, so the report gives
the σ of the linearised joint model F = W_pneu·b + c·D(b) at the two-step estimate instead
(its Cramér–Rao bound; chosen because the step-2 σ alone understates the spread several times
over on synthetic data — see tests/test_tyre_bench.py).

**Synthetic Flat Trac** (`steering_feel_segments`, `synthetic_flat_trac`): the steering-feel
sequences of §4.3 A (straight line, small slip steps ±1°, load sine ±500 N at 3 and 6 Hz, slip
sines ±1° at 3, 4.5, 6 Hz, medium slip profiles ±4°) at 40–160 km/h, simulated through the
state-space model (3-82…3-87, `relaxation.simulate`) from a known polynomial model and K_y,
plus the bench's noise.
"""

import dataclasses
import math
from collections.abc import Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import lsq
from ..errors import InputError
from . import relaxation
from .poly import STRUCTURES, PolynomialModel, parse_name, regressor_model, table6_domains

__all__ = ["REQUIRED", "Segments", "steering_feel_segments", "segment_inputs",
           "synthetic_flat_trac", "butterworth", "filtfilt", "condition", "Conditioned",
           "deformation_from_psa", "psa_from_deformation", "structure_rules", "identify",
           "BenchReport", "OutputReport"]

REQUIRED = ("t", "segment", "steer", "camber", "speed", "omega", "FZ", "FX", "FY", "MZ")
UNITS = {"t": "s", "segment": None, "steer": "rad", "camber": "rad", "speed": "mm/s",
         "omega": "rad/s", "FZ": "N", "FX": "N", "FY": "N", "MZ": "N·mm"}

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
    `ramp_period` [s], `sequence` (1–5, §4.3 A)."""

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


def make_segments(rows) -> Segments:
    """Segments from a list of dicts (missing fields: 0, periods 1 s)."""
    fields = [f.name for f in dataclasses.fields(Segments)]
    default = {f: 0.0 for f in fields}
    default.update(step_period=1.0, ramp_period=1.0)
    cols = {f: jnp.asarray([float(r.get(f, default[f])) for r in rows]) for f in fields}
    return Segments(**cols)


def segment_inputs(seg: Segments, t, rolling_radius: float = 0.294) -> dict:
    """The inputs of one segment at time t [s]: the PSA slip δ [rad], `fz` [kN], `gamma` [rad],
    `speed` [m/s], `omega` [rad/s] (free rolling, ω = V·cos δ/R_r: κ′ = 0), `delta` δ′ [m],
    `phi` φ′ = δ̇/ω [rad], `kappa` [m]."""
    deg = math.pi / 180.0
    w = 2.0 * math.pi

    def slip(s):
        tri = jnp.arcsin(0.98 * jnp.sin(w * s / seg.ramp_period)) / math.asin(0.98)
        return deg * (seg.slip0 + seg.sine_amp * jnp.sin(w * seg.sine_freq * s)
                      + seg.step_amp * jnp.tanh(3.0 * jnp.sin(w * s / seg.step_period))
                      / math.tanh(3.0) + seg.ramp_amp * tri)

    d, ddot = jax.jvp(slip, (jnp.asarray(t, dtype=float),), (jnp.ones_like(t, dtype=float),))
    v = seg.speed / 3.6
    omega = v * jnp.cos(d) / rolling_radius
    return {"slip": d, "fz": seg.fz0 + seg.fz_amp * jnp.sin(w * seg.fz_freq * t),
            "gamma": seg.camber * deg, "speed": v, "omega": omega,
            "delta": -v * jnp.sin(d) / omega, "phi": ddot / omega,
            "kappa": v * jnp.cos(d) / omega - rolling_radius}


@eqx.filter_jit
def _simulate_all(fy_model, mz_model, fx_model, k_fy, k_mz, seg, t, rolling_radius):
    def one(s):
        sim = relaxation.simulate(
            fy_model, mz_model, lambda tt: segment_inputs(s, tt, rolling_radius), t,
            k_fy=k_fy, k_mz=k_mz, fx=lambda u: fx_model(u), throw=False)
        u = jax.vmap(lambda tt: segment_inputs(s, tt, rolling_radius))(t)
        return sim.fy, sim.mz, fx_model(u), u, sim.stable
    return jax.vmap(one)(seg)


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
    from ..errors import ModelError

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


# --------------------------------------------------------------------------------------------
# Signal conditioning


def butterworth(cutoff: float, rate: float, order: int = 4) -> np.ndarray:
    """Butterworth low-pass of even `order` as second-order sections (n, 6) = [b0 b1 b2 1 a1 a2]
    per row, bilinear transform with pre-warping, unit DC gain per section (the response of
    `scipy.signal.butter(order, cutoff/(rate/2), output="sos")`, which puts the gain in the
    first section instead). Order 4, run forward and backward (`filtfilt`), attenuates a 6 Hz
    signal by 1e-5 at 25 Hz, and 10 Hz by 7e-4 (order 2: 3e-3 and 2.5e-2)."""
    if order < 2 or order % 2:
        raise InputError(f"filter order {order}: an even number ≥ 2")
    if not 0 < cutoff < rate / 2:
        raise InputError(f"cut-off {cutoff:g} Hz must lie in (0, {rate / 2:g}) Hz (Nyquist)")
    k = math.tan(math.pi * cutoff / rate)
    rows = []
    for m in range(order // 2):
        q = 1.0 / (2.0 * math.cos(math.pi * (2 * m + 1) / (2 * order)))
        norm = 1.0 / (1.0 + k / q + k * k)
        b0 = k * k * norm
        rows.append([b0, 2.0 * b0, b0, 1.0, 2.0 * (k * k - 1.0) * norm,
                     (1.0 - k / q + k * k) * norm])
    return np.array(rows)


def _section_zi(sec):
    """lfilter_zi of one section: (I − companion(a)ᵀ)·zi = b[1:] − a[1:]·b[0]."""
    A = jnp.array([[1.0 + sec[4], -1.0], [sec[5], 1.0]])
    return jnp.linalg.solve(A, jnp.stack([sec[1] - sec[4] * sec[0], sec[2] - sec[5] * sec[0]]))


def filtfilt(sos, x):
    """Zero-phase filtering of x along its last axis, as `scipy.signal.sosfiltfilt(sos, x)`
    with its defaults (odd extension of 3·(2·n_sections + 1) samples, steady-state initial
    conditions in every section). Traceable (`lax.scan`), vmappable."""
    sos = jnp.asarray(sos, dtype=float)
    x = jnp.asarray(x, dtype=float)
    n_sec = sos.shape[0]
    pad = 3 * (2 * n_sec + 1)
    if x.shape[-1] <= pad:
        raise InputError(f"a segment of {x.shape[-1]} samples is too short for the zero-phase "
                         f"filter (more than {pad} needed)")
    # Steady state of section s for a constant input: its input is x0 times the DC gain of
    # the sections before it.
    gains = jnp.sum(sos[:, :3], axis=1) / jnp.sum(sos[:, 3:], axis=1)
    scale = jnp.concatenate([jnp.ones(1), jnp.cumprod(gains)[:-1]])
    zis = [_section_zi(sos[s]) * scale[s] for s in range(n_sec)]

    def run(v):
        for s in range(n_sec):
            v = _sos_one(sos[s], v, zis[s])
        return v

    def one(v):
        ext = jnp.concatenate([2 * v[0] - v[pad:0:-1], v, 2 * v[-1] - v[-2:-pad - 2:-1]])
        y = run(ext)
        y = run(y[::-1])[::-1]
        return y[pad:-pad]

    flat = x.reshape(-1, x.shape[-1])
    return jax.vmap(one)(flat).reshape(x.shape)


def _sos_one(sec, v, zi):
    """One section with initial state zi·v[0] (sosfilt's convention: zi scaled by x[0])."""
    b0, b1, b2, _, a1, a2 = (sec[i] for i in range(6))

    def step(z, xi):
        y = b0 * xi + z[0]
        return jnp.stack([b1 * xi - a1 * y + z[1], b2 * xi - a2 * y]), y
    return jax.lax.scan(step, zi * v[0], v)[1]


@dataclasses.dataclass(frozen=True)
class Conditioned:
    """Conditioned bench data (polynomial units: fz [kN], delta, kappa [m], phi, gamma [rad],
    pi_* products, fydot_w [N], fy, fx [N]).

    **Parallel filtering:** the regression is run on the *filtered* output and the *filtered
    columns* of the regressor built from the unfiltered inputs, H(y) = H(W(u))·b, which holds
    exactly for any linear filter H; filtering the inputs instead, W(H(u)), misses the
    harmonics that the nonlinear terms create (at 25 Hz the δ′³ term of a 6 Hz slip sine is
    off by several newtons). Only Ḟ_y is taken from the filtered F_y (the raw one is noise).

    **Fields:** `samples` (input → (segments, samples) unfiltered, full rate), `sos` (the
    filter's second-order sections), `rows` (the kept sample indices after trimming the ends
    and thinning), `inputs`
    (the same inputs at the kept rows, for checks and plots), `fy` [N], `mz` [N·m] (filtered,
    kept rows), `rate` [Hz] after thinning, `segment` per kept row, `excitation` (input →
    standard deviation)."""

    samples: dict
    sos: np.ndarray
    rows: np.ndarray
    inputs: dict
    fy: np.ndarray
    mz: np.ndarray
    rate: float
    segment: np.ndarray
    excitation: dict

    def regressor(self, model) -> np.ndarray:
        """H(W(u)) at the kept rows, (n, p), for a `lsq.algebra.LinearModel`."""
        return np.asarray(_filtered_regressor(model, self.samples, self.sos, self.rows))


@eqx.filter_jit
def _filtered_regressor(model, samples, sos, rows):
    W = model.regressor(samples)  # (segments, samples, p)
    Wf = filtfilt(sos, jnp.moveaxis(W, -1, -2))  # along time
    return jnp.moveaxis(Wf[..., rows], -1, -2).reshape(-1, W.shape[-1])


def _centred_derivative(v, dt):
    """dv/dt by the five-point centred difference (−v₊₂ + 8v₊₁ − 8v₋₁ + v₋₂)/12h, error
    O(h⁴) (the three-point one, O(h²), is 0.6 % off at 6 Hz sampled at 200 Hz, which biases
    the relaxation terms by several σ); three-point at the second and penultimate samples and
    one-sided at the ends (trimmed away by `condition`)."""
    inner = (-v[..., 4:] + 8 * v[..., 3:-1] - 8 * v[..., 1:-3] + v[..., :-4]) / (12 * dt)
    two = (v[..., 2:] - v[..., :-2]) / (2 * dt)
    first = (v[..., 1:2] - v[..., 0:1]) / dt
    last = (v[..., -1:] - v[..., -2:-1]) / dt
    return jnp.concatenate([first, two[..., :1], inner, two[..., -1:], last], axis=-1)


@jax.jit
def _condition_block(cols, sos, dt, rolling_radius):
    """(segments, samples) arrays → deformation inputs (unfiltered kinematics), Ḟ_y/ω from
    the filtered F_y, filtered F_y and M_z."""
    speed = cols["speed"] * 1e-3
    steer = cols["steer"]
    omega = cols["omega"]
    vx, vy = speed * jnp.cos(steer), -speed * jnp.sin(steer)
    bdot = _centred_derivative(steer, dt)
    g = cols["camber"]
    fy_f = filtfilt(sos, cols["FY"])
    return {
        "fz": cols["FZ"] * 1e-3, "kappa": vx / omega - rolling_radius, "delta": vy / omega,
        "phi": bdot / omega, "gamma": g, "pi_gamma_vx": g * vx / omega,
        "pi_gamma_bdot": g * bdot / omega, "pi_gamma2_bdot": g * g * bdot / omega,
        "fydot_w": _centred_derivative(fy_f, dt) / omega, "fy": cols["FY"], "fx": cols["FX"],
    }, fy_f, filtfilt(sos, cols["MZ"]) * 1e-3


def _check_table(table, cutoff):
    missing = [c for c in REQUIRED if c not in table]
    if missing:
        raise InputError(f"bench table: missing channel(s) {', '.join(missing)}; a Flat Trac "
                         f"table needs {', '.join(REQUIRED)} (units {UNITS}). Add them, or map "
                         "your column names to these.")
    cols = {c: np.asarray(table[c], dtype=float) for c in REQUIRED}
    n = {len(v) for v in cols.values()}
    if len(n) != 1:
        raise InputError("bench table: channels of different lengths")
    for c, v in cols.items():
        if not np.all(np.isfinite(v)):
            i = int(np.flatnonzero(~np.isfinite(v))[0])
            raise InputError(f"bench table: channel {c} has a non-finite value at row {i + 1}; "
                             "remove or repair that row.")
    seg = cols["segment"]
    ids, starts, counts = np.unique(seg, return_index=True, return_counts=True)
    order = np.argsort(starts)
    ids, starts, counts = ids[order], starts[order], counts[order]
    if np.any(np.diff(starts) != counts[:-1]):
        raise InputError("bench table: the rows of a segment must be contiguous (sort by "
                         "segment, then time).")
    if len(set(counts.tolist())) != 1:
        raise InputError(f"bench table: segments of different lengths {sorted(set(counts))}; "
                         "cut them to a common length (the conditioning is batched).")
    m = int(counts[0])
    t = cols["t"].reshape(len(ids), m)
    dt = np.diff(t, axis=1)
    if np.any(dt <= 0):
        s, i = np.argwhere(dt <= 0)[0]
        raise InputError(f"bench table: time is not increasing in segment {ids[s]:g} at row "
                         f"{starts[s] + i + 2} (t = {t[s, i + 1]:g} s after {t[s, i]:g} s); "
                         "sort the rows by time or remove duplicates.")
    step = float(np.median(dt))
    if np.max(np.abs(dt - step)) > 1e-6 * max(step, 1e-12) + 1e-9:
        raise InputError("bench table: the sampling is not uniform; resample to a constant "
                         "rate first (the filter and the centred differences assume one).")
    rate = 1.0 / step
    if rate < 4.0 * cutoff:
        raise InputError(f"bench table: the sampling rate {rate:.4g} Hz is too low for the "
                         f"{cutoff:g} Hz low-pass filter (at least {4 * cutoff:g} Hz, 4× the "
                         "cut-off); record faster or lower the cut-off.")
    if m < 30:
        raise InputError(f"bench table: segments of {m} samples are too short to filter "
                         "(at least 30).")
    if np.any(cols["omega"] <= 0):
        raise InputError("bench table: omega must be > 0 (the wheel rolls); the deformation "
                         "inputs divide by it.")
    return cols, len(ids), m, rate


def condition(table: Mapping, *, cutoff: float = 25.0, rolling_radius: float = 294.0,
              decimate: int | None = None, trim: int | None = None, order: int = 4
              ) -> Conditioned:
    """Check and condition a bench table (see the module docstring and `Conditioned`).

    **Arguments:** `table` (column → array, library units, `REQUIRED`); `cutoff` [Hz] (25 Hz:
    above the wheel rotation at 160 km/h, spec §3.4); `rolling_radius` R_r [mm];
    `order` of the Butterworth filter (run forward and backward); `decimate`: keep every m-th
    row (default m = ⌊rate/(2·cutoff)⌋); `trim`: samples dropped at
    each end of a segment (the filter's edge transient; default 2·rate/cutoff, at least 5).
    """
    cols, n_seg, m, rate = _check_table(table, cutoff)
    sos = butterworth(cutoff, rate, order)
    block = {c: jnp.asarray(cols[c].reshape(n_seg, m)) for c in REQUIRED
             if c not in ("t", "segment")}
    samples, fy_f, mz_f = _condition_block(block, sos, 1.0 / rate, rolling_radius * 1e-3)
    k = decimate if decimate is not None else max(1, int(rate // (2 * cutoff)))
    trim = trim if trim is not None else max(5, int(2 * rate / cutoff))
    rows = np.arange(trim, m - trim, k)
    if len(rows) < 2:
        raise InputError(f"bench table: segments of {m} samples leave nothing after trimming "
                         f"{trim} samples at each end; record longer segments.")
    inputs = {c: np.asarray(v)[:, rows].ravel() for c, v in samples.items()}
    segment = np.repeat(np.unique(cols["segment"]), len(rows))
    exc = {c: float(np.std(inputs[c])) for c in ("kappa", "delta", "phi", "gamma", "fz",
                                                   "pi_gamma_vx", "pi_gamma_bdot",
                                                   "pi_gamma2_bdot")}
    return Conditioned(samples, sos, rows, inputs, np.asarray(fy_f)[:, rows].ravel(),
                       np.asarray(mz_f)[:, rows].ravel(), rate / k, segment, exc)


# --------------------------------------------------------------------------------------------
# Structure search rules (spec §3.3 validation criteria, §7 item 19)


def structure_rules(output: str, fz_range: tuple[float, float], *, rolling_radius: float = 0.294,
                    loads: tuple[float, ...] | None = None, well_excited_load: bool = True,
                    ic_threshold: float = 0.1, sigma_pct_threshold: float | None = 100.0):
    """A `check=` rule for `lsq.eliminate` (spec §3.3, §7 item 19): returns the name of the
    coefficient to drop, or None when the identified polynomial behaves.

    1. **load polynomials keep their sign**: c_{F,X,i}(F_z) of every kept (X, i) must not vanish
       on [F_zmin, F_zmax] (a sign change is a structural discontinuity): drop the top monomial
       in X of that P_{F,X} (`well_excited_load`) or the top power of F_z;
    2. **concave stiffness**: the cornering stiffness c_{F,δ′,1}(F_z) (F_y) must be concave on
       the range (d²/dF_z² ≤ 0), else drop its top load monomial;
    3. **extremum counts** in the Table 6 domains, mapped from δ with δ′ = −R_r·tan δ
       (CORRECTIONS 3): at each load, at most one maximum and one minimum of P_{F,δ′} in
       the useful domain [−12°, 12°] (F_y) or [−6°, 6°] (M_z); else drop its top δ′ monomial.

    The rules judge a statistically clean model, as the thesis does (simplify after the
    significance tests): while a kept coefficient still fails IC ≥ `ic_threshold` or
    σ % ≤ `sigma_pct_threshold`, the rule returns None and lets the elimination remove it.
    """
    lo, hi = fz_range
    loads = loads or tuple(np.linspace(lo, hi, 4))
    dom = table6_domains(rolling_radius)[output]
    x_lo = min(v[0] for v in dom.values())
    x_hi = max(v[1] for v in dom.values())

    def rule(fit: lsq.Fit) -> str | None:
        free = fit.kept & ~fit.fixed
        ic = np.where(np.isnan(fit.confidence), np.inf, fit.confidence)
        pending = free & (ic < ic_threshold)
        if sigma_pct_threshold is not None:
            rel = 100 * np.abs(fit.combination_sigma / fit.combination_values)
            pending |= free & (np.nan_to_num(rel) > sigma_pct_threshold)
        if np.any(pending):
            return None
        active = {n: x for n, x, k, f in zip(fit.names, fit.x, fit.kept, fit.fixed, strict=True)
                  if k and not f and x != 0}
        pneu = {n: x for n, x in active.items() if parse_name(n)[1] not in ("Ly", "P2")}
        by_block: dict[tuple[str, int], dict[int, float]] = {}
        for n, x in pneu.items():
            _, block, i, j = parse_name(n)
            by_block.setdefault((block, i), {})[j] = x
        # 1. load polynomials keep their sign on [lo, hi] (and vanish only at F_z = 0)
        fz = np.linspace(lo, hi, 41)
        for (block, _i), cj in sorted(by_block.items()):
            c = sum(v * fz**j for j, v in cj.items())
            if np.min(c) < 0 < np.max(c):
                top = [(ii, j) for (b, ii), cc in by_block.items() if b == block
                       for j in cc]
                if well_excited_load:
                    ii, j = max(top)
                else:
                    j, ii = max((j, ii) for ii, j in top)
                return f"b_{output}_{block}_{ii}_{j}"
        # 2. concave cornering stiffness (F_y)
        if output == "Fy" and ("delta", 1) in by_block:
            cj = by_block[("delta", 1)]
            d2 = sum(v * j * (j - 1) * fz ** max(j - 2, 0) for j, v in cj.items())
            # PSA sign: the stiffness is negative; concave in magnitude means |c| concave.
            if np.max(-d2) > 0 and max(cj) >= 2:
                return f"b_{output}_delta_1_{max(cj)}"
        # 3. extremum counts in the useful domain
        if any(b == "delta" for b, _ in by_block):
            model = PolynomialModel.create(output, {"delta": max(i for b, i in by_block
                                                                 if b == "delta")},
                                           values={n: x for n, x in pneu.items()
                                                   if parse_name(n)[1] == "delta"})
            for f in loads:
                ex = model.extrema(float(f), "delta", x_lo, x_hi)
                if (sum(k == "max" for _, _, k in ex) > 1 or sum(k == "min" for _, _, k in ex) > 1):
                    i, j = max((i, j) for (b, i), cc in by_block.items() if b == "delta"
                               for j in cc)
                    return f"b_{output}_delta_{i}_{j}"
        return None

    return rule


# --------------------------------------------------------------------------------------------
# Identification


@dataclasses.dataclass
class OutputReport:
    """One output's identification: `fit` (step 1, the `lsq.Fit` with its elimination log),
    `reduced` (the final structure refitted alone: its coefficients with their σ, σ %),
    `model` (the identified F_pneu), `compliance` K_y⁻¹ [m/N] and `compliance_sigma` (joint
    linearisation, see the module docstring), `compliance_sigma_step2` (the thesis's σ of
    the step-2 regression), `stiffness` K_y [N/m], `step2` (the step-2 `lsq.Fit`), `removed`
    (name → reason), `not_identifiable` (name → why)."""

    output: str
    fit: lsq.Fit
    reduced: lsq.Fit
    model: PolynomialModel
    compliance: float
    compliance_sigma: float
    compliance_sigma_step2: float
    step2: lsq.Fit
    removed: dict
    not_identifiable: dict

    @property
    def stiffness(self) -> float:
        return 1.0 / self.compliance

    @property
    def stiffness_sigma_pct(self) -> float:
        return 100.0 * self.compliance_sigma / abs(self.compliance)


@dataclasses.dataclass
class BenchReport:
    """The result of `identify`: `outputs` ("Fy", "Mz" → `OutputReport`), `stable` (the
    identified F_y model has ∂Fy_pneu/∂δ′ < 0 on every conditioned sample), `min_margin`
    (max ∂Fy_pneu/∂δ′ over the data, N/m), `flags` (warnings in words), `notes` (what is not
    identifiable and why), `structure`, `n_rows`, `rate`."""

    outputs: dict
    stable: bool
    max_margin: float
    flags: list
    notes: list
    structure: str
    n_rows: int
    rate: float

    def table(self) -> str:
        lines = [f"bench identification ({self.structure} structure): {self.n_rows} rows at "
                 f"{self.rate:.4g} Hz after conditioning"]
        for out, r in self.outputs.items():
            lines.append(f"== {out}: K_y = {r.stiffness:.6g} N/m (sigma {r.stiffness_sigma_pct:.3g}"
                         f" %); compliance {r.compliance:.4g} m/N")
            for n, x, s in zip(r.reduced.names, r.reduced.x, r.reduced.sigma_pct, strict=True):
                lines.append(f"  {n:<20} {x:>13.6g}  ({s:.3g} %)")
            if r.removed:
                lines.append(f"  removed by the structure search: {len(r.removed)} terms")
        lines += [f"note: {n}" for n in self.notes]
        lines += [f"FLAG: {f}" for f in self.flags]
        return "\n".join(lines)

    def __str__(self):
        return self.table()

    def to_dict(self) -> dict:
        return {"structure": self.structure, "stable": self.stable, "flags": self.flags,
                "notes": self.notes, "n_rows": self.n_rows, "rate": self.rate,
                "outputs": {o: {"stiffness": r.stiffness, "compliance": r.compliance,
                                "compliance_sigma": r.compliance_sigma,
                                "coefficients": r.model.values(),
                                "sigma_pct": {n: float(s) for n, s in zip(
                                    r.reduced.names, r.reduced.sigma_pct, strict=True)},
                                "removed": r.removed, "not_identifiable": r.not_identifiable}
                            for o, r in self.outputs.items()}}


def _joint_sigma(Wp, D, extra, b, c, y):
    """σ of c in the joint model y = W b + c·(D b + extra) (the relaxation written with the
    interaction coefficients, (3-49…3-52)), linearised at the two-step estimate (b, c)."""
    w = D @ b + extra
    J = np.concatenate([Wp + c * D, w[:, None]], axis=1)
    f = lsq.solve(J, y - (Wp @ b + c * w) + J @ np.append(b, c))
    return float(f.sigma[-1])


def identify_output(cond: Conditioned, output: str, degrees, *, search: bool = True,
                    rules: bool = True, sigma_pct_threshold: float | None = 10.0,
                    ic_threshold: float = 0.0, fixed=None, rolling_radius: float = 0.294
                    ) -> OutputReport:
    """Two-step identification of one output ("Fy" or "Mz") on conditioned data (spec §3.3):
    step 1 [W_pneu | W_Ly (| W_P2)] with the structure search, step 2 K_y⁻¹ (3-76, 3-77).

    The search removes, one at a time, the coefficient with σ % > `sigma_pct_threshold`
    (default 10 %: the thesis's tables print nothing above 3.9 %) or with a confidence index
    below `ic_threshold` (default 0: off — the thesis's IC < 0.1 rule is not what its tables
    show, which keep coefficients with IC down to 0.01, and on synthetic data it removes true
    terms such as b_Fy_delta_5_2), then applies the behaviour rules (`structure_rules`)."""
    y = cond.fy if output == "Fy" else cond.mz
    lip = regressor_model(output, degrees, ly=True, p2=(output == "Mz"))
    W = cond.regressor(lip)
    names = lip.names
    removed, not_ident = {}, {}
    if search:
        fz = cond.inputs["fz"]
        check = structure_rules(output, (float(fz.min()), float(fz.max())),
                                rolling_radius=rolling_radius, ic_threshold=ic_threshold,
                                sigma_pct_threshold=sigma_pct_threshold) if rules else None
        fit, log = lsq.eliminate(W, y, names=names, sigma_pct_threshold=sigma_pct_threshold,
                                 ic_threshold=ic_threshold, check=check, fixed=fixed)
        for st in log:
            removed[st.removed] = st.reason
    else:
        fit = lsq.solve(W, y, names=names, fixed=fixed)
    # The engine judges identifiability on the full model (a removed column still regroups
    # with the kept ones), so the kept coefficients of the final structure get their σ from
    # the reduced model itself: one more fit on the kept columns.
    active = [i for i in range(len(names)) if fit.kept[i] and not fit.fixed[i]]
    reduced = lsq.solve(W[:, active], y, names=[names[i] for i in active])
    x_full = np.zeros(len(names))
    x_full[active] = reduced.x
    for i, n in enumerate(names):
        # dropped for rank (neither kept nor removed by the search): no effect, or a
        # combination of others
        if not fit.kept[i] and not fit.fixed[i]:
            not_ident[n] = fit._status(i) or "not identifiable"
    pneu_idx = [i for i, n in enumerate(names) if parse_name(n)[1] not in ("Ly", "P2")]
    pneu_names = [names[i] for i in pneu_idx]
    b_pneu = x_full[pneu_idx]
    model = PolynomialModel.create(output, degrees, values=dict(zip(pneu_names, b_pneu,
                                                                    strict=True)))
    # Step 2: the Ly columns are (Ḟ_y/ω)·∂(δ′^i F_z^j)/∂δ′, so (∂F̂_pneu/∂δ′)·Ḟ_y/ω = D·b̂.
    D = np.zeros((W.shape[0], len(pneu_idx)))
    for k, n in enumerate(pneu_names):
        _, block, i, j = parse_name(n)
        if block == "delta":
            D[:, k] = W[:, names.index(f"b_{output}_Ly_{i - 1}_{j}")]
    extra = W[:, names.index(f"b_{output}_P2_0_0")] if output == "Mz" else np.zeros(len(y))
    Wp = W[:, pneu_idx]
    d = D @ b_pneu + extra
    step2 = lsq.solve(d[:, None], y - Wp @ b_pneu, names=[f"K_{output}_y^-1"])
    c = float(step2.x[0])
    keep = np.array([bool(fit.kept[i]) and not bool(fit.fixed[i]) for i in pneu_idx])
    sig = _joint_sigma(Wp[:, keep], D[:, keep], extra, b_pneu[keep], c, y)
    return OutputReport(output, fit, reduced, model, c, sig, float(step2.sigma[0]), step2,
                        removed, not_ident)


def identify(table: Mapping, *, structure: str = "just-necessary", cutoff: float = 25.0,
             rolling_radius: float = 294.0, decimate: int | None = None, search: bool = True,
             outputs=("Fy", "Mz"), sigma_pct_threshold: float | None = 10.0,
             ic_threshold: float = 0.0) -> BenchReport:
    """Identify the polynomial tyre model and the lateral stiffnesses K_{Fy,y}, K_{Mz,y} from a
    Flat Trac table (spec §3.3–3.5). `structure`: "just-necessary" (Table 10) or "apriori"
    (Table 5); `search`: run the structure search (else one least-squares fit of the whole
    structure). Bad input raises `InputError`; an identified model that is unstable on the
    data (∂F̂y_pneu/∂δ′ ≥ 0 somewhere) is flagged in `report.flags` and `report.stable`."""
    if structure not in STRUCTURES:
        raise InputError(f"structure {structure!r}: one of {', '.join(STRUCTURES)}")
    cond = condition(table, cutoff=cutoff, rolling_radius=rolling_radius, decimate=decimate)
    r_m = rolling_radius * 1e-3
    reports = {o: identify_output(cond, o, STRUCTURES[structure][o], search=search,
                                  rolling_radius=r_m, sigma_pct_threshold=sigma_pct_threshold,
                                  ic_threshold=ic_threshold) for o in outputs}
    notes, flags = [], []
    exc = cond.excitation
    if exc["kappa"] < 1e-6:
        notes.append("K_x is not identifiable: kappa' is not excited (free rolling, std "
                     f"{exc['kappa']:.2g} m) and F_x carries only the rolling resistance; the "
                     "longitudinal joint is locked (spec §3.4).")
    for o, r in reports.items():
        if r.not_identifiable:
            notes.append(f"{o}: not identifiable on these data: "
                         + ", ".join(sorted(r.not_identifiable)))
        if r.compliance <= 0:
            flags.append(f"{o}: the identified compliance K_y^-1 = {r.compliance:.4g} m/N is not "
                         "positive: the relaxation is not excited enough (no slip transient).")
    stable, margin = True, float("nan")
    if "Fy" in reports:
        m = np.asarray(relaxation.stability_margin(reports["Fy"].model, cond.inputs))
        margin = float(np.max(m))
        stable = bool(margin < 0)
        if not stable:
            k = int(np.argmax(m))
            flags.append(f"unstable identified model: dFy_pneu/ddelta' = {margin:.4g} N/m >= 0 "
                         f"at F_z = {cond.inputs['fz'][k]:.3g} kN, delta' = "
                         f"{1e3 * cond.inputs['delta'][k]:.3g} mm (beyond the grip peak; the "
                         "simulation model (3-82) would diverge there).")
    return BenchReport(reports, stable, margin, flags, notes, structure, len(cond.fy), cond.rate)


# --------------------------------------------------------------------------------------------
# Monte-Carlo of the two-step method (one vmapped program)


def _two_step_arrays(W, y, pneu_idx, ly_idx, p2_idx, fixed):
    """Step 1 (`lsq.solve_arrays`, `fixed` columns at 0), step 2 and the joint σ, pure JAX."""
    sol = lsq.solve_arrays(W, y, fixed=fixed)
    b = sol.x[pneu_idx]
    D = jnp.where(ly_idx[None, :] >= 0, W[:, jnp.maximum(ly_idx, 0)], 0.0)
    extra = W[:, p2_idx] if p2_idx is not None else jnp.zeros_like(y)
    Wp = W[:, pneu_idx]
    d = D @ b + extra
    r = y - Wp @ b
    c = d @ r / (d @ d)
    sig2 = jnp.sqrt(jnp.sum((r - c * d) ** 2) / (y.shape[0] - 1)) / jnp.linalg.norm(d)
    J = jnp.concatenate([Wp + c * D, d[:, None]], axis=1)
    joint = lsq.solve_arrays(J, y - Wp @ b - c * d + J @ jnp.append(b, c),
                             fixed=jnp.append(fixed[pneu_idx], False))
    return sol.x, sol.sigma, c, sig2, joint.sigma[-1]


def monte_carlo(table: Mapping, output: str, degrees, keep, *, noise: Mapping[str, float],
                seeds: int = 20, cutoff: float = 25.0, rolling_radius: float = 294.0,
                decimate: int | None = None, order: int = 4, key: int = 0) -> dict:
    """The two-step identification of `output` repeated on `seeds` noisy copies of a
    (noise-free) bench table, in one vmapped program: white noise of σ `noise[channel]`
    (table units) added to FY, MZ, FX, FZ; the structure fixed to the coefficients `keep`
    (names; the others held at 0 and not even built, e.g. the result of a structure search or
    the true model).

    **Returns:** dict of arrays over seeds: `x` (seeds, p) step-1 coefficients, `sigma`
    (seeds, p) their reported σ, `compliance` (seeds,) K_y⁻¹, `sigma_step2` (the thesis's σ),
    `sigma_joint` (the report's σ), and `names`.
    """
    cols, n_seg, m, rate = _check_table(table, cutoff)
    sos = jnp.asarray(butterworth(cutoff, rate, order))
    k = decimate if decimate is not None else max(1, int(rate // (2 * cutoff)))
    trim = max(5, int(2 * rate / cutoff))
    rows = jnp.arange(trim, m - trim, k)
    full = regressor_model(output, degrees, ly=True, p2=(output == "Mz"))
    unknown = [n for n in keep if n not in full.names]
    if unknown:
        raise InputError(f"keep: {unknown} are not coefficients of the {output} model")
    # Only the kept columns are built and filtered (the others are held at 0).
    lip = full.select([n for n in full.names if n in keep])
    names = lip.names
    fixed = jnp.zeros(len(names), bool)
    pneu_idx = jnp.asarray([i for i, n in enumerate(names)
                            if parse_name(n)[1] not in ("Ly", "P2")])
    ly_idx = []
    for i in np.asarray(pneu_idx):
        _, block, ii, j = parse_name(names[int(i)])
        ly = f"b_{output}_Ly_{ii - 1}_{j}"
        ly_idx.append(names.index(ly) if block == "delta" and ly in names else -1)
    ly_idx = jnp.asarray(ly_idx)
    p2 = f"b_{output}_P2_0_0"
    p2_idx = names.index(p2) if p2 in names else None
    base = {c: jnp.asarray(cols[c].reshape(n_seg, m)) for c in REQUIRED
            if c not in ("t", "segment")}
    sig = {c: float(noise.get(c, 0.0)) for c in ("FY", "MZ", "FX", "FZ")}

    @jax.jit
    def run(keys):
        def one(kk):
            ks = jax.random.split(kk, 4)
            noisy = dict(base)
            for s, c in zip(ks, ("FY", "MZ", "FX", "FZ"), strict=True):
                noisy[c] = base[c] + sig[c] * jax.random.normal(s, base[c].shape)
            samples, fy_f, mz_f = _condition_block(noisy, sos, 1.0 / rate, rolling_radius * 1e-3)
            W = _filtered_regressor(lip, samples, sos, rows)
            y = (fy_f if output == "Fy" else mz_f)[:, rows].ravel()
            return _two_step_arrays(W, y, pneu_idx, ly_idx, p2_idx, fixed)
        return jax.vmap(one)(keys)

    x, sigma, c, s2, sj = run(jax.random.split(jax.random.PRNGKey(key), seeds))
    return {"names": names, "x": np.asarray(x), "sigma": np.asarray(sigma),
            "compliance": np.asarray(c), "sigma_step2": np.asarray(s2),
            "sigma_joint": np.asarray(sj)}


# --------------------------------------------------------------------------------------------
# Batched structure search (many tyres in one program)


def eliminate_r(R, n, *, sigma_pct_threshold: float = 10.0, max_steps: int | None = None):
    """The σ % elimination loop of `identify_output` (without the behaviour rules), traced:
    from the augmented R-factor of one data set (`lsq.qr_r` of [W, −y]), repeatedly hold at 0
    the kept coefficient whose combination has the largest σ % above `sigma_pct_threshold`,
    refitting from R alone (spec: guaranteed_least_squares §3.9), until none is left.
    `jax.vmap` it over stacked R-factors (4 tyres × 3 pressures: one program).

    **Returns:** (fixed mask, x, σ) of the final fit (x = 0 where fixed or not kept)."""
    from ..lsq import core

    p = R.shape[-1] - 1
    dtype = R.dtype
    thr = jnp.asarray(0.0, dtype)
    prior, prior_sigma, lower, upper, _ = core.fill_defaults(p, dtype, "basic", None, None,
                                                             None, None, None)
    n = jnp.asarray(n, dtype)
    ident = core._identifiability(R, n, thr, True)

    def solve(fixed):
        return core._solve_r(R, n, prior, prior_sigma, lower, upper, fixed, thr, ident,
                             method="basic", pivot=True, dof="n-rank")

    def worst(sol, fixed):
        rel = 100.0 * jnp.abs(sol.relation_sigma / sol.relation_values)
        bad = sol.kept & ~fixed & (jnp.nan_to_num(rel) > sigma_pct_threshold)
        score = jnp.where(bad, jnp.nan_to_num(rel), -jnp.inf)
        return jnp.any(bad), jnp.argmax(score)

    def cond(state):
        fixed, go, k = state
        return go & (k < (max_steps if max_steps is not None else p))

    def body(state):
        fixed, _, k = state
        any_bad, i = worst(solve(fixed), fixed)
        return jnp.where(any_bad, fixed.at[i].set(True), fixed), any_bad, k + 1

    fixed, _, _ = jax.lax.while_loop(cond, body, (jnp.zeros(p, bool), jnp.asarray(True), 0))
    sol = solve(fixed)
    return fixed, sol.x, sol.sigma
