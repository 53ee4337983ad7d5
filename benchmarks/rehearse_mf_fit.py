"""Monte-Carlo rehearsal of the Magic Formula fit (`diffsusp.tyre.fit.FitRehearsal`): random
truths ±20 % around a real start file (the FEDA truck tyre, PAC2002 convention), its bench
programme simulated with noise σ = 20 N + 1 % |F| (and optionally 2 % gross outliers), fitted from
the start file with default options (noise estimated from the sweeps, Huber loss, staged
strategy). Per coefficient: identified rate, coverage of the 1/2/3σ intervals among identified,
mean bias/σ, false-"identified" rate (identified but outside 3σ); per scenario the consistent-
verdict rate.

Uses `diffsusp.identify.rehearse` when it exists, else its own loop with the same numbers.

    python benchmarks/rehearse_mf_fit.py [--n 200]
        [--scenario fy|fy-outliers|fy-mz|fy-70from60|fy-70from60-outliers|all]

fy-70from60: the truths around the neighbouring 70 psi file (renormalised to the start's FNOMIN),
fitted from the 60 psi file.
"""

import argparse
import json
import time

import _common  # noqa: F401  (compiler flags, results folder)
import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

from diffsusp.io.tir import read_tir  # noqa: E402
from diffsusp.tyre import MagicFormula6  # noqa: E402
from diffsusp.tyre import fit as F  # noqa: E402
from diffsusp.tyre.examples import DATA  # noqa: E402
from diffsusp.tyre.fit_start import renormalise  # noqa: E402

SHARED = str(DATA) + "/"  # the shipped copies of the shared tyre files


DESCRIPTION = {
    "fy": "truths: the FEDA 60 psi file's F_y coefficients x(1 + 0.2 U(-1, 1)); start: the 60 "
          "psi file; F_y programme 3 loads x 3 cambers x 41 slip angles; sigma = 20 N + 1 % |F|, "
          "estimated by the fit; Huber loss",
    "fy-outliers": "as fy, and 2 % gross spikes of 30-60 sigma",
    "fy-mz": "truths around the 70 psi file; start: the 70 psi file; F_y and M_z",
    "fy-70from60": "truths: the FEDA 70 psi file's F_y coefficients (written for the 60 psi "
                   "file's FNOMIN) x(1 + 0.2 U(-1, 1)); start: the 60 psi file (a neighbouring "
                   "real file); the 60 psi programme; sigma = 20 N + 1 % |F| estimated; Huber",
    "fy-70from60-outliers": "as fy-70from60, and 2 % gross spikes of 30-60 sigma",
}


def scenario(name):
    start_file = {"fy": 60, "fy-outliers": 60, "fy-mz": 70}.get(name, 60)
    tir = read_tir(SHARED + f"335_65R22_5_G275MSA_{start_file}psi.tir")
    start = MagicFormula6.from_tir(tir)
    centre = None
    if name.startswith("fy-70from60"):   # a neighbouring file, in the start's normalisation
        centre = renormalise(MagicFormula6.from_tir(read_tir(
            SHARED + "335_65R22_5_G275MSA_70psi.tir")), float(start["FNOMIN"]))
    lim = start.limit
    channels = ("FY", "MZ") if name == "fy-mz" else ("FY",)
    prog = F.bench_programme(start, loads=np.linspace(lim["FZMIN"], lim["FZMAX"], 3),
                             cambers=[lim["CAMMIN"], 0.0, lim["CAMMAX"]], n_slip=41,
                             channels=channels)
    return F.FitRehearsal(start, prog, spread=0.2, tir=tir, centre=centre,
                          outliers=0.02 if name.endswith("outliers") else 0.0)


def own_loop(sc, n, seed):
    rng = np.random.default_rng(seed)
    truths = sc.draw(rng, n)
    reports = sc.identify(truths, rng)
    p = len(sc.names)
    ident = np.zeros((n, p), bool)
    z = np.full((n, p), np.nan)
    consistent = np.zeros(n, bool)
    for i, rep in enumerate(reports):
        st = rep.status_list
        for j, name in enumerate(sc.names):
            k = rep.names.index(name)
            ident[i, j] = st[k] == "identified"
            z[i, j] = (rep.values[k] - truths[i, j]) / rep.sigma[k]
        consistent[i] = bool(rep.consistency.consistent)
    per = {}
    for j, name in enumerate(sc.names):
        sel = ident[:, j]
        zz = np.abs(z[sel, j])
        per[name] = {"identified_rate": float(sel.mean()),
                     "coverage_1s": float(np.mean(zz <= 1)) if sel.any() else None,
                     "coverage_2s": float(np.mean(zz <= 2)) if sel.any() else None,
                     "coverage_3s": float(np.mean(zz <= 3)) if sel.any() else None,
                     "bias_over_sigma": float(np.mean(z[sel, j])) if sel.any() else None,
                     "false_identified_rate": float(np.mean(sel & ~(np.abs(z[:, j]) <= 3)))}
    return {"n": n, "consistent_rate": float(consistent.mean()), "parameters": per,
            "false_identified_overall": float(np.mean(ident & ~(np.abs(z) <= 3))),
            "coverage_3s_overall": float(np.mean(np.abs(z[ident]) <= 3))}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--scenario", default="all")
    args = ap.parse_args()
    names = ["fy", "fy-outliers", "fy-mz"] if args.scenario == "all" else [args.scenario]
    results = {}
    for name in names:
        sc = scenario(name)
        t0 = time.perf_counter()
        try:
            from diffsusp.identify import rehearse
            rep = rehearse(sc, n=args.n, seed=args.seed)
            out = rep.summary() if hasattr(rep, "summary") else rep.to_dict()
        except ImportError:
            out = own_loop(sc, args.n, args.seed)
        out["seconds"] = time.perf_counter() - t0
        results[name] = out
        rows = out.get("parameters", {})
        rows = list(rows.values()) if isinstance(rows, dict) else rows
        cov = [r["coverage_3s"] for r in rows if r.get("coverage_3s") is not None]
        out["max_false_identified_rate"] = max(r["false_identified_rate"] for r in rows)
        out["min_coverage_3s"] = min(cov) if cov else None
        out["scenario"] = DESCRIPTION[name]
        print(name, json.dumps({k: v for k, v in out.items()
                                if k not in ("parameters", "bottom_line")}))
        for v in rows:
            print("  " + " ".join(f"{a}={b:.3g}" if isinstance(b, float) else f"{a}={b}"
                                  for a, b in v.items()))
    path = _common.RESULTS / "rehearse_mf_fit.json"
    old = json.loads(path.read_text()) if path.exists() else {}
    old.update(results)
    path.write_text(json.dumps(old, indent=2) + "\n")


if __name__ == "__main__":
    main()
