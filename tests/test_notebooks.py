"""Every notebook in notebooks/ (jupytext percent-format .py) runs top to bottom as a notebook.

Each notebook is its own pytest-xdist work unit (an `xdist_group`, with `--dist loadgroup`), so
the two workers share them; they run last (conftest), when the rest of the suite has put the
programs they share with it (the pseudo-McPherson's solves, K&C metrics and sensitivities) in
the run's compilation cache, which their kernels inherit."""

import pathlib

import pytest

NOTEBOOKS = sorted((pathlib.Path(__file__).parent.parent / "notebooks").glob("[0-9]*.py"))


@pytest.mark.slow
@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.xdist_group(p.stem))
                                  for p in NOTEBOOKS], ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs(path, tmp_path):
    import jupytext
    import nbclient

    nb = jupytext.read(path)
    client = nbclient.NotebookClient(nb, timeout=900, kernel_name="python3",
                                     resources={"metadata": {"path": str(tmp_path)}})
    client.execute()
    errors = [out for cell in nb.cells if cell.cell_type == "code"
              for out in cell.get("outputs", []) if out.get("output_type") == "error"]
    assert not errors
