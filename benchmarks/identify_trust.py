"""The held-out Monte-Carlo of tests/test_identify_trust.py, with its numbers printed
(per method and parameter: seeds identified, bias/σ, spread/σ; consistency; LM convergence) and
the CPU time. `--extra N`: N more noise draws of the same truth (σ = 0.05 mm, new keys) fitted
by `least_squares_batch` alone, for the spread/σ with a tighter interval (its relative standard
error is ≈ 1/√(2(n − 1))). Run by hand: `python benchmarks/identify_trust.py [--extra 100]`."""

import argparse
import pathlib
import sys
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))

import jax.numpy as jnp  # noqa: E402
import test_identify_trust as trust  # noqa: E402

from diffsusp import identify, measure  # noqa: E402
from diffsusp.identify.report import check_data  # noqa: E402


def _fixture(f):
    return getattr(f, "_get_wrapped_function", lambda: f.__wrapped__)()


def extra_draws(scenario, n):
    """spread/σ of every parameter over n new noise draws of the first truth (least squares,
    strut unmeasured)."""
    ref, params, truths, sets = scenario
    exact = measure.synthesize(params.apply(ref, jnp.asarray(truths[0])), sets[0].loads,
                               layout=sets[0].layout)
    keys = jax.random.split(jax.random.PRNGKey(99), n)
    batch = jax.jit(jax.vmap(lambda k: measure.add_noise(exact, measure.GaussianNoise(), k)))(
        keys)
    items = [jax.tree.map(lambda a, s=s: a[s] if hasattr(a, "shape") and a.shape[:1] == (n,)
                          else a, batch) for s in range(n)]
    data = trust._stack([check_data(ref, trust._without(m, "strut"))[0] for m in items])
    fit = identify.least_squares_batch(ref, data, params)
    err = fit.estimates - truths[0]
    print(f"extra draws: {n}, LM converged {int(fit.converged.sum())}/{n}")
    for j, name in enumerate(params.names):
        ok = np.array([r.is_identified[j] for r in fit.reports])
        if ok.sum() < 2:  # the gate (sigma% at the start values) is one verdict for all draws
            print(f"  {name:<14} {int(ok.sum()):>4}/{n} (sigma% at the start "
                  f"{fit.reports[0].gate_sigma_pct[j]:.3g})")
            continue
        sigma = np.sqrt(np.mean(fit.sigma[ok, j] ** 2))
        spread = err[ok, j].std(ddof=1) / sigma
        half = 1.96 / np.sqrt(2 * (ok.sum() - 1))
        print(f"  {name:<14} {int(ok.sum()):>4}/{n} bias/σ {err[ok, j].mean() / sigma:6.2f} "
              f"spread/σ {spread:5.2f} (95 % ±{half * spread:.2f})")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--extra", type=int, default=0)
    args = parser.parse_args()
    start = time.process_time()
    scenario = _fixture(trust.scenario)()
    truths, out, fits = _fixture(trust.results)(scenario)
    cpu = time.process_time() - start
    n = trust.N_SEEDS
    print(f"{'method':<14} {'parameter':<14} {'identified':>10} {'bias/σ':>8} {'spread/σ':>9}")
    for method, name, k, bias, spread in trust.monte_carlo_table(truths, out,
                                                                 scenario[1].names):
        print(f"{method:<14} {name:<14} {k:>7}/{n} {bias:>8.2f} {spread:>9.2f}")
    for method, res in out.items():
        clean = [(int(res["identified"][k].sum()), bool(res["consistent"][k]))
                 for k in range(n, len(truths))]
        print(f"{method}: noisy sets consistent {int(res['consistent'][:n].sum())}/{n}, mean "
              f"χ²/dof {np.mean(res['chi2'][:n]):.3g}; noise-free (identified, consistent): "
              f"{clean}")
    print(f"LM converged {sum(r.converged for r in fits)}/{len(fits)}, steps "
          f"{[r.steps for r in fits]}")
    print(f"CPU {cpu:.1f} s")
    if args.extra:
        start = time.process_time()
        extra_draws(scenario, args.extra)
        print(f"CPU (extra draws) {time.process_time() - start:.1f} s")


if __name__ == "__main__":
    main()
