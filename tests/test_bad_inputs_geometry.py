"""Bad options of `identify geometry` and `identify correct`:
a non-finite or non-positive number, or a figures folder that is a file, is exit 2 naming the
option, before any work (the measurements given are not even a table: they are never read)."""

import pytest
from typer.testing import CliRunner

import diffsusp.cli.identify  # noqa: F401  (registers `identify`)
from diffsusp.cli import app


@pytest.mark.parametrize("args, option", [
    (["geometry", "--landmark-sigma", "nan"], "--landmark-sigma"),
    (["geometry", "--landmark-sigma", "inf"], "--landmark-sigma"),
    (["geometry", "--max-sigma", "0"], "--max-sigma"),
    (["geometry", "--min-snr", "-1"], "--min-snr"),
    (["correct", "--case", "1", "--tol", "nan"], "--tol"),
    (["correct", "--case", "1", "--tol", "0"], "--tol"),
    (["geometry", "--figures", "FILE"], "figures"),
])
def test_bad_options_exit_2_before_work(tmp_path, args, option):
    not_a_table = tmp_path / "poses.bin"
    not_a_table.write_bytes(b"\x00\xff")
    a_file = tmp_path / "a_file"
    a_file.write_text("")
    args = [str(a_file) if a == "FILE" else a for a in args]
    result = CliRunner().invoke(app, ["identify", args[0], "double_wishbone", "-m",
                                      str(not_a_table), *args[1:]])
    assert result.exit_code == 2, result.output
    assert option in result.output and "Traceback" not in result.output, result.output
