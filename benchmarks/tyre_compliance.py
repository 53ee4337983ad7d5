"""Monte-Carlo of the contact compliances' σ (spec tyre §1.5, §3.3, Table 7):
`bench.identify_compliances` on synthetic campaigns of `bench.compliant_flat_trac` (the
patch on three finite-rotation joints under a Magic-Formula-shaped law: not the polynomial,
first-order model the identification is written against), slip sines, κ′ sines and load
sines at 40 and 80 km/h, loads 3 and 6 kN, the default bench noise (F_x 10 N, F_y 20 N,
M_z 2 N·m, F_z 10 N), one seed per draw.

Reported per output and compliance: the mean estimate over the truth, the spread of the
estimates over the mean σ the method claims (calibrated: within 1/1.5…1.5) and the bias in
units of σ/√n (|bias| < 3), and the consistency verdicts; seed 0 is the noise-free recovery.

    python benchmarks/tyre_compliance.py [N_DRAWS] [OUTPUTS]   (default 40 Fx)
"""

import sys
import time

import jax
import numpy as np
from _common import save_results

jax.config.update("jax_enable_x64", True)

from diffsusp.tyre import bench  # noqa: E402

TRUTH = {"x": 1 / 3.0e5, "y": 1 / 1.6e5, "beta": 1 / 1.3e4}


def main(n: int, outputs: tuple[str, ...]) -> dict:
    seg = bench.compliance_segments(speeds=(40.0, 80.0), loads=(3.0, 6.0))
    truth = np.array([TRUTH[k] for k in bench.COMPLIANCES])
    est = {o: [] for o in outputs}
    sig = {o: [] for o in outputs}
    verdicts = {o: [] for o in outputs}
    free = {}
    for seed in range(n + 1):
        t0 = time.time()
        noise = dict(FY=0.0, MZ=0.0, FX=0.0, FZ=0.0) if seed == 0 else None
        tab = bench.compliant_flat_trac(segments=seg, seed=seed, noise=noise)
        rep = bench.identify_compliances(tab, outputs=outputs)
        for o, r in rep.outputs.items():
            c = np.asarray(r.compliance, float)
            if seed == 0:
                free[o] = (c / truth).tolist()
                continue
            est[o].append(c)
            sig[o].append(np.asarray(r.compliance_sigma, float))
            verdicts[o].append(bool(r.consistency.consistent))
        print(f"draw {seed}: {time.time() - t0:.1f} s", flush=True)
    out = {"draws": n, "noise_free_over_truth": free, "outputs": {}}
    for o in outputs:
        e, s = np.array(est[o]), np.array(sig[o])
        row = {}
        for k, comp in enumerate(bench.COMPLIANCES):
            if comp not in bench.TABLE7_JOINTS[o]:
                continue
            spread, mean_sig = float(np.std(e[:, k], ddof=1)), float(np.mean(s[:, k]))
            bias = float(np.mean(e[:, k]) - truth[k])
            row[comp] = {"mean_over_truth": float(np.mean(e[:, k]) / truth[k]),
                         "spread_over_sigma": spread / mean_sig,
                         "bias_over_sigma_sqrt_n": bias / (mean_sig / np.sqrt(n)),
                         "sigma_pct": 100.0 * mean_sig / truth[k]}
        row["consistent_fraction"] = float(np.mean(verdicts[o]))
        out["outputs"][o] = row
    return out


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 40
    outputs = tuple(sys.argv[2].split(",")) if len(sys.argv) > 2 else ("Fx",)
    res = main(n, outputs)
    print(res)
    save_results("tyre_compliance", res)
