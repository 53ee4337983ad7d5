import gc
import os

import jax
import pytest

jax.config.update("jax_enable_x64", True)
# No persistent compilation cache by default (on a fresh clone it only costs writes). Set
# DIFFSUSP_TEST_CACHE=<dir> to reuse compiled programs across local runs (one directory per
# pytest-xdist worker; notebook kernels inherit it through JAX_COMPILATION_CACHE_DIR). The CLI's
# own cache (DIFFSUSP_CACHE) is off inside the tests either way.
os.environ["DIFFSUSP_CACHE"] = ""
_root = os.environ.get("DIFFSUSP_TEST_CACHE")
if _root:
    _dir = os.path.join(_root, os.environ.get("PYTEST_XDIST_WORKER", "main"))
    os.environ["JAX_COMPILATION_CACHE_DIR"] = _dir
    jax.config.update("jax_compilation_cache_dir", _dir)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


@pytest.fixture(scope="module", autouse=True)
def _release_compiled_programs():
    """Drop every compiled program after each test module. XLA maps each CPU executable's code
    into memory (~6 mappings each) and JAX's jit caches keep them alive: a worker that compiled
    one half of the suite passed Linux's vm.max_map_count (65 530) and died with a segmentation
    fault inside an XLA compile (CI, twice). Modules share programs through their own
    module-scoped fixtures, not across modules, so this costs no recompilation."""
    yield
    jax.clear_caches()
    gc.collect()


def pytest_collection_modifyitems(items):
    """The notebooks first: they are the longest file (one kernel after another), and
    pytest-xdist hands files out in collection order, so starting them first lets the other
    worker take the rest of the suite meanwhile instead of waiting at the end."""
    items.sort(key=lambda item: item.path.name != "test_notebooks.py")
