"""mkdocs hooks: pages generated from the code at build time (mkdocs.yml `hooks:`).

A page containing one of the markers below gets the generated Markdown in its place:

- `<!-- generated: metrics -->`: the K&C metric table, from the registry
  `diffsusp.kc.metrics.METRICS` (name, description and sign, internal and display unit, kind,
  the events whose default figures show it);
- `<!-- generated: cli -->`: the reference of the `diffsusp` command, from its Typer app
  (`typer.cli.get_docs_for_click`, the generator behind `typer ... utils docs`).

Nothing of these is written to disk: the documentation cannot go stale against the code.

The notebooks (`notebooks/NN_*.py`, jupytext percent format) are pages of their own, under
`notebooks/` in the site, rendered by mkdocs-jupyter without executing them (`execute: false`):
`tests/test_notebooks.py` executes each one and saves the executed copy to
`build/notebooks/NN_*.ipynb` (`save_executed`), stamped with the SHA-256 of its source. The
page shows that copy, outputs and figures included, when it is current; otherwise (no test run
yet, or the source changed since) the source without outputs, under a note that says so and
how to get them. The page notebooks are written to `build/docs-pages/notebooks/` (`on_files`). A
full local site: `python -m pytest -n 0 tests/test_notebooks.py && mkdocs build`.
"""

import datetime
import hashlib
import html
import os
import pathlib
import re

from mkdocs.plugins import event_priority
from mkdocs.structure.files import File

ROOT = pathlib.Path(__file__).resolve().parent.parent
NOTEBOOKS = ROOT / "notebooks"
EXECUTED = ROOT / "build" / "notebooks"  # written by tests/test_notebooks.py
PAGES = ROOT / "build" / "docs-pages"  # the notebooks the site renders, under notebooks/

_MARKER = re.compile(r"<!--\s*generated:\s*(\w+)\s*-->")


def _cell(text) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def metrics_table() -> str:
    """Markdown table of every entry of `diffsusp.kc.metrics.METRICS`, in registry order, with
    its small figure (`metric_figures`, files added by `on_files`)."""
    from diffsusp.kc.metrics import METRICS

    rows = ["| metric | description (sign) | unit | shown in | kind | default figures | figure |",
            "|---|---|---|---|---|---|---|"]
    for name, m in METRICS.items():
        if m.derivative:
            kind = "derivative (per roll angle)" if m.per_roll else "derivative"
        else:
            kind = "geometric / load"
        shown = m.display_unit if m.scale == 1.0 else f"{m.display_unit} (× {m.scale:.6g})"
        plots = ", ".join(f"`{e}`" for e in m.plots) or "—"
        figure = (f"[![{name}]({FIGURES}/{name}.png){{ width=220 }}]({FIGURES}/{name}.png)"
                  if name in _figures() else "—")
        rows.append(f"| `{name}` | {_cell(m.description)} | {_cell(m.unit)} | {_cell(shown)} "
                    f"| {kind} | {plots} | {figure} |")
    return "\n".join(rows) + "\n"


# -- one small figure per K&C metric --------------------------------------------------------------

FIGURES = "figures/metrics"  # relative to reference/metrics.md: docs/reference/figures/metrics/

# metric → (event, x, y, how): the curve the metric is read from, y against x in one event of
# `_metric_events`; how: "value" (the metric is y, marked at design), "slope" (the metric is
# dy/dx at design: the tangent is drawn with the metric's value as slope), "x" (the metric is
# the event's load, x; y shows what it does). Keys are per corner (an axle's with 'left/').
_TRAVEL_VALUE = ("toe", "camber", "caster", "kingpin_inclination", "scrub_radius",
                 "mechanical_trail", "wheel_centre_x", "wheel_centre_y", "wheel_centre_z",
                 "contact_patch_x", "contact_patch_y", "contact_patch_z", "spin_axis_x",
                 "spin_axis_y", "spin_axis_z", "half_track_change", "wheelbase_change",
                 "vertical_force")
FIGURE_SPECS = {
    **{name: ("parallel_travel", "wheel_travel", name, "value") for name in _TRAVEL_VALUE},
    "steer": ("steering", "rack_travel", "steer", "value"),
    "wheel_travel": ("parallel_travel", "vertical_force", "wheel_travel", "value"),
    "lateral_force": ("lateral_force", "lateral_force", "toe", "x"),
    "longitudinal_force": ("longitudinal_force", "longitudinal_force", "toe", "x"),
    "aligning_torque": ("aligning_torque", "aligning_torque", "toe", "x"),
    "bump_steer": ("parallel_travel", "wheel_travel", "toe", "slope"),
    "bump_camber": ("parallel_travel", "wheel_travel", "camber", "slope"),
    "wheel_rate": ("parallel_travel", "wheel_travel", "vertical_force", "slope"),
    "roll_centre_height": ("parallel_travel", "contact_patch_y", "contact_patch_z", "roll_centre"),
    "contact_recession_rate": ("parallel_travel", "wheel_travel", "_contact_rearward", "slope"),
    "wheel_centre_recession_rate": ("parallel_travel", "wheel_travel", "wheelbase_change",
                                    "slope"),
    **{f"{what}_compliance_{angle}": (load, load, "toe" if angle == "steer" else "camber",
                                      "slope")
       for what, load in (("lateral", "lateral_force"), ("longitudinal", "longitudinal_force"),
                          ("aligning_torque", "aligning_torque"))
       for angle in ("steer", "camber")},
    "steer_gain": ("steering", "rack_travel", "steer", "slope"),
    "camber_steer_gain": ("steering", "rack_travel", "camber", "slope"),
    "roll_angle": ("opposite_travel", "left/wheel_travel", "roll_angle", "value"),
    "roll_stiffness": ("opposite_travel", "roll_angle", "_roll_moment", "slope"),
    "roll_steer": ("opposite_travel", "roll_angle", "left/steer", "slope"),
}
_DESIGN = 6  # the middle of 13 cases: the design position (zero travel, zero load)


def _metric_events():
    """The events the figures are read from: the thesis's pseudo-McPherson half axle on a rack
    (parallel travel ±60 mm, steering ±20 mm of rack, lateral and longitudinal force ±4 kN and
    aligning torque ±300 N·m at its design load), and an axle of two double wishbones with
    bushings in opposite travel ±40 mm; 13 cases each, the middle one the design position."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np

    from diffsusp import kc
    from diffsusp.model.combine import combine
    from diffsusp.model.mirror import mirror
    from diffsusp.models import double_wishbone, pseudo_mcpherson

    pm = kc.with_rack(pseudo_mcpherson())
    dw = double_wishbone(bushings=True)
    axle = combine({"left": dw, "right": mirror(dw)})
    span = np.linspace(-1.0, 1.0, 13)
    events = {"parallel_travel": kc.parallel_travel(pm, 60.0 * span),
              "steering": kc.steering(pm, 20.0 * span),
              "lateral_force": kc.lateral_force(pm, 4000.0 * span),
              "longitudinal_force": kc.longitudinal_force(pm, 4000.0 * span),
              "aligning_torque": kc.aligning_torque(pm, 3.0e5 * span),
              "opposite_travel": kc.opposite_travel(axle, 40.0 * span)}
    for name, ev in events.items():
        assert ev.converged.all(), name
    return events


def _series(ev, key):
    """A metric of `ev` (internal units), or one of the two quantities the figures add:
    `_contact_rearward` (mm: the contact point's rearward displacement from design) and
    `_roll_moment` (N·mm: −(T/2)(F_L − F_R), T the design track of the wheel centres)."""
    import numpy as np

    m = {k: np.asarray(v) for k, v in ev.metrics.items()}
    if key == "_contact_rearward":
        rc = ev.rig.corners[0]
        c = np.stack([m[f"contact_patch_{a}"] for a in "xyz"], axis=-1)
        return (c - c[_DESIGN]) @ np.asarray(rc.rearward)
    if key == "_roll_moment":
        track = abs(m["left/wheel_centre_y"][_DESIGN] - m["right/wheel_centre_y"][_DESIGN])
        return -0.5 * track * (m["left/vertical_force"] - m["right/vertical_force"])
    return m[key] if key in m else np.asarray(ev.x)  # the event's input (rack travel)


def _label(key, ev):
    from diffsusp.kc.metrics import METRICS

    base = key.rsplit("/", 1)[-1]
    if key not in ev.metrics and key == ev.x_name:
        return key, ev.x_unit, 1.0
    if key == "_contact_rearward":
        return "contact point rearward", "mm", 1.0
    if key == "_roll_moment":
        return "roll moment −(T/2)(F_L − F_R)", "N·m", 1e-3
    m = METRICS[base]
    return key, m.display_unit, m.scale


def metric_figure(name, events):
    """The PNG of metric `name`'s small figure, and for a slope the (metric, finite-difference
    slope) pair at design, both in internal units (the build checks they agree)."""
    import io

    import numpy as np
    from matplotlib.figure import Figure

    from diffsusp.kc.metrics import METRICS

    event, xkey, ykey, how = FIGURE_SPECS[name]
    ev = events[event]
    metric = METRICS[name]
    key = ("left/" + name if f"left/{name}" in ev.metrics else name)
    x, y = _series(ev, xkey), _series(ev, ykey)
    (xl, xu, xs), (yl, yu, ys) = _label(xkey, ev), _label(ykey, ev)
    fig = Figure(figsize=(3.3, 2.3), dpi=100, layout="constrained")
    ax = fig.add_subplot()
    ax.tick_params(labelsize=7)
    ax.plot(x * xs, y * ys, "-", color="0.35", lw=1.2)
    x0, y0 = x[_DESIGN] * xs, y[_DESIGN] * ys
    check = None
    if how == "value":
        ax.plot([x0], [y0], "o", color="C3", ms=5)
        ax.set_title(f"at design: {y0:.4g} {yu}", fontsize=7, color="C3")
    elif how == "x":
        ax.axvline(0.0, color="C3", lw=0.8, ls=":")
        ax.set_title(f"x: {metric.description} →", fontsize=7, color="C3")
    elif how == "slope":
        value = float(np.asarray(ev.metrics[key])[_DESIGN])
        fd = float(np.gradient(y, x)[_DESIGN])
        check = (value, fd)
        half = 0.5 * (x.max() - x.min()) * xs
        tx = np.array([x0 - 0.6 * half, x0 + 0.6 * half])
        ax.plot(tx, y0 + value * (ys / xs) * (tx - x0), "-", color="C3", lw=1.6)
        ax.plot([x0], [y0], "o", color="C3", ms=4)
        ax.set_title(f"slope = {value * metric.scale:.4g} {metric.display_unit}", fontsize=7,
                     color="C3")
    elif how == "roll_centre":  # front view of the contact point's path, and its normal
        rc = ev.rig.corners[0]
        o, z = np.asarray(rc.outboard), np.asarray(rc.up)
        c = np.stack([_series(ev, f"contact_patch_{a}") for a in "xyz"], axis=-1)
        lateral, height = c @ o, c @ z
        rch = float(np.asarray(ev.metrics[key])[_DESIGN])
        ax.cla()
        ax.tick_params(labelsize=7)
        ax.plot(lateral, height, "-", color="0.35", lw=1.2)
        ax.plot([lateral[_DESIGN], 0.0], [height[_DESIGN], height[_DESIGN] + rch], "-",
                color="C3", lw=1.2)
        ax.plot([0.0], [height[_DESIGN] + rch], "o", color="C3", ms=5)
        ax.axvline(0.0, color="0.6", lw=0.8, ls=":")
        ax.set_title(f"roll centre {rch:.4g} mm above C", fontsize=7, color="C3")
        ax.set_aspect("equal", adjustable="datalim")
        xl, xu, yl, yu = "C outboard (front view)", "mm", "C height", "mm"
        # the normal to the path at design, through C, meets the centreline at that height
        d = np.gradient(np.stack([lateral, height], axis=-1), axis=0)[_DESIGN]
        check = (rch, lateral[_DESIGN] * d[0] / d[1])
    ax.set_xlabel(f"{xl} ({xu})", fontsize=7)
    ax.set_ylabel(f"{yl} ({yu})", fontsize=7)
    ax.grid(True, lw=0.3)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue(), check


_FIGURE_CACHE = {}


def _figures() -> dict:
    """metric → PNG bytes, computed once per build (`_metric_events`: six events, ~10 s of
    CPU); each slope checked against the curve's central difference at design (to 3 %: the
    figure must show what the metric says)."""
    if "png" not in _FIGURE_CACHE:
        from diffsusp.kc.metrics import METRICS

        missing = sorted(set(METRICS) - set(FIGURE_SPECS))
        if missing:
            raise ValueError(f"docs/hooks.py: no figure for the metrics {missing}: add them to "
                             "FIGURE_SPECS")
        events = _metric_events()
        png, bad = {}, []
        for name in METRICS:
            png[name], check = metric_figure(name, events)
            if check is not None and not abs(check[0] - check[1]) <= 0.03 * abs(check[0]):
                bad.append((name, *check))
        if bad:
            raise ValueError(f"docs/hooks.py: metric figures whose slope disagrees with the "
                             f"curve (metric, finite difference): {bad}")
        _FIGURE_CACHE["png"] = png
    return _FIGURE_CACHE["png"]


def cli_reference() -> str:
    """Markdown reference of every verb of `diffsusp`, from the Typer app."""
    import typer
    import typer.cli

    from diffsusp.cli import app

    command = typer.main.get_command(app)
    ctx = typer.Context(command)
    text = typer.cli.get_docs_for_click(obj=command, ctx=ctx, name="diffsusp", title=None)
    # Typer titles the page with a level-1 heading: the page has its own.
    return re.sub(r"\A# .*\n", "", text.lstrip())


GENERATORS = {"metrics": metrics_table, "cli": cli_reference}


# -- notebooks ----------------------------------------------------------------------------------

def source_hash(source: pathlib.Path) -> str:
    return hashlib.sha256(pathlib.Path(source).read_bytes()).hexdigest()


def saved_source_hash(saved: pathlib.Path):
    """The source SHA-256 an executed notebook saved by `save_executed` was stamped with."""
    import nbformat

    return nbformat.read(saved, as_version=4).metadata.get("diffsusp", {}).get("source_sha256")


def save_executed(nb, source: pathlib.Path) -> pathlib.Path:
    """Save an executed notebook (an `nbformat` node) of `notebooks/<source>` for the site, as
    `build/notebooks/<stem>.ipynb`, stamped with its source's SHA-256 and the time (written to
    a temporary name, then renamed: a build running meanwhile reads the old or the new)."""
    import nbformat

    source = pathlib.Path(source)
    nb.metadata["diffsusp"] = {
        "source": f"notebooks/{source.name}", "source_sha256": source_hash(source),
        "executed": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")}
    EXECUTED.mkdir(parents=True, exist_ok=True)
    path = EXECUTED / f"{source.stem}.ipynb"
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    nbformat.write(nb, tmp)
    os.replace(tmp, path)
    return path


def notebook_page(source: pathlib.Path, out_dir: pathlib.Path):
    """Write the notebook the site shows for `source` to `out_dir/<stem>.ipynb`: its executed
    copy (`save_executed`) when that copy's source hash is the source's, else the source
    without outputs; a note after the title says which. Returns (path, executed)."""
    import jupytext
    import nbformat

    source = pathlib.Path(source)
    saved = EXECUTED / f"{source.stem}.ipynb"
    nb, executed = None, False
    if saved.is_file():
        nb = nbformat.read(saved, as_version=4)
        stamp = nb.metadata.get("diffsusp", {})
        executed = stamp.get("source_sha256") == source_hash(source)
    run = f"`python -m pytest -n 0 tests/test_notebooks.py -k {source.stem}`"
    if executed:
        note = (f"*Executed by the test suite ({stamp['executed']}) from "
                f"`notebooks/{source.name}`; the outputs below are that run's.*")
    else:
        stale = nb is not None
        nb = jupytext.read(source)
        note = ("> **This page shows the notebook without its outputs**: "
                + ("its saved run is older than its source. " if stale else
                   "it has not been executed on the machine that built the site. ")
                + f"Run {run} (or the whole of `tests/test_notebooks.py`), then `mkdocs build`, "
                f"to see them; or open `notebooks/{source.name}` with Jupyter (jupytext).")
    cell = nbformat.v4.new_markdown_cell(note, id="diffsusp-site-note")
    if nb.nbformat_minor < 5:  # cell ids came with nbformat 4.5
        cell.pop("id")
    first = 1 if nb.cells and nb.cells[0].cell_type == "markdown" else 0
    nb.cells.insert(first, cell)
    out_dir = pathlib.Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"{source.stem}.ipynb"
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    nbformat.write(nb, tmp)
    os.replace(tmp, path)
    return path, executed


def render_notebook(path: pathlib.Path) -> str:
    """The HTML body mkdocs-jupyter makes of a notebook for its page (not executed)."""
    from mkdocs_jupyter.convert import nb2html

    return nb2html(str(path), execute=False)


def html_text(text: str) -> str:
    """Visible text of an HTML fragment (scripts, styles and tags removed, entities decoded)."""
    text = re.sub(r"<(script|style)\b.*?</\1>", "", text, flags=re.S)
    return html.unescape(re.sub(r"<[^>]+>", "", text))


@event_priority(50)  # before mkdocs-jupyter's on_files, which makes pages of the .ipynb files
def on_files(files, config):
    """Add `notebooks/<stem>.ipynb` (from `build/docs-pages/`) for every notebook."""
    for source in sorted(NOTEBOOKS.glob("[0-9]*.py")):
        path, _ = notebook_page(source, PAGES / "notebooks")
        files.append(File(f"notebooks/{path.name}", src_dir=str(PAGES),
                          dest_dir=config["site_dir"],
                          use_directory_urls=config["use_directory_urls"]))
    for name, png in _figures().items():
        files.append(File.generated(config, f"reference/{FIGURES}/{name}.png", content=png))
    return files


def on_page_markdown(markdown, page, config, files):  # noqa: ARG001 (mkdocs hook signature)
    def replace(match):
        try:
            generate = GENERATORS[match.group(1)]
        except KeyError:
            raise ValueError(f"{page.file.src_path}: unknown generated block "
                             f"{match.group(1)!r} (known: {sorted(GENERATORS)})") from None
        return generate()

    return _MARKER.sub(replace, markdown)
