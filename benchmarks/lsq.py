"""Benchmark of the guaranteed least squares (diffsusp.lsq).

Run by hand: `python benchmarks/lsq.py [--quick]`. Prints a table and writes
benchmarks/results/lsq.json. Timings are never asserted anywhere.

Problem: the direct identification's stacked system, 10 000 load cases of 7 rows each and 20
stiffness-like unknowns (columns of very different units), i.e. W (70 000 × 20). Measured after
compilation (compile time reported separately):

- one-shot: `lsq.solve` (QR of the 70 000 × 21 [W, −y], identifiability, relations, σ, report);
  and its core alone (`qr_r` + `solve_r`);
- streaming: `Accumulator.add_blocks` in chunks of 1 000 cases (7 000 rows), then `solve`;
  `Accumulator.add` one case (7 rows) at a time, per-add latency;
- batched: `vmap(solve_arrays)` over 1 000 small data sets (13 cases × 7 rows × 20), the
  Monte-Carlo use;
- (OPENBLAS_NUM_THREADS defaults to 1, see below);
- baselines in the same process: NumPy `np.linalg.qr(mode="r")` + triangular solve, and
  `np.linalg.lstsq` (SVD) on the same stacked system; a NumPy loop of lstsq for the batch.
"""

import argparse
import os
import time

# One BLAS thread for NumPy and for JAX's LAPACK calls alike (both use OpenBLAS here): on the
# shared 2-core machine, more threads oversubscribe the cores and make both 2–30× slower.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy.linalg  # noqa: E402
from _common import save_results, timed  # noqa: E402

from diffsusp import lsq  # noqa: E402
from diffsusp.lsq import core  # noqa: E402


def first_call(fn):
    t0 = time.perf_counter()
    jax.block_until_ready(fn())
    return time.perf_counter() - t0


def data(rng, cases, rows=7, p=20):
    units = 10.0 ** rng.uniform(-3, 1, p)  # mm and rad columns of very different sizes
    W = rng.normal(size=(cases * rows, p)) * units
    x = rng.uniform(1e3, 1e4, p) / units
    y = W @ x + rng.normal(0, 1.0, cases * rows)
    return W, y


def main(quick: bool):
    rng = np.random.default_rng(0)
    cases = 1_000 if quick else 10_000
    rows, p = 7, 20
    W, y = data(rng, cases, rows, p)
    results = {"cases": cases, "rows": cases * rows, "p": p, "jax": jax.__version__,
               "openblas_threads": os.environ["OPENBLAS_NUM_THREADS"]}
    names = [f"k{i}" for i in range(p)]

    # One-shot, full report
    results["solve_first_call_s"] = first_call(lambda: lsq.solve(W, y, names=names).x)
    results["solve_s"], fit = timed(lambda: lsq.solve(W, y, names=names).x, 5)
    fit = lsq.solve(W, y, names=names)

    # Core only: QR of [W, −y] and solve_r (no validation, no report)
    Wj, yj = jnp.asarray(W), jnp.asarray(y)
    qr = jax.jit(lambda W, y: core.qr_r(core.augmented(W, y)))
    results["core_qr_first_call_s"] = first_call(lambda: qr(Wj, yj))
    results["core_qr_s"], R = timed(lambda: qr(Wj, yj), 5)
    args = core.fill_defaults(p, R.dtype, "basic", None, None, None, None, None)
    n = jnp.asarray(float(cases * rows))
    thr = jnp.asarray(0.0)
    solve = lambda: core.solve_r(R, n, *args, thr).x  # noqa: E731
    results["core_solve_r_s"], _ = timed(solve, 50)

    # Streaming in chunks of 1 000 cases
    chunk = 1000

    def stream():
        acc = lsq.Accumulator(p)
        for c in range(0, cases, chunk):
            acc = acc.add_blocks(W[c * rows:(c + chunk) * rows].reshape(-1, rows, p),
                                 y[c * rows:(c + chunk) * rows].reshape(-1, rows))
        return acc

    results["stream_chunks_first_call_s"] = first_call(lambda: stream().R)
    results["stream_chunks_s"], acc = timed(lambda: stream().R, 3)
    acc = stream()
    results["stream_solve_s"], _ = timed(lambda: acc.solve(names=names).x, 5)
    sfit = acc.solve(names=names)
    results["stream_vs_one_shot_max_rel_dx"] = float(np.max(np.abs(sfit.x - fit.x)
                                                             / np.abs(fit.x)))
    # One case at a time (7 rows per add)
    n_single = 200 if quick else 1000

    def single():
        acc = lsq.Accumulator(p)
        for c in range(n_single):
            acc = acc.add(W[c * rows:(c + 1) * rows], y[c * rows:(c + 1) * rows])
        return acc.R

    first_call(single)
    t, _ = timed(single, 1)
    results["stream_single_add_s"] = t / n_single

    # Batched (vmap) solves: Monte-Carlo over small problems
    batch, small_rows = (200 if quick else 1000), 13 * rows
    Wb = rng.normal(size=(small_rows, p)) * 10.0 ** rng.uniform(-3, 1, p)
    Yb = Wb @ rng.uniform(1, 2, p) + rng.normal(size=(batch, small_rows))
    vsolve = jax.jit(jax.vmap(lambda y: lsq.solve_arrays(Wb, y).x))
    results["vmap_first_call_s"] = first_call(lambda: vsolve(jnp.asarray(Yb)))
    results["vmap_batch_s"], xb = timed(lambda: vsolve(jnp.asarray(Yb)), 5)
    results["vmap_per_solve_s"] = results["vmap_batch_s"] / batch

    # NumPy baselines, same process
    M = np.column_stack([W, -y])

    def numpy_qr():
        Rn = np.linalg.qr(M, mode="r")
        return scipy.linalg.solve_triangular(Rn[:p, :p], -Rn[:p, p])

    results["numpy_qr_s"], xq = timed(numpy_qr, 5)
    results["numpy_lstsq_s"], xl = timed(lambda: np.linalg.lstsq(W, y, rcond=None)[0], 5)
    results["one_shot_vs_numpy_max_rel_dx"] = float(np.max(np.abs(fit.x - xl) / np.abs(xl)))
    t0 = time.perf_counter()
    xs = [np.linalg.lstsq(Wb, Yb[i], rcond=None)[0] for i in range(batch)]
    results["numpy_loop_per_solve_s"] = (time.perf_counter() - t0) / batch
    results["vmap_vs_numpy_max_rel_dx"] = float(np.max(np.abs(np.asarray(xb) - np.array(xs))
                                                       / np.abs(np.array(xs))))

    rows_out = [
        ("lsq.solve one-shot (QR + full report)", results["solve_s"], results["numpy_lstsq_s"]),
        ("core qr_r of [W, -y]", results["core_qr_s"], results["numpy_qr_s"]),
        ("core solve_r (from R, p = 20)", results["core_solve_r_s"], None),
        (f"Accumulator.add_blocks, {chunk}-case chunks", results["stream_chunks_s"],
         results["numpy_qr_s"]),
        ("Accumulator.solve", results["stream_solve_s"], None),
        ("Accumulator.add, one 7-row case", results["stream_single_add_s"], None),
        (f"vmap solve_arrays, per solve (batch {batch}, {small_rows}x{p})",
         results["vmap_per_solve_s"], results["numpy_loop_per_solve_s"]),
    ]
    print(f"lsq benchmark: {cases} cases x {rows} rows = {cases * rows} rows, p = {p}")
    print(f"{'what':<58} {'time':>11} {'numpy':>11} {'numpy/ours':>10}")
    for what, t, base in rows_out:
        ratio = f"{base / t:10.2f}" if base else ""
        base_s = f"{base * 1e3:9.3f}ms" if base else ""
        print(f"{what:<58} {t * 1e3:9.3f}ms {base_s:>11} {ratio}")
    print("numpy baselines: np.linalg.lstsq (one-shot), np.linalg.qr(mode='r') + "
          "solve_triangular (QR / streaming), a loop of lstsq (vmap)")
    print(f"first calls (compile + run): solve {results['solve_first_call_s']:.2f} s, "
          f"qr {results['core_qr_first_call_s']:.2f} s, streaming "
          f"{results['stream_chunks_first_call_s']:.2f} s, "
          f"vmap {results['vmap_first_call_s']:.2f} s")
    print(f"agreement: streaming vs one-shot {results['stream_vs_one_shot_max_rel_dx']:.1e}, "
          f"one-shot vs numpy lstsq {results['one_shot_vs_numpy_max_rel_dx']:.1e}, "
          f"vmap vs numpy {results['vmap_vs_numpy_max_rel_dx']:.1e} (max relative dx)")
    save_results("lsq", results, quick)
    return results


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1 000 cases instead of 10 000")
    main(parser.parse_args().quick)
