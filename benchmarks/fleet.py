"""Fleet throughput: N least-squares fits of the pseudo-McPherson (N noisy landmark
tables, bushings A and B's Ktx through the equilibrium), in-process batched vs a local Dask
cluster of 2 worker processes; items/s, programs compiled, scaling efficiency, and a paper
calculation for 100 nodes.

    python benchmarks/fleet.py            # 1 000 fits, batches of 50
    python benchmarks/fleet.py --quick    # 96 fits, batches of 32

Both runs use the same persistent compilation cache (a fresh folder: the in-process run fills
it, the workers load from it), so the cluster's numbers include the workers' start-up (Python,
JAX, tracing) but not XLA compilation. Wall time is what the user waits for; CPU time (the
driver's and each worker's) is the steadier number on a shared machine. Writes
benchmarks/results/fleet.json.
"""

import argparse
import json
import os
import pathlib
import shutil
import tempfile
import time

import jax  # noqa: E402
from _common import RESULTS  # noqa: F401  (sets the CLI's XLA flags before JAX starts)

jax.config.update("jax_enable_x64", True)


def _tables(folder: pathlib.Path, n: int, mech):
    import equinox as eqx

    from diffsusp import measure
    from diffsusp.models import thesis_load_cases

    exact = measure.synthesize(mech, thesis_load_cases(mech),
                               layout=measure.place_landmarks(mech, seed=0))
    draw = eqx.filter_jit(lambda key: measure.add_noise(
        exact, measure.GaussianNoise(landmarks=0.05), key))
    for seed in range(n):
        measure.write_measurements(draw(jax.random.PRNGKey(seed)),
                                   folder / f"draw{seed:05d}.csv", mech)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--n", type=int, default=None)
    parser.add_argument("--batch", type=int, default=None)
    args = parser.parse_args()
    n = args.n or (96 if args.quick else 1000)
    batch = args.batch or (32 if args.quick else 50)

    import distributed

    from diffsusp import fleet
    from diffsusp.fleet.engine import worker_environment
    from diffsusp.models import pseudo_mcpherson

    work = pathlib.Path(tempfile.mkdtemp(prefix="diffsusp-fleet-bench-"))
    cache = work / "cache"
    jax.config.update("jax_compilation_cache_dir", str(cache))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    mech = pseudo_mcpherson()
    items = work / "items"
    items.mkdir()
    t0 = time.perf_counter()
    _tables(items, n, mech)
    print(f"{n} tables in {time.perf_counter() - t0:.1f} s")
    options = {"bushings": ["bushing_A", "bushing_B"], "axes": ["Ktx"], "max_steps": 30}
    glob = str(items / "*.csv")
    results = {"n": n, "batch": batch, "options": options, "load": os.getloadavg(),
               "cpu_count": os.cpu_count()}

    # ------------------------------------------------------------ in-process, batched
    c0, t0 = time.process_time(), time.perf_counter()
    local = fleet.run("least_squares", glob, work / "in_process", model=mech, options=options,
                      batch_size=batch)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    results["in_process"] = dict(wall_s=wall, cpu_s=cpu, items_per_s=n / wall,
                                 ok=local.ok, compiled=local.compiled,
                                 cache_hits=local.cache_hits)
    print(f"in-process: {local.text()}; CPU {cpu:.1f} s")

    # ------------------------------------------------------------ 2 local worker processes
    c0, t0 = time.process_time(), time.perf_counter()
    # The workers see as many CPU devices as this process (one per core, `_common`): the same
    # device topology, so the programs the in-process run compiled are found in the cache.
    env = {**worker_environment(), "JAX_NUM_CPU_DEVICES": str(jax.local_device_count())}
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0", env=env) as cluster, \
            distributed.Client(cluster) as client:
        started = time.perf_counter() - t0
        remote = fleet.run("least_squares", glob, work / "cluster", model=mech,
                           options=options, batch_size=batch, client=client)
        worker_cpu = sum(client.run(time.process_time).values())
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    results["cluster"] = dict(workers=2, wall_s=wall, start_s=started, run_wall_s=remote.seconds,
                              driver_cpu_s=cpu, workers_cpu_s=worker_cpu,
                              items_per_s=n / wall, ok=remote.ok, compiled=remote.compiled,
                              cache_hits=remote.cache_hits)
    print(f"cluster: {remote.text()}; start {started:.1f} s, driver CPU {cpu:.1f} s, "
          f"workers CPU {worker_cpu:.1f} s")
    same = (work / "in_process" / "summary.csv").read_text() == (
        work / "cluster" / "summary.csv").read_text()
    results["identical_summaries"] = same

    # ------------------------------------------------------------ scaling, and 100 nodes
    r1 = results["in_process"]["items_per_s"]
    r2 = results["cluster"]["items_per_s"]
    efficiency = r2 / (2 * r1)
    # Per worker, steady state: the items of one worker per second of its run, without the
    # start-up (import, tracing: paid once per worker, in parallel on a cluster).
    per_worker = n / remote.seconds / 2
    startup = started + max(0.0, remote.seconds - n / (2 * per_worker))
    nodes, cores = 100, 32
    big = 100_000
    task_overhead = 1e-3  # Dask's scheduler: ~1 ms per task (documented order of magnitude)
    t_big = startup + big / (nodes * cores * per_worker) + (big / batch) * task_overhead
    results["scaling_efficiency_2_workers"] = efficiency
    results["paper_100_nodes"] = dict(
        nodes=nodes, cores_per_node=cores, items=big, per_worker_items_per_s=per_worker,
        startup_s=startup, scheduler_s_per_task=task_overhead, batch=batch,
        estimated_wall_s=t_big, estimated_items_per_s=big / t_big)
    print(f"scaling efficiency, 2 workers vs in-process: {efficiency:.2f} "
          f"({r2:.3g} vs 2 × {r1:.3g} items/s); summaries identical: {same}")
    print(f"paper, {nodes} nodes × {cores} workers, {big:,} fits: {per_worker:.3g} items/s per "
          f"worker, {startup:.0f} s start-up, {big / batch:.0f} tasks × {task_overhead * 1e3:.0f} "
          f"ms on the scheduler → ≈ {t_big:.0f} s ({big / t_big:.3g} items/s)")
    RESULTS.mkdir(exist_ok=True)
    name = "fleet_quick.json" if args.quick else "fleet.json"
    (RESULTS / name).write_text(json.dumps(results, indent=1) + "\n")
    shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":  # the worker processes are spawned: they import this file
    main()
