"""Specification quantities of a tyre model, macro-coefficients and similarity.

spec: tyre §2.1 (the carmaker's specifications), §2.2 (2-115…2-118, macro-coefficients),
§2.3 (2-119…2-125, similarity), §7 C items 12–13; CORRECTIONS 1 (shape factor), 2, 8.
Every derivative here is exact (JAX autodiff), never a finite difference.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike

__all__ = ["magic_formula", "macro_to_bcde", "bcde_to_macro", "similarity",
           "similarity_primitive", "specification", "SPEC_UNITS"]


def magic_formula(x: ArrayLike, B, C, D, E, Sh=0.0, Sv=0.0) -> Array:
    """Y = D·sin(C·atan(φ)) + S_v, φ = (1 − E)·B·(x + S_h) + E·atan(B·(x + S_h)) (2-115; the
    shift as in (B-9), CORRECTIONS 8)."""
    u = jnp.asarray(x) + Sh
    return D * jnp.sin(C * jnp.arctan((1.0 - E) * B * u + E * jnp.arctan(B * u))) + Sv


def macro_to_bcde(K, D, x_m, L, S_h=0.0, S_v=0.0, *, kind: str = "force"):
    """(B, C, D, E) from the specification quantities (2-116…2-118), with the corrected shape
    factor (CORRECTIONS 1): C = 2 − (2/π)·arcsin(L/D) for forces (1 < C < 2) and
    C = 2 + (2/π)·arcsin(−L/D) for M_z (2 < C < 3).

    **Arguments:** `K` slope at the centre (= BCD), `D` extremum above S_v, `x_m` abscissa of the
    extremum, `L` asymptote above S_v, `S_h`, `S_v` the centre's shifts (x + S_h convention);
    `kind` "force" or "moment". Any consistent units (the slope in Y per unit of x)."""
    if kind not in ("force", "moment"):
        raise ValueError(f"kind {kind!r}: 'force' or 'moment'")
    r = jnp.asarray(L) / D
    if kind == "force":
        C = 2.0 - (2.0 / math.pi) * jnp.arcsin(r)
    else:
        C = 2.0 + (2.0 / math.pi) * jnp.arcsin(-r)
    B = K / (C * D)
    bx = B * (x_m + S_h)
    E = (bx - jnp.tan(math.pi / (2.0 * C))) / (bx - jnp.arctan(bx))
    return B, C, jnp.asarray(D), E


def bcde_to_macro(B, C, D, E, S_h=0.0, S_v=0.0, *, newton_steps: int = 60):
    """(K, D, x_m, L) of a Magic Formula curve: K = BCD, L = D·sin(Cπ/2) (the asymptote above
    S_v), x_m solves C·atan(φ(x_m)) = π/2 (Newton from the E = 0 solution; NaN where C ≤ 1, no
    extremum). Inverse of `macro_to_bcde` for E < 1."""
    B, C, D, E = (jnp.asarray(v, dtype=float) for v in (B, C, D, E))
    target = jnp.tan(math.pi / (2.0 * jnp.where(C > 1.0, C, 2.0)))
    # solve (1 − E)·z + E·atan z = target for z = B(x_m + S_h): monotone increasing for E < 1
    z = target

    def step(z, _):
        f = (1.0 - E) * z + E * jnp.arctan(z) - target
        df = (1.0 - E) + E / (1.0 + z * z)
        return z - f / df, None

    z, _ = jax.lax.scan(step, z, None, length=newton_steps)
    x_m = jnp.where(C > 1.0, z / B - S_h, jnp.nan)
    return B * C * D, D, x_m, D * jnp.sin(C * math.pi / 2.0)


def similarity(delta, fy, mz, *, D_y, BCD_y, S_hy, S_vy, BCD_z, S_hz, S_vz):
    """The similarity normalisation (2-119…2-122, 2-125), in the (x + S_h) convention of (B-9)
    (CORRECTIONS 8: the thesis's (2-119) writes δ − S_h with the opposite sign of S_h):

    X̄ = BCD_y·(δ + S_hy)/D_y, F̄_y = (F_y − S_vy)/D_y, M̄_z = (M_z − S_vz)/(D_t·D_y) with
    D_t = BCD_z/BCD_y, and S̄_hMz = (BCD_y/D_y)·(S_hz − S_hy). Returns (X̄, F̄_y, M̄_z, S̄_hMz).
    """
    X = BCD_y * (jnp.asarray(delta) + S_hy) / D_y
    Dt = BCD_z / BCD_y
    return X, (fy - S_vy) / D_y, (mz - S_vz) / (Dt * D_y), (BCD_y / D_y) * (S_hz - S_hy)


def similarity_primitive(X, C, E, S=0.0):
    """P(X̄) = sin(C·atan[(1 − E)(X̄ + S)/C + E·atan((X̄ + S)/C)]) (2-123, 2-124): the F̄_y
    primitive with S = 0, the M̄_z one with S = S̄_hMz. F̄_y = P_Fy(X̄) exactly when C_y and
    E_y do not vary with load and camber. For M_z the identity is M̄_z = P_Mz(r·X̄, S = r·S̄_hMz)/r
    with r = D_t·D_y/D_z: the printed (2-124) (r = 1) holds only when D_z = D_t·D_y, i.e. when
    the M_z peak scales like the trail times the F_y peak (checked in the tests)."""
    u = (jnp.asarray(X) + S) / C
    return jnp.sin(C * jnp.arctan((1.0 - E) * u + E * jnp.arctan(u)))


# ------------------------------------------------------------------ specification quantities

SPEC_UNITS = {
    "fz": "N", "cornering_stiffness": "N/rad", "slip_stiffness": "N",
    "aligning_stiffness": "N·mm/rad", "pneumatic_trail": "mm", "camber_stiffness": "N/rad",
    "camber_torque_stiffness": "N·mm/rad", "fy_at_zero": "N", "mz_at_zero": "N·mm",
    "fx_at_zero": "N", "fy_peak": "N", "alpha_at_fy_peak": "rad", "mz_peak": "N·mm",
    "alpha_at_mz_peak": "rad", "fx_peak": "N", "kappa_at_fx_peak": "-", "mu_y": "-",
    "mu_x": "-",
}
"""Units of the columns `specification` returns."""


def _curves(model, pressure):
    """(fx(κ, fz), fy(α, γ, fz), mz(α, γ, fz)) in library units, pure slip
    (`AbstractTyre.forces`)."""
    def fx(k, fz):
        return model.forces(fz, k, 0.0, 0.0, pressure=pressure, combined=False,
                            channels=("FX",))["FX"]

    def fy(a, g, fz):
        return model.forces(fz, 0.0, a, g, pressure=pressure, combined=False,
                            channels=("FY",))["FY"]

    def mz(a, g, fz):
        return model.forces(fz, 0.0, a, g, pressure=pressure, combined=False,
                            channels=("MZ",))["MZ"]
    return fx, fy, mz


def _extremum(f, alpha_max, n_grid, newton_steps):
    """The first extremum of f on (0, alpha_max] in the direction of its slope at 0 (NaN when the
    largest |f| is at the end of the range: no peak inside), refined by Newton on f'."""
    grid = jnp.linspace(0.0, alpha_max, n_grid)
    s = jnp.sign(jax.grad(f)(0.0))
    vals = jax.vmap(f)(grid) * s
    i = jnp.argmax(vals)
    df = jax.grad(f)
    d2f = jax.grad(df)

    def step(a, _):
        a_new = a - df(a) / d2f(a)
        h = alpha_max / (n_grid - 1)
        return jnp.clip(a_new, grid[i] - h, grid[i] + h), None

    a, _ = jax.lax.scan(step, grid[i], None, length=newton_steps)
    inside = (i > 0) & (i < n_grid - 1)
    return jnp.where(inside, f(a), jnp.nan), jnp.where(inside, a, jnp.nan)


def specification(model, fz: ArrayLike, *, pressure=None, alpha_max: float = 0.35,
                  kappa_max: float = 0.5, n_grid: int = 351, newton_steps: int = 8
                  ) -> dict[str, Array]:
    """The vehicle-dynamics specification quantities at each load (spec §2.1, §7 C item 13), pure
    slip, camber 0, library units (`SPEC_UNITS`):

    - `cornering_stiffness` dF_y/dα, `aligning_stiffness` dM_z/dα, `slip_stiffness` dF_x/dκ,
      all at zero slip (exact derivatives);
    - `pneumatic_trail` = −(dM_z/dα)/(dF_y/dα) [mm] (positive for a usual tyre in ISO-W and PSA
      signs; the thesis's D_t = BCD_Mz/BCD_Fy of (2-122) is its negative, in its units);
    - `camber_stiffness` dF_y/dγ, `camber_torque_stiffness` dM_z/dγ at zero slip and camber;
    - `fy_at_zero`, `mz_at_zero`, `fx_at_zero`: values at zero slip and camber (the "pull");
    - `fy_peak`, `alpha_at_fy_peak`: the F_y extremum for α in (0, alpha_max] on the side of
      the slope, NaN when there is none inside (e.g. the thesis's sets with C = 1, CORRECTIONS 2);
      `mz_peak`, `alpha_at_mz_peak`: the same for M_z (the thesis's "minimum M_z" in PSA signs);
    - `fx_peak`, `kappa_at_fx_peak`: the braking F_x extremum for κ in [−kappa_max, 0) (braking:
      the side every property file is measured on; a file with KPUMAX = 0 has no driving side),
      NaN when there is none inside; saturated at the file's KPUMIN as `evaluate` is;
    - `mu_y` = |fy_peak|/F_z and `mu_x` = |fx_peak|/F_z: the friction coefficients (the peak
      force per unit load; NaN where the peak is).

    `model`: a `MagicFormula6` (pressure [Pa], default INFLPRES) or a `MagicFormula89`.
    `fz` [N]: one load or an array of loads (the spec asks for at least two).
    """
    fx, fy, mz = _curves(model, pressure)

    def one(load):
        fy_a = lambda a: fy(a, 0.0, load)  # noqa: E731
        mz_a = lambda a: mz(a, 0.0, load)  # noqa: E731
        ky = jax.grad(fy_a)(0.0)
        kz = jax.grad(mz_a)(0.0)
        fpk, apk = _extremum(fy_a, alpha_max, n_grid, newton_steps)
        mpk, ampk = _extremum(mz_a, alpha_max, n_grid, newton_steps)
        xpk, kpk = _extremum(lambda k: fx(-k, load), kappa_max, n_grid, newton_steps)
        return {
            "fz": load, "cornering_stiffness": ky, "slip_stiffness": jax.grad(fx)(0.0, load),
            "aligning_stiffness": kz, "pneumatic_trail": -kz / ky,
            "camber_stiffness": jax.grad(fy, argnums=1)(0.0, 0.0, load),
            "camber_torque_stiffness": jax.grad(mz, argnums=1)(0.0, 0.0, load),
            "fy_at_zero": fy_a(0.0), "mz_at_zero": mz_a(0.0), "fx_at_zero": fx(0.0, load),
            "fy_peak": fpk, "alpha_at_fy_peak": apk, "mz_peak": mpk, "alpha_at_mz_peak": ampk,
            "fx_peak": xpk, "kappa_at_fx_peak": -kpk, "mu_y": jnp.abs(fpk) / load,
            "mu_x": jnp.abs(xpk) / load,
        }

    fz = jnp.atleast_1d(jnp.asarray(fz, dtype=float))
    return jax.jit(jax.vmap(one))(fz)


def to_rows(spec: dict[str, Array]) -> list[dict[str, float]]:
    """The `specification` columns as rows of Python floats (for tables and JSON)."""
    cols = {k: np.asarray(v) for k, v in spec.items()}
    return [{k: float(v[i]) for k, v in cols.items()} for i in range(len(cols["fz"]))]
