"""A Chrono tabulated spring to Adams and back (an Adams spline spring).

Chrono's HMMWV rear double wishbone (tests/data/chrono/HMMWV_DoubleWishboneRear.json: a 21-point
'Spring Curve Data' and Minimum/Maximum Length stops) is read as a linear spring plus 30
one-sided stops; `write_adm` wrote nothing (ModelError: stops outside the .adm subset). Now each
stop is a two-body SFORCE of MAX(0, …) of DM(i, j) (exact for the piecewise-linear law), read
back as the same stop; the written-and-read model's equilibria equal the original's.
"""

from pathlib import Path

import numpy as np
import pytest

import diffsusp
from diffsusp.errors import ModelWarning
from diffsusp.io.adams import parse_adm, read_adm, stop_of_function, write_adm
from diffsusp.io.adams_write import stop_function
from diffsusp.io.chrono import read_chrono

HMMWV = Path(__file__).parent / "data" / "chrono" / "HMMWV_DoubleWishboneRear.json"


def _assert_same_equilibria(mech, back):
    """`back` (read back from a written file) has `mech`'s equilibria under the same loads:
    bump to 30 kN and a combined lateral case, at the contact patch (that the stops carry load
    there: tests/test_chrono_fidelity.py, the same loads)."""
    force = np.zeros((8, 3))
    force[:7, 2] = np.linspace(0.0, 30000.0, 7)
    force[7] = (0.0, 4000.0, 15000.0)
    sols = [diffsusp.solve_statics(m, m.loads(forces={"contact_patch": force}))
            for m in (mech, back)]
    for s in sols:
        assert np.all(np.asarray(s.status) == 0)
    qa, qb = (np.asarray(s.q).reshape(8, -1, 6) for s in sols)
    assert np.abs(qa[..., :3]).max() > 10.0                     # the wheel did move
    np.testing.assert_allclose(qb[..., :3], qa[..., :3], rtol=0, atol=1e-9)
    np.testing.assert_allclose(qb[..., 3:], qa[..., 3:], rtol=0, atol=1e-12)


def test_spring_curve_and_stops_round_trip_through_adm(tmp_path):
    """The 30 stops come back with the same kind, length, rate (to the bit: repr-exact numbers),
    on the same markers; the spring and all else as before; the equilibria under a 0–30 kN
    vertical contact load (rebound stops engaged at the low loads, knots crossed) and a lateral
    load agree to 1e-9 mm."""
    mech = read_chrono(HMMWV)
    st = mech.stops
    assert len(st.names) >= 20 and {"bump", "rebound"} <= set(st.kind)
    path = tmp_path / "hmmwv.adm"
    text = write_adm(mech, path)
    assert text.count("SFORCE/") == len(st.names) and "MAX(0, " in text
    back = read_adm(path)
    bs = back.stops
    assert bs.names == st.names and bs.kind == st.kind
    for field in ("length", "k", "cubic"):
        np.testing.assert_array_equal(np.asarray(getattr(bs, field)),
                                      np.asarray(getattr(st, field)), err_msg=field)
    names = mech.markers.names
    assert [back.markers.names[i] for i in bs.i_marker] == [names[i] for i in st.i_marker]
    assert [back.markers.names[j] for j in bs.j_marker] == [names[j] for j in st.j_marker]
    assert back.parts == mech.parts and back.springs.names == mech.springs.names
    np.testing.assert_allclose(np.asarray(back.springs.free_length),
                               np.asarray(mech.springs.free_length), rtol=1e-15)

    _assert_same_equilibria(mech, back)


def test_stop_function_grammar(tmp_path):
    """Bump and rebound, with and without a cubic term, any spacing and case; anything else is
    not a stop (and goes the old way: a constant SFORCE or a skipped statement)."""
    for kind in ("bump", "rebound"):
        for cubic in (0.0, 2.5e-3):
            f = stop_function(kind, 201.25, 1722.3015999999998, cubic, 17, 18)
            assert stop_of_function(f) == (kind, 201.25, 1722.3015999999998, cubic, 17, 18)
            assert stop_of_function(f.lower().replace(" ", "")) == stop_of_function(f)
    assert stop_of_function("1000 * MAX(0, DM(1, 2) - 300)") is None   # a bump's sign, wrong
    assert stop_of_function("1000 * MAX(0, 300 - DM(1, 2)) + 5") is None
    assert stop_of_function("-(10 * MAX(0, DM(1, 2) - 3) + 1 * MAX(0, DM(1, 3) - 3)**3)") is None
    # a stop SFORCE on markers it does not name is not read as a stop (an unsupported function)
    mech = read_chrono(HMMWV)
    text = write_adm(mech, None)
    line = next(ln for ln in text.splitlines() if ln.startswith("SFORCE/1,"))
    bad = text.replace(line, line.replace("DM(", "DM(9").replace(", 18)", ", 918)"))
    with pytest.warns(ModelWarning, match=r"skipped 1 statement.*SFORCE") as rec:
        model = parse_adm(bad)
    assert len(rec) == 1
    assert "spring_knot_1" not in model.build().stops.names


def test_cli_write_model_adm_of_a_chrono_corner(tmp_path):
    """`identify fit <Chrono .json> --measurements rig.csv --write-model x.adm` end to end (through
    the CLI): a travel-rig table of the HMMWV rear corner (toe and camber at
    ±40 mm, the corner's own curve to the rig's 0.0001° resolution), the spring rate the
    unknown (not seen by a travel table: the start is written). The written .adm holds the
    spline spring's 30 stops as SFORCEs, reads back, and its equilibria (the loads of the
    round-trip test above: its compiled program) equal the Chrono model's to 1e-9 mm."""
    from typer.testing import CliRunner

    import diffsusp.cli.identify  # noqa: F401  (registers `identify`)
    from diffsusp.cli import app
    from diffsusp.measure.rig import write_rig_table

    rig = tmp_path / "travel.csv"
    write_rig_table(rig, {"wheel_travel": np.array([-40.0, 0.0, 40.0])},
                    {"toe": np.array([-0.0567, 0.0, 0.0367]),
                     "camber": np.array([1.2230, 0.0, -1.5366])},
                    {"toe": 0.01, "camber": 0.01}, {"toe": "deg", "camber": "deg"})
    adm = tmp_path / "hmmwv.adm"
    r = CliRunner().invoke(app, ["identify", "fit", str(HMMWV), "-m", str(rig), "--springs",
                                 "--write-model", str(adm)])
    assert r.exit_code == 0, r.output
    text = " ".join(r.output.split())
    assert "consistent with the data" in text and "INCONSISTENT" not in text, text
    assert f"identified model written to {adm}" in text, text
    mech = read_chrono(HMMWV)
    written = adm.read_text()
    assert written.count("SFORCE/") == len(mech.stops.names) and "MAX(0, " in written
    back = read_adm(adm)
    assert back.stops.names == mech.stops.names and back.stops.kind == mech.stops.kind
    np.testing.assert_array_equal(np.asarray(back.stops.k), np.asarray(mech.stops.k))
    np.testing.assert_allclose(np.asarray(back.springs.k), np.asarray(mech.springs.k),
                               rtol=1e-15)
    _assert_same_equilibria(mech, back)
