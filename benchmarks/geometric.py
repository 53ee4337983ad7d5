"""Benchmark of the geometric identification (joint localisation from relative motion), spec
geometry §4.

Run by hand: `python benchmarks/geometric.py [--quick]`. The problem: the tie-rod
pseudo-McPherson (`pseudo_mcpherson_steering`), 25 cases (5 vertical loads × 5 rack positions),
four landmarks on front arm, rear arm, tie rod and hub carrier with σ = 0.05 mm noise, and the
seven joints of chapter 3 (three ball joints, the tie rod on the rack, bushing A as a ball,
bushing B as a compliant link, the strut top as a ball on an unknown slide). Measures
`locate_joints` (all solvers, one compiled program) after compilation, with and without the σ
and the observability verdict (closed form: pose covariances and the solvers' implicit
derivatives case by case), its compile time, the scaling with the number of cases, and the
same estimates computed with NumPy/SciPy (SVD registration, `lstsq`,
`scipy.optimize.least_squares` from the same 27 starts), printed as a ratio. Writes
benchmarks/results/geometric.json. Timings are never asserted anywhere.
"""

import argparse
import pathlib
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from _common import save_results, timed, timed_cpu  # noqa: E402

from diffsusp import solve_statics  # noqa: E402
from diffsusp.identify.geometric import START_OFFSETS, joints_from_model, locate_joints  # noqa: E402
from diffsusp.measure import place_landmarks  # noqa: E402
from diffsusp.measure.measurements import from_landmarks  # noqa: E402
from diffsusp.models import pseudo_mcpherson_steering  # noqa: E402
from diffsusp.statics import part_poses  # noqa: E402

MEASURED = ("front_arm", "rear_arm", "tie_rod", "hub_carrier")


def problem(n_loads: int, n_rack: int, seed: int = 0):
    mech = pseudo_mcpherson_steering()
    fz, rack = np.meshgrid(np.linspace(1500, 7500, n_loads), np.linspace(-20, 20, n_rack),
                           indexing="ij")
    n = fz.size
    force = np.zeros((n, 3))
    force[:, 2] = fz.ravel()
    loads = mech.loads(forces={"contact_patch": force}, drivers={"rack_travel": rack.ravel()})
    rot, trans = part_poses(mech, solve_statics(mech, loads).q)
    index = [mech.parts.index(p) for p in MEASURED]
    layout = place_landmarks(mech, 4, parts=MEASURED, seed=seed)
    marks = np.einsum("cpij,pkj->cpki", np.asarray(rot)[:, index], np.asarray(layout.position))
    marks += np.asarray(trans)[:, index, None]
    marks += np.random.default_rng(seed).normal(scale=0.05, size=marks.shape)
    meas = from_landmarks(layout, marks, loads)
    joints, _ = joints_from_model(mech, MEASURED, compliant=("bushing_B",))
    return mech, layout, marks, meas, joints


# ----------------------------------------------------------------------- NumPy baseline


def _register(p, q):
    pc, qc = p - p.mean(0), q - q.mean(0)
    u, _, vt = np.linalg.svd(qc.T @ pc)
    d = np.sign(np.linalg.det(u @ vt))
    r = u @ np.diag([1, 1, d]) @ vt
    return r, q.mean(0) - r @ p.mean(0)


def numpy_locate(layout, marks, joints, parts):
    ref = np.asarray(layout.position)
    n = marks.shape[0]
    poses = {"ground": (np.broadcast_to(np.eye(3), (n, 3, 3)), np.zeros((n, 3)))}
    for k, part in enumerate(parts):
        rs, ts = zip(*(_register(ref[k], marks[c, k]) for c in range(n)), strict=True)
        poses[part] = (np.array(rs), np.array(ts))
    out = {}
    ordered = sorted(joints, key=lambda j: j.kind == "compliant_bushing")
    for j in ordered:
        (r1, t1), (r2, t2) = poses[j.parts[0]], poses[j.parts[1]]
        r = np.einsum("cji,cjk->cik", r1, r2)
        t = np.einsum("cji,cj->ci", r1, t2 - t1)
        m = (r - np.eye(3)).reshape(-1, 3)
        if j.kind == "ball":
            out[j.name] = np.linalg.lstsq(m, -t.ravel(), rcond=None)[0]
        elif j.kind == "ball_known_slide":
            u = np.asarray(j.slide) / np.linalg.norm(j.slide)
            v = np.cross(u, np.eye(3)[np.argmin(np.abs(u))])
            v /= np.linalg.norm(v)
            vw = np.stack([v, np.cross(u, v)])
            a = np.einsum("ij,cjk->cik", vw, r - np.eye(3)).reshape(-1, 3)
            out[j.name] = np.linalg.lstsq(a, -np.einsum("ij,cj->ci", vw, t).ravel(),
                                          rcond=None)[0]
        elif j.kind == "ball_unknown_slide":
            def line(c, r=r, t=t):
                pts = np.concatenate([c[None], np.einsum("cij,j->ci", r, c) + t])
                d = pts - pts.mean(0)
                w, vec = np.linalg.eigh(d.T @ d)
                u = vec[:, 2]
                return (d - np.outer(d @ u, u)).ravel() / np.sqrt(w[2] / len(pts))

            grid = np.array([-1.0, 0.0, 1.0]) * START_OFFSETS
            starts = np.stack(np.meshgrid(grid, grid, grid, indexing="ij"), -1).reshape(-1, 3)
            fits = [least_squares(line, np.asarray(j.prior) + s, method="lm") for s in starts]
            out[j.name] = min(fits, key=lambda f: f.cost).x
        else:  # compliant_bushing
            ball = out[j.link_ball]

            def link(c, r=r, t=t, ball=ball):
                u = (c - ball) / np.linalg.norm(c - ball)
                delta = t + np.einsum("cij,j->ci", r, c) - c
                return np.cross(delta, np.einsum("cij,j->ci", r, u)).ravel()

            start = np.linalg.lstsq(m, -t.ravel(), rcond=None)[0]
            out[j.name] = least_squares(link, start, method="lm").x
    return out


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    repeats = 3 if args.quick else 20
    results = {}
    mech, layout, marks, meas, joints = problem(5, 5)
    t0 = time.perf_counter()
    report = locate_joints(meas, joints)
    compile_sigma = time.perf_counter() - t0
    t0 = time.perf_counter()
    locate_joints(meas, joints, with_sigma=False)
    compile_plain = time.perf_counter() - t0
    run_sigma, cpu_sigma, _ = timed_cpu(lambda: locate_joints(meas, joints).joints[0].estimate,
                                        repeats)
    run_plain, cpu_plain, _ = timed_cpu(
        lambda: locate_joints(meas, joints, with_sigma=False).joints[0].estimate, repeats)
    t0 = time.perf_counter()
    for _ in range(max(1, repeats // 5)):
        ref = numpy_locate(layout, marks, joints, MEASURED)
    run_numpy = (time.perf_counter() - t0) / max(1, repeats // 5)
    agree = max(float(np.max(np.abs(ref[j.name] - j.estimate))) for j in report.joints)
    results["25_cases"] = dict(
        compile_with_sigma_s=compile_sigma, compile_without_sigma_s=compile_plain,
        run_with_sigma_ms=1e3 * run_sigma, run_without_sigma_ms=1e3 * run_plain,
        cpu_with_sigma_ms=1e3 * cpu_sigma, cpu_without_sigma_ms=1e3 * cpu_plain,
        numpy_scipy_ms=1e3 * run_numpy, ratio_numpy_over_jax=run_numpy / run_plain,
        ratio_numpy_over_jax_with_sigma=run_numpy / run_sigma,
        max_difference_to_numpy_mm=agree)
    print(f"25 cases, {len(joints)} joints: compile {compile_sigma:.1f} s (with σ), "
          f"{compile_plain:.1f} s (without)")
    print(f"  locate_joints with σ    {1e3 * run_sigma:8.2f} ms wall (best), "
          f"{1e3 * cpu_sigma:8.2f} ms CPU")
    print(f"  locate_joints without σ {1e3 * run_plain:8.2f} ms wall (best), "
          f"{1e3 * cpu_plain:8.2f} ms CPU")
    print(f"  NumPy/SciPy (no σ)      {1e3 * run_numpy:8.2f} ms  (× {run_numpy / run_plain:.1f} "
          f"without σ, × {run_numpy / run_sigma:.1f} with; estimates agree to {agree:.1e} mm)")
    if not args.quick:
        for n_loads, n_rack in ((10, 10), (20, 20)):
            _, _, _, meas_n, _ = problem(n_loads, n_rack)
            locate_joints(meas_n, joints, with_sigma=False)
            run, _ = timed(lambda m=meas_n: locate_joints(m, joints, with_sigma=False)
                           .joints[0].estimate, repeats)
            results[f"{n_loads * n_rack}_cases"] = dict(run_without_sigma_ms=1e3 * run)
            print(f"  {n_loads * n_rack:4d} cases without σ {1e3 * run:8.2f} ms")
    path = save_results("geometric", results, quick=args.quick)
    print(f"results written to {path}")


if __name__ == "__main__":
    main()
