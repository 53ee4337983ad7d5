"""A Griffe extension for the API reference (mkdocs.yml, mkdocstrings `extensions:`): the
docstrings' Markdown as their authors read it.

The docstrings are Markdown whose lists open right under their heading line, as in

    **Arguments:**
    - `mech`: the mechanism.

Python-Markdown (which mkdocstrings renders them with) starts a list only after a blank line: it
would print "- `mech`: ..." inside the paragraph. Before a docstring is rendered, this inserts
the blank line before a list item ("- ", "* ", "1. ") whose previous line is a paragraph line
(not blank, not indented, not itself an item), outside fenced code. The docstrings in the source
stay as they are (read as text, in `help()`, they are right).

Square brackets are notation in these docstrings, never links (`[A_S2][A_J/S2] D_eq`,
`[vᵀ; wᵀ]((R^c − I) C + T^c)`: Markdown would read a link, and the strict build fails on it): a
bracket pair followed by `(` or `[` is escaped, outside code.
"""

import re

import griffe

_ITEM = re.compile(r"^\s*(?:[-*]|\d+\.)\s+\S")
_FENCE = re.compile(r"^\s*(```|~~~)")
_CODE = re.compile(r"(```.*?```|~~~.*?~~~|(`+).+?\2)", re.S)  # fenced blocks, code spans
_LINKLIKE = re.compile(r"\[([^\[\]\n]*)\](?=[(\[])")


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


def literal_brackets(text: str) -> str:
    """`text` with every `[...]` that Markdown would read as a link's text escaped, outside code."""
    out, i = [], 0
    for m in _CODE.finditer(text):
        out.append(_LINKLIKE.sub(r"\\[\1]", text[i:m.start()]))
        out.append(m.group(0))
        i = m.end()
    out.append(_LINKLIKE.sub(r"\\[\1]", text[i:]))
    return "".join(out)


class DocstringMarkdown(griffe.Extension):
    """Applies `loosen_lists` and `literal_brackets` to the docstring of every object Griffe
    loads."""

    def on_instance(self, *, obj, **kwargs):  # noqa: ARG002 (Griffe's hook signature)
        if obj.docstring is not None:
            obj.docstring.value = literal_brackets(loosen_lists(obj.docstring.value))
