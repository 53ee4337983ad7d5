"""Rehearsal of the suspension identifications: how often is an "identified" stiffness right?

`diffsusp.identify.rehearse` with `SuspensionScenario`: N random truths (default 200) around the
start model, every selected stiffness × a log-uniform factor in 0.5–2, four landmarks per part
with σ = 0.05 mm (the thesis's arm), identified from the start model. Two scenarios:

- **isolated**: the isolated bushing (`models.isolated_bushing`), six stiffnesses, three
  combined load cases at its tip;
- **thesis**: the pseudo-McPherson (`models.pseudo_mcpherson`), bushings A and B (12
  stiffnesses), the 13 cases of Table 5-1 (the protocol of spec stiffness §2.8);
- **chrono**: a model none of the methods was written against, the Chrono double wishbone whose
  arm bushings are free in torsion (`tests/data/DoubleWishbone_bushings.json`, Krz = 0, left out
  of the unknowns: 10 stiffnesses), 12 combined contact-patch cases around its design load.

Per method and parameter: identified rate, 1/2/3σ coverage among the identified, bias/σ,
spread/σ, false-"identified" rate (claimed and outside 3σ, of all truths); per method the
consistent-verdict rate. Results to benchmarks/results/rehearse_<scenario>.json.

    python benchmarks/rehearse.py [--n 200] [--scenario isolated|thesis|chrono]
                                   [--methods direct,...] [--out FILE]
"""

import argparse
import json
import pathlib
import time

import jax
from _common import RESULTS

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

from diffsusp import load_model  # noqa: E402
from diffsusp.identify import (  # noqa: E402
    Params,  # noqa: E402
    SuspensionScenario,
    rehearse,
)
from diffsusp.kc.corner import equilibrium_load  # noqa: E402
from diffsusp.models import isolated_bushing, pseudo_mcpherson, thesis_load_cases  # noqa: E402

CHRONO = pathlib.Path(__file__).parents[1] / "tests" / "data" / "DoubleWishbone_bushings.json"


def scenario(name):
    if name == "isolated":
        mech = isolated_bushing()
        force = np.array([[30.0, -20.0, 50.0], [-12.0, 8.0, 4.0], [6.0, 3.0, -9.0]])
        moment = np.array([[2e4, -1e4, 3e4], [-5e3, 1e4, 2e3], [3e3, 4e3, -6e3]])
        return mech, mech.loads(forces={"tip": force}, moments={"tip": moment}), None
    if name == "chrono":
        mech = load_model(str(CHRONO))
        f0 = equilibrium_load(mech, "contact_patch")
        force = np.array([[x, y, z] for z in (0.7 * f0, 1.3 * f0) for y in (-2000.0, 0.0, 2000.0)
                          for x in (-1500.0, 1500.0)])
        return mech, mech.loads(forces={"contact_patch": force}), None
    mech = pseudo_mcpherson()
    return mech, thesis_load_cases(mech), Params.bushing_stiffness(mech, ("bushing_A",
                                                                          "bushing_B"))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--scenario", default="isolated")
    ap.add_argument("--methods", default="direct,least_squares,iterative")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=None,
                    help="results file (default results/rehearse_<scenario>.json; another "
                         "one lets methods run in parallel processes, merged by hand)")
    args = ap.parse_args()
    mech, loads, params = scenario(args.scenario)
    out = {}
    path = (pathlib.Path(args.out) if args.out else
            RESULTS / f"rehearse_{args.scenario}.json")
    if path.exists():
        out = json.loads(path.read_text())
    for method in args.methods.split(","):
        t0 = time.perf_counter()
        report = rehearse(SuspensionScenario(method, mech, loads, params), n=args.n,
                          seed=args.seed)
        wall = time.perf_counter() - t0
        print(report.table(), f"\n{method}: {wall:.0f} s", flush=True)
        out[method] = dict(report.summary(), wall_s=wall)
        path.write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
