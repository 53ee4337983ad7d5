"""Tyre property files (`.tir`, MF-Tyre / Adams / Chrono / MFeval format), read and written.

spec: tyre §7 C (MF 5.2 / 6.1 / 6.2 property files).

A `.tir` file is a list of sections (`[LATERAL_COEFFICIENTS]`), each holding `NAME = value`
lines; `$` starts a comment (at the start of a line or after a value), `!` a comment line; a few
sections hold tables (`[SHAPE]`: a `{radial width}` header and rows of numbers). Values are
numbers or quoted strings. The line grammar is `io.teimorbit`'s, shared with the Adams property
files (a `(SUBSECTION)` line is read as part of its section).

The file's own units are kept: a `TirFile` is **SI as written** (m, N, rad, Pa, m/s; the
`[UNITS]` section must say so), so writing it back reproduces every value exactly (numbers are
kept as the text that was read and written with `repr` when changed). The conversion to the
library's units (mm, N, N·mm, rad) happens when a model is built from the file
(`diffsusp.tyre.MagicFormula6.from_tir`) and back when a model is written
(`MagicFormula6.to_tir`).

```python
tir = read_tir("front.tir")
tir["PCY1"], tir.section_of("PCY1"), tir.fittyp
tir.set("PCY1", 1.45); write_tir(tir, "fitted.tir")
```
Errors (`ModelFileError`, an `InputError`) name the file, the line and the field.
"""

import dataclasses
import os

from ..errors import ModelFileError
from .files import read_input, write_text_atomic
from .teimorbit import NUMBER, classify, scalar, split_value, tokenise

__all__ = ["TirEntry", "TirFile", "read_tir", "write_tir", "tir_from_text"]

SI_UNITS = {"LENGTH": ("meter", "metre", "m"), "FORCE": ("newton", "n"),
            "ANGLE": ("radians", "radian", "rad"), "MASS": ("kg", "kilogram"),
            "TIME": ("second", "s", "sec")}


@dataclasses.dataclass
class TirEntry:
    """One `NAME = value $comment` line: `value` is a float or a str (quotes removed), `text` the
    value as written (kept so that an unchanged value is written back byte for byte), `line`
    1-based (None for an entry added by `set`)."""

    name: str
    value: float | str
    text: str
    comment: str
    section: str
    line: int | None


@dataclasses.dataclass
class TirFile:
    """A parsed `.tir` file, in the file's own (SI) units.

    **Fields:** `entries` (name → `TirEntry`, names upper-case; a name repeated in a later
    section, like MASS in [UNITS] and [INERTIA], is keyed `SECTION.NAME`),
    `sections` (section name → tuple of entry names, file order), `lines` (the original text
    lines, without line ends), `path` (or None), `tables` (section → rows of floats, e.g.
    `[SHAPE]`).
    """

    entries: dict[str, TirEntry]
    sections: dict[str, list[str]]
    lines: list[str]
    path: str | None = None
    tables: dict[str, list[tuple[float, ...]]] = dataclasses.field(default_factory=dict)

    def __contains__(self, name: str) -> bool:
        return name.upper() in self.entries

    def __getitem__(self, name: str) -> float | str:
        return self.entry(name).value

    def entry(self, name: str) -> TirEntry:
        try:
            return self.entries[name.upper()]
        except KeyError:
            raise ModelFileError(f"no {name.upper()} in the file", path=self.path,
                                 field=name.upper()) from None

    def section_of(self, name: str) -> str:
        return self.entry(name).section

    def get(self, name: str, default=None):
        e = self.entries.get(name.upper())
        return default if e is None else e.value

    def number(self, name: str, *, section: str | None = None, default: float | None = None
               ) -> float:
        """The value of `name` as a float. A missing entry is `default` when one is given, else an
        error naming the section where it belongs; a non-numeric one is always an error."""
        e = self.entries.get(name.upper())
        if e is None:
            if default is not None:
                return float(default)
            where = f" in [{section}]" if section else ""
            raise ModelFileError(f"missing coefficient {name.upper()}{where}; add the line "
                                 f"'{name.upper()} = <value>' to that section", path=self.path,
                                 field=name.upper())
        if not isinstance(e.value, float):
            raise ModelFileError(f"{name.upper()} in [{e.section}] must be a number, got "
                                 f"{e.text!r}", path=self.path, line=e.line, field=name.upper())
        return e.value

    @property
    def fittyp(self) -> int:
        """The `[MODEL] FITTYP` (Magic Formula version: 5/6 = MF 5.x, 61 = 6.1, 62 = 6.2)."""
        v = self.number("FITTYP", section="MODEL")
        if v != int(v):
            e = self.entry("FITTYP")
            raise ModelFileError(f"FITTYP must be an integer, got {e.text}", path=self.path,
                                 line=e.line, field="FITTYP")
        return int(v)

    def set(self, name: str, value: float | str, *, section: str | None = None,
            comment: str = "") -> None:
        """Set (or add, in `section`) one entry; a float is written with `repr` (exact)."""
        key = name.upper()
        text = repr(float(value)) if not isinstance(value, str) else f"'{value}'"
        val = float(value) if not isinstance(value, str) else value
        if key in self.entries:
            e = self.entries[key]
            e.value, e.text = val, text
            return
        if section is None:
            raise ModelFileError(f"{key} is not in the file: give the section to add it to",
                                 path=self.path, field=key)
        sec = section.upper()
        self.sections.setdefault(sec, [])
        self.sections[sec].append(key)
        self.entries[key] = TirEntry(key, val, text, comment, sec, None)

    def check_units(self) -> None:
        """Raise unless `[UNITS]` is absent or SI (meter, newton, radians, kg, second)."""
        for key, allowed in SI_UNITS.items():
            e = next((self.entries[k] for k in self.sections.get("UNITS", ())
                      if self.entries[k].name == key), None)
            if e is None:
                continue
            if str(e.value).strip().lower() not in allowed:
                v = e.value
                raise ModelFileError(f"[UNITS] {key} = {v!r} is not supported: diffsusp reads "
                                     f".tir files in SI ({allowed[0]})", path=self.path,
                                     line=e.line, field=key)

    def copy(self) -> "TirFile":
        return TirFile({k: dataclasses.replace(e) for k, e in self.entries.items()},
                       {k: list(v) for k, v in self.sections.items()}, list(self.lines),
                       self.path, {k: list(v) for k, v in self.tables.items()})


def tir_from_text(text: str, path: str | None = None) -> TirFile:
    """Parse the text of a `.tir` file (see the module docstring)."""
    if not isinstance(text, str):
        raise ModelFileError("a .tir file must be text", path=path)
    lines = text.splitlines()
    entries: dict[str, TirEntry] = {}
    sections: dict[str, list[str]] = {}
    tables: dict[str, list[tuple[float, ...]]] = {}
    section = None
    for t in tokenise(text):
        i = t.line
        if t.kind == "section":
            section = t.name
            sections.setdefault(section, [])
            continue
        if t.kind == "subsection" and section is not None:
            continue  # a (SUBSECTION) groups lines of its [SECTION]; entries stay in it
        if t.text.startswith("["):
            raise ModelFileError(f"malformed section header {t.text!r}", path=path, line=i)
        if t.kind == "assign":
            if section is None:
                raise ModelFileError(f"{t.name} is outside any [SECTION]", path=path,
                                     line=i, field=t.name)
            name = t.name.upper()
            try:
                value, vtext, comment = split_value(t.raw, name)
            except ValueError as exc:
                raise ModelFileError(str(exc), path=path, line=i, field=name) from None
            key = name
            if name in entries:
                # the same name in [UNITS] and another section (MASS in [UNITS] and [INERTIA])
                # is kept under SECTION.NAME; twice in one section is an error, and so is a
                # coefficient in two sections (a stray PCY1 in [LONGITUDINAL_COEFFICIENTS]
                # would silently replace the lateral one)
                first = entries[name]
                key = f"{section}.{name}"
                if first.section == section or key in entries:
                    raise ModelFileError(f"{name} defined twice in [{section}]", path=path,
                                         line=i, field=name)
                if "UNITS" not in (first.section, section):
                    raise ModelFileError(
                        f"{name} is defined in [{first.section}] (line {first.line}) and again "
                        f"in [{section}]; keep it in the section where it belongs only",
                        path=path, line=i, field=name)
            entries[key] = TirEntry(name, value, vtext, comment, section, i)
            sections[section].append(key)
            continue
        if section is not None and t.kind == "header":
            tables.setdefault(section, [])
            continue
        if (section is not None and t.kind == "row"
                and all(NUMBER.fullmatch(c) for c in t.cells)):
            tables.setdefault(section, []).append(tuple(scalar(c) for c in t.cells))
            continue
        raise ModelFileError(f"cannot read {t.text[:60]!r}: expected '[SECTION]', "
                             "'NAME = value', a comment ($ or !) or a table row", path=path,
                             line=i)
    if not entries:
        raise ModelFileError("no 'NAME = value' line: not a .tir file", path=path)
    tir = TirFile(entries, sections, lines, path, tables)
    tir.check_units()
    check_values(tir)
    return tir


POSITIVE = ("FNOMIN", "UNLOADED_RADIUS", "LONGVL", "WIDTH", "RIM_RADIUS",
            "VERTICAL_STIFFNESS")
"""Quantities that must be > 0 when present (a zero or negative FNOMIN, radius or reference
speed divides the Magic Formula by zero or flips its signs)."""
NON_NEGATIVE = ("NOMPRES", "INFLPRES", "PRESMIN", "PRESMAX", "FZMIN", "FZMAX")
"""Quantities that must be >= 0 when present (0 is written by some exporters for "none")."""


def check_values(tir: TirFile) -> None:
    """Every number finite (a value beyond float range, `1e400` or 400 digits, reads as inf),
    `POSITIVE` ones > 0 and `NON_NEGATIVE` ones >= 0; an error naming the key and its line.

    spec: tyre §7 C (the property file's quantities)."""
    for e in tir.entries.values():
        if not isinstance(e.value, float):
            continue
        if e.value != e.value or e.value in (float("inf"), float("-inf")):
            shown = e.text if len(e.text) <= 30 else e.text[:27] + "..."
            raise ModelFileError(f"{e.name} = {shown} is not a finite number (beyond the "
                                 "range of a float64)", path=tir.path, line=e.line,
                                 field=e.name)
        if e.section == "UNITS":
            continue
        if e.name in POSITIVE and not e.value > 0:
            raise ModelFileError(f"{e.name} = {e.text} must be > 0", path=tir.path,
                                 line=e.line, field=e.name)
        if e.name in NON_NEGATIVE and e.value < 0:
            raise ModelFileError(f"{e.name} = {e.text} must be >= 0", path=tir.path,
                                 line=e.line, field=e.name)


def read_tir(path: str | os.PathLike) -> TirFile:
    """Read a `.tir` file (any line ends; Latin-1 tolerated). See the module docstring."""
    path = os.fspath(path)
    try:
        # A regular file within the size limit (a device, a FIFO or an endless file is refused
        # before it is read: `io.files`).
        data = read_input(path, "tyre property file")
    except FileNotFoundError as exc:
        raise ModelFileError(f"cannot read the file: {exc.strerror}", path=path) from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    return tir_from_text(text, path)


def _format_line(e: TirEntry) -> str:
    line = f"{e.name:<26}= {e.text:<22}"
    if e.comment:
        line += f" ${e.comment}"
    return line.rstrip()


def to_text(tir: TirFile) -> str:
    """The file's text: original lines kept, changed entries rewritten, added ones appended at
    the end of their section (a new section at the end of the file)."""
    out = list(tir.lines)
    for e in tir.entries.values():
        if e.line is not None:
            old = classify(out[e.line - 1].strip())
            old = split_value(old.raw, e.name)[1] if old.kind == "assign" else None
            if old != e.text:
                out[e.line - 1] = _format_line(e)
    added: dict[str, list[str]] = {}
    for e in tir.entries.values():
        if e.line is None:
            added.setdefault(e.section, []).append(_format_line(e))
    if added:
        # the last line of each existing section
        section_end: dict[str, int] = {}
        current = None
        for i, line in enumerate(out):
            head = classify(line.strip())
            if head.kind == "section":
                current = head.name
            if current is not None and line.strip() and not line.strip().startswith("$"):
                section_end[current] = i
        for sec in sorted((s for s in added if s in section_end),
                          key=lambda s: -section_end[s]):
            pos = section_end[sec] + 1
            out[pos:pos] = added[sec]
        for sec in (s for s in added if s not in section_end):
            out += [f"[{sec}]"] + added[sec]
    return "\n".join(out) + "\n"


def write_tir(tir: TirFile, path: str | os.PathLike, *, header: str | None = None) -> None:
    """Write `tir` (SI, as read; changed values with `repr`, so write → read is exact);
    `header` (comment lines starting with `$`, ending with a newline) goes before the first
    line, e.g. to mark a fit that did not converge."""
    # through a temporary file renamed at the end: an interrupted write leaves no half file
    write_text_atomic(os.fspath(path), to_text(tir) if header is None else header + to_text(tir))
