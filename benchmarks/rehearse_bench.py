"""Rehearsal of the bench identification (spec: tyre §3.3–3.5, §4.3): how often is
an "identified" polynomial coefficient or K_y right?

Two scenarios (`diffsusp.tyre.bench_batch.BenchScenario`), each N random tyres (default 200)
around a start model — every non-zero F_pneu coefficient × U(0.8, 1.2), K_y × log-uniform
0.5–2 — simulated through the state-space model (3-82…3-87) on the scenario's bench programme,
the noise added, identified batched (`identify_many`: the structure search from Table 10's
degrees, two-step K_y):

- **het**: start the Dunlop R16 at 2.5 bar (Table 35, G.2 stiffnesses); the steering-feel
  programme of the shipped test campaign (54 segments: slip sines at three loads and cambers,
  load sines, medium slip ramps; 40 and 120 km/h; 1 s at 200 Hz); noise growing with the
  force, σ_FY = 2 N + 1 %·|F_y|, σ_MZ = 0.6 N·m, F_x, F_z 3 N;
- **outliers**: start the Dunlop R16 at 2.0 bar (Table 34); a reduced programme (24
  segments: slip sines at two loads and cambers, load sines, slip ramps); white noise 6 N on
  F_y and 2 % of its samples hit by ±20 σ spikes.

Per parameter (among the coefficients with a non-zero truth, the coefficients whose truth is 0
that the search kept, and K_y): how often "identified", the coverage of the 1/2/3 σ
intervals among the identified, the mean (estimate − truth)/σ, and the false "identified"
rate (claimed identified but outside 3 σ, of all claims); per scenario the consistent-verdict
rate. Results to benchmarks/results/rehearse_bench_<scenario>.json.

    python benchmarks/rehearse_bench.py [--n 200] [--scenario het|outliers|all]
"""

import argparse
import json
import sys
import time

import jax
from _common import RESULTS

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

from diffsusp.tyre import annex_g, bench, bench_batch, poly  # noqa: E402


def programme_54():
    return bench.make_segments(
        [dict(speed=v, fz0=f, camber=g, sine_amp=1.0, sine_freq=hz, sequence=4)
         for v in (40.0, 120.0) for f in (3.0, 4.5, 6.0) for g in (-1.5, 0.0, 1.5)
         for hz in (3.0, 6.0)]
        + [dict(speed=v, fz0=f, fz_amp=0.5, fz_freq=3.0, slip0=s, sequence=3)
           for v in (40.0, 120.0) for f in (3.0, 4.5) for s in (-1.0, 1.0)]
        + [dict(speed=v, fz0=f, camber=g, ramp_amp=3.0, ramp_period=2.0, step_amp=1.0,
                step_period=1.0, sequence=5)
           for v in (40.0, 120.0) for f, g in ((3.0, 0.0), (4.5, -1.5), (4.5, 0.0),
                                               (4.5, 1.5), (6.0, 0.0))])


def programme_24():
    return bench.make_segments(
        [dict(speed=v, fz0=f, camber=g, sine_amp=1.0, sine_freq=hz, sequence=4)
         for v in (40.0, 120.0) for f in (3.0, 6.0) for g in (0.0, 1.5) for hz in (3.0, 6.0)]
        + [dict(speed=v, fz0=4.5, fz_amp=0.5, fz_freq=3.0, slip0=s, sequence=3)
           for v in (40.0, 120.0) for s in (-1.0, 1.0)]
        + [dict(speed=v, fz0=f, ramp_amp=3.0, ramp_period=2.0, step_amp=1.0,
                step_period=1.0, sequence=5) for v in (40.0, 120.0) for f in (3.0, 6.0)])


def scenario(name):
    if name == "het":
        p, seg = 2.5, programme_54()
        noise = {"FY": (2.0, 0.01), "MZ": (600.0, 0.0), "FX": 3.0, "FZ": 3.0}
        extra = {}
    else:
        p, seg = 2.0, programme_24()
        noise = {"FY": (6.0, 0.0), "MZ": (600.0, 0.0), "FX": 3.0, "FZ": 3.0}
        extra = {"outliers": 0.02, "outlier_size": 20.0}
    return bench_batch.BenchScenario(
        fy=poly.PolynomialModel.from_annex_g("dunlop_r16", p, "Fy"),
        mz=poly.PolynomialModel.from_annex_g("dunlop_r16", p, "Mz"),
        k_fy=annex_g.lateral_stiffness("dunlop_r16", p, "Fy"),
        k_mz=annex_g.lateral_stiffness("dunlop_r16", p, "Mz"),
        segments=seg, noise=noise, optimize=True, **extra)


def statistics(sc, truths, reports):
    """Per parameter and per scenario, as the rehearsal reports them (see the docstring)."""
    names = sc.names
    est = np.array([[dict(zip(r.names, r.estimates, strict=True))[n] for n in names]
                    for r in reports])
    sig = np.array([[dict(zip(r.names, r.sigmas, strict=True))[n] for n in names]
                    for r in reports])
    ident = np.array([[dict(zip(r.names, r.is_identified, strict=True))[n] for n in names]
                      for r in reports])
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (est - truths) / sig
    out = {}
    for k, n in enumerate(names):
        idk = ident[:, k]
        if not (np.any(truths[:, k] != 0) or idk.any()):
            continue
        zk = z[idk, k]
        m = int(idk.sum())
        out[n] = {"identified_rate": float(idk.mean()), "n_identified": m,
                  "coverage_1": float(np.mean(np.abs(zk) <= 1)) if m else None,
                  "coverage_2": float(np.mean(np.abs(zk) <= 2)) if m else None,
                  "coverage_3": float(np.mean(np.abs(zk) <= 3)) if m else None,
                  "bias_over_sigma": float(np.mean(zk)) if m else None,
                  "false_identified": int(np.sum(np.abs(zk) > 3)),
                  "false_identified_rate": float(np.mean(np.abs(zk) > 3)) if m else 0.0,
                  "truth_zero": bool(np.all(truths[:, k] == 0))}
    cons = [r.consistency is not None and r.consistency.consistent for r in reports]
    claims = int(ident.sum())
    false = int(np.sum(ident & (np.abs(z) > 3)))
    return {"parameters": out, "consistent_rate": float(np.mean(cons)),
            "claims": claims, "false_claims": false,
            "false_identified_rate": false / max(claims, 1),
            "chi2_per_dof": [float(r.consistency.chi2_per_dof) for r in reports]}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--scenario", default="all")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    names = ("het", "outliers") if args.scenario == "all" else (args.scenario,)
    results = {}
    for name in names:
        sc = scenario(name)
        rng = np.random.default_rng(args.seed)
        t0 = time.perf_counter()
        truths = sc.draw(rng, args.n)
        reports = sc.identify(truths, rng)
        sec = time.perf_counter() - t0
        st = statistics(sc, truths, reports)
        st["seconds"] = sec
        st["n"] = args.n
        results[name] = st
        print(f"== {name}: {args.n} truths in {sec:.0f} s; consistent {st['consistent_rate']:.3f};"
              f" claims {st['claims']}, false {st['false_claims']} "
              f"({100 * st['false_identified_rate']:.2f} %)")
        print(f"{'parameter':<18}{'ident':>7}{'cov1':>7}{'cov2':>7}{'cov3':>7}{'bias/s':>8}"
              f"{'false':>7}")
        for n, s in st["parameters"].items():
            def f(v):
                return "   -  " if v is None else f"{v:7.3f}"

            def g(v):
                return " " * 8 if v is None else f"{v:8.2f}"

            print(f"{n:<18}{s['identified_rate']:7.3f}{f(s['coverage_1'])}{f(s['coverage_2'])}"
                  f"{f(s['coverage_3'])}{g(s['bias_over_sigma'])}"
                  f"{s['false_identified']:7d}{'  (truth 0)' if s['truth_zero'] else ''}")
        sys.stdout.flush()
        RESULTS.mkdir(exist_ok=True)
        (RESULTS / f"rehearse_bench_{name}.json").write_text(
            json.dumps(results[name], indent=1) + "\n")


if __name__ == "__main__":
    main()
