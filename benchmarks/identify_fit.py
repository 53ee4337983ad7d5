"""Benchmark of least-squares identification through the equilibrium (identify.least_squares).

Run by hand: `python benchmarks/identify_fit.py [--quick]`. Prints a table and writes
benchmarks/results/identify_fit.json. Timings are never asserted anywhere.

Problem (spec stiffness §2.7, §2.8, §7 R5): the pseudo-McPherson, the 13 load cases of Table 5-1,
12 landmarks (4 on each arm and on the hub carrier) with σ = 0.05 mm Gaussian noise; the 12
stiffnesses of bushings A and B identified, log-scaled, with a weak prior (σ of log K = 3, a
factor 20) that keeps the four the landmarks cannot see bounded.

- single fit from the thesis's start (10⁴ N/mm and 10⁴ N·mm/deg): compile (first call, in a
  fresh process) and time after compile;
- batched fit of 100 noise draws (20 with --quick) started from the nominal stiffnesses, one
  vmapped program per LM step;
- baseline, same process: `scipy.optimize.least_squares` (TRF, 2-point finite-difference
  Jacobian) on the same residuals (same parameters, log scale, prior, whitening), each residual
  computed by the independent NumPy/SciPy equilibrium of tests/oracle.py, case by case, warm
  started from the previous evaluation. Run to convergence for the single fit by default (each
  SciPy Jacobian is 13 oracle fits of 13 cases, ~20 s: it can take an hour); with --quick or
  `--baseline-steps N` a few iterations, compared per iteration. The batched baseline is the
  single-fit time × the number of data sets (stated as extrapolated).
"""

import argparse
import pathlib
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy.optimize  # noqa: E402

from diffsusp.identify import (  # noqa: E402
    least_squares,
    least_squares_batch,
    predict,
)
from diffsusp.identify.data import Landmarks  # noqa: E402
from diffsusp.identify.params import Params  # noqa: E402
from diffsusp.models import pseudo_mcpherson, thesis_load_cases  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))
import oracle  # noqa: E402
from _common import save_results  # noqa: E402

DEG = np.pi / 180
SIGMA = 0.05
PRIOR_LOG_SIGMA = 3.0


def landmark_points(mech):
    pos = np.asarray(mech.markers.position)
    lines = {"front_arm": ("L1_front_arm_bushing", "L8_front_arm_ball"),
             "rear_arm": ("L2_rear_arm_bushing", "L7_rear_arm_ball"),
             "hub_carrier": ("L5_strut_base", "wheel_centre")}
    parts, points = [], []
    for part, (a, b) in lines.items():
        pa, pb = pos[mech.markers.index(a)], pos[mech.markers.index(b)]
        mid = 0.5 * (pa + pb)
        for p in (0.8 * pa + 0.2 * pb, 0.2 * pa + 0.8 * pb, mid + [0.0, 0.0, 40.0],
                  mid + [40.0, 0.0, 0.0]):
            parts.append(part)
            points.append(p)
    return tuple(parts), np.array(points)


class OracleResiduals:
    """The same whitened residuals (and prior rows) as the JAX fit, by the NumPy oracle."""

    def __init__(self, ref, params, loads, parts, points, measured, prior_u, prior_w):
        self.ref, self.params = ref, params
        self.force = np.asarray(loads.force)
        self.moment = np.asarray(loads.moment)
        self.driver = np.asarray(loads.driver)
        self.part = np.array([ref.part_index(p) for p in parts])
        self.points, self.measured = points, measured
        self.prior_u, self.prior_w = prior_u, prior_w
        self.warm = [None] * self.force.shape[0]
        self.evaluations = 0

    def __call__(self, u):
        self.evaluations += 1
        theta = np.exp(u)  # every parameter is a log-scaled stiffness
        mech = self.params.apply(self.ref, jnp.asarray(theta))
        rows = []
        for c in range(self.force.shape[0]):
            sol = oracle.solve(mech, self.force[c], self.moment[c], self.driver[c],
                               q0=self.warm[c], throw=False)
            if not sol.converged:
                rows.append(np.full(self.measured[c].size, 1e8))
                continue
            self.warm[c] = sol
            model = sol.p[self.part] + np.einsum("kij,kj->ki", sol.R[self.part], self.points)
            rows.append(((model - self.measured[c]) / SIGMA).ravel())
        rows.append((u - self.prior_u) * self.prior_w)
        return np.concatenate(rows)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--baseline-steps", type=int, default=None,
                        help="SciPy's max_nfev (default: 2 with --quick, else 200 = run to "
                        "convergence; each of its Jacobians costs 13 oracle fits of 13 cases)")
    args = parser.parse_args()
    n_sets = 20 if args.quick else 100
    rng = np.random.default_rng(0)
    results = {"quick": args.quick}

    ref = pseudo_mcpherson()
    loads = thesis_load_cases(ref)
    parts, points = landmark_points(ref)
    template = Landmarks(loads, parts, points, np.zeros((13, len(parts), 3)), SIGMA)
    t0 = time.perf_counter()
    true = np.asarray(predict(ref, template)["landmarks"])
    results["compile_equilibrium_program_s"] = time.perf_counter() - t0

    params = Params.bushing_stiffness(ref, ("bushing_A", "bushing_B"))
    nominal = np.asarray(params.values(ref))
    start = np.tile([1e4] * 3 + [1e4 / DEG] * 3, 2)
    measured = true + SIGMA * rng.normal(size=true.shape)
    data = Landmarks(loads, parts, points, measured, SIGMA)
    prior = dict(prior=start, prior_sigma=PRIOR_LOG_SIGMA * start)

    # ---------------------------------------------------------------- single fit
    t0 = time.perf_counter()
    least_squares(ref, data, params.with_start(start), **prior)
    first = time.perf_counter() - t0
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        _, report = least_squares(ref, data, params.with_start(start), **prior)
        times.append(time.perf_counter() - t0)
    single = float(np.median(times))
    results["single"] = dict(first_call_s=first, after_compile_s=single, steps=report.steps,
                             converged=report.converged,
                             per_step_ms=1e3 * single / max(report.steps, 1),
                             estimate=report.estimate.tolist(), sigma=report.sigma.tolist(),
                             identifiable=report.identifiable.tolist())

    # ---------------------------------------------------------------- batched fit
    sets = true + SIGMA * rng.normal(size=(n_sets, *true.shape))
    batch_data = Landmarks(loads, parts, points, sets, SIGMA)
    batch_prior = dict(prior=nominal, prior_sigma=PRIOR_LOG_SIGMA * nominal)
    kw = dict(start=np.tile(nominal, (n_sets, 1)), **batch_prior)
    t0 = time.perf_counter()
    least_squares_batch(ref, batch_data, params, **kw)
    first_b = time.perf_counter() - t0
    t0 = time.perf_counter()
    batch = least_squares_batch(ref, batch_data, params, **kw)
    batched = time.perf_counter() - t0
    ok = batch.reports[0].identifiable
    spread = np.log(batch.estimates).std(axis=0, ddof=1)
    sig = (batch.sigma / batch.estimates).mean(axis=0)
    results["batched"] = dict(sets=n_sets, first_call_s=first_b, after_compile_s=batched,
                              max_steps=int(batch.steps.max()),
                              converged=int(batch.converged.sum()),
                              spread_over_sigma=dict(zip(np.array(params.names)[ok].tolist(),
                                                         (spread / sig)[ok].tolist(),
                                                         strict=True)))

    # ---------------------------------------------------------------- SciPy + oracle baseline
    u0 = np.log(start)
    fn = OracleResiduals(ref, params, loads, parts, points, measured, np.log(start),
                         np.full(12, 1.0 / PRIOR_LOG_SIGMA))
    # scipy's max_nfev counts residual evaluations outside the finite-difference Jacobians.
    budget = args.baseline_steps or (2 if args.quick else 200)
    print(f"single fit {results['single']['after_compile_s']:.2f} s, batched "
          f"{results['batched']['after_compile_s']:.2f} s after compile; SciPy baseline...",
          flush=True)
    t0 = time.perf_counter()
    sp = scipy.optimize.least_squares(fn, u0, method="trf", jac="2-point", max_nfev=budget,
                                      x_scale="jac")
    baseline = time.perf_counter() - t0
    per_eval = baseline / fn.evaluations
    results["baseline"] = dict(seconds=baseline, evaluations=fn.evaluations,
                               per_evaluation_s=per_eval, status=int(sp.status),
                               converged=bool(sp.status > 0), njev=int(sp.njev))
    jax_per_eval = single / max(report.steps, 1)
    if sp.status > 0:
        results["baseline"]["estimate_rel_diff_identifiable"] = float(np.max(np.abs(
            np.exp(sp.x)[ok] / report.estimate[ok] - 1.0)))
        ratio_single = baseline / single
        note = "SciPy run to convergence"
    else:
        # Evaluation budget: compare the cost of one Jacobian + residual (an LM/TRF iteration).
        ratio_single = per_eval * (len(params) + 1) / jax_per_eval
        note = "per iteration (SciPy: p + 1 residual evaluations; diffsusp: one LM step)"
    results["ratio_single"] = dict(value=ratio_single, basis=note)
    scipy_batch = (baseline if sp.status > 0 else per_eval * (len(params) + 1) * report.steps)
    results["ratio_batched"] = dict(value=scipy_batch * n_sets / batched,
                                    basis="extrapolated: single SciPy fit × number of sets")

    print(f"equilibrium program compile (first predict): "
          f"{results['compile_equilibrium_program_s']:.1f} s")
    s = results["single"]
    print(f"single fit, 12 parameters from noisy landmarks: {s['after_compile_s']:.2f} s after "
          f"compile ({s['steps']} LM steps, {s['per_step_ms']:.1f} ms/step), first call "
          f"{s['first_call_s']:.1f} s, converged {s['converged']}")
    b = results["batched"]
    print(f"batched fit, {n_sets} data sets: {b['after_compile_s']:.2f} s after compile "
          f"({b['max_steps']} steps), first call {b['first_call_s']:.1f} s, "
          f"{b['converged']}/{n_sets} converged")
    print("  Monte-Carlo spread / reported σ (identifiable): " + ", ".join(
        f"{k} {v:.2f}" for k, v in b["spread_over_sigma"].items()))
    bl = results["baseline"]
    print(f"SciPy TRF + NumPy oracle: {bl['seconds']:.1f} s, {bl['evaluations']} residual "
          f"evaluations ({bl['per_evaluation_s']:.2f} s each), status {bl['status']}")
    print(f"ratio single: {ratio_single:.0f}× ({note}); ratio batched: "
          f"{results['ratio_batched']['value']:.0f}× (extrapolated)")
    save_results("identify_fit", results, args.quick)


if __name__ == "__main__":
    main()
