"""Algebra of linear-in-parameter models (spec: tyre §3.1, §3.2, §7 D item 15; thesis Annex C).

A linear-in-parameter (LIP) model is y = W(u)·X: a regressor W, a function of the inputs u
(a dict of arrays with one leading sample axis), and named parameters X. Every column of W knows
the name of the coefficient it multiplies, so fits, reports and the Annex G tables speak the
same names.

- **sum** (Annex C.1): `a + b` concatenates the columns, W_c = [W_a W_b], X_c = [X_a; X_b];
- **product** (Annex C.1): `a * b` is the face-splitting (row-wise Kronecker) product,
  W_c = W_a ⊗ W_b (every pairwise element-wise product of a column of W_a and a column of W_b),
  X_c = (X_aᵀ ⊗ X_bᵀ)ᵀ: the coefficient of the product column (k, l) is X_a,k·X_b,l when the
  product of the two models is itself the model (it is the general LIP model otherwise);
- **derivative** with respect to one input, `model.derivative("x")`: ∂W/∂u_x, the regressor of
  ∂y/∂u_x with the same parameters (forward-mode autodiff: exact for any model, the Annex C.2
  rule d/dx Σ c_i x^i = Σ (i+1) c_{i+1} x^i for monomials, which `poly_derivative` gives on
  coefficient arrays);
- **extrema** of a one-variable polynomial: `extrema(c, lo, hi)` are the real roots of its
  derivative inside [lo, hi], each classified as a maximum (second derivative < 0), a minimum
  (> 0) or flat (= 0), spec §3.8 (b).

```python
from diffsusp.lsq import algebra
p = algebra.monomials("d", range(1, 6), name="d{}")        # d, d², ..., d⁵
q = algebra.monomials("fz", range(1, 4), name="fz{}")      # fz, fz², fz³
model = (p * q).rename(lambda n: n.replace("*", "_"))       # 15 columns d^i·fz^j
W = model.regressor({"d": d, "fz": fz})                      # (n, 15)
fit = lsq.solve(W, y, names=model.names)
```
"""

from collections.abc import Callable, Iterable, Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..errors import InputError

__all__ = ["LinearModel", "monomials", "column", "poly_derivative", "poly_eval", "real_roots",
           "extrema"]

Inputs = Mapping[str, ArrayLike]


class LinearModel(eqx.Module):
    """y = W(u)·X with named parameters (spec: tyre §3.1, Annex C).

    **Fields:** `names` (one per column of W), `inputs` (the input keys the regressor reads),
    `function` (u → W, (n, p)). Build with `monomials`, `column`, `+`, `*`.
    """

    names: tuple[str, ...] = eqx.field(static=True)
    inputs: tuple[str, ...] = eqx.field(static=True)
    function: Callable = eqx.field(static=True)

    def __check_init__(self):
        dup = sorted({n for n in self.names if self.names.count(n) > 1})
        if dup:
            raise InputError(f"parameter names must be unique; repeated: {dup}. Rename one "
                             "model's parameters (LinearModel.rename) before adding them.")

    @property
    def p(self) -> int:
        return len(self.names)

    def regressor(self, u: Inputs) -> Float[Array, "n p"]:
        """W(u), (n, p): one row per sample."""
        missing = [k for k in self.inputs if k not in u]
        if missing:
            raise InputError(f"input(s) {missing} missing; the model reads {list(self.inputs)}.")
        return self.function({k: jnp.asarray(u[k], dtype=float) for k in self.inputs})

    def __call__(self, u: Inputs, x: ArrayLike) -> Float[Array, " n"]:
        """y = W(u)·x."""
        return self.regressor(u) @ jnp.asarray(x, dtype=float)

    def __add__(self, other: "LinearModel") -> "LinearModel":
        """Sum of two LIP models: W_c = [W_a W_b], X_c = [X_a; X_b] (Annex C.1)."""
        fa, fb = self.function, other.function

        def function(u):
            return jnp.concatenate([fa(u), fb(u)], axis=-1)

        return LinearModel(self.names + other.names, _union(self.inputs, other.inputs), function)

    def __mul__(self, other: "LinearModel") -> "LinearModel":
        """Face-splitting product: column (k, l) = W_a[:, k]·W_b[:, l], row-major in (k, l), named
        "a_k*b_l" (Annex C.1)."""
        return self.product(other)

    def product(self, other: "LinearModel",
                name: Callable[[str, str], str] = "{}*{}".format) -> "LinearModel":
        """`a * b` with the product columns named `name(a_k, b_l)`."""
        fa, fb = self.function, other.function

        def function(u):
            A, B = fa(u), fb(u)
            return (A[..., :, None] * B[..., None, :]).reshape(A.shape[:-1] + (-1,))

        names = tuple(name(a, b) for a in self.names for b in other.names)
        return LinearModel(names, _union(self.inputs, other.inputs), function)

    def rename(self, rule: Callable[[str], str] | Mapping[str, str]) -> "LinearModel":
        """The same model with parameters renamed (a function or a mapping old → new)."""
        f = rule.get if isinstance(rule, Mapping) else rule
        names = tuple((f(n, n) if isinstance(rule, Mapping) else f(n)) for n in self.names)
        return LinearModel(names, self.inputs, self.function)

    def select(self, keep: Iterable[str]) -> "LinearModel":
        """The sub-model of the named columns (in the given order)."""
        keep = tuple(keep)
        unknown = [k for k in keep if k not in self.names]
        if unknown:
            raise InputError(f"unknown parameter(s) {unknown}; the model has {list(self.names)}")
        idx = np.array([self.names.index(k) for k in keep], dtype=int)
        f = self.function
        return LinearModel(keep, self.inputs, lambda u: f(u)[..., idx])

    def derivative(self, key: str) -> "LinearModel":
        """The regressor of ∂y/∂u_key, same parameters: ∂W/∂u_key (forward-mode, exact)."""
        if key not in self.inputs:
            raise InputError(f"the model does not read input {key!r}; it reads "
                             f"{list(self.inputs)}")
        f = self.function

        def function(u):
            x = u[key]
            return jax.jvp(lambda v: f({**u, key: v}), (x,), (jnp.ones_like(x),))[1]

        return LinearModel(self.names, self.inputs, function)


def _union(a: tuple[str, ...], b: tuple[str, ...]) -> tuple[str, ...]:
    return a + tuple(k for k in b if k not in a)


def monomials(key: str, powers: Iterable[int], *, name: str = "{key}^{i}") -> LinearModel:
    """The model Σ_i u_key^i·X_i over `powers` (0 gives the constant column); parameter names
    `name.format(key=key, i=i)`."""
    powers = tuple(int(i) for i in powers)
    if any(i < 0 for i in powers):
        raise InputError(f"powers must be ≥ 0; got {powers}")
    pw = np.asarray(powers, dtype=float)

    def function(u):
        x = u[key]
        return x[..., None] ** pw

    return LinearModel(tuple(name.format(key=key, i=i) for i in powers), (key,), function)


def column(key: str, name: str | None = None) -> LinearModel:
    """A single column, the input itself: y = u_key·X."""
    return LinearModel((name or key,), (key,), lambda u: u[key][..., None])


# --------------------------------------------------------------------------------------------
# One-variable polynomials: coefficients in ascending powers, c[i] multiplies x^i.


def poly_derivative(c: ArrayLike) -> np.ndarray:
    """d/dx Σ c_i x^i = Σ (i+1)·c_{i+1}·x^i (Annex C.2); ascending coefficients."""
    c = np.asarray(c, dtype=float)
    if c.shape[-1] <= 1:
        return np.zeros(c.shape[:-1] + (1,))
    return c[..., 1:] * np.arange(1, c.shape[-1])


def poly_eval(c: ArrayLike, x: ArrayLike) -> np.ndarray:
    """Σ c_i x^i (ascending coefficients), NumPy."""
    c = np.asarray(c, dtype=float)
    return np.polynomial.polynomial.polyval(np.asarray(x, dtype=float), c)


def real_roots(c: ArrayLike, *, rtol: float = 1e-7) -> np.ndarray:
    """The real roots of Σ c_i x^i (eigenvalues of the companion matrix; a root counts as real
    when |Im| ≤ rtol·max(1, |root|)), sorted."""
    c = np.trim_zeros(np.asarray(c, dtype=float), "b")
    if c.size <= 1:
        return np.zeros(0)
    r = np.polynomial.polynomial.polyroots(c)
    real = np.abs(r.imag) <= rtol * np.maximum(1.0, np.abs(r))
    return np.sort(r.real[real])


def extrema(c: ArrayLike, lo: float = -np.inf, hi: float = np.inf
            ) -> list[tuple[float, float, str]]:
    """The extrema of Σ c_i x^i inside [lo, hi]: (x, value, "max" | "min" | "flat") for every
    real root of the derivative there, classified by the sign of the second derivative
    (spec §3.8 (b): maxima where d²P/dx² < 0, minima where > 0)."""
    d1 = poly_derivative(c)
    d2 = poly_derivative(d1)
    out = []
    for x in real_roots(d1):
        if lo <= x <= hi:
            s = float(poly_eval(d2, x))
            scale = float(np.max(np.abs(d2))) * max(1.0, abs(x)) ** (len(d2) - 1)
            kind = "flat" if abs(s) <= 1e-12 * scale else ("max" if s < 0 else "min")
            out.append((float(x), float(poly_eval(c, x)), kind))
    return out
