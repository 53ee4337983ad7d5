import os

import jax

jax.config.update("jax_enable_x64", True)
# No persistent compilation cache by default: on a fresh clone it only costs writes, and a JAX
# cache write (serialising an executable) once crashed a CI worker with a segmentation fault.
# Set DIFFSUSP_TEST_CACHE=<dir> to reuse compiled programs across local runs (one directory per
# pytest-xdist worker; notebook kernels inherit it through JAX_COMPILATION_CACHE_DIR). The CLI's
# own cache (DIFFSUSP_CACHE) is off inside the tests either way.
os.environ["DIFFSUSP_CACHE"] = ""
_root = os.environ.get("DIFFSUSP_TEST_CACHE")
if _root:
    _dir = os.path.join(_root, os.environ.get("PYTEST_XDIST_WORKER", "main"))
    os.environ["JAX_COMPILATION_CACHE_DIR"] = _dir
    jax.config.update("jax_compilation_cache_dir", _dir)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
