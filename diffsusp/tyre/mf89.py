"""The Magic Formula of the thesis: Bakker–Pacejka 1989/1991 coefficient set (Annex B).

spec: tyre §2.4 (B-1…B-39), §7 C item 11, CORRECTIONS 5, 7. Coefficients b0…b12
(longitudinal), a0…a13 with a11 split into a111, a112 (lateral), c0…c17 (aligning torque),
am0…am9 and bm0…bm3 (combined slip), λ scale factors (all 1 in the thesis), relaxation lengths.

**Units** are the thesis's: F_z in kN, slip angle δ, camber γ and torsion in degrees, κ in the
unit its b-set was identified with (Bakker 1989: percent; the thesis gives no b-set), F in N, M_z
in N·m. `evaluate` converts from and to the library's units (N, rad, N·mm) at the edge.

Conventions: PSA signs (spec §0.2): κ = R_r·ω/V_x − 1, δ = arctan(−V_y/V_x). The horizontal
shift enters as (x + S_h) as in (B-1)/(B-9) (CORRECTIONS 8; `spec.similarity` converts).
Choices where the annex is silent or garbled, each documented where applied:
- **D = 0** (tables with c1 = c2 = 0): the linear law Y = BCD·(x + S_h) + S_v (the limit of
  D·sin(C·atan(B·x)) as D → 0 at fixed BCD, with E bounded);
- **E clipping** min(·, 1) on E_x (B-6) and E_y (B-14) as printed; E_z (B-22) is not clipped;
- (B-8), (B-16), (B-24) use S_Vx, S_Vy, S_Vz respectively (spec §0.5.5);
- **transients**: the longitudinal one (B-34…B-36) as printed (its steady state is κ exactly);
  the lateral one in Pacejka's form σ_Y·dv/dt + |V_x|·v = −σ_Y·V_y, δ' = arctan(v/σ_Y·sgn V_x)
  whose steady state is δ = arctan(−V_y/V_x) of (B-1) — (B-37…B-39) as printed give the
  opposite sign and mix σ_X in (CORRECTIONS 7).
"""

import math
from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .. import lsq
from . import thesis_sets
from .base import AbstractTyre
from .mf6 import check_x64

__all__ = ["MagicFormula89", "NAMES", "fx0", "fy0", "mz0", "combined", "evaluate", "macro",
           "longitudinal_relaxation_rate", "lateral_relaxation_rate", "transient_slips"]

_LAMBDAS = ("l_mux l_cx l_kx l_ex l_hx l_vx l_muy l_cy l_ky l_ey l_hy l_vy l_muz l_cz l_kz l_ez "
            "l_hz l_vz l_xa l_yk l_vyk l_sx l_sy").split()
NAMES = tuple([f"b{i}" for i in range(13)]
              + [f"a{i}" for i in range(11)] + ["a111", "a112", "a12", "a13"]
              + [f"c{i}" for i in range(18)] + [f"am{i}" for i in range(10)]
              + [f"bm{i}" for i in range(4)] + _LAMBDAS + ["sigma_x", "sigma_y"])
"""Every coefficient of the 1989 set (a11,1 and a11,2 written a111, a112; λ factors l_*;
relaxation lengths sigma_x, sigma_y [m])."""


class MagicFormula89(AbstractTyre):
    """A Bakker–Pacejka 1989/1991 Magic Formula tyre (spec: tyre §2.4), thesis units, an
    `AbstractTyre` (its `forces` in library units).

    **Fields:** `coefficients` (name → float64 scalar array; see `NAMES`). Missing ones are 0
    except the λ's (1) when built with `from_values`.
    """

    coefficients: dict[str, Float[Array, ""]]
    channels: ClassVar[tuple[str, ...]] = ("FX", "FY", "MZ")

    def __check_init__(self):
        missing = [n for n in NAMES if n not in self.coefficients]
        if missing:
            raise ValueError(f"coefficients missing: {', '.join(missing[:8])}; build with "
                             "MagicFormula89.from_values or from_thesis")

    @property
    def nominal_load(self) -> float:
        """4000 N: the set has no nominal load (its loads are in kN); a bench programme
        without ranges is centred there."""
        return 4000.0

    def forces(self, fz, kappa, alpha, gamma=0.0, vx=None, pressure=None, *, combined=True,
               channels=None) -> dict[str, Array]:
        """F_x, F_y [N] and M_z [N·mm] in library units (`AbstractTyre.forces`): combined
        slip by `evaluate`, pure slip by `fx0`, `fy0`, `mz0` (κ in the b-set's unit as given);
        the set has no speed or pressure terms (`vx`, `pressure` unused)."""
        del vx, pressure, channels
        if combined:
            fx, fy, mz = evaluate(self, fz, kappa, alpha, gamma)
            return {"FX": fx, "FY": fy, "MZ": mz}
        fz = jnp.asarray(fz) / 1000.0
        alpha, gamma = jnp.rad2deg(alpha), jnp.rad2deg(gamma)
        return {"FX": fx0(self, kappa, fz), "FY": fy0(self, alpha, fz, gamma),
                "MZ": 1000.0 * mz0(self, alpha, fz, gamma)}

    def default_groups(self, channels) -> list[str]:
        """mf1989_lateral, whatever the channels."""
        del channels
        return ["mf1989_lateral"]

    @classmethod
    def from_values(cls, values: dict) -> "MagicFormula89":
        check_x64()
        unknown = set(values) - set(NAMES)
        if unknown:
            raise ValueError(f"unknown coefficient(s) {sorted(unknown)}; known: {NAMES}")
        return cls({n: jnp.asarray(float(values.get(n, 1.0 if n in _LAMBDAS else 0.0)),
                                   dtype=float) for n in NAMES})

    @classmethod
    def from_specification(cls, fz, *, cornering_stiffness, fy_peak, fy_shift=None,
                           aligning_stiffness=None, mz_peak=None, mz_shift=None,
                           a0: float = 1.0, c0: float = 2.5, a7: float = 0.0, c9: float = 0.0,
                           a4: float | None = None) -> "MagicFormula89":
        """Step 1 of the thesis's polynomial → Magic Formula conversion (spec §3.8 (a)–(c),
        (3-96…3-108)) from specification quantities at several loads, thesis units:

        - (a3, a4) from the cornering stiffness K [N/°] by **total least squares** on
          K·F_z² = 2F_z·(a3·a4) − K·a4² (3-100) (`diffsusp.lsq.tls`), requiring X2 = a4² > 0
          (a stiffness concave in load); otherwise the linear range K = (2a3/a4)·F_z (3-101)
          with the a-priori `a4` (an error without it);
        - (a1, a2) from the F_y extremum/asymptote D [N] = a1·F_z² + a2·F_z (3-108);
        - (a9, a10) from the shift S_h [°] = a9·F_z + a10 (3-104), when given;
        - (c3, c4), (c1, c2), (c12, c13) likewise for M_z [N·m/°, N·m, °] when given.

        C (a0, c0) and E (a7, c9) are a-priori values (the thesis fixes C and fits E in step 2).
        `fz` [kN], at least two loads (three for the TLS)."""
        import numpy as np

        fz = np.asarray(fz, float)
        K = np.asarray(cornering_stiffness, float)
        values = {"a0": a0, "c0": c0, "a7": a7, "c9": c9}
        tls = lsq.tls(np.stack([2.0 * fz, -K], axis=1), K * fz**2, names=["X1", "X2"])
        X1, X2 = (float(v) for v in tls.x)
        if X2 > 0:
            values["a4"] = math.sqrt(X2)
            values["a3"] = X1 / values["a4"]
        else:
            if a4 is None:
                raise ValueError("the cornering stiffness is not concave in load (X2 = a4² = "
                                 f"{X2:.4g} ≤ 0): only the linear range 2·a3/a4 is determined; "
                                 "give an a-priori a4 [kN]")
            X3 = float(np.linalg.lstsq(fz[:, None], K, rcond=None)[0][0])
            values["a4"] = a4
            values["a3"] = X3 * a4 / 2.0
        quad = np.stack([fz**2, fz], axis=1)
        lin = np.stack([fz, np.ones_like(fz)], axis=1)
        values["a1"], values["a2"] = np.linalg.lstsq(quad, np.asarray(fy_peak, float),
                                                     rcond=None)[0]
        if fy_shift is not None:
            values["a9"], values["a10"] = np.linalg.lstsq(lin, np.asarray(fy_shift, float),
                                                          rcond=None)[0]
        if aligning_stiffness is not None:
            values["c3"], values["c4"] = np.linalg.lstsq(
                quad, np.asarray(aligning_stiffness, float), rcond=None)[0]
        if mz_peak is not None:
            values["c1"], values["c2"] = np.linalg.lstsq(quad, np.asarray(mz_peak, float),
                                                         rcond=None)[0]
        if mz_shift is not None:
            values["c12"], values["c13"] = np.linalg.lstsq(lin, np.asarray(mz_shift, float),
                                                           rcond=None)[0]
        return cls.from_values({k: float(v) for k, v in values.items()})

    @classmethod
    def from_thesis(cls, tyre: str, pressure: float, *, fy: str = "slip_fy",
                    mz: str = "slip_mz") -> "MagicFormula89":
        """One of the thesis's identified sets (Tables 14–29, spec §4.6), e.g.
        `from_thesis("dunlop_r16", 2.0)`: the a-set of F_y vs slip and the c-set of M_z vs slip.
        `mz="torsion_fy"` or `"torsion_mz"` loads a torsion table's c-set instead (those tables
        use the M_z structure (B-17…B-24) on the torsion abscissa); `fy=None` leaves a = 0."""
        values = {}
        if fy is not None:
            values.update(thesis_sets.coefficients(tyre, pressure, fy))
        if mz is not None:
            values.update(thesis_sets.coefficients(tyre, pressure, mz))
        return cls.from_values(values)


def _curve(D, C, BCD, E, Sh, Sv, x):
    """D·sin(C·atan(φ)) + S_v, φ = B(1−E)(x+S_h) + E·atan(B(x+S_h)), B = BCD/(C·D); the linear
    law BCD·(x+S_h) + S_v where D = 0 (exactly: guarded so gradients stay finite)."""
    zero = D == 0.0
    Ds = jnp.where(zero, 1.0, D)
    Cs = jnp.where(C == 0.0, 1.0, C)
    B = BCD / (Cs * Ds)
    u = x + Sh
    phi = B * (1.0 - E) * u + E * jnp.arctan(B * u)
    return jnp.where(zero, BCD * u, Ds * jnp.sin(C * jnp.arctan(phi))) + Sv


def macro(m: MagicFormula89, fz: ArrayLike, gamma: ArrayLike = 0.0) -> dict[str, Array]:
    """The macro-coefficients (D, C, BCD, B, E, S_h, S_v) of F_x0, F_y and M_z0 at a load [kN] and
    camber [deg] (B-2…B-8, B-10…B-16, B-18…B-24), keys like "Dy", "BCDz", "Shx"."""
    c = m.coefficients
    fz = jnp.asarray(fz, dtype=float)
    g = jnp.asarray(gamma, dtype=float)
    out = {
        "Dx": (c["b1"] * fz**2 + c["b2"] * fz) * c["l_mux"],
        "Cx": c["b0"] * c["l_cx"],
        "BCDx": (c["b3"] * fz**2 + c["b4"] * fz) * jnp.exp(-c["b5"] * fz) * c["l_kx"],
        "Ex": jnp.minimum((c["b6"] * fz**2 + c["b7"] * fz + c["b8"]) * c["l_ex"], 1.0),
        "Shx": (c["b9"] * fz + c["b10"]) * c["l_hx"],
        "Svx": (c["b11"] * fz + c["b12"]) * c["l_vx"] * c["l_mux"],
        "Dy": (c["a1"] * fz**2 + c["a2"] * fz) * c["l_muy"],
        "Cy": c["a0"] * c["l_cy"],
        "BCDy": (c["a3"] * jnp.sin(2.0 * jnp.arctan(fz / c["a4"])) * (1.0 - c["a5"] * jnp.abs(g))
                 * c["l_ky"]),
        "Ey": jnp.minimum((c["a6"] * fz + c["a7"]) * c["l_ey"], 1.0),
        "Shy": (c["a8"] * g + c["a9"] * fz + c["a10"]) * c["l_hy"],
        "Svy": ((c["a12"] * fz + c["a13"] + (c["a112"] * fz**2 + c["a111"] * fz) * g)
                * c["l_vy"] * c["l_muy"]),
        "Dz": (c["c1"] * fz**2 + c["c2"] * fz) * c["l_muz"],
        "Cz": c["c0"] * c["l_cz"],
        "BCDz": ((c["c3"] * fz**2 + c["c4"] * fz) * jnp.exp(-c["c5"] * fz)
                 * (1.0 - c["c6"] * jnp.abs(g)) * c["l_kz"]),
        "Ez": (c["c7"] * fz**2 + c["c8"] * fz + c["c9"]) * (1.0 - c["c10"] * jnp.abs(g))
        * c["l_ez"],
        "Shz": (c["c11"] * g + c["c12"] * fz + c["c13"]) * c["l_hz"],
        "Svz": ((c["c16"] * fz + c["c17"] + (c["c14"] * fz**2 + c["c15"] * fz) * g)
                * c["l_vz"] * c["l_muz"]),
    }
    for k in "xyz":
        D, C = out["D" + k], out["C" + k]
        out["B" + k] = out["BCD" + k] / (jnp.where(C == 0, 1.0, C) * jnp.where(D == 0, 1.0, D))
    return out


def _axis(m, k, x, fz, gamma):
    p = macro(m, fz, gamma)
    return _curve(p["D" + k], p["C" + k], p["BCD" + k], p["E" + k], p["Sh" + k], p["Sv" + k],
                  jnp.asarray(x, dtype=float))


def fx0(m: MagicFormula89, kappa: ArrayLike, fz: ArrayLike) -> Array:
    """Pure longitudinal force F_x0 [N] (B-1…B-8); κ in the b-set's unit, F_z [kN]."""
    return _axis(m, "x", kappa, fz, 0.0)


def fy0(m: MagicFormula89, delta: ArrayLike, fz: ArrayLike, gamma: ArrayLike = 0.0) -> Array:
    """Pure lateral force F_y [N] (B-9…B-16); δ [deg], F_z [kN], γ [deg]."""
    return _axis(m, "y", delta, fz, gamma)


def mz0(m: MagicFormula89, delta: ArrayLike, fz: ArrayLike, gamma: ArrayLike = 0.0) -> Array:
    """Pure self-aligning torque M_z0 [N·m] (B-17…B-24); δ [deg], F_z [kN], γ [deg]."""
    return _axis(m, "z", delta, fz, gamma)


def combined(m: MagicFormula89, kappa: ArrayLike, delta: ArrayLike, fz: ArrayLike,
             gamma: ArrayLike = 0.0) -> tuple[Array, Array, Array]:
    """Combined slip (B-25…B-33): (F_x, F_y) [N] and M_z0 [N·m] (the annex gives no combined
    M_z). G_x = G_y = 1 and F_yx = 0 when the other slip is zero only if b_m1, a_m1 = 0 and
    a_m8 κ = 0 respectively (as printed)."""
    c = m.coefficients
    kappa, delta, fz, gamma = (jnp.asarray(v, dtype=float) for v in (kappa, delta, fz, gamma))
    BD = c["bm2"] * jnp.cos(jnp.arctan(c["bm3"] * kappa)) * c["l_xa"]
    Gx = (jnp.cos(c["bm0"] * jnp.arctan(BD * (delta - c["bm1"])))
          / jnp.cos(c["bm0"] * jnp.arctan(-BD * c["bm1"])))
    BG = c["am2"] * jnp.cos(jnp.arctan(c["am3"] * (delta - c["am4"]))) * c["l_yk"]
    Gy = (jnp.cos(c["am0"] * jnp.arctan(BG * (kappa - c["am1"])))
          / jnp.cos(c["am0"] * jnp.arctan(-BG * c["am1"])))
    Fyx = (c["am5"] * fz * (gamma - (c["am6"] * fz + c["am7"]))
           * jnp.sin(1.9 * jnp.arctan(c["am8"] * kappa)) * jnp.cos(jnp.arctan(c["am9"] * delta))
           * c["l_vyk"] * c["l_muy"])
    return (Gx * fx0(m, kappa, fz), Gy * fy0(m, delta, fz, gamma) + Fyx,
            mz0(m, delta, fz, gamma))


def evaluate(m: MagicFormula89, fz: ArrayLike, kappa: ArrayLike, alpha: ArrayLike,
             gamma: ArrayLike = 0.0, *, kappa_scale: float = 1.0):
    """F_x, F_y [N] and M_z [N·mm] in library units: `fz` [N], `kappa` [-] (multiplied by
    `kappa_scale` into the b-set's unit, e.g. 100 for percent), `alpha`, `gamma` [rad] (PSA
    signs; converted to the thesis's kN and degrees here)."""
    fx, fy, mz = combined(m, jnp.asarray(kappa) * kappa_scale, jnp.rad2deg(alpha),
                          jnp.asarray(fz) / 1000.0, jnp.rad2deg(gamma))
    return fx, fy, mz * 1000.0


def longitudinal_relaxation_rate(m: MagicFormula89, u: ArrayLike, vx: ArrayLike,
                                 vr: ArrayLike) -> Array:
    """du/dt of (B-36): σ'_X·du/dt + |V_r|·u = −σ'_X·V_SX, V_SX = V_x − V_r, σ'_X = σ_X·λ_αX
    (B-35); speeds and σ in one length unit per second and that length."""
    s = m["sigma_x"] * m["l_sx"]
    return (-s * (vx - vr) - jnp.abs(vr) * u) / s


def lateral_relaxation_rate(m: MagicFormula89, v: ArrayLike, vx: ArrayLike, vy: ArrayLike
                            ) -> Array:
    """dv/dt of the lateral first-order relaxation σ'_Y·dv/dt + |V_x|·v = −σ'_Y·V_y (σ'_Y =
    σ_Y·λ_αY, B-38); the form whose steady state is δ of (B-1) (CORRECTIONS 7)."""
    s = m["sigma_y"] * m["l_sy"]
    return (-s * vy - jnp.abs(vx) * v) / s


def transient_slips(m: MagicFormula89, u: ArrayLike, v: ArrayLike, vx: ArrayLike,
                    vr: ArrayLike) -> tuple[Array, Array]:
    """The transient slips (κ', δ' [rad]) that replace (κ, δ) in the steady-state formulas:
    κ' = u/(sgn(V_r)·σ'_X − u) (B-34) and δ' = arctan(v/(σ'_Y)·sgn V_x). At the steady states of
    the two rates they equal κ = V_r/V_x − 1 and δ = arctan(−V_y/V_x)."""
    sx = m["sigma_x"] * m["l_sx"]
    sy = m["sigma_y"] * m["l_sy"]
    return u / (jnp.sign(vr) * sx - u), jnp.arctan(v / sy * jnp.sign(vx))
