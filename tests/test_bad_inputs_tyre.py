"""Bad inputs of the tyre verbs end in a clear error:
exit 2 naming the file, the line and the field before any work, exit 3 for a fit that did not
converge, or a warning; never a traceback, a hang, an internal error or NaN with exit 0. Every
bad file is written here, from a shipped file the checks were not written against."""

import json
import os
import re

import numpy as np
import pytest
from typer.testing import CliRunner

from diffsusp.cli import app
from diffsusp.io.tir import read_tir
from diffsusp.tyre import examples

BOOK = examples.DATA / "PacejkaBook_Defaults.tir"   # MF 6.1 with the book's values
MF52 = examples.DATA / "MagicFormula52_Paramerters.tir"
MF61 = examples.DATA / "MagicFormula61_Paramerters.tir"   # pressure and speed dependent


def _run(*args, **kw):
    return CliRunner().invoke(app, [*map(str, args)], **kw)


def _text(r):
    return " ".join(r.output.split())


def _variant(tmp_path, name, source, pattern, replacement):
    text = source.read_text(encoding="latin-1")
    new, n = re.subn(pattern, replacement, text, count=1, flags=re.M | re.I)
    assert n == 1, pattern
    path = tmp_path / name
    path.write_text(new, encoding="latin-1")
    return path


def _line_of(path, key):
    for i, line in enumerate(path.read_text(encoding="latin-1").splitlines(), start=1):
        if re.match(rf"\s*{key}\s*=", line, re.I):
            return i
    raise AssertionError(key)


def test_tir_values_and_duplicates_exit_2(tmp_path):
    """D2, D3: non-positive FNOMIN/radius/LONGVL, a negative NOMPRES, 1e400 and a 400-digit
    value, a coefficient repeated in another section: exit 2 naming file:line: key."""
    cases = [("fnomin.tir", BOOK, r"^(\s*FNOMIN\s*=\s*)\S+", r"\g<1>-4000", "FNOMIN"),
             ("radius.tir", MF52, r"^(\s*UNLOADED_RADIUS\s*=\s*)\S+", r"\g<1>0.0",
              "UNLOADED_RADIUS"),
             ("longvl.tir", BOOK, r"^(\s*LONGVL\s*=\s*)\S+", r"\g<1>0", "LONGVL"),
             ("nompres.tir", BOOK, r"^(\s*NOMPRES\s*=\s*)\S+", r"\g<1>-1.5e5", "NOMPRES"),
             ("huge.tir", BOOK, r"^(\s*PDY1\s*=\s*)\S+", r"\g<1>1.2e400", "PDY1"),
             ("digits.tir", MF52, r"^(\s*PKY1\s*=\s*)\S+", r"\g<1>-" + "7" * 400, "PKY1")]
    for name, src, pat, rep, key in cases:
        path = _variant(tmp_path, name, src, pat, rep)
        for verb in (["info", "--json"], ["spec", "--json"]):
            r = _run("tyre", verb[0], path, *verb[1:])
            assert r.exit_code == 2, (name, r.output)
            assert f"{path}:{_line_of(path, key)}: {key}" in _text(r), (name, r.output)
            assert "NaN" not in r.output and "Infinity" not in r.output
    # a stray PCY1 in the longitudinal section, before the lateral one
    dup = _variant(tmp_path, "dup.tir", MF52, r"^(\[LONGITUDINAL_COEFFICIENTS\].*)$",
                   "\\1\nPCY1 = 2.5 $ stray")
    r = _run("tyre", "info", dup)
    assert r.exit_code == 2 and f"{dup}:" in _text(r) and ": PCY1:" in _text(r), r.output
    assert "[LONGITUDINAL_COEFFICIENTS]" in _text(r) and "[LATERAL_COEFFICIENTS]" in _text(r)
    # the legitimate repetition (MASS in [UNITS] and [INERTIA]) still reads
    assert "INERTIA.MASS" in read_tir(examples.DATA / "MagicFormula61_Paramerters.tir").entries


def test_eval_tables_exit_2_before_work(tmp_path):
    """D1, D8, D15, D20 on `tyre eval --inputs`: a FIFO and /dev/zero (no hang), a table over
    --max-file-mb, a binary .csv, an infinite or negative pressure, FZ and LOAD together, a
    Parquet table of zero rows, an inf cell and FY = 1e300: exit 2 with file, line, column."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    r = _run("tyre", "eval", BOOK, "--inputs", fifo)
    assert r.exit_code == 2 and "FIFO" in _text(r) and str(fifo) in _text(r), r.output
    big = tmp_path / "big.csv"
    big.write_text("FZ [N],SA [deg]\n" + "4000,1\n" * 200_000)
    try:
        r = _run("--max-file-mb", "1", "tyre", "eval", BOOK, "--inputs", big)
    finally:
        os.environ.pop("DIFFSUSP_MAX_FILE_MB", None)   # the option sets it for the process
    assert r.exit_code == 2 and "more than the limit" in _text(r), r.output
    binary = tmp_path / "bin.csv"
    binary.write_bytes(b"FZ [N],SA [rad]\n3000,0.01\n\x89PNG\xff\x00,1\n")
    r = _run("tyre", "eval", BOOK, "--inputs", binary)
    assert r.exit_code == 2 and f"{binary}:3" in _text(r) and "UTF-8" in _text(r), r.output
    bad = {"pinf.csv": ("FZ [kN],SA [deg],P [bar]\n3,2,2.2\n4,1,inf\n", 3, "P"),
           "pneg.csv": ("FZ,SA,P [kPa]\n3000,0.01,-200\n", 2, "P"),
           "both.csv": ("FZ [N],Load [N],SA\n3000,3500,0.02\n", 1, "Load"),
           "fzneg.csv": ("FZ [N],SA\n-3000,0.02\n", 2, "FZ"),
           "infsl.csv": ("FZ [N],SL,SA\n3000,0,0\n3000,-inf,0\n", 3, "SL")}
    for name, (text, line, field) in bad.items():
        path = tmp_path / name
        path.write_text(text)
        r = _run("tyre", "eval", BOOK, "--inputs", path)
        assert r.exit_code == 2, (name, r.output)
        assert f"{path}:{line}: {field}" in _text(r), (name, r.output)
    empty = tmp_path / "empty.parquet"
    pq.write_table(pa.table({"FZ": pa.array([], pa.float64()),
                             "SA": pa.array([], pa.float64())}), empty)
    r = _run("tyre", "eval", BOOK, "--inputs", empty)
    assert r.exit_code == 2 and "no data rows" in _text(r), r.output
    # a measured channel far beyond any tyre (fit data): exit 2 naming it, before the fit
    huge = tmp_path / "huge.csv"
    huge.write_text("FZ [N],SA [deg],FY [N]\n" + "".join(
        f"{fz},{a},{-50 * a}\n" for fz in (3000, 5000) for a in range(-8, 9)) +
        "4000,1,1e300\n")
    r = _run("tyre", "fit", huge, "--model", "mf1989")
    assert r.exit_code == 2 and f"{huge}:36: FY" in _text(r), r.output
    # D16: one point repeated: refused before anything compiles
    rep = tmp_path / "repeated.csv"
    rep.write_text("FZ [N],SA [deg],FY [N]\n" + "4200,3,-2100\n" * 20_000)
    r = _run("tyre", "fit", rep, "--model", "mf1989")
    assert r.exit_code == 2 and "1 distinct input point" in _text(r), r.output


def test_options_and_help(tmp_path, monkeypatch):
    """D7 (`spec --loads`), D14 (`identify --cutoff/--radius/--rolling-radius`), D17 (`rig`
    sizes and values), D9 (`onboard --window-time/--grouping`), D21 (units kept in --help)."""
    import diffsusp.tyre as tyre
    from diffsusp.errors import InputError
    from diffsusp.tyre import rig

    def stop(*a, **k):   # the work itself is not the subject: the warnings before it are
        raise InputError("stopped before the work")

    monkeypatch.setattr(tyre, "specification", stop)
    monkeypatch.setattr(rig, "tyre_rig", stop)
    r = _run("tyre", "spec", BOOK, "--loads", "3000,90000")
    assert "90000 N beyond FZMAX" in _text(r), r.output
    r = _run("tyre", "rig", BOOK, "--slip-angle", "-90:90:3", "--slip-ratio", "5",
             "--camber-offset", "1e9")
    for limit in ("ALPMAX", "KPUMAX", "CAMMAX", "side-on"):
        assert limit in _text(r), (limit, r.output)
    monkeypatch.undo()
    for loads in ("nan", "-2000", "0", "inf", ",", "", "3000,,abc"):
        r = _run("tyre", "spec", BOOK, "--loads", loads, "--json")
        assert r.exit_code == 2 and "--loads" in _text(r), (loads, r.output)
        assert "NaN" not in r.output
    table = tmp_path / "ft.csv"
    table.write_text("t,segment,steer,camber,speed,omega,FZ,FX,FY,MZ\n0,0,0,0,2e4,70,4e3,0,0,0\n")
    for opt, val in (("--cutoff", "0"), ("--radius", "0"), ("--rolling-radius", "nan")):
        r = _run("tyre", "identify", table, opt, val)
        assert r.exit_code == 2 and opt in _text(r), (opt, r.output)
    for args in (("--slip-angle", "-4:4:200000"), ("--slip-angle", "nan"),
                 ("--fz", "0"), ("--fz", "nan"), ("--camber-offset", "inf")):
        r = _run("tyre", "rig", BOOK, *args)
        assert r.exit_code == 2, (args, r.output)
    rec = tmp_path / "rec.npz"
    np.savez(rec, time=np.arange(10) * 0.01)
    for args in (("--window-time", "nan"), ("--window-time", "0"), ("--grouping", ",")):
        r = _run("tyre", "onboard", rec, *args)
        assert r.exit_code == 2 and args[0] in _text(r), (args, r.output)
    for verb, unit in (("eval", "[rad]"), ("rig", "[deg, ISO-W]"), ("onboard", "[s]"),
                       ("identify", "[mm]")):
        r = _run("tyre", verb, "--help", terminal_width=300)
        assert r.exit_code == 0 and unit in r.output, (verb, r.output)


def test_onboard_records_exit_2(tmp_path):
    """D1, D9, D10: a FIFO, a renamed .npy, time that is NaN, constant, 2-D, text, in
    milliseconds or whole seconds, a wheel that does not spin: exit 2 naming the channel."""
    fifo = tmp_path / "live.npz"
    os.mkfifo(fifo)
    r = _run("tyre", "onboard", fifo)
    assert r.exit_code == 2 and "FIFO" in _text(r), r.output
    npy = tmp_path / "one.npz"
    with open(npy, "wb") as f:
        np.save(f, np.arange(5.0))
    r = _run("tyre", "onboard", npy)
    assert r.exit_code == 2 and "numpy.savez" in _text(r), r.output
    n = 400
    good_t = np.arange(n) * 0.005
    spin = np.full((n, 4), 60.0)
    cases = {"nan": dict(time=np.where(np.arange(n) == 7, np.nan, good_t)),
             "const": dict(time=np.zeros(n)),
             "twod": dict(time=good_t.reshape(-1, 2)),
             "text": dict(time=np.array(["a"] * n)),
             "ms": dict(time=np.arange(n) * 5.0),
             "seconds": dict(time=np.arange(n, dtype=np.int64)),
             "spin": dict(time=good_t, spin=np.zeros((n, 4)))}
    for name, arrays in cases.items():
        path = tmp_path / f"{name}.npz"
        np.savez(path, **{"spin": spin, **arrays})
        r = _run("tyre", "onboard", path)
        channel = "spin" if name == "spin" else "time"
        assert r.exit_code == 2 and f"{path}: {channel}:" in _text(r), (name, r.output)


def test_identify_units_and_plausibility(tmp_path):
    """D5, D13, D20 on `tyre identify`: km/h, rpm and ms headers are read (no "unknown unit");
    a belt speed in km/h without its unit (278x off), a negative load, NaN in a channel and a
    reversed time are exit 2 naming file, line and column, before any work."""
    n = 60
    rr = 294.0
    omega = np.full(n, 60.0)
    speed_mm_s = omega * rr
    base = {"t [ms]": np.arange(n) * 5.0, "segment": np.zeros(n), "steer [deg]": np.zeros(n),
            "camber": np.zeros(n), "speed [km/h]": speed_mm_s * 3.6e-3,
            "omega [rpm]": omega * 60 / (2 * np.pi), "FZ": np.full(n, 4e3), "FX": np.zeros(n),
            "FY": np.linspace(-500, 500, n)}   # no MZ: the library's own error, after ours

    def write(name, cols):
        path = tmp_path / name
        names = list(cols)
        rows = np.column_stack([np.asarray(cols[c], float) for c in names])
        path.write_text(",".join(names) + "\n" + "".join(
            ",".join(repr(float(v)) for v in row) + "\n" for row in rows))
        return path

    r = _run("tyre", "identify", write("units.csv", base))
    assert r.exit_code == 2 and "missing channel(s) MZ" in _text(r), r.output
    assert "not understood" not in _text(r) and "unknown unit" not in _text(r)
    kmh = dict(base)
    kmh["speed"] = kmh.pop("speed [km/h]")      # km/h written without its unit
    path = write("kmh.csv", kmh)
    r = _run("tyre", "identify", path)
    assert r.exit_code == 2 and f"{path}:1: speed" in _text(r) and "unit" in _text(r), r.output
    neg = dict(base, FZ=np.where(np.arange(n) == 4, -4e3, 4e3))
    path = write("neg.csv", neg)
    r = _run("tyre", "identify", path)
    assert r.exit_code == 2 and f"{path}:6: FZ" in _text(r), r.output
    nan = dict(base, FX=np.where(np.arange(n) == 9, np.nan, 0.0))
    path = write("nan.csv", nan)
    r = _run("tyre", "identify", path)
    assert r.exit_code == 2 and f"{path}:11: FX" in _text(r), r.output
    ms = dict(base)
    ms["t"] = ms.pop("t [ms]")      # milliseconds written without their unit
    path = write("ms.csv", ms)
    r = _run("tyre", "identify", path)
    assert r.exit_code == 2 and f"{path}:1: t:" in _text(r) and "[ms]" in _text(r), r.output
    back = dict(base)
    back["t [ms]"] = np.concatenate([np.arange(30) * 5.0, np.arange(30) * 5.0])
    path = write("back.csv", back)
    r = _run("tyre", "identify", path)
    assert r.exit_code == 2 and f"{path}:32: t" in _text(r), r.output


@pytest.fixture(scope="module")
def grid_table(tmp_path_factory):
    """`tyre eval --out` of MF 6.1 file at a pressure and speed of its own: the
    table a user fits back (has MX, MY, P_Pa, VX_m_s)."""
    folder = tmp_path_factory.mktemp("grid")
    inputs = folder / "in.csv"
    fz = np.repeat([2500.0, 4000.0, 5500.0], 31)
    sa = np.tile(np.linspace(-10, 10, 31), 3)
    inputs.write_text("FZ [N],SA [deg],P [kPa],VX [km/h]\n" + "".join(
        f"{float(a)!r},{float(b)!r},300,40\n" for a, b in zip(fz, sa, strict=True)))
    out = folder / "grid.csv"
    r = _run("tyre", "eval", MF61, "--inputs", inputs, "--out", out)
    assert r.exit_code == 0, r.output
    return inputs, out


def test_round_trip_and_unconverged_fit(tmp_path, grid_table, monkeypatch):
    """The P_Pa/VX_m_s round trip; D23 (mf1989 on a table with MX, MY: fits FX, FY, MZ and
    notes the rest) and D4 (a fit stopped by --max-steps: exit 3, the report says not
    converged, the .tir only with --keep-unconverged and marked in its first line)."""
    from diffsusp.tyre import fit as F

    inputs, grid = grid_table
    again = tmp_path / "again.csv"
    r = _run("tyre", "eval", MF61, "--inputs", grid, "--out", again)
    assert r.exit_code == 0, r.output
    first = np.genfromtxt(grid, delimiter=",", skip_header=1)
    second = np.genfromtxt(again, delimiter=",", skip_header=1)
    np.testing.assert_allclose(second, first, rtol=1e-12)   # P 300 kPa, VX 40 km/h kept
    # the same rows at the file's nominal pressure and speed differ: the round trip matters
    nominal = tmp_path / "nominal.csv"
    nominal.write_text("FZ [N],SA [rad]\n" + "".join(f"{float(a)!r},{float(b)!r}\n"
                                                     for a, b in first[:, :3:2]))
    r = _run("tyre", "eval", MF61, "--inputs", nominal, "--out", tmp_path / "nom_out.csv")
    nom = np.genfromtxt(tmp_path / "nom_out.csv", delimiter=",", skip_header=1)
    assert np.max(np.abs(nom[:, 7] - first[:, 7])) > 1.0   # FY [N]

    seen = []
    real_fit = F.fit

    def spy(*a, **k):
        seen.append(real_fit(*a, **k))
        return seen[-1]

    monkeypatch.setattr(F, "fit", spy)
    report = tmp_path / "fit.json"
    r = _run("tyre", "fit", grid, "--model", "mf1989", "--max-steps", "1", "--report", report)
    assert r.exit_code == 3, r.output
    assert "MX, MY not fitted" in _text(r) and "did NOT converge" in _text(r)
    doc = json.loads(report.read_text())["mf1989_lateral"]
    assert doc["converged"] is False
    # the CLI's handling of that non-converged report for an MF 5.2 start (.tir written)
    stuck = seen[-1][1]
    assert not stuck.converged
    monkeypatch.setattr(F, "fit", lambda m0, *a, **k: (m0, stuck))
    out = tmp_path / "fitted.tir"
    r = _run("tyre", "fit", grid, "--model", "mf52", "--start", MF52, "--out", out,
             "--mode", "pure_lateral")
    assert r.exit_code == 3 and not out.exists(), r.output
    assert "--keep-unconverged" in _text(r)
    r = _run("tyre", "fit", grid, "--model", "mf52", "--start", MF52, "--out", out,
             "--mode", "pure_lateral", "--keep-unconverged")
    assert r.exit_code == 3 and out.exists(), r.output
    assert out.read_text().startswith("$ NOT CONVERGED")
    read_tir(out)   # still a readable property file
    # slip angles in degrees in a column read as radians: warned
    deg = tmp_path / "deg.csv"
    rows = np.genfromtxt(inputs, delimiter=",", skip_header=1)
    deg.write_text("FZ,SA\n" + "".join(f"{float(a)!r},{float(b)!r}\n" for a, b in rows[:, :2]))
    r = _run("tyre", "eval", MF61, "--inputs", deg, "--out", tmp_path / "deg_out.csv")
    assert r.exit_code == 0 and "beyond ±90°" in _text(r) and "SA [deg]" in _text(r), r.output


_SLOW_COMPILE = r'''
import sys
import jax
import jax.numpy as jnp
import typer
from diffsusp.cli.common import _App, cli_errors

app = _App() if sys.argv.pop() == "app" else typer.Typer()   # "plain": the old entry


@app.command()
def compile_long():
    with cli_errors():
        def body(c, x):
            c = jnp.sin(c) * 1.0001 + jnp.cos(c * x) - jnp.tanh(c + x)
            return c, c

        f = jax.jit(lambda x: jax.lax.scan(body, 0.0, x, unroll=2000)[0])
        lowered = f.lower(jnp.ones(2000))
        print("compiling", flush=True)
        lowered.compile()   # about 40 s of XLA here


app()
'''


def test_sigterm_during_compile_exits_at_once(tmp_path):
    """D16: SIGTERM in the middle of a long XLA compilation ends the command at once (exit 130,
    the message printed). JAX returns from the interrupted compile, but the interpreter's
    shutdown used to wait for XLA's compiling threads (the whole compile: ~40 s here, 10 min on
    10⁶ rows) and then crash; the entry point (`common._App`) now ends with os._exit."""
    import signal
    import subprocess
    import sys
    import time

    script = tmp_path / "slow.py"
    script.write_text(_SLOW_COMPILE)
    env = dict(os.environ, JAX_ENABLE_COMPILATION_CACHE="false", DIFFSUSP_CACHE="")
    p = subprocess.Popen([sys.executable, str(script), "app"], env=env, text=True,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        assert p.stdout.readline() == "compiling\n"
        time.sleep(1.0)
        t0 = time.monotonic()
        p.send_signal(signal.SIGTERM)
        _, err = p.communicate(timeout=8.0)
        took = time.monotonic() - t0
    finally:
        p.kill()
        p.wait()
    assert p.returncode == 130 and "terminated (SIGTERM)" in err, (p.returncode, err)
    assert took < 3.0, took
