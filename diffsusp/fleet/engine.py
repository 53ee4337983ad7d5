"""Where a fleet's batches run: in this process, or on a Dask distributed cluster.

An engine takes a function and a list of tasks and yields `(index, result)` as tasks finish
(`result` is what the function returned, or the exception that ended the task). That is the
whole interface (`Engine`): a Ray engine would be another ~40 lines (`ray.remote(fn)`,
`ray.wait` in a loop, `max_retries` for dead workers).

**Why Dask.** The unit of work is independent (one batch of data sets → their reports), so a
task scheduler with retries fits, and lock-step multi-host JAX (`jax.distributed`) does not.
Dask distributed is pure Python (a pip dependency, no daemon), starts a `LocalCluster` of worker
processes on a laptop, and reaches the clusters users already have through `dask-jobqueue`
(Slurm, PBS, SGE…), `dask-kubernetes` or a running `dask scheduler` (give its address). Its
nanny restarts a killed worker and the scheduler re-runs the tasks the worker held (up to
`distributed.scheduler.allowed-failures` times, then `KilledWorker`). Ray would do the same
with a heavier runtime (its own object store and raylet daemon per node).
"""

import abc
import os

__all__ = ["DaskEngine", "Engine", "InProcessEngine", "engine_for"]


class Engine(abc.ABC):
    """Runs tasks; yields `(index, result or exception)` in the order they finish."""

    workers: int = 1

    @abc.abstractmethod
    def map_unordered(self, fn, tasks: list):
        ...

    def close(self) -> None:  # noqa: B027 - nothing to release by default
        pass

    def describe(self) -> str:
        return type(self).__name__

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class InProcessEngine(Engine):
    """Every task in this process, one after the other (the reference the clusters match)."""

    def map_unordered(self, fn, tasks: list):
        for i, task in enumerate(tasks):
            try:
                result = fn(task)
            except Exception as e:
                result = e
            yield i, result

    def describe(self) -> str:
        return "in-process"


class DaskEngine(Engine):
    """Tasks on a Dask distributed cluster.

    **Arguments** (one of): `client` (a `distributed.Client` you made: nothing is started or
    closed here), `scheduler` (the address of a running scheduler, e.g.
    `tcp://10.0.0.5:8786`, or of `dask-jobqueue`'s cluster), or `workers` (start a
    `LocalCluster` of that many worker processes, one thread each, closed with the engine).
    `retries`: re-runs of a task that raised (a task that lost its worker is re-run by the
    scheduler anyway).
    """

    def __init__(self, *, workers: int | None = None, scheduler: str | None = None,
                 client=None, retries: int = 1, env: dict | None = None):
        try:
            import distributed
        except ImportError:  # pragma: no cover - the 'fleet' extra
            from ..errors import InputError

            raise InputError("running a fleet on a cluster needs Dask: pip install "
                             "'diffsusp[fleet]' (dask[distributed]).") from None
        self._owned = []
        self.retries = retries
        if client is None:
            if scheduler is not None:
                client = distributed.Client(scheduler)
            else:
                n = int(workers or 1)
                cluster = distributed.LocalCluster(
                    n_workers=n, threads_per_worker=1, processes=True,
                    dashboard_address=":0", env=dict(env or {}))
                self._owned.append(cluster)
                client = distributed.Client(cluster)
            self._owned.insert(0, client)
        self.client = client
        self._distributed = distributed

    @property
    def workers(self) -> int:
        return max(1, len(self.client.scheduler_info(n_workers=-1).get("workers", {})))

    def map_unordered(self, fn, tasks: list):
        futures = [self.client.submit(fn, task, pure=False, retries=self.retries,
                                      key=f"diffsusp-fleet-{getattr(task, 'key', i)}")
                   for i, task in enumerate(tasks)]
        index = {f.key: i for i, f in enumerate(futures)}
        try:
            for future in self._distributed.as_completed(futures):
                try:
                    result = future.result()
                except Exception as e:  # the task raised, or its workers kept dying
                    result = e
                yield index[future.key], result
                future.release()
        finally:
            for f in futures:
                if not f.done():
                    f.cancel()

    def close(self) -> None:
        for obj in self._owned:
            obj.close()
        self._owned = []

    def describe(self) -> str:
        return f"dask ({self.workers} workers, scheduler {self.client.scheduler.address})"


def engine_for(workers: int | None = None, scheduler: str | None = None, client=None) -> Engine:
    """In-process without arguments; else a `DaskEngine`."""
    if workers is None and scheduler is None and client is None:
        return InProcessEngine()
    return DaskEngine(workers=workers, scheduler=scheduler, client=client)


def worker_environment() -> dict:
    """Variables a local worker process needs before JAX starts: the compiler flags
    (`diffsusp._compile.XLA_FLAGS`) and float64."""
    from .._compile import set_xla_flags

    env = {"XLA_FLAGS": os.environ.get("XLA_FLAGS", "")}
    set_xla_flags(env)
    return env
