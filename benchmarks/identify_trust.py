"""Issue 12: the held-out Monte-Carlo of tests/test_identify_trust.py, with its numbers printed
(per method and parameter: seeds identified, bias/σ, spread/σ; consistency; LM convergence) and
the CPU time. Run by hand: `python benchmarks/identify_trust.py`."""

import pathlib
import sys
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))

import test_identify_trust as trust  # noqa: E402


def main():
    start = time.process_time()
    scenario = trust.scenario.__wrapped__()
    truths, out, batch = trust.results.__wrapped__(scenario)
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
    print(f"LM converged {int(batch.converged.sum())}/{batch.converged.size}, steps "
          f"{batch.steps.tolist()}")
    print(f"CPU {cpu:.1f} s")


if __name__ == "__main__":
    main()
