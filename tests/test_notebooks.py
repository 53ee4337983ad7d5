"""Every notebook in notebooks/ (jupytext percent-format .py) runs top to bottom as a notebook.

Each notebook is a test class of its own, so each is its own pytest-xdist work unit
(`--dist loadscope` makes one unit per class, and one per module for the other files, which
have no test classes): the two workers share them. They run last (conftest), when the rest of
the suite has put the programs they share with it (the pseudo-McPherson's solves, K&C metrics
and sensitivities, the steering model's 42-case solve) in the run's compilation cache, which
their kernels inherit."""

import pathlib

import pytest

NOTEBOOKS = sorted((pathlib.Path(__file__).parent.parent / "notebooks").glob("[0-9]*.py"))


class _Notebook:
    path: pathlib.Path

    @pytest.mark.slow
    def test_runs(self, tmp_path):
        import jupytext
        import nbclient

        nb = jupytext.read(self.path)
        client = nbclient.NotebookClient(nb, timeout=900, kernel_name="python3",
                                         resources={"metadata": {"path": str(tmp_path)}})
        client.execute()
        errors = [out for cell in nb.cells if cell.cell_type == "code"
                  for out in cell.get("outputs", []) if out.get("output_type") == "error"]
        assert not errors


for _path in NOTEBOOKS:  # Test_01_kc_analysis, ...
    globals()[f"Test_{_path.stem}"] = type(f"Test_{_path.stem}", (_Notebook,), {"path": _path})
