"""Benchmark of the iterative (correlation) identification, spec stiffness §2 / §7 R5.

Run by hand: `python benchmarks/identify_iterative.py [--quick]`. The R5 problem: pseudo_mcpherson,
the 13 cases of Table 5-1, bushings A and B started at 10⁴ N/mm and 10⁴ N·mm/deg, ε = 0.01.
Measures the first call (compile + run) and the run after compile, and the same loop with the
plain NumPy/SciPy Newton of tests/oracle.py (finite-difference Jacobians, one case at a time,
warm-started from the previous iteration) as the baseline, printed as a ratio. Writes
benchmarks/results/identify_iterative.json. Timings are never asserted anywhere.
"""

import argparse
import pathlib
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)
import equinox as eqx  # noqa: E402
import numpy as np  # noqa: E402

import diffsusp as ds  # noqa: E402
from diffsusp.identify._iterative import _equalise, iterative  # noqa: E402
from diffsusp.models import pseudo_mcpherson, thesis_load_cases  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))
import oracle  # noqa: E402
from _common import save_results  # noqa: E402

NAMES = ("bushing_A", "bushing_B")
DEG = np.pi / 180
RESOLUTION = (1e-3, 0.01 * DEG)


def problem():
    ref = pseudo_mcpherson()
    loads = thesis_load_cases(ref)
    sol = ds.solve_statics(ref, loads)
    d_t, ang, _, _ = ds.bushing_states(ref, sol.q)
    idx = np.array([ref.bushings.index(n) for n in NAMES])
    measured = np.concatenate([d_t, ang], axis=-1)[:, idx]
    start = eqx.tree_at(lambda m: (m.bushings.k_trans, m.bushings.k_rot), ref,
                        (ref.bushings.k_trans.at[idx].set(1e4),
                         ref.bushings.k_rot.at[idx].set(1e4 / DEG)))
    return start, loads, measured, idx


def numpy_loop(start, loads, measured, idx, max_iterations):
    """The same loop with the oracle's equilibria (linear bushings: restoring force K·δ)."""
    k = np.concatenate([np.asarray(start.bushings.k_trans)[idx],
                        np.asarray(start.bushings.k_rot)[idx]], axis=1)
    floor = np.repeat(RESOLUTION, 3)
    resolved = measured.std(axis=0) > floor
    sols = None
    for it in range(1, max_iterations + 1):
        mech = eqx.tree_at(lambda m: (m.bushings.k_trans, m.bushings.k_rot), start,
                           (start.bushings.k_trans.at[idx].set(k[:, :3]),
                            start.bushings.k_rot.at[idx].set(k[:, 3:])))
        force, moment = np.asarray(loads.force), np.asarray(loads.moment)
        driver = np.asarray(loads.driver)
        sols = [oracle.solve(mech, force[c], moment[c], driver[c],
                             q0=None if sols is None else sols[c]) for c in range(len(force))]
        model = []
        for s in sols:
            d_t, ang = oracle.bushing_deformations(mech, s.p, s.R)
            model.append(np.concatenate([d_t, ang], axis=1)[idx])
        f = np.asarray(model) * k  # restoring force and torque in J (linear law)
        d = measured - measured.mean(0)
        fc = f - f.mean(0)
        cov = (d * fc).mean(0)
        slope = cov / (d * d).mean(0)
        r = cov / np.sqrt((d * d).mean(0) * (fc * fc).mean(0))
        accepted = (r > 0.75) & resolved
        k_new = np.where(accepted, slope, k)
        k_new, _ = _equalise(k_new, accepted, (fc * fc).sum(0), np.zeros(len(idx), bool))
        change = np.max(np.abs(k_new - k) / np.abs(k))
        k = k_new
        if change < 0.01:
            return k, it
    return k, max_iterations


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true", help="skip the NumPy baseline")
    args = parser.parse_args()
    start, loads, measured, idx = problem()
    t0 = time.perf_counter()
    _, report = iterative(start, loads, NAMES, measured=measured, resolution=RESOLUTION)
    first = time.perf_counter() - t0
    repeats = 5
    t0 = time.perf_counter()
    for _ in range(repeats):
        _, report = iterative(start, loads, NAMES, measured=measured, resolution=RESOLUTION)
    run = (time.perf_counter() - t0) / repeats
    row = dict(problem="R5 pseudo_mcpherson, 13 cases, A and B", iterations=report.iterations,
               first_call_s=first, run_s=run, per_iteration_ms=1e3 * run / report.iterations)
    print(f"diffsusp: {report.iterations} iterations, first call {first:.2f} s, after compile "
          f"{run * 1e3:.1f} ms ({row['per_iteration_ms']:.1f} ms per iteration)")
    if not args.quick:
        t0 = time.perf_counter()
        k, its = numpy_loop(start, loads, measured, idx, 100)
        base = time.perf_counter() - t0
        row.update(baseline_s=base, baseline_iterations=its, ratio=base / run,
                   max_rel_diff=float(np.max(np.abs(k - report.stiffness) / report.stiffness)))
        print(f"NumPy/SciPy oracle loop: {its} iterations, {base:.2f} s → {base / run:.0f}× "
              f"(stiffnesses agree to {row['max_rel_diff']:.1e} relative)")
    save_results("identify_iterative", row)


if __name__ == "__main__":
    main()
