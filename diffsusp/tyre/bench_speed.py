"""The speed test of the bench identification (thesis §3.4.5, (3-54); spec tyre §3.4).

The thesis asks whether the interaction model depends on the wheel spin ω (Coriolis stresses
on the tread may change the contact pressure): it adds to the F_y model (3-49) a cornering
stiffness K_δ = P_Fz1·ω² + P_Fz2·ω + P_Fz3, an offset S_v = P′_Fz6·ω² + P′_Fz7·ω + P′_Fz8 and
a relaxation angle L_R = P_Fz9·ω² + P_Fz10·ω + P_Fz11 (P load polynomials F_z¹…F_z³, P′ with
F_z⁰ too), identifies it on all its speeds (40–160 km/h) and finds the ω terms not
identifiable: the static model is speed-independent on the steering-feel tests.

Here the test is an option of the bench identification (`bench.identify(speed_test=True)`,
`diffsusp tyre identify --speed-test`): the candidate columns `speed_columns` join the
structure search, which keeps a speed term only when its removal raises the residual beyond
the noise (the F-test of `bench.identify_output`). The columns, named as the polynomial's:

- `b_<F>_wdelta_<k>_<j>`: δ′·ω₀^k·F_z^j (j = 1…3), the speed part of K_δ;
- `b_<F>_wone_<k>_<j>`: ω₀^k·F_z^j (j = 0…3), the speed part of S_v;
- `b_<F>_wLy_<k>_<j>`: (Ḟ_y/ω)·ω₀^k·F_z^j (j = 1…3), the speed part of the relaxation L_R:
  in step 1 the free image of the δ′·ω₀^k·F_z^j column, as `b_<F>_Ly_0_<j>` is that of
  δ′·F_z^j (L = (∂F_pneu/∂δ′)·K_y⁻¹, (3-50)); step 2 then reads K_y from the δ′-derivative
  of the kept columns, the speed ones included (`bench.two_step`). Without these images a
  speed-dependent cornering stiffness (b_Fy_wdelta_1_1 = −15 on the campaign) was detected
  but K_y came out 2.5–3.5 σ high.

**The speed variable** is the run's speed level ω₀ = V_T/R_r [rad/s] (`speed_levels`), not
the instantaneous ω. A Flat Trac holds the belt speed V_T per run while ω = V_T·cos δ/(R_r +
κ′) moves with the slip, and the two speeds of a campaign then make ω² nearly, not exactly, a
combination of 1 and ω. On the 40/120 km/h campaign made from a speed-independent model the
search, given 1, ω and ω² (instantaneous), removed the offset b_<F>_one_1_0 (the largest
σ % of the three) and kept b_Fy_wone_1_0 = −1.71 ± 0.03 and b_Fy_wone_2_0 = 0.0113 ±
0.0002: each "significant", together −48.5 N at 40 km/h and −48.1 N at 120 km/h, the
speed-independent offset (−48.3 N without the speed terms). On k speed levels only ω₀¹…
ω₀^(k−1) are independent of the constant (a Vandermonde system, as camber powers on steady
camber levels): the higher powers are reported not identifiable (`speed_powers`).
"""

from collections.abc import Mapping

import jax.numpy as jnp
import numpy as np

from ..lsq import algebra
from .poly import parse_name

__all__ = ["SPEED_BLOCKS", "SPEED_LY", "SPEED_POWERS", "LEVEL_RTOL", "speed_columns",
           "speed_levels", "speed_powers", "speed_unit", "speed_notes"]

SPEED_BLOCKS = ("wdelta", "wone")
"""Blocks of the speed columns: δ′·ω₀^k·F_z^j (K_δ's) and ω₀^k·F_z^j (S_v's), (3-54)."""
SPEED_LY = "wLy"
"""Block of the speed test's relaxation columns (Ḟ_y/ω)·ω₀^k·F_z^j: relaxation columns of
`bench.two_step` (free in step 1), not interaction ones."""
SPEED_POWERS = (1, 2)
"""The powers of ω in (3-54)."""
LEVEL_RTOL = 0.02
"""Runs whose speeds differ by less than this fraction are one speed level (`speed_levels`)."""


def speed_columns(output: str, powers=SPEED_POWERS) -> algebra.LinearModel:
    """The speed candidate columns of `output` (3-54), inputs `fz` [kN], `delta` δ′ [m],
    `omega0` ω₀ [rad/s] and `fydot_w` Ḟ_y/ω [N]: b_<F>_wdelta_<k>_<j> (δ′·ω₀^k·F_z^j,
    j = 1…3), b_<F>_wone_<k>_<j> (ω₀^k·F_z^j, j = 0…3) and their relaxation images
    b_<F>_wLy_<k>_<j> ((Ḟ_y/ω)·ω₀^k·F_z^j, j = 1…3), k in `powers`, lower powers first."""
    cols = ([(f"b_{output}_wdelta_{k}_{j}", k, j, "delta") for k in powers for j in (1, 2, 3)]
            + [(f"b_{output}_wone_{k}_{j}", k, j, None) for k in powers for j in range(4)]
            + [(f"b_{output}_{SPEED_LY}_{k}_{j}", k, j, "fydot_w") for k in powers
               for j in (1, 2, 3)])

    def function(u):
        w, fz = u["omega0"], u["fz"]
        return jnp.stack([(jnp.ones_like(fz) if x is None else u[x]) * w**k * fz**j
                          for _, k, j, x in cols], axis=-1)

    return algebra.LinearModel(tuple(c[0] for c in cols),
                               ("fz", "delta", "omega0", "fydot_w"), function)


def speed_levels(samples: Mapping, rolling_radius: float, *, rtol: float = LEVEL_RTOL
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The speed level ω₀ = V_T/R_r [rad/s] of each run of conditioned samples (arrays
    (segments, samples): `omega` ω, `kappa` κ′, `delta` δ′ [m]; R_r [m]): the belt speed from
    the bench kinematics, V_T = ω·√((κ′ + R_r)² + δ′²) (V_x = (κ′ + R_r)·ω, V_y = δ′·ω), its
    median over the run, the runs within `rtol` of each other merged into one level (their
    mean). Returns (ω₀ per sample, (segments, samples); the levels, ascending)."""
    w = np.asarray(samples["omega"], float)
    v = w * np.hypot(np.asarray(samples["kappa"], float) + rolling_radius,
                     np.asarray(samples["delta"], float))
    run = np.median(v, axis=-1) / rolling_radius
    order = np.argsort(run)
    group = np.zeros(len(run), int)
    g, start = 0, run[order[0]]
    for k in order[1:]:
        if run[k] > start * (1.0 + rtol):
            g, start = g + 1, run[k]
        group[k] = g
    group[order[0]] = 0
    levels = np.array([run[group == i].mean() for i in range(g + 1)])
    return np.broadcast_to(levels[group][:, None], w.shape).copy(), levels


def speed_powers(names, levels) -> dict:
    """name → why, for the speed columns that `levels` (the distinct ω₀ of the data) cannot
    determine: on k levels only ω₀¹…ω₀^(k−1) are independent of the constant."""
    k = len(levels)
    out = {}
    for n in names:
        _, block, i, _ = parse_name(n)
        if block in SPEED_BLOCKS + (SPEED_LY,) and i > k - 1:
            out[n] = (f"not identifiable: the data hold {k} speed level(s) (ω₀ "
                      + ", ".join(f"{w:.1f}" for w in levels)
                      + f" rad/s), so ω₀^{i} is a "
                      f"combination of ω₀^0..ω₀^{k - 1} (the speed test (3-54) needs runs at "
                      f"{i + 1} speeds or more)")
    return out


def speed_unit(output: str, block: str, i: int, j: int) -> str:
    """The unit of a speed coefficient: F/(m·(rad/s)^i·kN^j) (wdelta), F/((rad/s)^i·kN^j)
    (wone) or (F/N)/((rad/s)^i·kN^j) (wLy: it multiplies Ḟ_y/ω [N])."""
    top = "N·m" if output == "Mz" else "N"
    if block == SPEED_LY:
        top = "m" if output == "Mz" else "1"
    parts = (["m"] if block == "wdelta" else []) + [
        "rad/s" if i == 1 else f"(rad/s)^{i}"] + ([] if j == 0 else
                                                  ["kN" if j == 1 else f"kN^{j}"])
    return f"{top}/({'·'.join(parts)})" if len(parts) > 1 else f"{top}/{parts[0]}"


def speed_notes(output: str, reduced, levels) -> list[str]:
    """The report's notes of the speed test for one output: the speed terms the search kept
    (value ± σ, the data support a speed dependence) or none kept. `reduced`: the output's
    final coefficients (`bench.Coefficients`)."""
    kept = [(n, x, s) for n, x, s in zip(reduced.names, reduced.x, reduced.sigma, strict=True)
            if parse_name(n)[1] in SPEED_BLOCKS + (SPEED_LY,)]
    where = (f"{len(levels)} speed levels (ω₀ " + ", ".join(f"{w:.1f}" for w in levels)
             + " rad/s)")
    if len(levels) < 2:
        return [f"{output}: speed test (3-54) not possible: the data hold one speed level "
                f"(ω₀ {levels[0]:.1f} rad/s); it needs runs at two speeds or more."]
    if not kept:
        return [f"{output}: speed test (3-54) on {where}: no speed term is kept (every "
                "removal leaves the residual within the noise): the interaction model is "
                "speed-independent on these data, as the thesis finds (§3.4.5)."]
    terms = ", ".join(f"{n} = {x:.4g} ± {s:.2g}" for n, x, s in kept)
    return [f"{output}: speed test (3-54) on {where}: the data support a speed dependence "
            f"(kept: {terms}); these terms are in the report's rows and `reduced`, not in "
            "the returned polynomial `model`."]
