"""Tests of the built-in models (diffsusp.models): structure (DOF, rank, redundancy, free modes),
closed forms, convergence on the thesis load cases, and physically sensible responses.

Building a model validates it (a compiled Jacobian), and each new model structure or load-table
shape compiles the solver once, so every model is built once per module and solves reuse a
compiled table shape where they can."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffsusp
from diffsusp.geometry import matrix_to_rotvec, reuler_deg_to_matrix
from diffsusp.models import (
    DOUBLE_WISHBONE_DESIGN_LOAD,
    TABLE_4_4,
    TABLE_5_1,
    ZOO,
    thesis_load_cases,
)
from diffsusp.models._isolated_bushing import ISOLATED_BUSHING_REULER_DEG
from diffsusp.models._pseudo_mcpherson import SPRING_FREE_LENGTH, _builder

# name: (coordinates, constraint rows, rank, kinematic DOF, redundant rows)
EXPECTED_STRUCTURE = {
    "isolated_bushing": (6, 0, 0, 6, ()),
    "isolated_bushing_10000": (6, 0, 0, 6, ()),
    "crank_slider": (18, 18, 17, 1, ("joint 'slide' (translational) row 4",)),
    "two_bushing_coupler": (18, 10, 10, 8, ()),
    "pseudo_mcpherson": (24, 12, 12, 12, ()),
    "pseudo_mcpherson_wheel_travel": (24, 13, 13, 11, ()),
    "double_wishbone": (18, 17, 17, 1, ()),
    "double_wishbone_bushings": (18, 7, 7, 11, ()),
}


class _Zoo:
    """Builds each model once, on first use."""

    def __init__(self):
        self._built = {}

    def __getitem__(self, name):
        if name not in self._built:
            self._built[name] = ZOO[name]()
        return self._built[name]


@pytest.fixture(scope="module")
def zoo():
    return _Zoo()


def _marker_position(mech, q, name):
    pos, _ = diffsusp.marker_poses(mech, q)
    return pos[..., mech.markers.index(name), :]


def _part_rotation(mech, q, part):
    rot, _ = diffsusp.part_poses(mech, q)
    return rot[..., mech.part_index(part), :, :]


# ----------------------------------------------------------------------------- structure


def test_zoo_is_covered():
    assert set(ZOO) == set(EXPECTED_STRUCTURE)


def test_describe_is_plain_data_naming_every_element(zoo):
    """`describe` lists the joints with their marker names, the element names and the corner
    (side resolved, kingpin ends) of the pseudo-McPherson axle, as JSON-ready data."""
    import json

    mech = zoo["pseudo_mcpherson"]
    d = diffsusp.model.describe(mech)
    assert json.loads(json.dumps(d)) == d
    assert d["name"] == mech.name and d["parts"] == list(mech.parts)
    assert d["markers"] == len(mech.markers.names)
    assert [(j["name"], j["kind"]) for j in d["joints"]] == [
        ("tie_rod", "distance"), ("strut_slide", "translational"),
        ("rear_ball_joint", "spherical"), ("front_ball_joint", "spherical")]
    assert all((j["i"], j["j"]) == (j["name"] + ".i", j["name"] + ".j") for j in d["joints"])
    assert sorted(d["bushings"]) == ["bushing_A", "bushing_B", "bushing_F"]
    assert (d["springs"], d["stops"], d["drivers"]) == (["spring"], [], [])
    assert sorted(d["load_points"]) == ["contact_patch", "wheel_centre"]
    (corner,) = d["corners"]
    assert (corner["side"], corner["frame"], corner["wheel_centre"], corner["contact_point"]) \
        == ("left", "adams", "wheel_centre", "contact_patch")
    top, bottom = corner["kingpin"]
    assert top == "L4_strut_top" and bottom["part"] == "hub_carrier"
    assert len(bottom["offset"]) == 3


@pytest.mark.parametrize("name", list(EXPECTED_STRUCTURE))
def test_structure(zoo, name):
    mech = zoo[name]
    report = diffsusp.validate(mech)
    n, rows, rank, dof, redundant = EXPECTED_STRUCTURE[name]
    assert (report.n_coordinates, report.n_rows, report.rank, report.dof) == (n, rows, rank, dof)
    assert report.redundant == redundant
    assert report.free_modes == ()
    assert report.max_assembly_error < 1e-9
    assert len(mech.independent_rows) == rank


def test_crank_slider_solves_with_its_redundant_row_dropped(zoo):
    """18 rows, n = 18, 1 DOF (structure in `test_structure`): with the redundant row dropped
    the equilibrium solves, and the slider moves only along its axis, so the bushing deforms
    only along x (its only identifiable direction)."""
    mech = zoo["crank_slider"]
    assert len(mech.independent_rows) == 17
    force = jnp.array([[0.0, 1000.0, 0.0], [800.0, -500.0, 300.0]])
    loads = mech.loads(forces={"crank_pin": force})
    sol = diffsusp.solve_statics(mech, loads)
    assert bool(jnp.all(sol.converged))
    delta_t, angles, _, _ = diffsusp.bushing_states(mech, sol.q)
    assert np.all(np.abs(np.asarray(delta_t[:, 0, 0])) > 1e-3)
    np.testing.assert_allclose(delta_t[:, 0, 1:], 0.0, atol=1e-9)
    np.testing.assert_allclose(angles[:, 0], 0.0, atol=1e-12)


# ----------------------------------------------------------------------------- closed form


@pytest.mark.parametrize("name, k_trans", [("isolated_bushing", 100.0),
                                           ("isolated_bushing_10000", 10000.0)])
def test_isolated_bushing_closed_form(zoo, name, k_trans):
    """Force F and moment M at the bushing centre: δ_T = R_Jᵀ F / K and projected angles
    R_Jᵀ M / K_T exactly (spec stiffness §7 R1), in the rotated bushing frame J."""
    mech = zoo[name]
    k_rot = 10000.0 * 180.0 / np.pi
    force = np.array([300.0, -200.0, 500.0])
    moment = np.array([2e4, -1e4, 3e4])
    sol = diffsusp.solve_statics(
        mech, mech.loads(forces={"centre": force}, moments={"centre": moment}), rtol=1e-13
    )
    r_j = np.asarray(reuler_deg_to_matrix(jnp.asarray(ISOLATED_BUSHING_REULER_DEG)))
    delta_t, angles, _, _ = diffsusp.bushing_states(mech, sol.q)
    np.testing.assert_allclose(delta_t[0], r_j.T @ force / k_trans, rtol=0, atol=1e-12)
    np.testing.assert_allclose(angles[0], r_j.T @ moment / k_rot, rtol=0, atol=1e-12)
    # The arm translates by F/K in the global frame.
    np.testing.assert_allclose(_marker_position(mech, sol.q, "centre.m"), force / k_trans,
                               rtol=0, atol=1e-12)


# ----------------------------------------------------------------------------- load tables


def test_load_tables_and_mapping(zoo):
    assert TABLE_5_1.shape == (13, 3) and TABLE_4_4.shape == (17, 3)
    assert np.all(TABLE_5_1[:, 0] >= 1500) and np.all(TABLE_4_4[:, 0] >= 1500)
    mech = zoo["pseudo_mcpherson"]
    loads = thesis_load_cases(mech, TABLE_4_4)
    k = mech.load_points.index("contact_patch")
    np.testing.assert_array_equal(loads.force[:, k], TABLE_4_4[:, ::-1])
    assert loads.force.shape[0] == 17 and not np.any(np.asarray(loads.moment))
    with pytest.raises(ValueError, match="shape"):
        thesis_load_cases(mech, TABLE_5_1[:, :2])


# ----------------------------------------------------------------------------- pseudo-McPherson


@pytest.fixture(scope="module")
def mcpherson_table_5_1(zoo):
    mech = zoo["pseudo_mcpherson"]
    return mech, diffsusp.solve_statics(mech, thesis_load_cases(mech, TABLE_5_1))


def test_pseudo_mcpherson_table_5_1_converges(mcpherson_table_5_1):
    mech, sol = mcpherson_table_5_1
    assert bool(jnp.all(sol.converged))
    travel = np.asarray(_marker_position(mech, sol.q, "wheel_centre")) - [0.0, -787.0, 305.0]
    # Vertical cases 1500..7500 N: the wheel centre rises with the load; no stops are modelled,
    # so the travel is large at the ends (values documented in `pseudo_mcpherson`).
    assert np.all(np.diff(travel[:5, 2]) > 20.0)
    np.testing.assert_allclose(travel[[0, 4], 2], [-137.8, 102.3], atol=0.5)
    # Longitudinal force along +x (rearward) moves the wheel rearward, symmetric in sign.
    assert travel[12, 0] > travel[11, 0] > 0.0 > travel[10, 0] > travel[9, 0]
    # Lateral force along +y moves the wheel centre toward +y.
    assert travel[8, 1] > travel[5, 1]
    # Bushing rotations stay within the projected angles' validity (15°, 15°, 90°).
    _, angles, _, _ = diffsusp.bushing_states(mech, sol.q)
    assert np.all(np.abs(np.degrees(angles[..., :2])) < 15.0)
    assert np.all(np.abs(np.degrees(angles[..., 2])) < 90.0)


def test_pseudo_mcpherson_spring_free_length(mcpherson_table_5_1):
    """The reconstructed free length keeps the wheel centre at its design height under the
    4500 N design load (Table 5-1 case 3)."""
    mech, sol = mcpherson_table_5_1
    assert float(mech.springs.free_length[0]) == SPRING_FREE_LENGTH
    z = float(_marker_position(mech, sol.q[2], "wheel_centre")[2])
    assert abs(z - 305.0) < 0.05


def test_pseudo_mcpherson_wheel_travel_is_the_softest_mode(zoo):
    """1 DOF per wheel: condensed onto the hub carrier (wheel-centre translation and rotation ×
    305 mm, against force and moment / 305 mm at the wheel centre), the design-load compliance's
    softest mode is the vertical wheel travel, well apart from the next one. Central
    differences of 13 equilibria (the Table 5-1 shape, so the solve is not recompiled)."""
    mech = zoo["pseudo_mcpherson"]
    radius, h = 305.0, 10.0
    contact = np.tile([0.0, 0.0, 4500.0], (13, 1))
    force, moment = np.zeros((13, 3)), np.zeros((13, 3))
    for k in range(6):
        for sign, row in ((1.0, 1 + 2 * k), (-1.0, 2 + 2 * k)):
            (force if k < 3 else moment)[row, k % 3] = sign * h * (1.0 if k < 3 else radius)
    loads = mech.loads(forces={"contact_patch": contact, "wheel_centre": force},
                       moments={"wheel_centre": moment})
    sol = diffsusp.solve_statics(mech, loads)
    centre = _marker_position(mech, sol.q, "wheel_centre")
    rot = _part_rotation(mech, sol.q, "hub_carrier")
    turn = jax.vmap(lambda r: matrix_to_rotvec(r @ rot[0].T))(rot)
    u = np.asarray(jnp.concatenate([centre, radius * turn], axis=1))
    compliance = np.stack([(u[1 + 2 * k] - u[2 + 2 * k]) / (2 * h) for k in range(6)], axis=1)
    np.testing.assert_allclose(compliance, compliance.T, atol=1e-6)
    w, v = np.linalg.eigh(0.5 * (compliance + compliance.T))
    softest = v[:, -1]
    assert abs(softest[2]) > 0.95  # vertical wheel-centre motion
    assert 20.0 < 1.0 / w[-1] < 30.0  # wheel rate (N/mm)
    assert w[-1] / w[-2] > 5.0  # next mode (longitudinal compliance) is much stiffer


def test_pseudo_mcpherson_free_modes_detected():
    """The two motions the model removes are free in the physical topology: a tie-rod part
    between two ball joints spins about its axis (exactly free), and with a cylindrical strut
    joint the strut spins about its axis (bushing F has Krz = 0; nearly free with the Table
    2.2 poses, whose misalignments give it ~10 N·mm/deg, so it shows at tol=1e-5)."""
    builder = _builder(False, SPRING_FREE_LENGTH, tie_rod_part=True, strut_joint="cylindrical")
    mech = builder.build(check=False)
    report = diffsusp.validate(mech, tol=1e-5)
    assert (report.n_coordinates, report.rank, report.dof) == (30, 16, 14)
    assert len(report.free_modes) == 2
    tie_rod = next(f for f in report.free_modes if f.startswith("part 'tie_rod' is free"))
    strut = next(f for f in report.free_modes if f.startswith("part 'strut' is free"))

    def axis(text):
        inside = text.split("rotation about axis (")[1].split(")")[0]
        return np.array([float(c) for c in inside.split(",")])

    p = mech.markers.position
    tie_axis = np.asarray(p[mech.markers.index("L6_tie_rod_outer")]
                          - p[mech.markers.index("L3_tie_rod_inner")])
    slide_axis = np.asarray(mech.markers.orientation[mech.markers.index("strut_slide.j")][:, 2])
    assert abs(axis(tie_rod) @ tie_axis) / np.linalg.norm(tie_axis) > 0.999
    assert abs(axis(strut) @ slide_axis) > 0.999


# ----------------------------------------------------------------------------- double wishbone


@pytest.mark.parametrize("name", ["double_wishbone", "double_wishbone_bushings"])
def test_double_wishbone_converges(zoo, name):
    """Vertical 0.5–1.5× the design load and ±4000 N lateral at the design load."""
    mech = zoo[name]
    f0 = DOUBLE_WISHBONE_DESIGN_LOAD
    vertical = f0 * np.array([0.5, 0.75, 1.0, 1.25, 1.5])
    table = np.concatenate([np.c_[vertical, np.zeros((5, 2))],
                            [[f0, -4000.0, 0.0], [f0, 4000.0, 0.0]]])
    sol = diffsusp.solve_statics(mech, thesis_load_cases(mech, table))
    assert bool(jnp.all(sol.converged))
    travel = np.asarray(_marker_position(mech, sol.q, "wheel_centre")) - [-40.0, 1100.0, -26.0]
    assert np.all(np.diff(travel[:5, 2]) > 10.0)
    if name == "double_wishbone":
        # The design position is the equilibrium under the design load.
        np.testing.assert_allclose(sol.q[2], 0.0, atol=1e-6)
    else:
        assert np.linalg.norm(travel[2]) < 5.0
