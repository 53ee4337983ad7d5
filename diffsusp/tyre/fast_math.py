"""Vectorisable float64 arctan, sin, cos, tan and sqrt for the Magic Formula's hot loops.

XLA's CPU backend evaluates float64 `atan`, `sin`, `cos` and `tan` by a scalar call per element
(CPU time per element on the project's machine: atan 9–10 ns, sin, cos, tan 19–20 ns, against
under 1 ns for a vectorised multiply-add, exp or division), and a combined-slip F_x, F_y, M_z
evaluation of MF 6.1 calls them about 36 times. These are the Cephes double-precision
algorithms (S. L. Moshier, Cephes Math Library 2.8: `atan.c`, `sin.c`) written with jnp
arithmetic and `where` branches, so that XLA fuses and LLVM vectorises them: range reduction,
then a rational (atan) or polynomial (sin, cos) approximation; relative error about 1e-16
(tests/test_tyre_mf6.py), far below the 1e-10 the tyre tests ask for. Each is about 2 ns per
element alone.

Measured with `benchmarks/tyre.py`: MF 6.1 combined F_x, F_y, M_z costs 2.4× less CPU time per
point with these than with XLA's calls (545 → 230 ns), not the 10× the functions alone
promise — a loop fusion that also holds a float64 `sqrt` is not vectorised (one Magic Formula
cosine term with a sqrt in its B factor: 49 ns per element against 9 ns without), hence `sqrt`
here (for the equivalent slips) and `cos_arctan` for 1/√(1 + x²) (a float32 reciprocal square
root refined by Newton steps: 245 → 213 ns per point against cos(arctan x));
what is left is the fusion structure XLA picks for the three outputs.
The program they make compiles about 2.5× slower, so `mf6` uses them only for batches of
`mf6.FAST_MATH_POINTS` points or more.

Each has a custom JVP with the exact derivative (1/(1 + x²), cos, −sin, 1 + tan², 1/(2√x))
written with these same functions, so derivatives of any order are those of the exact
functions, not of the approximations, and no `where` branch leaks a NaN into a gradient.

Valid for |x| < 1e8 (sin, cos, tan: the three-part Cody–Waite reduction by π/4); the Magic
Formula's arguments are a few radians at most.
"""

import math

import jax
import jax.numpy as jnp

__all__ = ["arctan", "cos", "cos_arctan", "sin", "sqrt", "tan"]

# ---- arctan (Cephes atan.c)
_T3P8 = 2.41421356237309504880  # tan(3π/8)
_MOREBITS = 6.123233995736765886130e-17
_P = (-8.750608600031904122785e-1, -1.615753718733365076637e1, -7.500855792314704667340e1,
      -1.228866684490136173410e2, -6.485021904942025371773e1)
_Q = (2.485846490142306297962e1, 1.650270098316988542046e2, 4.328810604912902668951e2,
      4.853903996359136964868e2, 1.945506571482613964425e2)


def _horner(z, coefficients, leading_one=False):
    acc = z + coefficients[0] if leading_one else coefficients[0]
    for c in coefficients[1:]:
        acc = acc * z + c
    return acc


@jax.custom_jvp
def arctan(x):
    """arctan x (float64, vectorised; Cephes atan.c)."""
    a = jnp.abs(x)
    big = a > _T3P8
    mid = a > 0.66
    # reduced argument: −1/a (big), (a − 1)/(a + 1) (mid), a; the unselected branches are
    # finite for finite a except −1/0, which `where` discards
    safe = jnp.where(big, a, 1.0)
    r = jnp.where(big, -1.0 / safe, jnp.where(mid, (a - 1.0) / (a + 1.0), a))
    base = jnp.where(big, math.pi / 2, jnp.where(mid, math.pi / 4, 0.0))
    extra = jnp.where(big, _MOREBITS, jnp.where(mid, 0.5 * _MOREBITS, 0.0))
    z = r * r
    y = base + (r + r * (z * _horner(z, _P) / _horner(z, _Q, leading_one=True)) + extra)
    return jnp.where(x < 0, -y, y)


@arctan.defjvp
def _arctan_jvp(primals, tangents):
    (x,), (t,) = primals, tangents
    return arctan(x), t / (1.0 + x * x)


# ---- sin, cos (Cephes sin.c)
_DP1 = 7.85398125648498535156e-1
_DP2 = 3.77489470793079817668e-8
_DP3 = 2.69515142907905952645e-15
_SIN = (1.58962301576546568060e-10, -2.50507477628578072866e-8, 2.75573136213857245213e-6,
        -1.98412698295895385996e-4, 8.33333333332211858878e-3, -1.66666666666666307295e-1)
_COS = (-1.13585365213876817300e-11, 2.08757008419747316778e-9, -2.75573141792967388112e-7,
        2.48015872888517045348e-5, -1.38888888888730564116e-3, 4.16666666666665929218e-2)


def _reduce(x):
    """|x| = j·π/4 + z with j even (mod 8) and |z| ≤ π/4: (z, j mod 8)."""
    a = jnp.abs(x)
    y = jnp.floor(a * (4.0 / math.pi))
    y = 2.0 * jnp.floor(0.5 * y + 0.5)  # to the even multiple (floor, not mod: mod is a libm call)
    j = y - 8.0 * jnp.floor(0.125 * y)
    z = ((a - y * _DP1) - y * _DP2) - y * _DP3
    return z, j


def _sin_poly(z, zz):
    return z + z * zz * _horner(zz, _SIN)


def _cos_poly(zz):
    return 1.0 - 0.5 * zz + zz * zz * _horner(zz, _COS)


@jax.custom_jvp
def sin(x):
    """sin x (float64, vectorised; Cephes sin.c)."""
    z, j = _reduce(x)
    zz = z * z
    # j = 0: sin z; 2: cos z; 4: −sin z; 6: −cos z
    v = jnp.where((j == 2.0) | (j == 6.0), _cos_poly(zz), _sin_poly(z, zz))
    v = jnp.where(j >= 4.0, -v, v)
    return jnp.where(x < 0, -v, v)


@jax.custom_jvp
def cos(x):
    """cos x (float64, vectorised; Cephes sin.c)."""
    z, j = _reduce(x)
    zz = z * z
    # j = 0: cos z; 2: −sin z; 4: −cos z; 6: sin z
    v = jnp.where((j == 2.0) | (j == 6.0), _sin_poly(z, zz), _cos_poly(zz))
    return jnp.where((j == 2.0) | (j == 4.0), -v, v)


@sin.defjvp
def _sin_jvp(primals, tangents):
    (x,), (t,) = primals, tangents
    return sin(x), cos(x) * t


@cos.defjvp
def _cos_jvp(primals, tangents):
    (x,), (t,) = primals, tangents
    return cos(x), -sin(x) * t


@jax.custom_jvp
def tan(x):
    """tan x = sin x / cos x (float64, vectorised)."""
    z, j = _reduce(x)
    zz = z * z
    s, c = _sin_poly(z, zz), _cos_poly(zz)
    odd = (j == 2.0) | (j == 6.0)  # tan(z + π/2) = −cot z
    v = jnp.where(odd, -c / s, s / c)
    return jnp.where(x < 0, -v, v)


@tan.defjvp
def _tan_jvp(primals, tangents):
    (x,), (t,) = primals, tangents
    y = tan(x)
    return y, (1.0 + y * y) * t


@jax.custom_jvp
def sqrt(x):
    """√x (float64) for 1e-30 ≤ x ≤ 1e30: a float32 reciprocal square root refined by three
    Newton steps (relative error about 1e-16). Outside: 0 below 1e-30 (an absolute error below
    1e-15) and √(1e30) above 1e30 — enough for the Magic Formula's equivalent slips
    atan(√(tan²α + (K_xκ/K_yα)²κ²)), the only use. XLA's float64 sqrt stops LLVM from
    vectorising a loop fusion that also holds these functions (measured: one Magic Formula
    cosine term with a sqrt in its B factor, 49 ns per element against 9 ns without)."""
    positive = x >= 1e-30
    safe = jnp.where(positive, jnp.minimum(x, 1e30), 1.0)
    y = jax.lax.rsqrt(safe.astype(jnp.float32)).astype(safe.dtype)
    for _ in range(3):
        y = y * (1.5 - 0.5 * safe * y * y)
    return jnp.where(positive, safe * y, 0.0)


@sqrt.defjvp
def _sqrt_jvp(primals, tangents):
    (x,), (t,) = primals, tangents
    y = sqrt(x)
    return y, t * 0.5 / y


@jax.custom_jvp
def cos_arctan(x):
    """cos(atan x) = 1/√(1 + x²) (float64, |x| ≤ 1e15): a float32 reciprocal square root refined
    by three Newton steps, multiply-adds only (relative error about 1e-16), cheaper than cos of
    arctan and, unlike XLA's float64 sqrt, vectorised inside a loop fusion."""
    a = 1.0 + jnp.minimum(x * x, 1e30)
    y = jax.lax.rsqrt(a.astype(jnp.float32)).astype(a.dtype)
    for _ in range(3):
        y = y * (1.5 - 0.5 * a * y * y)
    return y


@cos_arctan.defjvp
def _cos_arctan_jvp(primals, tangents):
    (x,), (t,) = primals, tangents
    y = cos_arctan(x)
    return y, -x * y * y * y * t
