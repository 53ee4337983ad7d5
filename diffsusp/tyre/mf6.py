"""Magic Formula 5.2 / 6.1 / 6.2 steady-state tyre forces from `.tir` property files.

spec: tyre §7 C. The equations are those of Pacejka, *Tyre and
Vehicle Dynamics* (3rd ed., 2012) §4.3.2 (4.E1–4.E78) for MF 6.1/6.2 and the MF-Tyre 5.2
equation manual for FITTYP 5/6, with the deviations that TNO's MF-Tyre adopts and MFeval
reproduces (each listed below: "deviation"). The .tir axis system is ISO-W (TYDEX W).

**Units.** Library units at this interface: F_z [N], κ [-], α [rad], γ [rad], V_x [mm/s],
pressure [Pa]; forces [N], moments [N·mm]. `from_tir` converts the file's SI values at the
boundary (UNLOADED_RADIUS m → mm, LONGVL and VXLOW m/s → mm/s; every other coefficient is
dimensionless or already N, rad, Pa); `to_tir` converts back.

**Modes** (the MF-Tyre USE_MODE switches as MFeval's useMode 1xx/2xx, x1x/x2x):
- `limits=True` (default, MF-Tyre's "limit checks on"): inputs saturated at the file's ranges
  (FZMAX, KPUMIN/KPUMAX, ALPMIN/ALPMAX, CAMMIN/CAMMAX, PRESMIN/PRESMAX; a missing range is no
  limit), F_z < 0 set to 0, the curvature factors E_x, E_y, E_t, E_xα, E_yκ clipped at 1, and
  F_z raised to FZMIN in D_t and D_r (M_z) only; below FZMIN, M_x uses F_z·(F_z/FZMIN)² and M_y
  F_z·(F_z/FZMIN) (MF-Tyre's low-load reductions). `check_limits` reports (warns about) the
  inputs that will be saturated. `evaluate` called eagerly (concrete inputs and model) announces
  its own saturation once per call (one `ModelWarning` naming each saturated input, its count and
  first row); traced (under `jax.jit`, `vmap`, `grad`: any input or coefficient
  a tracer) it checks nothing and saturates silently.
- `alpha_star=False` (default, as MF-Tyre): α* = α and γ* = γ; True: α* = tan α, γ* = sin γ
  (the book's (4.E3)–(4.E4)).
- `turn_slip=None` (default): no turn slip, all ζ = 1 (ζ0 = 1); no low-speed model: the
  formulas assume V_x > VXLOW > 0.

**Turn slip** (MF 6.1/6.2, `evaluate(..., turn_slip=φ_t)`; Pacejka 2012 §4.3.3, (4.75)–(4.106),
coefficients of [TURNSLIP_COEFFICIENTS]): spin φ = φ_t·cos α + (1 − ε_γ)·Ω·sin γ·|cos α|/V_x
(the book's (4.76) with ψ̇ = −φ_t·V_c and V'_c = V_x/|cos α|; MFeval's φ_t·cos α; Ω from
`vertical.spin` unless given), ε_γ = p_εγφ1(1 + p_εγφ2·df_z). ζ1 = cos atan(B_xφ·R0·φ) on D_x,
B_xφ = p_Dxφ1(1 + p_Dxφ2·df_z)·cos atan(p_Dxφ3·κ); ζ2 = cos atan(B_yφ(R0|φ| + p_Dyφ4√(R0|φ|)))
on D_y, S_Vy, S_Vyγ and the D_r load term, B_yφ = p_Dyφ1(1 + p_Dyφ2·df_z)·cos atan(p_Dyφ3·tan α);
ζ3 = cos atan(p_Kyφ1·R0²φ²) on K_yα; ζ0 = 0 and ζ4 = 1 + S_Hyφ − S_Vyγ/K'_yα in S_Hy, S_Hyφ =
D_Hyφ·sin(C_Hyφ·atan(B_Hyφ·R0φ − E_Hyφ(B_Hyφ·R0φ − atan(B_Hyφ·R0φ)))), C_Hyφ = p_Hyφ1, D_Hyφ =
p_Hyφ2 + p_Hyφ3·df_z, E_Hyφ = p_Hyφ4 (≤ 1 with limits), B_Hyφ = K_yRφ0/(C_Hyφ·D_Hyφ·K'_yα0),
K_yRφ0 = K_yγ0/(1 − ε_γ) (K_yα0: K_yα at γ = 0, with ζ3); ζ5 = cos atan(q_Dtφ1·R0·φ) on D_t;
ζ6 = cos atan(q_Brφ1·R0·φ) on B_r; ζ8 − 1 = D_rφ = D_Drφ·sin(C_Drφ·atan(B_Drφ·R0φ)) added to D_r
(whose camber term is multiplied by ζ0 = 0), C_Drφ = q_Drφ1, D_Drφ = M_zφ∞/sin(πC_Drφ/2), M_zφ∞ =
max(q_Crφ1·|μ_y|·R0·F_z·√(F_z/F'_z0)·λ_Mφ, 1e-6), B_Drφ = K_zγr0/(C_Drφ·D_Drφ(1 − ε_γ));
ζ7 = C_r = (2/π)·arccos(M_zφ90/|D_rφ|) (argument clipped to ±1), M_zφ90 = M_zφ∞·(2/π)·
atan(q_Crφ2·R0·|φ_t|)·G_yκ (G_yκ = 1 for the pure-slip functions). M'_z uses F_y0 at γ = 0
without turn slip, as before. Choices where the sources differ or are silent:
- K_zγr0 = F_z·R0(q_Dz8 + q_Dz9·df_z)(1 + p_Pz2·dp_i)·λ_Kzγ·λ_μy, the camber slope of the
  no-turn-slip D_r at γ = 0 (MFeval writes q_Dz8·q_Dz9·df_z + q_Dz10 + q_Dz11·df_z·|γ| and
  marks it as doubtful). With this choice and K_yRφ0, turn-slip mode at φ_t = 0 reproduces the
  camber slopes ∂F_y/∂γ and ∂M_z/∂γ at α = κ = γ = 0 of the plain model times R0·Ω/V_x (exactly;
  tested), the spin a camber γ produces;
- the spin's sign is the book's (φ = −(ψ̇ − (1 − ε_γ)Ω sin γ)/V'_c); with the opposite sign the
  camber thrust would change sign when turn slip is switched on;
- B_Hyφ's denominator has a further ±ε (a file without turn-slip coefficients, p_Hyφ2 = 0, gives
  S_Hyφ = 0 instead of NaN); missing turn-slip coefficients are 0 except p_Hyφ1 = q_Drφ1 = 1;
- MF 5.2 has no turn slip (an error).

**Deviations from the book (MF-Tyre / MFeval), for 6.1 and 6.2:**
- A_μ = 1 in (4.E8) (λ'_μ = λ*_μ) and λ_μV = 0 (not in .tir files);
- M'_z0 = −t₀·F_y0(γ = 0) (4.E32) and, combined, F'_y = G_yκ·F_y0(γ = 0) (4.E74);
- D_t = F_z·(R0/F'_z0)(q_Dz1 + q_Dz2·df_z)(1 − p_pz1·dp_i)(1 + q_Dz3·γ + q_Dz4·γ²)λ_t (paper A60,
  γ not |γ|); B_t with (1 + q_Bz4·γ + q_Bz5·|γ|) (A58; q_Bz6 does not exist in .tir files);
- D_r carries cos α* and M_zr0 a further cos α' (as MFeval); the combined M_zr has no cos α';
- α_t,eq = atan(√(tan²α_t + (K_xκ/K'_yα)²κ²))·sgn α_t, same for α_r (A54–A55);
  s = R0(s_sz1 + s_sz2·F_y/F_z0 + (s_sz3 + s_sz4·df_z)γ)λ_s with F_z0 (A56); t multiplied by
  λ_Fz0;
- M_x: the Besselink draft (49) with q_sx12…q_sx14; M_y: paper (A48), negative in ISO-W.

**Friction ellipse** (`friction_ellipse`, the `FE_METHOD = 'YES'` of MF-Tyre 5.0 / PAC2002
files, e.g. the FEDA truck tyre's; Chrono's `ChPac02Tire` with USE_MODE 4): combined slip
combines the pure-slip forces instead of using the R* coefficients. With F_x0, F_y0 the pure-slip
forces, S_Vx, S_Vy, S_Hx, S_Hy their shifts, K_xκ, K_yα the slip stiffnesses, D_x, D_y the peaks:
κ_c = κ + S_Hx + S_Vx/K_xκ, α_c = α + S_Hy + S_Vy/K_yα, s = sin α_c,
F_x = F_x0·D_y|κ_c| / √((D_y·κ_c)² + ((F_x0 − S_Vx)·s)²),
F_y = F_y0·D_x|s| / √((D_x·s)² + ((F_y0 − S_Vy)·κ_c)²),
M_z = −t₀·F_y + M_zr0 (the pure-slip trail and residual moment, no s·F_x term). These are
Chrono's μ_x,c/μ_x,act and μ_y,c/μ_y,act (β = arccos(|κ_c|/√(κ_c² + s²))) with F_z cancelled,
written without 0/0: where both terms of a root vanish (κ_c = 0 with s = 0 or F_x0 = S_Vx, as at
κ = 0 on a file without κ shifts) the factor is its limit along the slip, D_y/√(D_y² + (K_xκ·s)²)
(D_x/√(D_x² + (K_yα·κ_c)²)), so values and derivatives stay finite there. M_x and M_y take the
combined F_x, F_y. At κ_c = 0 the factor of F_y is 1 (pure lateral slip unchanged) and at s = 0
that of F_x. This M_z uses the combined F_y with its camber terms (the plain combined M_z uses F_y0
at γ = 0). MFeval and TNO's 6.x files have no FE_METHOD: it is off for them.

**Evaluation.** For batches of `FAST_MATH_POINTS` points or more, arctan, sin, cos, tan and
the equivalent slips' sqrt are the vectorised float64 implementations of `diffsusp.tyre.fast_math`
(Cephes algorithms, relative error about 1e-16, exact custom derivatives) instead of XLA's
scalar calls: the combined F_x, F_y, M_z cost 2.4× less CPU time per point
(benchmarks/README.md, tyre section); smaller batches keep XLA's functions, whose program
compiles faster.

MF 6.2 steady-state forces and moments at a given F_z are the 6.1 equations (6.2 changes the
vertical model: loaded radius, deflection and stiffness with camber, in
`diffsusp.tyre.vertical`). **MF 5.2** (FITTYP 5, 6):
no pressure terms; K_yα = p_Ky1·F'_z0·sin(p_Ky4·atan(F_z/(p_Ky2·F'_z0)))(1 − p_Ky3|γ|)λ_Kyα
(p_Ky4 = 2 when absent); S_Hy = (p_Hy1 + p_Hy2·df_z)λ_Hy + p_Hy3·γ·λ_Kyγ; K_yγ0 = (p_Hy3·K_yα0 +
F_z(p_Vy3 + p_Vy4·df_z))λ_Kyγ; M_z = −t·(F_y − S_Vyκ) + M_zr + s·F_x; M_y =
−R0·F_z·λ_My(q_sy1 + q_sy2·F_x/F_z0 + q_sy3|V_x/V0| + q_sy4(V_x/V0)⁴). FITTYP 5 (MF-Tyre 5.0 /
PAC2002 files, e.g. Chrono's) is evaluated with these MF 5.2 equations; the λ_γ scale factors
(LGAX, LGAY, LGAZ) are read but not applied (as MFeval; they are 1 in every file shipped).
"""

import math
import warnings
from typing import ClassVar, NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..errors import ModelFileError, ModelWarning
from ..io.tir import TirFile
from . import fast_math, fit_start
from .base import AbstractTyre
from .vertical import spin

__all__ = ["MagicFormula6", "TyreForces", "evaluate", "check_limits", "COEFFICIENTS",
           "FITTYP_VERSION"]

FITTYP_VERSION = {5: "5.2", 6: "5.2", 52: "5.2", 61: "6.1", 62: "6.2"}
"""The FITTYP values diffsusp evaluates and the equations it uses for each."""

EPS = 1e-6  # ε_x, ε_y, ε_K, ε_V of (4.E6a) etc., as MF-Tyre

_SCALING = ("LFZO LCX LMUX LEX LKX LHX LVX LCY LMUY LEY LKY LHY LVY LTR LRES LXAL LYKA LVYKA "
            "LS LKYC LKZC LVMX LMX LMY LMP LGAX LGAY LGAZ").split()
_SECTIONS = {
    "MODEL": "FITTYP LONGVL VXLOW".split(),
    "DIMENSION": ["UNLOADED_RADIUS", "WIDTH", "ASPECT_RATIO"],
    "OPERATING_CONDITIONS": ["INFLPRES", "NOMPRES"],
    "VERTICAL": ("FNOMIN VERTICAL_STIFFNESS BREFF DREFF FREFF Q_RE0 Q_V1 Q_V2 Q_FZ2 Q_FCX Q_FCY "
                 "PFZ1 Q_FCY2 Q_CAM1 Q_CAM2 Q_CAM3 Q_FYS1 Q_FYS2 Q_FYS3").split(),
    "SCALING_COEFFICIENTS": _SCALING,
    "LONGITUDINAL_COEFFICIENTS": (
        "PCX1 PDX1 PDX2 PDX3 PEX1 PEX2 PEX3 PEX4 PKX1 PKX2 PKX3 PHX1 PHX2 PVX1 PVX2 PPX1 PPX2 "
        "PPX3 PPX4 RBX1 RBX2 RBX3 RCX1 REX1 REX2 RHX1").split(),
    "OVERTURNING_COEFFICIENTS": ("QSX1 QSX2 QSX3 QSX4 QSX5 QSX6 QSX7 QSX8 QSX9 QSX10 QSX11 "
                                 "QSX12 QSX13 QSX14 PPMX1").split(),
    "LATERAL_COEFFICIENTS": (
        "PCY1 PDY1 PDY2 PDY3 PEY1 PEY2 PEY3 PEY4 PEY5 PKY1 PKY2 PKY3 PKY4 PKY5 PKY6 PKY7 PHY1 "
        "PHY2 PHY3 PVY1 PVY2 PVY3 PVY4 PPY1 PPY2 PPY3 PPY4 PPY5 RBY1 RBY2 RBY3 RBY4 RCY1 REY1 "
        "REY2 RHY1 RHY2 RVY1 RVY2 RVY3 RVY4 RVY5 RVY6").split(),
    "ROLLING_COEFFICIENTS": "QSY1 QSY2 QSY3 QSY4 QSY5 QSY6 QSY7 QSY8".split(),
    "ALIGNING_COEFFICIENTS": (
        "QBZ1 QBZ2 QBZ3 QBZ4 QBZ5 QBZ9 QBZ10 QCZ1 QDZ1 QDZ2 QDZ3 QDZ4 QDZ6 QDZ7 QDZ8 QDZ9 QDZ10 "
        "QDZ11 QEZ1 QEZ2 QEZ3 QEZ4 QEZ5 QHZ1 QHZ2 QHZ3 QHZ4 PPZ1 PPZ2 SSZ1 SSZ2 SSZ3 SSZ4"
    ).split(),
    "TURNSLIP_COEFFICIENTS": ("PDXP1 PDXP2 PDXP3 PKYP1 PDYP1 PDYP2 PDYP3 PDYP4 PHYP1 PHYP2 "
                              "PHYP3 PHYP4 PECP1 PECP2 QDTP1 QCRP1 QCRP2 QBRP1 QDRP1").split(),
}
SECTION_OF = {name: sec for sec, names in _SECTIONS.items() for name in names}
COEFFICIENTS = tuple(n for sec, names in _SECTIONS.items() for n in names if n != "FITTYP")
"""Every coefficient the steady-state equations read (the model's differentiable leaves)."""

REQUIRED = tuple(
    "UNLOADED_RADIUS FNOMIN PCX1 PDX1 PDX2 PEX1 PEX2 PKX1 PKX2 PKX3 PHX1 PHX2 PVX1 PVX2 PCY1 "
    "PDY1 PDY2 PDY3 PEY1 PEY2 PKY1 PKY2 PHY1 PHY2 PVY1 PVY2 QBZ1 QBZ2 QCZ1 QDZ1 QDZ2 QEZ1 QEZ2 "
    "QHZ1 QHZ2".split())
"""Coefficients every MF file must give (a missing one is an error naming its section); any
other missing coefficient takes its neutral value (λ = 1, p_Ky4 = 2, others 0)."""

LIMITS = {"FZMIN": 0.0, "FZMAX": math.inf, "KPUMIN": -math.inf, "KPUMAX": math.inf,
           "ALPMIN": -math.inf, "ALPMAX": math.inf, "CAMMIN": -math.inf, "CAMMAX": math.inf,
           "PRESMIN": -math.inf, "PRESMAX": math.inf}
_LIMIT_SECTION = {"FZMIN": "VERTICAL_FORCE_RANGE", "FZMAX": "VERTICAL_FORCE_RANGE",
                  "KPUMIN": "LONG_SLIP_RANGE", "KPUMAX": "LONG_SLIP_RANGE",
                  "ALPMIN": "SLIP_ANGLE_RANGE", "ALPMAX": "SLIP_ANGLE_RANGE",
                  "CAMMIN": "INCLINATION_ANGLE_RANGE", "CAMMAX": "INCLINATION_ANGLE_RANGE",
                  "PRESMIN": "INFLATION_PRESSURE_RANGE", "PRESMAX": "INFLATION_PRESSURE_RANGE"}
_TO_LIBRARY = {"UNLOADED_RADIUS": 1000.0, "LONGVL": 1000.0, "VXLOW": 1000.0, "WIDTH": 1000.0,
               "VERTICAL_STIFFNESS": 1e-3, "Q_CAM2": 1e-3}
"""SI → library factors (m → mm, m/s → mm/s, N/m → N/mm, 1/m → 1/mm) of the coefficients
that carry a length."""


class TyreForces(NamedTuple):
    """Forces [N] and moments [N·mm] at the contact point, ISO-W axes."""

    fx: Array
    fy: Array
    mx: Array
    my: Array
    mz: Array


class MagicFormula6(AbstractTyre):
    """A Magic Formula 5.2 / 6.1 / 6.2 tyre (spec: tyre §7 C; module docstring for equations),
    an `AbstractTyre`.

    **Fields:** `coefficients` (name → float64 scalar array, library units: UNLOADED_RADIUS mm,
    LONGVL mm/s, pressures Pa; differentiable, vmappable), `version` ("5.2", "6.1" or "6.2",
    static), `limits` (static tuple of (name, value) pairs in SI/rad: FZMIN … PRESMAX),
    `friction_ellipse` (static bool, default False: the file's `FE_METHOD = 'YES'`; combined
    slip by the friction ellipse instead of the R* coefficients, module docstring "Friction
    ellipse"; `check_limits` says so when the inputs combine slips).
    """

    coefficients: dict[str, Float[Array, ""]]
    version: str = eqx.field(static=True)
    limits: tuple[tuple[str, float], ...] = eqx.field(static=True)
    friction_ellipse: bool = eqx.field(static=True, default=False)

    def __check_init__(self):
        if self.version not in ("5.2", "6.1", "6.2"):
            raise ValueError(f"version {self.version!r}: expected '5.2', '6.1' or '6.2'")
        missing = [n for n in COEFFICIENTS if n not in self.coefficients]
        if missing:
            raise ValueError(f"coefficients missing: {', '.join(missing[:8])}; build the model "
                             "with MagicFormula6.from_tir or from_values")

    channels: ClassVar[tuple[str, ...]] = ("FX", "FY", "MX", "MY", "MZ")

    @property
    def limit(self) -> dict[str, float]:
        return dict(self.limits)

    def with_limits(self, limits: dict[str, float]) -> "MagicFormula6":
        """A copy whose validity ranges are `limits` (name → value; every other range open)."""
        return MagicFormula6(dict(self.coefficients), self.version,
                             tuple(sorted(limits.items())), self.friction_ellipse)

    @property
    def nominal_load(self) -> float:
        """FNOMIN [N]."""
        return float(self["FNOMIN"])

    def forces(self, fz, kappa, alpha, gamma=0.0, vx=None, pressure=None, *, combined=True,
               channels=None) -> dict[str, Array]:
        """`evaluate` as a dict channel → array (`AbstractTyre.forces`): NaN entries of `vx`
        and `pressure` are LONGVL and INFLPRES; only `channels` are computed (the others NaN)."""
        if vx is not None:
            vx = jnp.where(jnp.isnan(vx), self["LONGVL"], vx)
        if pressure is not None:
            pressure = jnp.where(jnp.isnan(pressure), self["INFLPRES"], pressure)
        out = evaluate(self, fz, kappa, alpha, gamma, vx, pressure, combined=combined,
                       outputs=tuple(c.lower() for c in (channels or self.channels)))
        return {"FX": out.fx, "FY": out.fy, "MX": out.mx, "MY": out.my, "MZ": out.mz}

    def default_groups(self, channels) -> list[str]:
        """pure_lateral, pure_longitudinal and pure_aligning as `channels` allow."""
        return [g for g, ch in (("pure_lateral", "FY"), ("pure_longitudinal", "FX"),
                                ("pure_aligning", "MZ")) if ch in channels]

    def data_start(self, data, names, predict) -> dict[str, float]:
        """The scale coefficients' starting values from the data (`fit_start.data_start`)."""
        return fit_start.data_start(self, data, names, predict)

    def constraint_violations(self, fz, gamma) -> list[str]:
        """The usual physical constraints over the range of load `fz` (and camber `gamma`):
        C_x, C_y, C_t > 0; |μ_x|, |μ_y| > 0 without a change of sign (the sign of D is the
        file's convention: PAC2002 files write PDY1 < 0); E_x, E_y ≤ 1 (spec: tyre §7 C)."""
        c = {k: float(v) for k, v in self.coefficients.items()}
        fz = np.linspace(float(jnp.min(fz)), float(jnp.max(fz)), 21)
        g = np.linspace(float(jnp.min(gamma)), float(jnp.max(gamma)), 7)[:, None]
        dfz = (fz - c["LFZO"] * c["FNOMIN"]) / (c["LFZO"] * c["FNOMIN"])
        out = []
        for name, v in (("C_x = PCX1·LCX", c["PCX1"] * c["LCX"]),
                        ("C_y = PCY1·LCY", c["PCY1"] * c["LCY"]), ("C_t = QCZ1", c["QCZ1"])):
            if v <= 0:
                out.append(f"{name} = {v:.4g} is not > 0")
        mux = (c["PDX1"] + c["PDX2"] * dfz) * (1 - c["PDX3"] * g**2)
        muy = (c["PDY1"] + c["PDY2"] * dfz) * (1 - c["PDY3"] * g**2)
        for name, v, s in (("mu_x (D_x/F_z)", mux, c["PDX1"]),
                           ("mu_y (D_y/F_z)", muy, c["PDY1"])):
            sgn = 1.0 if s >= 0 else -1.0
            if np.min(sgn * v) <= 0:
                out.append(f"|{name}| reaches 0 (sign change) in the data's range: "
                           f"{np.min(sgn * v) * sgn:.4g}")
        ex = (c["PEX1"] + c["PEX2"] * dfz + c["PEX3"] * dfz**2)[None, :] * (
            1 - c["PEX4"] * np.array([[-1.0], [1.0]]))
        ey = (c["PEY1"] + c["PEY2"] * dfz) * (1 + c["PEY5"] * g**2 - (c["PEY3"] + c["PEY4"] * g))
        ey2 = (c["PEY1"] + c["PEY2"] * dfz) * (1 + c["PEY5"] * g**2
                                               + (c["PEY3"] + c["PEY4"] * g))
        for name, v in (("E_x", ex), ("E_y", np.concatenate([ey, ey2]))):
            if np.max(v) > 1:
                out.append(f"{name} reaches {np.max(v):.4g} > 1 in the data's range (clipped "
                           "at 1)")
        return out

    def replace(self, *, friction_ellipse: bool | None = None, **values) -> "MagicFormula6":
        """A copy with some coefficients changed (library units); `friction_ellipse`: switch the
        friction-ellipse combination on or off (default: kept)."""
        c = dict(self.coefficients)
        for k, v in values.items():
            if k not in c:
                raise ValueError(f"unknown coefficient {k!r}")
            c[k] = jnp.asarray(v, dtype=float)
        fe = self.friction_ellipse if friction_ellipse is None else bool(friction_ellipse)
        return MagicFormula6(c, self.version, self.limits, fe)

    @classmethod
    def from_values(cls, values: dict, version: str = "6.1", limits: dict | None = None,
                    friction_ellipse: bool = False) -> "MagicFormula6":
        """From a dict of coefficients in library units (missing: neutral values)."""
        check_x64()
        c = {n: jnp.asarray(float(values.get(n, _default(n, values))), dtype=float)
             for n in COEFFICIENTS}
        lim = dict(LIMITS)
        lim.update(limits or {})
        return cls(c, version, tuple(sorted(lim.items())), bool(friction_ellipse))

    @classmethod
    def from_tir(cls, tir: TirFile) -> "MagicFormula6":
        """From a `.tir` file (SI → library units at this boundary; see the module docstring).

        `FE_METHOD = 'YES'` ([MODEL], MF-Tyre 5.0 / PAC2002 files) sets `friction_ellipse`.

        Raises `ModelFileError` for an unknown FITTYP, a missing required coefficient (naming
        its section), a non-numeric one (with its line) or an FE_METHOD other than 'YES'/'NO'."""
        fittyp = tir.fittyp
        if fittyp not in FITTYP_VERSION:
            e = tir.entry("FITTYP")
            raise ModelFileError(
                f"FITTYP = {fittyp} is not a Magic Formula version diffsusp evaluates "
                f"(known: {', '.join(map(str, FITTYP_VERSION))}: 5/6 = MF 5.x, 61 = MF 6.1, "
                "62 = MF 6.2)", path=tir.path, line=e.line, field="FITTYP")
        version = FITTYP_VERSION[fittyp]
        values = {}
        for n in COEFFICIENTS:
            if n in tir:
                values[n] = tir.number(n, section=SECTION_OF[n])
            elif n in REQUIRED:
                tir.number(n, section=SECTION_OF[n])  # raises, naming the section
        if "NOMPRES" not in values or values["NOMPRES"] == 0.0:
            values["NOMPRES"] = values.get("INFLPRES", 1.0) or 1.0
        values.setdefault("INFLPRES", values["NOMPRES"])
        for n, f in _TO_LIBRARY.items():
            if n in values:
                values[n] = values[n] * f
        limits = {n: tir.number(n) for n in LIMITS if n in tir}
        for n in ("PRESMIN", "PRESMAX"):
            if limits.get(n) == 0.0:  # some exporters write 0 for "no range"
                limits.pop(n)
        return cls.from_values(values, version, limits, _fe_method(tir))

    def to_tir(self, template: TirFile, *, ranges: bool = False) -> TirFile:
        """A copy of `template` with this model's coefficients written in (library → SI). Only
        coefficients that differ from the template or that it lacks are written; FE_METHOD is
        written where `friction_ellipse` differs from the template's. `ranges=True` also
        writes the model's finite validity ranges of load, slip and camber into their sections
        (a fitted model: the data's ranges, `diffsusp.tyre.fit.with_ranges`)."""
        tir = template.copy()
        if self.friction_ellipse != _fe_method(template):
            tir.set("FE_METHOD", "YES" if self.friction_ellipse else "NO", section="MODEL")
        for n in COEFFICIENTS:
            v = float(self.coefficients[n]) / _TO_LIBRARY.get(n, 1.0)
            if n in tir and isinstance(tir[n], float):
                if float(tir[n]) != v:
                    tir.set(n, v)
            elif v != _default(n, {}):
                tir.set(n, v, section=SECTION_OF[n])
        if ranges:
            for n, v in self.limit.items():
                if math.isfinite(v) and n in _LIMIT_SECTION and not n.startswith("PRES"):
                    tir.set(n, float(v), section=_LIMIT_SECTION[n])
        return tir


def _fe_method(tir: TirFile) -> bool:
    """The file's FE_METHOD ('YES' / 'NO', any case; absent: 'NO')."""
    e = tir.entries.get("FE_METHOD")
    if e is None:
        return False
    v = str(e.value).strip().upper() if isinstance(e.value, str) else None
    if v not in ("YES", "NO"):
        raise ModelFileError(f"FE_METHOD = {e.text}: expected 'YES' (friction ellipse for "
                             "combined slip) or 'NO'", path=tir.path, line=e.line,
                             field="FE_METHOD")
    return v == "YES"


def check_x64():
    import jax

    if not jax.config.jax_enable_x64:
        warnings.warn("jax_enable_x64 is off: the Magic Formula is evaluated in float32 (about "
                      "7 digits; the tests' 1e-10 agreement needs float64). Call "
                      "jax.config.update('jax_enable_x64', True) first.", stacklevel=3)


def _default(name: str, values: dict) -> float:
    if name in _SCALING:
        return 1.0
    if name in ("PKY4",):
        return 2.0
    if name in ("Q_RE0", "PHYP1", "QDRP1"):  # a radius ratio, two shape factors: 1 is neutral
        return 1.0
    if name == "LONGVL":
        return 16.7e3
    if name == "VXLOW":
        return 1.0e3
    if name in ("NOMPRES", "INFLPRES"):
        return float(values.get("INFLPRES", values.get("NOMPRES", 1.0)) or 1.0)
    return 0.0


class _XLA:
    """XLA's own float64 functions (scalar calls per element; a smaller program)."""

    arctan, sin, cos, tan, sqrt = (staticmethod(f) for f in (jnp.arctan, jnp.sin, jnp.cos,
                                                             jnp.tan, jnp.sqrt))


FAST_MATH_POINTS = 20_000
"""Evaluations with at least this many points (the inputs' broadcast size, known when the
program is traced) use the vectorised functions of `diffsusp.tyre.fast_math`; smaller ones XLA's
own. Both agree to about 1e-16 relative; the vectorised ones cost 2.4× less CPU per point but
make a program that compiles about 2.5× slower, which small batches (fits, the tyre on the K&C
rig, tests) do not win back."""


def _cos_atan(x, fm):
    """cos(atan x) = 1/√(1 + x²); with the vectorised functions `fast_math.cos_arctan` (a float64
    sqrt in a loop fusion stops LLVM from vectorising it, see `diffsusp.tyre.fast_math`)."""
    if fm is fast_math:
        return fm.cos_arctan(x)
    return 1.0 / jnp.sqrt(1.0 + x * x)


def _sgn(x):
    """sign(x) with sign(0) = 1 (MF-Tyre's guard of divisions)."""
    return jnp.where(x < 0, -1.0, 1.0)


def _mf(B, C, E, x, fm):
    """D-less Magic Formula sin(C·atan(Bx − E(Bx − atan Bx)))."""
    bx = B * x
    return fm.sin(C * fm.arctan(bx - E * (bx - fm.arctan(bx))))


def _cosmf(B, C, E, x, fm):
    bx = B * x
    return fm.cos(C * fm.arctan(bx - E * (bx - fm.arctan(bx))))


class _PureLateral(NamedTuple):
    """The pure lateral force (4.E19–4.E30) and the quantities the combined slip and the
    aligning torque reuse."""

    Fy0: Array
    muy: Array
    Kya: Array
    SHy: Array
    SVy: Array
    By: Array
    Cy: Array
    Kyg0: Array
    zeta2: Array


def _fy0(c, v52, fz, dfz, dpi, alpha_s, gamma_s, limits, fm, ts=None) -> _PureLateral:
    """Pure lateral force (4.E19–4.E30): Fy0, μ_y, K_yα, S_Hy, S_Vy, B_y, C_y, K_yγ0, ζ2.
    `ts`: the turn-slip state (`_TurnSlip`) or None (all ζ = 1)."""
    Fz0p = c["LFZO"] * c["FNOMIN"]
    if v52:
        Kya = (c["PKY1"] * Fz0p * fm.sin(c["PKY4"] * fm.arctan(fz / (c["PKY2"] * Fz0p)))
               * (1.0 - c["PKY3"] * jnp.abs(gamma_s)) * c["LKY"])
        Kya0 = c["PKY1"] * Fz0p * fm.sin(c["PKY4"] * fm.arctan(fz / (c["PKY2"] * Fz0p))) \
            * c["LKYC"]
        Kyg0 = (c["PHY3"] * Kya0 + fz * (c["PVY3"] + c["PVY4"] * dfz)) * c["LKYC"]
    else:
        Kya = (c["PKY1"] * Fz0p * (1.0 + c["PPY1"] * dpi) * (1.0 - c["PKY3"] * jnp.abs(gamma_s))
               * fm.sin(c["PKY4"] * fm.arctan((fz / Fz0p) / ((c["PKY2"] + c["PKY5"] * gamma_s**2)
                                                              * (1.0 + c["PPY2"] * dpi))))
               * c["LKY"])
        Kyg0 = fz * (c["PKY6"] + c["PKY7"] * dfz) * (1.0 + c["PPY5"] * dpi) * c["LKYC"]
    zeta2 = 1.0
    if ts is not None:
        # turn slip (4.77–4.79): ζ2 peak, ζ3 cornering stiffness
        zeta3 = _cos_atan(c["PKYP1"] * ts.r_phi**2, fm)
        Kya = Kya * zeta3
        Byp = (c["PDYP1"] * (1.0 + c["PDYP2"] * dfz)
               * _cos_atan(c["PDYP3"] * fm.tan(ts.alpha), fm))
        r = jnp.abs(ts.r_phi)
        root = jnp.where(r > 0.0, jnp.sqrt(jnp.where(r > 0.0, r, 1.0)), 0.0)
        zeta2 = _cos_atan(Byp * (r + c["PDYP4"] * root), fm)
    SVyg = fz * (c["PVY3"] + c["PVY4"] * dfz) * gamma_s * c["LKYC"] * c["LMUY"] * zeta2
    if v52:
        SHy = (c["PHY1"] + c["PHY2"] * dfz) * c["LHY"] + c["PHY3"] * gamma_s * c["LKYC"]
    elif ts is not None:
        # ζ0 = 0 and ζ4 = 1 + S_Hyφ − S_Vyγ/K'_yα (4.80–4.89): the camber shift comes from spin
        Kya0 = (c["PKY1"] * Fz0p * (1.0 + c["PPY1"] * dpi)
                * fm.sin(c["PKY4"] * fm.arctan((fz / Fz0p) / (c["PKY2"] * (1.0 + c["PPY2"] * dpi))))
                * zeta3 * c["LKY"])
        Chyp = c["PHYP1"]
        Dhyp = c["PHYP2"] + c["PHYP3"] * dfz
        Ehyp = jnp.minimum(c["PHYP4"], 1.0) if limits else c["PHYP4"]
        den = Chyp * Dhyp * (Kya0 + EPS * _sgn(Kya0))
        Bhyp = Kyg0 / (1.0 - ts.eps_gamma) / (den + EPS * _sgn(den))
        SHyp = Dhyp * _mf(Bhyp, Chyp, Ehyp, ts.r_phi, fm)
        SHy = (c["PHY1"] + c["PHY2"] * dfz) * c["LHY"] + SHyp - SVyg / (Kya + EPS * _sgn(Kya))
    else:
        SHy = (c["PHY1"] + c["PHY2"] * dfz) * c["LHY"] + (Kyg0 * gamma_s - SVyg) / (
            Kya + EPS * _sgn(Kya))
    SVy = fz * (c["PVY1"] + c["PVY2"] * dfz) * c["LVY"] * c["LMUY"] * zeta2 + SVyg
    ay = alpha_s + SHy
    Cy = c["PCY1"] * c["LCY"]
    muy = ((c["PDY1"] + c["PDY2"] * dfz) * (1.0 + c["PPY3"] * dpi + c["PPY4"] * dpi**2)
           * (1.0 - c["PDY3"] * gamma_s**2) * c["LMUY"])
    Dy = muy * fz * zeta2
    Ey = ((c["PEY1"] + c["PEY2"] * dfz)
          * (1.0 + c["PEY5"] * gamma_s**2 - (c["PEY3"] + c["PEY4"] * gamma_s) * _sgn(ay))
          * c["LEY"])
    if limits:
        Ey = jnp.minimum(Ey, 1.0)
    By = Kya / (Cy * Dy + EPS * _sgn(Dy))
    Fy0 = Dy * _mf(By, Cy, Ey, ay, fm) + SVy
    return _PureLateral(Fy0, muy, Kya, SHy, SVy, By, Cy, Kyg0, zeta2)


class _TurnSlip(NamedTuple):
    """Turn-slip state: R0·φ (spin φ [1/mm] times R0 [mm]), R0·|φ_t| (turn slip as applied),
    ε_γ, and the clipped slip angle α [rad]."""

    r_phi: Array
    r_phit: Array
    eps_gamma: Array
    alpha: Array


class _Inputs(NamedTuple):
    """The inputs as evaluated: load (clipped to FZMAX with `limits`) and the unclipped load,
    slips, camber, speed and pressure (clipped to their ranges with `limits`)."""

    fz: Array
    ufz: Array
    kappa: Array
    alpha: Array
    gamma: Array
    vx: Array
    p: Array


def _inputs(model, fz, kappa, alpha, gamma, vx, pressure, limits) -> _Inputs:
    c = model.coefficients
    lim = model.limit
    fz = jnp.maximum(jnp.asarray(fz, dtype=float), 0.0)
    kappa, alpha, gamma = (jnp.asarray(x, dtype=float) for x in (kappa, alpha, gamma))
    vx = c["LONGVL"] if vx is None else jnp.asarray(vx, dtype=float)
    p = c["INFLPRES"] if pressure is None else jnp.asarray(pressure, dtype=float)
    ufz = fz
    if limits:
        fz = jnp.minimum(fz, lim["FZMAX"])
        kappa = jnp.clip(kappa, lim["KPUMIN"], lim["KPUMAX"])
        alpha = jnp.clip(alpha, lim["ALPMIN"], lim["ALPMAX"])
        gamma = jnp.clip(gamma, lim["CAMMIN"], lim["CAMMAX"])
        p = jnp.clip(p, lim["PRESMIN"], lim["PRESMAX"])
    return _Inputs(fz, ufz, kappa, alpha, gamma, vx, p)


def evaluate(model: MagicFormula6, fz: ArrayLike, kappa: ArrayLike, alpha: ArrayLike,
             gamma: ArrayLike = 0.0, vx: ArrayLike | None = None, pressure: ArrayLike | None = None,
             *, combined: bool = True, limits: bool = True, alpha_star: bool = False,
             outputs: tuple[str, ...] = ("fx", "fy", "mx", "my", "mz"),
             turn_slip: ArrayLike | None = None, omega: ArrayLike | None = None,
             announce: bool = True) -> TyreForces:
    """Steady-state forces and moments of a MF 5.2/6.1/6.2 tyre (spec: tyre §7 C; Pacejka 2012
    §4.3.2; deviations in the module docstring). Elementwise: inputs broadcast together.

    **Arguments:** `fz` [N] vertical load; `kappa` [-] longitudinal slip ratio; `alpha` [rad]
    slip angle; `gamma` [rad] inclination; `vx` [mm/s] forward speed (default LONGVL, > 0);
    `pressure` [Pa] (default INFLPRES). `combined=False`: the pure-slip functions F_x0(κ),
    F_y0(α), M_z0(α) (M_x and M_y then use F_y0 and F_x0). `limits`, `alpha_star`: the modes of
    the module docstring. `outputs`: the quantities to compute (the others are returned as NaN;
    a smaller traced program for fits of one channel). `turn_slip` [1/mm]: φ_t = −ψ̇/V_c, the
    path curvature; given (0 included), the MF 6.1/6.2 turn-slip functions ζ0…ζ8 are on (module
    docstring, "Turn slip"), with the spin φ = φ_t·cos α + (1 − ε_γ)·Ω·sin γ/V_c; None (default):
    no turn slip, every ζ = 1. `omega` [rad/s]: the wheel spin Ω used by turn slip (default from
    V_x, κ and the effective rolling radius, `diffsusp.tyre.vertical.spin`, which needs the
    file's VERTICAL_STIFFNESS, BREFF, DREFF, FREFF).

    **Saturation** (`limits=True`): called with concrete inputs and a concrete
    model, one `ModelWarning` per call lists every input beyond the file's ranges (its count and
    first row, flattened order, as `check_limits`), e.g. a driving slip on a file with KPUMAX = 0,
    whose F_x is then 0. Under `jax.jit`, `vmap` or `grad` (any input or coefficient a tracer)
    nothing is checked: the traced program saturates silently (call `check_limits` on the data
    beforehand). `announce=False` skips the check (for callers that ran `check_limits` already,
    as the CLI does).

    **Returns:** `TyreForces` (fx, fy [N]; mx, my, mz [N·mm]), ISO-W axes.
    """
    unknown = set(outputs) - set(TyreForces._fields)
    if unknown:
        raise ValueError(f"outputs {sorted(unknown)}: choose among {TyreForces._fields}")
    want_mx, want_my, want_mz = ("mx" in outputs, "my" in outputs, "mz" in outputs)
    need_fx = "fx" in outputs or want_my or (want_mz and combined)
    need_fy = "fy" in outputs or want_mx or want_mz
    ellipse = combined and model.friction_ellipse
    if ellipse:  # each combined force needs both pure-slip forces
        need_fx = need_fy = need_fx or need_fy
    c = model.coefficients
    v52 = model.version == "5.2"
    if turn_slip is not None and v52:
        raise ValueError("turn slip is defined for MF 6.1 / 6.2 files (FITTYP 61, 62), not 5.2")
    lim = model.limit
    if limits and announce:
        _announce(model, fz, kappa, alpha, gamma, pressure)
    ukappa = kappa
    fz, ufz, kappa, alpha, gamma, vx, p = _inputs(model, fz, kappa, alpha, gamma, vx, pressure,
                                                  limits)
    shapes = [jnp.shape(x) for x in (fz, kappa, alpha, gamma, vx, p)]
    fm = fast_math if math.prod(jnp.broadcast_shapes(*shapes)) >= FAST_MATH_POINTS else _XLA
    Fz0 = c["FNOMIN"]
    Fz0p = c["LFZO"] * Fz0
    R0 = c["UNLOADED_RADIUS"]
    dfz = (fz - Fz0p) / Fz0p
    dpi = 0.0 * fz if v52 else (p - c["NOMPRES"]) / c["NOMPRES"]
    if alpha_star:
        a_s, g_s = fm.tan(alpha), fm.sin(gamma)
    else:
        a_s, g_s = alpha, gamma
    # cos α' (4.E6): V_c = √(V_cx² + tan²α·V_cx²) = |V_cx|/|cos α|, so V_cx/(V_c + ε_V) =
    # V_cx·|cos α|/(|V_cx| + ε_V·|cos α|) (one cos instead of tan and sqrt; ε_V = 1e-6 m/s)
    cos_a = fm.cos(alpha)
    cos_ap = vx * jnp.abs(cos_a) / (jnp.abs(vx) + 1e3 * EPS * jnp.abs(cos_a))
    ts = None
    if turn_slip is not None:
        # spin (4.75–4.76, 4.90) with V'_c = V_x/|cos α| (V_x > VXLOW) and MFeval's φ_t·cos α
        om = spin(model, ufz, vx, ukappa, p) if omega is None else jnp.asarray(omega, float)
        phit = jnp.asarray(turn_slip, dtype=float) * cos_a
        eps_g = c["PECP1"] * (1.0 + c["PECP2"] * dfz)
        phi = phit + (1.0 - eps_g) * om * fm.sin(gamma) * jnp.abs(cos_a) / jnp.abs(vx)
        ts = _TurnSlip(R0 * phi, R0 * jnp.abs(phit), eps_g, alpha)

    nan = jnp.full(jnp.broadcast_shapes(jnp.shape(fz), jnp.shape(kappa), jnp.shape(alpha),
                                        jnp.shape(gamma)), jnp.nan)
    Fx = Fy = Mx = My = Mz = nan
    if need_fx:
        # pure longitudinal (4.E9–4.E18)
        Cx = c["PCX1"] * c["LCX"]
        mux = ((c["PDX1"] + c["PDX2"] * dfz) * (1.0 + c["PPX3"] * dpi + c["PPX4"] * dpi**2)
               * (1.0 - c["PDX3"] * gamma**2) * c["LMUX"])
        Dx = mux * fz
        if ts is not None:  # ζ1 (4.105–4.106)
            Bxp = c["PDXP1"] * (1.0 + c["PDXP2"] * dfz) * _cos_atan(c["PDXP3"] * kappa, fm)
            Dx = Dx * _cos_atan(Bxp * ts.r_phi, fm)
        Kxk = (fz * (c["PKX1"] + c["PKX2"] * dfz) * jnp.exp(c["PKX3"] * dfz)
               * (1.0 + c["PPX1"] * dpi + c["PPX2"] * dpi**2) * c["LKX"])
        Bx = Kxk / (Cx * Dx + EPS * _sgn(Dx))
        SHx = (c["PHX1"] + c["PHX2"] * dfz) * c["LHX"]
        SVx = fz * (c["PVX1"] + c["PVX2"] * dfz) * c["LVX"] * c["LMUX"]
        kx = kappa + SHx
        Ex = (c["PEX1"] + c["PEX2"] * dfz + c["PEX3"] * dfz**2) * (1.0 - c["PEX4"] * jnp.sign(kx)) \
            * c["LEX"]
        if limits:
            Ex = jnp.minimum(Ex, 1.0)
        Fx0 = Dx * _mf(Bx, Cx, Ex, kx, fm) + SVx

    if need_fy:
        # pure lateral
        Fy0, muy, Kya, SHy, SVy, By, Cy, _, zeta2 = _fy0(c, v52, fz, dfz, dpi, a_s, g_s,
                                                           limits, fm, ts)

    if want_mz:
        # pure aligning torque (4.E31–4.E49, A58, A60)
        Fy0_g0 = _fy0(c, v52, fz, dfz, dpi, a_s, 0.0 * g_s, limits, fm).Fy0
        fz_mz = jnp.where(fz <= 0.0, 0.0, jnp.maximum(fz, lim["FZMIN"])) if limits else fz
        SHt = c["QHZ1"] + c["QHZ2"] * dfz + (c["QHZ3"] + c["QHZ4"] * dfz) * g_s
        Kyap = Kya + EPS * _sgn(Kya)
        SHf = SHy + SVy / Kyap
        ar = a_s + SHf
        at = a_s + SHt
        Dt = ((c["QDZ1"] + c["QDZ2"] * dfz) * (1.0 - c["PPZ1"] * dpi)
              * (1.0 + c["QDZ3"] * gamma + c["QDZ4"] * gamma**2) * fz_mz * (R0 / Fz0p) * c["LTR"])
        if ts is not None:  # ζ5 (4.91)
            Dt = Dt * _cos_atan(c["QDTP1"] * ts.r_phi, fm)
        Bt = ((c["QBZ1"] + c["QBZ2"] * dfz + c["QBZ3"] * dfz**2)
              * (1.0 + c["QBZ4"] * gamma + c["QBZ5"] * jnp.abs(gamma)) * c["LKY"] / c["LMUY"])
        Ct = c["QCZ1"]
        Et = (c["QEZ1"] + c["QEZ2"] * dfz + c["QEZ3"] * dfz**2) * (
            1.0 + (c["QEZ4"] + c["QEZ5"] * g_s) * (2.0 / jnp.pi) * fm.arctan(Bt * Ct * at))
        if limits:
            Et = jnp.minimum(Et, 1.0)
        cos_as = fm.cos(a_s) if alpha_star else cos_a
        Br = c["QBZ9"] * c["LKY"] / c["LMUY"] + c["QBZ10"] * By * Cy
        if ts is None:
            Dr = (fz_mz * R0 * ((c["QDZ6"] + c["QDZ7"] * dfz) * c["LRES"]
                                + ((c["QDZ8"] + c["QDZ9"] * dfz) * (1.0 + c["PPZ2"] * dpi)
                                   + (c["QDZ10"] + c["QDZ11"] * dfz) * jnp.abs(g_s)) * g_s
                                * c["LKZC"]) * c["LMUY"] * cos_as)
        else:
            # ζ0 = 0, ζ2, ζ6 (4.102), ζ8 = 1 + D_rφ (4.93–4.99); C_r = ζ7 below
            Br = Br * _cos_atan(c["QBRP1"] * ts.r_phi, fm)
            Mzp_inf = jnp.maximum(c["QCRP1"] * jnp.abs(muy) * R0 * fz_mz
                                  * jnp.sqrt(fz_mz / Fz0p) * c["LMP"], 1e-6)
            Cdrp = c["QDRP1"]
            Ddrp = Mzp_inf / jnp.sin(0.5 * jnp.pi * Cdrp)
            Kzgr0 = (fz_mz * R0 * (c["QDZ8"] + c["QDZ9"] * dfz) * (1.0 + c["PPZ2"] * dpi)
                     * c["LKZC"] * c["LMUY"])
            Bdrp = Kzgr0 / (Cdrp * Ddrp * (1.0 - ts.eps_gamma))
            Drp = Ddrp * fm.sin(Cdrp * fm.arctan(Bdrp * ts.r_phi))
            Dr = (fz_mz * R0 * (c["QDZ6"] + c["QDZ7"] * dfz) * c["LRES"] * zeta2 * c["LMUY"]
                  * cos_as + Drp)
            Mzp90 = Mzp_inf * (2.0 / jnp.pi) * fm.arctan(c["QCRP2"] * ts.r_phit)
        Cr = 1.0

    if not combined:
        Fx = Fx0 if need_fx else nan
        Fy = Fy0 if need_fy else nan
        if want_mz:
            if ts is not None:
                Cr = _zeta7(Mzp90, Drp)
            t0 = Dt * _cosmf(Bt, Ct, Et, at, fm) * cos_ap
            Mz = -t0 * Fy0_g0 + Dr * fm.cos(Cr * fm.arctan(Br * ar)) * cos_ap
    elif ellipse:
        # friction ellipse (FE_METHOD = 'YES'; module docstring "Friction ellipse")
        Kxp = Kxk + EPS * _sgn(Kxk)
        Kyp = Kya + EPS * _sgn(Kya)
        kc = kappa + SHx + SVx / Kxp
        sc = fm.sin(a_s + SHy + SVy / Kyp)
        dx, dy = jnp.abs(Dx), jnp.abs(muy * fz * zeta2)
        ax, ay = jnp.abs(Fx0 - SVx), jnp.abs(Fy0 - SVy)
        Fx = Fx0 * _ellipse_factor(dy * kc, ax * sc, dy, Kxk * sc)
        Fy = Fy0 * _ellipse_factor(dx * sc, ay * kc, dx, Kya * kc)
        if want_mz:
            if ts is not None:
                Cr = _zeta7(Mzp90, Drp)
            t0 = Dt * _cosmf(Bt, Ct, Et, at, fm) * cos_ap
            Mz = -t0 * Fy + Dr * fm.cos(Cr * fm.arctan(Br * ar)) * cos_ap
    else:
        if need_fx:
            # combined longitudinal (4.E50–4.E57)
            Exa = c["REX1"] + c["REX2"] * dfz
            if limits:
                Exa = jnp.minimum(Exa, 1.0)
            Bxa = (c["RBX1"] + (0.0 if v52 else c["RBX3"] * g_s**2)) \
                * _cos_atan(c["RBX2"] * kappa, fm) * c["LXAL"]
            Gxa = (_cosmf(Bxa, c["RCX1"], Exa, a_s + c["RHX1"], fm)
                   / _cosmf(Bxa, c["RCX1"], Exa, c["RHX1"], fm))
            Fx = Gxa * Fx0
        if need_fy:
            # combined lateral (4.E58–4.E67)
            DVyk = (muy * fz * (c["RVY1"] + c["RVY2"] * dfz + c["RVY3"] * g_s)
                    * _cos_atan(c["RVY4"] * a_s, fm))
            SVyk = DVyk * fm.sin(c["RVY5"] * fm.arctan(c["RVY6"] * kappa)) * c["LVYKA"]
            SHyk = c["RHY1"] + c["RHY2"] * dfz
            Eyk = c["REY1"] + c["REY2"] * dfz
            if limits:
                Eyk = jnp.minimum(Eyk, 1.0)
            Byk = (c["RBY1"] + (0.0 if v52 else c["RBY4"] * g_s**2)) \
                * _cos_atan(c["RBY2"] * (a_s - c["RBY3"]), fm) * c["LYKA"]
            Gyk = (_cosmf(Byk, c["RCY1"], Eyk, kappa + SHyk, fm)
                   / _cosmf(Byk, c["RCY1"], Eyk, SHyk, fm))
            Fy = Gyk * Fy0 + SVyk
        if want_mz:
            # combined aligning torque (4.E71–4.E78, A54–A56)
            k2 = (Kxk / Kyap) ** 2 * kappa**2
            ar_eq = _alpha_eq(ar, k2, fm)
            at_eq = _alpha_eq(at, k2, fm)
            s = R0 * (c["SSZ1"] + c["SSZ2"] * (Fy / Fz0) + (c["SSZ3"] + c["SSZ4"] * dfz) * gamma) \
                * c["LS"]
            if ts is None:
                Mzr = Dr * _cos_atan(Br * ar_eq, fm)  # C_r = 1
            else:
                Mzr = Dr * fm.cos(_zeta7(Mzp90 * Gyk, Drp) * fm.arctan(Br * ar_eq))
            t = Dt * _cosmf(Bt, Ct, Et, at_eq, fm) * cos_ap * c["LFZO"]
            if v52:
                Mz = -t * (Fy - SVyk) + Mzr + s * Fx
            else:
                Mz = -t * (Gyk * Fy0_g0) + Mzr + s * Fx


    if want_mx:
        # overturning moment (Besselink draft (49); MF 5.2: manual)
        fz_mx = jnp.where(fz < lim["FZMIN"], fz * (fz / lim["FZMIN"]) ** 2, fz) if (
            limits and lim["FZMIN"] > 0) else fz
        if v52:
            Mx = R0 * fz_mx * (c["QSX1"] * c["LVMX"] - c["QSX2"] * gamma + c["QSX3"] * Fy / Fz0) \
                * c["LMX"]
        else:
            Mx = (R0 * fz_mx * c["LMX"] * (
                c["QSX1"] * c["LVMX"] - c["QSX2"] * gamma * (1.0 + c["PPMX1"] * dpi)
                - c["QSX12"] * gamma * jnp.abs(gamma) + c["QSX3"] * Fy / Fz0
                + c["QSX4"] * fm.cos(c["QSX5"] * fm.arctan((c["QSX6"] * fz_mx / Fz0) ** 2))
                * fm.sin(c["QSX7"] * gamma + c["QSX8"] * fm.arctan(c["QSX9"] * Fy / Fz0))
                + c["QSX10"] * fm.arctan(c["QSX11"] * fz_mx / Fz0) * gamma)
                + R0 * Fy * c["LMX"] * (c["QSX13"] + c["QSX14"] * jnp.abs(gamma)))
    if want_my:
        # rolling resistance moment (A48; MF 5.2: manual), F_z not saturated at FZMAX
        fz_my = jnp.where(ufz < lim["FZMIN"], ufz * (ufz / lim["FZMIN"]), ufz) if (
            limits and lim["FZMIN"] > 0) else ufz
        V0 = c["LONGVL"]
        roll = (c["QSY1"] + c["QSY2"] * Fx / Fz0 + c["QSY3"] * jnp.abs(vx / V0)
                + c["QSY4"] * (vx / V0) ** 4)
        if v52:
            My = -R0 * fz_my * c["LMY"] * roll
        else:
            My = -R0 * Fz0 * c["LMY"] * (
                roll + (c["QSY5"] + c["QSY6"] * fz_my / Fz0) * gamma**2) * (
                (fz_my / Fz0) ** c["QSY7"] * (p / c["NOMPRES"]) ** c["QSY8"])
    return TyreForces(Fx, Fy, Mx, My, Mz)


def _ellipse_factor(u, v, w, z):
    """|u|/√(u² + v²), the friction ellipse's F/F0 (module docstring), with u, v = D_y·κ_c,
    |F_x0 − S_Vx|·sin α_c for F_x (D_x·sin α_c, |F_y0 − S_Vy|·κ_c for F_y). Where u = v = 0
    (κ_c = 0 and sin α_c = 0 or F_x0 = S_Vx, e.g. κ = 0 on a file without κ shifts) it is the
    limit along the slip, |w|/√(w² + z²) with w, z = D_y, K_x·sin α_c (D_x, K_y·κ_c), and 1
    where that too is 0/0 (F_z = 0): finite values and derivatives (the double-where form)."""
    n2 = u * u + v * v
    ok = n2 > 0.0
    m2 = w * w + z * z
    ok2 = m2 > 0.0
    lim = jnp.where(ok2, jnp.abs(w) / jnp.sqrt(jnp.where(ok2, m2, 1.0)), 1.0)
    return jnp.where(ok, jnp.abs(u) / jnp.sqrt(jnp.where(ok, n2, 1.0)), lim)


def _alpha_eq(a, k2, fm):
    """atan(√(tan²a + k2))·sgn a (A54–A55), = a where k2 = 0 (κ = 0): the same value, and a
    derivative there instead of the 0·∞ of √ at a = κ = 0."""
    pos = k2 > 0.0
    x = fm.tan(a) ** 2 + k2
    eq = fm.arctan(fm.sqrt(jnp.where(pos, x, 1.0))) * _sgn_strict(a)
    return jnp.where(pos, eq, a)


def _zeta7(mzp90, drp):
    """ζ7 = (2/π)·arccos(M_zφ90/|D_rφ|), the argument clipped to [−1, 1] (MFeval) with a
    derivative that stays finite at the clip (0 beyond it)."""
    r = mzp90 / jnp.maximum(jnp.abs(drp), 1e-15)
    inside = jnp.abs(r) < 1.0
    return jnp.where(inside, (2.0 / jnp.pi) * jnp.arccos(jnp.where(inside, r, 0.0)),
                     jnp.where(r >= 1.0, 0.0, 2.0))


def _sgn_strict(x):
    return jnp.sign(x)


def _beyond(model: MagicFormula6, fz, kappa, alpha, gamma, pressure):
    """(input name, limit name, count, first flat index) of each file range an input exceeds."""
    lim = model.limit
    out = []
    for name, x, lo, hi in (("FZ", fz, None, "FZMAX"), ("SL", kappa, "KPUMIN", "KPUMAX"),
                            ("SA", alpha, "ALPMIN", "ALPMAX"), ("IA", gamma, "CAMMIN", "CAMMAX"),
                            ("P", pressure, "PRESMIN", "PRESMAX")):
        if x is None:
            continue
        x = np.asarray(x, dtype=float)
        for key, bad in ((lo, x < lim[lo] if lo else None), (hi, x > lim[hi])):
            if key is None or bad is None:
                continue
            n = int(np.count_nonzero(bad))
            if n:
                out.append((name, key, n, int(np.flatnonzero(bad.ravel())[0])))
    return out


def _announce(model: MagicFormula6, fz, kappa, alpha, gamma, pressure):
    """`evaluate`'s one warning per eager call (module docstring "Modes"); nothing when any
    input or coefficient is a JAX tracer (inside jit, vmap, grad)."""
    import jax

    leaves = jax.tree_util.tree_leaves((model.coefficients, fz, kappa, alpha, gamma, pressure))
    if any(isinstance(x, jax.core.Tracer) for x in leaves):
        return
    if pressure is None:
        pressure = model.coefficients["INFLPRES"]
    hits = _beyond(model, fz, kappa, alpha, gamma, pressure)
    if hits:
        lim = model.limit
        parts = "; ".join(f"{n} value(s) of {name} beyond {key} = {lim[key]:g} "
                          f"[{_LIMIT_SECTION[key]}] (first at row {first})"
                          for name, key, n, first in hits)
        warnings.warn(f"evaluate: inputs saturated at the tyre file's ranges as MF-Tyre does: "
                      f"{parts} (limits=False evaluates the formulas as they are)",
                      ModelWarning, stacklevel=3)


def check_limits(model: MagicFormula6, fz=None, kappa=None, alpha=None, gamma=None,
                 pressure=None, *, where: str = "", combined: bool = True) -> dict[str, int]:
    """Warn (`ModelWarning`) about inputs outside the file's ranges, which `evaluate` saturates
    as MF-Tyre does; returns {limit name: count of inputs beyond it}. Units as `evaluate`.

    On a model with `friction_ellipse` (FE_METHOD = 'YES') and `combined` inputs (some point
    with κ ≠ 0 and α ≠ 0), one further `ModelWarning` says that combined slip is the friction
    ellipse's, not the file's R* coefficients' (not counted in the result)."""
    lim = model.limit
    counts = {}
    if (combined and model.friction_ellipse and kappa is not None and alpha is not None
            and np.any((np.asarray(kappa, float) != 0.0) & (np.asarray(alpha, float) != 0.0))):
        warnings.warn(f"{where}FE_METHOD = 'YES': combined slip by the friction ellipse "
                      "(MF-Tyre 5.0 / PAC2002, as Chrono's ChPac02Tire), not the file's "
                      "combined-slip coefficients RBX*, RBY*, ...", ModelWarning, stacklevel=2)
    for name, key, n, first in _beyond(model, fz, kappa, alpha, gamma, pressure):
        counts[key] = n
        warnings.warn(f"{where}{n} value(s) of {name} beyond {key} = {lim[key]:g} "
                      f"[{_LIMIT_SECTION[key]}] (first at row {first}); saturated as "
                      "MF-Tyre does", ModelWarning, stacklevel=2)
    return counts
