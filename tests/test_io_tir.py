""".tir reader/writer (diffsusp.io.tir): every shipped file reads and writes back exactly; random
and mutated files raise the library's own error (property tests, like the other parsers)."""


import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from diffsusp.errors import ModelFileError
from diffsusp.io.tir import read_tir, tir_from_text, to_text
from diffsusp.tyre import MagicFormula6, examples

DATA = examples.DATA  # the example .tir files shipped in diffsusp/tyre/data
FILES = sorted(DATA.glob("*.tir"))
BASE = (DATA / "MagicFormula61_Paramerters.tir").read_text().splitlines()


@pytest.mark.parametrize("path", FILES, ids=[p.name for p in FILES])
def test_shipped_files_roundtrip(path):
    tir = read_tir(path)
    again = tir_from_text(to_text(tir))
    assert {k: e.value for k, e in tir.entries.items()} == \
        {k: e.value for k, e in again.entries.items()}
    assert to_text(tir).splitlines() == path.read_text().splitlines()
    assert tir.fittyp in (5, 6, 61, 62)
    assert tir["MASS"] == "kg"  # [UNITS] first; a later MASS is keyed SECTION.MASS
    if "INERTIA.MASS" in tir:
        assert isinstance(tir["INERTIA.MASS"], float)


def test_sections_comments_and_added_entries():
    tir = tir_from_text("$ header\n[MODEL]\nFITTYP = 61 $ version\n! note\n[LATERAL_COEFFICIENTS]\n"
                        "PCY1 = 1.3   $ shape\n[SHAPE]\n{radial width}\n 1.0 0.0\n 1.0 0.4\n")
    assert tir.section_of("PCY1") == "LATERAL_COEFFICIENTS"
    assert tir.entry("PCY1").comment == "shape" and tir.entry("PCY1").line == 6
    assert tir.tables["SHAPE"] == [(1.0, 0.0), (1.0, 0.4)]
    tir.set("PDY1", 0.1 + 0.2, section="LATERAL_COEFFICIENTS")
    tir.set("PCY1", 1.0 / 3.0)
    back = tir_from_text(to_text(tir))
    assert back["PDY1"] == 0.1 + 0.2 and back["PCY1"] == 1.0 / 3.0
    assert back.section_of("PDY1") == "LATERAL_COEFFICIENTS"
    with pytest.raises(ModelFileError, match="PCY1 defined twice in \\[LATERAL_COEFFICIENTS\\]"):
        tir_from_text("[LATERAL_COEFFICIENTS]\nPCY1 = 1\nPCY1 = 2\n")
    with pytest.raises(ModelFileError, match="outside any \\[SECTION\\]"):
        tir_from_text("PCY1 = 1\n")
    with pytest.raises(ModelFileError, match="unterminated string"):
        tir_from_text("[MODEL]\nTYRESIDE = 'LEFT\n")


def test_property_file_lines_are_read():
    """The line grammar shared with the Adams property files: a (SUBSECTION) line groups lines of
    its section, a section name may hold blanks, table rows take Fortran D exponents."""
    tir = tir_from_text("[MODEL]\n(VERSION)\nFITTYP = 61 ! MF 6.1\n[SHAPE]\n{radial width}\n"
                        " 1.0D0 0.0\n 1.0 4.0d-1\n[TYRE DATA]\nX = 'it's'\n")
    assert tir.section_of("FITTYP") == "MODEL" and tir.entry("FITTYP").comment == "MF 6.1"
    assert tir.tables["SHAPE"] == [(1.0, 0.0), (1.0, 0.4)]
    assert tir["X"] == "it's" and tir.section_of("X") == "TYRE DATA"
    assert to_text(tir).splitlines() == tir.lines  # written back as read


_FUZZ = settings(max_examples=120, deadline=None,
                 suppress_health_check=[HealthCheck.too_slow])


@_FUZZ
@given(st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=300))
def test_random_text_raises_library_error(text):
    try:
        tir_from_text(text, "fuzz.tir")
    except ModelFileError:
        pass


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(st.integers(0, len(BASE) - 1),
                          st.sampled_from(["drop", "dup", "garble", "value", "equals"]),
                          st.text(max_size=12)), min_size=1, max_size=4))
def test_mutated_file_raises_library_error(mutations):
    lines = list(BASE)
    for i, kind, junk in mutations:
        i = min(i, len(lines) - 1)
        if kind == "drop":
            del lines[i]
        elif kind == "dup":
            lines.insert(i, lines[i])
        elif kind == "garble":
            lines[i] = lines[i][: len(lines[i]) // 2] + junk
        elif kind == "value" and "=" in lines[i]:
            lines[i] = lines[i].split("=")[0] + "= " + junk
        elif kind == "equals":
            lines[i] = lines[i].replace("=", junk, 1)
        if not lines:
            lines = [""]
    try:
        tir = tir_from_text("\n".join(lines), "fuzz.tir")
        MagicFormula6.from_tir(tir)
    except ModelFileError:
        pass
