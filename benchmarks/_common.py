"""What every benchmark script shares: timing after compilation and writing its results."""

import json
import os
import pathlib
import time

from diffsusp.compilation import set_xla_flags

set_xla_flags(os.environ)  # the CLI's compiler flags, before JAX starts its backend
import jax  # noqa: E402

jax.config.update("jax_num_cpu_devices", os.cpu_count() or 1)  # as the CLI: one per core

RESULTS = pathlib.Path(__file__).parent / "results"


def timed(fn, repeats):
    """Mean seconds per call of `fn()` over `repeats` calls after a first (compiling) call, and
    the last output."""
    out = fn()
    jax.block_until_ready(out)
    t0 = time.perf_counter()
    for _ in range(repeats):
        out = fn()
    jax.block_until_ready(out)
    return (time.perf_counter() - t0) / repeats, out


def samples(fn, repeats):
    """(wall seconds, CPU seconds of this process) of each of `repeats` calls of `fn()` after a
    first (compiling) call, and the last output. CPU time is the steadier number on a shared
    machine: other processes delay a call but do not add to its CPU time."""
    out = jax.block_until_ready(fn())
    wall, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        out = jax.block_until_ready(fn())
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return wall, cpu, out


def timed_cpu(fn, repeats):
    """(best wall seconds, best CPU seconds) per call of `fn()` (see `samples`), and the last
    output."""
    wall, cpu, out = samples(fn, repeats)
    return min(wall), min(cpu), out


def save_results(name: str, results, quick: bool = False) -> pathlib.Path:
    """Write `results` to benchmarks/results/<name>.json (<name>_quick.json for a smoke run)."""
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / f"{name}{'_quick' if quick else ''}.json"
    path.write_text(json.dumps(results, indent=2) + "\n")
    return path
