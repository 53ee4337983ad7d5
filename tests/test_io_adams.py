"""Adams files (diffsusp.io.adams, diffsusp.io.expr): the spec's Annex F dataset
`model_exemple11` against the same model built by hand and the NumPy oracle, the Annex H load-case
file, the Annex I bushing splines (spec stiffness §7 R9), write/read round trips, reports of
statements outside the subset, errors with line numbers, and fuzzing of every parser.

Only three model structures are compiled here (the Annex F model, and the all-elements model of
the writer round trip); every other model reuses one of them or is never built.
"""

import dataclasses
import math
import re
import warnings
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import oracle
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import diffsusp
from diffsusp import MechanismBuilder
from diffsusp.errors import ModelError, ModelFileError, ModelWarning
from diffsusp.io.adams import (
    AdmModel,
    LoadCaseTable,
    parse_adm,
    parse_teimorbit,
    read_adm,
    read_bushing_property,
    read_lcf,
    spline_stiffness,
    write_adm,
    write_bushing_property,
    write_lcf,
)
from diffsusp.io.expr import (
    MAX_DEPTH,
    ExpressionError,
    distance_constraint,
    evaluate_text,
    parse_expression,
)
from diffsusp.models import isolated_bushing

DATA = Path(__file__).parent / "data"
EXAMPLE = DATA / "model_exemple11.adm"
EXAMPLE_TEXT = EXAMPLE.read_text()
LCF = DATA / "annex_h.lcf"
SPLINES = DATA / "annex_i_splines.adm"
BUS = DATA / "bushing_A.bus"
DEG = math.pi / 180.0
PHASES = np.array([0.0, 0.15, 0.3, 0.45, 0.55, 0.65])  # FX … TZ of GFORCE_1 (spec §4.1)
TIMES = np.array([0.0, 0.25, 0.5, 0.75, 1.0, 1.5])


@pytest.fixture(scope="module")
def example():
    model = parse_adm(EXAMPLE)
    return model, model.build()


def assert_same_mechanism(a, b, atol=0.0):
    """Same topology, names and static data; parameter arrays equal (to `atol`)."""
    assert a.parts == b.parts and a.independent_rows == b.independent_rows
    assert a.length_scale == pytest.approx(b.length_scale, abs=atol)
    np.testing.assert_allclose(a.reference_points, b.reference_points, rtol=0, atol=atol)
    for field in ("markers", "joints", "bushings", "springs", "stops", "drivers", "load_points"):
        ea, eb = getattr(a, field), getattr(b, field)
        assert jax.tree_util.tree_structure(ea) == jax.tree_util.tree_structure(eb), field
        for x, y in zip(jax.tree_util.tree_leaves(ea), jax.tree_util.tree_leaves(eb),
                        strict=True):
            np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=0, atol=atol,
                                       err_msg=field)


# ----------------------------------------------------------------------------- Annex F (.adm)


def test_parse_model_exemple11(example):
    """Every statement of the spec's example: title, units, names from adams_view_name, the
    continuation lines of BUSHING/1, the backslash-terminated GFORCE expressions, the commented-out
    JOINT/1 (inactive), the statements without static effect."""
    model, _ = example
    assert model.title == "ADAMS/View model name: model_exemple11"
    assert model.units == {"FORCE": "NEWTON", "MASS": "KILOGRAM", "LENGTH": "MILLIMETER",
                           "TIME": "SECOND"}
    assert (model.length_to_mm, model.force_to_n) == (1.0, 1.0)
    assert [s.label for s in model.statements][-2:] == ["BUSHING/1 'BUSHING_1'",
                                                        "GFORCE/1 'GFORCE_1'"]
    assert model.names[("MARKER", 9)] == "cm"
    assert [(s.keyword, s.id, s.line) for s in model.ignored] == [
        ("GRAPHICS", 2, 35), ("GRAPHICS", 3, 37), ("OUTPUT", None, 55), ("RESULTS", None, 56)]
    assert model.inactive == [(40, "JOINT/1, CYLINDRICAL, I = 3, J = 4")]
    assert model.skipped == []
    bushing = model.statements[-2]
    assert (bushing.line, bushing.end_line) == (43, 45)
    assert [v.text for v in bushing.arguments["KT"].values] == ["5.729577951E+005"] * 3
    assert [v.line for v in bushing.arguments["CT"].values] == [43, 43, 44]
    gforce = model.statements[-1]
    assert gforce.arguments["FY"].expression == "1000*sin(pi*(time+0.15))"
    assert gforce.arguments["TZ"].expression == "1000*sin(pi*(time+0.65))"


def test_model_exemple11_is_the_model_built_by_hand(example):
    """The dataset gives exactly the mechanism written with MechanismBuilder from the listing:
    PART/2 on the ground through BUSHING/1 (I = MARKER/7 on the part, J = MARKER/8 on the ground,
    K = 100 N/mm, KT = 5.729577951e5 N·mm/rad), GFORCE/1 on MARKER/12 with components in the
    axes of MARKER/13; the floating MARKER/14 carries no pose."""
    _, mech = example
    reuler = (28.18678543, 33.2259422, 350.8538915)
    b = MechanismBuilder("model_exemple11")
    b.part("PART_2")
    b.marker("MARKER_3", "ground", (0, 0, 0))
    b.marker("MARKER_8", "ground", (0, 0, 0), reuler_deg=reuler)
    b.marker("MARKER_13", "ground", (-300, 0, 0))
    b.marker("MARKER_1", "PART_2", (0, 0, 0), reuler_deg=(180, 0, 0))
    b.marker("MARKER_2", "PART_2", (-300, 3.673819061e-14, 0), reuler_deg=(180, 0, 0))
    b.marker("MARKER_4", "PART_2", (0, 0, 0))
    b.marker("MARKER_7", "PART_2", (0, 0, 0), reuler_deg=reuler)
    b.marker("cm", "PART_2", (-150, 1.859948827e-14, 0))
    b.marker("MARKER_11", "PART_2", (0, 0, 0))
    b.marker("MARKER_12", "PART_2", (-300, 0, 0))
    b.bushing("BUSHING_1", "MARKER_7", "MARKER_8", k_trans=100.0, k_rot=5.729577951e5)
    b.load_point("GFORCE_1", "MARKER_12", frame="MARKER_13")
    hand = b.build()
    assert mech.name == "model_exemple11"
    assert_same_mechanism(mech, hand, atol=1e-13)
    # KT = 5.729577951e5 N·mm/rad is 10 000 N·mm/deg (spec §7 R9).
    np.testing.assert_allclose(np.asarray(mech.bushings.k_rot) * DEG, 10000.0, rtol=1e-9)


def test_gforce_at_several_times_matches_the_hand_built_model(example):
    """GFORCE/1 evaluated at several times (FX = 1000 sin(π t), ..., TZ = 1000 sin(π(t + 0.65)),
    N and N·mm): the file's loads are those sinusoids; the static solutions of the imported
    model (diffsusp) equal those of `diffsusp.models.isolated_bushing` (built by hand from the
    same listing) solved by the independent NumPy oracle, to 1e-9."""
    model, mech = example
    loads = model.loads(mech, TIMES)
    expected = 1000.0 * np.sin(np.pi * (TIMES[:, None] + PHASES[None, :]))
    np.testing.assert_allclose(loads.force[:, 0], expected[:, :3], rtol=0, atol=1e-9)
    np.testing.assert_allclose(loads.moment[:, 0], expected[:, 3:], rtol=0, atol=1e-9)
    single = model.loads(mech, 0.25)
    np.testing.assert_allclose(single.force[0], expected[1, :3], atol=1e-9)
    sol = diffsusp.solve_statics(mech, loads)
    assert bool(jnp.all(sol.converged))
    hand = isolated_bushing()  # arm on the ground through bushing 'bush', load point 'tip'
    k = hand.load_points.index("tip")
    for case in range(TIMES.size):
        force, moment = np.zeros((2, 3)), np.zeros((2, 3))
        force[k], moment[k] = expected[case, :3], expected[case, 3:]
        ref = oracle.solve(hand, force, moment, np.zeros(0))
        np.testing.assert_allclose(sol.q[case], ref.q(), rtol=0, atol=1e-9)
    # The bushing turns by up to ~42° about its z axis: a real, large-rotation test.
    _, angles, _, _ = diffsusp.bushing_states(mech, sol.q)
    assert np.max(np.abs(np.asarray(angles))) > np.radians(30.0)


def test_units_are_converted(example):
    """The same model written in metres and kilonewtons reads to the same mechanism and loads
    (K kN/m → N/mm, KT kN·m/rad → N·mm/rad, QP m → mm, GFORCE kN and kN·m)."""
    model, mech = example
    text = EXAMPLE_TEXT.replace("FORCE = NEWTON", "FORCE = KILONEWTON").replace(
        "LENGTH = MILLIMETER", "LENGTH = METER")
    text = text.replace("QP = -300,", "QP = -0.3,").replace("QP = -150,", "QP = -0.15,")
    text = text.replace("3.673819061E-014", "3.673819061E-017").replace(
        "1.859948827E-014", "1.859948827E-017")
    text = text.replace("K = 100, 100, 100", "K = 100, 100, 100").replace(
        "5.729577951E+005", "0.5729577951")
    for comp in ("FX", "FY", "FZ"):
        text = re.sub(rf"{comp} = 1000\*", f"{comp} = 1*", text)
    for comp in ("TX", "TY", "TZ"):
        text = re.sub(rf"{comp} = 1000\*", f"{comp} = 0.001*", text)
    metric = parse_adm(text)
    assert (metric.length_to_mm, metric.force_to_n) == (1000.0, 1000.0)
    built = metric.build()
    assert_same_mechanism(built, mech, atol=1e-9)
    a, b = metric.loads(built, TIMES), model.loads(mech, TIMES)
    np.testing.assert_allclose(a.force, b.force, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(a.moment, b.moment, rtol=1e-12, atol=1e-9)


def test_write_read_round_trip_of_the_example(example, tmp_path):
    """write_adm (no template) then read_adm gives the same mechanism."""
    _, mech = example
    path = tmp_path / "out.adm"
    text = write_adm(mech, path)
    assert path.read_text() == text
    assert_same_mechanism(read_adm(path), mech, atol=1e-12)


def test_template_write_updates_only_the_stiffnesses(example, tmp_path):
    """With the original dataset as template, only the BUSHING's K and KT values change (the
    thesis's workflow of writing identified stiffnesses back); reading gives them back."""
    _, mech = example
    new_k, new_kt = np.array([10000.0, 12000.0, 9000.0]), np.array([4000.0, 5000.0, 6000.0])
    changed = eqx.tree_at(lambda m: (m.bushings.k_trans, m.bushings.k_rot), mech,
                          (jnp.asarray([new_k]), jnp.asarray([new_kt / DEG])))
    path = tmp_path / "identified.adm"
    write_adm(changed, path, template=EXAMPLE)
    old_lines, new_lines = EXAMPLE_TEXT.splitlines(), path.read_text().splitlines()
    assert len(old_lines) == len(new_lines)
    assert [k + 1 for k, (a, b) in enumerate(zip(old_lines, new_lines, strict=True))
            if a != b] == [43, 44, 45]
    assert new_lines[42].startswith("BUSHING/1, I = 7, J = 8, K = 10000.0, 12000.0, 9000.0, CT =")
    back = read_adm(path)
    np.testing.assert_allclose(back.bushings.k_trans, [new_k], rtol=1e-15)
    np.testing.assert_allclose(np.asarray(back.bushings.k_rot) * DEG, [new_kt], rtol=1e-14)
    assert_same_mechanism(
        eqx.tree_at(lambda m: (m.bushings.k_trans, m.bushings.k_rot), back,
                    (mech.bushings.k_trans, mech.bushings.k_rot)), mech, atol=1e-13)


# ----------------------------------------------------------------------------- Annex I (splines)


def test_annex_i_spline_stiffnesses():
    """spec §7 R9: the A/Car spline block of Annex I gives 14052.5, 14615.8, 677.07 N/mm and
    10000, 5097.3, 4220.9 N·mm/deg (Y = −K·X, X of torques in rad)."""
    model = parse_adm(SPLINES)
    assert sorted(model.splines) == [7, 8, 9, 10, 11, 12]
    assert all(s.linear_extrapolate for s in model.splines.values())
    stiff = model.spline_stiffnesses("BM5_JM_ref_bgl_Bushing_A")
    trans = [stiff["tx"], stiff["ty"], stiff["tz"]]
    rot = np.array([stiff["rx"], stiff["ry"], stiff["rz"]]) * DEG
    np.testing.assert_allclose(trans, [14052.5, 14615.8, 677.07], rtol=0, atol=0.005)
    np.testing.assert_allclose(rot, [10000.0, 5097.3, 4220.9], atol=0.05)
    assert spline_stiffness(model.splines[7]) == pytest.approx(14052.5, rel=1e-6)


def test_annex_i_splines_rewritten_from_a_stiffness(example):
    """Writer rule of spec §4.3: for a new linear K, every Y of the bushing's splines becomes
    −K·X (torques: K in N·mm/rad against X in rad); X and everything else are kept."""
    _, mech = example
    bushings = dataclasses.replace(mech.bushings, names=("Bushing_A",),
                                   k_trans=jnp.asarray([[1000.0, 2000.0, 300.0]]),
                                   k_rot=jnp.asarray([[7000.0, 8000.0, 9000.0]]) / DEG)
    renamed = dataclasses.replace(mech, bushings=bushings)
    text = write_adm(renamed, None, template=SPLINES)
    model = parse_adm(text)
    stiff = model.spline_stiffnesses("BM5_JM_ref_bgl_Bushing_A")
    np.testing.assert_allclose([stiff[a] for a in ("tx", "ty", "tz")], [1000, 2000, 300])
    np.testing.assert_allclose([stiff[a] * DEG for a in ("rx", "ry", "rz")], [7000, 8000, 9000])
    np.testing.assert_array_equal(model.splines[10].x, parse_adm(SPLINES).splines[10].x)
    np.testing.assert_allclose(model.splines[7].y, [10000.0, 5000.0, 0.0, -5000.0, -10000.0])


# ----------------------------------------------------------------------------- all elements


def _all_elements_model():
    """A small model with every element kind the .adm subset expresses."""
    b = MechanismBuilder("all elements")
    for part in ("a", "b", "c", "d", "e"):
        b.part(part)
    rot = np.asarray(diffsusp.geometry.reuler_deg_to_matrix(jnp.asarray([30.0, 40.0, 50.0])))
    for k, part in enumerate(("a", "b", "c", "d", "e")):
        b.bushing(f"hold_{part}", parts=(part, "ground"), at=(100.0 * k, 10.0, 0.0),
                  orientation=rot, k_trans=(100.0 + k, 200.0, 300.0), k_rot=(1e5, 2e5, 3e5),
                  preload_force=(1.0, -2.0, 3.0) if k == 0 else 0.0,
                  preload_torque=(10.0, 0.0, -5.0) if k == 1 else 0.0)
    b.joint("sph", "spherical", parts=("a", "ground"), at=(0.0, 50.0, 0.0))
    b.joint("rev", "revolute", parts=("b", "ground"), at=(100.0, 50.0, 0.0), z=(0, 1, 1))
    b.joint("cyl", "cylindrical", parts=("c", "ground"), at=(200.0, 50.0, 0.0), z=(1, 0, 0))
    b.joint("fix", "fixed", parts=("d", "c"), at=(250.0, 0.0, 0.0), orientation=rot)
    b.joint("trans", "translational", parts=("e", "ground"), at=(400.0, 50.0, 0.0),
            z=(0, 0, 1), x=(1, 1, 0))
    b.marker("a_u", "a", (50.0, 0.0, 0.0), z=(1, 0, 0))
    b.marker("b_u", "b", (50.0, 0.0, 0.0), z=(0, 1, 0))
    b.joint("univ", "universal", "a_u", "b_u")
    b.joint("line", "inline", parts=("e", "d"), at=(350.0, 0.0, 20.0), z=(0, 0, 1))
    b.joint("plane", "inplane", parts=("b", "e"), at=(300.0, 0.0, 0.0), z=(0, 1, 0))
    b.joint("perp", "perpendicular", "a_u", "b_u")
    b.marker("rod_a", "a", (0.0, 0.0, 30.0))
    b.marker("rod_e", "e", (400.0, 0.0, 70.0))
    b.joint("rod", "distance", "rod_a", "rod_e")
    b.spring("coil", parts=("b", "ground"), at=((100.0, 0.0, 0.0), (100.0, 0.0, 250.0)),
             k=25.0, free_length=300.0)
    b.spring("pull", parts=("c", "ground"), at=((200.0, 0.0, 0.0), (200.0, 80.0, 0.0)),
             table=([-1.0, 1.0], [-40.0, -40.0]))
    b.bushing("torsion", parts=("d", "ground"), at=(300.0, 0.0, 0.0), z=(0, 0, 1),
              k_rot=(0.0, 0.0, 5e4), offset_rot=(0.0, 0.0, 0.1), preload_torque=(0, 0, 7.0))
    b.load_point("global", part="a", at=(0.0, 0.0, 0.0))
    b.load_point("local", part="b", at=(100.0, 0.0, 0.0), frame="a_u")
    b.driver("lift", part="c", at=(200.0, 0.0, 0.0), direction=(0.0, 0.6, 0.8))
    return b.build()


@pytest.fixture(scope="module")
def all_elements():
    return _all_elements_model()


def test_all_elements_round_trip(all_elements, tmp_path):
    """Every joint kind (GCON DM for the distance joint, JPRIM for the primitives), bushings
    with preloads, a torsion spring (SPRINGDAMPER ROTATIONAL), a linear and a constant-tension
    spring, load points with global and marker-frame components (GFORCE) and a driver (MOTION)
    survive write_adm → read_adm; the auxiliary ground and floating markers written for RM,
    JFLOAT and the MOTION's J are not added back."""
    path = tmp_path / "all.adm"
    text = write_adm(all_elements, path)
    for statement in ("JPRIM/", "GCON/", "SPRINGDAMPER/", "ROTATIONAL", "GFORCE/", "MOTION/",
                      "FLOATING", "UNIVERSAL"):
        assert statement in text
    back = read_adm(path)
    assert_same_mechanism(back, all_elements, atol=1e-11)
    model = parse_adm(path)
    loads = model.loads(back, [0.0, 1.0])
    assert not np.any(np.asarray(loads.force)) and not np.any(np.asarray(loads.driver))


def test_write_refuses_what_the_subset_cannot_express(all_elements):
    cubic = eqx.tree_at(lambda m: m.bushings.cubic_trans, all_elements,
                        all_elements.bushings.cubic_trans.at[0, 0].set(1.0))
    with pytest.raises(ModelError, match="cubic"):
        write_adm(cubic, None)
    x = jnp.asarray([[-1.0, 0.0, 1.0]] * 2)
    curved = dataclasses.replace(all_elements, springs=dataclasses.replace(
        all_elements.springs, table_x=x, table_y=jnp.asarray([[0.0] * 3, [-40.0, 0.0, -40.0]])))
    with pytest.raises(ModelError, match="nonlinear table"):
        write_adm(curved, None)
    stops = diffsusp.model.mechanism.Stops(
        length=jnp.ones(1), k=jnp.ones(1), cubic=jnp.zeros(1), i_marker=(0,), j_marker=(1,),
        kind=("bump",), names=("bump",))
    # stops are written (SFORCE of MAX(0, ...); tests/test_adams_springs.py)
    assert "SFORCE/1, TRANSLATIONAL" in write_adm(dataclasses.replace(all_elements, stops=stops),
                                                  None)


# ----------------------------------------------------------------------------- reports, errors


UNSUPPORTED = """title
PART/1, GROUND
PART/2
MARKER/1, PART = 1
MARKER/2, PART = 2
MARKER/3, PART = 1, FLOATING
MARKER/4, PART = 2, FLOATING
ACCGRAV/JGRAV = -9806.65
! adams_view_name='hooke'
JOINT/5, HOOKE, I = 2, J = 1
FIELD/1, I = 2, J = 1, FUNCTION = USER(1, 2)
SFORCE/3, I = 2, J = 1, TRANSLATIONAL, ACTIONONLY, FUNCTION = DX(2, 1)
GFORCE/4, I = 2, JFLOAT = 4, RM = 1, FX = 1\\, FY = 0\\, FZ = 0\\, TX = 0\\, TY = 0\\, TZ = 0
MOTION/6, I = 2, J = 1, B1, FUNCTION = 0
GCON/7, I = 2, FUNCTION = DX(2, 1)
BUSHING/1, I = 2, J = 1, K = 1, 1, 1, KT = 1, 1, 1
END
PART/99, this is after END and never read
"""


def test_statements_outside_the_subset_are_reported():
    """Skipped statements are listed with keyword, id, name, line and reason, in the model and in
    one warning; the rest of the model is read."""
    with pytest.warns(ModelWarning, match="skipped 7 statement") as record:
        model = parse_adm(UNSUPPORTED)
    assert "JOINT/5 'hooke' (line 10)" in str(record[0].message)
    found = {(s.keyword, s.id, s.line) for s in model.skipped}
    assert found == {("ACCGRAV", None, 8), ("JOINT", 5, 10), ("FIELD", 1, 11),
                     ("SFORCE", 3, 12), ("GFORCE", 4, 13), ("MOTION", 6, 14), ("GCON", 7, 15)}
    reasons = {s.keyword: s.reason for s in model.skipped}
    assert "HOOKE" in reasons["JOINT"] and "moving part" in reasons["GFORCE"]
    assert "DX" in reasons["SFORCE"]
    assert [s.keyword for s in model.statements][-1] == "BUSHING"


@pytest.mark.parametrize("text, line, match", [
    (", K = 1\nPART/1, GROUND", 2, "continuation"),
    ("PART/1, GROUND\nthis is not a statement", 3, "expected a statement"),
    ("PART/1, GROUND\nMARKER/1, PART = 2", 3, "not a defined PART"),
    ("PART/1, GROUND\nPART/2\nMARKER/1, PART = 1\nMARKER/2, PART = 2\n"
     "BUSHING/1, I = 2, J = 9, K = 1, 1, 1", 6, "J = 9 is not a defined MARKER"),
    ("PART/1, GROUND\nMARKER/1, PART = 1, QP = 1, 2", 3, "QP needs 3"),
    ("PART/1, GROUND\nMARKER/1, PART = 1, QP = 1, 2, 1e999", 3, "not a finite number"),
    ("PART/1, GROUND\nMARKER/1, PART = 1, QP = 1, 2, nan", 3, "QP needs 3"),
    ("PART/1, GROUND\nMARKER/1, PART = 1, QP = abc, 1, 2", 3, "not a number"),
    ("PART/1, GROUND\nMARKER/1, PART = 1\nMARKER/1, PART = 1", 4, "defined twice"),
    ("PART/1, GROUND\nMARKER/1, PART = 1, QP = 1D, 0, 0", 3, "degree suffix"),
    ("PART/1, GROUND\nMARKER/1, PART = 1, PART = 1", 3, "given twice"),
    ("PART/1, GROUND\nPART/2\nMARKER/1, PART = 1\nMARKER/2, PART = 2\n"
     "BUSHING/1, I = 2.5, J = 1", 6, "one integer"),
    ("UNITS/LENGTH = FURLONG\nPART/1, GROUND", 2, "FURLONG"),
    ("PART/1, GROUND\nPART/2, GROUND", 3, "second GROUND"),
    ("PART/1, GROUND\nPART/2\nMARKER/1, PART = 1\nMARKER/2, PART = 2, QP = 0, 0, 10\n"
     "GCON/1, I = 2, FUNCTION = DM(2, 1) - 12", 6, "10 mm apart"),
    ("PART/1, GROUND\nMARKER/1, PART = 1, QP = 1 2 3", 3, "expected ','"),
    ("PART/1, GROUND\nMARKER/1, PART = 1, REULER = 1, 2, 3, ZP = 0, 0, 1", 3, "not both"),
])
def test_errors_name_the_line(text, line, match):
    with pytest.raises(ModelFileError, match=match) as info:
        parse_adm("title\n" + text)
    assert info.value.line == line


@pytest.mark.parametrize("element, match", [
    ("BUSHING/1, I = 2, J = 3, K = 1, 1, 1", "both markers on part"),
    ("BUSHING/1, I = 2, J = 1, K = -1, 1, 1", "negative"),
    ("SPRINGDAMPER/1, TRANSLATIONAL, I = 2, J = 1, K = 0, LENGTH = 1, FORCE = 0", None),
])
def test_builder_errors_name_the_statement_line(element, match):
    """Errors found while building (before any compilation) carry the statement's line."""
    text = ("title\nPART/1, GROUND\nPART/2\nMARKER/1, PART = 1\nMARKER/2, PART = 2\n"
            f"MARKER/3, PART = 2, QP = 1, 0, 0\n{element}\n")
    if match is None:  # zero rate and zero force: the markers coincide, no spring line
        match = "zero length"
    with pytest.raises(ModelFileError, match=match) as info:
        read_adm(text)
    assert info.value.line == 7


def test_reading_executes_nothing(tmp_path):
    """Function expressions are parsed by the explicit grammar, never evaluated as code."""
    marker = tmp_path / "executed"
    payload = f"__import__('pathlib').Path('{marker}').touch()"
    text = EXAMPLE_TEXT.replace("1000*sin(pi*time)", payload)
    with pytest.warns(ModelWarning, match="GFORCE/1"):
        model = parse_adm(text)
    assert model.skipped[0].keyword == "GFORCE" and not marker.exists()
    with pytest.raises(ExpressionError):
        evaluate_text(payload)
    with pytest.raises(ExpressionError):
        evaluate_text("(lambda: 1)()")
    assert not marker.exists()


# ----------------------------------------------------------------------------- expressions


@pytest.mark.parametrize("text, value", [
    ("1000*sin(pi*(time+0.15))", 1000 * math.sin(math.pi * 0.65)),
    ("-2*-3 + 4/8", 6.5),
    ("30D", math.pi / 6),
    ("cos(PI)", -1.0),
    ("STEP(time, 0, 0, 1, 10)", 5.0),
    ("STEP(time, 1, 0, 2, 10)", 0.0),
    ("((1))", 1.0),
])
def test_expression_values(text, value):
    assert evaluate_text(text, time=0.5) == pytest.approx(value, rel=1e-15, abs=1e-15)


def test_expression_errors_and_distance():
    for bad in ("1 +", "1 ** 2", "foo(1)", "sin(1, 2)", "1/0", "DM(1, 2)", "x", "(" * 200):
        with pytest.raises(ExpressionError):
            evaluate_text(bad)
    with pytest.raises(ExpressionError, match="longer than"):
        evaluate_text("+".join(["1"] * 5000))  # a bounded tree: no recursion limit reached
    with pytest.raises(ExpressionError, match="deeper"):
        parse_expression("(" * (MAX_DEPTH + 1) + "1" + ")" * (MAX_DEPTH + 1))
    assert distance_constraint(parse_expression("DM(3, 4) - 12.5")) == (3, 4, 12.5)
    assert distance_constraint(parse_expression("-7 + DM(1,2)")) == (1, 2, 7.0)
    assert distance_constraint(parse_expression("DM(1, 2) * 2")) is None


# ----------------------------------------------------------------------------- .lcf and .bus


def test_annex_h_load_cases():
    """spec §4.2: the Annex H file holds 14 load cases (Table 5-1's 13 plus the design case
    repeated as row 12); the left wheel's vertical sweep, then brake_l (rows 6–9) and lat_l
    (rows 10–14) at 4500 N; the right wheel stays at 4500 N. Columns are read by name."""
    table = read_lcf(LCF)
    assert table.n_cases == 14 and table.data.shape == (14, 8)
    assert table.columns[:3] == ("whl_z_l", "whl_z_r", "lat_l")
    np.testing.assert_array_equal(table.column("whl_z_l")[:5], [1500, 3000, 4500, 6000, 7500])
    np.testing.assert_array_equal(table.column("WHL_Z_R"), 4500.0)
    np.testing.assert_array_equal(table.column("brake_l")[5:9], [-4000, -2000, 2000, 4000])
    np.testing.assert_array_equal(table.column("lat_l")[9:], [-4000, -2000, 0, 2000, 4000])
    np.testing.assert_array_equal(table.data[11], table.data[2])
    assert table.mode["VERTICAL_MODE"] == "wheel_vertical_force"
    assert table.units["FORCE"] == "newton" and table.comments == ["Loadcase type -- Static Load"]
    assert table.header["FILE_VERSION"] == 6.0
    with pytest.raises(KeyError, match="align_l"):
        table.column("align_l")


def test_lcf_round_trip(tmp_path):
    table = read_lcf(LCF)
    path = tmp_path / "out.lcf"
    write_lcf(table, path)
    back = read_lcf(path)
    assert back.columns == table.columns and back.mode == table.mode
    assert back.units == table.units and back.comments == table.comments
    np.testing.assert_array_equal(back.data, table.data)
    odd = LoadCaseTable(("a", "b"), np.array([[0.1, -1e-300], [1e300, 2.0 / 3.0]]))
    np.testing.assert_array_equal(read_lcf(write_lcf(odd, None)).data, odd.data)


def test_verbatim_thesis_truncations_are_errors():
    """The thesis prints '…' where it cut columns and rows: not a number, reported by line."""
    text = LCF.read_text().replace("drive_r}", "drive_r…}").replace(
        " 1500.0 4500.0 0.0  0.0 0.0 0.0 0.0 0.0", " 1500.0 4500.0 0.0  0.0 0.0 0.0 0.0 0.0 …")
    with pytest.raises(ModelFileError, match="'…'") as info:
        read_lcf(text)
    assert info.value.line == 25


@pytest.mark.parametrize("edit, line, match", [
    (lambda t: t.replace(" 3000.0 4500.0 0.0  0.0 0.0 0.0 0.0 0.0\n",
                         " 3000.0 4500.0 0.0  0.0 0.0 0.0 0.0\n"), 26, "7 value"),
    (lambda t: t.replace("[DATA]", "[DATUM]"), 38, "no \\[DATA\\]"),
    (lambda t: t.replace("'lcf'", "'bus'"), 2, "FILE_TYPE"),
    (lambda t: t.replace(" 6000.0 4500.0", " 6000.0 1e999"), 28, "finite"),
    (lambda t: t.replace("[UNITS]", "[MODE]"), 17, "given twice"),
])
def test_lcf_errors(edit, line, match):
    with pytest.raises(ModelFileError, match=match) as info:
        read_lcf(edit(LCF.read_text()))
    assert info.value.line == line


def test_bushing_property_file():
    """An A/Car bushing property file holding bushing A of Annex I (restoring-force curves, deg):
    its linear stiffnesses are those of §7 R9; the law returned is the force on I (y = −K·x)."""
    prop = read_bushing_property(BUS)
    np.testing.assert_allclose(prop.k_trans, [14052.5, 14615.8, 677.07], rtol=0, atol=0.005)
    np.testing.assert_allclose(prop.k_rot * DEG, [10000.0, 5097.3, 4220.9], atol=0.05)
    x, y = prop.splines["rx"]
    np.testing.assert_allclose(x, np.radians([-30, -15, 0, 15, 30]))
    np.testing.assert_allclose(y, [300000.0, 150000.0, 0.0, -150000.0, -300000.0])
    assert prop.damping["RZ"] == 0.1


def test_bushing_property_round_trip(tmp_path):
    k_trans, k_rot = np.array([100.0, 200.0, 30.0]), np.array([1e5, 2e5, 3e4])
    path = tmp_path / "b.bus"
    write_bushing_property(path, k_trans, k_rot)
    prop = read_bushing_property(path)
    np.testing.assert_allclose(prop.k_trans, k_trans, rtol=1e-14)
    np.testing.assert_allclose(prop.k_rot, k_rot, rtol=1e-14)


def test_property_files_share_the_tir_line_grammar():
    """One TeimOrbit grammar for property and .tir files: ``!`` comment lines, a comment after a
    value, Fortran D exponents, rows of numbers without a {header}; a shipped .tir file reads."""
    sections = parse_teimorbit("! written by hand\n[UNITS]\n LENGTH = 'mm' $ millimetre\n"
                               " SCALE = 1.5D3 ! per mille\n[SHAPE]\n 1.0 0.0\n 1.0d0 0.4\n"
                               "[DATA]\n{a b}\n 2.5D-1 'x'\n")
    assert sections["UNITS"].values == {"LENGTH": "mm", "SCALE": 1500.0}
    assert sections["SHAPE"].tables[0].columns == ()
    assert sections["SHAPE"].tables[0].rows == [[1.0, 0.0], [1.0, 0.4]]
    assert sections["DATA"].tables[0].rows == [[0.25, "x"]]
    tir = DATA.parent.parent / "diffsusp" / "tyre" / "data" / "MagicFormula61_Paramerters.tir"
    assert parse_teimorbit(tir)["MODEL"].values["FITTYP"] == 61.0
    with pytest.raises(ModelFileError, match="no {column header}") as info:
        read_lcf("[DATA]\n 1.0 2.0\n")
    assert info.value.line == 2


# ----------------------------------------------------------------------------- fuzzing


_FUZZ = settings(max_examples=150, deadline=None, derandomize=True,
                 suppress_health_check=[HealthCheck.function_scoped_fixture,
                                        HealthCheck.too_slow])


def _parses_or_file_error(fn, source):
    """`fn(source)` returns, or raises ModelFileError with a line number ≥ 1."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ModelWarning)
            return fn(source)
    except ModelFileError as e:
        assert e.line is not None and e.line >= 1, e
        return None


_PARSERS = {"adm": parse_adm, "lcf": read_lcf, "bus": read_bushing_property}
_SOURCES = {"adm": EXAMPLE_TEXT, "lcf": LCF.read_text(), "bus": BUS.read_text()}


@pytest.mark.parametrize("kind", list(_PARSERS))
@_FUZZ
@given(data=st.binary(max_size=300))
def test_fuzz_random_bytes(kind, data):
    _parses_or_file_error(_PARSERS[kind], bytes(data) + b"\n")


@pytest.mark.parametrize("kind", list(_PARSERS))
@_FUZZ
@given(text=st.text(alphabet=st.characters(codec="utf-8", exclude_categories=["Cs"]),
                    max_size=200))
def test_fuzz_random_text(kind, text):
    _parses_or_file_error(_PARSERS[kind], text + "\n")


@pytest.mark.parametrize("kind", list(_PARSERS))
@_FUZZ
@given(data=st.data())
def test_fuzz_truncated_and_mutated(kind, data):
    source = _SOURCES[kind]
    cut = data.draw(st.integers(1, len(source)))
    text = source[:cut]
    for _ in range(data.draw(st.integers(0, 4))):
        at = data.draw(st.integers(0, len(text)))
        length = data.draw(st.integers(0, 8))
        insert = data.draw(st.sampled_from(
            ["", ",", "=", "\\", "!", "(", ")", "'", "{", "}", "[", "]", "\n", "\n,", "1e999",
             "nan", "-", "D", "\x00", "é", "K = ", "GROUND", "$", "1" * 400]))
        text = text[:at] + insert + text[at + length:]
    _parses_or_file_error(_PARSERS[kind], text + "\n")


_VALUES = st.one_of(st.floats(allow_nan=False, allow_infinity=False, allow_subnormal=False)
                    .map(repr), st.sampled_from(["nan", "inf", "1e999", "-0", "x", "1D", "'1'",
                                                 "", "1" * 400, "(1)"]))


_EDITS = {"K = 100, 100, 100": "K = {}, 100, 100",
          "KT = 5.729577951E+005, 5.729577951E+005": "KT = {}, 5.729577951E+005",
          "FX = 1000*sin(pi*time)": "FX = {}", "TZ = 1000*sin(pi*(time+0.65))": "TZ = {}"}


@settings(max_examples=25, deadline=None, derandomize=True)
@given(key=st.sampled_from(list(_EDITS)), value=_VALUES)
def test_fuzz_values_of_a_model_that_builds(key, value):
    """Changing stiffness and force values keeps the model's structure (its compiled
    validation is reused): read_adm builds a mechanism or raises ModelFileError with a line."""
    text = EXAMPLE_TEXT.replace(key, _EDITS[key].format(value))
    mech = _parses_or_file_error(read_adm, text)
    if mech is not None:
        assert isinstance(mech, diffsusp.Mechanism) and len(mech.bushings.names) == 1


@settings(max_examples=200, deadline=None, derandomize=True)
@given(text=st.text(alphabet="0123456789.+-*/() ,DdeEPIpisnctmoTIMESTEPM\\\n", max_size=80))
def test_fuzz_expressions(text):
    """Any text: a finite float or an ExpressionError, never another exception."""
    try:
        value = evaluate_text(text, time=0.3)
    except ExpressionError:
        return
    assert math.isfinite(value)


def test_parse_accepts_text_bytes_and_paths(tmp_path):
    """Sources: a path, a path string, text (with a newline), bytes (UTF-8 or Latin-1)."""
    latin = EXAMPLE_TEXT.replace("! adams_view_name='cm'", "! commentaire déjà vu").encode(
        "latin-1")
    for source in (EXAMPLE, str(EXAMPLE), EXAMPLE_TEXT, EXAMPLE_TEXT.encode(), latin):
        model = parse_adm(source)
        assert isinstance(model, AdmModel) and len(model.statements) == 16
    with pytest.raises(ModelFileError, match="cannot read"):
        parse_adm(tmp_path / "missing.adm")
