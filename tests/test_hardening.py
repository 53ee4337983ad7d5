"""Hostile inputs: every file, table and run fails safely, with the library's own
message and exit code, and never a Python traceback or source line.

Almost everything here exercises parsers and argument handling without compiling a solve; the
interruption tests replace `solve_statics` by a stand-in so that only the (tiny) isolated
bushing's output program compiles.
"""

import json
import os
import pathlib
import re
import signal
import threading

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

import diffsusp.cli.model as cli_model
from diffsusp import simulation
from diffsusp.cli import app
from diffsusp.errors import ModelFileError
from diffsusp.io import read_table, write_table
from diffsusp.statics import StaticSolution

ROOT = pathlib.Path(__file__).parent
DATA = ROOT / "data"
MODELS = pathlib.Path(cli_model.__file__).parents[1] / "models" / "data"
ADM = (DATA / "model_exemple11.adm").read_text()
BUSHING_TOML = (MODELS / "isolated_bushing.toml").read_text()
TIR = next((pathlib.Path(cli_model.__file__).parents[1] / "tyre" / "data").glob("*.tir"))


def invoke(*args, env=None):
    return CliRunner().invoke(app, [str(a) for a in args], env=env)


def text(result) -> str:
    return " ".join(result.stderr.split())


def assert_clean(result):
    """No Python traceback, source path or code line on either stream."""
    for stream in (result.stdout, result.stderr):
        assert "Traceback" not in stream
        assert not re.search(r"\.py:\d+", stream), stream


# ------------------------------------------------------------------ 1. files: type and size


@pytest.mark.parametrize("suffix", [".toml", ".adm", ".json"])
def test_a_link_to_an_endless_device_is_refused(tmp_path, suffix):
    link = tmp_path / f"model{suffix}"
    link.symlink_to("/dev/zero")
    result = invoke("info", link)
    assert result.exit_code == 2, result.output
    assert "is a character device, not a regular file" in text(result)
    assert_clean(result)


def test_a_fifo_is_refused_without_opening_it(tmp_path):
    fifo = tmp_path / "model.toml"
    os.mkfifo(fifo)

    def unblock():  # the old code blocked in open(); this lets it fail instead of hanging
        try:
            fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
            os.close(fd)
        except OSError:
            pass

    timer = threading.Timer(5.0, unblock)
    timer.start()
    try:
        result = invoke("info", fifo)
    finally:
        timer.cancel()
    assert result.exit_code == 2, result.output
    assert "is a FIFO (named pipe), not a regular file" in text(result)


def test_size_limit_and_its_override(tmp_path):
    model = tmp_path / "bushing.toml"
    model.write_text(BUSHING_TOML)  # ~1.5 kB
    env = {"DIFFSUSP_MAX_FILE_MB": "0.001"}  # 1 kB
    result = invoke("info", model, env=env)
    assert result.exit_code == 2, result.output
    assert "more than the limit of 1048 bytes" in text(result)
    assert "--max-file-mb" in text(result)
    result = invoke("--max-file-mb", "1", "info", model, "--json", env=env)
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["bushings"] == ["bush"]
    result = invoke("--max-file-mb", "-3", "info", model)
    assert result.exit_code == 2 and "--max-file-mb must be a positive" in text(result)


def test_every_reader_checks_type_and_size(tmp_path, monkeypatch):
    from diffsusp import measure
    from diffsusp.io import read_adm, read_chrono, read_iges, read_model_toml, read_tir
    from diffsusp.io.adams import read_bushing_property, read_lcf
    from diffsusp.models import isolated_bushing

    for reader, name in ((read_model_toml, "m.toml"), (read_adm, "m.adm"),
                         (read_chrono, "m.json"), (read_lcf, "m.lcf"),
                         (read_bushing_property, "m.bus"), (read_tir, "t.tir"),
                         (read_iges, "p.igs"), (read_table, "t.csv"),
                         (read_table, "t.parquet"),
                         (lambda p: measure.read_measurements(p, isolated_bushing()), "t.csv")):
        link = tmp_path / name
        if not link.exists():
            link.symlink_to("/dev/zero")
        with pytest.raises(ModelFileError, match="character device"):
            reader(link)
    big = tmp_path / "big.csv"
    big.write_text("fz\n" + "1\n" * 2000)
    monkeypatch.setenv("DIFFSUSP_MAX_FILE_MB", "0.001")
    with pytest.raises(ModelFileError, match="more than the limit"):
        read_table(big)
    monkeypatch.setenv("DIFFSUSP_MAX_FILE_MB", "lots")
    with pytest.raises(ModelFileError, match="positive number of MiB"):
        read_table(big)


def test_large_native_file_parses_with_the_linear_parser():
    """A 2 000-marker native file: tomllib reads it (tomlkit, quadratic in practice, is only
    asked for the wording of a small malformed file)."""
    from diffsusp.io.native import model_from_toml

    extra = "".join(f'\n[markers."m{i}"]\npart = "arm"\nposition = [{i}.0, 1.0, 2.0]\n'
                    for i in range(2000))
    mf = model_from_toml(BUSHING_TOML + extra, check=False)
    assert len(mf.mechanism.markers.names) == 2004


# ------------------------------------------------------------------ 2. verbatim messages


def test_bracketed_text_in_messages_and_paths_is_printed(tmp_path):
    result = invoke("info", tmp_path / "suspension[v2].toml")
    assert result.exit_code == 2
    assert "suspension[v2].toml" in text(result)
    no_units = tmp_path / "no_units.toml"
    no_units.write_text(re.sub(r"\[units\][^\[]*", "", BUSHING_TOML))
    result = invoke("info", no_units)
    assert result.exit_code == 2
    assert "missing [units]: declare the file's units" in text(result)
    assert_clean(result)
    tir = tmp_path / "tyre[v2].tir"
    tir.write_text(TIR.read_text(encoding="latin-1"), encoding="latin-1")
    result = invoke("tyre", "info", tir)
    assert result.exit_code == 0, result.output
    assert "tyre[v2].tir" in " ".join(result.stdout.split())


def test_a_model_name_with_markup_is_printed_verbatim(tmp_path):
    model = tmp_path / "m.toml"
    model.write_text(BUSHING_TOML.replace('name = "isolated bushing (model_exemple11)"',
                                          'name = "axle [bold]v2[/bold]"'))
    result = invoke("info", model)
    assert result.exit_code == 0, result.output
    assert "axle [bold]v2[/bold]" in result.stdout


# ------------------------------------------------------------------ 5. warnings, skipped loads


def _adm(tmp_path, old, new, name="m.adm"):
    assert old in ADM
    path = tmp_path / name
    path.write_text(ADM.replace(old, new))
    return path


GFORCE = "GFORCE/1, I = 12, JFLOAT = 14, RM = 13"


def test_warnings_use_the_cli_format_and_a_skipped_load_keeps_its_load_point(tmp_path):
    path = _adm(tmp_path, GFORCE, GFORCE + ", FUNCTION = USER(1)")
    result = invoke("info", path, "--json")
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["load_points"] == ["GFORCE_1"]
    assert "warning: " in result.stderr and "USER(...)" in text(result)
    assert "load point 'GFORCE_1' is kept" in text(result)
    assert "ModelWarning" not in result.stderr
    assert_clean(result)


def test_a_load_that_cannot_be_placed_is_named_as_missing(tmp_path):
    # The reaction marker on a moving part: the load statement is skipped, and `info` says
    # which load point the model does not have.
    path = _adm(tmp_path, "MARKER/14, PART = 1, FLOATING", "MARKER/14, PART = 2, FLOATING")
    result = invoke("info", path, "--json")
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["load_points"] == []
    assert "THE MODEL HAS NO LOAD POINT 'GFORCE_1'" in text(result)
    assert_clean(result)


# ------------------------------------------------------------------ 6. one fault, one code


@pytest.fixture(scope="module")
def free_models(tmp_path_factory):
    """The isolated bushing without its torsional stiffness about x: a free rotation, as an
    Adams dataset and as the native file of the same mechanism."""
    from diffsusp.io import save_model
    from diffsusp.io.adams import parse_adm

    folder = tmp_path_factory.mktemp("free")
    adm = folder / "free.adm"
    adm.write_text(ADM.replace(", KT = 5.729577951E+005, 5.729577951E+005",
                               ", KT = 0, 5.729577951E+005"))
    save_model(parse_adm(adm).build(check=False), folder / "free.toml")
    loads = folder / "loads.csv"
    write_table(loads, {"GFORCE_1.fx": [1.0]})
    return adm, folder / "free.toml", loads


@pytest.mark.parametrize("kind", [0, 1])
def test_a_free_mode_has_one_exit_code_whatever_the_format(free_models, tmp_path, kind):
    model, loads = free_models[kind], free_models[2]
    result = invoke("simulate", model, "--loads", loads, "--out", tmp_path / "r.csv")
    assert result.exit_code == 4, result.output
    assert "is free: rotation" in text(result)
    info = invoke("info", model, "--json")
    assert info.exit_code == 0, info.output
    assert any("free: rotation" in m for m in json.loads(info.stdout)["free_modes"])


# ------------------------------------------------------------------ 7. messages that mislead


def test_empty_adams_dataset(tmp_path):
    for content in ("", "just a title\n"):
        path = tmp_path / "empty.adm"
        path.write_text(content)
        result = invoke("info", path)
        assert result.exit_code == 2
        assert "holds no statement (an empty file?)" in text(result)
        assert "concatenate" not in text(result)


def test_truncated_native_file_and_nul_bytes(tmp_path):
    from diffsusp.io.native import model_from_toml

    cut = BUSHING_TOML[: BUSHING_TOML.index("[0.9330127021193223") + 10]
    with pytest.raises(ModelFileError, match="the file ends early") as e:
        model_from_toml(cut, path="cut.toml")
    assert "\\x00" not in str(e.value) and e.value.line == cut.count("\n") + 1
    with pytest.raises(ModelFileError, match="NUL byte") as e:
        model_from_toml(BUSHING_TOML[:200] + "\x00" * 50, path="z.toml")
    assert e.value.line == BUSHING_TOML[:200].count("\n") + 1


@pytest.mark.parametrize("bad", ["NaN", "-Infinity", "1e999"])
def test_chrono_non_finite_numbers_are_located(tmp_path, bad):
    from diffsusp.io import read_chrono

    lines = (DATA / "chrono" / "DoubleWishbone.json").read_text().splitlines()
    k = max(i for i, line in enumerate(lines) if re.search(r":\s*-?[\d.]+,?\s*$", line))
    lines[k] = re.sub(r"-?[\d.]+(,?\s*)$", bad + r"\1", lines[k])
    path = tmp_path / "bad.json"
    path.write_text("\n".join(lines))
    with pytest.raises(ModelFileError, match=re.escape(bad)) as e:
        read_chrono(path)
    assert e.value.line == k + 1 > 1


def test_adams_message_names_its_field_once(tmp_path):
    path = _adm(tmp_path, "BUSHING/1, I = 7, J = 8, K = 100, 100, 100",
                "BUSHING/1, I = 7, J = 8, K = 100, 100")
    with pytest.raises(ModelFileError) as e:
        from diffsusp.io import read_adm

        read_adm(path)
    assert e.value.field == "K"
    assert str(e.value).endswith(":43: BUSHING/1 'BUSHING_1': K needs 3 value(s); got 2.")


LANDMARKS = ("case,part,landmark,x,y,z,x0,y0,z0,centre.fz\n"
             "1,arm,a,0,0,0,0,0,0,10\n1,arm,b,100,0,0,100,0,0,10\n1,arm,c,0,100,0,0,100,0,10\n")


def test_measurement_tables_name_unknown_parts_and_absurd_numbers(tmp_path):
    from diffsusp import measure
    from diffsusp.models import isolated_bushing

    mech = isolated_bushing()
    path = tmp_path / "m.csv"
    path.write_text(LANDMARKS.replace("1,arm,c", "1,hub,c"))
    with pytest.raises(ModelFileError, match="part 'hub' is not a moving part of model") as e:
        measure.read_measurements(path, mech)
    assert e.value.line == 4
    path.write_text(LANDMARKS.replace("1,arm,b,100,0,0", "1,arm,b,1e300,0,0"))
    with pytest.raises(ModelFileError, match=r"1e300 in column 'x' \(column 4\) is beyond") as e:
        measure.read_measurements(path, mech)
    assert e.value.line == 3


# ------------------------------------------------------------------ 3. default fit selection


def test_fit_default_selection_leaves_zero_stiffnesses_out_with_a_note():
    from diffsusp.identify import fit_selection
    from diffsusp.models import pseudo_mcpherson

    mech = pseudo_mcpherson()
    k = np.concatenate([np.asarray(mech.bushings.k_trans), np.asarray(mech.bushings.k_rot)], 1)
    assert (k == 0).any()  # the shipped model has free bushing directions
    params, notes = fit_selection(mech, None, None)
    assert len(params) == int(np.sum(k > 0))
    assert "bushing_F.Krz" not in params.names
    assert notes and "bushing_F.Krz" in notes[0] and "--start" in notes[0]
    # With --start every selected stiffness is fitted from that value.
    params, notes = fit_selection(mech, None, None, start=1e4)
    assert len(params) == k.size
    assert not notes


# ------------------------------------------------------------------ 8. outputs checked first


@pytest.fixture
def no_solve(monkeypatch):
    import diffsusp.statics

    def refuse(*args, **kwargs):
        raise AssertionError("the solve ran before the output path was checked")

    monkeypatch.setattr(diffsusp.statics, "solve_statics", refuse)


@pytest.fixture(scope="module")
def loads5(tmp_path_factory):
    path = tmp_path_factory.mktemp("loads") / "loads.csv"
    write_table(path, {"centre.fx": [10.0, 20.0, 30.0, 40.0, 50.0]}, {"centre.fx": "N"})
    return path


def test_output_paths_are_checked_before_the_work(tmp_path, loads5, no_solve, monkeypatch):
    import diffsusp.cli.kc as cli_kc

    monkeypatch.setattr(cli_kc, "run_event", lambda *a, **k: pytest.fail("event ran"))
    a_file = tmp_path / "file.txt"
    a_file.write_text("x")
    for args, message in (
        (("simulate", "isolated_bushing", "-l", loads5, "-o", tmp_path / "no/such/r.csv"),
         "does not exist"),
        (("simulate", "isolated_bushing", "-l", loads5, "-o", tmp_path),
         "unknown format '(no suffix)'"),
        (("kc", "isolated_bushing", "--out", a_file), "it is a file, not a folder"),
        (("sensitivity", "isolated_bushing", "--out", a_file), "it is a file, not a folder"),
        (("demo", "--out", a_file), "it is a file, not a folder"),
        (("identify", "fit", "isolated_bushing", "-m", loads5, "--out",
          tmp_path / "nope" / "r.json"), "does not exist"),
        (("identify", "direct", "isolated_bushing", "-m", loads5, "--write-model",
          tmp_path / "nope" / "m.toml"), "does not exist"),
        (("identify", "iterative", "isolated_bushing", "-m", loads5, "--figures", a_file),
         "it is a file, not a folder"),
        (("tyre", "eval", TIR, "--grid", "--out", tmp_path / "nope" / "r.csv"),
         "does not exist"),
        (("tyre", "rig", TIR, "--model", "pseudo_mcpherson", "--out", tmp_path / "r.txt"),
         "unknown format '.txt'"),
        (("tyre", "fit", loads5, "--start", TIR, "--out", tmp_path / "nope" / "f.tir"),
         "does not exist"),
        (("identify", "geometry", "isolated_bushing", "-m", loads5, "--out",
          tmp_path / "nope" / "j.csv"), "does not exist"),
    ):
        result = invoke(*args)
        assert result.exit_code == 2, (args, result.output)
        assert message in text(result), (args, text(result))
        assert_clean(result)


def _fake_solutions(stop_after, interrupt):
    """A stand-in for solve_statics (patched where `solve_statics_chunks` calls it): zero
    displacement, converged, for `stop_after` calls; then `interrupt()`."""
    calls = []

    def solve(mech, loads, **kwargs):
        calls.append(loads.n_cases)
        if len(calls) > stop_after:
            interrupt()
        n = loads.n_cases
        return StaticSolution(
            q=np.zeros((n, 6 * len(mech.parts))), multipliers=np.zeros((n, 0)),
            status=np.zeros(n, int), iterations=np.ones(n, int), residual=np.zeros(n),
            constraint_error=np.zeros(n), stable=np.ones(n, bool), law_valid=np.ones(n, bool))

    return solve


def _raise_keyboard_interrupt():
    raise KeyboardInterrupt


def _send_sigterm():
    os.kill(os.getpid(), signal.SIGTERM)


@pytest.mark.parametrize("interrupt,word", [(_raise_keyboard_interrupt, "interrupted"),
                                            (_send_sigterm, "terminated (SIGTERM)")])
@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_an_interrupted_simulate_leaves_the_finished_cases_on_disk(
        tmp_path, loads5, monkeypatch, interrupt, word, suffix):
    import diffsusp.statics.solve

    monkeypatch.setattr(simulation, "CHUNK", 2)
    monkeypatch.setattr(diffsusp.statics.solve, "solve_statics", _fake_solutions(1, interrupt))
    out = tmp_path / f"r{suffix}"
    result = invoke("simulate", "isolated_bushing", "-l", loads5, "-o", out)
    assert result.exit_code == 130, result.output
    assert f"{word} after 2 of 5 load cases" in text(result)
    table = read_table(out)
    np.testing.assert_array_equal(table["case"], np.arange(5))
    np.testing.assert_array_equal(table["status"], [0, 0, -1, -1, -1])
    np.testing.assert_array_equal(table["stable"], [1, 1, 0, 0, 0])  # not solved: not flagged
    np.testing.assert_array_equal(table["centre.fx"], [10, 20, 30, 40, 50])
    assert np.all(table["arm.x"][:2] == 0) and np.all(np.isnan(table["arm.x"][2:]))
    assert_clean(result)


def test_simulate_writes_chunk_by_chunk(tmp_path, loads5, monkeypatch):
    """The rows of a finished chunk are on disk while the next one is being solved."""
    import diffsusp.statics.solve

    out = tmp_path / "r.csv"
    seen = []

    def look():
        seen.append(read_table(out).n_rows)

    solve = _fake_solutions(10, None)

    def solve_and_look(mech, loads, **kwargs):
        if out.exists():
            look()
        return solve(mech, loads, **kwargs)

    monkeypatch.setattr(simulation, "CHUNK", 2)
    monkeypatch.setattr(diffsusp.statics.solve, "solve_statics", solve_and_look)
    result = invoke("simulate", "isolated_bushing", "-l", loads5, "-o", out)
    assert result.exit_code == 0, result.output
    assert seen == [2, 4]
    assert read_table(out).n_rows == 5


# ------------------------------------------------------------------ property: random files


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cut=st.integers(min_value=0, max_value=len(BUSHING_TOML)),
       junk=st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=8))
def test_mutated_native_files_raise_the_library_error(cut, junk):
    """Any truncation of a valid file, with any junk appended, is read or refused with a
    `ModelFileError` (or the model error of a file that is well written but unsolvable)."""
    from diffsusp.errors import ModelError
    from diffsusp.io.native import model_from_toml

    try:
        model_from_toml(BUSHING_TOML[:cut] + junk, path="m.toml", check=False)
    except ModelError as e:
        assert "\\x00" not in str(e)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cut=st.integers(min_value=0, max_value=len(ADM)),
       junk=st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=8))
def test_mutated_adams_files_raise_the_library_error(cut, junk):
    import warnings

    from diffsusp.errors import ModelError
    from diffsusp.io.adams import parse_adm

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # skipped statements of a cut file
            parse_adm(ADM[:cut] + junk + "\n").build(check=False)
    except ModelError as e:
        assert "concatenate" not in str(e)


@pytest.mark.parametrize("suffix", [".csv", ".json"])
def test_an_interrupted_fit_leaves_its_last_estimate_on_disk(tmp_path, monkeypatch, suffix):
    import diffsusp.identify
    from diffsusp.identify.least_squares_report import StepRecord

    def fit_then_interrupt(mech, data, params, *, callback, **kwargs):
        estimate = np.asarray(params.start) * 2.0
        callback(0, StepRecord(step=0, trial=estimate, trial_loss=1.0,
                                          failed_cases=0, accepted=True, estimate=estimate,
                                          step_size=1.0))
        os.kill(os.getpid(), signal.SIGTERM)

    monkeypatch.setattr(diffsusp.identify, "least_squares", fit_then_interrupt)
    table = tmp_path / "marks.csv"
    table.write_text(LANDMARKS)
    out = tmp_path / f"fit{suffix}"
    result = invoke("identify", "fit", "isolated_bushing", "-m", table, "--start", "1e4",
                    "--out", out)
    assert result.exit_code == 130, result.output
    assert "terminated (SIGTERM); the estimate of the last LM step is in" in text(result)
    if suffix == ".json":
        rows = json.loads(out.read_text())["rows"]
    else:
        lines = out.read_text().splitlines()
        header = lines[0].split(",")
        rows = [dict(zip(header, line.split(","), strict=True)) for line in lines[1:]]
    assert [r["parameter"] for r in rows] == [f"bush.{a}" for a in
                                              ("Ktx", "Kty", "Ktz", "Krx", "Kry", "Krz")]
    assert all(float(r["value"]) == pytest.approx(2e4) for r in rows)
    assert {r["status"] for r in rows} == {"interrupted"}
    assert_clean(result)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(row=st.integers(min_value=1, max_value=3), column=st.integers(min_value=0, max_value=9),
       cell=st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr),
                      st.text(max_size=6)))
def test_mutated_measurement_cells_raise_the_library_error(tmp_path_factory, row, column, cell):
    """Any one cell of a landmark table replaced by any number or text: read, or refused with
    the library's own error (`InputError`, of which `ModelFileError` is one)."""
    from diffsusp import measure
    from diffsusp.errors import InputError
    from diffsusp.models import isolated_bushing

    lines = LANDMARKS.splitlines()
    cells = lines[row].split(",")
    cells[column] = cell.replace(",", ";").replace("\n", " ").replace("\r", " ").replace('"', "'")
    lines[row] = ",".join(cells)
    path = tmp_path_factory.mktemp("cell") / "m.csv"
    path.write_text("\n".join(lines) + "\n")
    try:
        meas = measure.read_measurements(path, isolated_bushing())
    except InputError:
        return
    assert np.all(np.isfinite(np.asarray(meas.loads.force)))


def test_an_empty_load_table_is_bad_input(tmp_path, no_solve):
    loads = tmp_path / "empty.csv"
    loads.write_text("centre.fx [N]\n")
    result = invoke("simulate", "isolated_bushing", "-l", loads, "-o", tmp_path / "r.csv")
    assert result.exit_code == 2, result.output
    assert "the load table has no rows" in text(result)


def test_an_interrupted_kc_run_exits_130_without_a_traceback(monkeypatch):
    import diffsusp.cli.kc as cli_kc

    def terminate(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGTERM)

    monkeypatch.setattr(cli_kc, "run_event", terminate)
    before = signal.getsignal(signal.SIGTERM)
    result = invoke("kc", "isolated_bushing")
    assert result.exit_code == 130, result.output
    assert "terminated (SIGTERM)" in text(result)
    assert signal.getsignal(signal.SIGTERM) == before  # the previous handler is back
    assert_clean(result)
