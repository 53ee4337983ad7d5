"""Rehearsal of the geometric location: how often is an "identified" joint coordinate right?

`diffsusp.identify.rehearse` with `GeometryScenario`: N random truths (default 200), the model's
located joint hardpoints (both markers of each element) displaced by a uniform ±5 mm per
coordinate, the corner's combined-load grid (`diffsusp.identify.rehearse.corner_cases`: design load
× 0.7/1/1.3, lateral −2/0/+2 kN, longitudinal ±1.5 kN, 18 cases) solved on each truth, four
landmarks per part with σ = 0.05 mm, the joints located with the nominal model as the start
(revolute priors, compliance bias). Two scenarios:

- **dw**: the built-in double wishbone (`models.double_wishbone`: revolute pivots, ball joints,
  ideal kinematics);
- **chrono**: the Chrono double wishbone whose arm bushings are free in torsion
  (`tests/data/DoubleWishbone_bushings.json`): the bushings located as revolutes, their position
  along the axis not observable, the arms' compliance carried in σ;
- **pm** (extra): the pseudo-McPherson (`models.pseudo_mcpherson`: compliant bushings A and B
  located as balls, the strut top F as a revolute; no steering, so F is not observable).

Per coordinate: identified rate, 1/2/3σ coverage among the identified, bias/σ, spread/σ,
false-"identified" rate (claimed and outside 3σ, of all truths); the consistent-verdict rate.
Results to benchmarks/results/rehearse_geometry_<scenario>.json.

    python benchmarks/rehearse_geometry.py [--n 200] [--scenario dw|chrono|pm] [--seed 0]
"""

import argparse
import json
import pathlib
import time

import jax
from _common import RESULTS

jax.config.update("jax_enable_x64", True)

from diffsusp import load_model  # noqa: E402
from diffsusp.identify._rehearse import GeometryScenario, corner_cases, rehearse  # noqa: E402
from diffsusp.models import double_wishbone, pseudo_mcpherson  # noqa: E402

CHRONO = pathlib.Path(__file__).parents[1] / "tests" / "data" / "DoubleWishbone_bushings.json"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--scenario", default="chrono")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--noise", type=float, default=0.05)
    ap.add_argument("--spread", type=float, default=5.0)
    args = ap.parse_args()
    if args.scenario == "chrono":
        mech = load_model(str(CHRONO))
    elif args.scenario == "pm":
        mech = pseudo_mcpherson()
    else:
        mech = double_wishbone()
    t0 = time.perf_counter()
    scenario = GeometryScenario(mech, corner_cases(mech), noise=args.noise, spread=args.spread)
    report = rehearse(scenario, n=args.n, seed=args.seed)
    wall = time.perf_counter() - t0
    print(report.table(), f"\ngeometry ({args.scenario}): {wall:.0f} s", flush=True)
    identified = [p for p in report.parameters if p.identified]
    summary = dict(report.summary(), wall_s=wall, scenario=args.scenario,
                   min_coverage_3s=min((p.coverage[2] for p in identified), default=None),
                   claims=sum(p.identified for p in identified),
                   wrong_claims=sum(p.false_identified for p in identified))
    path = RESULTS / f"rehearse_geometry_{args.scenario}.json"
    path.write_text(json.dumps(summary, indent=2) + "\n")


if __name__ == "__main__":
    main()
