"""Flat Trac bench signal conditioning (spec tyre §3.4, §7 D item 17): the bench table's
columns, the zero-phase Butterworth filter (`butterworth`, `filtfilt`, `filter_matrix`), the
centred differences, the bench kinematics and `condition` → `Conditioned`, the filtered
regressor rows the identification in `diffsusp.tyre.bench` reads (the method is described in
that module's docstring). Every public name is importable from `diffsusp.tyre.bench`.
"""

import dataclasses
import functools
import math
from collections.abc import Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy import ndimage, signal

from ..compilation import CPU_OPTIONS
from ..errors import InputError

REQUIRED = ("t", "segment", "steer", "camber", "speed", "omega", "FZ", "FX", "FY", "MZ")
UNITS = {"t": "s", "segment": None, "steer": "rad", "camber": "rad", "speed": "mm/s",
         "omega": "rad/s", "FZ": "N", "FX": "N", "FY": "N", "MZ": "N·mm"}

def quick_jit(fn):
    """`jax.jit` with XLA's backend optimisation off: this module's programs (the campaign's
    simulation, the regressors, the Monte-Carlo) are compiled once and run in well under a
    second, and compiling them at the default level costs 3× more CPU than it saves (the
    Monte-Carlo program: 2.7 s instead of 8.3 s to compile, 1.1 s instead of 0.8 s for 40
    seeds)."""
    compiled = {}

    def call(*args):
        if "f" not in compiled:
            options = {"xla_backend_optimization_level": 0}
            if jax.default_backend() == "cpu":
                options.update(CPU_OPTIONS)
            compiled["f"] = jax.jit(fn, compiler_options=options)
        return compiled["f"](*args)
    return call


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


MAX_SEGMENT = 2048
"""Longest segment filtered as one block (samples); longer ones are cut into equal pieces."""


@functools.lru_cache(maxsize=16)
def filter_matrix(cutoff: float, rate: float, m: int, order: int = 4) -> np.ndarray:
    """The zero-phase filter of a segment of m samples as an (m, m) matrix: `filtfilt(sos, x)
    = F @ x` (NumPy, cached). `filtfilt` is linear in x (odd extension, steady-state initial
    conditions scaled by the end samples), so F is the filter applied to the identity; it
    makes the conditioning a few matrix products and gives the noise model of the
    identification (`identify_output`) its correlations."""
    sos = butterworth(cutoff, rate, order)
    n_sec = sos.shape[0]
    pad = 3 * (2 * n_sec + 1)
    if m <= pad:
        raise InputError(f"a segment of {m} samples is too short for the zero-phase filter "
                         f"(more than {pad} needed)")
    gains = sos[:, :3].sum(axis=1) / sos[:, 3:].sum(axis=1)
    scale = np.concatenate([[1.0], np.cumprod(gains)[:-1]])
    zis = [np.linalg.solve(np.array([[1.0 + c[4], -1.0], [c[5], 1.0]]),
                           np.array([c[1] - c[4] * c[0], c[2] - c[5] * c[0]])) * scale[s]
           for s, c in enumerate(sos)]

    def section(sec, v, zi):
        b0, b1, b2, _, a1, a2 = sec
        z0, z1 = zi[0] * v[0], zi[1] * v[0]
        out = np.empty_like(v)
        for i in range(v.shape[0]):
            y = b0 * v[i] + z0
            z0, z1 = b1 * v[i] - a1 * y + z1, b2 * v[i] - a2 * y
            out[i] = y
        return out

    def run(v):
        for s in range(n_sec):
            v = section(sos[s], v, zis[s])
        return v

    x = np.eye(m)
    ext = np.concatenate([2 * x[:1] - x[pad:0:-1], x, 2 * x[-1:] - x[-2:-pad - 2:-1]])
    y = run(run(ext)[::-1])[::-1]
    return np.ascontiguousarray(y[pad:-pad])


@functools.lru_cache(maxsize=16)
def difference_matrix(m: int, dt: float) -> np.ndarray:
    """`centred_derivative` as an (m, m) matrix (NumPy, cached)."""
    return np.asarray(centred_derivative(np.eye(m).T, dt)).T.copy()


@dataclasses.dataclass(frozen=True)
class Conditioned:
    """Conditioned bench data (polynomial units: fz [kN], delta, kappa [m], phi, gamma [rad],
    pi_* products, fydot_w [N], fy, fx [N]).

    **Parallel filtering:** the regression is run on the *filtered* output and the *filtered
    columns* of the regressor built from the unfiltered inputs, H(y) = H(W(u))·b, which holds
    exactly for any linear filter H; filtering the inputs instead, W(H(u)), misses the
    harmonics that the nonlinear terms create (at 25 Hz the δ′³ term of a 6 Hz slip sine is
    off by several newtons). Ḟ_y too is taken by centred differences of the *unfiltered* F_y
    inside the relaxation columns, which are then low-passed with the others: the same 25 Hz
    band as the thesis's filter-then-differentiate, without a second attenuation of the F_y
    harmonics near the cut-off (filtering F_y before differencing biased the δ′², δ′⁴
    relaxation terms by one σ on noise-free synthetic data; the noise is removed by the outer
    filter alike).

    **Fields:** `samples` (input → (segments, samples) unfiltered, full rate, with `omega`),
    `operator` (the filter's rows at the kept samples, (rows, samples): H_rows),
    `difference` (the centred-difference matrix), `sos` (the filter's second-order
    sections), `rows` (the kept sample indices after trimming the ends and thinning),
    `inputs` (the same inputs at the kept rows, for checks and plots), `fy` [N], `mz` [N·m]
    (filtered, kept rows), `rate` [Hz] after thinning, `segment` per kept row,
    `excitation` (input → standard deviation), `dt` [s] the sampling step, `noise` (FY [N],
    MZ [N·m] → the noise σ from their content above the cut-off, rms over the samples),
    `noise_profile` (FY, MZ → (segments, samples) σ_t relative to that level: the noise
    growing with the force, `noise_model`), `noise_models` (FY, MZ → (a, b) of σ = a + b·|F|,
    a in N or N·m), `outliers` (FY, MZ → samples replaced), `noise_dof` (FY, MZ → degrees of
    freedom of the noise level, `noise_dof`)."""

    samples: dict
    sos: np.ndarray
    rows: np.ndarray
    inputs: dict
    fy: np.ndarray
    mz: np.ndarray
    rate: float
    segment: np.ndarray
    excitation: dict
    operator: np.ndarray
    difference: np.ndarray
    dt: float
    noise: dict
    noise_profile: dict | None = None
    noise_models: dict | None = None
    outliers: dict | None = None
    noise_dof: dict | None = None

    def regressor(self, model) -> np.ndarray:
        """H(W(u)) at the kept rows, (n, p), for a `lsq.algebra.LinearModel`."""
        W = np.asarray(_regressor_program(model)(self.samples))
        return np.einsum("rm,smp->srp", self.operator, W).reshape(-1, W.shape[-1])


_PROGRAMS: dict = {}


def _regressor_program(model):
    """One compiled regressor per model structure (its names and inputs), reused by every
    call with equal shapes."""
    key = (model.names, model.inputs)
    if key not in _PROGRAMS:
        _PROGRAMS[key] = quick_jit(lambda s: model.regressor(s))
    return _PROGRAMS[key]


def centred_derivative(v, dt):
    """dv/dt by the five-point centred difference (−v₊₂ + 8v₊₁ − 8v₋₁ + v₋₂)/12h, error
    O(h⁴) (the three-point one, O(h²), is 0.6 % off at 6 Hz sampled at 200 Hz, which biases
    the relaxation terms by several σ); three-point at the second and penultimate samples and
    one-sided at the ends (trimmed away by `condition`). NumPy in, NumPy out."""
    xp = np if isinstance(v, np.ndarray) else jnp
    inner = (-v[..., 4:] + 8 * v[..., 3:-1] - 8 * v[..., 1:-3] + v[..., :-4]) / (12 * dt)
    two = (v[..., 2:] - v[..., :-2]) / (2 * dt)
    first = (v[..., 1:2] - v[..., 0:1]) / dt
    last = (v[..., -1:] - v[..., -2:-1]) / dt
    return xp.concatenate([first, two[..., :1], inner, two[..., -1:], last], axis=-1)


def kinematics(cols, Dm, rolling_radius):
    """(segments, samples) channels (table units) → the deformation inputs and Ḟ_y/ω at full
    rate, polynomial units; NumPy or JAX arrays (the difference as the matrix Dm)."""
    xp = np if isinstance(cols["FY"], np.ndarray) else jnp
    speed = cols["speed"] * 1e-3
    steer = cols["steer"]
    omega = cols["omega"]
    vx, vy = speed * xp.cos(steer), -speed * xp.sin(steer)
    bdot = steer @ Dm.T
    g = cols["camber"]
    fz = cols["FZ"] * 1e-3
    # F_x as its load polynomial F̂x_pneu(F_z) (3-48), fitted to the measured F_x: the
    # coupling column −F_y·F_x of M_z (3-69) built from the raw F_x is an error in the
    # variables (3 N of F_x noise times F_y: a 0.75 σ bias of M_z's coefficients)
    V = xp.stack([xp.ones_like(fz), fz, fz**2, fz**3], axis=-1).reshape(-1, 4)
    coef = xp.linalg.lstsq(V, cols["FX"].reshape(-1), rcond=None)[0]
    return {
        "fz": fz, "kappa": vx / omega - rolling_radius, "delta": vy / omega,
        "phi": bdot / omega, "gamma": g, "pi_gamma_vx": g * vx / omega,
        "pi_gamma_bdot": g * bdot / omega, "pi_gamma2_bdot": g * g * bdot / omega,
        "fydot_w": (cols["FY"] @ Dm.T) / omega, "fy": cols["FY"],
        "fx": (V @ coef).reshape(fz.shape), "omega": omega}


@jax.jit
def _condition_block(cols, sos, dt, rolling_radius):
    """(segments, samples) arrays → deformation inputs (unfiltered kinematics), Ḟ_y/ω,
    filtered F_y and M_z, by the scan filter (`filtfilt`): the benchmark's long-record path."""
    m = cols["FY"].shape[-1]
    eye = jnp.eye(m)
    Dm = centred_derivative(eye, dt).T
    samples = kinematics(cols, Dm, rolling_radius)
    return samples, filtfilt(sos, cols["FY"]), filtfilt(sos, cols["MZ"]) * 1e-3


@eqx.filter_jit
def _filtered_regressor(model, samples, sos, rows):
    W = model.regressor(samples)  # (segments, samples, p)
    Wf = filtfilt(sos, jnp.moveaxis(W, -1, -2))  # along time
    return jnp.moveaxis(Wf[..., rows], -1, -2).reshape(-1, W.shape[-1])


OUTLIER_LEVEL = 6.0
"""A raw F_y or M_z sample whose content above the cut-off exceeds this many local noise σ is
an outlier (`noise_model`): a Gaussian sample does so with probability 2e-9."""


def noise_model(y, E, F, inner, *, E_noise=None, outliers: bool = True, passes: int = 8,
                margin: int = 0):
    """The noise of one bench channel from its content above the cut-off (spec tyre §4.2: the
    bench's white measurement noise; force rigs' noise usually grows with the force), NumPy or
    JAX arrays (traced by `tyre.bench_batch`).

    The high-pass residual z = (I − F)·y of each segment (`E` = I − F, `F` the zero-phase
    filter) is the noise e filtered by E, the signal being below the cut-off:
    E[z_t²] = Σ_k E_tk²·v_k ≈ c_t·v_t with c_t = Σ_k E_tk². The noise σ is modelled as
    σ_t = a + b·|F·y|_t (the force itself, low-passed): E|z_t|/√c_t = √(2/π)·(a + b·|F·y|_t),
    a linear regression of |z_t|/√c_t on (1, |F·y|_t). The slope is kept only when it is
    significant (|b| above 3 standard errors, and a + b·|F| positive on the data); else the
    noise is white. The level is read in a higher band, `E_noise` = I − F_noise (`condition`:
    above 0.3× the sampling rate, 60 Hz at 200 Hz): just above a 25 Hz cut-off the signal
    has content of its own (the 5th harmonic of a 6 Hz slip sine through δ′⁵: up to 6 N on
    F_y and 13 N·m on M_z on the shipped campaign, 20× M_z's noise), above 60 Hz less than
    0.02 N.

    **Outliers** (`outliers`): a sample farther than `OUTLIER_LEVEL`·σ_t (in units of the
    noise band's gain) from the noise band's low-pass of the cleaned record is replaced by the
    25 Hz low-pass of the cleaned record, the flags recomputed at each of `passes` passes
    (an outlier's neighbours, flagged while it leaks into the low-pass, are released once it is
    out) and the noise fit repeated without them. Isolated outliers above ≈ 9 σ are found
    (2 % of 20 σ spikes on F_y: 90 % flagged, none falsely); two adjacent ones of the same
    sign are nearly invisible above 60 Hz and stay: the residual's consistency test then
    says so. Only the samples `inner` (bool, per sample of a segment: the
    rows the identification keeps, the filter's edge transients trimmed) are used, and
    flagged with `margin` samples more on each side (the samples whose noise reaches the kept
    rows through the filter and the differences).

    **Returns:** (the cleaned y, the mean noise σ (rms over the samples, the level the
    identification's noise model scales), the relative σ profile w (σ_t/that level, same shape
    as y), (a, b), the outlier mask)."""
    xp = np if isinstance(y, np.ndarray) else jnp
    E_noise = E if E_noise is None else E_noise
    cn = xp.sqrt(xp.sum(E_noise * E_noise, axis=1))
    flagged = xp.zeros(y.shape, bool)
    inside = xp.broadcast_to(xp.asarray(inner), y.shape)
    near = np.asarray(inner).copy()
    if margin:
        idx = np.flatnonzero(near)
        near[max(idx[0] - margin, 0):idx[-1] + margin + 1] = True
    # (not at the segment ends, where the zero-phase filter's band has no gain)
    gain = np.sqrt(np.sum(np.asarray(E_noise) ** 2, axis=1)) if xp is np else None
    if gain is not None:
        near &= gain >= 0.8 * np.median(gain)
    near = xp.broadcast_to(xp.asarray(near), y.shape)
    low = xp.eye(E_noise.shape[0]) - E_noise  # the noise band's low-pass
    clean = y
    a, b = xp.asarray(0.0), xp.asarray(0.0)
    level = None
    for _ in range(passes):
        zn = clean @ E_noise.T
        f = xp.abs(clean @ F.T)
        u = xp.abs(zn) / cn / math.sqrt(2.0 / math.pi)
        ok = ~flagged & inside
        if level is not None:
            ok = ok & (xp.abs(zn) <= 4.0 * cn * level)
        w = ok.astype(y.dtype)
        n = xp.sum(w)
        # weighted least squares of u on (1, f) (the 2×2 normal equations)
        s1, sf, sff = n, xp.sum(w * f), xp.sum(w * f * f)
        su, suf = xp.sum(w * u), xp.sum(w * u * f)
        det = s1 * sff - sf * sf
        det = xp.where(det > 0, det, 1.0)
        b = (s1 * suf - sf * su) / det
        a = (su - b * sf) / s1
        res = u - a - b * f
        var_r = xp.sum(w * res * res) / xp.maximum(n - 2.0, 1.0)
        se_b = xp.sqrt(var_r * s1 / det)
        fmax = xp.max(xp.where(ok, f, 0.0))
        keep = (xp.abs(b) > 3.0 * se_b) & (a + b * fmax > 0) & (a > 0)
        mean_u = su / s1
        a, b = xp.where(keep, a, mean_u), xp.where(keep, b, 0.0)
        level = xp.maximum(a + b * f, 1e-12 * xp.maximum(mean_u, 1e-300))
        if outliers:
            # the sample against the noise band's low-pass of the cleaned record (the signal
            # has no content above it), flags recomputed each pass: an outlier's neighbours,
            # flagged while it still leaks into the low-pass, are released once it is out
            # (a channel whose noise is below 1e-6 of its size, noise-free data, has none)
            noisy = mean_u > 1e-6 * xp.sqrt(xp.mean(y * y))
            flagged = near & noisy & (xp.abs(y - clean @ low.T)
                                      > OUTLIER_LEVEL * cn * level)
            clean = xp.where(flagged, clean @ F.T, y)
    # the mean level: the rms of σ_t over the kept samples (from E|z|, with the samples
    # beyond 4 σ_t left out of the fit: a mean of z² let the signal's own content above the
    # cut-off — M_z's harmonics on slip ramps, 4× the noise on the shipped campaign — stand
    # for noise)
    w = inside.astype(y.dtype)
    ce = cn * cn
    mean_level = xp.sqrt(xp.sum(w * level * level * ce) / xp.sum(w * ce))
    return clean, mean_level, level / mean_level, (a, b), flagged


def noise_band(rate: float, cutoff: float, m: int, order: int = 4) -> np.ndarray:
    """E_noise = I − F of the band where `noise_model` reads the noise level: above
    max(0.3·rate, 1.2·cutoff) (60 Hz at 200 Hz), (m, m)."""
    return np.eye(m) - filter_matrix(max(0.3 * rate, 1.2 * cutoff), float(rate), m, order)


def noise_dof(E, n_seg: int) -> float:
    """The effective degrees of freedom of the noise level estimated above the cut-off
    (`noise_model`: Σ z² over n_seg segments of z = E·e, Satterthwaite: n·tr(EᵀE)²/tr((EᵀE)²))
    — the uncertainty of the reference the consistency test compares the residual with."""
    G = E.T @ E
    return float(n_seg * np.trace(G) ** 2 / np.sum(G * G))


def check_table(table, cutoff):
    """Check a bench table; returns (channels as (segments, samples) arrays, number of
    segments, samples per segment, rate [Hz]). Segments longer than `MAX_SEGMENT` samples are
    cut into equal pieces (each filtered on its own; the tail beyond a whole number of pieces
    is dropped)."""
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
    blocks = {c: v.reshape(len(ids), m) for c, v in cols.items()}
    pieces = -(-m // MAX_SEGMENT)
    if pieces > 1:
        mm = m // pieces
        blocks = {c: v[:, :pieces * mm].reshape(len(ids) * pieces, mm)
                  for c, v in blocks.items()}
        m = mm
    return blocks, blocks["FY"].shape[0], m, rate


MEDIAN_CHANNELS = ("steer", "camber", "speed", "omega", "FZ", "FX", "FY", "MZ")
"""The measured channels the median filter cleans (not the time and segment columns)."""

SPIKE_LEVEL = 6.0
"""`median_filter` replaces a sample that departs from its window's median by more than this
many σ of the channel's noise, estimated robustly from its second differences (white noise
of σ has Var Δ²x = 6σ²; σ = 1.4826·MAD(Δ²x)/√6, a spike or a smooth signal barely moves it)."""


def median_filter(blocks: Mapping[str, np.ndarray], width: int) -> dict[str, np.ndarray]:
    """The measured channels (`MEDIAN_CHANNELS`) of (segments, samples) blocks cleaned of
    "Dirac" spikes by a running median of `width` samples (odd; `scipy.signal.medfilt`),
    segment by segment: the thesis's median filter joined to the zero-phase low-pass
    (§1.3.3), used as a spike detector (a Hampel identifier) — a sample that departs from its
    window's median by more than `SPIKE_LEVEL` σ of the channel's noise, and most within its
    window, is replaced by the median of the window's other samples; again until none is
    left (a spike moves its neighbours' medians). The others, and the half-window at each
    end, are kept as measured.

    Why not the plain running median: it flattens the peaks of the slip and force sines, a
    distortion different on each channel, and the relaxation's lateral stiffness is read
    from their phase — on the shipped campaign with 1 % spikes, a plain 5-sample median gave
    K_y = 3.7e6 N/m (truth 157 381), none 149 056 ± 4.6 %, this filter 157 208 ± 0.096 %."""
    if width < 3 or width % 2 == 0:
        raise InputError(f"median filter width {width}: an odd number of samples ≥ 3.")
    h = width // 2
    out = dict(blocks)
    for c in MEDIAN_CHANNELS:
        if c not in out:
            continue
        rows = []
        for row in np.asarray(out[c], float):
            scale = 1.4826 * np.median(np.abs(np.diff(row, 2))) / math.sqrt(6.0)
            for _ in range(width):  # the worst first: a spike shifts its neighbours' median
                dev = np.abs(row - signal.medfilt(row, width))
                spike = (dev > SPIKE_LEVEL * scale) & (dev >= ndimage.maximum_filter1d(dev,
                                                                                       width))
                spike[:h] = spike[row.size - h:] = False
                if not spike.any():
                    break
                # the median of the window's other samples (a slope's centre, not a neighbour)
                i = np.flatnonzero(spike)
                window = row[i[:, None] + np.r_[-h:0, 1:h + 1][None, :]]
                row = row.copy()
                row[i] = np.median(window, axis=1)
            rows.append(row)
        out[c] = np.stack(rows)
    return out


def kept_rows(m, rate, cutoff, decimate, trim):
    # (+1e-6: a rate of 199.999… Hz from the time column still thins by 4 at 25 Hz)
    k = decimate if decimate is not None else max(1, int(rate / (2 * cutoff) + 1e-6))
    trim = trim if trim is not None else max(5, int(2 * rate / cutoff + 1e-6))
    rows = np.arange(trim, m - trim, k)
    if len(rows) < 2:
        raise InputError(f"bench table: segments of {m} samples leave nothing after trimming "
                         f"{trim} samples at each end; record longer segments.")
    return rows, k


def condition(table: Mapping, *, cutoff: float = 25.0, rolling_radius: float = 294.0,
              decimate: int | None = None, trim: int | None = None, order: int = 4,
              outliers: bool = True, median: int | None = None) -> Conditioned:
    """Check and condition a bench table (see the module docstring and `Conditioned`).

    **Arguments:** `table` (column → array, library units, `REQUIRED`); `cutoff` [Hz] (25 Hz:
    above the wheel rotation at 160 km/h, spec §3.4); `rolling_radius` R_r [mm];
    `order` of the Butterworth filter (run forward and backward); `decimate`: keep every m-th
    row (default m = ⌊rate/(2·cutoff)⌋); `trim`: samples dropped at
    each end of a segment (the filter's edge transient; default 2·rate/cutoff, at least 5);
    `outliers`: replace the F_y and M_z samples that `noise_model` flags (default on);
    `median`: spikes replaced by the running median of this many samples on every measured
    channel first (`median_filter`; default none). The trim must cover its half-width.
    """
    cols, n_seg, m, rate = check_table(table, cutoff)
    rows, k = kept_rows(m, rate, cutoff, decimate, trim)
    if median:
        if rows[0] < median // 2:
            raise InputError(f"median filter width {median}: wider than twice the trimmed "
                             f"edge ({rows[0]} samples); trim more or narrow the window.")
        cols = median_filter(cols, median)
    Fm = filter_matrix(float(cutoff), float(rate), m, order)
    H = Fm[rows]
    # The noise of F_y and M_z from their content above the cut-off (the residual of the
    # filter), an estimate independent of the model: I − F removes the band; its growth with
    # the force and the outliers (replaced before anything is derived from the channel).
    E = np.eye(m) - Fm
    E_noise = noise_band(rate, cutoff, m, order)
    inner = np.zeros(m, bool)
    inner[rows[0]:rows[-1] + 1] = True
    noise, profile, models, flagged = {}, {}, {}, {}
    for c, unit in (("FY", 1.0), ("MZ", 1e-3)):
        clean, level, w, (a, b), bad = noise_model(cols[c], E, Fm, inner, E_noise=E_noise,
                                                   outliers=outliers,
                                                   margin=max(rows[0] // 2, 0))
        cols[c] = clean
        noise[c], profile[c] = float(level) * unit, np.asarray(w)
        models[c] = (float(a) * unit, float(b))
        flagged[c] = int(np.sum(bad))
    Dm = difference_matrix(m, 1.0 / rate)
    samples = kinematics(cols, Dm, rolling_radius * 1e-3)
    inputs = {c: np.asarray(v)[:, rows].ravel() for c, v in samples.items()}
    segment = np.repeat(np.arange(n_seg, dtype=float), len(rows))
    exc = {c: float(np.std(inputs[c])) for c in ("kappa", "delta", "phi", "gamma", "fz",
                                                   "pi_gamma_vx", "pi_gamma_bdot",
                                                   "pi_gamma2_bdot")}
    return Conditioned(samples, butterworth(cutoff, rate, order), rows, inputs,
                       (cols["FY"] @ H.T).ravel(), (cols["MZ"] @ H.T).ravel() * 1e-3,
                       rate / k, segment, exc, H, Dm, 1.0 / rate, noise, profile, models,
                       flagged, {c: noise_dof(E_noise[inner], n_seg) for c in ("FY", "MZ")})
