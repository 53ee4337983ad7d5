"""Benchmark of K&C events with exact derivative metrics (docs/reference/metrics.md).

Run by hand: `python benchmarks/kc.py [--quick]`. Prints a table and writes
benchmarks/results/kc.json (kc_quick.json with --quick). Measures, after compilation:

1. a full parallel-travel event on pseudo_mcpherson (161 points, −80…80 mm) with every metric
   and every derivative metric (bump steer, bump camber, wheel rate, roll centre, recession
   rates, lateral / longitudinal / aligning-torque compliance steer and camber), through
   `kc.parallel_travel` (what a user calls) and through `kc.evaluate` alone;
2. 1 000 designs (the 18 bushing stiffnesses scattered ±20 %, the spring ±5 %) × the 13 load
   cases of Table 5-1 with all metrics, derivative metrics and the 6×6 wheel-centre compliance
   matrix: `kc.design_batch` (a compiled loop over the designs of `kc.evaluate` on the force
   rig, in one call), `max_steps=20` (converging cases take ≤ 8 Newton steps), and the same
   loop of the Newton alone (where the time goes: the rest is the metrics). The spring sets
   the ride height: Table 5-1's 1500 N and 7500 N cases already sit 138 mm and 102 mm from
   design on this axle, which has no bump stops, and a ±20 % spring takes 2 % of the cases past
   the suspension's travel, where there is no equilibrium; a batched Newton loop runs until its
   slowest case stops, so those few cases set the cost of their design (reported as `failed`);
3. the same computations by a plain NumPy/SciPy implementation run in the same process: the
   Newton solver of tests/oracle.py (finite-difference Jacobian) for each equilibrium and
   central finite differences of its equilibria for each derivative (2 extra solves per
   derivative direction, warm-started), on a subset of the points, reported per point and as a
   ratio. Timings are never asserted anywhere.
"""

import argparse
import pathlib
import resource
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)
import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import diffsusp as ds  # noqa: E402
from diffsusp import compilation, kc  # noqa: E402
from diffsusp.models import TABLE_5_1, pseudo_mcpherson  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))
import oracle  # noqa: E402
from _common import save_results, timed  # noqa: E402


def baseline_point(mech, force, moment, driver, directions, steps, warm=None):
    """One equilibrium and central differences along `directions` (each (dforce, dmoment,
    ddriver)) by the NumPy oracle: 1 + 2·len(directions) solves."""
    sol = oracle.solve(mech, force, moment, driver, q0=warm)
    for (df, dm, dd), h in zip(directions, steps, strict=True):
        for sign in (1.0, -1.0):
            oracle.solve(mech, force + sign * h * df, moment + sign * h * dm,
                         driver + sign * h * dd, q0=sol)
    return sol


def unit_directions(rig):
    """The rig inputs as unit perturbations of a case's arrays (primary, lateral,
    longitudinal, aligning torque)."""
    basis = kc.events._basis(rig)
    return [(np.asarray(basis.force[u]), np.asarray(basis.moment[u]),
             np.asarray(basis.driver[u])) for u in range(4)]


def bench_travel(pm, n_points, baseline_points):
    travel = np.linspace(-80.0, 80.0, n_points)
    t0 = time.perf_counter()
    ev = kc.parallel_travel(pm, travel)
    jax.block_until_ready(ev.metrics)
    first = time.perf_counter() - t0
    event_time, ev = timed(lambda: kc.parallel_travel(pm, travel), repeats=10)
    rig, loads = ev.rig, ev.loads
    kernel_time, _ = timed(lambda: kc.evaluate(rig, loads), repeats=10)
    # Baseline: oracle equilibria along the path (warm-started) + central differences.
    force, moment, driver = (np.asarray(a) for a in (loads.force, loads.moment, loads.driver))
    picks = np.linspace(0, n_points - 1, baseline_points).astype(int)
    dirs = unit_directions(rig)
    t0 = time.perf_counter()
    warm = None
    worst = 0.0
    for c in picks:
        warm = baseline_point(rig.mech, force[c], moment[c], driver[c], dirs,
                              (0.05, 2.0, 2.0, 2e3), warm)
        x, _ = oracle.marker_poses(rig.mech, warm.p, warm.R)
        k = rig.mech.markers.index("wheel_centre")
        worst = max(worst, abs(x[k, 0] - float(ev.metrics["wheel_centre_x"][c])))
    per_point = (time.perf_counter() - t0) / len(picks)
    return dict(points=n_points, compile_and_first=first, event_seconds=event_time,
                evaluate_seconds=kernel_time, iterations=float(np.mean(ev.solution.iterations)),
                baseline_per_point=per_point, baseline_points=int(len(picks)),
                baseline_event_estimate=per_point * n_points,
                ratio=per_point * n_points / event_time, max_position_difference=worst)


def bench_designs(pm, n_designs, baseline_designs, rng):
    rig = kc.force_rig(pm)
    table = TABLE_5_1
    loads = kc.events.event_loads(rig, len(table), vertical=table[:, 0], lateral=table[:, 1],
                                  longitudinal=table[:, 2])
    scale_b = rng.uniform(0.8, 1.2, (n_designs, *pm.bushings.k_trans.shape))
    scale_r = rng.uniform(0.8, 1.2, (n_designs, *pm.bushings.k_rot.shape))
    scale_s = rng.uniform(0.95, 1.05, (n_designs, *pm.springs.k.shape))
    k_trans = pm.bushings.k_trans * scale_b
    k_rot = pm.bushings.k_rot * scale_r
    k_spring = pm.springs.k * scale_s

    def design(kt, kr, ks):
        return eqx.tree_at(lambda r: (r.mech.bushings.k_trans, r.mech.bushings.k_rot,
                                      r.mech.springs.k), rig, (kt, kr, ks))

    def where(m):
        return m.bushings.k_trans, m.bushings.k_rot, m.springs.k

    def run(kt, kr, ks):  # the library's design batch: one compiled program
        return kc.design_batch(rig, where, (kt, kr, ks), loads=loads, max_steps=20)

    t0 = time.perf_counter()
    out = run(k_trans, k_rot, k_spring)
    jax.block_until_ready(out.solution)
    first = time.perf_counter() - t0
    seconds, out = timed(lambda: run(k_trans * 1.0, k_rot, k_spring), 3)
    sol, metrics = out.solution, out.metrics
    # Where the time goes: the Newton alone (the same loop of solves, no metrics).
    sel = kc.select(rig.mech, where)
    theta = jnp.asarray(out.theta)

    @compilation.filter_jit
    def solve_only(th):
        return jax.lax.map(lambda t: ds.solve_statics(sel.apply(rig.mech, t), loads,
                                                      max_steps=20, throw=False, checks=False),
                           th)

    jax.block_until_ready(solve_only(theta))
    newton_seconds, _ = timed(lambda: solve_only(theta), 3)
    status = np.asarray(sol.status)
    failed = int(np.sum(status != 0))
    failed_by_case = np.sum(status != 0, axis=0).tolist()
    iterations = np.asarray(sol.iterations)[status == 0]
    # The batch against kc.evaluate called design by design, for two designs.
    worst = 0.0
    for d in range(2):
        _, m_d, _ = kc.evaluate(design(k_trans[d], k_rot[d], k_spring[d]), loads, max_steps=20)
        for name in ("toe", "bump_steer", "lateral_compliance_steer", "wheel_rate"):
            a, b = np.asarray(m_d[name]), np.asarray(metrics[name][d])
            same_nan = np.array_equal(np.isnan(a), np.isnan(b))
            diff = np.nanmax(np.abs(a - b) / (np.abs(a) + 1e-30)) if np.any(~np.isnan(a)) else 0
            worst = max(worst, float(diff) if same_nan else np.inf)
    # Baseline: every case of a few designs by the oracle, with its 4 + 6 difference directions.
    force, moment, driver = (np.asarray(a) for a in (loads.force, loads.moment, loads.driver))
    basis = kc.events._basis(rig)
    dirs = [(np.asarray(basis.force[u]), np.asarray(basis.moment[u]),
             np.asarray(basis.driver[u])) for u in range(rig.n_inputs)]
    steps = (2.0, 2.0, 2.0, 2e3) + (10.0,) * 3 + (1e4,) * 3
    t0 = time.perf_counter()
    for d in range(baseline_designs):
        mech = design(k_trans[d], k_rot[d], k_spring[d]).mech
        for c in range(len(table)):
            baseline_point(mech, force[c], moment[c], driver[c], dirs, steps)
    per_design = (time.perf_counter() - t0) / baseline_designs
    return dict(designs=n_designs, cases=len(table), compile_and_first=first, seconds=seconds,
                newton_seconds=newton_seconds,
                failed=failed, failed_by_case=failed_by_case,
                max_iterations_converged=int(iterations.max()) if iterations.size else 0,
                vmap_vs_loop_max_relative=worst,
                baseline_per_design=per_design, baseline_designs=baseline_designs,
                baseline_estimate=per_design * n_designs,
                ratio=per_design * n_designs / seconds)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true", help="fewer designs (CI smoke)")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    pm = pseudo_mcpherson()
    results = dict(
        travel=bench_travel(pm, 161, baseline_points=3 if args.quick else 9),
        designs=bench_designs(pm, 50 if args.quick else 1000, 1 if args.quick else 2, rng),
    )
    results["max_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t, d = results["travel"], results["designs"]
    print(f"parallel travel, {t['points']} points, all metrics and derivative metrics "
          f"(pseudo_mcpherson): {t['event_seconds'] * 1e3:.1f} ms per event "
          f"(kc.evaluate alone {t['evaluate_seconds'] * 1e3:.1f} ms; compile + first "
          f"{t['compile_and_first']:.1f} s; {t['iterations']:.2f} Newton iterations per point)")
    print(f"  NumPy/SciPy baseline (oracle Newton + central differences, 9 solves per point): "
          f"{t['baseline_per_point'] * 1e3:.0f} ms per point, "
          f"{t['baseline_event_estimate']:.1f} s per event; ratio {t['ratio']:.0f}x "
          f"(largest wheel-centre difference {t['max_position_difference']:.1e} mm)")
    print(f"{d['designs']} designs x {d['cases']} load cases (Table 5-1), all metrics, "
          f"derivatives and compliance matrices: {d['seconds']:.2f} s "
          f"({d['designs'] * d['cases'] / d['seconds']:.0f} cases/s; compile + first "
          f"{d['compile_and_first']:.1f} s; the Newton alone {d['newton_seconds']:.2f} s; "
          f"{d['failed']} failed, by case "
          f"{d['failed_by_case']}; converged in ≤ {d['max_iterations_converged']} steps; vmap vs "
          f"loop {d['vmap_vs_loop_max_relative']:.1e})")
    print(f"  NumPy/SciPy baseline (21 solves per case): {d['baseline_per_design']:.1f} s per "
          f"design, {d['baseline_estimate'] / 60:.0f} min for all; ratio {d['ratio']:.0f}x")
    print(f"peak RSS: {results['max_rss_mb']:.0f} MB")
    save_results("kc", results, args.quick)


if __name__ == "__main__":
    main()
