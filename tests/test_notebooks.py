"""Every notebook in notebooks/ (jupytext percent-format .py) runs top to bottom as a notebook,
and its executed copy is kept for the documentation site.

Each notebook is a test class of its own, so each is its own pytest-xdist work unit
(`--dist loadscope` makes one unit per class, and one per module for the other files, which
have no test classes): the two workers share them. They run last (conftest), when the rest of
the suite has put the programs they share with it (the pseudo-McPherson's solves, K&C metrics
and sensitivities, the steering model's 42-case solve) in the run's compilation cache, which
their kernels inherit.

The executed notebook (outputs and figures) is saved to `build/notebooks/<name>.ipynb`
(git-ignored), stamped with the SHA-256 of its source: the site (docs/hooks.py) renders it as
the notebook's page, so the notebooks are executed once, by the tests, not again by the
documentation build (`python -m pytest tests/test_notebooks.py && mkdocs build`). The test then
renders that page as the site does (mkdocs-jupyter, `execute: false`) and checks that every
figure and text output is in it."""

import importlib.util
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent
NOTEBOOKS = sorted((ROOT / "notebooks").glob("[0-9]*.py"))


def _hooks():
    spec = importlib.util.spec_from_file_location("diffsusp_docs_hooks", ROOT / "docs" / "hooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class _Notebook:
    path: pathlib.Path

    @pytest.mark.slow
    def test_runs(self, tmp_path):
        import jupytext
        import nbclient

        nb = jupytext.read(self.path)
        # The kernel starts with matplotlib's inline backend on (as `%matplotlib inline`): a
        # cell ending with a `Figure` (`plot.kc_curves(...)`, `report.plot()`) shows it, even in
        # a notebook that never imports pyplot (01, 04).
        client = nbclient.NotebookClient(nb, timeout=900, kernel_name="python3",
                                         extra_arguments=["--matplotlib=inline"],
                                         resources={"metadata": {"path": str(tmp_path)}})
        client.execute()
        outputs = [out for cell in nb.cells if cell.cell_type == "code"
                   for out in cell.get("outputs", [])]
        errors = [out for out in outputs if out.get("output_type") == "error"]
        assert not errors

        # The site's copy: saved, then rendered as the site renders it.
        hooks = _hooks()
        saved = hooks.save_executed(nb, self.path)
        assert saved == hooks.EXECUTED / f"{self.path.stem}.ipynb" and saved.is_file()
        page_nb, executed = hooks.notebook_page(self.path, tmp_path / "page")
        assert executed  # the saved copy is current: the page shows its outputs
        html = hooks.render_notebook(page_nb)

        figures = [out["data"]["image/png"] for out in outputs
                   if "image/png" in out.get("data", {})]
        assert figures, "a notebook of the site shows at least one figure"
        unshown = [out["data"]["text/plain"] for out in outputs
                   if str(out.get("data", {}).get("text/plain", "")).startswith("<Figure")
                   and "image/png" not in out["data"]]
        assert not unshown  # every figure a cell returns is drawn
        for png in figures:  # every figure, embedded as the kernel drew it
            assert f"data:image/png;base64,{png.strip()}" in html.replace("\n", "")
        streams = [out["text"] for out in outputs if out.get("output_type") == "stream"]
        for text in streams:  # and every printed line (its last non-blank one)
            last = [line for line in text.splitlines() if line.strip()][-1:]
            for line in last:
                assert line.strip()[:40] in hooks.html_text(html), line
        assert "without its outputs" not in html


for _path in NOTEBOOKS:  # Test_01_kc_analysis, ...
    globals()[f"Test_{_path.stem}"] = type(f"Test_{_path.stem}", (_Notebook,), {"path": _path})
