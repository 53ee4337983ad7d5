"""Compiler options of diffsusp's programs, and the CLI's cache of traced programs.

XLA's CPU backend (jaxlib 0.10) hands element-wise products and reductions to YNNPACK fusions.
On the small, case-batched 3-vector algebra of the statics kernel those run 2–3× slower than
XLA's own loop fusions (the assembly of 1 000 pseudo-McPherson KKT systems: 150 ms → 60 ms of
CPU), so the programs below are compiled without them. Set on the CPU only, when a program is
first called (asking for the backend at import time would initialise it too early for a user who
configures JAX after importing diffsusp).

They are compiled with XLA's classic loop emitters instead of its MLIR fusion emitters
(`xla_cpu_use_fusion_emitters`): the programs here are many small fusions, which the MLIR path
compiles ~1.7× slower for the same code speed (pseudo-McPherson 13-case solve: 4.9 → 2.9 s of
CPU to compile, 5.4 → 4.7 ms to run; its wheel-centre Jacobian: 9.1 → 5.1 s, 6.5 → 6.2 ms).

They are also compiled without Eigen's intra-op thread pool (`xla_cpu_multi_thread_eigen`):
jaxlib's batched LAPACK kernels (LU, eigen-decomposition, SVD) split a batch over that pool and
wait for it from a pool thread, so two such calls running at once — two independent ones in one
program, or one per device — leave every thread of a 2-core machine's pool waiting: a deadlock,
met in the K&C metrics program, the on-board tyre pipeline and the statics split over devices.
Without the pool each call runs on its own thread; a batch uses both cores when it is split
over the devices (`solve_statics(devices=...)`).

**Program cache.** JAX's persistent compilation cache skips XLA's compilation on a second run,
but not the tracing and lowering of the Python code, which cost a warm `diffsusp demo` most of
its time. With `enable_program_cache(dir)` (the CLI turns it on beside the compilation cache),
each top-level program is also kept as a serialised `jax.export` artefact (StableHLO), keyed on
everything the trace depends on: the function, its static arguments (pickled: model topology,
tolerances, options), the shapes and dtypes of its array arguments, the source of the diffsusp
package, and the versions of jax and jaxlib. A later run with the same key deserialises the
program (milliseconds) instead of tracing it, and calls it compiled with the same options, so it
returns the same bits. Only the forward program is kept: a cached call is not differentiable,
which top-level calls (concrete arrays in, concrete arrays out) never need. Anything that cannot
be exported or pickled falls back to the ordinary path.
"""

import functools
import hashlib
import os
import pathlib
import pickle

import equinox as eqx
import jax

CPU_OPTIONS = {"xla_cpu_experimental_ynn_fusion_type": "", "xla_cpu_multi_thread_eigen": False,
               "xla_cpu_use_fusion_emitters": False}
XLA_FLAGS = ("--xla_cpu_experimental_ynn_fusion_type=",  # the same, for XLA_FLAGS (CLI, tests)
             "--xla_cpu_multi_thread_eigen=false", "--xla_cpu_use_fusion_emitters=false")

_PROGRAM_DIR: list = [None]  # where exported programs are kept (None: off)


def enable_program_cache(directory) -> None:
    """Keep the traced top-level programs in `directory` (None turns it off); see above."""
    _PROGRAM_DIR[0] = None if directory is None else pathlib.Path(directory)


@functools.cache
def _source_digest() -> str:
    root = pathlib.Path(__file__).parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def _spec(x):
    aval = jax.typeof(x)
    return jax.ShapeDtypeStruct(aval.shape, aval.dtype, weak_type=aval.weak_type)


class _KeyPickler(pickle.Pickler):
    """Pickles the static arguments for the key; devices and meshes by their ids and axes."""

    def reducer_override(self, obj):
        if isinstance(obj, jax.sharding.Mesh):
            return str, (f"Mesh{tuple(d.id for d in obj.devices.flat)}{obj.axis_names}",)
        if isinstance(obj, jax.Device):
            return str, (f"Device({obj.platform}, {obj.id})",)
        return NotImplemented


def _key(fn, dynamic, static) -> str:
    import io

    import jaxlib

    avals = [(s.shape, str(s.dtype), s.weak_type) for s in map(_spec, jax.tree.leaves(dynamic))]
    buffer = io.BytesIO()
    _KeyPickler(buffer).dump(static)
    parts = (fn.__module__, fn.__qualname__, buffer.getvalue(), repr(avals),
             jax.__version__, jaxlib.__version__, jax.default_backend(), _source_digest())
    return hashlib.sha256(pickle.dumps(parts)).hexdigest()


class _Exported:
    """A deserialised program: call it with the array leaves, get the output pytree."""

    def __init__(self, exported, skeleton, options):
        shardings = None
        if exported.nr_devices > 1:  # a program split over devices: inputs on all of them
            import numpy as np

            mesh = jax.sharding.Mesh(np.array(jax.local_devices()[:exported.nr_devices]), ("d",))
            shardings = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec())
        self.call = jax.jit(exported.call, compiler_options=options, in_shardings=shardings)
        self.skeleton = skeleton

    def __call__(self, leaves):
        out = self.call(*leaves)
        return jax.tree.map(lambda i: out[i], self.skeleton)


def _export(fn, dynamic, static, options, path):
    from jax import export

    leaves, treedef = jax.tree.flatten(dynamic)
    box = {}

    def flat(*leaves_):
        args, kwargs = eqx.combine(jax.tree.unflatten(treedef, leaves_), static)
        out = fn(*args, **kwargs)
        out_dynamic, out_static = eqx.partition(out, eqx.is_array)
        out_leaves, out_tree = jax.tree.flatten(out_dynamic)
        box["skeleton"] = eqx.combine(jax.tree.unflatten(out_tree, range(len(out_leaves))),
                                      out_static)
        return out_leaves

    exported = export.export(jax.jit(flat), platforms=[jax.default_backend()])(
        *map(_spec, leaves))
    blob = pickle.dumps((exported.serialize(), box["skeleton"]))
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".{os.getpid()}.tmp")
    tmp.write_bytes(blob)
    tmp.replace(path)  # atomic: a concurrent reader sees the whole file or none
    return _Exported(exported, box["skeleton"], options)


def _load(path, options):
    from jax import export

    serialized, skeleton = pickle.loads(path.read_bytes())
    return _Exported(export.deserialize(serialized), skeleton, options)


def filter_jit(fn):
    """`equinox.filter_jit(fn)`, compiled with `CPU_OPTIONS` on the CPU backend when called at
    the top level (JAX takes compiler options only there; inside another program it is an
    ordinary nested jit), and kept in the program cache when that is on."""
    nested = eqx.filter_jit(fn)
    top = {}
    programs = {}  # key → _Exported, or None when the program cannot be exported

    def options():
        return CPU_OPTIONS if jax.default_backend() == "cpu" else None

    def cached(args, kwargs):
        dynamic, static = eqx.partition((args, kwargs), eqx.is_array)
        try:
            key = _key(fn, dynamic, static)
        except Exception:  # an argument that does not pickle: no cache for this call
            return None
        if key not in programs:
            path = _PROGRAM_DIR[0] / f"{key}.jaxexport"
            try:
                programs[key] = _load(path, options()) if path.exists() else None
            except Exception:
                programs[key] = None
            if programs[key] is None:
                try:
                    programs[key] = _export(fn, dynamic, static, options(), path)
                except Exception:  # not exportable (or a user error: the plain path reports it)
                    programs[key] = None
        program = programs[key]
        return None if program is None else program(jax.tree.leaves(dynamic))

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        leaves = jax.tree.leaves((args, kwargs))
        if any(isinstance(x, jax.core.Tracer) for x in leaves):
            return nested(*args, **kwargs)
        if _PROGRAM_DIR[0] is not None:
            out = cached(args, kwargs)
            if out is not None:
                return out
        if "fn" not in top:
            top["fn"] = eqx.filter_jit(fn, compiler_options=options())
        return top["fn"](*args, **kwargs)

    return wrapper


def set_xla_flags(environ):
    """Add `XLA_FLAGS` to `environ["XLA_FLAGS"]` (before JAX starts its backend); a flag the
    user set already is kept."""
    flags = environ.get("XLA_FLAGS", "")
    for flag in XLA_FLAGS:
        if flag.split("=")[0] not in flags:
            flags = f"{flags} {flag}".strip()
    environ["XLA_FLAGS"] = flags
