"""Which markers are the wheel: the corners a model carries (`Mechanism.corners`, see
`diffsusp.model.corner`), looked up for K&C events, sensitivity and identification.

Every built-in model and every imported model states its corner when it is built (the Chrono
importer from the file's spindle, contact point and ball joints; a native model file in its
`[[corner]]` tables); nothing is guessed from the model's name. A model without one (an Adams
dataset, a version-1 native file) needs a `Corner` passed as `corner=` (or the CLI's corner
options).
"""

import math

import numpy as np

from ..errors import InputError
from ..model import Loads, Mechanism
from ..model.corner import (  # noqa: F401  (re-exported: diffsusp.kc.Corner)
    FRAMES,
    Corner,
    PointRef,
    ResolvedCorner,
)
from ..statics import Status, marker_poses, solve_statics
from ..statics.validation import design_terms
from .rig import add_road_contact, remove_drivers


def default_corner(mech: Mechanism, prefix: str = "") -> Corner:
    """The corner `mech` carries under `prefix` ('' for a half axle), or an `InputError` that
    says how to describe the wheel."""
    for corner in mech.corners:
        if corner.prefix == prefix:
            return corner
    stated = ", ".join(repr(c.prefix) for c in mech.corners)
    raise InputError(
        f"no default K&C corner for model '{mech.name}'"
        + (f" under prefix '{prefix}' (it has {stated})" if stated else
           " (the model states none: an Adams dataset or a version-1 native file)")
        + ". Describe the wheel with diffsusp.kc.Corner(wheel_centre=..., contact_point=..., "
        "kingpin=(upper, lower), frame='adams'|'iso', loaded_radius=...) and pass it as "
        "corner=, or store it with the model (MechanismBuilder.corner, a [[corner]] table of "
        "the native file)."
    )


def corners_of(mech: Mechanism) -> dict[str, Corner]:
    """The corners of a model by prefix: one for a half axle (key ''), or one per side for an
    axle made by `diffsusp.model.combine.combine` (keys are its prefixes, e.g. 'left/')."""
    if not mech.corners:
        return {"": default_corner(mech)}
    return {c.prefix: c for c in mech.corners}


def design_load(mech: Mechanism, corner: Corner | None = None) -> float:
    """The vertical wheel load at design (N) of `corner` (default: the model's, see
    `default_corner`): the one it states (`Corner.design_load`), else the load at the ground
    contact point of a wheel of its loaded radius that holds the wheel centre at its design
    height (`equilibrium_load`). The force events' default; pass it to `Corner.resolve`."""
    c = corner or default_corner(mech)
    if c.design_load is not None:
        return float(c.design_load)
    wc = mech.markers.index(c.prefix + c.wheel_centre)
    return equilibrium_load(mech, c.prefix + c.contact_point, (0.0, 0.0, 1.0), wc,
                            loaded_radius=float(c.loaded_radius))


_LOADS = {}  # id(mechanism) → (mechanism, contact point, up, load): a computed design load


def equilibrium_load(mech: Mechanism, contact_point: str, up=(0.0, 0.0, 1.0),
                     wheel_centre: str | int | None = None, *,
                     loaded_radius: float | None | str = "corner") -> float:
    """The vertical contact load (N, along `up`) that holds the wheel centre at its design
    height, `mech` without its motion drivers (spec: stiffness §1.4). With a `loaded_radius`
    (mm) the load acts where the K&C force events apply it: at the ground contact point of a
    wheel of that radius, moving with the wheel plane (`diffsusp.kc.rig.add_road_contact`,
    `Loads.contact_radius`; `up` must then be the road normal +z); 'corner' (default): the
    loaded radius of the model's corner under the contact point's prefix (the same load as
    `Corner.resolve`), or, for a model that states no corner, the load point; None: at load
    point `contact_point` (fixed on the wheel carrier). Solved through the statics for any number
    of degrees of freedom: the height of the solved wheel centre is a function of the load,
    h(F), and a safeguarded secant (Illinois once bracketed) finds h(F) = h(design) to 1e-9
    mm, each step an equilibrium warm-started from the previous one. The start is the
    virtual-work estimate at the design position, the least-squares (F, λ) of Q0 + F·Q1 +
    Φ_qᵀλ = 0 (exact for a one-DOF corner, where the secant stops at once); on a corner on
    bushings that estimate asks every bushing to be unloaded at design and means nothing,
    the secant corrects it.

    `wheel_centre`: its marker (name or index; default `'wheel_centre'` under the contact
    point's prefix). Raises `InputError` when no load within ±1 MN holds the design height
    (the design is not an equilibrium under any vertical load). The value is remembered per
    mechanism object."""
    prefix = contact_point.rpartition("/")[0] + "/" if "/" in contact_point else ""
    if wheel_centre is None:
        wheel_centre = prefix + "wheel_centre"
    wc = wheel_centre if isinstance(wheel_centre, int) else mech.markers.index(wheel_centre)
    if isinstance(loaded_radius, str):
        if loaded_radius != "corner":
            raise InputError(f"equilibrium_load: loaded_radius must be a length (mm), 'corner' "
                             f"or None; got {loaded_radius!r}.")
        stated = [c for c in mech.corners if c.prefix + c.contact_point == contact_point]
        loaded_radius = float(stated[0].loaded_radius) if stated else None
    key = (contact_point, tuple(up), wc, loaded_radius)
    hit = _LOADS.get(id(mech))
    if hit is not None and hit[0] is mech and hit[1] == key:
        return hit[2]
    base = remove_drivers(mech, mech.drivers.names)
    if loaded_radius is None:
        k, radius = base.load_points.index(contact_point), None
    else:
        if tuple(float(v) for v in up) != (0.0, 0.0, 1.0):
            raise InputError("equilibrium_load: the ground contact point needs the road normal "
                             f"up = (0, 0, 1); got {tuple(up)}.")
        base, k = add_road_contact(base, wc, prefix)
        radius = np.zeros(len(base.load_points.names))
        radius[k] = float(loaded_radius)
    n, n_l = base.n_coordinates, len(base.load_points.names)
    zero = np.zeros((n_l, 3))
    unit = zero.copy()
    unit[k] = np.asarray(up, dtype=float)
    r0 = design_terms(base, Loads(force=zero, moment=zero, driver=np.zeros(0),
                                  contact_radius=radius))[1][:n]
    _, r1, jac = design_terms(base, Loads(force=unit, moment=zero, driver=np.zeros(0),
                                          contact_radius=radius))
    a = jac[:n, n:]  # Φ_qᵀ: the residual is linear in the multipliers
    estimate = float(np.linalg.lstsq(np.column_stack([r1[:n] - r0, a]), -r0, rcond=None)[0][0])
    up_v = np.asarray(up, dtype=float)
    h0 = float(np.asarray(base.markers.position)[wc] @ up_v)
    state = {"q": None}

    def height(force: float) -> float:
        loads = Loads(force=(force * unit)[None], moment=zero[None], driver=np.zeros((1, 0)),
                      contact_radius=None if radius is None else radius[None])
        sol = solve_statics(base, loads, q0=state["q"], throw=False, checks=False)
        if int(np.asarray(sol.status)[0]) != Status.CONVERGED:
            return math.nan
        state["q"] = sol.q
        pos, _ = marker_poses(base, sol.q)
        return float(np.asarray(pos)[0, wc] @ up_v) - h0

    value = _secant(height, estimate if math.isfinite(estimate) else 0.0)
    if value is None:
        raise InputError(
            f"the design position of '{mech.name}' is not an equilibrium under any vertical "
            f"load at '{contact_point}' within ±1 MN (the wheel centre never reaches its design "
            "height): state the corner's design_load, or check the springs' free lengths and "
            "the bushings' preloads.")
    if len(_LOADS) > 64:
        _LOADS.clear()
    _LOADS[id(mech)] = (mech, key, value)
    return value


def _secant(height, f0: float, *, tol: float = 1e-9, limit: float = 1e6, steps: int = 60):
    """The root of the increasing function `height` (mm of load F, N; NaN where F has no
    equilibrium) from `f0`: secant steps until the root is bracketed (a step whose load has no
    equilibrium is halved back toward the last good load), then Illinois regula falsi. None
    when no root lies within ±`limit`."""
    fa, ha = f0, height(f0)
    if not math.isfinite(ha):
        fa, ha = 0.0, height(0.0)
    if not math.isfinite(ha):
        return None
    if abs(ha) <= tol:
        return fa
    fb = fa - math.copysign(max(1000.0, 0.1 * abs(fa)), ha)  # an upward load lifts the wheel
    for _ in range(steps):  # phase 1: secant until the sign changes
        if abs(fb) > limit:
            return None
        hb = height(fb)
        while not math.isfinite(hb):
            fb = 0.5 * (fa + fb)
            if abs(fb - fa) < 1e-9 * max(1.0, abs(fa)):
                return None
            hb = height(fb)
        if abs(hb) <= tol:
            return fb
        if ha * hb < 0:
            break
        slope = (hb - ha) / (fb - fa)
        room = 4.0 * abs(fb - fa) + 1000.0
        step = -hb / slope if slope > 0 else math.copysign(room, -hb)
        fa, ha, fb = fb, hb, fb + math.copysign(min(abs(step), room), step)
    else:
        return None
    for _ in range(steps):  # phase 2: Illinois on the bracket (fa, fb)
        fc = fb - hb * (fb - fa) / (hb - ha)
        hc = height(fc)
        if not math.isfinite(hc):
            return None
        if abs(hc) <= tol or abs(fc - fb) <= 1e-13 * max(1.0, abs(fc)):
            return fc
        if hc * hb < 0:
            fa, ha = fb, hb
        else:
            ha *= 0.5
        fb, hb = fc, hc
    return None


__all__ = ["FRAMES", "Corner", "PointRef", "ResolvedCorner", "corners_of", "default_corner",
           "design_load", "equilibrium_load"]
