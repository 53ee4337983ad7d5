"""Fleets (diffsusp.fleet): 42 landmark data sets of the pseudo-McPherson (40 noise
draws made with diffsusp.measure, two broken files) identified by the direct method in-process
and on a local Dask cluster of two worker processes, one of which is killed mid-run: every good
item's report equals the in-process one (1e-12), the broken ones carry their error, the two
summaries are identical, and a re-run skips everything. Also the time limit (checked in
process, enforced on the cluster by restarting the worker of a hung batch), the CLI and bad
input. The recipes beyond `direct` and the devices of a worker: test_fleet_recipes.py.

CPU: one cluster for the module; the recipe is the cheapest (direct: linear); the noise draws
are one jitted program; the workers load the programs the in-process run compiled from the
run's persistent compilation cache."""

import csv
import inspect
import io
import json
import math
import os
import pathlib
import shutil
import signal
import sys
import time

import equinox as eqx
import jax
import numpy as np
import pytest
from typer.testing import CliRunner

from diffsusp import fleet, identify, measure
from diffsusp.cli import app
from diffsusp.errors import InputError
from diffsusp.models import pseudo_mcpherson, thesis_load_cases

distributed = pytest.importorskip("distributed")  # the 'fleet' extra, in 'test'

N_DRAWS = 40
BATCH = 4
# The cheap linear method, whatever the default of `direct` (no polishing fit).
OPTIONS = {"polish": False} if "polish" in inspect.signature(identify.direct).parameters else {}


@pytest.fixture(scope="module")
def mech():
    return pseudo_mcpherson()


@pytest.fixture(scope="module")
def items(tmp_path_factory, mech):
    """40 noisy landmark tables (σ 0.05 mm, seeds 0–39) and two broken ones: a number that is
    text (same shape as the good tables: it shares their batch) and a table cut short."""
    folder = tmp_path_factory.mktemp("fleet_items")
    exact = measure.synthesize(mech, thesis_load_cases(mech),
                               layout=measure.place_landmarks(mech, seed=0))
    draw = eqx.filter_jit(lambda key: measure.add_noise(
        exact, measure.GaussianNoise(landmarks=0.05), key))
    for seed in range(N_DRAWS):
        measure.write_measurements(draw(jax.random.PRNGKey(seed)),
                                   folder / f"draw{seed:03d}.csv", mech)
    lines = (folder / "draw000.csv").read_text().splitlines()
    cells = lines[5].split(",")
    cells[3] = "abc"
    (folder / "bad_number.csv").write_text("\n".join(lines[:5] + [",".join(cells)] + lines[6:])
                                           + "\n")
    (folder / "cut_short.csv").write_text("\n".join(lines[:40]) + "\n1,upright\n")
    return folder


@pytest.fixture(scope="module")
def in_process(items, mech, tmp_path_factory):
    out = tmp_path_factory.mktemp("fleet_in_process")
    result = fleet.run("direct", str(items / "*.csv"), out, model=mech, options=OPTIONS,
                       batch_size=BATCH)
    return out, result


@pytest.fixture(scope="module")
def client():
    import dask

    from diffsusp.fleet.engine import LOST_WORKER_TIMEOUT, worker_environment

    # the worker restarted past its time limit must not be given up for lost while it imports
    # JAX on a loaded machine (Dask's default: its nanny closed after 15 s)
    with dask.config.set({"distributed.deploy.lost-worker-timeout": LOST_WORKER_TIMEOUT}), \
            distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0", env=worker_environment()) as cluster:
        with distributed.Client(cluster) as c:
            yield c


def _report(out, item):
    return json.loads((out / "reports" / f"{item}.json").read_text())


def _assert_close(a, b, path="report"):
    """Same structure, same strings, numbers equal to 1e-12 (relative)."""
    if isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            _assert_close(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list) and a and all(isinstance(x, int | float) for x in a):
        np.testing.assert_allclose(np.asarray(a, float), np.asarray(b, float), rtol=1e-12,
                                   atol=0, err_msg=path)
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _assert_close(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and not isinstance(a, bool):
        assert (math.isnan(a) and math.isnan(b)) or a == pytest.approx(b, rel=1e-12, abs=0), path
    else:
        assert a == b, path


def test_in_process_reports_are_the_library_results(in_process, items, mech):
    """The fleet's report of an item is `identify.direct` on that table; the broken files are
    reported with their error; summary, journal and status agree."""
    out, result = in_process
    assert (result.total, result.ok, result.failed, result.skipped) == (N_DRAWS + 2, N_DRAWS,
                                                                         2, 0)
    _, direct = identify.direct(mech, measure.read_measurements(items / "draw007.csv", mech),
                                **OPTIONS)
    _assert_close(_report(out, "draw007"), json.loads(json.dumps(direct.to_dict())))
    state = fleet.status(out)
    assert (state.total, state.ok, state.failed, state.pending) == (N_DRAWS + 2, N_DRAWS, 2, 0)
    failures = {item: message for item, _, message in state.failures}
    assert "bad_number.csv:6" in failures["bad_number"]
    assert "cut_short.csv" in failures["cut_short"]
    assert not (out / "reports" / "bad_number.json").exists()
    rows = (out / "summary.csv").read_text().splitlines()
    assert len(rows) == N_DRAWS + 3 and rows[0].startswith("item,status,message,hash,")
    assert rows[1].startswith("bad_number,error,")
    # Beside each estimate, the library's status of that parameter.
    table = {r["item"]: r for r in csv.DictReader(io.StringIO("\n".join(rows)))}
    for name, status in zip(direct.names, direct.statuses, strict=True):
        assert table["draw007"][f"{name} status"] == status


def test_cluster_with_a_killed_worker_matches_in_process(in_process, items, mech, client,
                                                         tmp_path):
    """Two worker processes; once 28 of the 42 items are in, a worker busy with a batch is
    killed (SIGKILL) in the middle of it: its batch runs again elsewhere (late in the run, so
    that the worker the nanny restarts has little left to compile: CPU), every good report
    equals the in-process one to 1e-12, the summaries are identical, and a re-run skips
    everything."""
    ref_out, _ = in_process
    out = tmp_path / "cluster"
    killed = {}

    def kill_one(progress):
        if killed or progress["done"] < N_DRAWS - 3 * BATCH:
            return
        busy = {w: keys for w, keys in client.processing().items() if keys}
        if not busy:
            return
        pids = client.run(os.getpid)
        worker = sorted(busy)[0]
        killed.update(pid=pids[worker], keys=set(busy[worker]), at=progress["done"])
        os.kill(pids[worker], signal.SIGKILL)

    result = fleet.run("direct", str(items / "*.csv"), out, model=mech, options=OPTIONS,
                       batch_size=BATCH, client=client, progress=kill_one)
    assert killed and killed["at"] < N_DRAWS + 2
    assert (result.ok, result.failed) == (N_DRAWS, 2)
    journal = [json.loads(line) for line in (out / "journal.jsonl").read_text().splitlines()]
    assert len(journal) == N_DRAWS + 2
    lost = {k.removeprefix("diffsusp-fleet-") for k in killed["keys"]}
    rerun = [e for e in journal if e["batch"] in lost]
    assert rerun and not any(e["worker"].endswith(f":{killed['pid']}") for e in rerun)
    for seed in range(N_DRAWS):
        _assert_close(_report(out, f"draw{seed:03d}"), _report(ref_out, f"draw{seed:03d}"))
    assert (out / "summary.csv").read_text() == (ref_out / "summary.csv").read_text()
    again = fleet.run("direct", str(items / "*.csv"), out, model=mech, options=OPTIONS,
                      batch_size=BATCH, client=client)
    assert (again.skipped, again.batches, again.ok, again.failed) == (N_DRAWS + 2, 0, 0, 0)
    # A changed option is another computation: everything is to do again.
    state = fleet.status(out)
    assert state.pending == 0 and state.ok == N_DRAWS


def test_time_limit_and_retry(items, mech, tmp_path):
    """An item past its time limit is reported as 'timeout' (the fleet goes on); a re-run skips
    it unless asked to retry the failed items."""
    paths = [items / "draw001.csv", items / "draw002.csv"]
    result = fleet.run("direct", paths, tmp_path, model=mech, options=OPTIONS, time_limit=1e-9)
    assert (result.ok, result.failed) == (0, 2)
    state = fleet.status(tmp_path)
    assert {s for _, s, _ in state.failures} == {"timeout"}
    assert "time limit" in state.failures[0][2]
    assert fleet.run("direct", paths, tmp_path, model=mech, options=OPTIONS).skipped == 2
    retried = fleet.run("direct", paths, tmp_path, model=mech, options=OPTIONS,
                        retry_failed=True)
    assert (retried.ok, retried.skipped) == (2, 0)


def test_cli_fleet_and_status(in_process, items, tmp_path):
    """`diffsusp fleet direct --items LIST --out DIR` (in-process) and `diffsusp fleet status`."""
    listing = tmp_path / "items.txt"
    listing.write_text(f"{items / 'draw003.csv'}\n{items / 'cut_short.csv'}\n")
    out = tmp_path / "out"
    opts = [f"--option={k}={json.dumps(v)}" for k, v in OPTIONS.items()]
    runner = CliRunner()
    result = runner.invoke(app, ["fleet", "direct", "--items", str(listing), "--out", str(out),
                                 "--model", "pseudo_mcpherson", "--json", *opts])
    assert result.exit_code == 3, result.output  # one item failed
    data = json.loads(result.stdout)
    assert (data["ok"], data["failed"]) == (1, 1)
    assert data["failures"][0][0] == "cut_short"
    ref_out, _ = in_process
    _assert_close(_report(out, "draw003"), _report(ref_out, "draw003"))
    result = runner.invoke(app, ["fleet", "status", str(ref_out)])
    assert result.exit_code == 0, result.output
    assert f"{N_DRAWS + 2} items: {N_DRAWS} ok, 2 failed, 0 to do" in result.stdout
    result = runner.invoke(app, ["fleet", "status", str(tmp_path / "nothing")])
    assert result.exit_code == 2 and "holds no fleet" in result.output


def test_bad_input(items, mech, tmp_path):
    with pytest.raises(InputError, match="unknown recipe 'kc_magic'"):
        fleet.run("kc_magic", str(items / "*.csv"), tmp_path, model=mech)
    with pytest.raises(InputError, match="matches no file"):
        fleet.run("direct", str(tmp_path / "*.parquet"), tmp_path, model=mech)
    shutil.copy(items / "draw001.csv", tmp_path / "draw001.csv")
    with pytest.raises(InputError, match="two items are named 'draw001'"):
        fleet.run("direct", [items / "draw001.csv", tmp_path / "draw001.csv"], tmp_path,
                  model=mech)
    with pytest.raises(InputError, match="not both"):
        fleet.run("direct", str(items / "*.csv"), tmp_path, model=mech, workers=2,
                  scheduler="tcp://localhost:8786")
    with pytest.raises(InputError, match="devices must be a count"):
        fleet.run("direct", str(items / "*.csv"), tmp_path, model=mech, devices="two")
    listing = tmp_path / "items.txt"  # a .txt list: one path or glob a line, # comments
    listing.write_text(f"# the draws\n{items / 'draw001.csv'}\n\n{tmp_path / 'draw001.csv'}\n")
    with pytest.raises(InputError, match="two items are named 'draw001'"):
        fleet.run("direct", listing, tmp_path, model=mech)


class _Hang(fleet.Recipe):
    """Runs `draw001` as a call that never returns nor checks its deadline (as a hung XLA
    call would); the other items at once."""

    name = "hang"

    def read(self, mech, path):
        return pathlib.Path(path).stem

    def run(self, mechs, data, deadline, mesh=None):
        if "draw001" in data:
            time.sleep(600)
        return [({"item": d}, {"length": float(len(d))}) for d in data]


def test_hard_time_limit_on_the_cluster(items, mech, client, tmp_path):
    """On the cluster the time limit is enforced: the batch that hangs is cancelled once past
    its limit (+ HARD_GRACE), its worker restarted, its item reported 'timeout'; the other
    item is done, and the cluster has its two workers again."""
    import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # _Hang, to the workers
    start = time.monotonic()
    result = fleet.run(_Hang(), [items / "draw001.csv", items / "draw002.csv"], tmp_path,
                       model=mech, batch_size=1, time_limit=1.0, client=client)
    assert time.monotonic() - start < 120  # not the 600 s of the hung call
    assert (result.ok, result.failed) == (1, 1)
    (item, status, message), = fleet.status(tmp_path).failures
    assert (item, status) == ("draw001", "timeout") and "worker was restarted" in message
    assert _report(tmp_path, "draw002") == {"item": "draw002"}
    client.wait_for_workers(2, timeout=60)
