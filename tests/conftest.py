import os

import jax

jax.config.update("jax_enable_x64", True)
# Persistent compilation cache: notebooks executed by the tests (separate kernels, which inherit
# JAX_COMPILATION_CACHE_DIR) and repeated local runs reuse the solver's compiled programs instead
# of paying 20-60 s per model again. One directory per pytest-xdist worker: JAX writes cache
# entries in place, so two processes must not share one.
_root = os.environ.get("DIFFSUSP_TEST_CACHE",
                       os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".jax_cache"))
_dir = os.path.join(_root, os.environ.get("PYTEST_XDIST_WORKER", "main"))
os.environ["JAX_COMPILATION_CACHE_DIR"] = _dir
jax.config.update("jax_compilation_cache_dir", _dir)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
