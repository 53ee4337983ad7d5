"""Tables (diffsusp.io.tables): units, CSV and Parquet round trips, located errors, load-case
columns, and fuzzed input that must read or raise ModelFileError (with a line for CSV)."""

import importlib
import math
import re
from unittest import mock

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from diffsusp.errors import ModelFileError
from diffsusp.io import Table, loads_from_table, parse_unit, read_table, write_table
from diffsusp.io.tables import unit_factor
from diffsusp.model import MechanismBuilder

# ------------------------------------------------------------------------ units


@pytest.mark.parametrize("unit,dims,factor", [
    ("mm", (1, 0, 0), 1.0),
    ("m", (1, 0, 0), 1000.0),
    ("in", (1, 0, 0), 25.4),
    ("kN", (0, 1, 0), 1000.0),
    ("lbf", (0, 1, 0), 4.4482216152605),
    ("deg", (0, 0, 1), math.pi / 180),
    ("°", (0, 0, 1), math.pi / 180),
    ("N·mm", (1, 1, 0), 1.0),
    ("N*m", (1, 1, 0), 1000.0),
    ("N m", (1, 1, 0), 1000.0),
    ("N.m", (1, 1, 0), 1000.0),
    ("Nmm", (1, 1, 0), 1.0),
    ("kNm", (1, 1, 0), 1e6),
    ("kN·m", (1, 1, 0), 1e6),
    ("N/mm", (-1, 1, 0), 1.0),
    ("kN/m", (-1, 1, 0), 1.0),
    ("N·mm/deg", (1, 1, -1), 180 / math.pi),
    ("N/mm^3", (-3, 1, 0), 1.0),
    ("N/m³", (-3, 1, 0), 1e-9),
    ("1/mm", (-1, 0, 0), 1.0),
    ("-", (0, 0, 0), 1.0),
    (None, (0, 0, 0), 1.0),
])
def test_parse_unit(unit, dims, factor):
    got_dims, got_factor = parse_unit(unit)
    assert got_dims == dims
    assert got_factor == pytest.approx(factor, rel=1e-15)


@pytest.mark.parametrize("unit,message", [
    ("furlong", "unknown unit 'furlong'"),
    ("N/mm/s", "more than one '/'"),
    ("N/", "nothing after '/'"),
    ("mm^x", "cannot read 'mm^x'"),
])
def test_bad_units(unit, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        parse_unit(unit)


def test_unit_factor_checks_the_dimension():
    assert unit_factor("kN", "force") == 1000.0
    assert unit_factor(None, "moment") == 1.0
    with pytest.raises(ValueError, match="unit 'mm' is not a force unit"):
        unit_factor("mm", "force")


# ------------------------------------------------------------------------ round trips

AWKWARD = np.array([0.1, -0.0, 5e-324, 1.7976931348623157e308, np.nan, -np.inf, 1 / 3, 2.0**53,
                    -7.0])


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_write_read_is_exact(tmp_path, suffix):
    path = tmp_path / f"t{suffix}"
    columns = {"contact_patch.fz": AWKWARD, "lift, mm": np.arange(9.0), "plain": -AWKWARD}
    write_table(path, columns, {"contact_patch.fz": "kN", "lift, mm": "mm"})
    table = read_table(path)
    assert table.names == tuple(columns)
    assert table.units == {"contact_patch.fz": "kN", "lift, mm": "mm", "plain": None}
    for name, values in columns.items():
        got, want = table[name], np.asarray(values, dtype=np.float64)
        assert got.dtype == np.float64
        nan = np.isnan(want)  # NaN comes back as NaN (its sign and payload are not kept)
        assert np.array_equal(np.isnan(got), nan)
        assert got[~nan].tobytes() == want[~nan].tobytes()  # every other bit, -0.0 included
    if suffix == ".csv":
        header = path.read_text().splitlines()[0]
        assert header == 'contact_patch.fz [kN],"lift, mm [mm]",plain'
        assert table.lines == tuple(range(2, 11))


def test_csv_conventions(tmp_path):
    path = tmp_path / "loads.csv"
    path.write_bytes(
        "\ufeff# a K&C table\n\n fz [ N ] ,fy[kN],case\n"
        "# a comment row\n1500, -1.5 ,1\n1e3,nan,2\n".encode()
    )
    table = read_table(path)
    assert table.units == {"fz": "N", "fy": "kN", "case": None}
    np.testing.assert_array_equal(table["fz"], [1500.0, 1000.0])
    assert table.lines == (5, 6) and table.header_line == 3
    assert math.isnan(table["fy"][1])


CSV_ERRORS = [
    ("fz,fy\n1,2\n3,abc\n", 3, "fy", "'abc' in column 'fy' is not a number"),
    ("fz,fy\n1,2\n3\n", 3, None, "the row has 1 values but the header names 2 columns"),
    ("fz,fz\n1,2\n", 1, "fz", "column 'fz' appears twice"),
    ("fz,\n1,2\n", 1, None, "column 2 has no name"),
    ("fz [furlong]\n1\n", 1, "fz", "unknown unit 'furlong'"),
    ("fz,fy\n1,\n", 2, "fy", "empty cell in column 'fy'"),
    ("# only comments\n", 1, None, "the table is empty"),
    ('fz\n"1\n', 2, None, "not a valid CSV row"),
]


@pytest.mark.parametrize("text,line,field,message", CSV_ERRORS)
def test_csv_errors_name_the_line_and_column(tmp_path, text, line, field, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(ModelFileError) as info:
        read_table(path)
    e = info.value
    assert message in str(e)
    assert (e.line, e.field) == (line, field)
    assert str(e).startswith(f"{path}:{line}")


def test_parquet_errors(tmp_path):
    path = tmp_path / "bad.parquet"
    pq.write_table(pa.table({"fz": ["1", "2"]}), path)
    with pytest.raises(ModelFileError, match="column 'fz' holds string, not numbers"):
        read_table(path)
    pq.write_table(pa.table({"fz": pa.array([1.0, None, 3.0])}), path)
    with pytest.raises(ModelFileError, match="column 'fz' has no value in row 2"):
        read_table(path)
    # Units from field metadata, or from a bracketed name.
    schema = pa.schema([pa.field("fz", pa.float64(), metadata={"unit": "kN"}),
                        pa.field("fy [N]", pa.int64())])
    pq.write_table(pa.table({"fz": [1.5], "fy [N]": [2]}, schema=schema), path)
    table = read_table(path)
    assert table.units == {"fz": "kN", "fy": "N"}
    assert table["fy"].dtype == np.float64 and table["fy"][0] == 2.0
    path.write_bytes(b"PAR1 not really")
    with pytest.raises(ModelFileError, match="not a readable Parquet file") as info:
        read_table(path)
    assert info.value.line is None
    with pytest.raises(ModelFileError, match="unknown table format '.xlsx'"):
        read_table(tmp_path / "t.xlsx")
    with pytest.raises(FileNotFoundError):
        read_table(tmp_path / "missing.parquet")


# ------------------------------------------------------------------------ load cases


@pytest.fixture(scope="module")
def rig():
    """Two load points (one named contact_patch) and a driver."""
    b = MechanismBuilder("table rig")
    b.part("arm")
    b.bushing("bush", parts=("arm", "ground"), at=(0.0, 0.0, 0.0), k_trans=100.0, k_rot=1e6)
    b.load_point("tip", part="arm", at=(-300.0, 0.0, 0.0))
    b.load_point("contact_patch", part="arm", at=(0.0, 0.0, -300.0))
    b.driver("lift", part="arm", at=(0.0, 0.0, 0.0))
    return _unvalidated(b)


def _unvalidated(builder):
    """Build without the validation step (it traces a Jacobian per structure; only names and
    load points matter to these tests)."""
    builder_module = importlib.import_module("diffsusp.model.builder")
    with mock.patch.object(builder_module, "finalize", lambda mech, check=True: mech):
        return builder.build()


def _table(columns, units=None, lines=None):
    return Table(columns={k: np.asarray(v, dtype=float) for k, v in columns.items()},
                 units={k: (units or {}).get(k) for k in columns}, path="loads.csv",
                 lines=lines, header_line=1 if lines else None)


def test_loads_from_table_columns_and_units(rig):
    table = _table(
        {"case": [1, 2], "tip.fx": [0.1, 0.2], "tip.mz": [1.0, 2.0], "fz": [1500.0, 3000.0],
         "my": [5.0, 6.0], "lift": [0.01, -0.02]},
        units={"tip.fx": "kN", "tip.mz": "N·m", "lift": "m"},
    )
    loads = loads_from_table(rig, table)
    expected = rig.loads(
        forces={"tip": [[100.0, 0, 0], [200.0, 0, 0]],
                "contact_patch": [[0, 0, 1500.0], [0, 0, 3000.0]]},
        moments={"tip": [[0, 0, 1000.0], [0, 0, 2000.0]],
                 "contact_patch": [[0, 5.0, 0], [0, 6.0, 0]]},
        drivers={"lift": [10.0, -20.0]},
    )
    for got, want in ((loads.force, expected.force), (loads.moment, expected.moment),
                      (loads.driver, expected.driver)):
        np.testing.assert_allclose(got, want, rtol=1e-15, atol=0)
    assert loads.n_cases == 2


def test_loads_from_table_errors(rig):
    with pytest.raises(ModelFileError) as info:
        loads_from_table(rig, _table({"fz": [1.0], "tip.fq": [1.0], "wheel": [2.0]},
                                     lines=[2]))
    e = info.value
    assert "unknown columns 'tip.fq', 'wheel' for model 'table rig'" in str(e)
    assert "valid columns: tip.fx, tip.fy, tip.fz, tip.mx" in str(e)
    assert "lift, fx, fy, fz, mx, my, mz, case" in str(e)
    assert (e.line, e.field) == (1, "tip.fq")
    with pytest.raises(ModelFileError, match="column 'fz': unit 'mm' is not a force unit"):
        loads_from_table(rig, _table({"fz": [1.0]}, units={"fz": "mm"}))
    with pytest.raises(ModelFileError, match="columns 'fz' and 'contact_patch.fz' both give"):
        loads_from_table(rig, _table({"fz": [1.0], "contact_patch.fz": [2.0]}))
    with pytest.raises(ModelFileError) as info:
        loads_from_table(rig, _table({"fz": [1.0, np.nan]}, lines=[4, 7]))
    assert "column 'fz' has nan in row 2 (line 7)" in str(info.value)
    assert info.value.line == 7
    with pytest.raises(ModelFileError, match="the table has no rows"):
        loads_from_table(rig, _table({"fz": []}))


def test_shorthand_needs_one_load_point_or_a_contact_patch():
    b = MechanismBuilder("two points")
    b.part("arm")
    b.bushing("bush", parts=("arm", "ground"), at=(0.0, 0.0, 0.0), k_trans=1.0, k_rot=1.0)
    b.load_point("a", part="arm", at=(1.0, 0.0, 0.0))
    b.load_point("b", part="arm", at=(2.0, 0.0, 0.0))
    two = _unvalidated(b)
    with pytest.raises(ModelFileError, match="unknown column 'fz'.*valid columns: a.fx"):
        loads_from_table(two, _table({"fz": [1.0]}))
    one = MechanismBuilder("one point")
    one.part("arm")
    one.bushing("bush", parts=("arm", "ground"), at=(0.0, 0.0, 0.0), k_trans=1.0, k_rot=1.0)
    one.load_point("a", part="arm", at=(1.0, 0.0, 0.0))
    loads = loads_from_table(_unvalidated(one), _table({"fz": [3.0], "mx": [4.0]}))
    np.testing.assert_array_equal(loads.force, [[[0.0, 0.0, 3.0]]])
    np.testing.assert_array_equal(loads.moment, [[[4.0, 0.0, 0.0]]])


# ------------------------------------------------------------------------ fuzzing

VALID_CSV = "case,contact_patch.fz [N],contact_patch.fy [kN]\n1,1500,0\n2,3000,-1.5\n3,4500,2\n"
FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _reads_or_located_error(path, lines=True):
    try:
        table = read_table(path)
    except ModelFileError as e:
        if lines:
            assert e.line is not None and e.line >= 1, str(e)
        return None
    assert all(v.dtype == np.float64 and v.shape == (table.n_rows,)
               for v in table.columns.values())
    return table


@FUZZ
@given(data=st.binary(max_size=300))
def test_fuzz_csv_random_bytes(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("fuzz") / "t.csv"
    path.write_bytes(data)
    _reads_or_located_error(path)


@FUZZ
@given(edits=st.lists(st.tuples(st.integers(0, len(VALID_CSV)),
                                st.sampled_from(["", ",", "\n", '"', "x", "nan", "1e999", "[",
                                                 "]", "\x00", "\r", "#", "é", " "]),
                                st.integers(0, 3)), min_size=1, max_size=4))
def test_fuzz_csv_mutated_and_truncated(tmp_path_factory, edits):
    text = VALID_CSV
    for pos, insert, drop in edits:
        text = text[:pos] + insert + text[pos + drop:]
    path = tmp_path_factory.mktemp("fuzz") / "t.csv"
    path.write_text(text[: edits[0][0] + len(text) // 2], encoding="utf-8")
    _reads_or_located_error(path)


@pytest.fixture(scope="module")
def parquet_bytes(tmp_path_factory):
    path = tmp_path_factory.mktemp("pq") / "valid.parquet"
    write_table(path, {"contact_patch.fz": [1500.0, 3000.0], "wheel_travel": [0.0, 10.0]},
                {"contact_patch.fz": "N", "wheel_travel": "mm"})
    return path.read_bytes()


@settings(max_examples=100, deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_fuzz_parquet_mutated_truncated_random(tmp_path_factory, parquet_bytes, data):
    kind = data.draw(st.sampled_from(["random", "truncated", "mutated"]))
    if kind == "random":
        blob = data.draw(st.binary(max_size=300))
    elif kind == "truncated":
        blob = parquet_bytes[: data.draw(st.integers(0, len(parquet_bytes)))]
    else:
        blob = bytearray(parquet_bytes)
        for _ in range(data.draw(st.integers(1, 8))):
            blob[data.draw(st.integers(0, len(blob) - 1))] = data.draw(st.integers(0, 255))
        blob = bytes(blob)
    path = tmp_path_factory.mktemp("fuzz") / "t.parquet"
    path.write_bytes(blob)
    table = _reads_or_located_error(path, lines=False)
    if table is not None and kind == "truncated":
        assert len(blob) == len(parquet_bytes)  # only the whole file reads


def test_write_table_rejects_bad_names(tmp_path):
    with pytest.raises(ValueError, match="cannot hold a unit or a newline"):
        write_table(tmp_path / "t.csv", {"fz [N]": [1.0]})
    with pytest.raises(ValueError, match="one common length"):
        write_table(tmp_path / "t.csv", {"a": [1.0], "b": [1.0, 2.0]})
