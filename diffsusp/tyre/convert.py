"""Polynomial tyre model → Magic Formula 1989 coefficients (thesis §3.6.1).

spec: tyre §3.8 (3-93…3-108), §7 E items 21–22, CORRECTIONS 1–4, 8. Units: the polynomial in
the thesis's units (F_z kN, δ′ m, F_y N, M_z N·m), the Magic Formula in the 1989 set's (F_z kN,
δ in **degrees**, PSA sign). The slip conversion is δ′ = −R·tan δ with the **conversion radius
R a parameter** (CORRECTIONS 4: the thesis's sets imply about 0.32–0.35 m, not R_r = 0.294 m).

**Step 1** (closed forms, `step1`), at a set of loads spanning the data:
- (a) slip stiffness K(F_z) = −R·(π/180)·c_{F,δ′,1}(F_z) [N/° or N·m/°]: (a3, a4) by **total
  least squares** on K·F_z² = 2F_z·(a3a4) − K·a4² with the check X2 = a4² > 0 (a stiffness
  concave in load) and the linear-range fallback K = (2a3/a4)·F_z with an a-priori a4
  (`MagicFormula89.from_specification`, which this module reuses); (c3, c4) by LS for M_z;
- (b) S_h from the extrema: the real roots of dP/dδ′ of smallest modulus in the useful domain
  (Table 6, mapped with CORRECTIONS 3), S_h = −(δ_max + δ_min)/2 in degrees with the MF's
  (x + S_h) convention (CORRECTIONS 8), fitted affine in F_z: (a9, a10) or (c12, c13);
  no extremum: S_h is not identifiable by step 1 (it starts at 0 and step 2 fits it);
- (c) D = (|Y_min| + |Y_max|)/2 at the extrema, quadratic in load: (a1, a2) or (c1, c2).
  **No extremum** (every thesis F_y set has C = a0 = 1, a monotone curve with D an asymptote,
  CORRECTIONS 2): D from the polynomial's value F_e at the edge x_e of the domain under the
  a-priori C = 1, E = 0: F = K·x/√(1 + (K·x/D)²) gives D = K·x_e/√((K·x_e/F_e)² − 1).

**Step 2** (`refine`, (3-95)): nonlinear least squares of the slip coefficients with C fixed
(the thesis bounds C; here it is held at its a-priori value, the §3.6.1.1 choice "C fixed a
priori"), reusing the Magic Formula fitter (`diffsusp.tyre.fit.fit`, Levenberg–Marquardt with
exact Jacobians and the guaranteed-least-squares report). It fits the measured pure-slip data
when given (the thesis's Y), otherwise the polynomial's own slip response on a grid. The
linear part W_L·X_L of (3-95) (camber, offset, relaxation) is not refitted jointly: pass data
with those contributions removed.
"""

import math

import jax.numpy as jnp
import numpy as np

from ..errors import InputError
from ..lsq import algebra
from . import fit as mf_fit
from . import mf89
from .poly import PolynomialModel, parse_name, table6_domains

__all__ = ["step1", "refine", "to_magic_formula", "fit_slip_polynomial", "slip_data",
           "torsion_set", "torsion_stiffness"]


def deg_to_dp(delta_deg, radius):
    return -radius * np.tan(np.radians(delta_deg))


def dp_to_deg(dp, radius):
    return -np.degrees(np.arctan(np.asarray(dp) / radius))


def _slip_features(model: PolynomialModel, fz, radius, output):
    """(x_max, y_max, kind), (x_min, y_min, kind) of P_{F,δ′} at one load: for each, the
    real root of dP/dδ′ of smallest modulus inside its Table 6 domain (CORRECTIONS 3 signs);
    None when either is missing."""
    c = model.input_polynomial(float(fz), "delta")
    dom = table6_domains(radius)[output]
    maxima = [e for e in algebra.extrema(c, *dom["max"]) if e[2] == "max"]
    minima = [e for e in algebra.extrema(c, *dom["min"]) if e[2] == "min"]
    if not maxima or not minima:
        return None
    return min(maxima, key=lambda e: abs(e[0])), min(minima, key=lambda e: abs(e[0]))


def _shift_and_peak(model, loads, radius, output):
    feats = [(f, _slip_features(model, f, radius, output)) for f in loads]
    feats = [(f, x) for f, x in feats if x is not None]
    if len(feats) < 2:
        return None
    f = np.array([f for f, _ in feats])
    shift = np.array([-(dp_to_deg(a[0], radius) + dp_to_deg(b[0], radius)) / 2
                      for _, (a, b) in feats])
    peak = np.array([(abs(a[1]) + abs(b[1])) / 2 for _, (a, b) in feats])
    return f, shift, peak


def step1(fy: PolynomialModel | None = None, mz: PolynomialModel | None = None, *,
          loads=(2.0, 3.0, 4.0, 5.0, 6.0), radius: float = 0.33, a0: float = 1.0,
          c0: float = 2.5, a7: float = 0.0, c9: float = 0.0, a4: float | None = None,
          edge_deg: float = 4.0) -> tuple[mf89.MagicFormula89, dict]:
    """Closed-form MF start from the polynomial models (see the module docstring).

    **Arguments:** `fy`, `mz` the identified F_y and M_z polynomials (their δ′ blocks);
    `loads` [kN] where the features are read; `radius` the conversion radius R [m]; `a0`, `c0`
    (C), `a7`, `c9` (E) a-priori; `a4` the a-priori load at peak stiffness if the stiffness is
    not concave (fallback of (3-101)); `edge_deg` the edge of the domain [°] for D without
    extremum. **Returns:** (MagicFormula89, notes: dict of what was found and how).
    """
    loads = np.asarray(loads, float)
    notes = {}
    spec = {"a0": a0, "c0": c0, "a7": a7, "c9": c9, "a4": a4}
    if fy is None:
        raise InputError("step1 needs at least the F_y polynomial")
    k_fy = -math.radians(radius) * fy.cornering_stiffness(loads)
    sp = _shift_and_peak(fy, loads, radius, "Fy")
    if sp is not None:
        notes["Fy"] = (f"extrema found at {len(sp[0])} loads: S_h and D from the extrema "
                       "(3-103, 3-107)")
        fy_loads, fy_shift, peak = sp
    else:
        # C = 1, E = 0: D from the value at the domain edges.
        x_e = edge_deg
        d = []
        for f, k in zip(loads, k_fy, strict=True):
            c = fy.input_polynomial(float(f), "delta")
            vals = [abs(float(algebra.poly_eval(c, deg_to_dp(s * x_e, radius))))
                    for s in (-1, 1)]
            ratio = abs(k) * x_e / np.mean(vals)
            d.append(abs(k) * x_e / math.sqrt(ratio**2 - 1.0) if ratio > 1 else np.mean(vals))
        peak, fy_loads, fy_shift = np.array(d), loads, None
        notes["Fy"] = ("no extremum in the useful domain (C = 1 sets are monotone): S_h not "
                       "identifiable by step 1 (0, fitted in step 2); D from the edge value")
    spec["cornering_stiffness"] = k_fy
    # D quadratic (3-108) and S_h affine (3-104) in load, through the loads that have them
    quad = np.linalg.lstsq(np.stack([fy_loads**2, fy_loads], 1), peak, rcond=None)[0]
    spec["fy_peak"] = quad[0] * loads**2 + quad[1] * loads
    if fy_shift is not None:
        spec["fy_shift"] = np.polyval(np.polyfit(fy_loads, fy_shift, 1), loads)
    if mz is not None:
        k_mz = -math.radians(radius) * mz.cornering_stiffness(loads)
        spec["aligning_stiffness"] = k_mz
        sp = _shift_and_peak(mz, loads, radius, "Mz")
        if sp is not None:
            # quadratic D and affine S_h through the loads that have both extrema
            fl, sh, pk = sp
            spec["mz_shift"] = np.polyval(np.polyfit(fl, sh, 1), loads)
            quad = np.linalg.lstsq(np.stack([fl**2, fl], 1), pk, rcond=None)[0]
            spec["mz_peak"] = quad[0] * loads**2 + quad[1] * loads
            notes["Mz"] = (f"extrema found at {len(fl)} loads: S_h and D from the extrema")
        else:
            notes["Mz"] = "no extremum: D = 0 (the linear law), S_h not identifiable"
    model = mf89.MagicFormula89.from_specification(loads, **spec)
    return model, notes


def slip_data(fz_kn, delta_deg, fy=None, mz=None) -> mf_fit.BenchData:
    """Pure-slip data (γ = 0) as the MF fitter's `BenchData` (library units): loads [kN],
    slip angles [°, PSA] and measured F_y [N] and/or M_z [N·m] (flattened)."""
    fz = np.asarray(fz_kn, float).ravel() * 1e3
    alpha = np.radians(np.asarray(delta_deg, float).ravel())
    channels, meas = [], []
    if fy is not None:
        channels.append("FY")
        meas.append(np.asarray(fy, float).ravel())
    if mz is not None:
        channels.append("MZ")
        meas.append(np.asarray(mz, float).ravel() * 1e3)
    if not channels:
        raise InputError("slip_data needs fy and/or mz")
    n = len(fz)
    z = jnp.zeros(n)
    return mf_fit.BenchData(jnp.asarray(fz), z, jnp.asarray(alpha), z, jnp.full(n, jnp.nan),
                            jnp.full(n, jnp.nan), jnp.asarray(np.stack(meas)),
                            jnp.ones((len(channels), n), bool), tuple(channels))


def refine(start: mf89.MagicFormula89, data: mf_fit.BenchData, *,
           fy_params=("a1", "a2", "a3", "a4", "a7", "a9", "a10"),
           mz_params=("c1", "c2", "c3", "c4", "c9", "c12", "c13"), noise=None):
    """Step 2 (3-95): Levenberg–Marquardt on the slip coefficients with C fixed, through
    `diffsusp.tyre.fit.fit` (pure slip, linear loss): `fy_params`, `mz_params` the F_y and M_z
    coefficients fitted (names), each where the data measure its channel. Returns (model,
    report)."""
    names = []
    if "FY" in data.channels:
        names += list(fy_params)
    if "MZ" in data.channels:
        names += list(mz_params)
    return mf_fit.fit(start, data, names, noise=noise, loss="linear", combined=False,
                      max_steps=400)


def to_magic_formula(fy: PolynomialModel, mz: PolynomialModel | None = None, *,
                     data: mf_fit.BenchData | None = None, loads=(2.0, 3.0, 4.0, 5.0, 6.0),
                     radius: float = 0.33, slip_range: float = 4.0, **step1_options):
    """Step 1 then step 2. Without `data`, step 2 fits the polynomials' slip responses on
    `loads` × [−slip_range, slip_range]° (γ = 0, offset removed). Returns (MagicFormula89,
    step-2 report, step-1 notes, step-1 model)."""
    start, notes = step1(fy, mz, loads=loads, radius=radius, **step1_options)
    if data is None:
        fz = np.repeat(np.asarray(loads, float), 41)
        dd = np.tile(np.linspace(-slip_range, slip_range, 41), len(loads))
        dp = deg_to_dp(dd, radius)
        u = {"fz": jnp.asarray(fz), "delta": jnp.asarray(dp)}
        yfy = np.asarray(_slip_only(fy)(u))
        ymz = None if mz is None else np.asarray(_slip_only(mz)(u))
        data = slip_data(fz, dd, yfy, ymz)
    fitted, report = refine(start, data)
    return fitted, report, notes, start


def _slip_only(model: PolynomialModel) -> PolynomialModel:
    values = {n: v for n, v in model.values().items() if "_delta_" in n}
    return PolynomialModel.create(model.output, {"delta": dict(model.degrees)["delta"]},
                                  values=values)


def fit_slip_polynomial(output: str, fz_kn, delta_p, y, *, degree: int = 5) -> PolynomialModel:
    """LS fit of P_{F,δ′} = Σ_{i=1..degree} Σ_{j=1..3} δ′^i F_z^j b (the round trip's
    polynomial, spec §8 "sanity tests"); F_z [kN], δ′ [m]. Plain least squares (NumPy, the
    columns scaled to unit norm): a data-reduction step, not a report."""
    fz, dp = np.asarray(fz_kn, float).ravel(), np.asarray(delta_p, float).ravel()
    names = PolynomialModel.create(output, {"delta": degree}).names
    W = np.stack([dp ** parse_name(n)[2] * fz ** parse_name(n)[3] for n in names], axis=1)
    scale = np.linalg.norm(W, axis=0)
    x = np.linalg.lstsq(W / scale, np.asarray(y, float).ravel(), rcond=None)[0] / scale
    return PolynomialModel.create(output, {"delta": degree}, values=dict(zip(names, x,
                                                                             strict=True)))


def torsion_stiffness(model: PolynomialModel, fz) -> np.ndarray:
    """The torsion stiffness of a polynomial model, ∂F/∂φ′ at φ′ = 0 per degree of torsion:
    (π/180)·c_{F,φ′,1}(F_z) [N/° or N·m/°] at loads `fz` [kN] (spec §3.2, (3-58), (3-66))."""
    fz = np.asarray(fz, float)
    slope = [np.r_[model.input_polynomial(float(f), "phi"), 0.0][1] for f in fz.ravel()]
    return math.radians(1.0) * np.reshape(slope, fz.shape)


def torsion_set(model: PolynomialModel, *, loads=(3.0, 4.5, 6.0), ramp_deg: float = 0.85,
                c0: float = 2.5, c9: float = 0.01) -> tuple[mf89.MagicFormula89, dict]:
    """The torsion Magic Formula set of a polynomial model's φ′ response by the step-1 closed
    forms (thesis §3.6.2, the "comportement en torsion" sets of Tables 14/15, 18/19, 22/23,
    26/27; spec §3.8, §4.6): the c-set of (B-17…B-24) on the torsion abscissa in degrees, from
    P_{F,φ′} at `loads` [kN] (the thesis's 3, 4.5 and 6 kN):

    - stiffness BCD(F_z) = c3·F_z² + c4·F_z (c5 = 0) by least squares on `torsion_stiffness`;
    - extrema of P_{F,φ′} inside the thesis's torsion ramp ±`ramp_deg` (§3.5.5.3; a maximum
      and a minimum at two loads at least): D = (|Y_max| + |Y_min|)/2 quadratic in load
      (c1, c2) and S_h = −(φ_max + φ_min)/2 [°] affine in load (c12, c13);
    - none: the linear law, D = 0 (c1 = c2 = 0), S_h = 0, as the thesis's tables print
      where no extremum was identified (spec §3.8 (e));
    - C = `c0` and E = `c9` a priori (the tables' placeholders 2.5 and 0.01).

    Where there are extrema the thesis refined the set by its step 2 (C, E and D fitted),
    which this function does not do: its D and stiffness are the polynomial's.

    **Returns:** (a `MagicFormula89` whose `mz0(m, torsion_deg, fz)` is the torsion response,
    in the model's output unit (N for F_y, N·m for M_z), notes).
    """
    loads = np.asarray(loads, float)
    k = torsion_stiffness(model, loads)
    c3, c4 = np.linalg.lstsq(np.stack([loads**2, loads], 1), k, rcond=None)[0]
    values = {"c0": c0, "c3": float(c3), "c4": float(c4), "c9": c9}
    r = math.radians(ramp_deg)
    found = []
    for f in loads:
        ex = algebra.extrema(model.input_polynomial(float(f), "phi"), -r, r)
        maxima = [e for e in ex if e[2] == "max"]
        minima = [e for e in ex if e[2] == "min"]
        if maxima and minima:
            a = min(maxima, key=lambda e: abs(e[0]))
            b = min(minima, key=lambda e: abs(e[0]))
            found.append((f, -math.degrees(a[0] + b[0]) / 2, (abs(a[1]) + abs(b[1])) / 2))
    if len(found) >= 2:
        f, shift, peak = (np.array(v) for v in zip(*found, strict=True))
        c1, c2 = np.linalg.lstsq(np.stack([f**2, f], 1), peak, rcond=None)[0]
        c12, c13 = np.polyfit(f, shift, 1)
        values.update(c1=float(c1), c2=float(c2), c12=float(c12), c13=float(c13))
        notes = (f"extrema inside ±{ramp_deg:g}° at {len(f)} loads: D and S_h from them; "
                 "C and E a priori")
    else:
        notes = f"no extremum inside ±{ramp_deg:g}°: the linear law (D = 0)"
    return mf89.MagicFormula89.from_values(values), {"torsion": notes}
