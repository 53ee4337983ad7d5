"""Compiler options of diffsusp's programs.

XLA's CPU backend (jaxlib 0.10) hands element-wise products and reductions to YNNPACK fusions.
On the small, case-batched 3-vector algebra of the statics kernel those run 2–3× slower than
XLA's own loop fusions (the assembly of 1 000 pseudo-McPherson KKT systems: 150 ms → 60 ms of
CPU), so the programs below are compiled without them. Set on the CPU only, when a program is
first called (asking for the backend at import time would initialise it too early for a user who
configures JAX after importing diffsusp).
"""

import functools

import equinox as eqx
import jax

CPU_OPTIONS = {"xla_cpu_experimental_ynn_fusion_type": ""}
XLA_FLAG = "--xla_cpu_experimental_ynn_fusion_type="  # the same, for XLA_FLAGS (CLI, tests)


def filter_jit(fn):
    """`equinox.filter_jit(fn)`, compiled with `CPU_OPTIONS` on the CPU backend when called at
    the top level (JAX takes compiler options only there; inside another program it is an
    ordinary nested jit)."""
    nested = eqx.filter_jit(fn)
    top = {}

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        leaves = jax.tree.leaves((args, kwargs))
        if any(isinstance(x, jax.core.Tracer) for x in leaves):
            return nested(*args, **kwargs)
        if "fn" not in top:
            options = CPU_OPTIONS if jax.default_backend() == "cpu" else None
            top["fn"] = eqx.filter_jit(fn, compiler_options=options)
        return top["fn"](*args, **kwargs)

    return wrapper


def set_xla_flags(environ):
    """Add `XLA_FLAG` to `environ["XLA_FLAGS"]` (before JAX starts its backend)."""
    flags = environ.get("XLA_FLAGS", "")
    if "ynn_fusion_type" not in flags:
        environ["XLA_FLAGS"] = f"{flags} {XLA_FLAG}".strip()
