"""Chrono fidelity on Chrono's HMMWV rear double wishbone
(tests/data/chrono/HMMWV_DoubleWishboneRear.json: a 21-point 'Spring Curve Data' and
'Minimum/Maximum Length' stops): the spring curve interpolated linearly and the length stops as
Chrono evaluates them, the wheel corner carried by the imported model, `--side`.

The oracle is independent of the importer's element decomposition: the kinematics come from the
NumPy solver of tests/oracle.py driving the wheel-centre height (0 DOF: no force element
enters the positions), the spring tension from Chrono's own law written here from its
definition (`NonlinearSpringForce::evaluate` + `SpringForce::evaluate_stops`: tension =
interp(ℓ − L0) − P − bump(min − ℓ) + rebound(ℓ − max), `ChFunctionInterp` linear), and the
equilibrium from virtual work: F·dz_cp = T·dℓ, root-found in the wheel-centre height.

One compiled program: the vertical sweep (13 cases, 0–30 kN, the rebound stops engaged below
~7 kN), shared with the CLI runs through the program cache only where the shapes agree.
"""

import json
from pathlib import Path

import numpy as np
import oracle
import pytest
from scipy.interpolate import CubicSpline
from scipy.optimize import brentq
from typer.testing import CliRunner

import diffsusp
import diffsusp.cli.kc  # noqa: F401  (registers `kc`)
import diffsusp.cli.sensitivity  # noqa: F401  (registers `sensitivity`)
from diffsusp import kc, load_model, save_model
from diffsusp.cli import app
from diffsusp.io.chrono import STOP_CURVE, read_chrono
from diffsusp.kc.corner import default_corner, equilibrium_load

DATA = Path(__file__).parent / "data" / "chrono"
HMMWV = DATA / "HMMWV_DoubleWishboneRear.json"
FZ = np.linspace(0.0, 30000.0, 13)


def chrono_tension(length, doc):
    """Chrono's spring + stops tension (N, pulling the seats together) at `length` (mm)."""
    sp = doc["Spring"]
    curve = np.asarray(sp["Spring Curve Data"], dtype=float)
    free = 1000.0 * sp["Free Length"]
    low, high = 1000.0 * sp["Minimum Length"], 1000.0 * sp["Maximum Length"]
    stop_x, stop_y = (np.asarray(v) for v in zip(*STOP_CURVE, strict=True))
    length = np.asarray(length, dtype=float)
    tension = np.interp(length - free, 1000.0 * curve[:, 0], curve[:, 1]) - sp.get("Preload", 0)
    tension = tension - np.where(length < low, np.interp(low - length, stop_x, stop_y), 0.0)
    return tension + np.where(length > high, np.interp(length - high, stop_x, stop_y), 0.0)


def model_tension(mech, length):
    """Tension of the model's spring and stops along the same line (their documented laws)."""
    s, st = mech.springs, mech.stops
    t = float(s.k[0]) * (length - float(s.free_length[0]))
    for e, kind in enumerate(st.kind):
        pen = (float(st.length[e]) - length) if kind == "bump" else (length - float(st.length[e]))
        force = float(st.k[e]) * np.maximum(pen, 0.0) + float(st.cubic[e]) * np.maximum(pen, 0) ** 3
        t = t + (-force if kind == "bump" else force)
    return t


@pytest.fixture(scope="module")
def doc():
    return json.loads(HMMWV.read_text())


@pytest.fixture(scope="module")
def mech():
    return read_chrono(HMMWV)


def test_spring_and_stops_are_chronos_laws(mech, doc):
    """Spring curve linear between its knots and the length stops on Chrono's curve: the model's
    linear spring plus one-sided stops give Chrono's tension to rounding over the table
    (deflection ±200 mm) and 60 mm into each stop. (The smooth option, the Akima law of a
    tabulated spring: tests/test_io_chrono.py::test_tierod_body_and_spring_curve.)"""
    length = np.linspace(182.0, 410.0, 2281)  # the table's range; into the rebound stops
    np.testing.assert_allclose(
        model_tension(mech, length), chrono_tension(length, doc), rtol=1e-12, atol=1e-7
    )
    bump = np.linspace(90.0, 150.0, 601)  # the bump stops (Chrono: beyond the table, held)
    mask = np.array(["bump_" in n for n in mech.stops.names])
    got = sum(
        -float(mech.stops.k[e]) * np.maximum(float(mech.stops.length[e]) - bump, 0.0)
        for e in np.flatnonzero(mask)
    )
    stop_x, stop_y = (np.asarray(v) for v in zip(*STOP_CURVE, strict=True))
    np.testing.assert_allclose(-got, np.interp(150.0 - bump, stop_x, stop_y), atol=1e-7)
    with pytest.raises(ValueError, match="spring_interpolation"):
        read_chrono(HMMWV, spring_interpolation="cubic")


@pytest.fixture(scope="module")
def event(mech):
    """The vertical-force K&C event over FZ: the library call `diffsusp kc --event
    vertical-force` makes (the CLI test below reuses its compiled programs)."""
    return kc.vertical_force(mech, FZ)


def oracle_path(doc, heights, radius=330.0):
    """Oracle kinematics at wheel-centre heights (mm from design): spring length, the vertical
    rate dz/dh of the wheel carrier's material point at the ground contact point (the wheel
    plane's lowest point, `radius` below the wheel centre: where the K&C rig applies the tyre
    force) and the wheel centre, as functions of the height (cubic splines)."""
    rig = read_chrono(HMMWV, wheel_travel=True, check=False)
    zero = np.zeros((len(rig.load_points.names), 3))
    k = rig.markers.index("wheel_centre")
    a, b = rig.markers.index("spring_chassis"), rig.markers.index("spring_arm")
    up = rig.parts.index("upright")
    length, centre, trans, rot, contact = [], [], [], [], []
    sol = None
    for h in heights:
        sol = oracle.solve(rig, zero, zero, np.array([h]), q0=sol)
        pos, axes = oracle.marker_poses(rig, sol.p, sol.R)
        length.append(np.linalg.norm(pos[a] - pos[b]))
        centre.append(pos[k])
        s = axes[k][:, 2]
        u = np.array([0.0, 0.0, 1.0]) - s[2] * s
        contact.append(pos[k] - radius * u / np.linalg.norm(u))
        trans.append(sol.p[up])
        rot.append(sol.R[up].reshape(9))
    p, r, c = (CubicSpline(heights, np.array(v)) for v in (trans, rot, contact))

    def patch_rate(h):  # d/dh of the material point that is at the contact point at h
        body = r(h).reshape(3, 3).T @ (c(h) - p(h))
        return (p(h, 1) + r(h, 1).reshape(3, 3) @ body)[2]

    return CubicSpline(heights, length), patch_rate, CubicSpline(heights, np.array(centre))


def test_vertical_sweep_matches_chrono_oracle(doc, event):
    """Wheel-centre path under a 0–30 kN vertical contact load: diffsusp (linear spring curve
    and length stops as imported) against the oracle (Chrono's law on the oracle's kinematics,
    virtual work). The rebound stops carry load in the lower cases (spring longer than
    'Maximum Length' 350 mm)."""
    mech = event.rig.mech
    assert bool(np.all(event.solution.converged))
    pos, _ = diffsusp.marker_poses(mech, event.solution.q)
    centre = np.asarray(pos[:, mech.markers.index("wheel_centre")])
    a, b = mech.markers.index("spring_chassis"), mech.markers.index("spring_arm")
    spring = np.linalg.norm(np.asarray(pos[:, a] - pos[:, b]), axis=1)
    assert np.sum(spring > 350.0) >= 3 and np.sum(spring < 350.0) >= 6  # stops engage, release
    heights = np.linspace(-185.0, 10.0, 27)
    length, patch_rate, wheel = oracle_path(doc, heights)

    def load(h):  # virtual work: F·dz_cp = T·dℓ
        return chrono_tension(length(h), doc) * length(h, 1) / patch_rate(h)

    h_star = np.array(
        [brentq(lambda h, f=f: load(h) - f, heights[0], heights[-1], xtol=1e-12) for f in FZ]
    )
    error = np.abs(centre - wheel(h_star))
    print(f"max wheel-centre deviation from the oracle: {error.max():.2e} mm")
    np.testing.assert_allclose(centre, wheel(h_star), rtol=0, atol=1e-4)


def test_corner_travels_with_the_model(mech, tmp_path):
    """The importer attaches the wheel (ISO frame, left, 330 mm loaded radius = the contact
    patch's depth, kingpin through the ball joints, design load computed: the load that holds
    the design position); it survives a native save/load, and `load_model(side=...)` gives the
    right side (read on that side for a Chrono file, mirrored otherwise)."""
    corner = default_corner(mech)
    assert (corner.frame, corner.side, corner.loaded_radius, corner.design_load) == (
        "iso",
        "left",
        330.0,
        None,
    )
    assert corner.kingpin == ("uca_upright", "lca_upright")
    path = tmp_path / "hmmwv.toml"
    save_model(mech, path)
    assert load_model(path, check=False).corners == mech.corners
    right = load_model(HMMWV, side="right", check=False)
    assert right.corners[0].side == "right" and right.name.endswith("(right)")
    mirrored = load_model(path, side="right", check=False)
    assert mirrored.corners[0].side == "right"
    np.testing.assert_allclose(mirrored.markers.position, right.markers.position, atol=1e-9)
    assert load_model(path, side="left", check=False).corners == mech.corners
    with pytest.raises(diffsusp.errors.InputError, match="side must be"):
        load_model(path, side="middle")


def test_design_load_holds_the_design_position(mech, event):
    """The computed design load lies in the sweep where the solved wheel centre crosses its
    design height (linear interpolation of the sweep, 1 % of the load)."""
    f0 = equilibrium_load(mech, "contact_patch")
    assert event.rig.corners[0].design_load == f0
    pos, _ = diffsusp.marker_poses(event.rig.mech, event.solution.q)
    z = np.asarray(pos[:, mech.markers.index("wheel_centre"), 2])
    z0 = float(mech.markers.position[mech.markers.index("wheel_centre"), 2])
    assert f0 == pytest.approx(np.interp(z0, z, FZ), rel=1e-2)


def test_kc_and_sensitivity_run_on_the_file_without_corner_flags(event):
    """`diffsusp kc FILE.json` and `diffsusp sensitivity FILE.json` with no corner option: the
    same vertical-force event (the kc run matches the library's), then its sensitivities."""
    runner = CliRunner()
    sweep = ["--event", "vertical-force", "--fz", f"{FZ[0]}:{FZ[-1]}:{FZ.size}"]
    result = runner.invoke(app, ["kc", str(HMMWV), *sweep, "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["status"] == [0] * FZ.size
    np.testing.assert_allclose(
        data["metrics"]["toe"]["values"],
        kc.display("toe", event.metrics["toe"]),
        rtol=1e-9,
        atol=1e-12,
    )
    result = runner.invoke(
        app, ["sensitivity", str(HMMWV), *sweep, "--no-derivatives", "--metric", "toe", "--json"]
    )
    assert result.exit_code == 0, result.output
    assert "toe" in json.dumps(json.loads(result.stdout))
