"""K&C events by name: what the `diffsusp kc` and `diffsusp sensitivity` verbs call, so that the
command line only parses and formats (DESIGN.md "Architecture": a thin edge).

`run_event(mech, 'opposite-travel', travel=...)` dispatches to the event functions of
`diffsusp.kc` and builds what an event needs that the model may not have: the axle (the model
and its mirror image) for opposite travel, a rack at the tie rod for steering. Ranges are arrays
or the command line's `start:stop:count` text (`parse_range`). Units: mm, N, N·mm (the aligning
torque is given in N·m, as on the command line).
"""

import dataclasses
import math

import numpy as np

from ..errors import InputError
from ..model.combine import combine, component_names
from ..model.mirror import mirror
from ..tyre.vertical import loaded_radius as vertical_radius
from .corner import Corner, corners_of, default_corner, design_load, equilibrium_load
from .events import (
    TABLES,
    aligning_torque,
    braking,
    lateral_force,
    load_table,
    opposite_travel,
    parallel_travel,
    steering,
    traction,
    vertical_force,
)
from .metrics import display, display_unit
from .rig import with_rack

EVENTS = {
    "parallel-travel": "wheel travel (mm), --travel",
    "opposite-travel": "wheel travel (mm), --travel; axle = model + its mirror image",
    "vertical-force": "vertical force (N), --fz",
    "lateral-force": "lateral force (N, inboard +), --force, at --fz",
    "braking": "braking force (N) at the contact patch, --force, at --fz",
    "traction": "traction force (N) at the wheel centre, --force, at --fz",
    "aligning-torque": "aligning torque (N·m, toe-out +), --torque, at --fz",
    "steering": "rack travel (mm, left +), --rack",
    "table-5-1": "the 13 cases of the thesis's Table 5-1",
    "table-4-4": "the 17 cases of the thesis's Table 4.4",
}
"""The events `run_event` knows, with their input."""


def parse_range(text, what: str) -> np.ndarray:
    """`start:stop:count` → numpy.linspace(start, stop, count); a single number → [number];
    an array is returned as it is. `what` names the option in the error."""
    if not isinstance(text, str):
        return np.asarray(text, dtype=float).reshape(-1)
    parts = text.split(":")
    try:
        if len(parts) == 1:
            return np.array([float(parts[0])])
        if len(parts) == 3:
            start, stop, count = float(parts[0]), float(parts[1]), int(parts[2])
            if count < 1:
                raise ValueError
            return np.linspace(start, stop, count)
    except ValueError:
        pass
    raise InputError(f"--{what} '{text}' is not a range: give start:stop:count (e.g. "
                     "-80:80:161) or one number.")


def corner_with(mech, *, frame=None, loaded_radius=None, kingpin=None, side=None, tyre=None):
    """The model's own corner (`Mechanism.corners`) with some of its settings replaced (None:
    that corner, unchanged; a model without one starts from `Corner()`). `kingpin`: two marker
    names, a tuple or the text 'upper,lower'. `tyre` (a `diffsusp.tyre.MagicFormula6`): the
    loaded radius is the tyre's at the design load (`tyre_loaded_radius`); not with
    `loaded_radius`."""
    if tyre is not None and loaded_radius is not None:
        raise InputError("give the loaded radius (--loaded-radius) or a tyre (--tyre), not "
                         "both: the tyre's radius at the design load is the loaded radius.")
    if frame is None and loaded_radius is None and kingpin is None and side is None and (
            tyre is None):
        return None  # the model's registered corner
    try:
        base = default_corner(mech)
    except InputError:
        base = Corner()
    changes = {}
    if frame is not None:
        changes["frame"] = frame
    if loaded_radius is not None:
        changes["loaded_radius"] = loaded_radius
    if side is not None:
        changes["side"] = side
    if kingpin is not None:
        names = kingpin.split(",") if isinstance(kingpin, str) else list(kingpin)
        if len(names) != 2:
            raise InputError("--kingpin must be two marker names 'upper,lower'.")
        changes["kingpin"] = tuple(n.strip() for n in names)
    if loaded_radius is not None:
        changes["loaded_radius_stated"] = True
    out = dataclasses.replace(base, **changes)
    if tyre is not None:
        radius, _ = tyre_loaded_radius(mech, tyre, out)
        out = dataclasses.replace(out, loaded_radius=radius, loaded_radius_stated=True)
    return out


def tyre_loaded_radius(mech, tyre, corner=None, *, tol: float = 1e-6, steps: int = 8
                       ) -> tuple[float, float]:
    """The loaded radius (mm) of `tyre` (a `diffsusp.tyre.MagicFormula6`: UNLOADED_RADIUS and
    its vertical model, `tyre.vertical.loaded_radius`) under the corner's design load, and
    that load (N): the load the corner states, or the one that holds the wheel centre at its
    design height with the tyre force at the ground contact point of that radius — a fixed
    point (the radius sets the load's lever arm, the load the tyre's deflection), iterated
    until the radius moves less than `tol` mm (two or three rounds: a millimetre of radius
    changes the load by little). `corner`: default the model's."""
    c = corner or default_corner(mech)

    def radius(load: float) -> float:
        state = vertical_radius(tyre, max(float(load), 0.0))
        if not bool(np.asarray(state.converged)):
            raise InputError(f"the tyre's vertical model has no loaded radius at {load:.6g} N "
                             "(the corner's design load).")
        return float(np.asarray(state.rl))

    if c.design_load is not None:
        return radius(c.design_load), float(c.design_load)
    wc = mech.markers.index(c.prefix + c.wheel_centre)
    r = float(c.loaded_radius)
    for _ in range(steps):
        load = equilibrium_load(mech, c.prefix + c.contact_point, (0.0, 0.0, 1.0), wc,
                                loaded_radius=r)
        new = radius(load)
        if abs(new - r) < tol:
            return new, load
        r = new
    raise InputError("the tyre's loaded radius and the corner's design load do not settle "
                     f"(last radius {r:.6g} mm): state the corner's design_load.")


def loaded_radius_origin(mech, corner=None, *, given: float | None = None,
                         tyre_file=None) -> dict:
    """Where the loaded radius of an event comes from, as `diffsusp kc` prints it (and puts in
    `--json`): `{"value": mm, "origin": text, "default": bool}` — the tyre file's radius at
    the design load (`tyre_file`, the corner already carrying it), the option (`given`), the
    model's corner, or a reader's default (`Corner.loaded_radius_stated` False: a Chrono
    suspension file carries no tyre). The first corner of an axle; None for a model that
    states no corner (the event then says what is missing)."""
    if corner is None:
        if not mech.corners:
            return None
        corner = mech.corners[0]
    c = corner
    value = float(c.loaded_radius)
    if tyre_file is not None:
        origin = (f"the tyre {tyre_file}: its loaded radius at the design load (UNLOADED_RADIUS "
                  "and the vertical model)")
    elif given is not None:
        origin = "given (--loaded-radius)"
    elif c.loaded_radius_stated:
        origin = "stated by the model's corner"
    else:
        origin = ("default: the model states no tyre (a Chrono suspension file carries none); "
                  "--tyre FILE.tir or --loaded-radius sets it")
    return {"value": value, "origin": origin,
            "default": tyre_file is None and given is None and not c.loaded_radius_stated}


def mirrored_corner(corner: Corner) -> Corner:
    """The same corner on the other side (for the mirror image of a half axle)."""
    return corner.mirrored()


def default_fz_range(mech, corner=None) -> str:
    """0.5–1.5× the corner's design load, 21 cases (N): the load it states, else the one that
    holds the wheel centre at its design height (`design_load`)."""
    fz0 = design_load(mech, corner or corners_of(mech)[""])
    return f"{0.5 * fz0}:{1.5 * fz0}:21"


LOADED_EVENTS = ("vertical-force", "lateral-force", "braking", "traction", "aligning-torque")
"""The events whose cases carry the corner's design load unless `fz` is given."""


def default_load(mech, event: str, corner=None, fz=None) -> dict | None:
    """The design load an event uses by default, with its origin: None when `fz` is given or
    the event applies no vertical load; else `{"value": N, "origin": text}` — the load the
    model's corner states, or the one computed to hold the wheel centre at its design height
    (`diffsusp.kc.corner.equilibrium_load`)."""
    if fz is not None or event not in LOADED_EVENTS:
        return None
    c = corner or corners_of(mech)[""]
    value = design_load(mech, c)
    origin = ("stated by the model's corner" if c.design_load is not None else
              "computed: the vertical load that holds the wheel centre at its design height")
    return {"value": value, "origin": origin}


def run_event(mech, event: str, corner=None, *, travel="-80:80:161", fz=None,
              force="-4000:4000:17", torque="-200:200:17", rack="-30:30:61"):
    """Run the K&C event `event` (a key of `EVENTS`) on `mech`; returns its `KCEvent`.

    **Arguments:** `corner` (None: the model's registered corner); the ranges of the event's
    input (an array, or `start:stop:count` text): `travel` (mm), `fz` (N: one value for the
    force events, default the design load; a range for vertical-force, default
    `default_fz_range`), `force` (N), `torque` (N·m), `rack` (mm). Only the event's own input
    is read.

    **Raises:** `InputError` for an unknown event or a bad range.
    """
    if event not in EVENTS:
        raise InputError(f"unknown event '{event}'; known events: {', '.join(EVENTS)}.")
    fz_value = None
    if fz is not None and event != "vertical-force":
        values = parse_range(fz, "fz")
        if values.size != 1:
            raise InputError(f"--fz must be one value (N) for the {event} event.")
        fz_value = float(values[0])
    if event == "parallel-travel":
        return parallel_travel(mech, parse_range(travel, "travel"), corner=corner)
    if event == "opposite-travel":
        axle = mech if component_names(mech) else combine({"left": mech, "right": mirror(mech)})
        corners = None if corner is None else {"left": corner, "right": mirrored_corner(corner)}
        return opposite_travel(axle, parse_range(travel, "travel"), corner=corners)
    if event == "vertical-force":
        if fz is None:
            fz = default_fz_range(mech, corner)
        return vertical_force(mech, parse_range(fz, "fz"), corner=corner)
    forces = {"lateral-force": lateral_force, "braking": braking, "traction": traction}
    if event in forces:
        return forces[event](mech, parse_range(force, "force"), fz=fz_value, corner=corner)
    if event == "aligning-torque":
        return aligning_torque(mech, 1e3 * parse_range(torque, "torque"), fz=fz_value,
                               corner=corner)
    if event == "steering":
        frame = (corner or corners_of(mech)[""]).frame
        return steering(with_rack(mech, frame=frame), parse_range(rack, "rack"), corner=corner)
    table = TABLES["table_5_1" if event == "table-5-1" else "table_4_4"]
    return load_table(mech, table, corner=corner)


def reference_case(ev) -> int:
    """The event's reference case: the design load (vertical-force), the first case (load
    tables), else zero input."""
    if ev.x_name == "vertical_force":
        target = ev.rig.corners[0].design_load
    elif ev.x_name == "case":
        return 0
    else:
        target = 0.0
    return int(np.argmin(np.abs(np.asarray(ev.x) - target)))


def event_json(ev, model_name: str) -> dict:
    """The JSON of a K&C event (`diffsusp kc MODEL --json`, and each report of a K&C fleet):
    model and event names, the swept quantity (N·m for torques), held inputs, per-case status,
    iterations and flags, every metric in its display unit (`kc.display`), and the wheel-centre
    compliance matrices when the event has them. A non-finite value (a case that did not
    converge) is None (null)."""
    def clean(a):
        a = np.asarray(a, dtype=float)
        if a.ndim == 0:
            return float(a) if math.isfinite(a) else None
        return [clean(r) for r in a]

    def flags(value):
        return None if value is None else np.asarray(value, dtype=bool).tolist()

    x_scale = 1e-3 if ev.x_unit == "N·mm" else 1.0
    out = {
        "model": model_name,
        "event": ev.name,
        "x": {"name": ev.x_name, "unit": "N·m" if ev.x_unit == "N·mm" else ev.x_unit,
              "values": clean(np.asarray(ev.x) * x_scale)},
        "held": ev.held,
        "status": np.asarray(ev.solution.status).tolist(),
        "iterations": np.asarray(ev.solution.iterations).tolist(),
        "stable": flags(ev.solution.stable),
        "law_valid": flags(ev.solution.law_valid),
        "metrics": {name: {"unit": display_unit(name), "values": clean(display(name, v))}
                    for name, v in sorted(ev.metrics.items())},
    }
    if ev.compliance:
        out["compliance_matrix"] = {
            "unit": "mm/N, mm/(N·mm), rad/N, rad/(N·mm); rows and columns x, y, z, rx, ry, rz "
                    "(global) at the wheel centre",
            "values": {prefix or "corner": clean(c) for prefix, c in ev.compliance.items()},
        }
    return out


__all__ = ["EVENTS", "corner_with", "default_fz_range", "event_json", "loaded_radius_origin",
           "mirrored_corner", "parse_range", "reference_case", "run_event", "tyre_loaded_radius"]
