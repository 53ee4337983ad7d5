"""The fleet driver: items → content hashes → batches of one shape → an engine → the store.

**Models.** Every item has the fleet's model or its own (`Item(model=...)`; for `kc` with a
named event, the item *is* a model file). Each distinct model is loaded once in the driver and
fingerprinted (every leaf's bytes and the tree's static data, the same in every process); the
fingerprint is part of the item's content hash, and the batch carries the models of its items.

**Batches and shapes.** Items are grouped by their model's structure (tree definition and leaf
shapes: models that vmap together) and a cheap data shape key read without parsing (a CSV
table's header and number of rows, a Parquet file's schema and row count, an in-memory
measurement's array shapes), sorted by model and name, and cut into batches of `batch_size`.
A worker compiles each program once per structure and shape (and loads it from the shared
persistent compilation cache when another worker compiled it already); a batched recipe also
pads every batch to `batch_size` data sets (to a multiple of the worker's devices when it splits
a batch over them), so a fleet of ragged data sets compiles one program per distinct table
shape, not one per item or per batch length. The batches are the same whatever the engine, so
an in-process run and a cluster run compute the same numbers.

**Faults.** An item that fails (unreadable file, a model that does not load, a fit that
raises) gets status `error` and the message; a batch past its time (`time_limit` seconds per
item, checked between items and between the steps of a fit; on Dask also enforced by
restarting the worker: `diffsusp.fleet.engine`) gets `timeout`; a batch whose workers kept
dying (Dask gives up after `distributed.scheduler.allowed-failures` deaths) gets `error` with
the reason. None of these stops the fleet. A worker killed mid-batch loses only that batch,
which the scheduler runs again elsewhere.
"""
import dataclasses
import glob
import hashlib
import json
import os
import pathlib
import pickle
import sys
import time
from collections.abc import Callable, Sequence

import numpy as np

from ..compilation import set_xla_flags
from ..errors import InputError, ModelFileError
from ..io.files import read_input
from .engine import DaskEngine, Engine, InProcessEngine, worker_environment
from .recipes import ItemTimeout, NotConverged, Recipe
from .recipes import recipe as make_recipe
from .store import Store

__all__ = ["FleetResult", "Item", "run"]

FORMAT = "diffsusp-fleet-1"


@dataclasses.dataclass(frozen=True)
class Item:
    """One item of a fleet, under a unique `name`: a `path` (CSV or Parquet table), or
    in-memory `data` (what the recipe's `read` would return, e.g. a `measure.Measurements`),
    and its own `model` (a model file, built-in name or object; None: the fleet's model). An
    item of a recipe that reads no data (`kc` with a named event) is its model alone."""

    name: str
    path: str | None = None
    data: object = None
    model: object = None


@dataclasses.dataclass
class _Prepared:
    name: str
    hash: str
    shape: tuple
    suffix: str = ""
    content: bytes | None = None
    data: object = None
    model: str = ""  # the fingerprint of the item's model (a key of _Batch.models)
    structure: str = ""  # the model's structure (tree and leaf shapes): batches are vmappable
    error: str | None = None  # the item's model could not be loaded


@dataclasses.dataclass
class _Batch:
    """One task: the items of a batch and everything a worker needs to run them."""

    key: str
    recipe: Recipe
    models: dict  # fingerprint → the model as a NumPy tree (those of this batch's items)
    items: list
    time_limit: float | None
    cache_dir: str | None
    cache_min_seconds: float
    x64: bool
    devices: int | str | None = None


@dataclasses.dataclass(frozen=True)
class FleetResult:
    """What a `run` did: item counts (`ok`, `failed`, `skipped` because already done with the
    same hash), batches, wall `seconds` and `items_per_s` (items run / seconds), the programs
    the workers compiled and loaded from the persistent cache, and where the summary is."""

    out: pathlib.Path
    total: int
    ok: int
    failed: int
    skipped: int
    batches: int
    seconds: float
    items_per_s: float
    compiled: int
    cache_hits: int
    engine: str
    summary: pathlib.Path

    def text(self) -> str:
        return (f"{self.total} items: {self.ok} ok, {self.failed} failed, {self.skipped} "
                f"already done; {self.batches} batches on {self.engine} in {self.seconds:.1f} s "
                f"({self.items_per_s:.3g} items/s); programs compiled {self.compiled}, loaded "
                f"from the cache {self.cache_hits}; summary {self.summary}")


# ----------------------------------------------------------------------------- items


def _as_items(items, items_are_models: bool = False) -> list[Item]:
    if isinstance(items, str | os.PathLike):
        items = [items]
    out: list[Item] = []
    for it in items:
        if isinstance(it, Item):
            out.append(it)
            continue
        text = os.fspath(it)
        if text.lower().endswith(".txt") and os.path.isfile(text):
            out += _as_items(_listed_paths(text), items_are_models)
            continue
        paths = sorted(glob.glob(text)) if glob.has_magic(text) else [text]
        if not paths:
            raise InputError(f"--items {text!r} matches no file.")
        out += [Item(name=pathlib.Path(p).stem, model=p) if items_are_models
                else Item(name=pathlib.Path(p).stem, path=p) for p in paths]
    seen: dict[str, str] = {}
    for it in out:
        if it.name in seen:
            raise InputError(f"two items are named {it.name!r} ({seen[it.name]} and "
                             f"{it.path or it.model}): item names (file stems) must be unique.")
        seen[it.name] = str(it.path or it.model or "<data>")
        if items_are_models:
            if it.model is None or it.path is not None or it.data is not None:
                raise InputError(f"item {it.name!r}: this recipe's items are models (give "
                                 "Item(name, model=...), or model files as paths), not data.")
        elif (it.path is None) == (it.data is None):
            raise InputError(f"item {it.name!r}: give a path or data (one of them).")
    if not out:
        raise InputError("the fleet has no items.")
    return out


def _listed_paths(path: str) -> list[str]:
    """The paths (or globs) a `.txt` item list names, one a line (blank lines and `#` comments
    skipped)."""
    try:
        text = read_input(path, "item list").decode("utf-8")
    except UnicodeDecodeError:
        raise ModelFileError("the item list is not UTF-8 text.", path=path) from None
    return [line.strip() for line in text.splitlines()
            if line.strip() and not line.lstrip().startswith("#")]


def _numpy_tree(tree):
    """Array leaves as NumPy (they pickle the same whatever the receiver's JAX settings)."""
    import equinox as eqx
    import jax

    return jax.tree.map(lambda x: np.asarray(x) if eqx.is_array(x) else x, tree)


def _jax_tree(tree):
    import jax
    import jax.numpy as jnp

    return jax.tree.map(lambda x: jnp.asarray(x) if isinstance(x, np.ndarray) else x, tree)


def _digest(*parts: bytes) -> str:
    h = hashlib.sha256()
    for p in parts:
        h.update(len(p).to_bytes(8, "little"))
        h.update(p)
    return h.hexdigest()


def _shape_of_file(path: str, content: bytes) -> tuple:
    suffix = pathlib.Path(path).suffix.lower()
    if suffix == ".parquet":
        try:
            import io

            import pyarrow.parquet as pq

            meta = pq.ParquetFile(io.BytesIO(content)).metadata
            return (suffix, str(meta.schema.to_arrow_schema()), meta.num_rows)
        except Exception:
            return (suffix, "unreadable")
    lines = content.splitlines()
    return (suffix, lines[0].strip() if lines else b"", len([x for x in lines if x.strip()]))


class _Models:
    """The models of a fleet, each loaded once in the driver (by file name, or by object), with
    its fingerprint (hash of every leaf and of the tree: values and structure) and structure
    key (the tree and its leaf shapes: models with equal keys vmap together)."""

    def __init__(self, rec: Recipe, default):
        self.recipe = rec
        self.default = default
        self.trees: dict[str, object] = {}
        self.structures: dict[str, str] = {}
        self._seen: dict[object, tuple] = {}
        self._keep: list = []  # the objects whose id is a key of _seen stay alive
        self._kinds: dict[tuple, str] = {}
        self.names: set[str] = set()

    def get(self, spec) -> tuple[str, str]:
        """(fingerprint, structure) of a model spec; raises what loading it raised."""
        if spec is None:
            spec = self.default
        if spec is None:
            raise InputError("no model: give the fleet a model= or every item its own.")
        key = os.fspath(spec) if isinstance(spec, str | os.PathLike) else id(spec)
        if key not in self._seen:
            import jax

            try:
                model = self.recipe.load_model(spec)
            except Exception as e:
                self._seen[key] = (None, e)
            else:
                tree = _numpy_tree(model)
                leaves, treedef = jax.tree.flatten(tree)
                fp = _digest(_fingerprint(tree))
                self.trees.setdefault(fp, tree)
                # Tree definitions compare by their static data (not by repr: a model's
                # topology object prints its address); numbered in the order first seen.
                shapes = tuple(np.shape(x) for x in leaves if isinstance(x, np.ndarray))
                kinds = self._kinds.setdefault((treedef, shapes), f"{len(self._kinds):06d}")
                self.structures[fp] = kinds
                self.names.add(str(getattr(model, "name", type(model).__name__)))
                self._seen[key] = (fp, None)
            if not isinstance(key, str):
                self._keep.append(spec)
        fp, error = self._seen[key]
        if error is not None:
            raise error
        return fp, self.structures[fp]


def _prepare(items: list[Item], salt: bytes, models: _Models) -> list[_Prepared]:
    out = []
    for it in items:
        try:
            fp, structure = models.get(it.model)
            error = None
        except Exception as e:
            fp, structure = "", ""
            error = f"the item's model: {_message(e)}"
        model_bytes = fp.encode() if fp else _digest(b"unloadable", repr(it.model).encode(
            ) if not isinstance(it.model, str | os.PathLike) else _file_bytes(it.model)).encode()
        if it.path is not None:
            try:   # a regular file within the table limit: never a FIFO or /dev/zero
                content = read_input(it.path, "fleet item", "table")
            except (OSError, ModelFileError) as e:
                content = None
                shape = ("unreadable", str(e))
                digest = _digest(salt, model_bytes, b"missing", str(it.path).encode())
            else:
                shape = _shape_of_file(it.path, content)
                digest = _digest(salt, model_bytes, content)
            p = _Prepared(it.name, digest, shape, pathlib.Path(it.path).suffix.lower(),
                          content=content)
        elif it.data is not None:
            import jax

            data = _numpy_tree(it.data)
            leaves = jax.tree.leaves(data)
            shape = ("data", type(it.data).__name__,
                     tuple(np.shape(x) for x in leaves if isinstance(x, np.ndarray)))
            digest = _digest(salt, model_bytes, pickle.dumps(
                [x.tobytes() if isinstance(x, np.ndarray) else repr(x) for x in leaves]),
                repr(jax.tree.structure(data)).encode())
            p = _Prepared(it.name, digest, shape, data=data)
        else:  # the item is its model
            p = _Prepared(it.name, _digest(salt, model_bytes), ("model",))
        p.model, p.structure, p.error = fp, structure, error
        out.append(p)
    return out


def _file_bytes(path) -> bytes:
    try:
        return read_input(path, "model file")
    except (OSError, ModelFileError):
        return os.fspath(path).encode()


def _batches(prepared: list[_Prepared], batch_size: int) -> list[list[_Prepared]]:
    """Batches of one model structure and data shape, items of the same model together."""
    groups: dict[str, list[_Prepared]] = {}
    for p in prepared:
        groups.setdefault(repr((p.structure, p.shape)), []).append(p)
    out = []
    for key in sorted(groups):
        members = sorted(groups[key], key=lambda p: (p.model, p.name))
        out += [members[i:i + batch_size] for i in range(0, len(members), batch_size)]
    return out


def _fingerprint(mech) -> bytes:
    """Every leaf's bytes, dtype and shape, and the tree with its static data, the same in
    every process (object addresses masked: a mechanism's topology, derived from the other
    static data, prints one), so that a re-run in another process finds its items done."""
    import re

    import jax

    leaves, treedef = jax.tree.flatten(_numpy_tree(mech))
    return pickle.dumps(([(x.tobytes(), x.dtype.str, x.shape) if isinstance(x, np.ndarray)
                          else repr(x) for x in leaves],
                         re.sub(r" at 0x[0-9a-fA-F]+", "", repr(treedef))))


# ----------------------------------------------------------------------------- worker side

_WORKER = {"setup": False, "compiled": 0, "hits": 0}


def _count_compiles():
    import jax

    def duration(event, seconds, **kwargs):
        if event == "/jax/core/compile/backend_compile_duration":
            _WORKER["compiled"] += 1

    def counter(event, **kwargs):
        if event == "/jax/compilation_cache/cache_hits":
            _WORKER["hits"] += 1

    jax.monitoring.register_event_duration_secs_listener(duration)
    jax.monitoring.register_event_listener(counter)


def _setup(batch: _Batch, own_process: bool) -> None:
    """Once per process: count compilations; in a worker process (not the caller's), also
    the driver's float64 setting and the shared persistent compilation cache."""
    if _WORKER["setup"]:
        return
    _WORKER["setup"] = True
    if own_process:
        set_xla_flags(os.environ)  # before JAX starts its backend (a fresh worker)
        import jax

        jax.config.update("jax_enable_x64", batch.x64)
        if batch.devices not in (None, 1, "1"):
            # Several CPU devices in this worker (before JAX starts its backend; no effect on
            # GPUs, which are devices already), and K&C tables split over them too.
            n = (os.cpu_count() or 1) if batch.devices == "all" else int(batch.devices)
            try:
                jax.config.update("jax_num_cpu_devices", n)
            except RuntimeError:  # the backend had started: keep its devices
                pass
            os.environ["DIFFSUSP_DEVICES"] = str(batch.devices)
        if batch.cache_dir and not jax.config.jax_compilation_cache_dir:
            jax.config.update("jax_compilation_cache_dir", batch.cache_dir)
            jax.config.update("jax_persistent_cache_min_compile_time_secs",
                              batch.cache_min_seconds)
    _count_compiles()


def run_batch(batch: _Batch, own_process: bool = True) -> dict:
    """Run one batch (in a worker): `{"results": [...], "worker", "compiled", "hits"}`, one
    result per item: `{"item", "status", "message", "report", "values", "seconds"}`."""
    import tempfile

    _setup(batch, own_process)
    compiled0, hits0 = _WORKER["compiled"], _WORKER["hits"]
    models = {fp: _jax_tree(tree) for fp, tree in batch.models.items()}
    mesh = _mesh(batch.devices)
    start = time.monotonic()
    deadline = None if batch.time_limit is None else start + batch.time_limit * len(batch.items)
    results: list[dict] = []
    data, mechs, where = [], [], []
    with tempfile.TemporaryDirectory(prefix="diffsusp-fleet-") as tmp:
        for k, p in enumerate(batch.items):
            folder = pathlib.Path(tmp)
            entry = {"item": p.name, "status": "ok", "message": "", "report": None,
                     "values": None}
            results.append(entry)
            try:
                mech = models[p.model]
                if p.data is not None:
                    data.append(_jax_tree(p.data))
                elif p.shape == ("model",):  # the item is its model
                    data.append(None)
                else:
                    if p.content is None:
                        raise FileNotFoundError(p.shape[1])
                    folder = pathlib.Path(tmp) / str(k)
                    folder.mkdir()
                    path = folder / f"{p.name}{p.suffix}"
                    path.write_bytes(p.content)
                    data.append(batch.recipe.read(mech, path))
                mechs.append(mech)
                where.append(k)
            except Exception as e:
                entry.update(status="error", message=_message(e, f"{folder}{os.sep}"))
        outcomes = batch.recipe.run(mechs, data, deadline, mesh) if data else []
    for k, outcome in zip(where, outcomes, strict=True):
        entry = results[k]
        if isinstance(outcome, ItemTimeout):
            entry.update(status="timeout", message=str(outcome))
        elif isinstance(outcome, NotConverged):   # a failure, with its report
            entry.update(status="not converged", message=str(outcome))
            entry["report"], entry["values"] = outcome.report, outcome.values
        elif isinstance(outcome, Exception):
            entry.update(status="error", message=_message(outcome))
        else:
            entry["report"], entry["values"] = outcome
    seconds = (time.monotonic() - start) / max(len(batch.items), 1)
    for entry in results:
        entry["seconds"] = seconds
    import socket

    hits = _WORKER["hits"] - hits0  # a cache hit is also a backend-compile event
    return {"results": results, "worker": f"{socket.gethostname()}:{os.getpid()}",
            "compiled": _WORKER["compiled"] - compiled0 - hits, "hits": hits}


def _mesh(devices):
    """A one-axis ("items") mesh over this process's first `devices` local devices (a count,
    "all"; None: `$DIFFSUSP_DEVICES`, else 1), None for one device."""
    import jax

    if devices is None:
        devices = os.environ.get("DIFFSUSP_DEVICES", "1")
    local = jax.local_devices()
    n = len(local) if devices == "all" else min(int(devices), len(local))
    if n <= 1:
        return None
    return jax.sharding.Mesh(np.array(local[:n]), ("items",))


def _message(e: BaseException, hide: str = "") -> str:
    """One line; `hide` (the worker's temporary folder) removed, so that the message names the
    item's file the same on every engine."""
    text = str(e).strip().replace("\n", " ")
    if hide:
        text = text.replace(hide, "")
    return f"{type(e).__name__}: {text}" if text else type(e).__name__


# ----------------------------------------------------------------------------- driver


def _progress_printer(stream=None) -> Callable[[dict], None]:
    stream = stream or sys.stderr
    tty = getattr(stream, "isatty", lambda: False)()

    def show(p):
        line = (f"fleet: {p['done']}/{p['total']} items, {p['failed']} failed, "
                f"{p['items_per_s']:.3g} items/s")
        stream.write(("\r" + line) if tty else line + "\n")
        if tty and p["done"] == p["total"]:
            stream.write("\n")
        stream.flush()

    return show


def run(
    recipe: str | Recipe,
    items: str | os.PathLike | Sequence,
    out: str | os.PathLike,
    *,
    model=None,
    options: dict | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    client=None,
    engine: Engine | None = None,
    batch_size: int = 16,
    time_limit: float | None = None,
    devices: int | str | None = None,
    cache_dir: str | None = None,
    retry_failed: bool = False,
    progress: bool | Callable[[dict], None] = False,
) -> FleetResult:
    """Run one identification or analysis per item, on this process or a Dask cluster,
    streaming the reports to `out` and skipping what an earlier run there finished (see
    `diffsusp.fleet`).

    **Arguments:**
    - `recipe`: `'direct'`, `'iterative'`, `'least_squares'`, `'kc'`, `'tyre_fit'` (with
      `options`: see each recipe in `diffsusp.fleet.recipes`), or a `Recipe` object.
    - `items`: a glob (`'data/*.csv'`), a path, a `.txt` file listing one path or glob per line
      (`#` comments), or a list of those and `Item`s (in-memory data, a model of its own).
      An item's name is its file stem; its report is
      `out/reports/NAME.json`. For `kc` with a named event the paths are model files (one
      design variant per item).
    - `out`: the output folder (made if needed): see `diffsusp.fleet.store`.
    - `model`: the model of every item without its own: a `Mechanism`, a model file or a
      built-in name (a `.tir` file or Magic Formula object for `tyre_fit`). Items are batched
      by model structure and data shape, so items with different models of one structure
      share their compiled programs.
    - `workers` (start a local Dask cluster of that many processes), `scheduler` (address of a
      running Dask scheduler), `client` (a `distributed.Client`), or `engine`; none: in-process.
    - `batch_size`: items per task (and the padded batch of a batched recipe).
    - `time_limit`: seconds per item (a batch gets `time_limit × its items`). Everywhere it is
      checked between items and between the steps of a fit (status `timeout`, the worker goes
      on); on the Dask engine it is also enforced: a batch still running `HARD_GRACE` s past
      its limit is cancelled, its worker restarted (the nanny), and its items reported
      `timeout` (`diffsusp.fleet.engine.DaskEngine`). In-process, a call that hangs inside XLA
      is not interrupted.
    - `devices`: local devices of a worker that a batch is split over (`jax.sharding`): a
      count (an int or its text) or "all" (in a worker process started for the fleet, on the
      CPU, that many CPU devices are made); None: `$DIFFSUSP_DEVICES`, else 1. Batched
      `least_squares` places the batch axis on them; `kc` splits each event's cases
      (`solve_statics(devices=...)`).
    - `cache_dir`: the persistent compilation cache the workers share (default: this
      process's, else `$DIFFSUSP_CACHE` or `~/.cache/diffsusp/jax` as the CLI).
    - `retry_failed`: also re-run the items that failed before.
    - `progress`: True prints a progress line on stderr; or a function of a dict (`done`,
      `failed`, `total`, `items_per_s`, `batch_worker`).

    **Returns:** a `FleetResult`.
    """
    import jax

    rec = make_recipe(recipe, **(options or {}))
    rec.check()
    if batch_size < 1:
        raise InputError(f"batch_size must be at least 1; got {batch_size}.")
    if time_limit is not None and not time_limit > 0:
        raise InputError(f"time_limit must be positive (seconds per item); got {time_limit}.")
    if rec.batched and rec.options.get("pad_to") is None:
        rec = dataclasses.replace(rec, options={**rec.options, "pad_to": batch_size})
    if isinstance(devices, str) and devices.isdigit():
        devices = int(devices)
    if devices is not None and devices != "all" and not (isinstance(devices, int)
                                                         and devices >= 1):
        raise InputError(f"devices must be a count (at least 1) or 'all'; got {devices!r}.")
    if workers is not None and scheduler is not None:
        raise InputError("give workers or a scheduler, not both.")
    if workers is not None and workers < 1:
        raise InputError(f"workers must be at least 1; got {workers}.")
    item_list = _as_items(items, rec.items_are_models)
    if model is None and any(it.model is None for it in item_list):
        raise InputError("no model: give the fleet a model= (or every item its own).")
    models = _Models(rec, model)
    if model is not None:   # the fleet's own model is bad input, not a failure of every item
        try:
            models.get(model)
        except InputError:
            raise
        except Exception as e:
            raise InputError(f"the fleet's model {model!r}: {_message(e)}") from None
    salt = _digest(FORMAT.encode(), rec.name.encode(),
                   json.dumps(rec.options, sort_keys=True, default=str).encode()).encode()
    prepared = _prepare(item_list, salt, models)
    store = Store(out)
    done = store.entries()
    todo = [p for p in prepared if not (
        p.name in done and done[p.name]["hash"] == p.hash
        and (done[p.name]["status"] == "ok" or not retry_failed)
        and (done[p.name]["status"] != "ok" or (store.reports / f"{p.name}.json").exists()))]
    names = sorted(models.names)
    manifest = {"format": FORMAT, "recipe": rec.name, "options": rec.options,
                "model": names[0] if len(names) == 1 else f"{len(names)} models",
                "batch_size": batch_size,
                "items": [{"item": p.name, "hash": p.hash} for p in prepared],
                "last_run": store.manifest().get("last_run")}
    store.open(manifest)
    for p in todo:  # an item whose model does not load fails here, without a batch
        if p.error is not None:
            store.record({"item": p.name, "hash": p.hash, "status": "error",
                          "message": p.error, "values": None, "seconds": None,
                          "worker": None, "batch": None}, None)
    unloadable = sum(p.error is not None for p in todo)
    todo = [p for p in todo if p.error is None]
    if cache_dir is None:
        cache_dir = jax.config.jax_compilation_cache_dir or os.environ.get(
            "DIFFSUSP_CACHE", os.path.expanduser("~/.cache/diffsusp/jax")) or None
    cache_min = (float(jax.config.jax_persistent_cache_min_compile_time_secs)
                 if jax.config.jax_compilation_cache_dir else 0.0)
    tasks = [_Batch(key=_digest(*(p.hash.encode() for p in b))[:16], recipe=rec,
                    models={p.model: models.trees[p.model] for p in b}, items=b,
                    time_limit=time_limit, cache_dir=cache_dir, cache_min_seconds=cache_min,
                    x64=bool(jax.config.jax_enable_x64), devices=devices)
             for b in _batches(todo, batch_size)]
    show = _progress_printer() if progress is True else (progress or None)
    owned = engine is None
    if engine is None:
        if not tasks or (workers is None and scheduler is None and client is None):
            engine = InProcessEngine()  # (nothing to do: no cluster either)
        else:
            engine = DaskEngine(workers=workers, scheduler=scheduler, client=client,
                                env=worker_environment())
    in_process = isinstance(engine, InProcessEngine)
    counts = {"ok": 0, "failed": unloadable, "compiled": 0, "hits": 0}
    total = len(todo) + unloadable
    limits = None if time_limit is None else [time_limit * len(t.items) for t in tasks]
    t0 = time.perf_counter()
    try:
        fn = _run_here if in_process else run_batch
        for i, result in engine.map_unordered(fn, tasks, limits=limits):
            batch = tasks[i]
            if isinstance(result, BaseException):  # the batch itself failed (lost workers…)
                timeout = isinstance(result, ItemTimeout)
                message = str(result) if timeout else f"the batch failed: {_message(result)}"
                result = {"worker": None, "compiled": 0, "hits": 0, "results": [
                    {"item": p.name, "status": "timeout" if timeout else "error",
                     "values": None, "report": None, "seconds": None, "message": message}
                    for p in batch.items]}
            counts["compiled"] += result["compiled"]
            counts["hits"] += result["hits"]
            hashes = {p.name: p.hash for p in batch.items}
            finished = []
            for r in result["results"]:
                entry = {"item": r["item"], "hash": hashes[r["item"]], "status": r["status"],
                         "message": r["message"], "values": r["values"],
                         "seconds": r["seconds"], "worker": result["worker"],
                         "batch": batch.key}
                finished.append((entry, r["report"]))
                counts["ok" if r["status"] == "ok" else "failed"] += 1
            store.record_batch(finished)
            if show is not None:
                elapsed = time.perf_counter() - t0
                n = counts["ok"] + counts["failed"]
                show({"done": n, "failed": counts["failed"], "total": total,
                      "items_per_s": n / elapsed if elapsed > 0 else 0.0,
                      "batch_worker": result["worker"]})
    finally:
        seconds = time.perf_counter() - t0
        description = engine.describe()
        if owned:
            engine.close()
        n = counts["ok"] + counts["failed"]
        manifest["last_run"] = {"engine": description, "seconds": seconds, "items": n,
                                "items_per_s": n / seconds if seconds > 0 and n else 0.0}
        store.open(manifest)
        summary = store.write_summary()
    return FleetResult(out=store.out, total=len(prepared), ok=counts["ok"],
                       failed=counts["failed"], skipped=len(prepared) - total,
                       batches=len(tasks), seconds=seconds,
                       items_per_s=n / seconds if seconds > 0 and n else 0.0,
                       compiled=counts["compiled"], cache_hits=counts["hits"],
                       engine=description, summary=summary)


def _run_here(batch: _Batch) -> dict:
    return run_batch(batch, own_process=False)
