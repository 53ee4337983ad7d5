"""The documentation site (mkdocs.yml, docs/): it builds with `mkdocs build --strict`, its
generated pages cover what the code has, and every Python code block of its pages runs.

- `test_site_builds_strict`: `mkdocs build --strict` into a temporary folder, in a subprocess
  (the command CI and a user run), so a broken link, a missing page, an object the API
  reference names but the code lost, or a failing generator fails the suite; then the built
  metric reference has one row per entry of `diffsusp.kc.metrics.METRICS` and the built CLI
  reference a section per verb of the Typer app (the generated pages are complete).
  The notebooks have pages (`notebooks/NN_*/`: their executed copies from
  `tests/test_notebooks.py` when a run saved them, else their sources without outputs, saying
  so) and every K&C metric a small figure (`reference/figures/metrics/<metric>.png`, computed
  by docs/hooks.py from one event per kind, each slope checked against its curve); the tyre
  reference lists every quantity of the tyre registries, with its figures.
- `test_api_reference_is_complete`: every public name of every public package and module of
  `diffsusp` (walked with pkgutil: its `__all__`; a top-level module without one, its
  functions and classes; `diffsusp.cli` is the CLI reference's) has an entry in the built API
  pages (`reference/api/`): an element id `<module>.<name>` that mkdocstrings gives the heading,
  whose module's `<name>` is the same object (a re-export is documented where it is defined).
  A new public name without an entry fails here; the pages show no private name.
  `test_docstring_markdown`: the Griffe extension that renders the docstrings' lists and
  brackets as their authors meant them.
- `test_notebook_page_shows_outputs_or_says_why_not`: the page notebook docs/hooks.py makes of a
  notebook source: without a saved run, and with a stale one, the source without outputs under
  a note saying so; with a current saved run, its outputs, which the rendered page contains.
- `test_code_blocks_run[page]`: every ```python block of every page under docs/, in page
  order, in one namespace per page, from the repository root (the pages read
  `tests/data/...`), in this process: the pages share the compiled programs (small models:
  the isolated bushing, the Chrono MacPherson strut, the thesis half axle). A page whose
  example raises, or whose `assert` fails, fails its test. Pages are found, not listed: a
  new page's blocks are executed without touching this file.
"""

import html
import importlib
import importlib.util
import os
import pathlib
import pkgutil
import re
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
_BLOCK = re.compile(r"^```python[^\n]*\n(.*?)^```", re.S | re.M)


def _pages_with_code():
    return sorted(p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md")
                  if _BLOCK.search(p.read_text(encoding="utf-8")))


PAGES = _pages_with_code()


def _text(path: pathlib.Path) -> str:
    """The visible text of a built page's article (tags stripped, entities decoded)."""
    page = path.read_text(encoding="utf-8")
    page = page[page.find("<article"):page.find("</article>")]
    return html.unescape(re.sub(r"<[^>]+>", " ", page))


def _hooks():
    spec = importlib.util.spec_from_file_location("diffsusp_docs_hooks", DOCS / "hooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    out = tmp_path_factory.mktemp("site")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1", JAX_PLATFORMS="cpu")
    run = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--quiet",
                          "--config-file", str(ROOT / "mkdocs.yml"), "--site-dir", str(out)],
                         cwd=ROOT, env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr
    return out


def test_site_builds_strict(site):
    from diffsusp.cli import app
    from diffsusp.kc.metrics import METRICS

    for page in ("index.html", "getting-started/index.html", "guides/kc/index.html",
                 "reference/api/kc/index.html"):
        assert (site / page).is_file(), page

    metrics = _text(site / "reference/metrics/index.html")
    rows = re.findall(r"^\s*([a-z_]+)\s*$", metrics, re.M)
    assert [r for r in rows if r in METRICS] == list(METRICS)  # every metric, registry order

    cli = _text(site / "reference/cli/index.html")
    verbs = [c.name for c in app.registered_commands]
    groups = [g.name for g in app.registered_groups]
    assert verbs and groups
    for name in (*verbs, *groups):
        assert f"diffsusp {name}" in cli, name
    for group in app.registered_groups:  # the sub-verbs too: identify direct, tyre fit, ...
        for sub in group.typer_instance.registered_commands:
            name = sub.name or sub.callback.__name__.replace("_", "-")
            assert f"diffsusp {group.name} {name}" in cli, (group.name, name)

    api = _text(site / "reference/api/kc/index.html")
    assert "parallel_travel" in api and "Parallel wheel travel" in api  # docstrings rendered

    page = (site / "reference/metrics/index.html").read_text(encoding="utf-8")
    for name in METRICS:  # a small figure per metric, in its row
        png = site / "reference/figures/metrics" / f"{name}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
        assert f'src="../figures/metrics/{name}.png"' in page, name

    hooks = _hooks()
    tyre = _text(site / "reference/tyre/index.html")  # every tyre quantity of the registries
    from diffsusp.tyre import TyreForces
    from diffsusp.tyre.onboard import QUANTITIES
    from diffsusp.tyre.poly import INPUT_UNITS
    from diffsusp.tyre.spec import SPEC_UNITS
    from diffsusp.tyre.vertical import VerticalState

    for names in (TyreForces._fields, SPEC_UNITS, VerticalState._fields, INPUT_UNITS,
                  QUANTITIES, hooks.TYRE_INPUTS):
        for name in names:
            assert re.search(rf"^\s*{re.escape(name)}\s*$", tyre, re.M), name
    page = (site / "reference/tyre/index.html").read_text(encoding="utf-8")
    for src in re.findall(r'src="(\.\./figures/tyre/[a-z_]+\.png)"', page):
        assert (site / "reference/tyre" / src).resolve().is_file(), src
    assert len(re.findall(r'src="\.\./figures/tyre/', page)) == 7

    for source in sorted((ROOT / "notebooks").glob("[0-9]*.py")):  # a page per notebook
        text = _text(site / "notebooks" / source.stem / "index.html")
        title = re.search(r"^# # (.+)$", source.read_text(encoding="utf-8"), re.M).group(1)
        assert title.strip() in text, source.name
        # with its saved run's outputs, or without outputs saying so (the notebook tests may
        # save a run while the site builds: which one is checked by the test below)
        executed = "Executed by the test suite" in text
        assert executed != ("This page shows the notebook without its outputs" in text)
        if executed:
            saved = hooks.EXECUTED / f"{source.stem}.ipynb"
            assert hooks.saved_source_hash(saved) == hooks.source_hash(source), source.name


def _public_names():
    """{module: [public name]} for every public package and module of `diffsusp` (see the module
    docstring): `__all__` where a module declares it; a top-level module without one (`plot`,
    `compilation`), the functions and classes it defines. A submodule without `__all__` is the
    implementation of its package, whose `__all__` is its public face."""
    import diffsusp

    found = [("diffsusp", True)] + [(m.name, m.ispkg) for m in
                                    pkgutil.walk_packages(diffsusp.__path__, "diffsusp.")]
    public = {}
    for name, ispkg in found:
        if any(part.startswith("_") for part in name.split(".")) or name.startswith("diffsusp.cli"):
            continue
        module = importlib.import_module(name)
        names = getattr(module, "__all__", None)
        if names is None:
            if ispkg or name.count(".") != 1:
                continue
            names = [n for n, obj in vars(module).items() if not n.startswith("_")
                     and (isinstance(obj, type) or callable(obj))
                     and getattr(obj, "__module__", None) == name]
        public[name] = list(names)
    return public


def test_api_reference_is_complete(site):
    ids = set()
    for page in (site / "reference/api").rglob("index.html"):
        ids |= set(re.findall(r'id="(diffsusp(?:\.\w+)*)"', page.read_text(encoding="utf-8")))
    assert not [i for i in ids if "._" in i]  # no private name rendered
    documented = {}  # name → the objects documented under it
    for ident in ids:
        module, _, name = ident.rpartition(".")
        if not module:
            continue
        try:
            obj = getattr(importlib.import_module(module), name)
        except (ImportError, AttributeError):  # a module's own heading: checked below by its id
            continue
        documented.setdefault(name, []).append(obj)
    public = _public_names()
    assert {"diffsusp.fleet", "diffsusp.lsq", "diffsusp.measure", "diffsusp.geometry",
            "diffsusp.mdh", "diffsusp.plot", "diffsusp.compilation"} <= set(public)
    assert sum(map(len, public.values())) > 600
    missing = []
    for module, names in public.items():
        for name in names:
            obj = getattr(importlib.import_module(module), name)
            if type(obj).__name__ == "module":
                if obj.__name__ not in ids:
                    missing.append(obj.__name__)
            elif not any(obj is other for other in documented.get(name, ())):
                missing.append(f"{module}.{name}")
    assert not missing, ("public names without an entry in docs/reference/api/*.md (add them to "
                         f"the page of the module that defines them): {missing}")


def test_docstring_markdown():
    """The Griffe extension of the API reference (docs/reference/api/docstring_markdown.py): a
    list right under a paragraph line gets its blank line, brackets before '(' or '[' are
    escaped; lists, code spans and fenced code stay as written."""
    spec = importlib.util.spec_from_file_location(
        "diffsusp_docstring_markdown", DOCS / "reference/api/docstring_markdown.py")
    ext = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ext)

    text = "**Arguments:**\n- `a`: one\n  more\n- `b`: two\n\nText\n1. first\n"
    assert ext.loosen_lists(text) == (
        "**Arguments:**\n\n- `a`: one\n  more\n- `b`: two\n\nText\n\n1. first\n")
    fenced = "```\nx\n- y\n```"
    assert ext.loosen_lists(fenced) == fenced
    assert ext.literal_brackets("[A_S2][A_J/S2] D, [vᵀ; wᵀ]((R − I) C), [mm] `a[i](j)`") == (
        "\\[A_S2][A_J/S2] D, \\[vᵀ; wᵀ]((R − I) C), [mm] `a[i](j)`")
    assert ext.literal_brackets("```\nf[i](x)\n```") == "```\nf[i](x)\n```"


def test_notebook_page_shows_outputs_or_says_why_not(tmp_path, monkeypatch):
    import nbformat

    hooks = _hooks()
    monkeypatch.setattr(hooks, "EXECUTED", tmp_path / "executed")
    source = tmp_path / "00_example.py"
    source.write_text("# %% [markdown]\n# # 00 — An example\n\n# %%\nprint(\"ab\" * 3)\n",
                      encoding="utf-8")

    page, executed = hooks.notebook_page(source, tmp_path / "pages")  # never run
    assert not executed
    text = hooks.html_text(hooks.render_notebook(page))
    assert "without its outputs" in text and "not been executed" in text
    assert "00 — An example" in text and 'print("ab" * 3)' in text and "ababab" not in text

    import jupytext

    nb = jupytext.read(source)
    nb.cells[1].outputs = [nbformat.v4.new_output("stream", name="stdout", text="ababab\n")]
    saved = hooks.save_executed(nb, source)
    assert saved == tmp_path / "executed" / "00_example.ipynb"
    page, executed = hooks.notebook_page(source, tmp_path / "pages")  # a current run
    assert executed
    text = hooks.html_text(hooks.render_notebook(page))
    assert "Executed by the test suite" in text and "ababab" in text
    assert "without its outputs" not in text

    source.write_text(source.read_text(encoding="utf-8") + "print(1)\n", encoding="utf-8")
    page, executed = hooks.notebook_page(source, tmp_path / "pages")  # the source changed
    assert not executed
    text = hooks.html_text(hooks.render_notebook(page))
    assert "older than its source" in text and "print(1)" in text and "ababab" not in text


def test_pages_with_code_are_found():
    assert {"getting-started.md", "concepts.md", "guides/models.md", "guides/kc.md"} <= set(PAGES)


@pytest.mark.parametrize("page", PAGES)
def test_code_blocks_run(page, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    monkeypatch.chdir(ROOT)
    blocks = _BLOCK.findall((DOCS / page).read_text(encoding="utf-8"))
    namespace = {"__name__": f"docs:{page}"}
    try:
        for i, block in enumerate(blocks):
            exec(compile(block, f"docs/{page} [python block {i + 1}]", "exec"), namespace)
    finally:
        plt.close("all")
