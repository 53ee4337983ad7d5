"""Polynomial (linear-in-parameter) tyre models P_{F,X} of the thesis's chapter 3.

spec: tyre §3.1–3.5 (3-16…3-28, 3-55…3-71), Tables 5 and 10, §7 D items 14–16 and 19. Units
of the thesis (spec §0.3): F_z in **kN**, δ′ and κ′ in **m**, φ′ and γ in **rad**, F_x, F_y in
N, M_z in **N·m**; Ḟ_y/ω in N (N/s over rad/s). `bench` converts library units at the edge.

Each dependence of F ∈ {Fx, Fy, Mz} on an input X is P_{F,X} = Σ_{i=1..n_X} Σ_{j=m_X..3}
X^i·F_z^j·b_{F,X,i,j} (3-22), with m_X = 1 for the deformation inputs (no contact patch, no
force at F_z = 0) and 0 for γ and the offset "one" (3-20, 3-21). The parameter of the column
X^i·F_z^j is named `b_<F>_<X>_<i>_<j>` (e.g. `b_Fy_delta_5_2`), as in `annex_g`.

Inputs (keys of the input dict, arrays with one sample axis): `fz` [kN], `kappa` κ′ [m],
`delta` δ′ [m], `phi` φ′ [rad], `gamma` [rad], `pi_gamma_vx` γ·V_x/ω [rad·m],
`pi_gamma_bdot` γ·β̇/ω [rad²], `pi_gamma2_bdot` γ²·β̇/ω [rad³]; for the contact terms
`fydot_w` Ḟ_y/ω [N], `fy`, `fx` [N]. The constant input of the offset block is built in.

Extra terms of the identification models (spec §3.5):
- `ly=True`: the relaxation term (Ḟ_y/ω)·∂P_{F,δ′}/∂δ′ (3-61, 3-62, 3-70, 3-71): columns
  (Ḟ_y/ω)·(k+1)·δ′^k·F_z^j named `b_<F>_Ly_<k>_<j>` (k = i − 1, the Annex G row index); in step 1
  they are free, standing in for b_{F,δ′,k+1,j}/K_y;
- `p2=True` (M_z): the coupling column −F_y·F_x, parameter `b_Mz_P2_0_0` = K_y⁻¹ (3-69).

Structures: `APRIORI` (Table 5, plus P_{Fy,π(γ,β̇)} of degree 3, which (3-17) and §3.4.1 include
and Table 5 prints as 0) and `JUST_NECESSARY` (Table 10: δ′, φ′, γ of degree 5 and the offset).
"""

import math
from collections.abc import Mapping

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..errors import InputError
from ..lsq import algebra
from . import annex_g

__all__ = ["APRIORI", "JUST_NECESSARY", "STRUCTURES", "DEFORMATION_INPUTS", "INPUT_UNITS",
           "PolynomialModel", "regressor_model", "parse_name", "table6_domains"]

DEFORMATION_INPUTS = ("kappa", "delta", "phi", "pi_gamma_vx", "pi_gamma_bdot", "pi_gamma2_bdot")
"""Inputs whose load polynomial vanishes at F_z = 0 (j = 1…3); `gamma` and `one` have j = 0…3."""
INPUT_UNITS = {"fz": "kN", "kappa": "m", "delta": "m", "phi": "rad", "gamma": "rad",
               "pi_gamma_vx": "rad·m", "pi_gamma_bdot": "rad²", "pi_gamma2_bdot": "rad³",
               "fydot_w": "N", "fy": "N", "fx": "N"}

APRIORI = {
    "Fx": {"kappa": 7, "pi_gamma_bdot": 3, "gamma": 5, "one": 1},
    "Fy": {"delta": 7, "phi": 7, "pi_gamma_bdot": 3, "gamma": 5, "one": 1},
    "Mz": {"delta": 7, "phi": 7, "pi_gamma_vx": 3, "pi_gamma2_bdot": 3, "gamma": 5, "one": 1},
}
"""Degrees n_X of Table 5 (spec §3.2)."""
JUST_NECESSARY = {
    "Fx": {"one": 1},
    "Fy": {"delta": 5, "phi": 5, "gamma": 5, "one": 1},
    "Mz": {"delta": 5, "phi": 5, "gamma": 5, "one": 1},
}
"""Degrees of Table 10 (spec §4.5); F_x reduced to its load polynomial (3-48)."""
STRUCTURES = {"apriori": APRIORI, "just-necessary": JUST_NECESSARY}


def parse_name(name: str) -> tuple[str, str, int, int]:
    """"b_Fy_delta_5_2" → ("Fy", "delta", 5, 2)."""
    parts = name.split("_")
    if len(parts) < 5 or parts[0] != "b":
        raise InputError(f"{name!r} is not a polynomial coefficient name b_<F>_<X>_<i>_<j>")
    return parts[1], "_".join(parts[2:-2]), int(parts[-2]), int(parts[-1])


def _block(output: str, key: str, degree: int) -> algebra.LinearModel:
    lo = 1 if key in DEFORMATION_INPUTS else 0
    if key == "one":
        base = algebra.LinearModel(("1",), ("fz",), lambda u: jnp.ones_like(u["fz"])[..., None])
        powers_x = (1,)
    else:
        if key not in DEFORMATION_INPUTS + ("gamma",):
            raise InputError(f"unknown input block {key!r}; known: "
                             f"{DEFORMATION_INPUTS + ('gamma', 'one')}")
        powers_x = tuple(range(1, degree + 1))
        base = algebra.monomials(key, powers_x, name="{i}")
    load = algebra.monomials("fz", range(lo, 4), name="{i}")
    names = [f"b_{output}_{key}_{i}_{j}" for i in powers_x for j in range(lo, 4)]
    model = base.product(load)
    return model.rename(dict(zip(model.names, names, strict=True)))


def regressor_model(output: str, degrees: Mapping[str, int], *, ly: bool = False,
                    p2: bool = False) -> algebra.LinearModel:
    """The LIP model of `output` with the given block degrees (spec §3.2 (3-25…3-28)), plus the
    relaxation (`ly`) and coupling (`p2`) columns of §3.5."""
    if output not in APRIORI:
        raise InputError(f"output {output!r}: one of Fx, Fy, Mz")
    blocks = [_block(output, k, int(n)) for k, n in degrees.items() if int(n) > 0]
    if not blocks:
        raise InputError(f"no block of degree > 0 in {dict(degrees)}")
    model = blocks[0]
    for b in blocks[1:]:
        model = model + b
    if ly:
        n = int(degrees.get("delta", 0))
        if n == 0:
            raise InputError("the relaxation term needs a δ′ block (degree > 0)")
        d = _block(output, "delta", n).derivative("delta")
        fdot = algebra.column("fydot_w")
        rel = d.product(fdot, name=lambda a, b: a)
        rel = rel.rename(lambda s: _ly_name(s))
        model = model + rel
    if p2:
        model = model + algebra.LinearModel(
            (f"b_{output}_P2_0_0",), ("fy", "fx"), lambda u: (-u["fy"] * u["fx"])[..., None])
    return model


def _ly_name(name: str) -> str:
    out, _, i, j = parse_name(name)
    return f"b_{out}_Ly_{i - 1}_{j}"


class PolynomialModel(eqx.Module):
    """A polynomial tyre model with its coefficients (spec §3.2): F = W(u)·b.

    **Fields:** `b` (p,) coefficients (thesis units); static: `output`, `degrees` (block →
    degree), `ly`, `p2` and the parameter `names`.
    """

    b: Float[Array, " p"]
    output: str = eqx.field(static=True)
    degrees: tuple[tuple[str, int], ...] = eqx.field(static=True)
    ly: bool = eqx.field(static=True)
    p2: bool = eqx.field(static=True)
    names: tuple[str, ...] = eqx.field(static=True)

    @classmethod
    def create(cls, output: str, degrees: Mapping[str, int] | str = "apriori", *,
               ly: bool = False, p2: bool = False,
               values: Mapping[str, float] | None = None) -> "PolynomialModel":
        """The model of `output` with `degrees` (a mapping or "apriori" / "just-necessary") and
        coefficients `values` by name (others 0; an unknown name is an error)."""
        if isinstance(degrees, str):
            if degrees not in STRUCTURES:
                raise InputError(f"structure {degrees!r}: one of {tuple(STRUCTURES)}")
            degrees = STRUCTURES[degrees][output]
        degrees = tuple((k, int(v)) for k, v in degrees.items())
        names = regressor_model(output, dict(degrees), ly=ly, p2=p2).names
        b = np.zeros(len(names))
        for k, v in (values or {}).items():
            if k not in names:
                raise InputError(f"coefficient {k!r} is not in the model of {output} with "
                                 f"degrees {dict(degrees)} (ly={ly}, p2={p2})")
            b[names.index(k)] = float(v)
        return cls(jnp.asarray(b), output, degrees, ly, p2, names)

    @classmethod
    def from_annex_g(cls, tyre: str, pressure: float, output: str, *,
                     degrees: Mapping[str, int] | str = "apriori", ly: bool = False
                     ) -> "PolynomialModel":
        """The interaction model F_pneu of one Annex G table (Tables 34–57); `ly=True` keeps the
        table's relaxation coefficients too (spec §4.7)."""
        values = annex_g.coefficients(tyre, pressure, output, include_ly=ly, include_p2=False)
        return cls.create(output, degrees, ly=ly, values=values)

    @property
    def model(self) -> algebra.LinearModel:
        return regressor_model(self.output, dict(self.degrees), ly=self.ly, p2=self.p2)

    def values(self) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.names, np.asarray(self.b), strict=True)}

    def __call__(self, u: Mapping[str, ArrayLike]) -> Float[Array, " n"]:
        """F(u) (N or N·m)."""
        return self.model.regressor(_complete(u, self.model.inputs)) @ self.b

    def pneu(self) -> "PolynomialModel":
        """The interaction part F_pneu (the model without its Ly and P2 columns)."""
        keep = [k for k, n in enumerate(self.names) if parse_name(n)[1] not in ("Ly", "P2")]
        return PolynomialModel(self.b[np.array(keep)], self.output, self.degrees, False, False,
                               tuple(self.names[k] for k in keep))

    def derivative(self, u: Mapping[str, ArrayLike], key: str = "delta") -> Float[Array, " n"]:
        """∂F/∂u_key at u (exact)."""
        return self.model.derivative(key).regressor(_complete(u, self.model.inputs)) @ self.b

    def input_polynomial(self, fz: float, key: str = "delta") -> np.ndarray:
        """The ascending coefficients c_i(F_z) = Σ_j b_{F,key,i,j}·F_z^j of P_{F,key} at one load
        [kN] (c_0 = 0): the response to `key` alone (spec §3.7)."""
        n = dict(self.degrees).get(key, 0)
        c = np.zeros(n + 1)
        for name, v in zip(self.names, np.asarray(self.b), strict=True):
            out, block, i, j = parse_name(name)
            if block == key:
                c[i] += v * fz**j
        return c

    def load_polynomial(self, key: str, i: int) -> np.ndarray:
        """Ascending coefficients in F_z of c_{F,key,i}(F_z) (spec (3-20), (3-21))."""
        c = np.zeros(4)
        for name, v in zip(self.names, np.asarray(self.b), strict=True):
            _, block, ii, j = parse_name(name)
            if block == key and ii == i:
                c[j] += v
        return c

    def cornering_stiffness(self, fz: ArrayLike) -> np.ndarray:
        """c_{F,δ′,1}(F_z) = ∂P_{F,δ′}/∂δ′ at δ′ = 0 (3-89), [N/m] or [N·m/m]; F_z [kN]."""
        return algebra.poly_eval(self.load_polynomial("delta", 1), fz)

    def extrema(self, fz: float, key: str = "delta", lo: float = -math.inf,
                hi: float = math.inf) -> list[tuple[float, float, str]]:
        """Extrema of the response to `key` alone at load `fz` [kN] inside [lo, hi] (Annex C.2,
        spec §3.8 (b)): [(x, value, "max" | "min" | "flat"), ...]."""
        return algebra.extrema(self.input_polynomial(fz, key), lo, hi)


def _complete(u, keys):
    u = dict(u)
    if "fz" not in u:
        raise InputError("input 'fz' [kN] is missing")
    fz = jnp.asarray(u["fz"], dtype=float)
    for k in keys:
        if k not in u:
            u[k] = jnp.zeros_like(fz)
    return u


def table6_domains(rolling_radius: float = 0.294) -> dict[str, dict[str, tuple[float, float]]]:
    """The useful δ′ domains [m] of Table 6 mapped from its δ column with δ′ = −R_r·tan δ
    (CORRECTIONS 3): the F_y maximum at δ′ ∈ [−6, −3]·10⁻² (δ ∈ [6, 12]°) and the M_z maximum
    at δ′ ∈ [0, 3]·10⁻² (δ ∈ [−6, 0]°)."""
    def dp(d_lo, d_hi):
        a, b = (-rolling_radius * math.tan(math.radians(d)) for d in (d_lo, d_hi))
        return (min(a, b), max(a, b))
    return {"Fy": {"zero": dp(-1, 1), "max": dp(6, 12), "min": dp(-12, -6)},
            "Mz": {"zero": dp(-1, 1), "max": dp(-6, 0), "min": dp(0, 6)}}

