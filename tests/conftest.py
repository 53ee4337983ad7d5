import gc
import os

# One BLAS thread per process (set before NumPy loads it; the pytest-xdist workers and the
# notebook kernels inherit it): two workers on two cores each running a multi-threaded OpenBLAS
# spin-wait on each other (a 1176 × 60 QR: 0.12 s of CPU against 0.9 ms on one thread).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import shutil  # noqa: E402
import tempfile  # noqa: E402

import jax  # noqa: E402
import pytest  # noqa: E402
from hypothesis import settings  # noqa: E402

# Property tests draw the same examples on every run (hypothesis's derandomize): a CI run is
# reproducible, and a failing example is one a developer meets again.
settings.register_profile("diffsusp", derandomize=True)
settings.load_profile("diffsusp")

from diffsusp.compilation import set_xla_flags  # noqa: E402

# The CLI's compiler flags for every program of the tests and the notebook kernels (they
# inherit XLA_FLAGS), set before JAX starts its backend, and without XLA's backend (LLVM)
# optimisation: the suite's time is compilation, not running (pseudo-McPherson 13-case solve:
# 2.9 → 0.8 s of CPU to compile, 4.7 → 16 ms to run; its wheel-centre Jacobian 5.1 → 1.8 s and
# 6.2 → 19 ms). It changes last bits, so tests that compare with shipped files do it to the
# last bits. DIFFSUSP_TEST_O0=0 compiles as the library does.
if os.environ.get("DIFFSUSP_TEST_O0", "1") != "0":
    os.environ["XLA_FLAGS"] = " ".join([os.environ.get("XLA_FLAGS", ""),
                                        "--xla_backend_optimization_level=0",
                                        "--xla_llvm_disable_expensive_passes=true"]).strip()
set_xla_flags(os.environ)
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_num_cpu_devices", 2)  # as the CLI does: `solve_statics(devices=2)` works
# ... and so do the processes the tests start (the mkdocs build, the notebook kernels, CLI
# subprocesses): a program compiled for a backend of one device has another key in the
# compilation cache than the same program compiled with two, so a process started with JAX's
# default of one device found none of the workers' programs in the run's cache (measured: the
# pseudo-McPherson's 13-case parallel travel, 14.8 s of CPU cold, 9.0 s from the cache of a
# two-device process only when the second has two devices too).
os.environ["JAX_NUM_CPU_DEVICES"] = "2"
os.environ["DIFFSUSP_DEVICES"] = "1"  # but the CLI's commands run in-process keep one device
# The CLI's own cache (DIFFSUSP_CACHE) is off inside the tests.
os.environ["DIFFSUSP_CACHE"] = ""

# One persistent compilation cache per test run, shared by the pytest-xdist workers and the
# notebook kernels (which inherit JAX_COMPILATION_CACHE_DIR): a program that several files or
# notebooks compile (the pseudo-McPherson's 13-case solve, its K&C metrics...) is compiled once
# per run instead of once per file; a hit still traces and lowers. The controller makes the
# folder before it starts the workers (they find it in DIFFSUSP_TEST_RUN_CACHE) and removes it
# at the end. DIFFSUSP_TEST_CACHE=<dir> uses (and keeps) that folder instead, across runs.
_RUN_CACHE = "DIFFSUSP_TEST_RUN_CACHE"
_owned_cache = None
_cache_dir = os.environ.get("DIFFSUSP_TEST_CACHE") or os.environ.get(_RUN_CACHE)
if not _cache_dir:
    _cache_dir = _owned_cache = tempfile.mkdtemp(prefix="diffsusp-xla-cache-")
    os.environ[_RUN_CACHE] = _cache_dir
os.environ["JAX_COMPILATION_CACHE_DIR"] = _cache_dir
os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0.5"
jax.config.update("jax_compilation_cache_dir", _cache_dir)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)


def _write_cache_entries_atomically():
    """JAX writes a cache entry in place (unless the cache evicts, which needs `filelock`): the
    other worker could read half a file. Write to a temporary name and rename instead. A torn
    read that still happens (a notebook kernel writes in place) is a warning and a recompile:
    pyproject.toml ignores that warning."""
    try:
        from jax._src import lru_cache
    except ImportError:
        return
    put = getattr(lru_cache.LRUCache, "put", None)
    suffix = getattr(lru_cache, "_CACHE_SUFFIX", None)
    if put is None or suffix is None:
        return

    def atomic_put(self, key, value):
        if getattr(self, "eviction_enabled", True) or not key:
            return put(self, key, value)
        path = self.path / f"{key}{suffix}"
        if path.exists():
            return
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        tmp.write_bytes(value)
        os.replace(tmp, path)

    lru_cache.LRUCache.put = atomic_put


_write_cache_entries_atomically()


def pytest_unconfigure(config):
    if _owned_cache and not hasattr(config, "workerinput"):
        shutil.rmtree(_owned_cache, ignore_errors=True)


# Past these, the compiled programs are dropped at the end of a test module (see below).
_MAX_MAPPINGS = 24_000  # Linux's vm.max_map_count is 65 530
_MAX_RSS_BYTES = 5 << 30


def _memory_is_filling() -> bool:
    """True when this process's memory mappings or resident size near their limits (always
    True where /proc cannot tell)."""
    try:
        with open("/proc/self/maps", "rb") as f:
            mappings = sum(1 for _ in f)
        with open("/proc/self/statm") as f:
            rss = int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError):
        return True
    return mappings > _MAX_MAPPINGS or rss > _MAX_RSS_BYTES


@pytest.fixture(scope="module", autouse=True)
def _release_compiled_programs():
    """Drop every compiled program after a test module when memory fills. XLA maps each CPU
    executable's code into memory (~6 mappings each) and JAX's jit caches keep them alive: a
    worker that compiled one half of the suite passed Linux's vm.max_map_count (65 530) and
    died with a segmentation fault inside an XLA compile (CI, twice). Until then the programs
    stay, so that the next modules of the worker reuse the traced and compiled programs they
    share (the pseudo-McPherson's solves and K&C metrics...) instead of tracing them again;
    across workers they share the run's compilation cache."""
    yield
    if _memory_is_filling():
        jax.clear_caches()
        gc.collect()


# The files whose programs cost the most (measured: compile counts and seconds per file), handed
# out first so that the short files fill the end of the run on both workers.
_LONG_FILES = ("test_oracle.py", "test_statics.py", "test_sensitivity.py",
               "test_identify_trust.py", "test_fit.py", "test_geometric.py", "test_tyre_bench.py",
               "test_direct.py", "test_tyre_rig.py", "test_fleet.py", "test_kc.py")


def pytest_collection_modifyitems(items):
    """pytest-xdist work units (`--dist loadscope`: a module, or a test class: each notebook,
    test_notebooks.py) are handed out in collection order: the longest files first, then the
    others in name order, then the notebooks, which start when the other files have filled the
    run's compilation cache with the programs they share, and which the two workers split at
    the end. (`--dist loadgroup` would do it with xdist_group marks, but pytest-xdist 3.8
    cannot rename pytest 9's node ids: every test became a unit of its own.)"""

    def rank(item):
        name = item.path.name
        if name == "test_notebooks.py":
            return 2, 0
        if name in _LONG_FILES:
            return 0, _LONG_FILES.index(name)
        return 1, 0

    items.sort(key=rank)


# DIFFSUSP_TEST_CPU_LOG=<file>: each process appends the CPU seconds (its own and its finished
# children's: the notebook kernels) spent per work unit (module, or notebook class), to find
# where the suite's time goes (`sort -k2 -n <file>`).
_CPU_LOG = os.environ.get("DIFFSUSP_TEST_CPU_LOG")
_cpu_spent: dict = {}


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    if not _CPU_LOG:
        yield
        return
    import resource

    def cpu():
        own, kids = (resource.getrusage(w) for w in (resource.RUSAGE_SELF,
                                                     resource.RUSAGE_CHILDREN))
        return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime

    start = cpu()
    yield
    unit = item.nodeid.split("::")[0] + (f"::{item.cls.__name__}" if item.cls else "")
    _cpu_spent[unit] = _cpu_spent.get(unit, 0.0) + cpu() - start


def pytest_sessionfinish(session):
    if _CPU_LOG and _cpu_spent:
        with open(_CPU_LOG, "a") as f:
            f.writelines(f"{unit} {seconds:.1f}\n" for unit, seconds in _cpu_spent.items())
