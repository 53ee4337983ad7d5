"""Set-membership identification of a factorised polynomial (thesis Annex A, §A.3; §1.3.4).

A factorised polynomial P(x, p) = C(x)·X(p) is linear in its expanded coefficients X but
polynomial in the physical parameters p (the thesis's example is the tyre's relaxation model:
the step-1 columns b_{F,δ′,i,j} and their relaxation images b_{F,δ′,i,j}·K_y⁻¹, (3-62), the
two-step method identifying them one after the other). Annex A asks for the set of p
compatible with the data rather than one estimate:

1. the least squares of the expanded model give the solution ellipsoid (A-11),
   ‖ρ‖² = (X − X̂)ᵀ·Q·(X − X̂) + ‖ρ_min‖², Q = CᵀC;
2. in its principal axes, Q = Uᵀ·Σ·U (A-13), X′ = U·X (A-14…A-16), each X′_k is an
   independent variable centred on X̂′_k: the box ζ(X̂′, r) (A-19) with r = λ·σ_X′ (A-18:
   σ_X′ = √(Σ⁻¹·‖ρ_min‖²/(n − p)), λ the relaxation factor), or, when the noise is known to
   be bounded, |e_i| ≤ ε, the guaranteed radius r_k = ε·‖(U·Q⁻¹·Cᵀ)_k‖₁ (X̂′ − X′ =
   U·Q⁻¹·Cᵀ·e: the box then contains the truth whatever the noise within its bound — this
   replaces λ where the thesis has no bound);
3. the parameter set S = {p ∈ [p]₀ : U·X(p) ∈ ζ(X̂′, r)} (A-19), whose outer box is found by
   interval analysis (the thesis names the solvers of [Jaulin 01], [Granvilliers 03]): a
   branch and bound per parameter and side on boxes of [p]₀, a box rejected when the
   interval enclosure of a row of U·X(p) (the natural extension intersected with the
   mean-value form) misses its interval, the bound of an inner box
   (every row inside) reached. The bound returned is an outer (guaranteed) one; it stops at
   an inner box (the bound is then S's) or at a box narrower than `tol`·width([p]₀) that the
   enclosure cannot decide (near a vertex of S, where several constraints meet, each row
   alone is met on such a box and only their conjunction fails: the bound is then within a
   few tol of S's hull, 3·tol on the tests' case).

`smallest_relaxation` finds the smallest λ for which S is not empty (the constraint
satisfaction problem (A-19)). The thesis's LFT (A-1…A-8) is its representation of X(p); here
X(p) is a `PolynomialMap` (monomials of p), whose interval extension is the same algebra.
The thesis gives no example; `tests/test_tyre_setmembership.py` checks the method on a
synthetic relaxation model with bounded noise against linear programming.
"""

import dataclasses
import heapq
import itertools
from collections.abc import Mapping, Sequence

import numpy as np

from ..errors import InputError

__all__ = ["PolynomialMap", "SetMembership", "ellipsoid_box", "parameter_set",
           "smallest_relaxation"]


@dataclasses.dataclass(frozen=True)
class PolynomialMap:
    """X(p): the expanded coefficients as polynomials of the parameters p. Component k is
    Σ_t coef[k, t]·∏_i p_i^powers[t, i] over the distinct monomials `powers` (T, n_p).
    Build it with `from_terms`."""

    names: tuple
    powers: np.ndarray  # (T, n_p) non-negative integers
    coef: np.ndarray    # (k, T)

    @classmethod
    def from_terms(cls, names: Sequence[str],
                   components: Sequence[Mapping[tuple, float]]) -> "PolynomialMap":
        """`components[k]` maps an exponent tuple (one per parameter of `names`) to its
        coefficient: e.g. names ("b", "c") and [{(1, 0): 1.0}, {(1, 1): 1.0}] is X = (b, b·c)."""
        names = tuple(names)
        monos = sorted({tuple(int(e) for e in m) for comp in components for m in comp})
        for m in monos:
            if len(m) != len(names) or min(m) < 0:
                raise InputError(f"monomial {m}: {len(names)} non-negative exponents expected")
        coef = np.zeros((len(components), len(monos)))
        for k, comp in enumerate(components):
            for m, v in comp.items():
                coef[k, monos.index(tuple(int(e) for e in m))] += float(v)
        return cls(names, np.array(monos, int).reshape(-1, len(names)), coef)

    def monomials(self, p) -> np.ndarray:
        p = np.asarray(p, float)
        return np.prod(p[..., None, :] ** self.powers, axis=-1)

    def __call__(self, p) -> np.ndarray:
        """X(p), (k,) (or (..., k) for a stack of p)."""
        return self.monomials(p) @ self.coef.T

    def monomial_ranges(self, lo, hi, powers=None) -> tuple[np.ndarray, np.ndarray]:
        """The exact range of each monomial (of `powers`, default the map's) on the box
        [lo, hi] (a product of powers of distinct variables: the product of their ranges)."""
        powers = self.powers if powers is None else powers
        a, b = lo ** powers, hi ** powers  # (T, n_p)
        plo, phi = np.minimum(a, b), np.maximum(a, b)
        even_zero = (powers % 2 == 0) & (powers > 0) & (lo < 0) & (hi > 0)
        plo = np.where(even_zero, 0.0, plo)
        mlo, mhi = plo[:, 0], phi[:, 0]
        for i in range(1, powers.shape[1]):
            c1, c2 = mlo * plo[:, i], mlo * phi[:, i]
            c3, c4 = mhi * plo[:, i], mhi * phi[:, i]
            mlo = np.minimum(np.minimum(c1, c2), np.minimum(c3, c4))
            mhi = np.maximum(np.maximum(c1, c2), np.maximum(c3, c4))
        return mlo, mhi


def _row_range(G, mlo, mhi):
    """The natural interval extension of rows G (r, T) over monomial ranges."""
    c, w = 0.5 * (mlo + mhi), 0.5 * (mhi - mlo)
    mid, rad = G @ c, np.abs(G) @ w
    return mid - rad, mid + rad


def _enclosure(poly: PolynomialMap, R):
    """(a, b) → an enclosure of the rows R (r, T) of the monomials over the box [a, b]: the
    natural extension intersected with the mean-value form R·m(c) + Σ_i [∂/∂p_i](box)·[−h_i,
    h_i] (c the centre, h the half-widths), whose overestimation shrinks as the box's width
    squared where the natural one's shrinks as its width (the dependency of p_i appearing in
    several monomials)."""
    n_p, T = len(poly.names), len(poly.powers)
    # the monomials of the map and of its n_p derivatives, one stack: (T·(1 + n_p), n_p)
    powers = [poly.powers]
    rows = [R]
    for i in range(n_p):
        e = poly.powers[:, i]
        pw = poly.powers.copy()
        pw[:, i] = np.maximum(e - 1, 0)
        powers.append(pw)
        rows.append(R * e)
    powers = np.concatenate(powers)

    def enclose(a, b):
        mlo, mhi = poly.monomial_ranges(a, b, powers)
        mc, mw = 0.5 * (mlo + mhi), 0.5 * (mhi - mlo)
        nmid, nrad = R @ mc[:T], np.abs(R) @ mw[:T]  # the natural extension
        c, h = 0.5 * (a + b), 0.5 * (b - a)
        f0 = R @ poly.monomials(c)
        rad = np.zeros_like(f0)
        for i in range(n_p):  # the mean-value form: f(c) + Σ_i |[∂f/∂p_i]|·h_i
            Ri, sl = rows[i + 1], slice(T * (i + 1), T * (i + 2))
            dmid, drad = Ri @ mc[sl], np.abs(Ri) @ mw[sl]
            rad += (np.abs(dmid) + drad) * h[i]
        return np.maximum(nmid - nrad, f0 - rad), np.minimum(nmid + nrad, f0 + rad)

    return enclose


def ellipsoid_box(C, y, *, lam: float | None = None, noise_bound: float | None = None):
    """The Annex A box of the expanded coefficients in the principal axes of the least-squares
    ellipsoid (A-11…A-18): returns (U, X̂′ = U·X̂, r, X̂), the box ζ(X̂′, r) on X′ = U·X.
    `lam`: r = λ·σ_X′ (A-18); `noise_bound` ε: the guaranteed r_k = ε·‖(U·Q⁻¹·Cᵀ)_k‖₁ for
    noise |e_i| ≤ ε. C must have full column rank (the identifiable part, X_I = M_I·X, is the
    caller's: reduce C first)."""
    C, y = np.asarray(C, float), np.asarray(y, float)
    if (lam is None) == (noise_bound is None):
        raise InputError("ellipsoid_box: give either lam or noise_bound")
    n, k = C.shape
    if n <= k:
        raise InputError(f"ellipsoid_box: {n} equations for {k} coefficients")
    Q = C.T @ C
    s, V = np.linalg.eigh(Q)  # Q = V·diag(s)·Vᵀ: U = Vᵀ
    if s[0] <= 1e-12 * s[-1]:
        raise InputError("ellipsoid_box: C is rank deficient; keep its identifiable columns")
    U = V.T
    xhat = np.linalg.solve(Q, C.T @ y)
    if lam is not None:
        rho2 = float(np.sum((y - C @ xhat) ** 2))
        r = float(lam) * np.sqrt(rho2 / (n - k) / s)
    else:
        G = U @ np.linalg.solve(Q, C.T)
        r = float(noise_bound) * np.abs(G).sum(axis=1)
    return U, U @ xhat, r, xhat


@dataclasses.dataclass(frozen=True)
class SetMembership:
    """The parameter set S = {p ∈ [p]₀ : lo ≤ rows·m(p) ≤ hi} (m the monomials of
    `poly`) and its outer box: `names`, `box_lo`, `box_hi` (guaranteed: S ⊂ box), `empty`
    (no point of [p]₀ is in S), `tol` (the branch and bound's smallest box, relative to the
    prior box: each bound is within a few tol of S's hull — 3·tol on the synthetic case of
    the tests), `boxes` (interval evaluations made)."""

    names: tuple
    box_lo: np.ndarray
    box_hi: np.ndarray
    empty: bool
    tol: float
    boxes: int
    poly: PolynomialMap
    rows: np.ndarray
    lo: np.ndarray
    hi: np.ndarray

    def contains(self, p) -> bool:
        """Whether the point p satisfies every constraint of S."""
        v = self.rows @ self.poly.monomials(p)
        return bool(np.all((v >= self.lo) & (v <= self.hi)))

    def to_dict(self) -> dict:
        return {"names": list(self.names), "lower": self.box_lo.tolist(),
                "upper": self.box_hi.tolist(), "empty": self.empty, "tol": self.tol,
                "boxes": self.boxes}


def _bound(enclose, lo, hi, p_lo, p_hi, i, side, tol, budget):
    """Branch and bound for the min (side −1) or max (+1) of p_i over S: best-first on the
    boxes' bound. Ends at an inner box (the bound is S's) or at an undecided box narrower than
    `tol` (relative to the prior box; an outer bound). Returns (the bound or None when S is
    empty, boxes evaluated)."""
    width0 = p_hi - p_lo
    count = itertools.count()
    heap = [((p_lo[i] if side < 0 else -p_hi[i]), next(count), p_lo, p_hi)]
    n = 0
    while heap:
        key, _, a, b = heapq.heappop(heap)
        n += 1
        if n > budget:
            raise InputError(f"parameter_set: more than {budget} boxes; loosen tol or "
                             "narrow the prior box")
        rlo, rhi = enclose(a, b)
        if np.any(rhi < lo) or np.any(rlo > hi):
            continue  # no point of this box is in S
        inner = bool(np.all(rlo >= lo) and np.all(rhi <= hi))
        if inner or np.max((b - a) / width0) <= tol:
            return (a[i] if side < 0 else b[i]), n
        j = int(np.argmax((b - a) / width0))
        mid = 0.5 * (a[j] + b[j])
        for na, nb in ((a, np.r_[b[:j], mid, b[j + 1:]]), (np.r_[a[:j], mid, a[j + 1:]], b)):
            heapq.heappush(heap, ((na[i] if side < 0 else -nb[i]), next(count), na, nb))
    return None, n


def _feasible(enclose, violation, lo, hi, p_lo, p_hi, floor, budget):
    """Whether S has a point: boxes searched in the order of their centre's constraint
    violation; True at a centre in S, False when every box is rejected or narrower than
    `floor` (relative) without one."""
    width0 = p_hi - p_lo
    count = itertools.count()
    heap = [(violation(0.5 * (p_lo + p_hi)), next(count), p_lo, p_hi)]
    n = 0
    while heap:
        v, _, a, b = heapq.heappop(heap)
        n += 1
        if v <= 0:
            return True
        if n > budget:
            raise InputError(f"smallest_relaxation: more than {budget} boxes")
        rlo, rhi = enclose(a, b)
        if np.any(rhi < lo) or np.any(rlo > hi) or np.max((b - a) / width0) <= floor:
            continue
        j = int(np.argmax((b - a) / width0))
        mid = 0.5 * (a[j] + b[j])
        for na, nb in ((a, np.r_[b[:j], mid, b[j + 1:]]), (np.r_[a[:j], mid, a[j + 1:]], b)):
            heapq.heappush(heap, (violation(0.5 * (na + nb)), next(count), na, nb))
    return False


def parameter_set(poly: PolynomialMap, U, center, radius, prior_lo, prior_hi, *,
                  tol: float = 1e-3, budget: int = 200_000) -> SetMembership:
    """The set S = {p ∈ [prior_lo, prior_hi] : |U·X(p) − center| ≤ radius} (A-19) and its
    outer box by interval branch and bound (see the module docstring), each bound within
    `tol`·(prior width) of S's hull."""
    lo_p, hi_p = np.asarray(prior_lo, float), np.asarray(prior_hi, float)
    if lo_p.shape != (len(poly.names),) or np.any(~(hi_p > lo_p)):
        raise InputError("parameter_set: the prior box needs lo < hi for every parameter")
    G = np.asarray(U, float) @ poly.coef
    lo = np.asarray(center, float) - np.asarray(radius, float)
    hi = np.asarray(center, float) + np.asarray(radius, float)
    enclose = _enclosure(poly, G)
    out_lo, out_hi, total, empty = lo_p.copy(), hi_p.copy(), 0, False
    for i in range(len(poly.names)):
        for side in (-1, 1):
            v, n = _bound(enclose, lo, hi, lo_p, hi_p, i, side, tol, budget)
            total += n
            if v is None:
                empty = True
                break
            (out_lo if side < 0 else out_hi)[i] = v
        if empty:
            break
    return SetMembership(poly.names, out_lo, out_hi, empty, tol, total, poly, G, lo, hi)


def smallest_relaxation(poly: PolynomialMap, C, y, prior_lo, prior_hi, *,
                        rtol: float = 1e-3, floor: float = 1e-9,
                        budget: int = 200_000) -> float:
    """The smallest λ for which the set of (A-19) with the box ζ(X̂′, λ·σ) has a point in the
    prior box (the thesis's constraint satisfaction problem), by bisection on λ to `rtol`; a
    set counts as non-empty when the search finds a point of it (boxes searched in the order
    of their centre's violation, down to `floor` of the prior widths)."""
    U, xc, r1, _ = ellipsoid_box(C, y, lam=1.0)
    p_lo, p_hi = np.asarray(prior_lo, float), np.asarray(prior_hi, float)
    G = np.asarray(U, float) @ poly.coef
    enclose = _enclosure(poly, G)

    def feasible(lam):
        lo, hi = xc - lam * r1, xc + lam * r1

        def violation(q):
            v = G @ poly.monomials(q)
            return float(np.max(np.maximum(lo - v, v - hi) / r1))

        return _feasible(enclose, violation, lo, hi, p_lo, p_hi, floor, budget)

    lo, hi = 0.0, 1.0
    while not feasible(hi):
        lo, hi = hi, 2.0 * hi
        if hi > 1e6:
            raise InputError("smallest_relaxation: no λ up to 1e6 makes the set non-empty; "
                             "the prior box excludes the data's solution")
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if feasible(mid) else (mid, hi)
    return hi
