"""IGES reader (spec geometry §3.6, Annex B; CORRECTIONS 12): the thesis's sample file (repaired:
the spaces the text extraction put inside numbers and Hollerith strings deleted, records
re-padded to 80 columns), the reference numbers, transformations, units, bad files, and
fuzzing (random and mutated files raise ModelFileError or parse, nothing else)."""

import pathlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from diffsusp.errors import ModelFileError
from diffsusp.io.iges import IgesFile, read_iges

SAMPLE = pathlib.Path(__file__).parent / "data" / "annex_b.igs"
SAMPLE_TEXT = SAMPLE.read_text()


def test_annex_b_sample():
    f = read_iges(SAMPLE)
    assert [p.name for p in f.points] == ["Pt1", "Pt2"]
    np.testing.assert_array_equal(
        f.point("Pt1"), [17.7197143876002, -160.229593209037, -6.73288989141572])
    np.testing.assert_array_equal(
        f.point("Pt2"), [5.67953099641249, -142.756332361762, -9.80731721289495])
    (line,) = f.lines
    assert line.name == "Dr1"
    np.testing.assert_allclose(line.direction, [0.0, 0.99999835, -0.00181751], atol=5e-9)
    assert abs(line.direction[0]) < 1e-15
    np.testing.assert_allclose(line.length, 358.268, atol=5e-4)
    (plane,) = f.planes
    np.testing.assert_allclose(plane.normal, [0, 0, 1], atol=1e-16)
    np.testing.assert_allclose(plane.offset, -2.97322844289585, rtol=1e-15)
    # 2 spheres (158) and the arc (100) listed with the line of their D record; the matrix
    # (124) is a transformation, used by reference, not listed.
    assert f.skipped == ((158, 12), (158, 14), (100, 22))
    assert f.units == "MM" and f.scale == 1.0
    with pytest.raises(KeyError, match="Pt1, Pt2"):
        f.point("Pt3")


def test_sources_text_bytes_path():
    for source in (SAMPLE, str(SAMPLE), SAMPLE_TEXT, SAMPLE_TEXT.encode()):
        assert isinstance(read_iges(source), IgesFile)


def _with_transform_and_inches(text):
    """Point Pt1 mapped through the file's 124 matrix, and the file in inches."""
    lines = text.splitlines()
    lines = [ln[:48] + "      21" + ln[56:] if ln.startswith("     116       1") else ln
             for ln in lines]
    lines = [ln.replace("1.00,2,2HMM,", "1.00,1,2HIN,") for ln in lines]
    return "\n".join(lines) + "\n"


def test_transformation_and_units():
    f = read_iges(_with_transform_and_inches(SAMPLE_TEXT))
    m = np.array([0.000, 0.999999015908317, -1.40291924093015e-03, 0.000,
                  -0.999999735142205, -1.02106648237988e-06, -7.27814864724409e-04, 0.0,
                  -7.27815580961669e-04, 1.40291886935605e-03, 0.999998751050783, 0.000])
    m = m.reshape(3, 4)
    p = np.array([17.7197143876002, -160.229593209037, -6.73288989141572])
    np.testing.assert_allclose(f.point("Pt1"), 25.4 * (m[:, :3] @ p + m[:, 3]), rtol=1e-14)
    np.testing.assert_allclose(f.point("Pt2"), 25.4 * np.array(
        [5.67953099641249, -142.756332361762, -9.80731721289495]), rtol=1e-14)
    assert f.scale == 25.4


@pytest.mark.parametrize("edit, line, match", [
    (lambda t: t.replace("-6.73288989141572", "-6.7328x989141572"), 24, "must be a number"),
    (lambda t: t.replace("     116       1       0", "     116      99       0"), 8,
     "parameter record 99"),
    (lambda t: t.replace("            1P      1", "            1Q      1"), 24,
     "column 73"),
    (lambda t: t.replace("S      2\n", "S     \n"), 2, "sequence number"),
    (lambda t: t.replace("116,17.7197143876002,-160.229593209037,-6.73288989141572,0;",
                         "116,17.7197143876002;".ljust(59)), 24, "needs 3 parameters"),
    (lambda t: t.replace("     116       1       0       0       0       0       0",
                         "     116       1       0       0       0       0       9"), 8,
     "transformation 9"),
    (lambda t: t.replace("1.00,2,2HMM,", "1.00,3,2HZZ,"), 4, "unknown unit name"),
    (lambda t: "\n".join(ln for ln in t.splitlines() if ln[72] != "D"), None, "no directory"),
    (lambda t: t.replace("\n", "xx\n", 1), 1, "80 columns"),
])
def test_bad_files(edit, line, match):
    with pytest.raises(ModelFileError, match=match) as info:
        read_iges(edit(SAMPLE_TEXT))
    assert info.value.line == line


def test_missing_file(tmp_path):
    with pytest.raises(ModelFileError, match="cannot read"):
        read_iges(tmp_path / "missing.igs")


def _parses_or_file_error(text):
    try:
        return read_iges(text)
    except ModelFileError as exc:
        assert str(exc)
        return None


_FUZZ = settings(max_examples=150, deadline=None, derandomize=True)


@_FUZZ
@given(data=st.binary(max_size=400))
def test_fuzz_random_bytes(data):
    _parses_or_file_error(data + b"\n")


@_FUZZ
@given(data=st.data())
def test_fuzz_truncated_and_mutated(data):
    text = SAMPLE_TEXT[: data.draw(st.integers(1, len(SAMPLE_TEXT)))]
    for _ in range(data.draw(st.integers(0, 4))):
        at = data.draw(st.integers(0, len(text)))
        length = data.draw(st.integers(0, 8))
        insert = data.draw(st.sampled_from(
            ["", ",", ";", "H", "9H", "1H", "D", "P", "E", "1e999", "nan", "-", "\x00", "é",
             " " * 8, "       1", "\n", "99999999", "124", "116", "0"]))
        text = text[:at] + insert + text[at + length:]
    f = _parses_or_file_error(text + "\n")
    if f is not None:
        for p in f.points:
            assert np.all(np.isfinite(p.position))
        for ln in f.lines:
            assert np.isfinite(ln.length) and ln.length > 0
