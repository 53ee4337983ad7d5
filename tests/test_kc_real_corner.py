"""K&C on real corners by default. A compliant corner's design load: the vertical contact load
that holds the wheel centre at its design height, solved through the statics (any number of
DOF), and the force events that use it by default. On the Chrono double wishbone with `Bushing
Data` (11 DOF) the old virtual-work estimate at the design position (one load for every
generalised-force row, by least squares) gave a negative load, the wheel 117 mm below design
and a lateral compliance steer 4.5 times too large; on the one-DOF double wishbone both are
exact and agree.

The frames of the model read where a default depends on them (`with_rack`).

One model structure per file, one lateral-force program shared by the CLI run and the library."""

import json
import pathlib

import numpy as np
import pytest
from typer.testing import CliRunner

import diffsusp
import diffsusp.cli.kc  # noqa: F401  (registers `kc`)
from diffsusp import kc, load_model
from diffsusp.cli import app
from diffsusp.kc.corner import equilibrium_load
from diffsusp.model import Loads

DATA = pathlib.Path(__file__).parent / "data"
BUSHINGS = DATA / "DoubleWishbone_bushings.json"
RIGID = DATA / "chrono" / "DoubleWishbone.json"
FORCE = "-4000:4000:17"


@pytest.fixture(scope="module")
def bushings():
    return load_model(str(BUSHINGS))


def _virtual_work(mech, point="contact_patch"):
    """The old estimate: least-squares (F, λ) of Q0 + F·Q1 + Φ_qᵀλ = 0 at the design position."""
    from diffsusp.kc.rig import remove_drivers
    from diffsusp.statics.validation import design_terms

    base = remove_drivers(mech, mech.drivers.names)
    n, n_l = base.n_coordinates, len(base.load_points.names)
    zero, unit = np.zeros((n_l, 3)), np.zeros((n_l, 3))
    unit[base.load_points.index(point), 2] = 1.0
    r0 = design_terms(base, Loads(force=zero, moment=zero, driver=np.zeros(0)))[1][:n]
    _, r1, jac = design_terms(base, Loads(force=unit, moment=zero, driver=np.zeros(0)))
    return float(np.linalg.lstsq(np.column_stack([r1[:n] - r0, jac[:n, n:]]), -r0,
                                 rcond=None)[0][0])


def _height_at(mech, f0):
    n_l = len(mech.load_points.names)
    force = np.zeros((1, n_l, 3))
    force[0, mech.load_points.index("contact_patch"), 2] = f0
    from diffsusp.kc.rig import remove_drivers

    base = remove_drivers(mech, mech.drivers.names)
    sol = diffsusp.solve_statics(base, Loads(force=force, moment=np.zeros_like(force),
                                             driver=np.zeros((1, 0))), checks=False)
    pos, _ = diffsusp.marker_poses(base, sol.q)
    wc = base.markers.index("wheel_centre")
    return float(pos[0, wc, 2] - base.markers.position[wc, 2])


@pytest.mark.parametrize("path", [BUSHINGS, RIGID], ids=["bushings", "rigid"])
def test_design_load_holds_the_wheel_centre_at_design_height(path, bushings):
    mech = bushings if path == BUSHINGS else load_model(str(path))
    f0 = equilibrium_load(mech, "contact_patch", loaded_radius=None)  # at the load point
    assert abs(_height_at(mech, f0)) < 1e-8
    assert f0 > 0  # the spring carries the car: compressed, pushing the wheel down
    if path == RIGID:  # one DOF: the virtual-work estimate is exact, both agree
        assert f0 == pytest.approx(_virtual_work(mech), rel=1e-7)
    else:  # eleven DOF: the estimate is meaningless (negative; the wheel far below design)
        assert _virtual_work(mech) < 0 < f0
        assert _height_at(mech, _virtual_work(mech)) < -50.0


def test_lateral_force_defaults_to_the_equilibrium_design_load(bushings):
    """`diffsusp kc FILE --event lateral-force` with no other option: the wheel at design
    height at zero lateral force, the load's origin printed, and the compliance steer equal to
    the library's at the equilibrium design load to 1e-6."""
    runner = CliRunner()
    result = runner.invoke(app, ["kc", str(BUSHINGS), "--event", "lateral-force", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    f0 = equilibrium_load(bushings, "contact_patch")
    assert data["design_load"]["value"] == pytest.approx(f0, rel=1e-12)
    assert "design height" in data["design_load"]["origin"]
    travel = np.asarray(data["metrics"]["wheel_travel"]["values"])
    lateral = np.asarray(data["metrics"]["lateral_force"]["values"])
    assert abs(travel[np.argmin(np.abs(lateral))]) < 1e-6
    ev = kc.lateral_force(bushings, np.linspace(-4000.0, 4000.0, 17), fz=f0)
    np.testing.assert_allclose(data["metrics"]["lateral_compliance_steer"]["values"],
                               kc.display("lateral_compliance_steer",
                                          ev.metrics["lateral_compliance_steer"]),
                               rtol=1e-6, atol=1e-9)
    # the old default: the steer under load changed sign and size
    assert np.all(np.asarray(data["metrics"]["lateral_compliance_steer"]["values"]) > 0)
    text = runner.invoke(app, ["kc", str(BUSHINGS), "--event", "lateral-force"])
    assert text.exit_code == 0 and "Design load" in text.stdout and "computed" in text.stdout


@pytest.mark.parametrize("event", ["braking", "traction", "aligning-torque"])
def test_every_force_event_uses_the_equilibrium_design_load(bushings, event):
    """The other force events take the same default (their programs are compiled elsewhere:
    here the load they are given is checked, not re-solved)."""
    from diffsusp.kc.dispatch import default_load

    load = default_load(bushings, event)
    assert load["value"] == pytest.approx(equilibrium_load(bushings, "contact_patch"),
                                          rel=1e-12)
    assert default_load(bushings, event, fz="5000") is None
    assert default_load(bushings, "parallel-travel") is None


def test_vertical_force_without_fz_runs_around_the_design_load(bushings):
    """`--event vertical-force` without `--fz` was an internal error (exit 1): now 0.5–1.5× the
    equilibrium design load, and the wheel at design height at the design load."""
    result = CliRunner().invoke(app, ["kc", str(BUSHINGS), "--event", "vertical-force",
                                      "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    f0 = equilibrium_load(bushings, "contact_patch")
    fz = np.asarray(data["metrics"]["vertical_force"]["values"])
    np.testing.assert_allclose(fz[[0, -1]], [0.5 * f0, 1.5 * f0], rtol=1e-12)
    travel = np.asarray(data["metrics"]["wheel_travel"]["values"])
    assert abs(travel[np.argmin(np.abs(fz - f0))]) < 1e-6


def test_with_rack_reads_the_frame_from_the_model(bushings):
    """A Chrono (ISO 8855) corner: positive rack travel moves the inner tie-rod point to the
    vehicle's left, +y in ISO (it was -y, the Adams/Car default, unless frame= was given)."""
    assert bushings.corners[0].frame == "iso"
    tie_rod = next(n for n, k in zip(bushings.joints.names, bushings.joints.kind, strict=True)
                   if k == "distance")
    racked = kc.with_rack(bushings, tie_rod)
    explicit = kc.with_rack(bushings, tie_rod, frame="iso")
    k = racked.drivers.names.index("rack_travel")
    np.testing.assert_allclose(racked.drivers.direction.reshape(-1, 3)[k], [0.0, 1.0, 0.0],
                               atol=1e-15)
    np.testing.assert_array_equal(racked.drivers.direction, explicit.drivers.direction)
