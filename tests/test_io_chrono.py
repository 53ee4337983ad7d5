"""Chrono::Vehicle JSON import (diffsusp.io.chrono): the three generic templates of
tests/data/chrono, left and right, against the hand-built double wishbone
(`diffsusp.models.double_wishbone`, written independently from the same file) and the independent
NumPy solver of tests/oracle.py; physically sensible K&C responses; malformed files.

Compilation dominates the cost: each model structure compiles its validation and its solve once.
The imported left double wishbone *is* the hand-built one and is solved with the 7-case table
shape of tests/test_models.py, so the two files share those programs (persistent cache); every
other model is solved once with the same 7-case shape, and the right sides are solved by the
NumPy oracle (seconds, no compilation) and compared with the mirrored left solutions.
"""

import functools
import json
import math
import warnings
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import oracle
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import diffsusp
from diffsusp.errors import ModelFileError, ModelWarning
from diffsusp.io import chrono
from diffsusp.io.chrono import DEFAULT_LOADED_RADIUS, read_chrono
from diffsusp.models import DOUBLE_WISHBONE_DESIGN_LOAD, double_wishbone

DATA = Path(__file__).parent / "data"
CHRONO = DATA / "chrono"  # copies of /work/shared/data/chrono (Project Chrono, BSD-3-Clause)
TEMPLATES = ("DoubleWishbone", "MacPhersonStrut", "MultiLink")


class _Models:
    """Each (file, side, options) imported once per module."""

    def __init__(self):
        self._built = {}

    def __call__(self, path, side="left", **kw):
        key = (str(path), side, tuple(sorted(kw.items())))
        if key not in self._built:
            self._built[key] = read_chrono(path, side=side, **kw)
        return self._built[key]


@pytest.fixture(scope="module")
def models():
    return _Models()


# ----------------------------------------------------------------------------- K&C helpers


def wheel_state(mech, q, side):
    """Wheel-centre position (..., 3) mm, toe and camber (rad) from the spin axis (the
    wheel-centre marker's z axis, outboard). Chrono frame x forward, y left, z up; toe-in and
    camber top-out positive on both sides (Adams/Car convention, per side)."""
    pos, rot = diffsusp.marker_poses(mech, q)
    k = mech.markers.index("wheel_centre")
    return _wheel(np.asarray(pos[..., k, :]), np.asarray(rot[..., k, :, 2]), side)


def _wheel(centre, spin, side):
    s = 1.0 if side == "left" else -1.0
    toe = np.arctan2(spin[..., 0], s * spin[..., 1])  # heading turned inboard: toe-in
    camber = np.arctan2(-spin[..., 2], np.hypot(spin[..., 0], spin[..., 1]))  # axis dips: top out
    return centre, toe, camber


def oracle_wheel(mech, sols, side):
    centre, spin = [], []
    k = mech.markers.index("wheel_centre")
    for sol in sols:
        pos, rot = oracle.marker_poses(mech, sol.p, sol.R)
        centre.append(pos[k])
        spin.append(rot[k][:, 2])
    return _wheel(np.array(centre), np.array(spin), side)


def table(f0, mirror=False):
    """The 7-case shape of tests/test_models.py: vertical 0.5–1.5 of the design load f0 ... here
    f0 ± 2000 N in 5 steps, then ±4000 N lateral (+y: outboard on the left wheel) at f0."""
    vertical = f0 + np.array([-2000.0, -1000.0, 0.0, 1000.0, 2000.0])
    lateral = np.array([-4000.0, 4000.0]) * (-1.0 if mirror else 1.0)
    force = np.zeros((7, 3))
    force[:5, 2] = vertical
    force[5:, 2] = f0
    force[5:, 1] = lateral
    return force


def design_load(mech):
    """Vertical contact-patch load for which the design position is an equilibrium, from the
    oracle (NumPy): with L the one-column null space of Φ_q at design, F0 = −LᵀQ0 / LᵀQ1, Q0 the
    generalised forces at design without load and Q1 those of a 1 N vertical load."""
    p, r = np.zeros((len(mech.parts), 3)), np.tile(np.eye(3), (len(mech.parts), 1, 1))
    orc = oracle._oracle(mech)
    n_l = len(mech.load_points.names)
    zero, unit = np.zeros((n_l, 3)), np.zeros((n_l, 3))
    unit[mech.load_points.index("contact_patch"), 2] = 1.0
    lam = np.zeros(orc.n_mult)
    q0 = orc.residual(p, r, lam, zero, zero, np.zeros(0))[0][:orc.n]
    q1 = orc.residual(p, r, lam, unit, zero, np.zeros(0))[0][:orc.n] - q0
    phi_q = oracle.constraint_jacobian(mech, p, r)
    _, s, vt = np.linalg.svd(phi_q)
    null = vt[-1]
    assert s[-1] > 1e-10 * s[0] and vt.shape[0] - phi_q.shape[0] == 1  # rank m, 1 DOF
    return float(-(null @ q0) / (null @ q1))


def solve_left(mech, f0):
    loads = mech.loads(forces={"contact_patch": table(f0)})
    return diffsusp.solve_statics(mech, loads)


def solve_right_oracle(mech, f0):
    force = np.zeros((len(mech.load_points.names), 3))
    k = mech.load_points.index("contact_patch")
    sols = []
    for row in table(f0, mirror=True):
        force[k] = row
        sols.append(oracle.solve(mech, force, np.zeros_like(force), np.zeros(0)))
    return sols


# ----------------------------------------------------------------------------- double wishbone


def _assert_same_mechanism(a, b):
    """Same topology, names, static data and (exactly) the same parameter arrays; only the
    mechanism's name may differ."""
    import jax

    assert a.parts == b.parts
    assert a.independent_rows == b.independent_rows
    assert a.reference_points == b.reference_points and a.length_scale == b.length_scale
    for field in ("markers", "joints", "bushings", "springs", "stops", "drivers", "load_points"):
        ea, eb = getattr(a, field), getattr(b, field)
        assert jax.tree_util.tree_structure(ea) == jax.tree_util.tree_structure(eb), field
        for x, y in zip(jax.tree_util.tree_leaves(ea), jax.tree_util.tree_leaves(eb),
                        strict=True):
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y), err_msg=field)


def test_double_wishbone_is_the_hand_built_model(models):
    """The importer reproduces `diffsusp.models.double_wishbone`, written by hand from the same
    JSON and Chrono's ChDoubleWishbone: every marker, frame, joint, spring and load point."""
    mech = models(CHRONO / "DoubleWishbone.json")
    _assert_same_mechanism(mech, double_wishbone())
    assert mech.name == "Generic DoubleWishbone (left)"


def test_double_wishbone_bushing_data(models):
    """With Chrono 'Bushing Data' (5e6 N/m, 1e5 N·m/rad, DOF 0) each control-arm revolute
    becomes a bushing in the joint frame: 5000 N/mm on the translations, 1e8 N·mm/rad on the two
    rotations the revolute locks, 0 about its axis — the hand-built bushing variant."""
    mech = models(DATA / "DoubleWishbone_bushings.json")
    _assert_same_mechanism(mech, double_wishbone(bushings=True))
    np.testing.assert_array_equal(mech.bushings.k_rot, [[1e8, 1e8, 0.0], [1e8, 1e8, 0.0]])


def test_double_wishbone_wheel_travel_driver(models):
    """`wheel_travel=True` adds the hand-built model's driver 'wheel_travel' (wheel-centre
    global z): 18 rows, rank 18, 0 DOF."""
    mech = models(CHRONO / "DoubleWishbone.json", wheel_travel=True)
    assert mech.drivers.names == ("wheel_travel",)
    assert mech.markers.names[mech.drivers.marker[0]] == "wheel_centre"
    np.testing.assert_array_equal(mech.drivers.direction, [[0.0, 0.0, 1.0]])
    report = diffsusp.validate(mech)
    assert (report.n_rows, report.rank, report.dof) == (18, 18, 0)


@pytest.fixture(scope="module")
def left_solutions(models):
    out = {}
    for name in TEMPLATES:
        mech = models(CHRONO / f"{name}.json")
        f0 = design_load(mech)
        out[name] = (mech, f0, solve_left(mech, f0))
    return out


def test_double_wishbone_sweep_matches_oracle_on_hand_built(left_solutions):
    """Vertical load sweep (design load ± 2000 N) and ±4000 N lateral: wheel-centre position,
    toe and camber of the imported model solved by diffsusp agree with the NumPy oracle solving
    the hand-built model (independent construction, independent solver)."""
    mech, f0, sol = left_solutions["DoubleWishbone"]
    assert f0 == pytest.approx(DOUBLE_WISHBONE_DESIGN_LOAD, abs=1e-3)
    assert bool(jnp.all(sol.converged))
    hand = double_wishbone()
    force = np.zeros((2, 3))
    sols = [oracle.solve(hand, np.array([row, np.zeros(3)]), np.zeros_like(force), np.zeros(0))
            for row in table(f0)]
    centre, toe, camber = wheel_state(mech, sol.q, "left")
    c_ref, t_ref, k_ref = oracle_wheel(hand, sols, "left")
    np.testing.assert_allclose(centre, c_ref, rtol=0, atol=1e-6)
    np.testing.assert_allclose(toe, t_ref, rtol=0, atol=1e-8)
    np.testing.assert_allclose(camber, k_ref, rtol=0, atol=1e-8)
    # The design position is the equilibrium at the design load (middle case).
    np.testing.assert_allclose(sol.q[2], 0.0, atol=1e-6)


# ----------------------------------------------------------------------------- all templates


@pytest.mark.parametrize("name", TEMPLATES)
def test_left_side_kc_response_is_sensible(left_solutions, name):
    """K&C responses of each template about its design load f0 (the vertical load that holds
    the design position, found by the oracle): q = 0 solves the f0 case; the contact patch rises
    with vertical load at a plausible wheel rate; its compliance is positive for lateral load
    too (work-conjugate displacement along the force); toe and camber vary smoothly and by
    less than 2° over ±2000 N."""
    mech, f0, sol = left_solutions[name]
    assert bool(jnp.all(sol.converged))
    np.testing.assert_allclose(sol.q[2], 0.0, atol=1e-6)
    pos, _ = diffsusp.marker_poses(mech, sol.q)
    patch = np.asarray(pos[:, mech.markers.index("contact_patch.m")])
    rise = np.diff(patch[:5, 2])
    assert np.all(rise > 0)
    rate = 1000.0 / rise
    assert np.all((20.0 < rate) & (rate < 1000.0)), rate
    assert patch[6, 1] - patch[5, 1] > 0.0  # +y (outboard) force moves the patch outboard
    _, toe, camber = wheel_state(mech, sol.q, "left")
    for curve in (toe[:5], camber[:5]):
        assert np.ptp(curve) < np.radians(2.0)
        assert np.max(np.abs(np.diff(curve, 2))) < 0.2 * np.max(np.abs(np.diff(curve))) + 1e-9


@pytest.mark.parametrize("name", TEMPLATES)
def test_right_side_is_the_mirror_image(left_solutions, models, name):
    """The right side is Chrono's mirror (y → −y) of the left: mirrored markers, same topology;
    solved by the NumPy oracle under the mirrored loads it gives the mirrored left solution
    (wheel centre with y → −y, the same toe and camber), and the same design load."""
    left, f0, sol = left_solutions[name]
    right = models(CHRONO / f"{name}.json", side="right")
    assert right.markers.names == left.markers.names
    assert right.joints == left.joints and right.markers.part == left.markers.part
    mirror = np.array([1.0, -1.0, 1.0])
    np.testing.assert_allclose(right.markers.position, left.markers.position * mirror, atol=0)
    assert design_load(right) == pytest.approx(f0, rel=1e-9)
    sols = solve_right_oracle(right, f0)
    centre, toe, camber = oracle_wheel(right, sols, "right")
    c_left, t_left, k_left = wheel_state(left, sol.q, "left")
    np.testing.assert_allclose(centre, np.asarray(c_left) * mirror, rtol=0, atol=1e-6)
    np.testing.assert_allclose(toe, t_left, rtol=0, atol=1e-8)
    np.testing.assert_allclose(camber, k_left, rtol=0, atol=1e-8)


def test_template_structures(models):
    """Topology per template (Chrono's joints): 1 kinematic DOF (the wheel travel), no
    redundant row, no free mode; MacPherson strut with a cylindrical and a universal joint,
    MultiLink with two universal-joint links."""
    expected = {"DoubleWishbone": (18, 17), "MacPhersonStrut": (18, 17), "MultiLink": (24, 23)}
    for name, (n, rows) in expected.items():
        report = diffsusp.validate(models(CHRONO / f"{name}.json"))
        assert (report.n_coordinates, report.rank, report.dof) == (n, rows, 1)
        assert report.redundant == () and report.free_modes == ()
    strut = models(CHRONO / "MacPhersonStrut.json")
    assert sorted(strut.joints.kind) == ["cylindrical", "distance", "revolute", "spherical",
                                         "universal"]
    multi = models(CHRONO / "MultiLink.json")
    assert multi.joints.kind.count("universal") == 2
    # MacPherson spring from the strut top to the upright, as Chrono attaches it.
    i, j = strut.springs.i_marker[0], strut.springs.j_marker[0]
    assert strut.markers.part[i] == -1 and strut.parts[strut.markers.part[j]] == "upright"
    np.testing.assert_allclose(strut.markers.position[j], [-74.02507, 853.2915, 248.4536])


def test_tierod_body_and_spring_curve(models):
    """A tie rod with a Mass becomes Chrono's tie-rod body (spherical to the upright, universal
    to the chassis: its spin is held, 1 DOF overall); 'Spring Curve Data' with a 'Preload':
    tension = curve(ℓ − L0) − P (N, mm), linear between the points (the smooth Akima spline of
    a tabulated spring as an option)."""
    mech = models(DATA / "DoubleWishbone_tierod_body.json")
    report = diffsusp.validate(mech)
    assert (report.n_coordinates, report.rank, report.dof) == (24, 23, 1)
    assert report.free_modes == ()
    # Chrono interpolates the curve linearly: a straight curve is a linear spring, no stops.
    assert mech.springs.tabulated == (False,) and mech.stops.names == ()
    length, tension = diffsusp.spring_states(mech, jnp.zeros(mech.n_coordinates))
    np.testing.assert_allclose(tension, 369.149 * (length - 356.0) - 100.0, rtol=1e-9)
    smooth = read_chrono(DATA / "DoubleWishbone_tierod_body.json", spring_interpolation="akima",
                         check=False)
    assert smooth.springs.tabulated == (True,)
    np.testing.assert_allclose(smooth.springs.table_x[0], [-200.0, 0.0, 200.0])
    np.testing.assert_allclose(smooth.springs.table_y[0], [-73929.8, -100.0, 73729.8])


@pytest.mark.parametrize("side", ["left", "right"])
@pytest.mark.parametrize("toe_deg, camber_deg", [(0.0, 0.0), (1.0, -0.5), (-0.3, 2.0)])
def test_spin_axis_toe_and_camber(side, toe_deg, camber_deg):
    """Chrono's spindle orientation Rz(s·toe)·Rx(s·camber), s = −1 left, +1 right, read back
    with the toe-in / camber top-out convention of `wheel_state` gives the file's angles."""
    axis = chrono._outboard_axis(math.radians(toe_deg), math.radians(camber_deg), side)
    _, toe, camber = _wheel(np.zeros(3), axis, side)
    assert np.degrees(toe) == pytest.approx(toe_deg, abs=1e-12)
    assert np.degrees(camber) == pytest.approx(camber_deg, abs=1e-12)
    assert axis[1] * (1 if side == "left" else -1) > 0  # outboard


def test_loaded_radius(models):
    """The contact patch is `loaded_radius` below the wheel centre (default 330 mm), and the
    corner the importer attaches has the same loaded radius (no 300 mm default)."""
    mech = models(CHRONO / "DoubleWishbone.json")
    pos = np.asarray(mech.markers.position)
    centre = pos[mech.markers.index("wheel_centre")]
    patch = pos[mech.markers.index("contact_patch.m")]
    np.testing.assert_allclose(centre - patch, [0.0, 0.0, DEFAULT_LOADED_RADIUS])
    assert mech.corners[0].loaded_radius == DEFAULT_LOADED_RADIUS
    assert mech.corners[0].side == "left" and mech.corners[0].frame == "iso"


# ----------------------------------------------------------------------------- malformed files


def _write(tmp_path, data, name="s.json"):
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    return path


def _doc():
    return json.loads((CHRONO / "DoubleWishbone.json").read_text())


@pytest.mark.parametrize("edit, field, message", [
    (lambda d: d.pop("Spring"), "Spring", "'Spring' is missing"),
    (lambda d: d["Spring"].pop("Free Length"), "Spring/Free Length", "missing"),
    (lambda d: d["Spring"].__setitem__("Spring Coefficient", -5.0), "Spring/Spring Coefficient",
     "positive"),
    (lambda d: d["Tierod"].__setitem__("Location Chassis", [1, 2]), "Tierod/Location Chassis",
     "3 finite numbers"),
    (lambda d: d["Tierod"].__setitem__("Location Chassis", [1, "a", 2]),
     "Tierod/Location Chassis", "3 finite numbers"),
    (lambda d: d["Upper Control Arm"].__setitem__("Location Upright", [1e9, 0, 0]),
     "Upper Control Arm/Location Upright", "metres"),
    (lambda d: d.__setitem__("Template", "SolidAxle"), "Template", "not supported"),
])
def test_invalid_fields_name_the_field_and_line(tmp_path, edit, field, message):
    doc = _doc()
    edit(doc)
    path = _write(tmp_path, json.dumps(doc, indent=2))
    with pytest.raises(ModelFileError, match=message) as info:
        read_chrono(path)
    assert info.value.field == field
    lines = path.read_text().splitlines()
    key = field.split("/")[-1]
    assert f'"{key}"' in lines[info.value.line - 1] or key not in path.read_text()


def test_invalid_json_gives_the_line(tmp_path):
    text = (CHRONO / "DoubleWishbone.json").read_text().replace('"Radius":                   0.15,',
                                                                '"Radius":                   0.15')
    with pytest.raises(ModelFileError, match="not valid JSON") as info:
        read_chrono(_write(tmp_path, text))
    assert info.value.line == 12  # the decoder stops at the next key, "Width" (line 12)
    nan = (CHRONO / "DoubleWishbone.json").read_text().replace("1.103", "NaN")
    with pytest.raises(ModelFileError, match="JSON"):
        read_chrono(_write(tmp_path, nan, "nan.json"))


def test_comments_are_allowed(tmp_path, models):
    """Chrono reads JSON with // and /* */ comments (rapidjson kParseCommentsFlag)."""
    text = (CHRONO / "DoubleWishbone.json").read_text()
    text = "// header\n/* block\n comment */" + text.replace(
        '"Mass":                     1.103,', '"Mass": 1.103, // "Spindle" "COM": [1, 2, 3]')
    mech = read_chrono(_write(tmp_path, text))
    _assert_same_mechanism(mech, models(CHRONO / "DoubleWishbone.json"))


def test_non_perpendicular_universal_axes(tmp_path):
    doc = json.loads((CHRONO / "MultiLink.json").read_text())
    doc["Lateral"]["Universal Joint Axis Link"] = [0.0, 0.0, 1.0]
    with pytest.raises(ModelFileError, match="not perpendicular") as info:
        read_chrono(_write(tmp_path, doc))
    assert info.value.field == "Lateral/Universal Joint Axis Link"


def test_bad_arguments():
    with pytest.raises(ValueError, match="side"):
        read_chrono(CHRONO / "DoubleWishbone.json", side="middle")
    with pytest.raises(ValueError, match="loaded_radius"):
        read_chrono(CHRONO / "DoubleWishbone.json", loaded_radius=-1.0)
    with pytest.raises(ModelFileError, match="cannot read"):
        read_chrono(CHRONO / "missing.json")


def test_a_lone_stop_length_is_reported(tmp_path):
    """Chrono enables the spring's stops only with both 'Minimum Length' and 'Maximum Length'
    (`ReadTSDAFunctorJSON`); one alone is ignored, with a warning. Both: see
    tests/test_chrono_fidelity.py."""
    doc = _doc()
    doc["Spring"]["Minimum Length"] = 0.2
    doc["Spindle"]["COM"] = [1.0, 2.0]  # stop the read before the (compiled) build
    with pytest.warns(ModelWarning, match="only when both"), pytest.raises(ModelFileError):
        read_chrono(_write(tmp_path, doc))


def test_reading_executes_nothing(tmp_path):
    """Strings are data: nothing in a file is evaluated."""
    marker = tmp_path / "executed"
    doc = _doc()
    doc["Template"] = f"__import__('pathlib').Path('{marker}').touch()"
    doc["Name"] = doc["Template"]
    with pytest.raises(ModelFileError, match="not supported"):
        read_chrono(_write(tmp_path, doc))
    assert not marker.exists()


# ----------------------------------------------------------------------------- fuzzing

_SOURCE = (CHRONO / "DoubleWishbone.json").read_text()
# Values that are never a valid hardpoint or rate (the build, which compiles, is not reached),
# and stiffness-like fields whose valid values keep the structure (no new compilation).
_BAD_VALUES = ["NaN", "Infinity", "-Infinity", "1e400", "-1e400", "1e300", '"x"', "null", "[]",
               "{}", "true", "[1, 2]", "[1, 2, 3, 4]", "[1e999, 0, 0]", '"0.5"', "1" * 5000]
_RATE_KEYS = ['"Spring Coefficient":       369149.000', '"Free Length" :             0.356']


def _read_or_model_file_error(path):
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ModelWarning)
            mech = read_chrono(path)
    except ModelFileError as e:
        assert e.line is None or e.line >= 1
        return None
    assert isinstance(mech, diffsusp.Mechanism)
    return mech


_FUZZ = settings(max_examples=60, deadline=None, derandomize=True,
                 suppress_health_check=[HealthCheck.function_scoped_fixture])


@_FUZZ
@given(data=st.binary(max_size=400))
def test_fuzz_random_bytes(tmp_path, data):
    path = tmp_path / "f.json"
    path.write_bytes(data)
    assert _read_or_model_file_error(path) is None


@_FUZZ
@given(cut=st.integers(0, len(_SOURCE) - 2))
def test_fuzz_truncated(tmp_path, cut):
    assert _read_or_model_file_error(_write(tmp_path, _SOURCE[:cut])) is None


@functools.cache
def _reference_positions():
    return np.asarray(read_chrono(CHRONO / "DoubleWishbone.json").markers.position)


@_FUZZ
@given(position=st.integers(0, len(_SOURCE) - 1), length=st.integers(0, 12),
       insert=st.sampled_from(["", "{", "}", "[", "]", ",", ":", '"', "0", "-", "e", "\x00",
                               "é", "//", "/*"]))
def test_fuzz_mutated_text(tmp_path, position, length, insert):
    """Syntax mutations (digits are left alone so that a surviving model has the original
    geometry and reuses its compiled validation)."""
    span = _SOURCE[max(position - 1, 0):position + length + 1]
    assume(not any(c.isdigit() for c in span))
    text = _SOURCE[:position] + insert + _SOURCE[position + length:]
    mech = _read_or_model_file_error(_write(tmp_path, text))
    if mech is not None:
        np.testing.assert_array_equal(mech.markers.position, _reference_positions())


_NUMBERS = [(m.start(), m.end()) for m in __import__("re").finditer(
    r"-?\d+\.\d+(?:[eE][+-]?\d+)?", _SOURCE)]


@_FUZZ
@given(where=st.sampled_from(_NUMBERS), value=st.sampled_from(_BAD_VALUES))
def test_fuzz_bad_values(tmp_path, where, value):
    text = _SOURCE[:where[0]] + value + _SOURCE[where[1]:]
    mech = _read_or_model_file_error(_write(tmp_path, text))
    if mech is not None:  # an unused field (a mass, an inertia) may take any value
        assert mech.n_coordinates == 18


@settings(max_examples=10, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(key=st.sampled_from(_RATE_KEYS), value=st.floats(1e-3, 1e7))
def test_fuzz_valid_rates_load(tmp_path, key, value):
    """Valid values of the spring's rate or free length always give a model (same structure:
    no new compilation)."""
    name = key.split(":")[0]
    text = _SOURCE.replace(key, f"{name}: {value!r}")
    mech = _read_or_model_file_error(_write(tmp_path, text))
    assert mech is not None

