"""Outputs that cannot be written and interrupted writers
a file-size limit reached while a table is written is exit 2
"cannot write" (not an internal error), and leaves neither a half table under the final name nor
a temporary file; a streamed table interrupted is marked incomplete."""

import os
import resource

import numpy as np
import pytest
import typer

from diffsusp.cli.common import cli_errors
from diffsusp.io.tables import TableWriter, read_table, write_table


def test_write_failure_and_interruption(tmp_path, capsys):
    path = tmp_path / "results.csv"
    write_table(path, {"FZ": [1.0, 2.0]}, {"FZ": "N"})
    before = path.read_text()
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    big = {"FY": np.linspace(0.0, 1.0, 5000)}
    try:
        resource.setrlimit(resource.RLIMIT_FSIZE, (4096, hard))
        with pytest.raises(typer.Exit) as exit_info, cli_errors():
            write_table(path, big, {"FY": "N"})
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
    assert exit_info.value.exit_code == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "cannot write" in err and "internal error" not in err, err
    assert path.read_text() == before                       # the old table, whole
    assert sorted(os.listdir(tmp_path)) == ["results.csv"]  # no temporary file left
    # Parquet through the same temporary-and-rename path
    pq = tmp_path / "r.parquet"
    write_table(pq, big, {"FY": "N"})
    assert read_table(pq)["FY"].size == 5000 and sorted(os.listdir(tmp_path)) == [
        "r.parquet", "results.csv"]
    # a streamed table interrupted after two appends: the rows so far, and the mark
    stream = tmp_path / "stream.csv"
    with pytest.raises(KeyboardInterrupt), TableWriter(stream, ["FZ"], {"FZ": "N"}) as w:
        w.append({"FZ": [1.0, 2.0]})
        w.append({"FZ": [3.0]})
        raise KeyboardInterrupt
    assert stream.read_text().splitlines()[-1] == \
        "# INCOMPLETE: 3 rows written, then KeyboardInterrupt"
    assert read_table(stream)["FZ"].tolist() == [1.0, 2.0, 3.0]
