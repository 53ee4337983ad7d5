"""Writes the shipped data of the identification tests.

identify_trust.npz, the data of tests/test_identify_trust.py: random true
stiffnesses of bushings A and B of `pseudo_mcpherson` (×0.5–×2 of the thesis values, Table 2.1;
seeds 1208, then 1211 and 1207, used nowhere else), the 13 cases of Table 5-1, four landmarks
per part (`measure.place_landmarks(seed=0)`) synthesised by `diffsusp.measure`: 20 noise draws
(σ = 0.05 mm, spec stiffness §2.8, keys split from PRNGKey(1208)) of the first truth, then the
noise-free landmarks of the other two. Float64, as measured and registered (poses, rms), so
the test builds its `Measurements` without solving or registering anything (≈ 20 s of CPU
spared per run).

identify_direct_mc.npz, the data of tests/test_direct.py's Monte-Carlo: the nominal
`pseudo_mcpherson` (the thesis values), the same 13 cases and landmarks, 20 noise draws
(σ = 0.05 mm, keys split from PRNGKey(2024)).

Run from the repository root: python tests/data/make_identify_trust.py"""

import pathlib

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402

from diffsusp import measure  # noqa: E402
from diffsusp.identify import Params  # noqa: E402
from diffsusp.models import pseudo_mcpherson, thesis_load_cases  # noqa: E402

PATH = pathlib.Path(__file__).parent / "identify_trust.npz"
MC_PATH = pathlib.Path(__file__).parent / "identify_direct_mc.npz"
MC_SEED = 2024
A_B = ("bushing_A", "bushing_B")
N_SEEDS = 20
TRUTH_SEED, NOISELESS_SEEDS = 1208, (1211, 1207)
FIELDS = ("rotation", "translation", "landmarks", "weights", "rms")


def random_truth(params, seed):
    rng = np.random.default_rng(seed)
    return np.asarray(params.start) * np.exp(rng.uniform(np.log(0.5), np.log(2.0), len(params)))


def record():
    ref = pseudo_mcpherson()
    loads = thesis_load_cases(ref)
    params = Params.bushing_stiffness(ref, A_B)
    layout = measure.place_landmarks(ref, seed=0)
    truths = [random_truth(params, s) for s in (TRUTH_SEED, *NOISELESS_SEEDS)]
    exact = [measure.synthesize(params.apply(ref, jnp.asarray(t)), loads, layout=layout)
             for t in truths]
    keys = jax.random.split(jax.random.PRNGKey(TRUTH_SEED), N_SEEDS)
    noisy = jax.jit(jax.vmap(lambda k: measure.add_noise(exact[0], measure.GaussianNoise(),
                                                         k)))(keys)
    out = {f: np.concatenate([np.asarray(getattr(noisy, f))]
                             + [np.asarray(getattr(m, f))[None] for m in exact[1:]])
           for f in FIELDS}
    assert all(eqx.is_array(getattr(noisy, f)) for f in FIELDS)
    return dict(out, truth=np.array([truths[0]] * N_SEEDS + truths[1:]),
                names=np.array(params.names), layout=np.asarray(layout.position),
                parts=np.array(layout.parts), sigma=np.array([noisy.sigma, exact[1].sigma]))


def record_nominal():
    ref = pseudo_mcpherson()
    exact = measure.synthesize(ref, thesis_load_cases(ref), seed=0)
    keys = jax.random.split(jax.random.PRNGKey(MC_SEED), N_SEEDS)
    noisy = jax.jit(jax.vmap(lambda k: measure.add_noise(exact, measure.GaussianNoise(), k)))(
        keys)
    return dict({f: np.asarray(getattr(noisy, f)) for f in FIELDS},
                layout=np.asarray(exact.layout.position), parts=np.array(exact.parts),
                sigma=np.array(noisy.sigma))


def main():
    np.savez_compressed(PATH, **record())
    np.savez_compressed(MC_PATH, **record_nominal())


if __name__ == "__main__":
    main()
