"""Benchmark: the bench identification of a steering-feel campaign, 4 tyres × 3 pressures
batched (issue 16).

Data: for each of the 12 Annex G F_y tables (Tables 34–45) with its G.2 stiffness, a synthetic
Flat Trac campaign through the simulation model (slip sines ±1° at 3/4.5/6 Hz, load sines,
small slip steps; 40 and 120 km/h; 200 Hz; 6 N noise); generation is not timed.

Timed pipeline, per data set, all 12 in one compiled program (`lax.map` over the sets):
zero-phase 25 Hz filtering (the scan form of the long records) and
five-point differences (Ḟ_y from the raw F_y, filtered with the regressor), the deformation
inputs, the just-necessary regressor with its
relaxation columns (69 columns) filtered in parallel, thinning, the R-factor, the structure
search (σ % > 10 % eliminated one at a time from R, `bench.eliminate_r`), step 2 (K_y⁻¹).
Baseline in the same run: the same pipeline in NumPy/SciPy (`scipy.signal.sosfiltfilt`,
`numpy.linalg.qr`, the elimination loop with `numpy.linalg` on the R-factor), one data set
after the other. Then the library's own identification set by set (`bench.condition`,
`bench.identify_output`: the structure search with the F-test against the noise level on the
noise-model σ, the instrumental-variable estimate), timed and checked against the truth.

    python benchmarks/tyre_identify.py [--quick]
"""

import pathlib
import sys
import tempfile
import time

import jax
from _common import save_results, timed_cpu

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy.signal  # noqa: E402

from diffsusp import lsq  # noqa: E402
from diffsusp.tyre import annex_g, bench, poly  # noqa: E402

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
    lip = poly.regressor_model("Fy", DEGREES, ly=True)
    names = lip.names
    p = len(names)
    sos = jnp.asarray(bench.butterworth(25.0, 200.0, 4))
    trim, k = 16, 4
    rows = jnp.arange(trim, m - trim, k)
    cols = {c: jnp.stack([jnp.asarray(tb[c].reshape(n_seg, m)) for tb in tables])
            for c in bench.REQUIRED if c not in ("t", "segment")}
    pneu = np.array([i for i, n in enumerate(names) if poly.parse_name(n)[1] != "Ly"])
    ly_of = np.array([names.index(f"b_Fy_Ly_{poly.parse_name(names[i])[2] - 1}_"
                                  f"{poly.parse_name(names[i])[3]}")
                      if poly.parse_name(names[i])[1] == "delta" else -1 for i in pneu])

    def one(c):
        samples, fy_f, _ = bench._condition_block(c, sos, 1.0 / 200.0, 0.294)
        W = bench._filtered_regressor(lip, samples, sos, rows)
        y = fy_f[:, rows].ravel()
        R = lsq.qr_r(jnp.concatenate([W, -y[:, None]], axis=1))
        fixed, x, sigma = bench.eliminate_r(R, y.shape[0])
        b = x[pneu]
        D = jnp.where(ly_of[None, :] >= 0, W[:, np.maximum(ly_of, 0)], 0.0)
        d = D @ b
        r = y - W[:, pneu] @ b
        return fixed, x, sigma, d @ r / (d @ d)

    # one program for the 12 sets: `lax.map` (a loop inside the program) holds one set's
    # filtered regressor in memory at a time; `vmap` needs 12× that (several GB here).
    program = jax.jit(lambda c: jax.lax.map(one, c))
    c0 = time.process_time()
    t0 = time.perf_counter()
    jax.block_until_ready(program(cols))
    compile_wall, compile_cpu = time.perf_counter() - t0, time.process_time() - c0
    wall, cpu, out = timed_cpu(lambda: program(cols), 3)
    fixed, x, sigma, comp = (np.asarray(a) for a in out)
    K = 1.0 / comp
    K_true = np.array([annex_g.lateral_stiffness(t, pr, "Fy") for t, pr in SETS])
    kept = (~fixed).sum(axis=1)
    print(f"JAX: {wall:.3f} s wall, {cpu:.3f} s CPU after compile ({compile_wall:.1f} s wall, "
          f"{compile_cpu:.1f} s CPU to compile); kept {kept.min()}–{kept.max()} of {p}; "
          f"K_y error {100 * np.max(np.abs(K / K_true - 1)):.3f} % max")

    # ---- NumPy/SciPy baseline, one set after the other
    sos_np = np.array(sos)  # writable (scipy's sosfilt needs it)

    def numpy_one(tb):
        c = {k2: np.array(tb[k2]).reshape(n_seg, m) for k2 in bench.REQUIRED
             if k2 not in ("t", "segment")}
        dt = 1 / 200.0

        def deriv(v):
            out = np.empty_like(v)
            out[..., 2:-2] = (-v[..., 4:] + 8 * v[..., 3:-1] - 8 * v[..., 1:-3]
                              + v[..., :-4]) / (12 * dt)
            out[..., :2] = out[..., 2:3]
            out[..., -2:] = out[..., -3:-2]
            return out
        speed, steer, omega = c["speed"] * 1e-3, c["steer"], c["omega"]
        fy_f = scipy.signal.sosfiltfilt(sos_np, c["FY"], axis=-1)
        u = {"fz": c["FZ"] * 1e-3, "delta": -speed * np.sin(steer) / omega,
             "phi": deriv(steer) / omega, "gamma": c["camber"],
             "fydot_w": deriv(c["FY"]) / omega}  # raw F_y: the columns are filtered
        cols_np = []
        for name in names:
            _, block, i, j = poly.parse_name(name)
            if block == "Ly":
                col = u["fydot_w"] * (i + 1) * u["delta"] ** i * u["fz"] ** j
            elif block == "one":
                col = u["fz"] ** j
            else:
                col = u[block] ** i * u["fz"] ** j
            cols_np.append(col)
        W = scipy.signal.sosfiltfilt(sos_np, np.stack(cols_np, axis=-1), axis=1)
        r_idx = np.asarray(rows)
        W = W[:, r_idx, :].reshape(-1, p)
        y = fy_f[:, r_idx].ravel()
        R = np.linalg.qr(np.concatenate([W, -y[:, None]], axis=1), mode="r")
        Rw, B = R[:p, :p], -R[:p, p]
        scale = 1 / np.linalg.norm(Rw, axis=0)
        A = Rw * scale
        keep = np.ones(p, bool)
        n_rows = len(y)
        while True:
            # rank-revealing choice as in lsq: pivoted QR on the kept columns
            idx = np.flatnonzero(keep)
            q, rr, piv = scipy.linalg.qr(A[:, idx], mode="economic", pivoting=True)
            tol = max(n_rows, p + 1) * np.finfo(float).eps
            rank = int(np.sum(np.abs(np.diag(rr)) > tol * np.abs(rr[0, 0])))
            cols_k = idx[np.sort(piv[:rank])]
            xs, *_ = np.linalg.lstsq(A[:, cols_k], B, rcond=None)
            res = np.sum((A[:, cols_k] @ xs - B) ** 2) + R[p, p] ** 2
            s2 = res / (n_rows - rank)
            cov = s2 * np.linalg.inv(A[:, cols_k].T @ A[:, cols_k])
            rel = 100 * np.sqrt(np.diag(cov)) / np.abs(xs)
            if np.max(rel) <= 10.0:
                break
            keep[cols_k[np.argmax(rel)]] = False
        x = np.zeros(p)
        x[cols_k] = xs * scale[cols_k]
        b = x[pneu]
        D = np.where(ly_of[None, :] >= 0, W[:, np.maximum(ly_of, 0)], 0.0)
        d = D @ b
        return d @ (y - W[:, pneu] @ b) / (d @ d)

    t0, c0 = time.perf_counter(), time.process_time()
    comp_np = np.array([numpy_one(tb) for tb in tables])
    np_wall, np_cpu = time.perf_counter() - t0, time.process_time() - c0
    print(f"NumPy/SciPy: {np_wall:.3f} s wall, {np_cpu:.3f} s CPU; K_y error "
          f"{100 * np.max(np.abs(1 / comp_np / K_true - 1)):.3f} % max")
    print(f"ratio NumPy/JAX: {np_wall / wall:.2f}× wall, {np_cpu / cpu:.2f}× CPU")

    # ---- the library's identification, set by set (`bench.condition` + `identify_output`:
    # the structure search with the F-test on the noise-model σ, the instrumental-variable
    # estimate and its sandwich σ); a first set untimed (compiles its programs)
    bench.identify_output(bench.condition(tables[0]), "Fy", DEGREES)
    t0, c0 = time.perf_counter(), time.process_time()
    reps = [bench.identify_output(bench.condition(tb), "Fy", DEGREES) for tb in tables]
    lib_wall, lib_cpu = time.perf_counter() - t0, time.process_time() - c0
    K_lib = np.array([r.stiffness for r in reps])
    within = np.abs(K_lib - K_true) / (np.array([r.compliance_sigma for r in reps])
                                       * K_true**2)
    kept_lib = np.array([len(r.reduced.names) for r in reps])
    misfit = np.array([r.noise_sigma / 6.0 for r in reps])
    print(f"library (search with the F-test, IV): {lib_wall:.3f} s wall, {lib_cpu:.3f} s CPU; "
          f"kept {kept_lib.min()}–{kept_lib.max()}; K_y error "
          f"{100 * np.max(np.abs(K_lib / K_true - 1)):.3f} % max, {within.max():.2f} σ max; "
          f"residual noise / injected {misfit.min():.2f}–{misfit.max():.2f}")
    results = {"samples": int(total), "data_sets": len(SETS), "columns": p,
               "jax_wall_s": wall, "jax_cpu_s": cpu, "compile_wall_s": compile_wall,
               "compile_cpu_s": compile_cpu, "numpy_wall_s": np_wall, "numpy_cpu_s": np_cpu,
               "kept_min": int(kept.min()), "kept_max": int(kept.max()),
               "K_error_pct_max": float(100 * np.max(np.abs(K / K_true - 1))),
               "K_error_pct_max_numpy": float(100 * np.max(np.abs(1 / comp_np / K_true - 1))),
               "library_wall_s": lib_wall, "library_cpu_s": lib_cpu,
               "library_kept_min": int(kept_lib.min()), "library_kept_max": int(kept_lib.max()),
               "K_error_pct_max_library": float(100 * np.max(np.abs(K_lib / K_true - 1))),
               "K_error_sigma_max_library": float(within.max()),
               "library_residual_over_noise_max": float(misfit.max())}
    print(save_results("tyre_identify", results, QUICK))


if __name__ == "__main__":
    main()
