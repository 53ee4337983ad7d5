"""The tyre force at the ground contact point (docs/guides/kc.md): the K&C force events load the
wheel at the wheel plane's lowest point on the road, C = W − R_l·u (u the unit vector in the
wheel plane pointing up from the road), which moves with the wheel, not at a point fixed to the
wheel carrier; the loaded radius R_l from the tyre (its `.tir` at the design load), the option
or the model, a default said so.

The reference is independent of the kernel's contact code: the NumPy oracle (tests/oracle.py)
loaded at the wheel centre with the force F and the moment (C − W)×F computed here from the
solved pose must find the same equilibrium. On the Chrono double wishbone with `Bushing Data`
12 kN of braking (or of traction at the contact patch) winds the wheel carrier up by 2.5°: the
carrier-fixed point the rig used to load (330 mm below the wheel centre at design) then sits
14.4 mm along the road from C, and loading it gives another toe under load (−0.275° against
−0.308° under braking; another corner, 2.4° of wind-up: 13.7 mm and 1.17° against 0.94°).

One compiled solve (two cases) and one K&C event (the truck tyre's radius, from the CLI)."""

import json
import pathlib

import numpy as np
import oracle
import pytest
from typer.testing import CliRunner

import diffsusp
import diffsusp.cli.kc  # noqa: F401  (registers `kc`)
from diffsusp import kc, load_model
from diffsusp.cli import app
from diffsusp.io.tir import read_tir
from diffsusp.kc.dispatch import corner_with, loaded_radius_origin
from diffsusp.tyre import MagicFormula6
from diffsusp.tyre.examples import example_path
from diffsusp.tyre.vertical import loaded_radius

BUSHINGS = pathlib.Path(__file__).parent / "data" / "DoubleWishbone_bushings.json"
TRUCK = example_path("335_65R22_5_G275MSA_70psi.tir")
UP = np.array([0.0, 0.0, 1.0])


@pytest.fixture(scope="module")
def bushings():
    return load_model(str(BUSHINGS))


def _contact(w, s, radius):
    u = UP - (UP @ s) * s
    return w - radius * u / np.linalg.norm(u), u / np.linalg.norm(u)


def test_braking_acts_at_the_wheel_planes_lowest_point(bushings):
    rig = kc.force_rig(bushings)
    rc = rig.corners[0]
    mech = rig.mech
    radius = rc.loaded_radius
    assert radius == 330.0 and not bushings.corners[0].loaded_radius_stated
    loads = kc.corner_loads(mech, vertical=rc.design_load, longitudinal=[-12000.0, 12000.0])
    road = mech.load_points.index("road_contact")
    assert loads.contact_radius is not None and float(loads.contact_radius[0, road]) == radius
    sol = diffsusp.solve_statics(mech, loads)
    pos, rot = (np.asarray(a) for a in diffsusp.marker_poses(mech, sol.q))
    lp = mech.load_points
    wc_lp, cp_marker = lp.index("wheel_centre"), lp.marker[lp.index("contact_patch")]
    forward = np.asarray(rc.forward)
    design_down = np.asarray(mech.markers.position[cp_marker] - mech.markers.position[
        rc.wheel_centre])
    for c in range(2):
        w, s = pos[c, rc.wheel_centre], rot[c, rc.wheel_centre][:, 2]
        contact, u = _contact(w, s, radius)
        f = np.asarray(loads.force[c, road])
        force, moment = np.zeros((len(lp.names), 3)), np.zeros((len(lp.names), 3))
        force[wc_lp], moment[wc_lp] = f, np.cross(contact - w, f)
        ref = oracle.solve(mech, force, moment, np.asarray(loads.driver[c]), q0=sol.q[c])
        np.testing.assert_allclose(np.asarray(sol.q[c]), ref.q(), rtol=0, atol=1e-7)
        # the point fixed to the carrier has wound up with it, along the road
        carrier = pos[c, cp_marker]
        turned = rot[c, rc.wheel_centre] @ np.asarray(
            mech.markers.orientation[rc.wheel_centre]).T @ design_down
        wind_up = np.degrees(np.arccos(np.clip(-turned @ u / np.linalg.norm(turned), -1, 1)))
        assert 2.0 < wind_up < 3.0, wind_up
        assert abs((carrier - contact) @ forward) > 10.0
        assert abs(contact[2] - (w[2] - radius * u[2])) < 1e-9
    # the old rig (the force at the carrier-fixed point): another toe under braking
    toe = np.asarray(kc.corner_geometry(mech, rc, sol.q[1])["toe"])
    force = np.zeros((len(lp.names), 3))
    force[lp.index("contact_patch")] = np.asarray(loads.force[1, road])
    old = oracle.solve(mech, force, np.zeros_like(force), np.asarray(loads.driver[1]),
                       q0=sol.q[1])
    toe_old = np.asarray(kc.corner_geometry(mech, rc, old.q())["toe"])
    assert abs(np.degrees(toe - toe_old)) > 0.01, (np.degrees(toe), np.degrees(toe_old))


def test_truck_tyre_radius_is_used_and_the_default_is_said(bushings):
    """`--tyre` a 335/65 R22.5 truck tyre: the loaded radius is the tyre's at the design load
    (its vertical model; ~480 mm, not the reader's 330 mm), the design load holds the wheel
    centre at its design height with the force at that contact point, and the contact point is
    that far below the wheel centre in the wheel plane; `--json` says where it came from."""
    runner = CliRunner()
    result = runner.invoke(app, ["kc", str(BUSHINGS), "--event", "lateral-force", "--force",
                                 "-2000:2000:5", "--tyre", str(TRUCK), "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    radius, f0 = data["loaded_radius"]["value"], data["design_load"]["value"]
    tyre = MagicFormula6.from_tir(read_tir(TRUCK))
    assert radius == pytest.approx(float(loaded_radius(tyre, f0).rl), abs=1e-5)
    assert 440.0 < radius < 520.0 and TRUCK.name in data["loaded_radius"]["origin"]
    assert not data["loaded_radius"]["default"]
    m = {k: np.asarray(v["values"], dtype=float) for k, v in data["metrics"].items()}
    zero = int(np.argmin(np.abs(m["lateral_force"])))
    assert abs(m["wheel_travel"][zero]) < 1e-6
    sz = m["spin_axis_z"][zero]
    np.testing.assert_allclose(m["contact_patch_z"][zero],
                               m["wheel_centre_z"][zero] - radius * np.sqrt(1 - sz**2),
                               rtol=0, atol=1e-9)
    # the reader's default is said; an explicit radius is used; not both
    default = loaded_radius_origin(bushings)
    assert default["default"] and default["value"] == 330.0 and "default" in default["origin"]
    given = corner_with(bushings, loaded_radius=470.0)
    rig = kc.force_rig(bushings, given)
    assert float(kc.corner_loads(rig.mech, corner=given, vertical=1.0).contact_radius[
        0, rig.road[0]]) == 470.0
    assert not loaded_radius_origin(bushings, given, given=470.0)["default"]
    both = runner.invoke(app, ["kc", str(BUSHINGS), "--event", "lateral-force", "--tyre",
                               str(TRUCK), "--loaded-radius", "470"])
    assert both.exit_code == 2 and "not both" in both.output
