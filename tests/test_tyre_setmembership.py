"""Set-membership identification of a factorised polynomial (thesis Annex A; `setmembership`)
on a synthetic relaxation model with bounded noise: F = b₁·δ′·F_z + b₃·δ′³·F_z +
c·(b₁ + 3·b₃·δ′²)·F_z·ḟ, the shape of the two-step model (3-61, 3-62) with c = K_y⁻¹, whose
expanded coefficients X = (b₁, b₃, c·b₁, c·b₃) are polynomials of p = (b₁, b₃, c). The
guaranteed box of X contains the exact bounded-error polytope (linear programming), the
parameter set contains the truth, and its outer box is within tolerance of the hull found by
linear programming over a grid of c (for a fixed c the constraints are linear in b₁, b₃);
the smallest relaxation λ of (A-19) against the same LP."""

import numpy as np
import pytest
import scipy.optimize

from diffsusp.errors import InputError
from diffsusp.tyre import setmembership as sm

TRUTH = np.array([-2.0, 0.5, 0.3])  # b1, b3, c
PRIOR = (np.array([-5.0, -2.0, 0.0]), np.array([0.0, 2.0, 1.0]))
EPS = 0.02  # the noise bound
TOL = 3e-4  # the branch and bound's smallest box, relative to the prior box


@pytest.fixture(scope="module")
def problem():
    rng = np.random.default_rng(0)
    t = np.arange(300) / 100.0
    d = np.sin(2 * np.pi * 1.1 * t) + 0.3 * np.sin(2 * np.pi * 2.7 * t)
    fz = 1.0 + 0.3 * np.sin(2 * np.pi * 0.7 * t)
    fdot = np.cos(2 * np.pi * 1.1 * t) + 0.5 * np.cos(2 * np.pi * 3.9 * t + 0.4)
    C = np.stack([d * fz, d**3 * fz, fz * fdot, 3 * d**2 * fz * fdot], axis=1)
    poly = sm.PolynomialMap.from_terms(("b1", "b3", "c"), [
        {(1, 0, 0): 1.0}, {(0, 1, 0): 1.0}, {(1, 0, 1): 1.0}, {(0, 1, 1): 1.0}])
    y = C @ poly(TRUTH) + rng.uniform(-EPS, EPS, len(t))
    return C, y, poly


def _order(poly):
    """The columns of the monomials b1, b3, b1·c, b3·c in the map's order."""
    return [list(map(tuple, poly.powers)).index(m) for m in
            [(1, 0, 0), (0, 1, 0), (1, 0, 1), (0, 1, 1)]]


def _lp(c_obj, A, b):
    r = scipy.optimize.linprog(c_obj, A_ub=A, b_ub=b, bounds=(None, None), method="highs")
    return r.fun if r.status == 0 else None


def test_guaranteed_box_contains_the_bounded_error_polytope(problem):
    """Every rotated coefficient's range over {X : |y − C·X| ≤ ε} (linprog) lies in the
    guaranteed box ζ(X̂′, r), and the true X′ does."""
    C, y, poly = problem
    U, xc, r, _ = sm.ellipsoid_box(C, y, noise_bound=EPS)
    A = np.vstack([C, -C])
    b = np.r_[y + EPS, EPS - y]
    for k in range(4):
        lo = _lp(U[k], A, b)
        hi = -_lp(-U[k], A, b)
        assert xc[k] - r[k] <= lo + 1e-9 and hi <= xc[k] + r[k] + 1e-9, k
    assert np.all(np.abs(U @ poly(TRUTH) - xc) <= r)
    with pytest.raises(InputError, match="either"):
        sm.ellipsoid_box(C, y)


def _hull_by_lp(G, lo, hi, cs):
    """For a fixed c the constraints lo ≤ G·(b1, b3, c·b1, c·b3) ≤ hi are linear in (b1, b3):
    their min/max by linprog on a grid of c, each extreme refined by a bounded scalar search
    around its grid point, the ends of c's feasible range by bisection."""
    def extreme(c, j, sign):  # sign·min(sign·b_j) at c, or None if infeasible
        M = G[:, :2] + c * G[:, 2:]  # rows of (b1, b3)
        v = _lp(sign * np.eye(2)[j], np.vstack([M, -M]), np.r_[hi, -lo])
        return None if v is None else sign * v

    feas = [c for c in cs if extreme(c, 0, 1) is not None]
    ends = []
    for inside, step in ((feas[0], -1), (feas[-1], 1)):
        a, b = inside, inside + step * (cs[1] - cs[0])  # the grid is wider than the set
        for _ in range(40):
            m = 0.5 * (a + b)
            a, b = (m, b) if extreme(m, 0, 1) is not None else (a, m)
        ends.append(a)
    out = {"c": ends}
    for j, name in enumerate(("b1", "b3")):
        out[name] = []
        for sign in (1, -1):
            def f(c, j=j, sign=sign):
                v = extreme(min(max(c, ends[0]), ends[1]), j, sign)
                return np.inf if v is None else sign * v
            grid = np.r_[ends[0], feas, ends[1]]
            k = int(np.argmin([f(c) for c in grid]))
            r = scipy.optimize.minimize_scalar(
                f, bounds=(grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]),
                method="bounded", options={"xatol": 1e-9})
            out[name].append(sign * min(r.fun, f(grid[k])))
    return out


def test_parameter_set_contains_the_truth_and_is_tight(problem):
    """The set of (b₁, b₃, c) compatible with the guaranteed box contains the truth; its outer
    box contains the LP hull (over 51 values of c, the ends of c's range refined) and
    exceeds it by less than 3·tol of the prior widths (tol 3e-4, the branch and bound's
    smallest box; measured 1.1e-4…6.5e-4; tol 1e-4 gives 0.9e-4…2.7e-4)."""
    C, y, poly = problem
    U, xc, r, _ = sm.ellipsoid_box(C, y, noise_bound=EPS)
    res = sm.parameter_set(poly, U, xc, r, *PRIOR, tol=TOL)
    assert not res.empty and res.contains(TRUTH)
    assert np.all(res.box_lo <= TRUTH) and np.all(TRUTH <= res.box_hi)
    G = (U @ poly.coef)[:, _order(poly)]
    lp = _hull_by_lp(G, xc - r, xc + r, np.linspace(0.0, 1.0, 51))
    width = PRIOR[1] - PRIOR[0]
    for i, name in enumerate(("b1", "b3", "c")):
        lo, hi = lp[name]
        assert res.box_lo[i] <= lo + 1e-9 and hi - 1e-9 <= res.box_hi[i], name
        assert (lo - res.box_lo[i]) / width[i] < 3 * TOL, (name, res.box_lo[i], lo)
        assert (res.box_hi[i] - hi) / width[i] < 3 * TOL, (name, res.box_hi[i], hi)
    # the set is small: the data determine p (c to a few %)
    assert res.box_hi[2] - res.box_lo[2] < 0.05


def test_smallest_relaxation_against_linear_programming(problem):
    """λ_min of (A-19), the smallest λ whose box ζ(X̂′, λ·σ) meets X(p): against the LP
    min over (b₁, b₃, t) of t subject to |G(c)·b − X̂′| ≤ t·σ, minimised over a grid of c."""
    C, y, poly = problem
    lam = sm.smallest_relaxation(poly, C, y, *PRIOR, rtol=1e-2)
    U, xc, s1, _ = sm.ellipsoid_box(C, y, lam=1.0)
    G = (U @ poly.coef)[:, _order(poly)]

    def by_lp(c):  # min over (b1, b3, t) of t, |G(c)·b − X̂′| ≤ t·σ
        M = G[:, :2] + c * G[:, 2:]
        A = np.vstack([np.c_[M, -s1], np.c_[-M, -s1]])
        return _lp(np.array([0.0, 0.0, 1.0]), A, np.r_[xc, -xc])

    cs = np.linspace(0.0, 1.0, 41)
    k = int(np.argmin([by_lp(c) for c in cs]))
    best = scipy.optimize.minimize_scalar(by_lp, bounds=(cs[max(k - 1, 0)], cs[k + 1]),
                                          method="bounded", options={"xatol": 1e-10}).fun
    assert 0 < lam < 3.0
    assert best <= lam <= best * (1 + 1e-2), (lam, best)
