"""The native TOML model file (diffsusp.io.native): exact round trips of every built-in model, the
shipped files, hand-written files with comments and other units, located errors, and fuzzed
input that must load or raise ModelFileError with a line number.

Building a model validates it (a Jacobian traced per model structure, and names and design
positions are static), so each built-in model is built once per module; the fuzz tests that
produce many distinct valid models replace the validation step by the identity, and a short
end-to-end fuzz keeps it.
"""

import builtins
import dataclasses
import importlib
import math
import os
import pathlib
import re
import string
import subprocess
from unittest import mock

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from diffsusp.errors import ModelError, ModelFileError
from diffsusp.io import loads_from_table, model_from_toml, save_model
from diffsusp.model import MechanismBuilder, frame_from_axes
from diffsusp.models import TABLE_4_4, TABLE_5_1, ZOO, thesis_load_cases
from diffsusp.models._write_data import model_text
from diffsusp.resolve import load_model, load_model_file

DATA = pathlib.Path(importlib.import_module("diffsusp.models").__file__).parent / "data"


class _Zoo:
    def __init__(self):
        self._built = {}

    def __getitem__(self, name):
        if name not in self._built:
            self._built[name] = ZOO[name]()
        return self._built[name]


@pytest.fixture(scope="module")
def zoo():
    return _Zoo()


def assert_identical(a, b):
    """Same static topology (names, indices, kinds, scales) and every leaf equal bit for bit."""
    leaves_a, tree_a = jax.tree.flatten(a)
    leaves_b, tree_b = jax.tree.flatten(b)
    assert tree_a == tree_b
    for x, y in zip(leaves_a, leaves_b, strict=True):
        x, y = np.asarray(x), np.asarray(y)
        assert x.dtype == y.dtype and x.shape == y.shape
        assert x.tobytes() == y.tobytes()


_FLOAT = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")


def assert_same_text(a, b):
    """The same text, except that the numbers may differ in their last bits (a few units in the
    last place, or 1e-12 in absolute where a coordinate is a difference of larger ones)."""
    assert _FLOAT.split(a) == _FLOAT.split(b)
    x = np.array([float(t) for t in _FLOAT.findall(a)])
    y = np.array([float(t) for t in _FLOAT.findall(b)])
    np.testing.assert_allclose(x, y, rtol=1e-15, atol=1e-12)


def _assert_close_static(a, b, rtol):
    """Static metadata (e.g. a corner) equal, its floats to `rtol` (1e-12 mm absolute)."""
    if dataclasses.is_dataclass(a):
        assert type(a) is type(b)
        for f in dataclasses.fields(a):
            _assert_close_static(getattr(a, f.name), getattr(b, f.name), rtol)
    elif isinstance(a, (tuple, list)):
        assert isinstance(b, (tuple, list)) and len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            _assert_close_static(x, y, rtol)
    elif isinstance(a, float):
        assert a == pytest.approx(b, rel=rtol, abs=1e-12)
    else:
        assert a == b


def assert_same_model(a, b, rtol=1e-14):
    """Same topology and leaves equal to `rtol` (unit conversions round in the last bits, and
    XLA's sin/cos depend on the compiler's flags)."""
    def strip(m):
        return dataclasses.replace(m, length_scale=0.0, reference_points=(), corners=())

    assert jax.tree.structure(strip(a)) == jax.tree.structure(strip(b))
    assert a.length_scale == pytest.approx(b.length_scale, rel=rtol)
    np.testing.assert_allclose(a.reference_points, b.reference_points, rtol=rtol, atol=1e-12)
    _assert_close_static(a.corners, b.corners, rtol)
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=rtol, atol=1e-15)


# ------------------------------------------------------------------------ built-in models


@pytest.mark.parametrize("name", list(ZOO))
def test_shipped_file_equals_the_python_model_and_round_trips(name, tmp_path):
    # Validation is a deterministic function of the mechanism it finishes, so comparing before
    # it proves the validated models equal too (and test_models validates every built-in).
    with _no_validation():
        mech = ZOO[name]()
        path = DATA / f"{name}.toml"
        # The shipped file is what the generator writes for today's model, to the last bits of
        # the orientations the builders compute with XLA's sin/cos (which depend on the
        # compiler's flags: the tests compile with LLVM's optimisation off, the files were
        # written with it on).
        assert_same_text(path.read_text(encoding="utf-8"), model_text(name, mech))
        loaded = load_model(path)
        assert_same_model(loaded, mech, rtol=1e-15)
        # save -> load: identical mechanism, bit for bit.
        out = tmp_path / "again.toml"
        save_model(loaded, out)
        assert_identical(load_model(out), loaded)
        if name.startswith("pseudo_mcpherson"):
            tables = load_model_file(path).load_tables
            for key, thesis in (("table_5_1", TABLE_5_1), ("table_4_4", TABLE_4_4)):
                got = loads_from_table(mech, tables[key])
                assert_identical(got, thesis_load_cases(mech, thesis))


def test_shipped_file_with_validation(zoo):
    """End to end, the validated model: redundant rows dropped alike."""
    mech = load_model(DATA / "isolated_bushing.toml")
    assert_same_model(mech, zoo["isolated_bushing"], rtol=1e-15)


def test_builtin_name_loads_the_builtin_model(zoo):
    assert_same_model(load_model("isolated_bushing"), zoo["isolated_bushing"], rtol=1e-15)
    with _no_validation():
        mf = load_model_file("pseudo_mcpherson_wheel_travel")
    assert set(mf.load_tables) == {"table_5_1", "table_4_4", "wheel_travel_sweep"}
    np.testing.assert_array_equal(mf.load_tables["wheel_travel_sweep"]["wheel_travel"],
                                  np.linspace(-50.0, 50.0, 11))


def test_io_depends_on_the_model_layer_only():
    """No module of `diffsusp.io` imports a package above `diffsusp.model` (solvers, K&C,
    identification, built-in models, CLI, the resolver `diffsusp.resolve`), at module level or
    inside a function. And the file reader knows no built-in name of its own."""
    import ast

    from diffsusp.io import read_model_file

    below = {"errors", "geometry", "model", "compilation"}
    io_dir = pathlib.Path(importlib.import_module("diffsusp.io").__file__).parent
    found = set()
    for path in sorted(io_dir.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level >= 2:
                names = [node.module] if node.module else [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("diffsusp."):
                names = [node.module.split(".")[1]]
            elif isinstance(node, ast.Import):
                names = [a.name.split(".")[1] for a in node.names
                         if a.name.startswith("diffsusp.")]
            else:
                continue
            found |= {(path.name, n.split(".")[0]) for n in names}
    assert {(f, n) for f, n in found if n not in below} == set()
    with pytest.raises(ModelFileError, match=r"expected a \.toml, \.adm or \.json path\."):
        read_model_file("isolated_bushing")
    assert not hasattr(importlib.import_module("diffsusp.io"), "load_model_file")


def test_dispatch_on_suffix(tmp_path, monkeypatch):
    calls = []
    io = importlib.import_module("diffsusp.io")
    monkeypatch.setattr(io, "read_adm",
                        lambda path, **kw: calls.append(("adm", path)) or "adm-model")
    monkeypatch.setattr(io, "read_chrono",
                        lambda path: calls.append(("json", path)) or "chrono-model")
    for suffix in (".adm", ".json"):
        (tmp_path / f"m{suffix}").write_text("x")
    assert load_model(tmp_path / "m.adm") == "adm-model"
    assert load_model(str(tmp_path / "m.json")) == "chrono-model"
    assert calls == [("adm", str(tmp_path / "m.adm")), ("json", str(tmp_path / "m.json"))]
    with pytest.raises(ModelFileError, match="no such file.*built-in model name"):
        load_model(tmp_path / "missing.toml")
    with pytest.raises(ModelFileError, match=r"expected a \.toml, \.adm or \.json path"):
        load_model("not_a_model")
    with pytest.raises(ModelFileError, match="expected a .toml"):
        load_model(tmp_path / "m.txt")
    with pytest.raises(ModelFileError, match="use a .toml path"):
        save_model(None, tmp_path / "m.json")


# ------------------------------------------------------------------------ hand-written files

ISOLATED_BUSHING_SI = """\
# The Adams example model_exemple11, written by hand in metres, kilonewtons and degrees.
diffsusp = 1
name = "isolated bushing (model_exemple11)"
parts = ["arm"]          # the arm; the ground is implicit

[units]
length = "m"             # positions in metres
force = "kN"
angle = "deg"            # REULER angles, and rotational stiffness per degree

# BUSHING/1: I on the arm, J on the ground.
[bushings.bush]
parts = ["arm", "ground"]
at = [0, 0, 0]
reuler = [28.18678543, 33.2259422, 350.8538915]   # MARKER/7 and MARKER/8
k_trans = 100            # kN/m, i.e. 100 N/mm on each axis
k_rot = 0.01             # kN·m/deg = 10 000 N·mm/deg

[load_points.tip]        # QP of MARKER/12
part = "arm"
at = [-0.3, 0, 0]

[load_points.centre]
part = "arm"
at = [0.0, 0.0, 0.0]
"""


def test_hand_written_si_file_equals_the_builder(zoo):
    mech = model_from_toml(ISOLATED_BUSHING_SI, path="si.toml").mechanism
    assert_same_model(mech, zoo["isolated_bushing"])
    assert mech.markers.names == ("bush.i", "bush.j", "tip.m", "centre.m")
    # k_rot: 0.01 kN·m/deg = 1e4 N·mm/deg = 1e4·180/π N·mm/rad.
    np.testing.assert_allclose(mech.bushings.k_rot, 1e4 * 180 / math.pi, rtol=1e-15)
    # Orientation from REULER degrees goes through the builder's own conversion: exact.
    np.testing.assert_array_equal(mech.markers.orientation,
                                  zoo["isolated_bushing"].markers.orientation)


def _feature_rig() -> MechanismBuilder:
    """Every kind of element and option, in mm, N, rad (compare with FEATURE_RIG_SI)."""
    deg = 180.0 / math.pi
    b = MechanismBuilder("feature rig")
    b.part("arm")
    b.part("slider")
    b.marker("arm_frame", "arm", (-300.0, 0.0, 0.0),
             orientation=frame_from_axes(z=(0.0, 1.0, 0.0), x=(1.0, 0.0, 0.0)))
    b.marker("arm_reuler", "arm", (-150.0, 10.0, 0.0), reuler_deg=(10.0, 20.0, 30.0))
    b.marker("slider_top", "slider", (0.0, 500.0, 100.0))
    b.marker("stop_seat", "ground", (0.0, 500.0, 20.0))
    # The file adds joints before bushings: same order here, so marker indices agree.
    b.joint("slide", "translational", parts=("slider", "ground"), at=(0.0, 500.0, 0.0),
            z=(0.0, 0.0, 1.0), x=(1.0, 0.0, 0.0))
    b.bushing(
        "pivot", parts=("arm", "ground"), at=(0.0, 0.0, 0.0), z=(0.0, 0.0, 1.0),
        x=(1.0, 1.0, 0.0), k_trans=(1000.0, 2000.0, 3000.0),
        k_rot=(1e6 * deg, 2e6 * deg, 3e6 * deg), cubic_trans=5.0,
        cubic_rot=(0.0, 0.0, 2000.0 * deg**3), offset_trans=(0.1, 0.0, 0.0),
        offset_rot=(0.0, math.radians(0.5), 0.0), preload_force=(0.0, 0.0, 50.0),
        preload_torque=(0.0, 1000.0, 0.0),
        splines={"tz": ([-2.0, -1.0, 0.0, 1.0, 2.0], [6000.0, 3000.0, 0.0, -3000.0, -6000.0]),
                 "rx": (np.radians([-10.0, -5.0, 0.0, 5.0, 10.0]),
                        [1e5, 5e4, 0.0, -5e4, -1e5])},
    )
    b.spring("lift_spring", parts=("slider", "ground"), at=((0.0, 500.0, 100.0),
                                                            (0.0, 500.0, -200.0)),
             table=([-50.0, 0.0, 50.0, 100.0], [-1000.0, 0.0, 1200.0, 3000.0]),
             free_length=250.0)
    b.stop("bump", "slider_top", "stop_seat", kind="bump", length=60.0, k=500.0, cubic=0.1)
    b.driver("lift", marker="slider_top", direction=(0.0, 1.0, 2.0))
    b.load_point("tip", marker="arm_frame", frame="arm_frame")
    b.load_point("contact_patch", part="slider", at=(0.0, 500.0, 100.0))
    return b


FEATURE_RIG_SI = """\
# A rig with one of everything, in m, kN and deg. Comments everywhere must not matter.
diffsusp = 1
name = "feature rig"
parts = [
    "arm",     # on a bushing with splines
    "slider",  # on a translational joint, driven
]

[units]
length = "m"
force = "kN"
angle = "deg"

[markers.arm_frame]
part = "arm"
position = [-0.3, 0, 0]
axes = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]   # x, y, z

[markers.arm_reuler]
part = "arm"
position = [-0.15, 0.01, 0]
reuler = [10, 20, 30]

[markers.slider_top]
part = "slider"
position = [0, 0.5, 0.1]

[markers.stop_seat]
part = "ground"
position = [0, 0.5, 0.02]

[bushings.pivot]
parts = ["arm", "ground"]
at = [0, 0, 0]
z = [0, 0, 1]
x = [1, 1, 0]
k_trans = [1000, 2000, 3000]      # kN/m = N/mm
k_rot = [1, 2, 3]                 # kN·m/deg
cubic_trans = 5e6                 # kN/m³ = 5 N/mm³
cubic_rot = [0, 0, 0.002]         # kN·m/deg³
offset_trans = [0.0001, 0, 0]     # 0.1 mm
offset_rot = [0, 0.5, 0]          # deg
preload_force = [0, 0, 0.05]      # 50 N
preload_torque = [0, 0.001, 0]    # 1000 N·mm

[bushings.pivot.splines.tz]
x = [-0.002, -0.001, 0, 0.001, 0.002]   # m
y = [6, 3, 0, -3, -6]                   # kN

[bushings.pivot.splines.rx]
x = [-10, -5, 0, 5, 10]                 # deg
y = [0.1, 0.05, 0, -0.05, -0.1]         # kN·m

[joints.slide]
kind = "translational"
parts = ["slider", "ground"]
at = [0, 0.5, 0]
z = [0, 0, 1]
x = [1, 0, 0]

[springs.lift_spring]
parts = ["slider", "ground"]
at = [[0, 0.5, 0.1], [0, 0.5, -0.2]]
free_length = 0.25
table = {x = [-0.05, 0, 0.05, 0.1], y = [-1, 0, 1.2, 3]}

[stops.bump]
i = "slider_top"
j = "stop_seat"
kind = "bump"
length = 0.06
k = 500          # kN/m
cubic = 1e5      # kN/m³ = 0.1 N/mm³

[drivers.lift]
marker = "slider_top"
direction = [0, 1, 2]   # normalised on load

[load_points.tip]
marker = "arm_frame"
frame = "arm_frame"

[load_points.contact_patch]
part = "slider"
at = [0, 0.5, 0.1]

# Forces in the file's kN unless a column says otherwise; fz is the contact patch's.
[load_tables.steps]
columns = ["case", "tip.fx", "tip.mz [N*mm]", "fz", "lift"]
rows = [
    [1, 0.1, 2000, 0.5, 0.01],
    [2, -0.2, 0, 1.5, -0.02],   # a comment inside the table
]
"""


@pytest.fixture(scope="module")
def feature_rig():
    # Validation of this one-off model would compile its Jacobian twice (builder and file differ
    # in the last bits of static reference points): compare the mechanisms before it.
    with _no_validation():
        mech = _feature_rig().build()
    return mech


@pytest.fixture
def no_validation():
    with _no_validation():
        yield


def test_hand_written_file_with_every_feature_equals_the_builder(feature_rig, no_validation):
    mf = model_from_toml(FEATURE_RIG_SI, path="rig.toml")
    assert mf.units == {"length": "m", "force": "kN", "angle": "deg"}
    assert_same_model(mf.mechanism, feature_rig)
    # Static structure: spline axes, tabulated spring, stop kind, load-point frame.
    mech = mf.mechanism
    assert mech.bushings.spline_axes == ((False, False, True, True, False, False),)
    assert mech.springs.tabulated == (True,)
    assert mech.stops.kind == ("bump",)
    assert mech.load_points.frame == (mech.markers.index("arm_frame"), -1)
    np.testing.assert_allclose(mech.drivers.direction[0], np.array([0, 1, 2]) / math.sqrt(5),
                               rtol=1e-15)
    expected = feature_rig.loads(
        forces={"tip": [[100.0, 0, 0], [-200.0, 0, 0]],
                "contact_patch": [[0, 0, 500.0], [0, 0, 1500.0]]},
        moments={"tip": [[0, 0, 2000.0], [0, 0, 0]]},
        drivers={"lift": [10.0, -20.0]},
    )
    got = loads_from_table(mech, mf.load_tables["steps"])
    for x, y in zip(jax.tree.leaves(got), jax.tree.leaves(expected), strict=True):
        np.testing.assert_allclose(x, y, rtol=1e-15)


def test_save_is_exact_for_any_driver_direction_and_keeps_comments(feature_rig, tmp_path,
                                                                   no_validation):
    path = tmp_path / "rig.toml"
    path.write_text(FEATURE_RIG_SI, encoding="utf-8")
    mech = load_model(path)
    stiffer = eqx.tree_at(lambda m: m.bushings.k_trans, mech, mech.bushings.k_trans * 2)
    save_model(stiffer, path)  # over the hand-written file
    text = path.read_text(encoding="utf-8")
    for comment in ("# A rig with one of everything", "# on a bushing with splines",
                    "# normalised on load", "# a comment inside the table",
                    "# Forces in the file's kN unless a column says otherwise"):
        assert comment in text
    assert 'length = "mm"' in text
    mf = load_model_file(path)
    assert_identical(mf.mechanism, stiffer)
    # The kept load table was in kN and m: its columns now say so, the values did not move.
    assert "tip.fx [kN]" in text and "lift [m]" in text
    got = loads_from_table(mf.mechanism, mf.load_tables["steps"])
    np.testing.assert_allclose(got.force[:, 0, 0], [100.0, -200.0], rtol=1e-15)
    np.testing.assert_allclose(got.driver[:, 0], [10.0, -20.0], rtol=1e-15)
    # Saved in other units, it reads back to the same model (to rounding).
    save_model(stiffer, tmp_path / "si.toml", units={"length": "m", "force": "kN",
                                                      "angle": "deg"})
    assert_same_model(load_model(tmp_path / "si.toml"), stiffer)


def test_every_bit_survives_save_and_load(tmp_path, no_validation):
    """-0.0, subnormals and orientations that z alone does not rebuild are written exactly."""
    b = MechanismBuilder("bits")
    b.part("p")
    tilted = frame_from_axes(z=(0.1, 0.2, 0.97), x=(1.0, 0.0, 0.0))
    b.marker("m", "p", (-0.0, 5e-324, 1.0 / 3.0),
             orientation=np.array([[1.0, -0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
    b.marker("n", "ground", (0.0, 0.0, 0.0), orientation=tilted)
    b.bushing("bu", "m", "n", k_trans=(1.0, 2.0, 3.0), k_rot=1e-300,
              preload_force=(-0.0, 0.0, 0.0))
    b.driver("d", marker="m", direction=(0.3, -0.4, 1.1))
    mech = b.build()
    save_model(mech, tmp_path / "bits.toml")
    text = (tmp_path / "bits.toml").read_text()
    assert "position = [-0.0, 5e-324, 0.3333333333333333]" in text
    assert "preload_force = [-0.0, 0.0, 0.0]" in text
    assert_identical(load_model(tmp_path / "bits.toml"), mech)


def test_loading_a_commented_shipped_file_edited_by_hand(zoo):
    text = (DATA / "isolated_bushing.toml").read_text(encoding="utf-8")
    edited = text.replace("[bushings.bush]\n", "# the only bushing\n[bushings.bush]  # BUSHING/1\n")
    edited = edited.replace("k_trans = [100.0, 100.0, 100.0]",
                            "k_trans = 250 # stiffer, one value for the three axes")
    assert edited.count("#") == text.count("#") + 3
    mech = model_from_toml(edited).mechanism
    ref = zoo["isolated_bushing"]
    assert_same_model(mech, eqx.tree_at(lambda m: m.bushings.k_trans, ref,
                                        jnp.full((1, 3), 250.0)), rtol=1e-15)


# ------------------------------------------------------------------------ errors


def _error(text: str) -> ModelFileError:
    with pytest.raises(ModelFileError) as info:
        model_from_toml(text, path="bad.toml")
    return info.value


def _line_of(text: str, needle: str) -> int:
    return next(n for n, line in enumerate(text.splitlines(), 1) if needle in line)


BAD_EDITS = [
    # (replace, by, expected message, line containing, field)
    ("k_trans = 100 ", "k_trans = \"100\" ", "expected a number; got the string '100'",
     "k_trans =", "bushings.bush.k_trans"),
    ("k_rot = 0.01 ", "k_rot = nan ", "expected a finite number", "k_rot =",
     "bushings.bush.k_rot"),
    ("k_rot = 0.01 ", "k_rot = 1e400 ", "expected a finite number", "k_rot =",
     "bushings.bush.k_rot"),
    ("k_rot = 0.01 ", "k_rot = 1e20 ", "out of range", "k_rot =", "bushings.bush.k_rot"),
    ("k_rot = 0.01 ", "k_rot = 99999999999999999999999999999999999 ", "out of range",
     "k_rot =", "bushings.bush.k_rot"),
    ("k_rot = 0.01 ", "k_rott = 0.01 ", "unknown key 'k_rott'; allowed keys here: i, j",
     "k_rott =", "bushings.bush.k_rott"),
    ("k_rot = 0.01 ", "k_rot = [1, 2] ", "a number or a list of 3 numbers", "k_rot =",
     "bushings.bush.k_rot"),
    ('length = "m" ', 'length = "furlong" ', "unknown length unit 'furlong'; use one of mm",
     "furlong", "units.length"),
    ('parts = ["arm", "ground"]', 'parts = ["arm", "chassis"]', "unknown part 'chassis'",
     "[bushings.bush]", "bushings.bush"),
    ("at = [-0.3, 0, 0]", "at = [-0.3, 0, 0]\nmarker = \"tip\"", "give a marker, or part",
     'marker = "tip"', "load_points.tip.marker"),
    ("reuler = [", "z = [0, 0, 1]\nreuler = [", "give one orientation: reuler or z",
     "z = [0, 0, 1]", "bushings.bush.z"),
    ("[load_points.centre]", "[load_point.centre]", "unknown key or section 'load_point'",
     "[load_point.centre]", "load_point"),
    ("diffsusp = 1", "diffsusp = 3", "format version 3 is not supported", "diffsusp = 3",
     "diffsusp"),
    ("[load_points.centre]", "[[corner]]\nwheel_centre = \"tip\"\n[load_points.centre]",
     "[[corner]] tables need format version 2", "[[corner]]", "corner"),
    ("at = [-0.3, 0, 0]", "at = [-0.3, 0, 0]\nat = 1", "not valid TOML", "at = 1", None),
    ("[units]", "[units", "not valid TOML", "[units", None),
]


@pytest.mark.parametrize("old,new,message,needle,field", BAD_EDITS)
def test_errors_name_the_file_line_and_field(old, new, message, needle, field):
    assert old in ISOLATED_BUSHING_SI
    text = ISOLATED_BUSHING_SI.replace(old, new, 1)
    e = _error(text)
    assert message in str(e)
    assert e.path == "bad.toml"
    assert e.line == _line_of(text, needle), str(e)
    assert e.field == field
    assert str(e).startswith(f"bad.toml:{e.line}")
    assert e.bad_input


def test_missing_sections_and_keys():
    no_units = re.sub(r"\[units\].*?angle = \"deg\"[^\n]*\n", "", ISOLATED_BUSHING_SI,
                      flags=re.S)
    e = _error(no_units)
    assert "missing [units]" in str(e) and e.line == 1
    no_parts = ISOLATED_BUSHING_SI.replace('parts = ["arm"]', "")
    assert "missing 'parts'" in str(_error(no_parts))
    e = _error(ISOLATED_BUSHING_SI.replace('angle = "deg"', ""))
    assert "[units] is missing 'angle'" in str(e)
    e = _error(ISOLATED_BUSHING_SI.replace("k_trans = 100 ", ""))
    assert "missing required key 'k_trans'" in str(e)
    assert e.line == _line_of(ISOLATED_BUSHING_SI, "[bushings.bush]")
    with pytest.raises(ModelFileError, match=r"bad\.toml:3: byte 0xff is not UTF-8"):
        model_from_toml(b"a = 1\nb = 2\n\xff\n", path="bad.toml")


def test_unsolvable_model_is_a_located_error_with_exit_code_4():
    # A spherical joint whose markers do not coincide at design.
    text = """\
parts = ["link"]
[units]
length = "mm"
force = "N"
angle = "rad"
[markers.a]
part = "link"
position = [0, 0, 0]
[markers.b]
part = "ground"
position = [1, 0, 0]

[joints.ball]
kind = "spherical"
i = "a"
j = "b"
"""
    e = _error(text)
    assert "joint 'ball' (spherical) row 0 is violated by 1 mm at design" in str(e)
    assert e.line == _line_of(text, "[joints.ball]")
    assert isinstance(e, ModelError) and not e.bad_input  # the CLI maps it to 4
    # Free rotations of the link about the ball joint: loaded without checks for `info`.
    free = text.replace("[1, 0, 0]", "[0, 0, 0]")
    with pytest.raises(ModelFileError, match="free: rotation"):
        model_from_toml(free)
    assert model_from_toml(free, check=False).mechanism.joints.names == ("ball",)


def test_load_table_errors(no_validation):
    bad_column = FEATURE_RIG_SI.replace('"lift"]', '"lifts"]')
    e = _error(bad_column)
    assert "unknown column 'lifts' for this model; valid columns: tip.fx" in str(e)
    assert e.line == _line_of(bad_column, "columns = ")
    ragged = FEATURE_RIG_SI.replace("[2, -0.2, 0, 1.5, -0.02]", "[2, -0.2, 0, 1.5]")
    assert "row 2 must be a list of 5 numbers" in str(_error(ragged))
    text = FEATURE_RIG_SI.replace("[2, -0.2, 0, 1.5, -0.02]", '[2, -0.2, 0, "x", -0.02]')
    assert "expected a number; got the string 'x'" in str(_error(text))
    text = FEATURE_RIG_SI.replace('"tip.mz [N*mm]"', '"tip.mz [N]"')
    assert "unit 'N' is not a moment unit" in str(_error(text))


# ------------------------------------------------------------------------ nothing executes


def test_reading_never_executes_anything(tmp_path):
    marker = tmp_path / "pwned"
    payload = f"__import__('os').system('touch {marker}')"
    text = ISOLATED_BUSHING_SI.replace('name = "isolated bushing (model_exemple11)"',
                                       f'name = "{payload}"')

    def forbidden(*args, **kwargs):
        raise AssertionError("reading a model file must not execute code")

    with mock.patch.object(builtins, "eval", forbidden), \
            mock.patch.object(builtins, "exec", forbidden), \
            mock.patch.object(subprocess, "Popen", forbidden), \
            mock.patch.object(os, "system", forbidden):
        mech = model_from_toml(text).mechanism
        with pytest.raises(ModelFileError, match="expected a number; got the string"):
            model_from_toml(ISOLATED_BUSHING_SI.replace("k_trans = 100 ",
                                                        'k_trans = "50 * 2" '))
    assert mech.name == payload  # just text
    assert not marker.exists()


# ------------------------------------------------------------------------ fuzzing

SMALL = (DATA / "isolated_bushing.toml").read_text(encoding="utf-8")
SMALL_LINES = SMALL.count("\n") + 1
TOKENS = ["nan", "inf", "-inf", "1e400", "-1e309", "1e20", "1e15", "0", "-0.0", "1e-320",
          "99999999999999999999999999", "\"\"", "[]", "{}", "true", "[[", "]", "=", "\n",
          "[markers]", "\"bush.i\"", "'", "\\", "1979-05-27", "\x00", "é", "#"]


def _no_validation():
    """Replace the build-time validation by the identity: each fuzzed file that parses is a new
    static structure, and validating it would trace a Jacobian per example."""
    return mock.patch.object(importlib.import_module("diffsusp.model.builder"), "finalize",
                             lambda mech, check=True: mech)


def _loads_or_located_error(data, lines: bool = True):
    try:
        mf = model_from_toml(data, path="fuzz.toml")
    except ModelFileError as e:
        if lines:
            assert e.line is not None and e.line >= 1, str(e)
        return None
    # Loaded: a whole model (every part, marker and element named in the file is there).
    mech = mf.mechanism
    assert mech.parts and all(np.all(np.isfinite(np.asarray(x))) for x in jax.tree.leaves(mech))
    return mech


FUZZ = settings(max_examples=120, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@FUZZ
@given(st.binary(max_size=400))
def test_fuzz_random_bytes(data):
    with _no_validation():
        _loads_or_located_error(data)


@FUZZ
@given(st.integers(0, len(SMALL)))
def test_fuzz_truncated_files(cut):
    text = SMALL[:cut]
    with _no_validation():
        mech = _loads_or_located_error(text)
    if mech is not None:  # what loaded is every section the cut left, nothing less
        for section, names in (("markers", mech.markers.names),
                               ("bushings", mech.bushings.names),
                               ("load_points", mech.load_points.names)):
            assert len(re.findall(rf"^\[{section}\.", text, flags=re.M)) == len(names)


@st.composite
def _mutations(draw):
    text = SMALL
    for _ in range(draw(st.integers(1, 4))):
        pos = draw(st.integers(0, len(text)))
        kind = draw(st.sampled_from(["insert", "delete", "replace", "token", "number",
                                     "section"]))
        if kind == "insert":
            text = text[:pos] + draw(st.text(string.printable, min_size=1, max_size=3)) \
                + text[pos:]
        elif kind == "delete":
            text = text[:pos] + text[pos + draw(st.integers(1, 20)):]
        elif kind == "replace":
            text = text[:pos] + draw(st.sampled_from(string.printable)) + text[pos + 1:]
        elif kind == "token":
            text = text[:pos] + draw(st.sampled_from(TOKENS)) + text[pos:]
        elif kind == "number":
            numbers = list(re.finditer(r"-?\d+\.\d+(?:e[-+]?\d+)?", text))
            if numbers:
                m = numbers[draw(st.integers(0, len(numbers) - 1))]
                text = text[:m.start()] + draw(st.sampled_from(TOKENS[:11])) + text[m.end():]
        else:  # drop a whole section, header to next header
            headers = [m.start() for m in re.finditer(r"^\[", text, flags=re.M)]
            if headers:
                k = draw(st.integers(0, len(headers) - 1))
                end = headers[k + 1] if k + 1 < len(headers) else len(text)
                text = text[:headers[k]] + text[end:]
    return text


@FUZZ
@given(_mutations())
def test_fuzz_mutated_files(text):
    with _no_validation():
        _loads_or_located_error(text)


@settings(max_examples=5, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_mutations())
def test_fuzz_mutated_files_end_to_end(text):
    """With the real validation (free modes, assembly): still only ModelFileError."""
    _loads_or_located_error(text)


def test_huge_file_does_not_hang():
    rows = "\n".join(f"[markers.m{k}]\npart = \"arm\"\nposition = [{k}, 0, 0]"
                     for k in range(1000))
    text = SMALL + "\n" + rows + "\n[joints.j]\nkind = \"spherical\"\ni = \"m1\"\nj = \"nope\"\n"
    e = _error(text)
    assert "unknown marker 'nope'" in str(e)
    assert e.line == _line_of(text, "[joints.j]")


def test_generator_script_writes_every_builtin(tmp_path, monkeypatch):
    import diffsusp.models._write_data as writer

    monkeypatch.setattr(writer, "DATA", str(tmp_path))
    monkeypatch.setattr(writer, "model_text", lambda name: f"# {name}\n")
    writer.main()
    assert sorted(os.listdir(tmp_path)) == sorted(f"{n}.toml" for n in ZOO)
    assert (tmp_path / "crank_slider.toml").read_text() == "# crank_slider\n"


# ------------------------------------------------------------------------ corners (format 2)

CORNER = """
[[corner]]
wheel_centre = "tip.m"
contact_point = "tip"
wheel_centre_load = false
kingpin = ["tip.m", {part = "arm", offset = [0, 0, 0.1]}]
frame = "iso"
loaded_radius = 0.3
design_load = 4.5
"""


def test_corner_table_in_file_units_and_old_files():
    """A `[[corner]]` table (format 2) in the file's units (m, kN); a version-1 file states no
    corner, and K&C says so rather than guessing from the model's name."""
    from diffsusp import kc
    from diffsusp.errors import InputError
    from diffsusp.model.corner import Corner

    text = ISOLATED_BUSHING_SI.replace("diffsusp = 1", "diffsusp = 2") + CORNER
    mech = model_from_toml(text, path="c.toml", check=False).mechanism
    assert mech.corners == (Corner(
        wheel_centre="tip.m", contact_point="tip", wheel_centre_load=None,
        kingpin=("tip.m", ("arm", (0.0, 0.0, 100.0))), frame="iso", loaded_radius=300.0,
        design_load=4500.0),)
    old = model_from_toml(ISOLATED_BUSHING_SI, path="old.toml", check=False).mechanism
    assert old.corners == ()
    with pytest.raises(InputError, match="version-1 native file"):
        kc.default_corner(old)
    bad = text.replace('wheel_centre = "tip.m"', 'wheel_centre = "hub"')
    with pytest.raises(ModelFileError, match="'hub' is not in the model"):
        model_from_toml(bad, path="bad.toml", check=False)
