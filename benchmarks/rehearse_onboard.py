"""Rehearsal of the on-board tyre identification (spec: tyre §5.3–5.5): how often is
an "identified" coefficient of the reduced tyre model (4-16…4-18) right?

`diffsusp.tyre.onboard_rehearse.OnboardScenario`, N random tyres (default 200) around the
synthetic car's tyre (`vehicle.TyreTruth`: each of the 8 coefficients × (1 ± 0.2 uniform);
b_delta_0, b_L_2, b_L_0 are 0 in it and stay 0), each driving the thesis's steering-wheel sine
(6 s as the tests' record, 0.2 → 6 Hz, 1.2°, 25 m/s, 1 kHz), the sensors' default noise
(`vehicle.Sensors`), identified with the default pipeline (delay estimated and removed, even/odd
instrumental variables; the pooled "all wheels" model with camber):

- **sine**: the Correvit on time;
- **sine-delay**: the Correvit 100 ms late (the pipeline must estimate and remove it);
- **sine-remove-means** (a diagnosis, not in "all"): as **sine**, with the signals' record means
  removed as the thesis does (§5.5 item 1; `onboard.identify(remove_offsets=True)`),
  which biases the load polynomials: the mean of a product is not the product of the means;
  **sine-delay-remove-means** the same with the 100 ms delay.

Per coefficient the harness's rows (`diffsusp.identify.rehearse`); besides, per truth, the
estimates, σ, claims, the delay removed and χ²/dof, and the z-scores of the physical quantities
(`onboard.QUANTITIES`: K_δ at the front and rear static loads, K_φ, L_R, K_γ; C·x and
√(C Σ Cᵀ)), to tell a bias of the load polynomials from one of the model. Results to
benchmarks/results/rehearse_onboard_<scenario>.json.

    python benchmarks/rehearse_onboard.py [--n 200] [--scenario sine|sine-delay|
    sine-remove-means|sine-delay-remove-means|all]
"""

import argparse
import json
import time

import jax
from _common import RESULTS

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

from diffsusp.identify import rehearse  # noqa: E402
from diffsusp.tyre import onboard  # noqa: E402
from diffsusp.tyre.onboard_rehearse import OnboardScenario  # noqa: E402

SCENARIOS = {"sine": 0.0, "sine-delay": 0.1, "sine-remove-means": 0.0,
             "sine-delay-remove-means": 0.1}
LOADS_KN = (4.07, 3.34)  # the static front and rear wheel loads of the synthetic car


class Recording(OnboardScenario):
    """The scenario, keeping its truths and reports for the per-truth statistics."""

    def identify(self, truths, rng):
        self.truths = np.asarray(truths)
        self.reports = super().identify(truths, rng)
        return self.reports


def per_truth(sc):
    C = onboard.quantities(LOADS_KN)
    out = []
    for truth, rep in zip(sc.truths, sc.reports, strict=True):
        if rep is None:
            out.append(None)
            continue
        x, cov = np.asarray(rep.fit.x, float), np.asarray(rep.fit.covariance, float)
        q, qs = C @ x, np.sqrt(np.einsum("ij,jk,ik->i", C, cov, C))
        out.append({"estimates": x.tolist(), "sigmas": np.nan_to_num(rep.sigmas).tolist(),
                    "identified": np.asarray(rep.is_identified, bool).tolist(),
                    "truth": truth.tolist(), "delay_s": float(rep.delay),
                    "chi2_per_dof": float(rep.consistency.chi2 / rep.consistency.dof),
                    "consistent": bool(rep.consistency.consistent),
                    "quantities_z": ((q - C @ truth) / qs).tolist()})
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--scenario", default="all")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    names = ("sine", "sine-delay") if args.scenario == "all" else (args.scenario,)
    for name in names:
        sc = Recording(delay=SCENARIOS[name], remove_offsets=name.endswith("remove-means"))
        t0 = time.perf_counter()
        rep = rehearse(sc, args.n, seed=args.seed)
        sec = time.perf_counter() - t0
        rows = per_truth(sc)
        good = [r for r in rows if r is not None]
        qz = np.array([r["quantities_z"] for r in good])
        quantities = {q: {"coverage_3": float(np.mean(np.abs(qz[:, k]) <= 3)),
                          "bias_over_sigma": float(qz[:, k].mean()),
                          "spread_over_sigma": float(qz[:, k].std(ddof=1))}
                      for k, q in enumerate(onboard.QUANTITIES)}
        delays = np.array([r["delay_s"] for r in good])
        out = {"scenario": name, "description": __doc__.split("\n\n")[1],
               "correvit_delay_s": SCENARIOS[name], "seconds": sec, **rep.summary(),
               "min_coverage_3": min((r["coverage_3s"] for r in rep.rows()
                                      if r["identified"]), default=None),
               "quantities": quantities,
               "delay_estimate": {"mean_s": float(delays.mean()),
                                  "std_s": float(delays.std(ddof=1))},
               "chi2_per_dof_median": float(np.median([r["chi2_per_dof"] for r in good])),
               "per_truth": rows}
        print(f"== {name}: {args.n} truths in {sec:.0f} s")
        print(rep.table())
        print("quantities (C x at the static loads):", json.dumps(quantities, indent=1))
        print("delay estimate", out["delay_estimate"])
        RESULTS.mkdir(exist_ok=True)
        (RESULTS / f"rehearse_onboard_{name}.json").write_text(
            json.dumps(out, indent=1, default=float) + "\n")


if __name__ == "__main__":
    main()
