"""Joint identification of the vehicle's and the tyres' parameters from on-board measurements,
without the lateral forces (thesis (4-1)…(4-3)).

spec: tyre_contact_model §5.1: the vehicle's inverse dynamic model is linear in its parameters,
J_v·F = W_v·X_v (4-1), the tyre's is F = W_p·X_p (4-2), and substituting, W_p·X_p = J_v·W_v·X_v
(4-3): vehicle and tyre parameters identified together, without the dynamometric wheels'
forces. The thesis proposes it and does not do it; this module does, on the body's two
equations that the tyres' lateral forces drive:

* lateral, along the road plane's lateral direction u (the tyres' vertical loads drop out):
  Σ_i (u·y_p,i) F_y,i = m·u·f_O + u·(ω̇ × m r_G + ω × (ω × m r_G));
* yaw, about the road normal z_r through the body origin O:
  Σ_i ((P_i − O) × y_p,i)·z_r F_y,i = z_r·(I_O ω̇ + ω × I_O ω + m r_G × f_O);

with f_O the specific force at O (the inertial unit's, carried to O), ω and ω̇ the body's
angular velocity and acceleration (body frame), the whole car taken as one rigid body (the
wheels' travel relative to the body left out). Vehicle parameters X_v: the inertia I_O about
O (I_xx, I_yy, I_zz, I_xz; the car symmetric about its x–z plane) and the first moments
m·x_G, m·z_G; the mass m is given (a weighbridge): (4-3) is homogeneous, one scale must be
known. The longitudinal forces drop out of both equations when the two wheels of an axle
carry the same one (constant speed).

Each tyre's F_y,i is the reduced model (4-16…4-18) in the same coefficients as
`diffsusp.tyre.onboard` (F_pneu from δ′, φ′, γ at the load; the relaxation ODE
F_y − (L_R/ω) Ḟ_y = F_pneu integrated over the record, trapezoidal input, exact decay). The
vertical loads come from the tyres' deflection, F_z = k_t·(R_0 − r) − c_t·ṙ (r the loaded
radius from the ground plane and the carrier's pose; k_t, R_0, c_t the tyre's vertical data,
given): no wheel force is used.

The estimator: the even and the odd samples are two records of one motion whose sensor noises
are independent; the fit minimises the cross product Q = Σ r_e·r_o of their whitened residuals
(each equation by its residual σ), whose expectation is the noise-free residuals' sum of squares
— least squares would be pulled by the noise in the regressors (errors in variables: it
lengthens the relaxation to filter the inputs' noise). Q's stationarity condition is the
instrumented normal equation J_eᵀ r_o + J_oᵀ r_e = 0 (each half the other's instrument).
Levenberg–Marquardt steps on Q, accepted where Q decreases, from a start at zero (not the
truth), stop at a Newton decrement below `CROSS_TOL`. The rows: `ROWS_PER_WINDOW` per body
window. σ: the sandwich H⁻¹ (Σ_b g_b g_bᵀ) H⁻¹ (H = J_eᵀ J_o + J_oᵀ J_e) with the scores summed
over blocks of one window's rows (the window filters the noise: neighbouring rows' scores are
correlated: at one row per sample, unclustered σ came out half the spread). Consistency: the
residuals' even/odd sum against their difference (the noise is independent from one half to
the other, a misfit of the model is not), χ²/dof ≤ `onboard.MISFIT_RATIO`.

What the data pin (`DEFAULT_HELD`): the relaxation L_R acts on the axle forces through a lag of
a few ms; on a 6 s steering sine its profile of Q is flat within Q's noise (from −0.1 to −3),
and left free the fit converged on 73 % of the draws with σ undefined on the rest. It is held
(−0.5, the thesis's Table 32 at 4 kN), and every estimate is tested against it
(`JointReport.hinges`): one that moves by more than its σ when the held L_R moves by
`RELAXATION_SPREAD` is reported not determined — the torsion stiffness K_φ, which the sine
cannot tell from the relaxation (it moves by about 7 σ). The roll and pitch inertias are held
at 0 (their terms are below the yaw equation's noise; held at the car's values instead, no
estimate of the noise-free fit moved by 0.05 σ).

**Status (Monte-Carlo, benchmarks/tyre_onboard_joint.py: 100 noise draws of the 6 s record of
the 30-DOF car with `vehicle.MagicTyre`, a tyre the reduced model was not written against).**
Every fit converges and is consistent. Reported identified in every draw: the cornering
stiffnesses front and rear and the camber stiffness at the axles' loads and I_zz; against the
noise-free record's own fit (what σ covers) within 3σ in 99–100 % of the draws, spread/σ
0.76–1.04, |bias| ≤ 0.05σ; against the truth (the tyre's stiffnesses, the car's inertia) within
3σ in 98–100 %, |bias| ≤ 0.27σ (the reduced model's structure: K_δ front 0.7 % off on the
noise-free record). I_xz, m·x_G and m·z_G are calibrated alike (within 3σ in 100 %, spread/σ
0.77–0.98) but reported not determined (|x|/σ < 3.29: the car's values are near zero). K_φ is
reported not determined in every draw (above); its estimate is 11 % below the tyre's.

Units SI (m, N, s, rad, kg); F_z in kN in the load polynomials.
"""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.stats

from ..errors import InputError
from ..identify.report import IdentificationReport, consistency_from_residuals
from . import onboard
from .bench import format_report

TYRE = onboard.NAMES
VEHICLE = ("I_xx", "I_yy", "I_zz", "I_xz", "m_x_G", "m_z_G")
NAMES = TYRE + VEHICLE
"""The joint parameters: the reduced tyre model's (`onboard.NAMES`) then the vehicle's."""
_UNITS = {"b_delta_2": "N/(m·kN^2)", "b_delta_1": "N/(m·kN)", "b_delta_0": "N/m",
          "b_phi_1": "N/(rad·kN)", "b_gamma_1": "N/(rad·kN)", "b_L_2": "1/kN^2",
          "b_L_1": "1/kN", "b_L_0": "1", "I_xx": "kg·m^2", "I_yy": "kg·m^2",
          "I_zz": "kg·m^2", "I_xz": "kg·m^2", "m_x_G": "kg·m", "m_z_G": "kg·m"}
_DEFAULT = onboard.Options()
DEFAULT_HELD = {"b_L_2": 0.0, "b_L_1": 0.0, "b_L_0": -0.5, "I_xx": 0.0,
                "I_yy": 0.0}
"""What the joint identification holds by default: the relaxation L_R at −0.5 (the thesis's
Table 32 at 4 kN) and its load dependence — a steering sine does not pin it (see the module
docstring; `JointReport.hinges` flags the estimates that depend on the held value) — and the
roll and pitch inertias at 0 (their terms, the road normal's tilt times the roll and pitch
accelerations, are below the yaw equation's noise; left free, their σ is larger than
themselves). The cornering stiffness's load curvature is estimated: held at 0 against a tyre
whose K_δ is not linear in the load, it biased K_γ by 8 % and I_xz by 10 kg·m² (1.5 σ)."""
START_RELAXATION = -0.4
"""The relaxation L_R of the linear start (dimensionless, the synthetic car's sign)."""
RELAXATION_GRID = (-0.1, -0.2, -0.35, -0.6, -1.0, -1.7, -3.0)
"""The relaxations L_R at which `identify` profiles the cross-product objective for its start."""
ROWS_PER_WINDOW = 5
"""The equations' rows per body-estimate window (`onboard.Options.window_time`): denser rows
add no information (measured), sparser lose it (one row per window: σ twice as large)."""
RELAXATION_SPREAD = 0.2
"""The relative change of a held relaxation L_R against which `JointReport.hinges` tests every
estimate (spec tyre §9 item 8: one tyre's relaxation lengths in Annex G differ by about ±20 %
between its inflation pressures)."""
CROSS_TOL = 1e-8
"""Convergence: the Newton decrement gᵀ H⁻¹ g of the whitened cross-product objective (a
parameter's step of about 1e-4 of its σ)."""


class Signals(eqx.Module):
    """The joint model's inputs (`onboard.joint_signals` plus the loads): per wheel (n, 4)
    `fz_kn`, `delta_p`, `phi_p`, `gamma`, `spin`, `lat_arm`, `yaw_arm`; per instant (n, 3)
    `omega`, `omega_dot`, `f_o`, `normal`, `u`; `dt` (s), `mass` (kg)."""

    fz_kn: jax.Array
    delta_p: jax.Array
    phi_p: jax.Array
    gamma: jax.Array
    spin: jax.Array
    lat_arm: jax.Array
    yaw_arm: jax.Array
    omega: jax.Array
    omega_dot: jax.Array
    f_o: jax.Array
    normal: jax.Array
    u: jax.Array
    dt: jax.Array
    mass: jax.Array


def lateral_forces(x, sig: Signals):
    """The tyres' lateral forces F_y (n, 4) (N) of the reduced model (4-16…4-18) with the
    coefficients x[:8] (`TYRE` order), the relaxation ODE integrated over the record from its
    steady state (trapezoidal input, exact decay per step)."""
    b = x[:8]
    f = sig.fz_kn
    pneu = ((b[0] * f**2 + b[1] * f + b[2]) * sig.delta_p + b[3] * f * sig.phi_p
            + b[4] * f * sig.gamma)
    lr = b[5] * f**2 + b[6] * f + b[7]
    # L_R < 0 in this sign convention (a decaying ODE); a trial step past 0 is held stable
    tau = jnp.maximum(-lr, 1e-4) / sig.spin
    decay = jnp.exp(-sig.dt / tau)
    drive = 0.5 * (pneu[:-1] + pneu[1:])

    def step(fy, inp):
        a, p = inp
        fy = a * fy + (1.0 - a) * p
        return fy, fy

    _, rest = jax.lax.scan(step, pneu[0], (decay[:-1], drive))
    return jnp.concatenate([pneu[:1], rest])


def equations(x, sig: Signals):
    """The lateral (N) and yaw (N·m) equations' residuals (n, 2): tyre side − body side."""
    fy = lateral_forces(x, sig)
    ixx, iyy, izz, ixz, mx, mz = (x[8 + k] for k in range(6))
    z = jnp.zeros_like(mx)
    inertia = jnp.stack([jnp.stack([ixx, z, ixz]), jnp.stack([z, iyy, z]),
                         jnp.stack([ixz, z, izz])])
    mg = jnp.stack([mx, z, mz])
    w, wd, f_o = sig.omega, sig.omega_dot, sig.f_o
    body_force = (sig.mass * f_o + jnp.cross(wd, mg)
                  + jnp.cross(w, jnp.cross(w, jnp.broadcast_to(mg, w.shape))))
    lat = jnp.sum(sig.lat_arm * fy, axis=1) - jnp.sum(sig.u * body_force, axis=1)
    iw = w @ inertia
    body_moment = wd @ inertia + jnp.cross(w, iw) + jnp.cross(jnp.broadcast_to(mg, f_o.shape),
                                                              f_o)
    yaw = jnp.sum(sig.yaw_arm * fy, axis=1) - jnp.sum(sig.normal * body_moment, axis=1)
    return jnp.stack([lat, yaw], axis=1)


@eqx.filter_jit
def _iv_step(x, scale, weights, rows, sig_e, sig_o, free):
    """One instrumented Gauss–Newton step on the two half records: residuals r = [r_e; r_o],
    Jacobians J = [J_e; J_o], instruments Z = [J_o; J_e] (the other half's Jacobian at the
    same instants: its noise is independent of r's), Δ = −(Zᵀ J)⁻¹ Zᵀ r. Returns the new x,
    the residuals (2, rows, 2), J and Z (scaled parameters)."""
    free = np.asarray(free)

    def full(theta):
        return x.at[free].set(theta * scale)

    def res(theta, sig):
        return equations(full(theta), sig)[rows] * weights

    theta = x[free] / scale
    r = jnp.stack([res(theta, sig_e), res(theta, sig_o)])
    je = jax.jacfwd(lambda t: res(t, sig_e))(theta).reshape(-1, theta.size)
    jo = jax.jacfwd(lambda t: res(t, sig_o))(theta).reshape(-1, theta.size)
    J = jnp.concatenate([je, jo])
    Z = jnp.concatenate([jo, je])
    step = jnp.linalg.solve(Z.T @ J, Z.T @ r.reshape(-1))
    return full(theta - step), r, J, Z


def _cross(x, scale, weights, rows, sig_e, sig_o, free):
    """The cross-product objective Q = Σ r_e·r_o of the two half records' whitened residuals,
    its gradient g = J_eᵀ r_o + J_oᵀ r_e and its Gauss–Newton Hessian H = J_eᵀ J_o + J_oᵀ J_e
    (scaled parameters). The halves' noises are independent, so E[Q] is the noise-free
    residuals' sum of squares: its minimum is not pulled by the noise in the regressors
    (least squares would shorten the noise by lengthening the relaxation)."""
    _, r, J, Z = _iv_step(x, scale, weights, rows, sig_e, sig_o, free)
    r, J, Z = np.asarray(r), np.asarray(J), np.asarray(Z)
    H = Z.T @ J
    return float(np.sum(r[0] * r[1])), Z.T @ r.reshape(-1), 0.5 * (H + H.T)


def _decrement(g, H):
    """gᵀ H⁻¹ g, or inf where H is not positive definite."""
    try:
        c = np.linalg.cholesky(H)
    except np.linalg.LinAlgError:
        return np.inf
    v = np.linalg.solve(c, g)
    return float(v @ v)


def _minimise_cross(x, scale, weights, rows, sig_e, sig_o, free, lr_i, max_steps):
    """Minimise `_cross`'s Q: the start's relaxation L_R chosen on `RELAXATION_GRID` by the
    profile of Q (Q is quadratic in every other free parameter: one Newton step minimises it
    there), then Levenberg–Marquardt steps on Q, accepted where Q decreases, until the Newton
    decrement gᵀ H⁻¹ g is below `CROSS_TOL` (a step of 1e-4 σ) with H positive definite.
    Returns (x, converged, steps)."""
    fmask = np.asarray(free)
    sc = np.asarray(scale)

    def move(x, d):
        return x.at[fmask].add(jnp.asarray(d * sc))

    def profile(x):
        q, g, H = _cross(x, scale, weights, rows, sig_e, sig_o, free)
        keep = np.arange(g.size) != lr_i
        try:
            d = np.zeros(g.size)
            d[keep] = -np.linalg.solve(H[np.ix_(keep, keep)], g[keep])
        except np.linalg.LinAlgError:
            return np.inf, x
        x = move(x, d)
        return _cross(x, scale, weights, rows, sig_e, sig_o, free)[0], x

    if lr_i is not None:
        i = TYRE.index("b_L_0")
        trials = [profile(x.at[i].set(v)) for v in RELAXATION_GRID]
        x = min(trials, key=lambda t: t[0])[1]
    q, g, H = _cross(x, scale, weights, rows, sig_e, sig_o, free)
    lam = 1e-3
    for k in range(max_steps):
        if _decrement(g, H) < CROSS_TOL:
            return x, True, k
        D = np.diag(np.maximum(np.abs(np.diag(H)), 1e-12 * np.abs(np.diag(H)).max()))
        try:
            np.linalg.cholesky(H + lam * D)
        except np.linalg.LinAlgError:
            lam *= 10.0
            continue
        d = -np.linalg.solve(H + lam * D, g)
        xn = move(x, d)
        qn, gn, Hn = _cross(xn, scale, weights, rows, sig_e, sig_o, free)
        if np.isfinite(qn) and qn <= q:
            x, q, g, H, lam = xn, qn, gn, Hn, max(lam / 10.0, 1e-9)
        else:
            lam *= 10.0
            if lam > 1e12:
                break
    return x, _decrement(g, H) < CROSS_TOL, max_steps


@dataclasses.dataclass(frozen=True)
class JointReport(IdentificationReport):
    """The joint vehicle + tyre identification ((4-1)…(4-3), `identify`): the estimates in
    `NAMES` order, their covariance, the equations' residuals (n_rows, 2) and residual σ, the
    Correvit delay removed (s), and the consistency. As the shared report
    (`IdentificationReport`): a coefficient is determined when |x|/σ ≥ 3.29
    (`onboard.SIGNIFICANCE`) and the fit is consistent."""

    x: np.ndarray
    covariance: np.ndarray
    residual: np.ndarray
    residual_sigma: np.ndarray
    delay: float
    mass: float
    converged: bool
    consistency: object = None
    held_mask_: np.ndarray | None = None
    relaxation_shift: np.ndarray | None = None
    """Per parameter (`NAMES`), how far the estimate moves when the held relaxation L_R moves
    by `RELAXATION_SPREAD` of itself (None: L_R estimated); a parameter that moves by more than
    its σ is not determined (it hinges on the held value, not on the data)."""

    family = "onboard_joint"

    @property
    def names(self):
        return NAMES

    @property
    def estimates(self):
        return np.asarray(self.x, float)

    @property
    def sigmas(self):
        s = np.sqrt(np.abs(np.diagonal(self.covariance)))
        return np.where(self.held, np.nan, s)

    @property
    def sigma_pct(self):
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.x != 0, 100.0 * self.sigmas / np.abs(self.x), np.nan)

    @property
    def estimate_units(self):
        return tuple(_UNITS[n] for n in NAMES)

    @property
    def held(self):
        if self.held_mask_ is None:
            return np.zeros(len(NAMES), bool)
        return np.asarray(self.held_mask_, bool)

    @property
    def identifiable(self):
        crit = _critical()
        with np.errstate(divide="ignore", invalid="ignore"):
            z2 = (self.estimates / self.sigmas) ** 2
        return np.isfinite(z2) & (z2 >= crit) & ~self.held & ~self.hinges

    @property
    def hinges(self):
        """Per parameter: moves by more than its σ with the held relaxation (`relaxation_shift`)."""
        if self.relaxation_shift is None:
            return np.zeros(len(NAMES), bool)
        with np.errstate(invalid="ignore"):
            return np.abs(self.relaxation_shift) > self.sigmas

    @property
    def reasons(self):
        crit = np.sqrt(_critical())
        out = []
        for i in range(len(NAMES)):
            if self.held[i]:
                out.append(f"held at {self.estimates[i]:g}")
            elif not self.converged:
                out.append("the fit did not converge")
            elif self.hinges[i]:
                out.append(f"not determined: moves by "
                           f"{abs(self.relaxation_shift[i]) / self.sigmas[i]:.2g} sigma when "
                           f"the held L_R moves by {100 * RELAXATION_SPREAD:g} %")
            elif not self.identifiable[i]:
                out.append(f"not determined: |x|/sigma "
                           f"{abs(self.estimates[i]) / self.sigmas[i]:.2g} < {crit:.3g}")
            else:
                out.append("")
        return tuple(out)

    @property
    def combinations(self):
        """Per estimate that hinges on the held relaxation (`hinges`): its value as a function
        of L_R, linear through the estimate and the refit at the moved L_R."""
        if self.relaxation_shift is None:
            return ()
        lr = float(self.estimates[TYRE.index("b_L_0")])
        slope = np.asarray(self.relaxation_shift) / (RELAXATION_SPREAD * lr)
        return tuple(f"{n} = {self.estimates[i]:.6g} + {slope[i]:.4g}·(L_R − ({lr:g}))"
                     for i, n in enumerate(NAMES) if self.hinges[i])

    @property
    def residuals(self):
        return {}

    def table(self) -> str:
        head = (f"joint vehicle + tyre identification (4-3), mass {self.mass:g} kg given, "
                f"Correvit delay removed {1000 * self.delay:.1f} ms, {len(self.residual)} "
                f"instants; residual sigma lateral {self.residual_sigma[0]:.3g} N, yaw "
                f"{self.residual_sigma[1]:.3g} N·m")
        lines = [head, format_report(self)]  # value, σ, status and reason, the verdict
        lines += [f"hinges on the held L_R: {c}" for c in self.combinations]
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {"mass": self.mass, "delay_s": self.delay, "converged": self.converged,
                "estimates": dict(zip(NAMES, self.estimates.tolist(), strict=True)),
                "sigmas": dict(zip(NAMES, self.sigmas.tolist(), strict=True)),
                "residual_sigma": self.residual_sigma.tolist(),
                "consistency": None if self.consistency is None
                else self.consistency.summary()}


def _critical():
    return float(scipy.stats.chi2.isf(onboard.SIGNIFICANCE, 1))


def signals(data: dict, *, mass: float, tyre_vertical, options=_DEFAULT,
            delay: float = 0.0, kinematics=None) -> tuple[Signals, np.ndarray]:
    """The joint model's `Signals` of a checked record and its per-instant validity.
    `tyre_vertical` = (k_t N/m, R_0 m, c_t N·s/m): F_z = k_t (R_0 − r) − c_t ṙ."""
    k_t, r_0, c_t = (float(v) for v in tyre_vertical)
    js = onboard.joint_signals(data, options, correvit_delay_s=delay, kinematics=kinematics)
    fz = (k_t * (r_0 - js["radius"]) - c_t * js["radius_rate"]) / 1000.0
    t = np.asarray(data["time"])
    sig = Signals(fz, js["delta_p"], js["phi_p"], js["gamma"], js["spin"], js["lat_arm"],
                  js["yaw_arm"], js["omega"], js["omega_dot"], js["f_o"], js["normal"],
                  js["u"], jnp.asarray(t[1] - t[0]), jnp.asarray(float(mass)))
    return sig, np.asarray(js["valid"])


def identify(data: dict, *, mass: float, tyre_vertical, options=_DEFAULT,
             delay: float | None = None, kinematics=None, stride: int | None = None,
             held: dict | None = None, max_steps: int = 200) -> JointReport:
    """The joint vehicle + tyre identification (4-1…4-3; see the module docstring) on an
    on-board record (`vehicle.measure`'s channels; the wheel forces are not used): `mass` the
    car's mass (kg), `tyre_vertical` (k_t N/m, R_0 m, c_t N·s/m) the tyres' vertical data,
    `delay` the Correvit's (s; None: estimated as `onboard.identify` does), `kinematics` the
    30-DOF model's K&C tables (`vehicle_kc`) or None, `stride` samples between the equations'
    rows (default one window); `held` {name: value} the parameters held (default
    `DEFAULT_HELD`), the others estimated.

    **Returns:** `JointReport`. **Raises:** `InputError` for a bad record or mass."""
    if not (np.isfinite(mass) and mass > 0):
        raise InputError(f"mass {mass!r}: the car's mass in kg, > 0.")
    tv = np.asarray(tyre_vertical, float)
    if tv.shape != (3,) or not np.all(np.isfinite(tv)) or tv[0] <= 0 or tv[1] <= 0:
        raise InputError("tyre_vertical must be (k_t > 0 N/m, R_0 > 0 m, c_t N·s/m).")
    held = DEFAULT_HELD if held is None else dict(held)
    unknown = [k for k in held if k not in NAMES]
    if unknown:
        raise InputError(f"held: unknown parameter(s) {unknown}; the joint model's: "
                         f"{', '.join(NAMES)}.")
    data = onboard.check(data, options)
    if delay is None:
        delay = onboard.estimate_delay(data, options)[0]
    # the even and the odd samples: two records of one motion with independent noise, the
    # instruments of each other (as `onboard.iv_fit`): the lateral forces are a filter of
    # measured inputs, and least squares would shorten the noise by lengthening the relaxation
    hv = onboard.halves(data)
    parts = [signals({k: (v[h] if k in onboard.PER_SAMPLE else v) for k, v in hv.items()},
                     mass=mass, tyre_vertical=tv, options=options, delay=delay,
                     kinematics=kinematics) for h in (0, 1)]
    (sig_e, valid_e), (sig_o, valid_o) = parts
    valid = valid_e & valid_o
    t = np.asarray(hv["time"][0])
    half = max(int(round(options.window_time / (t[1] - t[0]) / 2)), 1)
    stride = stride or max(int(round((2 * half + 1) / ROWS_PER_WINDOW)), 1)
    block = max(-(-(2 * half + 1) // stride), 1)
    rows = np.arange(2 * half + 1, len(t) - 2 * half - 1, stride)
    rows = rows[valid[rows]]
    if rows.size < 2 * len(NAMES):
        raise InputError(f"{rows.size} valid instants: too few for {len(NAMES)} parameters; "
                         "give a longer record.")
    weights = jnp.array([1.0 / 50.0, 1.0 / 50.0])
    free = tuple(n not in held for n in NAMES)
    base = jnp.asarray([float(held.get(n, 0.0)) for n in NAMES])
    fmask = np.asarray(free)
    lr_i = int(np.flatnonzero(fmask).tolist().index(TYRE.index("b_L_0"))) \
        if fmask[TYRE.index("b_L_0")] else None
    # the start: the held values, the free parameters at 0 but a free L_R at
    # `START_RELAXATION`; the free parameters scaled by their Jacobian columns' norms
    x0 = base if lr_i is None else base.at[TYRE.index("b_L_0")].set(START_RELAXATION)
    _, _, J0, _ = _iv_step(x0, jnp.ones(int(fmask.sum())), weights, rows, sig_e, sig_o, free)
    norms = np.linalg.norm(np.asarray(J0), axis=0)
    sc = np.where(norms > 0, 1.0 / np.where(norms > 0, norms, 1.0), 1.0)
    scale = jnp.asarray(sc)
    # every free parameter but L_R enters linearly: Q is quadratic in them; the equations
    # weighted by their residual σ at a first fit, then the fit again
    x0, *_ = _minimise_cross(x0, scale, weights, rows, sig_e, sig_o, free, lr_i, max_steps)
    _, r0, _, _ = _iv_step(x0, scale, weights, rows, sig_e, sig_o, free)
    rs = np.sqrt(np.mean(np.asarray(r0) ** 2, axis=(0, 1))) / np.asarray(weights)
    weights = jnp.asarray(1.0 / rs)
    x, converged, steps = _minimise_cross(x0, scale, weights, rows, sig_e, sig_o, free, lr_i,
                                          max_steps)
    shift = None
    if lr_i is None and held.get("b_L_0", 0.0) != 0.0:
        # every free parameter enters linearly once L_R is held: Q is quadratic in them, one
        # Newton step from the estimate is the refit at the moved L_R
        i = TYRE.index("b_L_0")
        moved = x.at[i].multiply(1.0 + RELAXATION_SPREAD)
        _, g1, H1 = _cross(moved, scale, weights, rows, sig_e, sig_o, free)
        shift = np.zeros(len(NAMES))
        try:
            shift[fmask] = -np.linalg.solve(H1, g1) * sc
        except np.linalg.LinAlgError:
            shift[fmask] = np.inf
    _, r, J, Z = _iv_step(x, scale, weights, rows, sig_e, sig_o, free)
    r, x, J, Z = np.asarray(r), np.asarray(x), np.asarray(J), np.asarray(Z)
    rs = np.sqrt(np.mean(r**2, axis=(0, 1))) / np.asarray(weights)
    # sandwich (Zᵀ J)⁻¹ (Σ_t g_t g_tᵀ) (Jᵀ Z)⁻¹, clustered by instant (both halves, both
    # equations: they share the body's noise)
    white = r.reshape(-1)
    p = int(fmask.sum())
    try:
        bread = np.linalg.inv(Z.T @ J)
    except np.linalg.LinAlgError:
        bread, converged = np.full((p, p), np.nan), False
    g = (Z * white[:, None]).reshape(2, len(rows), 2, p).sum(axis=(0, 2))
    meat = g.T @ g
    # and by blocks of one window's rows: the body estimates filter the noise over a window,
    # so neighbouring rows' scores are correlated (at one row per sample, unclustered σ came
    # out half the spread)
    m = -(-g.shape[0] // block) * block
    g = np.concatenate([g, np.zeros((m - g.shape[0], p))]).reshape(-1, block, p).sum(axis=1)
    meat = g.T @ g
    n_cl = g.shape[0]
    n = white.size
    cov_s = bread @ meat @ bread.T * (n_cl / (n_cl - 1) * (n - 1) / max(n - p, 1))
    rw = r.reshape(2, len(rows), 2)
    r = r[0] / np.asarray(weights)
    cov = np.zeros((len(NAMES), len(NAMES)))
    cov[np.ix_(fmask, fmask)] = cov_s * np.outer(sc, sc)
    # the Correvit delay's σ is not carried in (`onboard.identify` does it); the report says
    # the delay removed
    # the halves' difference holds the noise, their sum the noise and a misfit of the model
    noise = np.sqrt(np.mean((rw[0] - rw[1]) ** 2, axis=0) / 2.0)
    white = (rw[0] + rw[1]) / np.sqrt(2.0) / noise
    con = consistency_from_residuals(
        [white.T], [white.size], p, ("lateral", "yaw"), measurements=("equations",),
        note=("the even/odd half-records' residuals, their sum against their difference; "
              f"limit chi2/dof {onboard.MISFIT_RATIO:g}"))
    con = dataclasses.replace(con, critical=onboard.MISFIT_RATIO * con.dof,
                              consistent=bool(np.isfinite(con.chi2)
                                              and con.chi2 <= onboard.MISFIT_RATIO * con.dof))
    return JointReport(x, cov, r, rs, float(delay), float(mass),
                       bool(converged), con, ~fmask, shift)


def truth(vehicle) -> dict:
    """The synthetic car's (`diffsusp.tyre.vehicle.Vehicle`) vehicle parameters in `VEHICLE`
    order, of the whole car (body and the four unsprung point masses at their design
    position) about the body origin: dict name → value, and the mass."""
    r = np.asarray(vehicle.corners, float)
    mu = float(vehicle.unsprung)
    ixx, iyy, izz = np.asarray(vehicle.inertia, float)
    inertia = np.diag([ixx, iyy, izz]) + mu * (np.sum(r * r) * np.eye(3) - r.T @ r)
    return {"I_xx": inertia[0, 0], "I_yy": inertia[1, 1], "I_zz": inertia[2, 2],
            "I_xz": inertia[0, 2], "m_x_G": mu * r[:, 0].sum(), "m_z_G": mu * r[:, 2].sum(),
            "mass": float(vehicle.mass) + 4 * mu}


__all__ = ["CROSS_TOL", "DEFAULT_HELD", "JointReport", "NAMES", "RELAXATION_GRID",
           "RELAXATION_SPREAD", "ROWS_PER_WINDOW", "START_RELAXATION", "Signals", "TYRE",
           "VEHICLE", "equations", "identify", "lateral_forces", "signals", "truth"]
