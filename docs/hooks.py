"""mkdocs hooks: pages generated from the code at build time (mkdocs.yml `hooks:`).

A page containing one of the markers below gets the generated Markdown in its place:

- `<!-- generated: metrics -->`: the K&C metric table, from the registry
  `diffsusp.kc.metrics.METRICS` (name, description and sign, internal and display unit, kind,
  the events whose default figures show it);
- `<!-- generated: cli -->`: the reference of the `diffsusp` command, from its Typer app
  (`typer.cli.get_docs_for_click`, the generator behind `typer ... utils docs`).

Nothing is written to disk: the documentation cannot go stale against the code.
"""

import re

_MARKER = re.compile(r"<!--\s*generated:\s*(\w+)\s*-->")


def _cell(text) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def metrics_table() -> str:
    """Markdown table of every entry of `diffsusp.kc.metrics.METRICS`, in registry order."""
    from diffsusp.kc.metrics import METRICS

    rows = ["| metric | description (sign) | unit | shown in | kind | default figures |",
            "|---|---|---|---|---|---|"]
    for name, m in METRICS.items():
        if m.derivative:
            kind = "derivative (per roll angle)" if m.per_roll else "derivative"
        else:
            kind = "geometric / load"
        shown = m.display_unit if m.scale == 1.0 else f"{m.display_unit} (× {m.scale:.6g})"
        plots = ", ".join(f"`{e}`" for e in m.plots) or "—"
        rows.append(f"| `{name}` | {_cell(m.description)} | {_cell(m.unit)} | {_cell(shown)} "
                    f"| {kind} | {plots} |")
    return "\n".join(rows) + "\n"


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


def on_page_markdown(markdown, page, config, files):  # noqa: ARG001 (mkdocs hook signature)
    def replace(match):
        try:
            generate = GENERATORS[match.group(1)]
        except KeyError:
            raise ValueError(f"{page.file.src_path}: unknown generated block "
                             f"{match.group(1)!r} (known: {sorted(GENERATORS)})") from None
        return generate()

    return _MARKER.sub(replace, markdown)
