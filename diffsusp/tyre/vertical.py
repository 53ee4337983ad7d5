"""The Magic Formula's vertical model: loaded radius, deflection, vertical stiffness, effective
rolling radius and wheel spin (MF 5.2 / 6.1 / 6.2 `.tir` files).

spec: tyre §7 C (the MF 6.2 vertical model). Equations: Pacejka, *Tyre and Vehicle
Dynamics* (3rd ed., 2012) Appendix 3 (A3.2–A3.3) and Besselink, Schmeitz & Pacejka, "An improved
Magic Formula/Swift tyre model that can handle inflation pressure changes" (VSD 48, 2010), eqs.
(1)–(8), for MF 5.2/6.1; the MF-Swift 6.2 equation manual's vertical force for FITTYP 62, in the
form MFeval (M. Furlan Tassara) evaluates it. Library units: lengths mm, speeds mm/s, Ω rad/s,
forces N, stiffness N/mm, pressure Pa (`MagicFormula6.from_tir` converts VERTICAL_STIFFNESS
N/m → N/mm, WIDTH m → mm and Q_CAM2 1/m → 1/mm).

**Free and effective radius** (all versions):
- R_Ω = R0·(q_re0 + q_V1·(Ω·R0/V0)²)  (free radius grown by the centrifugal term);
- R_e = R_Ω − (F_z0/C_z)·(D_reff·atan(B_reff·F_z/F_z0) + F_reff·F_z/F_z0), C_z = C_z0·(1 +
  p_Fz1·dp_i)  (Besselink (7));
- Ω from the forward speed and the slip ratio: κ = (Ω·R_e − V_x)/V_x, so Ω = V_x(1 + κ)/R_e(Ω),
  a fixed point solved by 6 substitutions (R_e depends on Ω only through q_V1; the map contracts
  by about 2·q_V1·(ΩR0/V0)² ≈ 1e-3).

**Vertical force from the loaded radius R_l** (the model's explicit direction):
- MF 5.2 / 6.1: ρ = max(R_Ω − R_l, 0), F_z = f_corr·(q_Fz1·ρ/R0 + q_Fz2·(ρ/R0)²)·F_z0 with
  f_corr = (1 + q_V2·|Ω|·R0/V0 − (q_Fcx·F_x/F_z0)² − (q_Fcy·F_y/F_z0)²)·(1 + p_Fz1·dp_i);
- MF 6.2 adds camber and the camber–side-force interaction: ρ_z = max(ρ_zfr + ρ_zγ, 1e-12 mm)
  with ρ_zfr = max(R_Ω − R_l, 0), ρ_zγ = ((q_cam1·R_l + q_cam2·R_l²)/(q_cam1·R_Ω +
  q_cam2·R_Ω²))²·(r_tw/8)·|tan γ| − q_cam3·ρ_zfr·|γ|, r_tw = (1.075 − 0.5·ASPECT_RATIO)·WIDTH,
  and the side-force term ((ρ_z/R0)^{q_Fcy2}·q_Fcy·(F_y − S_Fyγ)/F_z0)² with S_Fyγ = (q_Fys1 +
  q_Fys2·R_l/R_Ω + q_Fys3·(R_l/R_Ω)²)·γ;
- q_Fz1 = √((C_z0·R0/F_z0)² − 4·q_Fz2) (MFeval; the file's Q_FZ1 is not read), which makes the
  stiffness at F_z = F_z0 (no other effect) exactly C_z0.

**Loaded radius from the load** (`loaded_radius`): the root R_l of F_z(R_l) = F_z, by Newton's
method from R_Ω − F_z/C_z0 (8 steps, each kept at ρ ≥ 0; 4 reach 1e-14 on the shipped files
wherever a root exists), then one Newton step taken with the converged point held constant, so
that derivatives are those of the implicit function (dR_l/dθ = −(∂F_z/∂θ)/(∂F_z/∂R_l)), exact
at the root. `VerticalState.converged` says where |F_z(R_l) − F_z| ≤ 1e-8·F_z0. In MF 6.2 there
may be no root: the camber deflection ρ_zγ keeps ρ_z > 0 at R_l = R_Ω, so F_z(R_l) has a positive
minimum at a large camber (shipped 6.2 file: 732 N at γ = −0.105 rad with F_x = 5.3 kN), and a
lighter load cannot be carried (0.6 % of random points with F_z < 930 N, |F_x|, |F_y| ≤ 8 kN,
|γ| ≤ 0.15 rad); those points are returned with `converged` False, not silently. MF 5.2/6.1
could use the quadratic's closed form; the same solver is used for every version (the tests
check it against the closed form).

**Not modelled** (documented choices): bottoming (BOTTOM_OFFST, BOTTOM_STIFF), the MF 6.1 paper's
q_Fz3·γ² term (absent from the shipped files and not in MFeval), Q_CAM (6.1 camber stiffness
reduction; MFeval ignores it too), the contact-patch dimensions, and the F_z limits (FZMIN/FZMAX:
the vertical model is evaluated at the given load).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike

__all__ = ["VerticalState", "effective_rolling_radius", "free_radius", "loaded_radius",
           "spin", "vertical_force"]

_NEWTON_STEPS = 8
_SPIN_STEPS = 6


class VerticalState(NamedTuple):
    """The vertical model at one load (library units).

    `rl` loaded radius [mm]; `deflection` ρ (MF 6.2: ρ_z, camber included) [mm]; `stiffness`
    the tangent vertical stiffness −∂F_z/∂R_l [N/mm]; `secant` F_z/ρ [N/mm] (MFeval's C_z output);
    `re` effective rolling radius [mm]; `romega` free radius R_Ω [mm]; `omega` wheel spin [rad/s];
    `converged`: the load is reached (module docstring: there may be no root).
    """

    rl: Array
    deflection: Array
    stiffness: Array
    secant: Array
    re: Array
    romega: Array
    omega: Array
    converged: Array


def _c(model):
    c = model.coefficients
    cz0 = c["VERTICAL_STIFFNESS"]
    try:
        bad = float(cz0) <= 0.0
    except (TypeError, jax.errors.ConcretizationTypeError):  # traced: cannot check
        bad = False
    if bad:
        raise ValueError("the vertical model needs VERTICAL_STIFFNESS > 0 [VERTICAL] in the "
                         ".tir file")
    return c


def _dpi(model, c, pressure):
    if model.version == "5.2":
        return 0.0
    p = c["INFLPRES"] if pressure is None else jnp.asarray(pressure, dtype=float)
    return (p - c["NOMPRES"]) / c["NOMPRES"]


def free_radius(model, omega: ArrayLike) -> Array:
    """R_Ω = R0·(q_re0 + q_V1·(Ω·R0/V0)²) [mm] at wheel spin `omega` [rad/s]."""
    c = model.coefficients
    R0 = c["UNLOADED_RADIUS"]
    return R0 * (c["Q_RE0"] + c["Q_V1"] * (jnp.asarray(omega, dtype=float) * R0
                                             / c["LONGVL"]) ** 2)


def effective_rolling_radius(model, fz: ArrayLike, omega: ArrayLike,
                             pressure: ArrayLike | None = None) -> Array:
    """R_e [mm] at load `fz` [N] (negative → 0) and spin `omega` [rad/s] (Besselink (7))."""
    c = _c(model)
    fz = jnp.maximum(jnp.asarray(fz, dtype=float), 0.0)
    Fz0 = c["FNOMIN"]
    cz = c["VERTICAL_STIFFNESS"] * (1.0 + c["PFZ1"] * _dpi(model, c, pressure))
    return free_radius(model, omega) - (Fz0 / cz) * (
        c["DREFF"] * jnp.arctan(c["BREFF"] * fz / Fz0) + c["FREFF"] * fz / Fz0)


def spin(model, fz: ArrayLike, vx: ArrayLike | None = None, kappa: ArrayLike = 0.0,
         pressure: ArrayLike | None = None) -> Array:
    """Wheel spin Ω [rad/s] that gives slip ratio `kappa` at forward speed `vx` [mm/s] (default
    LONGVL): Ω = V_x(1 + κ)/R_e(Ω), by fixed-point substitution (module docstring)."""
    c = _c(model)
    vx = c["LONGVL"] if vx is None else jnp.asarray(vx, dtype=float)
    v = vx * (1.0 + jnp.asarray(kappa, dtype=float))
    omega = v / c["UNLOADED_RADIUS"]
    for _ in range(_SPIN_STEPS):
        omega = v / effective_rolling_radius(model, fz, omega, pressure)
    return omega


def vertical_force(model, rl: ArrayLike, *, fx: ArrayLike = 0.0, fy: ArrayLike = 0.0,
                   gamma: ArrayLike = 0.0, omega: ArrayLike = 0.0,
                   pressure: ArrayLike | None = None) -> tuple[Array, Array]:
    """(F_z [N], deflection [mm]) at loaded radius `rl` [mm], with forces `fx`, `fy` [N],
    inclination `gamma` [rad] (MF 6.2 only), spin `omega` [rad/s] and `pressure` [Pa]: the
    module docstring's equations for the model's version. Elementwise."""
    c = _c(model)
    rl = jnp.asarray(rl, dtype=float)
    fx, fy, gamma, omega = (jnp.asarray(x, dtype=float) for x in (fx, fy, gamma, omega))
    R0, V0, Fz0 = c["UNLOADED_RADIUS"], c["LONGVL"], c["FNOMIN"]
    q_fz2 = c["Q_FZ2"]
    q_fz1 = jnp.sqrt((c["VERTICAL_STIFFNESS"] * R0 / Fz0) ** 2 - 4.0 * q_fz2)
    romega = free_radius(model, omega)
    press = 1.0 + c["PFZ1"] * _dpi(model, c, pressure)
    speed = 1.0 + c["Q_V2"] * (R0 / V0) * jnp.abs(omega) - (c["Q_FCX"] * fx / Fz0) ** 2
    rho_fr = jnp.maximum(romega - rl, 0.0)
    if model.version == "6.2":
        ratio = rl / romega
        sfyg = (c["Q_FYS1"] + c["Q_FYS2"] * ratio + c["Q_FYS3"] * ratio**2) * gamma
        num = c["Q_CAM1"] * rl + c["Q_CAM2"] * rl**2
        den = c["Q_CAM1"] * romega + c["Q_CAM2"] * romega**2
        safe = jnp.where(den == 0.0, 1.0, den)
        rtw = (1.075 - 0.5 * c["ASPECT_RATIO"]) * c["WIDTH"]
        rho_g = (jnp.where(den == 0.0, 0.0, (num / safe) ** 2) * (rtw / 8.0)
                 * jnp.abs(jnp.tan(gamma)) - c["Q_CAM3"] * rho_fr * jnp.abs(gamma))
        rho = jnp.maximum(rho_fr + rho_g, 1e-12)
        x = rho / R0
        side = (x ** c["Q_FCY2"] * c["Q_FCY"] * (fy - sfyg) / Fz0) ** 2
    else:
        rho = rho_fr
        x = rho / R0
        side = (c["Q_FCY"] * fy / Fz0) ** 2
    fz = (speed - side) * press * (q_fz1 * x + q_fz2 * x * x) * Fz0
    return fz, rho


def loaded_radius(model, fz: ArrayLike, *, fx: ArrayLike = 0.0, fy: ArrayLike = 0.0,
                  gamma: ArrayLike = 0.0, kappa: ArrayLike = 0.0, vx: ArrayLike | None = None,
                  omega: ArrayLike | None = None, pressure: ArrayLike | None = None
                  ) -> VerticalState:
    """The vertical model at load `fz` [N] (≥ 0): the loaded radius solving
    `vertical_force(R_l) = fz` (module docstring), its deflection and stiffnesses, the effective
    rolling radius and the spin. `omega` [rad/s] default: `spin(model, fz, vx, kappa)`. Other
    arguments as `vertical_force`. Differentiable in every input and coefficient (implicit
    function at the root)."""
    _c(model)  # VERTICAL_STIFFNESS > 0
    fz = jnp.maximum(jnp.asarray(fz, dtype=float), 0.0)
    if omega is None:
        omega = spin(model, fz, vx, kappa, pressure)
    omega = jnp.asarray(omega, dtype=float)
    shape = jnp.broadcast_shapes(*(jnp.shape(x) for x in (fz, fx, fy, gamma, omega)))
    romega = free_radius(model, omega)

    def residual_fn(m, fz, fx, fy, gamma, omega):
        def f(rl):
            return vertical_force(m, rl, fx=fx, fy=fy, gamma=gamma, omega=omega,
                                  pressure=pressure)[0] - fz
        return f

    frozen = jax.lax.stop_gradient((model, fz, fx, fy, gamma, omega))
    g = residual_fn(*frozen)
    cz0 = frozen[0].coefficients["VERTICAL_STIFFNESS"]
    romega_sg = jax.lax.stop_gradient(romega)

    def newton(_, rl):
        value, slope = jax.jvp(g, (rl,), (jnp.ones_like(rl),))
        slope = jnp.where(slope < 0.0, slope, -cz0)
        return jnp.minimum(rl - value / slope, romega_sg)

    start = jnp.broadcast_to(romega_sg - frozen[1] / cz0, shape)
    rl = jax.lax.stop_gradient(jax.lax.fori_loop(0, _NEWTON_STEPS, newton, start))
    value, slope = jax.jvp(residual_fn(model, fz, fx, fy, gamma, omega), (rl,),
                           (jnp.ones_like(rl),))
    rl = rl - value / jax.lax.stop_gradient(slope)
    fz_check, rho = vertical_force(model, rl, fx=fx, fy=fy, gamma=gamma, omega=omega,
                                   pressure=pressure)
    stiffness = -slope
    secant = jnp.where(rho > 1e-9, fz_check / jnp.where(rho > 1e-9, rho, 1.0), stiffness)
    re = effective_rolling_radius(model, fz, omega, pressure)
    converged = jnp.abs(fz_check - fz) <= 1e-8 * model.coefficients["FNOMIN"]
    return VerticalState(rl, rho, stiffness, secant, re, jnp.broadcast_to(romega, shape),
                         jnp.broadcast_to(omega, shape), converged)
