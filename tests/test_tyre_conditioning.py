"""Conditioning options of the bench table (thesis §1.3.3, §1.3.6.3; `bench_select`): the
trapezoid integral against SciPy's and a closed form, the predicate sample selection against
an independent transcription, and both reachable from `diffsusp tyre identify --select`."""

import math

import numpy as np
import pytest
import scipy.integrate
from typer.testing import CliRunner

from diffsusp.cli import app
from diffsusp.errors import InputError
from diffsusp.io.tables import write_table
from diffsusp.tyre import bench, bench_select

RATE = 200.0


def _table(n_seg=3, m=400):
    """Segments of a medium slip profile (triangle ±3°, 2 s period, phase per segment), a
    belt speed of 40, 80, 120 km/h, a load sine, zero camber."""
    t = np.arange(m) / RATE
    rows = []
    for s in range(n_seg):
        tri = np.arcsin(np.sin(2 * np.pi * (t / 2.0 + 0.1 * s))) / (np.pi / 2)
        steer = np.radians(3.0) * tri
        v = (40.0 + 40.0 * s) / 3.6 * 1e3  # mm/s
        rows.append({"t": t + 10.0 * s, "segment": np.full(m, float(s)), "steer": steer,
                     "camber": np.zeros(m), "speed": np.full(m, v),
                     "omega": v / 294.0 * np.cos(steer), "FZ": 4500 + 500 * np.sin(6 * t),
                     "FX": np.zeros(m), "FY": -1500.0 * np.degrees(steer),
                     "MZ": np.zeros(m)})
    return {k: np.concatenate([r[k] for r in rows]) for k in rows[0]}


def test_trapezoid_against_scipy_and_closed_form():
    """Per segment, from 0 at its first row: SciPy's cumulative trapezoid on an irregular
    time base; the distance rolled at constant speed is V·t exactly; the wheel angle ∫ω dt of
    ω = V·cos δ/R_r is below V·t/R_r by the slip's cosine."""
    rng = np.random.default_rng(0)
    tab = _table()
    tab["t"] = tab["t"] + rng.uniform(0, 2e-3, tab["t"].size)  # irregular, still increasing
    for ch in ("FY", "omega", "speed"):
        got = bench_select.trapezoid(tab, ch)
        for s in range(3):
            r = tab["segment"] == s
            ref = scipy.integrate.cumulative_trapezoid(tab[ch][r], tab["t"][r], initial=0.0)
            np.testing.assert_allclose(got[r], ref, rtol=1e-12, atol=1e-9)
    tab = _table()
    dist = bench_select.trapezoid(tab, "speed")
    t0 = np.repeat(tab["t"][::400], 400)
    np.testing.assert_allclose(dist, tab["speed"] * (tab["t"] - t0), rtol=1e-12)
    theta = bench_select.trapezoid(tab, "omega")
    assert np.all(theta <= dist / 294.0 + 1e-9) and theta[399] > 0.99 * dist[399] / 294.0


def _select_reference(tab, keep, m):
    """An independent transcription: walk the rows, collect each maximal run of kept rows
    inside a segment, emit its whole pieces of m rows."""
    pieces, run = [], []
    for i in range(len(keep) + 1):
        same = i < len(keep) and run and tab["segment"][i] == tab["segment"][run[-1]]
        if i < len(keep) and keep[i] and (not run or same):
            run.append(i)
            continue
        pieces += [run[k * m:(k + 1) * m] for k in range(len(run) // m)]
        run = [i] if i < len(keep) and keep[i] else []
    return pieces


def test_selection_against_an_independent_transcription():
    """|δ| ≤ 1° (thesis §1.3.6.3), a steer-rate bound (its five-point derivative against the
    analytic one, away from the bound) and a distance rolled from the run's start (against
    SciPy): the same rows in the same pieces of 0.1 s, renumbered; nothing left is an error."""
    tab = _table()
    one = math.radians(1.0)
    out = bench_select.select(tab, {"steer": (-one, one)}, duration=0.1)
    keep = np.abs(tab["steer"]) <= one
    pieces = _select_reference(tab, keep, 20)
    idx = np.concatenate(pieces)
    np.testing.assert_array_equal(out["t"], tab["t"][idx])
    np.testing.assert_array_equal(out["FY"], tab["FY"][idx])
    np.testing.assert_array_equal(out["segment"], np.repeat(np.arange(len(pieces)), 20))
    assert len(pieces) >= 6 and np.all(np.abs(out["steer"]) <= one)
    # the steer rate (the steady states of §1.3.6.3) on a slip sine: the five-point derivative
    # against the analytic one (no sample within 1e-5 rad/s of the bound; the runs start and
    # end far from it, where the difference is one-sided)
    sine = dict(tab)
    sine["steer"] = math.radians(2.0) * np.sin(np.pi * tab["t"] + 0.3)
    analytic = math.radians(2.0) * np.pi * np.cos(np.pi * tab["t"] + 0.3)
    bound = math.radians(3.0)
    assert np.min(np.abs(np.abs(analytic) - bound)) > 1e-5
    out = bench_select.select(sine, {"d:steer": (-bound, bound)}, duration=0.1)
    idx = np.concatenate(_select_reference(sine, np.abs(analytic) <= bound, 20))
    np.testing.assert_array_equal(out["t"], sine["t"][idx])
    # the distance rolled: past the first 2 m of each run
    dist = scipy.integrate.cumulative_trapezoid(tab["speed"][:400], tab["t"][:400],
                                                initial=0.0)
    far = bench_select.select(tab, {"int:speed": (2000.0, np.inf)}, duration=0.1)
    first = int(np.argmax(dist >= 2000.0))
    assert far["t"][0] == tab["t"][first]
    with pytest.raises(InputError, match="no run of"):
        bench_select.select(tab, {"steer": (5.0, 6.0)})
    with pytest.raises(InputError, match="empty"):
        bench_select.select(tab, {"steer": (1.0, -1.0)})
    assert bench_select.parse_bound("int:speed:500:") == ("int:speed", (500.0, np.inf))
    assert bench_select.parse_bound("d:steer:-0.1:0.1") == ("d:steer", (-0.1, 0.1))
    with pytest.raises(InputError, match="CHANNEL:LO:HI"):
        bench_select.parse_bound("steer")


def test_cli_select_and_speed_test_reach_the_identification(tmp_path, monkeypatch):
    """`tyre identify --select ... --speed-test`: the table the identification receives is
    `select`'s (the same rows), with speed_test=True; a selection that leaves nothing exits 2
    with the reason. (The identification itself is stood in for: it is tested in
    tests/test_tyre_speed.py and tests/test_tyre_bench.py.)"""
    tab = _table()
    path = tmp_path / "bench.csv"
    write_table(path, tab)
    seen = {}

    def fake(table, **kw):
        seen.update(table=table, **kw)
        raise InputError("stood in")

    monkeypatch.setattr(bench, "identify", fake)
    r = CliRunner().invoke(app, ["tyre", "identify", str(path), "--select",
                                 "steer:-0.017453292519943295:0.017453292519943295",
                                 "--select-duration", "0.1", "--speed-test"])
    assert r.exit_code == 2 and "stood in" in r.output, r.output
    ref = bench_select.select(tab, {"steer": (-math.radians(1), math.radians(1))},
                              duration=0.1)
    assert seen["speed_test"] is True
    np.testing.assert_allclose(seen["table"]["t"], ref["t"], rtol=1e-12)
    np.testing.assert_array_equal(seen["table"]["segment"], ref["segment"])
    r = CliRunner().invoke(app, ["tyre", "identify", str(path), "--select", "steer:1:2"])
    assert r.exit_code == 2 and "no run of" in " ".join(r.output.split()), r.output
