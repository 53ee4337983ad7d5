"""What every benchmark script shares: timing after compilation and writing its results."""

import json
import pathlib
import time

import jax

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


def save_results(name: str, results, quick: bool = False) -> pathlib.Path:
    """Write `results` to benchmarks/results/<name>.json (<name>_quick.json for a smoke run)."""
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / f"{name}{'_quick' if quick else ''}.json"
    path.write_text(json.dumps(results, indent=2) + "\n")
    return path
