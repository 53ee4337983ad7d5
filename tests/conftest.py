import os

import jax

jax.config.update("jax_enable_x64", True)
# Persistent compilation cache: notebooks executed by the tests (separate kernels) and repeated
# local runs reuse the solver's compiled programs instead of paying 20-30 s per model again.
jax.config.update(
    "jax_compilation_cache_dir",
    os.environ.setdefault(
        "JAX_COMPILATION_CACHE_DIR", os.path.join(os.path.dirname(__file__), "..", ".jax_cache")
    ),
)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
