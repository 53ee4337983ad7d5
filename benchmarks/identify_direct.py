"""Benchmark of the direct stiffness identification and of landmark registration (spec
stiffness §2).

Run by hand: `python benchmarks/identify_direct.py [--quick]`. Prints a table and writes
benchmarks/results/identify_direct.json (identify_direct_quick.json with --quick). Measures,
after compilation (compile time reported separately):

- `identify.direct` on the pseudo-McPherson with the 13 cases of Table 5-1 (noisy landmarks,
  σ = 0.05 mm, four per part; 20 unknowns): the thesis's unweighted equations
  (`weighting="none"`) and the default GLS weighting (two more passes), and the assembly alone;
- the same for 10 000 cases (the 13 equilibria repeated with independent landmark noise);
- registration of 10 000 landmark sets (parts × cases, four landmarks each): Horn's quaternion
  (default) and Arun's SVD;
- baselines in the same process: a plain NumPy/SciPy direct method (generalised forces of the
  independent NumPy model of tests/oracle.py for unit stiffnesses, finite-difference constraint
  gradients, scipy.linalg.null_space, numpy.linalg.lstsq), and NumPy registration (batched
  numpy.linalg.svd; and SciPy's Rotation.align_vectors one set at a time), printed as ratios.

Timings are never asserted anywhere.
"""

import argparse
import dataclasses
import pathlib
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)
import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from scipy.linalg import null_space  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

from diffsusp import identify, measure  # noqa: E402
from diffsusp.geometry.registration import register_landmarks  # noqa: E402
from diffsusp.models import pseudo_mcpherson, thesis_load_cases  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))
import oracle  # noqa: E402
from _common import save_results  # noqa: E402

DEG = 180.0 / np.pi


def best_of(fn, repeats):
    """Smallest wall time of `repeats` calls (after one warm-up call), and the last output."""
    out = fn()
    jax.block_until_ready(out)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        jax.block_until_ready(out)
        times.append(time.perf_counter() - t0)
    return min(times), out


def first_call(fn):
    t0 = time.perf_counter()
    out = fn()
    jax.block_until_ready(out)
    return time.perf_counter() - t0, out


def tiled(meas, n_cases, seed):
    """`n_cases` cases: the exact equilibria repeated, each with its own landmark noise."""
    reps = -(-n_cases // meas.n_cases)
    idx = np.tile(np.arange(meas.n_cases), reps)[:n_cases]
    big = measure.case_subset(meas, idx)
    big = dataclasses.replace(big, cases=tuple(str(c + 1) for c in range(n_cases)))
    return measure.add_noise(big, measure.GaussianNoise(), jax.random.PRNGKey(seed))


# ----------------------------------------------------------------------------- NumPy baseline


class NumpyDirect:
    """The direct method in plain NumPy/SciPy (the construction of tests/test_direct.py)."""

    def __init__(self, mech):
        b, s = mech.bushings, mech.springs
        self.mech = mech
        self.n = mech.n_coordinates
        zero = eqx.tree_at(
            lambda m: (m.bushings.k_trans, m.bushings.k_rot, m.springs.k,
                       m.springs.free_length),
            mech, (jnp.zeros_like(b.k_trans), jnp.zeros_like(b.k_rot), jnp.zeros_like(s.k),
                   jnp.zeros_like(s.free_length)))
        self.zero = oracle._Oracle(zero)
        self.variants = []
        for e in range(len(b.names)):
            for a in range(6):
                k = np.zeros((len(b.names), 6))
                k[e, a] = 1.0 if a < 3 else DEG
                self.variants.append(oracle._Oracle(eqx.tree_at(
                    lambda m: (m.bushings.k_trans, m.bushings.k_rot), zero,
                    (jnp.asarray(k[:, :3]), jnp.asarray(k[:, 3:])))))
        self.springs = []
        for e in range(len(s.names)):
            def spring(k_e, l0_e, e=e):
                k = np.zeros(len(s.names))
                lz = np.zeros(len(s.names))
                k[e], lz[e] = k_e, l0_e
                return oracle._Oracle(eqx.tree_at(
                    lambda m: (m.springs.k, m.springs.free_length), zero,
                    (jnp.asarray(k), jnp.asarray(lz))))
            self.springs.append((spring(1.0, 0.0), spring(1.0, 1.0)))
        self.structure = oracle._Oracle(mech)

    def solve(self, rot, trans, force, moment, driver):
        rows, rhs = [], []
        for c in range(len(rot)):
            p, r = trans[c], rot[c]
            args = (force[c], moment[c], driver[c])

            def gen(orc, p=p, r=r, args=args):
                return orc.residual(p, r, np.zeros(orc.n_mult), *args)[0][: self.n]

            known = gen(self.zero)
            cols = [gen(v) - known for v in self.variants]
            for k1, k1l1 in self.springs:
                f0 = gen(k1)
                cols += [f0 - known, gen(k1l1) - f0]
            _, grad = self.structure.constraints(p, r, args[2])
            basis = null_space(grad)
            rows.append(basis.T @ np.column_stack(cols))
            rhs.append(-basis.T @ known)
        w, y = np.vstack(rows), np.concatenate(rhs)
        return np.linalg.lstsq(w, y, rcond=None)[0]


def numpy_kabsch(p, q):
    """Batched Arun/Kabsch with the reflection fix in NumPy: p, q (B, k, 3)."""
    pc = p - p.mean(axis=1, keepdims=True)
    qc = q - q.mean(axis=1, keepdims=True)
    u, _, vt = np.linalg.svd(np.einsum("bki,bkj->bij", qc, pc))
    d = np.sign(np.linalg.det(u @ vt))
    u[:, :, 2] *= d[:, None]
    r = u @ vt
    return r, q.mean(axis=1) - np.einsum("bij,bj->bi", r, p.mean(axis=1))


# ----------------------------------------------------------------------------- main


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true", help="small sizes only (smoke run)")
    args = parser.parse_args()
    repeats = 3 if args.quick else 10
    big_n = 1000 if args.quick else 10000
    results = dict(jax=jax.__version__, device=str(jax.devices()[0]), quick=args.quick)

    mech = pseudo_mcpherson()
    loads = thesis_load_cases(mech)
    t_synth, exact = first_call(lambda: measure.synthesize(mech, loads, seed=0))
    noisy = measure.add_noise(exact, measure.GaussianNoise(), jax.random.PRNGKey(1))

    rows = []

    def record(what, cases, compile_s, run_s, baseline_s=None):
        rows.append(dict(what=what, cases=cases, compile_s=compile_s, run_s=run_s,
                         baseline_s=baseline_s,
                         ratio=None if baseline_s is None else baseline_s / run_s))
        print(f"  {what}, {cases} cases: compile {compile_s:.2f} s, run {1e3 * run_s:.2f} ms",
              flush=True)

    # 13 cases
    for label, kw in (("direct, unweighted", dict(weighting="none")),
                      ("direct, GLS (default)", {}),
                      ("direct, GLS + elimination, hold model",
                       dict(hold="model", eliminate=True))):
        c, _ = first_call(lambda kw=kw: identify.direct(mech, noisy, **kw)[1].values)
        t, _ = best_of(lambda kw=kw: identify.direct(mech, noisy, **kw)[1].values, repeats)
        record(label, 13, c, t)
    c, _ = first_call(lambda: identify.direct_system(mech, noisy).W)
    t, _ = best_of(lambda: identify.direct_system(mech, noisy).W, repeats)
    record("assembly only", 13, c, t)

    # NumPy baseline on the same 13 cases
    base = NumpyDirect(mech)
    rot, trans = np.asarray(noisy.rotation), np.asarray(noisy.translation)
    lo = noisy.loads
    n_base = 3 if args.quick else 13
    t0 = time.perf_counter()
    x_np = base.solve(rot[:n_base], trans[:n_base], np.asarray(lo.force)[:n_base],
                      np.asarray(lo.moment)[:n_base], np.asarray(lo.driver)[:n_base])
    base_per_case = (time.perf_counter() - t0) / n_base
    rows[0]["baseline_s"] = base_per_case * 13
    rows[0]["ratio"] = rows[0]["baseline_s"] / rows[0]["run_s"]
    rows[3]["baseline_s"] = rows[0]["baseline_s"]
    rows[3]["ratio"] = rows[3]["baseline_s"] / rows[3]["run_s"]
    if not args.quick:  # same unknowns, same equations: the same least-squares solution
        x_ds = identify.direct_system(mech, noisy)
        x_ls = np.linalg.lstsq(x_ds.W, x_ds.y, rcond=None)[0]
        results["baseline_agreement"] = float(np.max(np.abs(x_np / x_ls - 1.0)))

    # many cases
    big = tiled(exact, big_n, 2)
    for label, kw in (("direct, unweighted", dict(weighting="none")),
                      ("direct, GLS (default)", {})):
        c, _ = first_call(lambda kw=kw: identify.direct(mech, big, **kw)[1].values)
        t, _ = best_of(lambda kw=kw: identify.direct(mech, big, **kw)[1].values,
                       max(2, repeats // 3))
        record(label, big_n, c, t, base_per_case * big_n)

    # registration of 10 000 landmark sets
    rng = np.random.default_rng(0)
    n_sets = 10000
    p = rng.normal(size=(n_sets, 4, 3)) * 100.0
    r = Rotation.random(n_sets, random_state=1).as_matrix()
    q = np.einsum("bij,bkj->bki", r, p) + rng.normal(size=(n_sets, 1, 3)) * 300.0
    q = q + rng.normal(size=q.shape) * 0.05
    pj, qj = jnp.asarray(p), jnp.asarray(q)
    t_np, _ = best_of(lambda: numpy_kabsch(p, q)[0], repeats)
    t0 = time.perf_counter()
    for i in range(500):
        Rotation.align_vectors(q[i] - q[i].mean(0), p[i] - p[i].mean(0))
    t_scipy = (time.perf_counter() - t0) / 500 * n_sets
    for method in ("quaternion", "svd"):
        fn = jax.jit(lambda a, b, method=method: register_landmarks(a, b, method=method))
        c, _ = first_call(lambda fn=fn: fn(pj, qj).rotation)
        t, _ = best_of(lambda fn=fn: fn(pj, qj).rotation, repeats)
        record(f"registration ({method})", n_sets, c, t, t_np)
    results["registration_scipy_loop_s"] = t_scipy

    results["rows"] = rows
    results["synthesize_13_first_call_s"] = t_synth
    print(f"{'what':<40} {'cases':>6} {'compile s':>10} {'run ms':>9} {'baseline ms':>12} "
          f"{'ratio':>7}")
    for row in rows:
        base_ms = "" if row["baseline_s"] is None else f"{1e3 * row['baseline_s']:.1f}"
        ratio = "" if row["ratio"] is None else f"{row['ratio']:.0f}×"
        print(f"{row['what']:<40} {row['cases']:>6} {row['compile_s']:>10.2f} "
              f"{1e3 * row['run_s']:>9.2f} {base_ms:>12} {ratio:>7}")
    print(f"registration, SciPy align_vectors one set at a time: {t_scipy:.2f} s per {n_sets}")
    if "baseline_agreement" in results:
        print(f"NumPy baseline vs diffsusp least squares (13 cases): max relative difference "
              f"{results['baseline_agreement']:.2e}")
    save_results("identify_direct", results, args.quick)


if __name__ == "__main__":
    main()
