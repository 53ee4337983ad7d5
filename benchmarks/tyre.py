"""Benchmark of the Magic Formula (diffsusp.tyre; docs/reference/tyre.md).

Run by hand: `python benchmarks/tyre.py [--quick]`. Prints a table and writes
benchmarks/results/tyre.json. Timings are never asserted anywhere.

- evaluation: MF 6.1 combined-slip F_x, F_y, M_z (`evaluate(..., outputs=("fx", "fy", "mz"))`)
  of 10⁶ random points (load, slip ratio, slip angle, camber, pressure) of the shipped
  MagicFormula61 file, jitted, float64, after compilation; evaluations per second; and the ratio
  to the vectorised NumPy transcription of the tests (tests/test_tyre_oracle.py, which computes
  M_x and M_y as well: about 15 % more work) on the same points in the same run;
- the same with turn slip on (φ_t random, ±0.3 1/m), and the MF 6.2 loaded radius of 10⁶ loads
  (with F_y and camber), for reference (no target);
- fit: the 20-coefficient pure-lateral fit of the tests from 10 000 noisy synthetic points
  (perturbed start ×0.7–1.3), Huber loss, after compilation (a second noise draw), with its
  Levenberg–Marquardt steps and the report (lsq) time;
- (OPENBLAS_NUM_THREADS defaults to 1: the machine has 2 shared cores).

Timing on a shared machine: every evaluation timing is repeated (`--repeats`, default 7) and
reported as the best and the median wall time and the median CPU time of this process
(`time.process_time`, all threads): with other jobs on the two cores the wall time measures
the share the scheduler gave us, the CPU time what the computation costs. The load average
(`os.getloadavg`) is recorded before and after. `--compare-libm` (default on) also times the
same program with XLA's own float64 arctan/sin/cos/tan/sqrt (scalar calls: the evaluation before
`diffsusp.tyre.fast_math`, and still the one of batches below `mf6.FAST_MATH_POINTS`) in the same
process.
"""

import argparse
import os
import pathlib
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# two CPU devices, so the batch can be sharded over the two cores (DESIGN: many devices are
# jax.sharding over the same batch axes); the single-device time is measured too
os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "")
                           + " --xla_force_host_platform_device_count=2").strip()

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _common import samples, save_results  # noqa: E402

from diffsusp.io.tir import read_tir  # noqa: E402
from diffsusp.tyre import (  # noqa: E402
    MagicFormula6,
    evaluate,
    examples,  # noqa: E402
)
from diffsusp.tyre import fit as F  # noqa: E402

ROOT = pathlib.Path(__file__).parent.parent
sys.path.insert(0, str(ROOT / "tests"))
import test_tyre_oracle as oracle  # noqa: E402

DATA = examples.DATA
NAMES = ("PCY1 PDY1 PDY2 PDY3 PEY1 PEY2 PEY3 PKY1 PKY2 PKY3 PKY4 PKY6 PKY7 PHY1 PHY2 PVY1 "
         "PVY2 PVY3 PVY4 PPY1").split()


def _timings(fn, repeats):
    """(best wall, median wall, median CPU) seconds of `fn()` over `repeats` calls after a
    first (compiling) call, and the last output."""
    wall, cpu, out = samples(fn, repeats)
    return (min(wall), float(np.median(wall)), float(np.median(cpu))), out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="10⁵ points, 1 repeat")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--no-compare-libm", dest="compare_libm", action="store_false")
    args = ap.parse_args()
    n = 100_000 if args.quick else 1_000_000
    repeats = 1 if args.quick else args.repeats
    load_before = os.getloadavg()
    tir = read_tir(DATA / "MagicFormula61_Paramerters.tir")
    model = MagicFormula6.from_tir(tir)
    rng = np.random.default_rng(0)
    fz = rng.uniform(1000.0, 12000.0, n)
    sl = rng.uniform(-0.3, 0.3, n)
    sa = rng.uniform(-0.3, 0.3, n)
    ia = rng.uniform(-0.08, 0.08, n)
    p = rng.uniform(2.2e5, 3.0e5, n)
    vx = np.full(n, 16.6)
    args_j = [jnp.asarray(v) for v in (fz, sl, sa, ia, vx * 1000.0, p)]

    def run_raw(m, fz, sl, sa, ia, vx, p):
        f = evaluate(m, fz, sl, sa, ia, vx, p, outputs=("fx", "fy", "mz"))
        return f.fx, f.fy, f.mz

    run = jax.jit(run_raw)

    t0 = time.perf_counter()
    jax.block_until_ready(run(model, *args_j))
    compile_eval = time.perf_counter() - t0
    (t_eval, t_eval_median, cpu_eval), out = _timings(lambda: run(model, *args_j), repeats)
    mesh = jax.sharding.Mesh(np.array(jax.devices()), ("batch",))
    sharded = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("batch"))
    args_s = [jax.device_put(a, sharded) for a in args_j]
    (t_shard, t_shard_median, cpu_shard), _ = _timings(lambda: run(model, *args_s), repeats)
    libm = {}
    if args.compare_libm:
        from diffsusp.tyre import mf6

        threshold = mf6.FAST_MATH_POINTS
        mf6.FAST_MATH_POINTS = 10**18  # every batch on XLA's own functions
        try:
            run_libm = jax.jit(lambda *a: run_raw(*a))  # a new trace with the patch
            (w, wm, c), out_libm = _timings(lambda: run_libm(model, *args_j), repeats)
            (ws, wsm, cs), _ = _timings(lambda: run_libm(model, *args_s), repeats)
        finally:
            mf6.FAST_MATH_POINTS = threshold
        libm = {"eval_s": w, "eval_median_s": wm, "eval_cpu_s": c, "eval_sharded_s": ws,
                "eval_sharded_median_s": wsm, "eval_sharded_cpu_s": cs,
                "max_abs_difference_N": max(float(np.max(np.abs(np.asarray(a) - np.asarray(b))))
                                            for a, b in zip(out, out_libm, strict=True))}
    # turn slip on (MF 6.1 ζ0…ζ8, spin from the effective rolling radius), same points, and
    # the vertical model (loaded radius by Newton, MF 6.2 file): CPU per point, for reference
    phit = jnp.asarray(rng.uniform(-0.3e-3, 0.3e-3, n))
    run_ts = jax.jit(lambda m, *a: tuple(
        getattr(evaluate(m, *a[:6], outputs=("fx", "fy", "mz"), turn_slip=a[6]), k)
        for k in ("fx", "fy", "mz")))
    (t_ts, _, cpu_ts), _ = _timings(lambda: run_ts(model, *args_j, phit), repeats)
    from diffsusp.tyre import vertical

    m62 = MagicFormula6.from_tir(read_tir(DATA / "MagicFormula62_Paramerters.tir"))
    run_rl = jax.jit(lambda m, fz, fy, ia, p: vertical.loaded_radius(
        m, fz, fy=fy, gamma=ia, vx=16.6e3, pressure=p).rl)
    fy_rl = jnp.asarray(rng.uniform(-5000.0, 5000.0, n))
    (t_rl, _, cpu_rl), _ = _timings(lambda: run_rl(m62, args_j[0], fy_rl, args_j[3], args_j[5]),
                                    repeats)
    t0 = time.perf_counter()
    ref = oracle.mf_numpy(tir, fz, sl, sa, ia, vx, p)
    t_numpy = time.perf_counter() - t0
    agree = max(float(np.max(np.abs(np.asarray(out[0]) - ref[0]))),
                float(np.max(np.abs(np.asarray(out[1]) - ref[1]))),
                float(np.max(np.abs(np.asarray(out[2]) / 1000.0 - ref[4]))))

    # ---- fit: 10 000 points, 20 coefficients
    loads = np.linspace(2000.0, 12000.0, 8)
    cambers = np.linspace(-0.08, 0.07, 5)
    na = 250
    f_fz = np.repeat(loads, len(cambers) * na)
    f_ia = np.tile(np.repeat(cambers, na), len(loads))
    f_sa = np.tile(np.linspace(-0.4, 0.4, na), len(loads) * len(cambers))
    z = np.zeros(f_fz.size)
    inputs = F.BenchData(*(jnp.asarray(v) for v in (f_fz, z, f_sa, f_ia, z + 16.6e3, z + 2.6e5)),
                         jnp.zeros((1, z.size)), jnp.ones((1, z.size), bool), ("FY",))
    clean = F.simulate(model, inputs, combined=False)
    sigma = 0.01 * float(np.ptp(np.asarray(clean.measured)))
    rs = np.random.default_rng(6)
    start = model.replace(**{k: float(model[k]) * rs.uniform(0.7, 1.3) for k in NAMES})
    data1 = F.simulate(model, inputs, noise={"FY": sigma}, seed=1, combined=False)
    data2 = F.simulate(model, inputs, noise={"FY": sigma}, seed=2, combined=False)
    t0 = time.perf_counter()
    F.fit(start, data1, NAMES, noise={"FY": sigma}, combined=False)
    compile_fit = time.perf_counter() - t0
    problem = F._prepare(start, data2, NAMES, {"FY": sigma}, "huber", 1.345, False)
    t0 = time.perf_counter()
    x, steps, ok = F._solve(problem, jnp.zeros(len(NAMES)), 200, 1e-9, 1e-9)
    jax.block_until_ready(x)
    t_solve = time.perf_counter() - t0
    t0 = time.perf_counter()
    _, report = F._report(problem, x, steps, ok, 1e-8)
    t_report = time.perf_counter() - t0

    results = {
        "points": n, "repeats": repeats, "load_average_before": load_before,
        "load_average_after": os.getloadavg(), "compile_eval_s": compile_eval,
        "eval_s": t_eval, "eval_median_s": t_eval_median, "eval_cpu_s": cpu_eval,
        "evaluations_per_s": n / t_eval, "evaluations_per_cpu_s": n / cpu_eval,
        "devices": len(jax.devices()), "eval_sharded_s": t_shard,
        "eval_sharded_median_s": t_shard_median, "eval_sharded_cpu_s": cpu_shard,
        "evaluations_per_s_sharded": n / t_shard, "libm": libm,
        "turn_slip_eval_s": t_ts, "turn_slip_eval_cpu_s": cpu_ts,
        "loaded_radius_s": t_rl, "loaded_radius_cpu_s": cpu_rl,
        "numpy_s": t_numpy, "speedup_vs_numpy": t_numpy / t_eval,
        "max_abs_difference_vs_numpy_N": agree,
        "fit_points": int(z.size), "fit_coefficients": len(NAMES), "compile_fit_s": compile_fit,
        "fit_solve_s": t_solve, "fit_report_s": t_report, "fit_steps": int(steps),
        "fit_converged": bool(ok), "fit_unidentifiable": list(report.unidentifiable),
    }
    print(f"load average {load_before[0]:.1f} before, {os.getloadavg()[0]:.1f} after")
    print(f"MF 6.1 combined F_x, F_y, M_z, {n} points (float64): best {t_eval * 1e3:.1f} ms "
          f"(median {t_eval_median * 1e3:.1f}, CPU {cpu_eval * 1e3:.1f}) = {n / t_eval:.3g} "
          f"evaluations/s, {n / cpu_eval:.3g} per CPU-second (compile {compile_eval:.1f} s); "
          f"NumPy {t_numpy * 1e3:.0f} ms, ratio {t_numpy / t_eval:.1f}x; max |diff| "
          f"{agree:.2e} N")
    print(f"  sharded over {len(jax.devices())} CPU devices: best {t_shard * 1e3:.1f} ms "
          f"(median {t_shard_median * 1e3:.1f}, CPU {cpu_shard * 1e3:.1f}) = "
          f"{n / t_shard:.3g} evaluations/s")
    if libm:
        print(f"  XLA's own transcendentals (before): best {libm['eval_s'] * 1e3:.1f} ms "
              f"(median {libm['eval_median_s'] * 1e3:.1f}, CPU {libm['eval_cpu_s'] * 1e3:.1f}),"
              f" sharded best {libm['eval_sharded_s'] * 1e3:.1f} ms; max |diff| "
              f"{libm['max_abs_difference_N']:.2e}")
    print(f"  turn slip on: best {t_ts * 1e3:.1f} ms, CPU {cpu_ts * 1e3:.1f} ms; MF 6.2 loaded "
          f"radius (Newton, F_y and camber terms): best {t_rl * 1e3:.1f} ms, CPU "
          f"{cpu_rl * 1e3:.1f} ms")
    print(f"pure-lateral fit, {len(NAMES)} coefficients, {z.size} points: LM {t_solve:.3f} s in "
          f"{int(steps)} steps (converged {bool(ok)}), report {t_report:.3f} s, compile "
          f"{compile_fit:.1f} s; not identifiable: {', '.join(report.unidentifiable)}")
    print("results:", save_results("tyre", results, quick=args.quick))


if __name__ == "__main__":
    main()
