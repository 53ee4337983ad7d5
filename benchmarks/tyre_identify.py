"""Benchmark: the bench identification of a steering-feel campaign, 4 tyres × 3 pressures
batched (spec tyre §3.3–3.5).

Data: for each of the 12 Annex G F_y tables (Tables 34–45) with its G.2 stiffness, a synthetic
Flat Trac campaign through the simulation model (slip sines ±1° at 3/4.5/6 Hz, load sines,
small slip steps; 40 and 120 km/h; 200 Hz; 6 N noise); generation is not timed.

Timed, all 12 sets in one compiled program (`diffsusp.tyre.bench_batch.identify_many`,
`lax.map` over the sets), per data set: the conditioning (the zero-phase 25 Hz filter and the
five-point differences as matrices, the deformation inputs, the noise level above the cut-off),
the just-necessary regressor with its relaxation columns (69 columns) filtered in parallel,
the R-factor, the library's structure search (σ % > 10 % under the noise-model sandwich σ and
the F-test at 10⁻³, refitted from R after every removal, aliases held with their removal, the
final pass under the instrumental-variable estimator) and step 2 (`bench.two_step`: K_y⁻¹ by
instrumental variables, σ of the joint model); then on the host the reports, the behaviour
rules, and the library's exact search for the sets a rule changes. Baseline in the same run:
the same pipeline in NumPy/SciPy, the library set by set (`bench.condition`,
`bench.identify_output`), timed and compared (structure, K_y) set by set.

    python benchmarks/tyre_identify.py [--quick]
"""

import pathlib
import sys
import tempfile
import time

import jax
from _common import save_results, timed_cpu

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

from diffsusp.tyre import annex_g, bench, bench_batch, poly  # noqa: E402

QUICK = "--quick" in sys.argv
SETS = [(t, p) for t in annex_g.TYRES for p in (2.0, 2.5, 3.0)]
DEGREES = poly.JUST_NECESSARY["Fy"]


def campaign(speeds):
    rows = []
    for v in speeds:
        rows += [dict(speed=v, fz0=f, camber=g, sine_amp=1.0, sine_freq=hz, sequence=4)
                 for f in (3.0, 4.5, 6.0) for g in (-1.5, 0.0, 1.5) for hz in (3.0, 4.5, 6.0)]
        rows += [dict(speed=v, fz0=f, fz_amp=0.5, fz_freq=hz, slip0=s, sequence=3)
                 for f in (3.0, 4.5) for hz in (3.0, 6.0) for s in (-1.0, 1.0)]
        rows += [dict(speed=v, fz0=f, camber=g, step_amp=1.0, step_period=2.0, sequence=2)
                 for f in (3.0, 4.5, 6.0) for g in (-1.5, 0.0, 1.5)]
    return bench.make_segments(rows)


def make_data(segments, duration):
    tables = []
    mz = poly.PolynomialModel.from_annex_g("dunlop_r16", 2.0, "Mz")
    for t, p in SETS:
        fy = poly.PolynomialModel.from_annex_g(t, p, "Fy")
        tables.append(bench.synthetic_flat_trac(
            fy, mz, k_fy=annex_g.lateral_stiffness(t, p, "Fy"),
            k_mz=annex_g.lateral_stiffness(t, p, "Mz"), segments=segments, duration=duration,
            rate=200.0, noise={"FY": 6.0, "MZ": 600.0, "FX": 3.0, "FZ": 3.0},
            seed=len(tables)))
    return tables


def main():
    segments = campaign((80.0,) if QUICK else (40.0, 80.0, 120.0, 160.0))
    duration = 1.0 if QUICK else 1.5
    t0 = time.perf_counter()
    cache = pathlib.Path(tempfile.gettempdir()) / f"diffsusp_tyre_identify{'_quick' * QUICK}.npz"
    if cache.exists():  # the campaign's generation (12 simulations) is not what is measured
        z = np.load(cache)
        tables = [{c: z[f"{i}_{c}"] for c in bench.REQUIRED} for i in range(len(SETS))]
    else:
        tables = make_data(segments, duration)
        np.savez(cache, **{f"{i}_{c}": tb[c] for i, tb in enumerate(tables) for c in tb})
    gen = time.perf_counter() - t0
    n_seg, m = segments.n, int(duration * 200)
    total = 12 * n_seg * m
    print(f"{len(SETS)} data sets × {n_seg} segments × {m} samples = {total} samples "
          f"(generated in {gen:.1f} s)")
    names = poly.regressor_model("Fy", DEGREES, ly=True).names
    p = len(names)
    K_true = np.array([annex_g.lateral_stiffness(t, pr, "Fy") for t, pr in SETS])

    # ---- JAX: the 12 sets in one compiled program (`bench_batch.identify_many`, `lax.map`):
    # conditioning, regressor, the library's structure search (σ % and F-test under the
    # noise-model sandwich σ, its final pass under the IV estimator), step 2; then on the host
    # the reports, the behaviour rules, and the exact search for the sets a rule changes
    def batched():
        return bench_batch.identify_many(tables, degrees=DEGREES, optimize=True)

    c0, t0 = time.process_time(), time.perf_counter()
    batched()
    first_wall, first_cpu = time.perf_counter() - t0, time.process_time() - c0
    wall, cpu, res = timed_cpu(batched, 3)
    program, program_cpu = res.program_seconds, res.program_cpu_seconds
    compile_wall, compile_cpu = first_wall - wall, first_cpu - cpu
    K = res.stiffness
    kept = res.kept.sum(axis=1)
    print(f"JAX (identify_many): {wall:.3f} s wall, {cpu:.3f} s CPU after compile (program "
          f"{program:.3f} s wall, {program_cpu:.3f} s CPU; {res.search_steps.sum()} removals, "
          f"{res.gram_updates.sum()} noise-Gram updates; compile {compile_wall:.1f} s wall, "
          f"{compile_cpu:.1f} s CPU); "
          f"kept {kept.min()}-{kept.max()} of {p}; exact path for {len(res.exact)} sets; "
          f"K_y error {100 * np.max(np.abs(K / K_true - 1)):.3f} % max")

    # ---- baseline: the same pipeline in NumPy/SciPy, the library set by set
    # (`bench.condition` + `bench.identify_output`; its identifiability calls are the lsq
    # JAX programs); a first set untimed (compiles those programs)
    bench.identify_output(bench.condition(tables[0]), "Fy", DEGREES)
    t0, c0 = time.perf_counter(), time.process_time()
    reps = [bench.identify_output(bench.condition(tb), "Fy", DEGREES) for tb in tables]
    lib_wall, lib_cpu = time.perf_counter() - t0, time.process_time() - c0
    K_lib = np.array([r.stiffness for r in reps])
    within = np.abs(K_lib - K_true) / (np.array([r.compliance_sigma for r in reps]) * K_true**2)
    kept_lib = np.array([len(r.reduced.names) for r in reps])
    same = [sorted(a.reduced.names) == sorted(b.reduced.names)
            for a, b in zip(res.reports, reps, strict=True)]
    dK = np.abs(K / K_lib - 1)
    print(f"NumPy/SciPy (library, set by set): {lib_wall:.3f} s wall, {lib_cpu:.3f} s CPU; "
          f"kept {kept_lib.min()}-{kept_lib.max()}; K_y error "
          f"{100 * np.max(np.abs(K_lib / K_true - 1)):.3f} % max, {within.max():.2f} sigma max")
    print(f"same structure as the library on {sum(same)} of {len(same)} sets; K_y JAX vs "
          f"library: {dK[np.array(same)].max() if any(same) else float('nan'):.2e} max relative "
          f"where the structure is the same, {dK.max():.2e} over all")
    print(f"ratio NumPy/JAX: {lib_wall / wall:.2f}x wall, {lib_cpu / cpu:.2f}x CPU")
    results = {"samples": int(total), "data_sets": len(SETS), "columns": p,
               "jax_wall_s": wall, "jax_cpu_s": cpu, "jax_program_wall_s": program,
               "jax_program_cpu_s": program_cpu, "removals": int(res.search_steps.sum()),
               "compile_wall_s": compile_wall, "compile_cpu_s": compile_cpu,
               "numpy_wall_s": lib_wall, "numpy_cpu_s": lib_cpu,
               "kept": kept.tolist(), "kept_library": kept_lib.tolist(),
               "exact_path_sets": sorted(res.exact), "same_structure": int(sum(same)),
               "K_error_pct_max": float(100 * np.max(np.abs(K / K_true - 1))),
               "K_error_pct_max_library": float(100 * np.max(np.abs(K_lib / K_true - 1))),
               "K_error_sigma_max_library": float(within.max()),
               "K_rel_diff_same_structure": float(dK[np.array(same)].max()) if any(same)
               else None, "K_rel_diff_max": float(dK.max())}
    print(save_results("tyre_identify", results, QUICK))


if __name__ == "__main__":
    main()
