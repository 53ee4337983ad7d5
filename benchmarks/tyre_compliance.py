"""Monte-Carlo of the contact compliances' σ and verdicts (spec tyre §1.5, §3.3, Table 7):
`bench.identify_compliances` on synthetic campaigns of `bench.compliant_flat_trac` (the
patch on three finite-rotation joints under a Magic-Formula-shaped law: not the polynomial,
first-order model the identification is written against), slip sines, κ′ sines and load
sines at 40 and 80 km/h, loads 3 and 6 kN, the default bench noise (F_x 10 N, F_y 20 N,
M_z 2 N·m, F_z 10 N), one seed per draw.

Reported per output and compliance: the mean estimate over the truth, the spread of the
estimates over the mean σ the method claims (calibrated: within 1/1.5…1.5), the bias in
units of σ/√n (|bias| < 3), the fraction of draws where the stiffness is reported identified
and the fraction of all draws where it is reported identified with a value more than 3 σ from
the truth (at most 3 %), and the consistency verdicts; seed 0 is the noise-free recovery.

    python benchmarks/tyre_compliance.py [N_DRAWS] [OUTPUTS]   (default 20 Fx,Fy,Mz)

A run on some outputs replaces their results in `results/tyre_compliance.json` and keeps
the others'.
"""

import json
import sys
import time

import jax
import numpy as np
from _common import RESULTS, save_results

jax.config.update("jax_enable_x64", True)

from diffsusp.tyre import bench  # noqa: E402

TRUTH = {"x": 1 / 3.0e5, "y": 1 / 1.6e5, "beta": 1 / 1.3e4}


def main(n: int, outputs: tuple[str, ...]) -> dict:
    seg = bench.compliance_segments(speeds=(40.0, 80.0), loads=(3.0, 6.0))
    truth = np.array([TRUTH[k] for k in bench.COMPLIANCES])
    est = {o: [] for o in outputs}
    sig = {o: [] for o in outputs}
    ident = {o: [] for o in outputs}
    verdicts = {o: [] for o in outputs}
    free, free_ident, seconds = {}, {}, []
    for seed in range(n + 1):
        t0 = time.time()
        noise = dict(FY=0.0, MZ=0.0, FX=0.0, FZ=0.0) if seed == 0 else None
        tab = bench.compliant_flat_trac(segments=seg, seed=seed, noise=noise)
        rep = bench.identify_compliances(tab, outputs=outputs)
        for o, r in rep.outputs.items():
            c = np.asarray(r.compliance, float)
            flags = dict(zip(r.names, r.identifiable, strict=True))
            ok = [bool(flags[name]) for name in r.stiffness_names]
            if seed == 0:
                free[o] = (c / truth).tolist()
                free_ident[o] = ok
                continue
            est[o].append(c)
            sig[o].append(np.asarray(r.compliance_sigma, float))
            ident[o].append(ok)
            verdicts[o].append(bool(r.consistency.consistent))
        seconds.append(time.time() - t0)
        print(f"draw {seed}: {seconds[-1]:.1f} s", flush=True)
    out = {"draws": n, "noise_free_over_truth": free, "noise_free_identified": free_ident,
           "seconds_per_draw": float(np.median(seconds[1:])) if n else None, "outputs": {}}
    for o in outputs:
        e, s, ok = np.array(est[o]), np.array(sig[o]), np.array(ident[o], bool)
        row = {}
        for k, comp in enumerate(bench.COMPLIANCES):
            if comp not in bench.TABLE7_JOINTS[o]:
                continue
            spread, mean_sig = float(np.std(e[:, k], ddof=1)), float(np.mean(s[:, k]))
            bias = float(np.mean(e[:, k]) - truth[k])
            z = (e[:, k] - truth[k]) / s[:, k]
            row[comp] = {"mean_over_truth": float(np.mean(e[:, k]) / truth[k]),
                         "spread_over_sigma": spread / mean_sig,
                         "bias_over_sigma_sqrt_n": bias / (mean_sig / np.sqrt(n)),
                         "sigma_pct": 100.0 * mean_sig / truth[k],
                         "max_abs_z": float(np.max(np.abs(z))),
                         "identified_fraction": float(np.mean(ok[:, k])),
                         "identified_outside_3_sigma": float(np.mean(ok[:, k]
                                                                     & (np.abs(z) > 3.0)))}
        row["consistent_fraction"] = float(np.mean(verdicts[o]))
        row["per_draw"] = {"compliance": e.tolist(), "sigma": s.tolist(),
                           "identified": ok.tolist()}
        out["outputs"][o] = row
    return out


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    outputs = tuple(sys.argv[2].split(",")) if len(sys.argv) > 2 else ("Fx", "Fy", "Mz")
    res = main(n, outputs)
    print({o: {k: v for k, v in row.items() if k != "per_draw"}
           for o, row in res["outputs"].items()})
    # a run on some outputs keeps the others' results (each output with its own draw count)
    path = RESULTS / "tyre_compliance.json"
    old = json.loads(path.read_text()) if path.exists() else {}
    merged = {"outputs": dict(old.get("outputs", {}))}
    for key in ("noise_free_over_truth", "noise_free_identified", "seconds_per_draw"):
        merged[key] = {**old.get(key, {})} if isinstance(old.get(key), dict) else {}
    for o in outputs:
        merged["outputs"][o] = {"draws": n, **res["outputs"][o]}
        merged["noise_free_over_truth"][o] = res["noise_free_over_truth"][o]
        merged["noise_free_identified"][o] = res["noise_free_identified"][o]
        merged["seconds_per_draw"][",".join(outputs)] = res["seconds_per_draw"]
    for row in merged["outputs"].values():
        row.setdefault("draws", old.get("draws"))
    save_results("tyre_compliance", merged)
