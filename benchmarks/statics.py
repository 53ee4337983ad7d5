"""Benchmark of the static-equilibrium solver.

Run by hand: `python benchmarks/statics.py [--quick]`. Prints a table and writes
benchmarks/results/statics.json. Measures the programs a first `solve_statics` call on the 13
thesis cases compiles and that call's warm wall time; after compilation: equilibria per second
for batches of 1, 13, 100, 1 000 and 10 000 load cases on pseudo_mcpherson and
double_wishbone, the latency of one solve, the compile time, the cost of the full Jacobian of
all marker positions with respect to all stiffnesses for the 13 thesis cases, and the same
equilibria solved by the plain NumPy/SciPy Newton of tests/oracle.py (finite-difference
Jacobian) in the same process, reported as a ratio. Timings are never asserted anywhere.
"""

import argparse
import logging
import os
import pathlib
import resource
import sys
import time

import jax
from _common import save_results, timed, timed_cpu  # noqa: I001 (sets XLA flags first)

jax.config.update("jax_enable_x64", True)
import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import diffsusp as ds  # noqa: E402
from diffsusp.models import double_wishbone, pseudo_mcpherson, thesis_load_cases  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))
import oracle  # noqa: E402

CONVERGED = ds.statics.Status.CONVERGED


def envelope(n, rng, vertical=(1500.0, 7500.0), horizontal=4000.0):
    """Loads across the thesis envelope: vertical 1500–7500 N, and one horizontal component at
    a time (lateral or longitudinal, like the thesis's cases) up to ±4000 N at 4500 N vertical,
    scaled with the vertical load (a friction-like limit: the model has no bump stops, and a
    4000 N side load on a lightly loaded wheel pulls it past its travel)."""
    fz = rng.uniform(*vertical, n)
    h = rng.uniform(-horizontal, horizontal, n) * np.minimum(1.0, fz / 4500.0)
    lateral = rng.random(n) < 0.5
    return np.stack([np.where(lateral, 0.0, h), np.where(lateral, h, 0.0), fz], axis=1)


def bench_model(name, mech, rng, sizes, baseline_cases):
    rows = []
    n_devices = len(jax.local_devices())
    for n in sizes:
        loads = mech.loads(forces={"contact_patch": envelope(n, rng)})
        # Newton + checks on one device; for large batches also the Newton alone (no flags),
        # and split over every local device.
        variants = [("one device", dict(devices=1))]
        if n >= 1000:
            variants.append(("Newton alone", dict(devices=1, checks=False)))
            if n_devices > 1:
                variants += [(f"{n_devices} devices", dict(devices=n_devices)),
                             (f"{n_devices} devices, Newton alone",
                              dict(devices=n_devices, checks=False))]
        for label, options in variants:
            t0 = time.perf_counter()
            sol = ds.solve_statics(mech, loads, throw=False, **options)
            jax.block_until_ready(sol.q)
            first = time.perf_counter() - t0
            dt, cpu, sol = timed_cpu(
                lambda loads=loads, o=options: ds.solve_statics(mech, loads, throw=False, **o),
                repeats=3 if n >= 1000 else 10)
            rows.append(dict(model=name, cases=n, variant=label, seconds=dt, per_second=n / dt,
                             cpu_seconds=cpu, per_cpu_second=n / cpu, compile_and_first=first,
                             mean_iterations=float(np.mean(sol.iterations)),
                             failed=int(np.sum(np.asarray(sol.status) != CONVERGED))))
    one = mech.loads(forces={"contact_patch": jnp.array([0.0, 0.0, 4500.0])})
    latency, _ = timed(lambda: ds.solve_statics(mech, one), repeats=20)
    # Baseline: the NumPy/SciPy Newton with a finite-difference Jacobian, same cases.
    loads = envelope(baseline_cases, rng)
    t0 = time.perf_counter()
    n_l = len(mech.load_points.names)
    for c in range(baseline_cases):
        force = np.zeros((n_l, 3))
        force[mech.load_points.index("contact_patch")] = loads[c]
        oracle.solve(mech, force, np.zeros((n_l, 3)), np.zeros(len(mech.drivers.names)))
    base = (time.perf_counter() - t0) / baseline_cases
    return rows, dict(model=name, latency_one=latency, baseline_per_solve=base)


def program_cost(name, mech, n_cases, rng):
    """Size of the batched solve_statics program (jaxpr equations, recursively) and the time of
    each stage, separately: trace, lower to StableHLO, XLA compile, run (after compile)."""
    from test_program_size import equations

    loads = mech.loads(forces={"contact_patch": envelope(n_cases, rng)})

    def solve(l):
        return ds.solve_statics(mech, l, throw=False)

    t0 = time.perf_counter()
    traced = jax.jit(solve).trace(loads)
    t1 = time.perf_counter()
    lowered = traced.lower()
    t2 = time.perf_counter()
    compiled = lowered.compile()
    t3 = time.perf_counter()
    run, _ = timed(lambda: compiled(loads), repeats=3)
    return dict(model=name, cases=n_cases, equations=equations(traced.jaxpr.jaxpr),
                stablehlo_mb=len(lowered.as_text()) / 1e6, trace=t1 - t0, lower=t2 - t1,
                compile=t3 - t2, run=run)


def thesis_call(mech):
    """One `solve_statics` call on the 13 thesis cases, flags included: the programs its first
    call compiles (names from jax_log_compiles) and the warm wall time (best and median of 50)."""
    loads = thesis_load_cases(mech)
    names = []

    class Compiles(logging.Handler):
        def emit(self, record):
            message = record.getMessage()
            if message.startswith("Compiling "):
                names.append(message.split(" ")[1])

    handler = Compiles()
    logging.getLogger("jax").addHandler(handler)
    jax.config.update("jax_log_compiles", True)
    try:
        t0 = time.perf_counter()
        jax.block_until_ready(ds.solve_statics(mech, loads).q)
        first = time.perf_counter() - t0
    finally:
        jax.config.update("jax_log_compiles", False)
        logging.getLogger("jax").removeHandler(handler)
    wall = []
    for _ in range(50):
        t0 = time.perf_counter()
        jax.block_until_ready(ds.solve_statics(mech, loads).q)
        wall.append(time.perf_counter() - t0)
    return dict(compiled=names, first_call=first, warm_best=min(wall),
                warm_median=float(np.median(wall)))


def jacobian_cost(mech):
    loads = thesis_load_cases(mech)

    def positions(k):
        m = eqx.tree_at(lambda m: (m.bushings.k_trans, m.bushings.k_rot, m.springs.k), mech, k)
        return ds.marker_poses(m, ds.solve_statics(m, loads).q)[0]

    k = (mech.bushings.k_trans, mech.bushings.k_rot, mech.springs.k)
    fn = eqx.filter_jit(jax.jacfwd(positions))
    t0 = time.perf_counter()
    jax.block_until_ready(fn(k))
    first = time.perf_counter() - t0
    dt, _ = timed(lambda: fn(k), repeats=5)
    n_params = sum(x.size for x in k)
    return dict(seconds=dt, compile_and_first=first, n_params=n_params)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true", help="small batches only (CI smoke)")
    parser.add_argument("--throughput", action="store_true",
                        help="only the 1 000-case batches and the NumPy baseline")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    sizes = (1, 13, 100) if args.quick else (1, 13, 100, 1000, 10000)
    if args.throughput:
        sizes = (1000,)
    results = dict(rows=[], models=[], programs=[])
    results["thesis_call"] = thesis_call(pseudo_mcpherson())  # first: nothing compiled yet
    for name, mech in (("pseudo_mcpherson", pseudo_mcpherson()),
                       ("double_wishbone", double_wishbone())):
        if not args.throughput:
            results["programs"].append(program_cost(name, mech, 13, rng))
    for name, mech in (("pseudo_mcpherson", pseudo_mcpherson()),
                       ("double_wishbone", double_wishbone())):
        rows, info = bench_model(name, mech, rng, sizes, baseline_cases=3 if args.quick else 13)
        results["rows"] += rows
        results["models"].append(info)
    if not args.throughput:
        results["jacobian_13_cases"] = jacobian_cost(pseudo_mcpherson())
    if not (args.quick or args.throughput):
        mech = pseudo_mcpherson()
        loads = mech.loads(forces={"contact_patch": envelope(100_000, rng)})
        t0 = time.perf_counter()
        sol = ds.solve_statics(mech, loads, throw=False, chunk=4096)
        jax.block_until_ready(sol.q)
        results["batch_100k"] = dict(seconds=time.perf_counter() - t0,
                                     failed=int(np.sum(np.asarray(sol.status) != CONVERGED)))
    results["load_average"] = os.getloadavg()
    results["max_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024

    for p in results["programs"]:
        print(f"{p['model']}: solve_statics program ({p['cases']} cases) {p['equations']} "
              f"equations, {p['stablehlo_mb']:.2f} MB StableHLO; trace {p['trace']:.2f} s, "
              f"lower {p['lower']:.2f} s, compile {p['compile']:.2f} s, run "
              f"{p['run'] * 1e3:.2f} ms")
    print(f"{'model':18s} {'cases':>7s} {'variant':>28s} {'solves/s':>10s} {'per CPU s':>10s} "
          f"{'iters':>6s} {'failed':>6s} {'compile+1st s':>13s}")
    for r in results["rows"]:
        print(f"{r['model']:18s} {r['cases']:7d} {r['variant']:>28s} {r['per_second']:10.0f} "
              f"{r['per_cpu_second']:10.0f} "
              f"{r['mean_iterations']:6.2f} {r['failed']:6d} {r['compile_and_first']:13.2f}")
    for info in results["models"]:
        best = max(r["per_second"] for r in results["rows"] if r["model"] == info["model"])
        print(f"{info['model']}: latency of one solve {info['latency_one'] * 1e3:.2f} ms; "
              f"NumPy/SciPy baseline {info['baseline_per_solve'] * 1e3:.1f} ms per solve; "
              f"ratio (best batched throughput / baseline) "
              f"{best * info['baseline_per_solve']:.0f}x")
    if "jacobian_13_cases" in results:
        jac = results["jacobian_13_cases"]
        print(f"Jacobian of all marker positions w.r.t. {jac['n_params']} stiffnesses, 13 cases: "
              f"{jac['seconds'] * 1e3:.1f} ms (compile+first {jac['compile_and_first']:.1f} s)")
    if "batch_100k" in results:
        print(f"100 000 cases (chunks of 4096): {results['batch_100k']['seconds']:.1f} s")
    call = results["thesis_call"]
    print(f"pseudo_mcpherson, one solve_statics call on the 13 thesis cases (flags included): "
          f"first call {call['first_call']:.1f} s compiling {len(call['compiled'])} program(s) "
          f"({', '.join(call['compiled'])}); warm {call['warm_best'] * 1e3:.2f} ms best, "
          f"{call['warm_median'] * 1e3:.2f} ms median")
    print(f"load average during the run (1, 5, 15 min): {results['load_average']}")
    print(f"peak RSS: {results['max_rss_mb']:.0f} MB")
    save_results("statics_throughput" if args.throughput else "statics", results, args.quick)


if __name__ == "__main__":
    main()
