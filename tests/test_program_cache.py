"""The program cache of the CLI (`diffsusp.compilation.enable_program_cache`): a second process
(here: a second wrapper of the same function) loads the exported program instead of tracing
it, and returns the same bits; any change of a static argument or of a shape is a new entry."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffsusp as ds
from diffsusp import compilation
from diffsusp.models import isolated_bushing
from diffsusp.statics import solve


class Out(eqx.Module):
    value: jax.Array
    label: str = eqx.field(static=True)


traces = []


def scaled(x, k: int, *, offset):
    traces.append(k)
    return Out(jnp.sin(x) * k + offset, f"k={k}"), None


@pytest.fixture
def cache_dir(tmp_path):
    compilation.enable_program_cache(tmp_path)
    yield tmp_path
    compilation.enable_program_cache(None)


def test_a_second_wrapper_loads_the_program_instead_of_tracing(cache_dir):
    x, offset = jnp.linspace(0.0, 1.0, 5), jnp.asarray(0.5)
    first = compilation.filter_jit(scaled)(x, 3, offset=offset)
    assert len(traces) == 1 and len(list(cache_dir.iterdir())) == 1
    again = compilation.filter_jit(scaled)(x, 3, offset=offset)  # a new process, in effect
    assert len(traces) == 1  # loaded, not traced
    assert again[0].label == "k=3" and again[1] is None
    np.testing.assert_array_equal(np.asarray(again[0].value), np.asarray(first[0].value))
    compilation.filter_jit(scaled)(x, 4, offset=offset)  # another static argument
    compilation.filter_jit(scaled)(x[:4], 3, offset=offset)  # another shape
    assert len(traces) == 3 and len(list(cache_dir.iterdir())) == 3
    # Under a transformation the plain (differentiable) path is taken.
    grad = jax.grad(lambda o: compilation.filter_jit(scaled)(x, 3, offset=o)[0].value.sum())(offset)
    assert float(grad) == 5.0


def test_a_cached_equilibrium_is_bit_identical(tmp_path):
    # The batched solve program alone, without the flags (`solve_statics` adds the host-side
    # checks of its inputs and results).
    mech = isolated_bushing()
    loads = mech.loads(forces={"tip": jnp.array([[10.0, -20.0, 30.0], [0.0, 5.0, -8.0]])})
    tol = solve._Tolerances(rtol=1e-12, atol=1e-10, max_steps=50)
    args = (mech, loads, jnp.zeros((2, mech.n_coordinates)), tol, False, 4096, False)
    plain = solve._solve_batch(*args)
    compilation.enable_program_cache(tmp_path)
    try:
        cached = solve._solve_batch(*args)
    finally:
        compilation.enable_program_cache(None)
    assert isinstance(cached[0], ds.StaticSolution) and len(list(tmp_path.iterdir())) == 1
    for a, b in zip(jax.tree.leaves(plain), jax.tree.leaves(cached), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
