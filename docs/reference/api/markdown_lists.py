"""A Griffe extension for the API reference (mkdocs.yml, mkdocstrings `extensions:`): lists that
follow a paragraph line directly.

The docstrings are Markdown whose lists open right under their heading line, as in

    **Arguments:**
    - `mech`: the mechanism.

Python-Markdown (which mkdocstrings renders them with) starts a list only after a blank line: it
would print "- `mech`: ..." inside the paragraph. Before a docstring is rendered, this inserts
the blank line before a list item ("- ", "* ", "1. ") whose previous line is a paragraph line
(not blank, not indented, not itself an item), outside fenced code. The docstrings in the source
stay as they are (read as text, in `help()`, they are right).
"""

import re

import griffe

_ITEM = re.compile(r"^\s*(?:[-*]|\d+\.)\s+\S")
_FENCE = re.compile(r"^\s*(```|~~~)")


def loosen_lists(text: str) -> str:
    """`text` with a blank line before every list item that directly follows a paragraph line."""
    out, fenced = [], False
    for line in text.split("\n"):
        if _FENCE.match(line):
            fenced = not fenced
        elif (not fenced and _ITEM.match(line) and out and out[-1].strip()
              and not _ITEM.match(out[-1]) and not out[-1][:1].isspace()):
            out.append("")
        out.append(line)
    return "\n".join(out)


class MarkdownLists(griffe.Extension):
    """Applies `loosen_lists` to the docstring of every object Griffe loads."""

    def on_instance(self, *, obj, **kwargs):  # noqa: ARG002 (Griffe's hook signature)
        if obj.docstring is not None:
            obj.docstring.value = loosen_lists(obj.docstring.value)
