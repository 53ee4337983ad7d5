"""Where a fleet's batches run: in this process, or on a Dask distributed cluster.

An engine takes a function, a list of tasks and optionally a time limit per task, and yields
`(index, result)` as tasks finish (`result` is what the function returned, or the exception
that ended the task: `ItemTimeout` for a task stopped at its limit). That is the whole
interface (`Engine`): a Ray engine would be another ~60 lines (`ray.remote(fn)`, `ray.wait`
with a timeout in a loop, `ray.cancel(force=True)` at the limit, `max_retries` for dead
workers).

**Time limits: what is guaranteed.** `InProcessEngine` cannot stop a running call (Python
cannot interrupt a thread inside XLA): the limit is only what the recipes check between items
and between the steps of a fit. `DaskEngine` enforces it: each task announces its start
(`Worker.log_event`, topic `diffsusp-fleet`), the driver watches the clock, and a task still
running `limit + HARD_GRACE` seconds after its start is cancelled and its worker restarted
(`Client.restart_workers`, through the worker's nanny: the process is killed, whatever it was
doing, and a fresh one joins); the task's result is an `ItemTimeout`. Guaranteed: no task
occupies a worker longer than its limit + `HARD_GRACE` + the restart (a few seconds) plus the
driver's polling (≤ 1 s). Not guaranteed: a worker run without a nanny (`dask worker
--no-nanny`) cannot be restarted (the task is still reported `timeout`, but its worker stays
busy until the call returns); the other tasks queued on a restarted worker are rescheduled
(they are not lost, and not counted against `allowed-failures`). A cluster of your own should
give a restarted worker time to come back: Dask's `distributed.deploy.lost-worker-timeout`
(15 s by default) closes the nanny of a worker that has not, and a worker importing JAX on a
loaded machine can take longer (the cluster a `DaskEngine` starts uses
`LOST_WORKER_TIMEOUT`). The clock of a task includes
its reading and compiling (the first batch of a shape on a worker).

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
import threading
import time

from ..compilation import set_xla_flags
from ..errors import InputError
from .recipes import ItemTimeout

__all__ = ["HARD_GRACE", "LOST_WORKER_TIMEOUT", "DaskEngine", "Engine", "InProcessEngine",
           "engine_for"]

LOST_WORKER_TIMEOUT = "300s"
"""How long the `LocalCluster` a `DaskEngine` starts waits for a restarted worker before it
closes the worker's nanny (Dask's `distributed.deploy.lost-worker-timeout`, 15 s by default):
a worker restarted past its time limit imports JAX and the library again, which takes longer
than 15 s on a loaded machine, and the cluster then lost the worker for good."""

HARD_GRACE = 2.0
"""Seconds past a task's time limit before `DaskEngine` restarts its worker (so that a recipe's
own checks, which stop a fit cleanly, come first)."""
_TOPIC = "diffsusp-fleet"


class Engine(abc.ABC):
    """Runs tasks; yields `(index, result or exception)` in the order they finish. `limits`:
    seconds per task (a list, None entries: no limit), enforced as the engine can (see the
    module docstring)."""

    workers: int = 1

    @abc.abstractmethod
    def map_unordered(self, fn, tasks: list, limits: list | None = None):
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
    """Every task in this process, one after the other (the reference the clusters match).
    Time limits are left to the tasks' own checks: a running call is not interrupted."""

    def map_unordered(self, fn, tasks: list, limits: list | None = None):
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
    scheduler anyway). Time limits are enforced by restarting the worker of a task that runs
    past its limit + `HARD_GRACE` (see the module docstring).
    """

    def __init__(self, *, workers: int | None = None, scheduler: str | None = None,
                 client=None, retries: int = 1, env: dict | None = None):
        try:
            import distributed
        except ImportError:  # pragma: no cover - the 'fleet' extra
            raise InputError("running a fleet on a cluster needs Dask: pip install "
                             "'diffsusp[fleet]' (dask[distributed]).") from None
        self._owned = []
        self.retries = retries
        if client is None:
            if scheduler is not None:
                client = distributed.Client(scheduler)
            else:
                n = int(workers or 1)
                import dask

                # for the cluster's life (its callbacks read the global config when a worker
                # goes): restored by `close`
                config = dask.config.set(
                    {"distributed.deploy.lost-worker-timeout": LOST_WORKER_TIMEOUT})
                cluster = distributed.LocalCluster(
                    n_workers=n, threads_per_worker=1, processes=True,
                    dashboard_address=":0", env=dict(env or {}))
                self._owned += [cluster, _Exit(config)]
                client = distributed.Client(cluster)
            self._owned.insert(0, client)
        self.client = client
        self._distributed = distributed

    @property
    def workers(self) -> int:
        return max(1, len(self.client.scheduler_info(n_workers=-1).get("workers", {})))

    def map_unordered(self, fn, tasks: list, limits: list | None = None):
        limited = limits is not None and any(x is not None for x in limits)
        call = _announced if limited else _plain
        futures = [self.client.submit(call, fn, task, pure=False, retries=self.retries,
                                      key=f"diffsusp-fleet-{getattr(task, 'key', i)}")
                   for i, task in enumerate(tasks)]
        index = {f.key: i for i, f in enumerate(futures)}
        started: dict[str, tuple[str, float]] = {}  # key → (worker, monotonic start)
        lock = threading.Lock()

        def on_start(event):
            _, msg = event
            with lock:
                started[msg["key"]] = (msg["worker"], time.monotonic())

        if limited:
            self.client.subscribe_topic(_TOPIC, on_start)
        try:
            if not limited:
                for future in self._distributed.as_completed(futures):
                    yield index[future.key], _result(future)
                    future.release()
                return
            pending = set(futures)
            while pending:
                try:
                    done, pending = self._distributed.wait(
                        pending, timeout=1.0, return_when="FIRST_COMPLETED")
                except TimeoutError:
                    done = set()
                for future in done:
                    yield index[future.key], _result(future)
                    future.release()
                now = time.monotonic()
                for future in list(pending):
                    limit = limits[index[future.key]]
                    with lock:
                        worker, t0 = started.get(future.key, (None, None))
                    if limit is None or t0 is None or now - t0 < limit + HARD_GRACE:
                        continue
                    pending.discard(future)
                    future.cancel()
                    self.client.restart_workers([worker], raise_for_error=False)
                    yield index[future.key], ItemTimeout(
                        f"the batch ran past its time limit ({limit:.3g} s; hard limit, "
                        f"its worker was restarted)")
        finally:
            if limited:
                self.client.unsubscribe_topic(_TOPIC)
            for f in futures:
                if not f.done():
                    f.cancel()

    def close(self) -> None:
        for obj in self._owned:
            obj.close()
        self._owned = []

    def describe(self) -> str:
        return f"dask ({self.workers} workers, scheduler {self.client.scheduler.address})"


class _Exit:
    """`close()` exits a context (a `dask.config.set` held for an engine's life)."""

    def __init__(self, context):
        self.context = context

    def close(self):
        self.context.__exit__(None, None, None)


def _result(future):
    try:
        return future.result()
    except Exception as e:  # the task raised, or its workers kept dying
        return e


def _plain(fn, task):
    return fn(task)


def _announced(fn, task):
    """`fn(task)` in a worker, after telling the driver that it starts (and where)."""
    from distributed import get_worker

    worker = get_worker()
    worker.log_event(_TOPIC, {"key": worker.get_current_task(), "worker": worker.address})
    return fn(task)


def engine_for(workers: int | None = None, scheduler: str | None = None, client=None) -> Engine:
    """In-process without arguments; else a `DaskEngine`."""
    if workers is None and scheduler is None and client is None:
        return InProcessEngine()
    return DaskEngine(workers=workers, scheduler=scheduler, client=client)


def worker_environment() -> dict:
    """Variables a local worker process needs before JAX starts: the compiler flags
    (`diffsusp.compilation.XLA_FLAGS`) and float64."""
    env = {"XLA_FLAGS": os.environ.get("XLA_FLAGS", "")}
    set_xla_flags(env)
    return env
