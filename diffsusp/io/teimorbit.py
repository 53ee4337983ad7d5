"""The TeimOrbit line grammar of Adams property files: tyre files (`.tir`, read by `io.tir`),
A/Car load-case files (`.lcf`) and bushing property files (`.bus`, read by `io.adams_property`).

spec: tyre §7 C (the .tir format), stiffness §4.2, §4.3 (.lcf, .bus).

One grammar for every reader; what a section means is the reader's. After stripping, a line is
- blank, or a comment: `$` or `!` first (skipped by `tokenise`);
- ``[SECTION]`` or ``(SUBSECTION)``: letters, digits, ``_`` and inner blanks;
- ``{col1 col2 ...}``: a table header naming its columns;
- ``NAME = value``: a quoted string (``'...'`` or ``"..."``), a number (Fortran ``D``
  exponents allowed: ``1.5D-3``) or unquoted text, then an optional ``$`` or ``!`` comment;
- a table row: numbers or quoted strings separated by blanks;
- anything else (kind ``other``): the reader says why it cannot read it.

Reading never executes anything from a file.
"""

import dataclasses
import re
from collections.abc import Iterator

__all__ = ["NUMBER", "WORD", "TeimLine", "tokenise", "classify", "split_value", "scalar"]

NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eEdD][+-]?\d+)?")
"""A number as written in a TeimOrbit file (``D`` or ``d`` for a Fortran double exponent)."""
WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_.]*")
"""An unquoted word value (``LEFT``, ``wheel_vertical_force``)."""
COMMENT = "$!"
"""Characters that start a comment line, or a comment after a value."""

_BLOCKS = (("section", re.compile(r"\[([^\[\]]*)\]")),
           ("subsection", re.compile(r"\(([^()]*)\)")))
_BLOCK_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_ ]*")
_HEADER = re.compile(r"\{(.*)\}")
_ASSIGN = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)\s*=\s*(.*)")
_CELL = re.compile(r"\s*('[^']*'|\"[^\"]*\"|[^\s'\"]+)")


@dataclasses.dataclass(frozen=True)
class TeimLine:
    """One line that is not blank or a comment: `kind` (``section``, ``subsection``,
    ``header``, ``assign``, ``row`` or ``other``), its 1-based `line`, `text` (stripped),
    `name` (a block's name upper-cased, or the assigned name as written), `raw` (the right-hand
    side of an assignment as written, comment included) and `cells` (a header's column names,
    a row's cells as written)."""

    kind: str
    line: int
    text: str
    name: str = ""
    raw: str = ""
    cells: tuple[str, ...] = ()


def _cells(text: str) -> tuple[str, ...] | None:
    """The blank-separated cells of `text` (quoted strings kept whole), or None where a cell is
    an unterminated quote."""
    cells, pos = [], 0
    while pos < len(text):
        c = _CELL.match(text, pos)
        if c is None:
            return None if text[pos:].strip() else tuple(cells)
        cells.append(c.group(1))
        pos = c.end()
    return tuple(cells)


def classify(text: str, line: int = 0) -> TeimLine:
    """The `TeimLine` of one stripped, non-comment line."""
    for kind, pattern in _BLOCKS:
        m = pattern.fullmatch(text)
        if m and _BLOCK_NAME.fullmatch(m.group(1).strip()):
            return TeimLine(kind, line, text, m.group(1).strip().upper())
    if m := _HEADER.fullmatch(text):
        return TeimLine("header", line, text, cells=tuple(m.group(1).split()))
    if m := _ASSIGN.fullmatch(text):
        return TeimLine("assign", line, text, m.group(1), m.group(2))
    cells = _cells(text)
    if cells:
        return TeimLine("row", line, text, cells=cells)
    return TeimLine("other", line, text)


def tokenise(text: str) -> Iterator[TeimLine]:
    """The lines of `text` that are neither blank nor comments, classified (`classify`)."""
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if stripped and stripped[0] not in COMMENT:
            yield classify(stripped, number)


def scalar(text: str) -> float | str:
    """A value or cell without its comment: a quoted string without its quotes, a number as a
    float (``D`` exponents read as ``E``; a number beyond float range is ±inf), or the text."""
    if len(text) >= 2 and text[0] == text[-1] and text[0] in "'\"":
        return text[1:-1]
    if NUMBER.fullmatch(text):
        return float(text.replace("d", "e").replace("D", "e"))
    return text


def split_value(raw: str, name: str) -> tuple[float | str, str, str]:
    """(value, text, comment) of the right-hand side `raw` of ``name = ...``: `value` from
    `scalar`, `text` the value as written (quotes kept), `comment` the text after ``$`` or
    ``!`` (stripped). Raises `ValueError` with the reason (an unterminated string, text after a
    quoted value that does not end with its quote, no value)."""
    raw = raw.strip()
    if raw[:1] in ("'", '"'):
        end = raw.find(raw[0], 1)
        if end < 0:
            raise ValueError(f"unterminated string for {name}")
        text, rest = raw[:end + 1], raw[end + 1:].strip()
        if rest and rest[0] not in COMMENT:
            if raw[-1] == raw[0]:  # the quote character inside the string: 'it's'
                return raw[1:-1], raw, ""
            raise ValueError(f"unexpected text {rest!r} after the value of {name}")
        return text[1:-1], text, rest[1:].strip()
    text, comment = raw, ""
    for mark in COMMENT:  # a `$` comment first: `X = ! $ note` is the value '!'
        if (pos := raw.find(mark)) >= 0:
            text, comment = raw[:pos].strip(), raw[pos + 1:].strip()
            break
    if not text:
        raise ValueError(f"no value for {name}")
    return scalar(text), text, comment
