"""mkdocs hooks: pages generated from the code at build time (mkdocs.yml `hooks:`).

A page containing one of the markers below gets the generated Markdown in its place:

- `<!-- generated: metrics -->`: the K&C metric table, from the registry
  `diffsusp.kc.metrics.METRICS` (name, description and sign, internal and display unit, kind,
  the events whose default figures show it);
- `<!-- generated: cli -->`: the reference of the `diffsusp` command, from its Typer app
  (`typer.cli.get_docs_for_click`, the generator behind `typer ... utils docs`);
- `<!-- generated: tyre_inputs|tyre_outputs|tyre_spec|tyre_vertical|tyre_poly_inputs|
  tyre_onboard -->`: the tyre quantities of the registries `tyre.evaluate`'s signature,
  `tyre.TyreForces`, `tyre.spec.SPEC_UNITS` (with the values of the shipped MF 6.1 example),
  `tyre.vertical.VerticalState`, `tyre.poly.INPUT_UNITS`, `tyre.onboard.QUANTITIES`, with the
  descriptions below (`TYRE_*`): a name a registry gains without one fails the build.

Figures, computed at build time and added to the site as files (`on_files`): one small figure
per K&C metric (`reference/figures/metrics/<metric>.png`: the curve the metric is read from,
the metric marked; six events of two small models, `_metric_events`, ~10 s of CPU), and the
tyre reference's (`reference/figures/tyre/`). Nothing of these is written to the repository:
the documentation cannot go stale against the code.

The notebooks (`notebooks/NN_*.py`, jupytext percent format) are pages of their own, under
`notebooks/` in the site, rendered by mkdocs-jupyter without executing them (`execute: false`):
`tests/test_notebooks.py` executes each one and saves the executed copy to
`build/notebooks/NN_*.ipynb` (`save_executed`), stamped with the SHA-256 of its source. The
page shows that copy, outputs and figures included, when it is current; otherwise (no test run
yet, or the source changed since) the source without outputs, under a note that says so and
how to get them. The page notebooks are written to `build/docs-pages/notebooks/` (`on_files`). A
full local site: `python -m pytest -n 0 tests/test_notebooks.py && mkdocs build`.
"""

import datetime
import hashlib
import html
import os
import pathlib
import re

from mkdocs.plugins import event_priority
from mkdocs.structure.files import File

ROOT = pathlib.Path(__file__).resolve().parent.parent
NOTEBOOKS = ROOT / "notebooks"
EXECUTED = ROOT / "build" / "notebooks"  # written by tests/test_notebooks.py
PAGES = ROOT / "build" / "docs-pages"  # the notebooks the site renders, under notebooks/

_MARKER = re.compile(r"<!--\s*generated:\s*(\w+)\s*-->")


def _cell(text) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def metrics_table() -> str:
    """Markdown table of every entry of `diffsusp.kc.metrics.METRICS`, in registry order, with
    its small figure (`metric_figures`, files added by `on_files`)."""
    from diffsusp.kc.metrics import METRICS

    rows = ["| metric | description (sign) | unit | shown in | kind | default figures | figure |",
            "|---|---|---|---|---|---|---|"]
    for name, m in METRICS.items():
        if m.derivative:
            kind = "derivative (per roll angle)" if m.per_roll else "derivative"
        else:
            kind = "geometric / load"
        shown = m.display_unit if m.scale == 1.0 else f"{m.display_unit} (× {m.scale:.6g})"
        plots = ", ".join(f"`{e}`" for e in m.plots) or "—"
        figure = (f"[![{name}]({FIGURES}/{name}.png){{ width=220 }}]({FIGURES}/{name}.png)"
                  if name in _figures() else "—")
        rows.append(f"| `{name}` | {_cell(m.description)} | {_cell(m.unit)} | {_cell(shown)} "
                    f"| {kind} | {plots} | {figure} |")
    return "\n".join(rows) + "\n"


# -- one small figure per K&C metric --------------------------------------------------------------

FIGURES = "figures/metrics"  # relative to reference/metrics.md: docs/reference/figures/metrics/

# metric → (event, x, y, how): the curve the metric is read from, y against x in one event of
# `_metric_events`; how: "value" (the metric is y, marked at design), "slope" (the metric is
# dy/dx at design: the tangent is drawn with the metric's value as slope), "x" (the metric is
# the event's load, x; y shows what it does). Keys are per corner (an axle's with 'left/').
_TRAVEL_VALUE = ("toe", "camber", "caster", "kingpin_inclination", "scrub_radius",
                 "mechanical_trail", "wheel_centre_x", "wheel_centre_y", "wheel_centre_z",
                 "contact_patch_x", "contact_patch_y", "contact_patch_z", "spin_axis_x",
                 "spin_axis_y", "spin_axis_z", "half_track_change", "wheelbase_change",
                 "vertical_force")
FIGURE_SPECS = {
    **{name: ("parallel_travel", "wheel_travel", name, "value") for name in _TRAVEL_VALUE},
    "steer": ("steering", "rack_travel", "steer", "value"),
    "wheel_travel": ("parallel_travel", "vertical_force", "wheel_travel", "value"),
    "lateral_force": ("lateral_force", "lateral_force", "toe", "x"),
    "longitudinal_force": ("longitudinal_force", "longitudinal_force", "toe", "x"),
    "aligning_torque": ("aligning_torque", "aligning_torque", "toe", "x"),
    "bump_steer": ("parallel_travel", "wheel_travel", "toe", "slope"),
    "bump_camber": ("parallel_travel", "wheel_travel", "camber", "slope"),
    "wheel_rate": ("parallel_travel", "wheel_travel", "vertical_force", "slope"),
    "roll_centre_height": ("parallel_travel", "contact_patch_y", "contact_patch_z", "roll_centre"),
    "contact_recession_rate": ("parallel_travel", "wheel_travel", "_contact_rearward", "slope"),
    "wheel_centre_recession_rate": ("parallel_travel", "wheel_travel", "wheelbase_change",
                                    "slope"),
    **{f"{what}_compliance_{angle}": (load, load, "toe" if angle == "steer" else "camber",
                                      "slope")
       for what, load in (("lateral", "lateral_force"), ("longitudinal", "longitudinal_force"),
                          ("aligning_torque", "aligning_torque"))
       for angle in ("steer", "camber")},
    "steer_gain": ("steering", "rack_travel", "steer", "slope"),
    "camber_steer_gain": ("steering", "rack_travel", "camber", "slope"),
    "roll_angle": ("opposite_travel", "left/wheel_travel", "roll_angle", "value"),
    "roll_stiffness": ("opposite_travel", "roll_angle", "_roll_moment", "slope"),
    "roll_steer": ("opposite_travel", "roll_angle", "left/steer", "slope"),
}
_DESIGN = 6  # the middle of 13 cases: the design position (zero travel, zero load)


def _metric_events():
    """The events the figures are read from: the thesis's pseudo-McPherson half axle on a rack
    (parallel travel ±60 mm, steering ±20 mm of rack) and without it (lateral and longitudinal
    force ±4 kN and aligning torque ±300 N·m at its design load: the rack held at zero is the
    same suspension), and an axle of two double wishbones with bushings in opposite travel
    ±40 mm; 13 cases each, the middle one the design position. These are the compiled programs
    of the test suite's own K&C events (the 13-case travel, steering and roll of
    tests/test_kc.py, the 13-case load table of the pseudo-McPherson): a build inside the test
    run finds them in the run's compilation cache."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np

    from diffsusp import kc
    from diffsusp.model.combine import combine
    from diffsusp.model.mirror import mirror
    from diffsusp.models import double_wishbone, pseudo_mcpherson

    pm = pseudo_mcpherson()
    rack = kc.with_rack(pm)
    dw = double_wishbone(bushings=True)
    axle = combine({"left": dw, "right": mirror(dw)})
    span = np.linspace(-1.0, 1.0, 13)
    events = {"parallel_travel": kc.parallel_travel(rack, 60.0 * span),
              "steering": kc.steering(rack, 20.0 * span),
              "lateral_force": kc.lateral_force(pm, 4000.0 * span),
              "longitudinal_force": kc.longitudinal_force(pm, 4000.0 * span),
              "aligning_torque": kc.aligning_torque(pm, 3.0e5 * span),
              "opposite_travel": kc.opposite_travel(axle, 40.0 * span)}
    for name, ev in events.items():
        assert ev.converged.all(), name
    return events


def _series(ev, key):
    """A metric of `ev` (internal units), or one of the two quantities the figures add:
    `_contact_rearward` (mm: the contact point's rearward displacement from design) and
    `_roll_moment` (N·mm: −(T/2)(F_L − F_R), T the design track of the wheel centres)."""
    import numpy as np

    m = {k: np.asarray(v) for k, v in ev.metrics.items()}
    if key == "_contact_rearward":
        rc = ev.rig.corners[0]
        c = np.stack([m[f"contact_patch_{a}"] for a in "xyz"], axis=-1)
        return (c - c[_DESIGN]) @ np.asarray(rc.rearward)
    if key == "_roll_moment":
        track = abs(m["left/wheel_centre_y"][_DESIGN] - m["right/wheel_centre_y"][_DESIGN])
        return -0.5 * track * (m["left/vertical_force"] - m["right/vertical_force"])
    return m[key] if key in m else np.asarray(ev.x)  # the event's input (rack travel)


def _label(key, ev):
    from diffsusp.kc.metrics import METRICS

    base = key.rsplit("/", 1)[-1]
    if key not in ev.metrics and key == ev.x_name:
        return key, ev.x_unit, 1.0
    if key == "_contact_rearward":
        return "contact point rearward", "mm", 1.0
    if key == "_roll_moment":
        return "roll moment −(T/2)(F_L − F_R)", "N·m", 1e-3
    m = METRICS[base]
    return key, m.display_unit, m.scale


def metric_figure(name, events):
    """The PNG of metric `name`'s small figure, and for a slope the (metric, finite-difference
    slope) pair at design, both in internal units (the build checks they agree)."""
    import io

    import numpy as np
    from matplotlib.figure import Figure

    from diffsusp.kc.metrics import METRICS

    event, xkey, ykey, how = FIGURE_SPECS[name]
    ev = events[event]
    metric = METRICS[name]
    key = ("left/" + name if f"left/{name}" in ev.metrics else name)
    x, y = _series(ev, xkey), _series(ev, ykey)
    (xl, xu, xs), (yl, yu, ys) = _label(xkey, ev), _label(ykey, ev)
    fig = Figure(figsize=(3.3, 2.3), dpi=100, layout="constrained")
    ax = fig.add_subplot()
    ax.tick_params(labelsize=7)
    ax.plot(x * xs, y * ys, "-", color="0.35", lw=1.2)
    x0, y0 = x[_DESIGN] * xs, y[_DESIGN] * ys
    check = None
    if how == "value":
        ax.plot([x0], [y0], "o", color="C3", ms=5)
        ax.set_title(f"at design: {y0:.4g} {yu}", fontsize=7, color="C3")
    elif how == "x":
        ax.axvline(0.0, color="C3", lw=0.8, ls=":")
        ax.set_title(f"x: {metric.description} →", fontsize=7, color="C3")
    elif how == "slope":
        value = float(np.asarray(ev.metrics[key])[_DESIGN])
        fd = float(np.gradient(y, x)[_DESIGN])
        check = (value, fd)
        half = 0.5 * (x.max() - x.min()) * xs
        tx = np.array([x0 - 0.6 * half, x0 + 0.6 * half])
        ax.plot(tx, y0 + value * (ys / xs) * (tx - x0), "-", color="C3", lw=1.6)
        ax.plot([x0], [y0], "o", color="C3", ms=4)
        ax.set_title(f"slope = {value * metric.scale:.4g} {metric.display_unit}", fontsize=7,
                     color="C3")
    elif how == "roll_centre":  # front view of the contact point's path, and its normal
        rc = ev.rig.corners[0]
        o, z = np.asarray(rc.outboard), np.asarray(rc.up)
        c = np.stack([_series(ev, f"contact_patch_{a}") for a in "xyz"], axis=-1)
        lateral, height = c @ o, c @ z
        rch = float(np.asarray(ev.metrics[key])[_DESIGN])
        ax.cla()
        ax.tick_params(labelsize=7)
        ax.plot(lateral, height, "-", color="0.35", lw=1.2)
        ax.plot([lateral[_DESIGN], 0.0], [height[_DESIGN], height[_DESIGN] + rch], "-",
                color="C3", lw=1.2)
        ax.plot([0.0], [height[_DESIGN] + rch], "o", color="C3", ms=5)
        ax.axvline(0.0, color="0.6", lw=0.8, ls=":")
        ax.set_title(f"roll centre {rch:.4g} mm above C", fontsize=7, color="C3")
        ax.set_aspect("equal", adjustable="datalim")
        xl, xu, yl, yu = "C outboard (front view)", "mm", "C height", "mm"
        # the normal to the path at design, through C, meets the centreline at that height
        d = np.gradient(np.stack([lateral, height], axis=-1), axis=0)[_DESIGN]
        check = (rch, lateral[_DESIGN] * d[0] / d[1])
    ax.set_xlabel(f"{xl} ({xu})", fontsize=7)
    ax.set_ylabel(f"{yl} ({yu})", fontsize=7)
    ax.grid(True, lw=0.3)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue(), check


_FIGURE_CACHE = {}


def _figures() -> dict:
    """metric → PNG bytes, computed once per build (`_metric_events`: six events, ~10 s of
    CPU); each slope checked against the curve's central difference at design (to 3 %: the
    figure must show what the metric says)."""
    if "png" not in _FIGURE_CACHE:
        from diffsusp.kc.metrics import METRICS

        missing = sorted(set(METRICS) - set(FIGURE_SPECS))
        if missing:
            raise ValueError(f"docs/hooks.py: no figure for the metrics {missing}: add them to "
                             "FIGURE_SPECS")
        events = _metric_events()
        png, bad = {}, []
        for name in METRICS:
            png[name], check = metric_figure(name, events)
            if check is not None and not abs(check[0] - check[1]) <= 0.03 * abs(check[0]):
                bad.append((name, *check))
        if bad:
            raise ValueError(f"docs/hooks.py: metric figures whose slope disagrees with the "
                             f"curve (metric, finite difference): {bad}")
        _FIGURE_CACHE["png"] = png
    return _FIGURE_CACHE["png"]


# -- the tyre quantities ------------------------------------------------------------------------
# Descriptions (definition; sign) of the quantities that registries in diffsusp.tyre enumerate:
# the tables are generated from the registries, and a name a registry gains without a
# description here fails the build.

TYRE_INPUTS = {  # the parameters of diffsusp.tyre.evaluate (the options are left out)
    "fz": ("F_z", "vertical load, the road's force on the tyre along +z (up); F_z < 0 is set to "
           "0 with limits on", "N"),
    "kappa": ("κ", "longitudinal slip ratio (Ω·R_e − V_x)/V_x; driving (wheel faster than "
              "the road) positive", "-"),
    "alpha": ("α", "slip angle, about +z from the wheel heading to the wheel's velocity over "
              "the road; a positive α pushes the tyre to its right (F_y < 0)", "rad"),
    "gamma": ("γ", "inclination: rotation of the wheel plane about the heading, top of the "
              "wheel to the right of the heading positive", "rad"),
    "vx": ("V_x", "forward speed of the wheel centre over the road (default LONGVL), > 0", "mm/s"),
    "pressure": ("p_i", "inflation pressure (default INFLPRES); dp_i = (p_i − NOMPRES)/NOMPRES "
                 "in the formulas", "Pa"),
    "turn_slip": ("φ_t", "path curvature −ψ̇/V_c (turn slip, MF 6.1/6.2); None: no turn slip, "
                  "every ζ = 1", "1/mm"),
    "omega": ("Ω", "wheel spin used by turn slip (default from V_x, κ and R_e)", "rad/s"),
}
_TYRE_OPTIONS = ("model", "combined", "limits", "alpha_star", "outputs", "announce")
TYRE_OUTPUTS = {  # diffsusp.tyre.TyreForces
    "fx": ("F_x", "longitudinal force along the heading (x); driving positive", "N"),
    "fy": ("F_y", "lateral force along y (to the left of the heading)", "N"),
    "mx": ("M_x", "overturning moment about x (the heading)", "N·mm"),
    "my": ("M_y", "rolling resistance moment about y; negative when rolling forward", "N·mm"),
    "mz": ("M_z", "aligning (self-aligning) moment about z (up); positive for a small "
           "positive α: it turns the heading towards the wheel's velocity (it peaks at a few "
           "degrees and fades at large slip)", "N·mm"),
}
TYRE_SPEC = {  # diffsusp.tyre.spec.SPEC_UNITS: the columns of tyre.specification
    "fz": "the load they are computed at",
    "cornering_stiffness": "K_yα = ∂F_y/∂α at α = κ = γ = 0 (exact derivative); negative in "
                           "ISO-W",
    "slip_stiffness": "K_xκ = ∂F_x/∂κ at κ = α = γ = 0; positive",
    "aligning_stiffness": "K_zα = ∂M_z/∂α at zero slip and camber; positive in ISO-W",
    "pneumatic_trail": "t = −K_zα/K_yα: distance behind the contact point at which F_y acts "
                       "at small slip; positive for a usual tyre (the thesis's D_t of (2-122) "
                       "is its negative, in its units)",
    "camber_stiffness": "K_yγ = ∂F_y/∂γ at zero slip and camber (camber thrust)",
    "camber_torque_stiffness": "K_zγ = ∂M_z/∂γ at zero slip and camber",
    "fy_at_zero": "F_y at α = κ = γ = 0: the pull of the shifts S_Hy, S_Vy (conicity, ply "
                  "steer)",
    "mz_at_zero": "M_z at α = κ = γ = 0: the residual aligning torque",
    "fx_at_zero": "F_x at α = κ = γ = 0 (the shifts S_Hx, S_Vx)",
    "fy_peak": "the F_y extremum for α in (0, 0.35 rad] on the side of the slope (NaN: no "
               "peak inside, e.g. the thesis's sets with C = 1)",
    "alpha_at_fy_peak": "the slip angle of that extremum",
    "mz_peak": "the M_z extremum on the same side (the thesis's \"minimum M_z\" in PSA signs)",
    "alpha_at_mz_peak": "the slip angle of that extremum",
    "fx_peak": "the braking F_x extremum for κ in [−0.5, 0) (NaN: no peak inside); saturated "
               "at the file's KPUMIN",
    "kappa_at_fx_peak": "the slip ratio of that extremum (negative: braking)",
    "mu_y": "lateral friction coefficient |fy_peak|/F_z",
    "mu_x": "longitudinal (braking) friction coefficient |fx_peak|/F_z",
}
TYRE_VERTICAL = {  # diffsusp.tyre.vertical.VerticalState (tyre.vertical.loaded_radius)
    "rl": ("R_l", "loaded radius: wheel centre to the road along the wheel plane", "mm"),
    "deflection": ("ρ", "vertical deflection R_Ω − R_l (MF 6.2: ρ_z, camber included)", "mm"),
    "stiffness": ("C_z", "tangent vertical stiffness −∂F_z/∂R_l", "N/mm"),
    "secant": ("F_z/ρ", "secant vertical stiffness (MFeval's C_z output)", "N/mm"),
    "re": ("R_e", "effective rolling radius V_x/Ω at free rolling (Besselink (7))", "mm"),
    "romega": ("R_Ω", "free radius, grown by the centrifugal term", "mm"),
    "omega": ("Ω", "wheel spin", "rad/s"),
    "converged": ("—", "the load is reached (MF 6.2 may have no root at large camber)", "bool"),
}
TYRE_POLY = {  # diffsusp.tyre.poly.INPUT_UNITS: inputs of the polynomial models
    "fz": ("F_z", "vertical load (the load polynomials' variable)"),
    "kappa": ("κ′", "longitudinal deformation V_x/ω − R_r seen by the contact patch "
              "(2-92); κ′ = R_r(1/(κ + 1) − 1) (2-101): negative when driving"),
    "delta": ("δ′", "lateral deformation V_y/ω (2-93); δ′ = −R_r·tan δ (2-102): a positive "
              "slip angle δ is a negative δ′"),
    "phi": ("φ′", "torsion (pseudo-torsion) β̇/ω (2-94); φ′ = −R_r·φ (2-104), φ the path "
            "curvature at the wheel carrier"),
    "gamma": ("γ", "camber between the rim plane and the ground plane"),
    "pi_gamma_vx": ("π(γ, V_x)", "γ·V_x/ω (2-95)"),
    "pi_gamma_bdot": ("π(γ, β̇)", "γ·β̇/ω"),
    "pi_gamma2_bdot": ("π(γ², β̇)", "γ²·β̇/ω"),
    "fydot_w": ("Ḟ_y/ω", "rate of the lateral force per wheel spin: the relaxation columns "
                "(3-61, 3-62)"),
    "fy": ("F_y", "lateral force (the coupling column −F_y·F_x of M_z, 3-69)"),
    "fx": ("F_x", "longitudinal force (the same coupling column)"),
}
TYRE_ONBOARD = {  # diffsusp.tyre.onboard.QUANTITIES (onboard.quantities)
    "K_delta_front": ("K_δ(F_z,front)", "cornering stiffness in δ′ at the front load: "
                      "b_delta_2·F_z² + b_delta_1·F_z + b_delta_0 (4-17)", "N/m"),
    "K_delta_rear": ("K_δ(F_z,rear)", "the same at the rear load", "N/m"),
    "K_phi": ("K_φ", "torsion stiffness b_phi_1·F_z (4-18), at the first load", "N/rad"),
    "L_R": ("L_R", "relaxation coefficient of F_y = Fy_pneu + L_R·Ḟ_y/ω (4-16), "
            "b_L_2·F_z² + b_L_1·F_z + b_L_0, at the first load", "-"),
    "K_gamma": ("K_γ", "camber stiffness b_gamma_1·F_z (4-18), at the first load; negative "
                "(the naive pipeline of the thesis found it positive)", "N/rad"),
}


def _check_described(what, registry, described):
    missing = [k for k in registry if k not in described]
    stale = [k for k in described if k not in registry]
    if missing or stale:
        raise ValueError(f"docs/hooks.py: {what}: no description for {missing}, described but "
                         f"gone from the code: {stale}")


def _quantity_table(what, keys, described, first, sign="") -> str:
    """A Markdown table of `keys` (the code's registry, checked complete against `described`:
    key → (symbol, definition, unit))."""
    _check_described(what, keys, described)
    rows = [f"| {first} | symbol | definition{sign} | unit |", "|---|---|---|---|"]
    for k in keys:
        sym, text, unit = described[k]
        rows.append(f"| `{k}` | {sym} | {_cell(text)} | {unit} |")
    return "\n".join(rows) + "\n"


def tyre_inputs() -> str:
    import inspect

    from diffsusp.tyre import evaluate

    params = [p for p in inspect.signature(evaluate).parameters if p not in _TYRE_OPTIONS]
    return _quantity_table("tyre.evaluate's inputs", params, TYRE_INPUTS, "argument",
                           "; sign (ISO-W)")


def tyre_outputs() -> str:
    from diffsusp.tyre import TyreForces

    return _quantity_table("tyre.TyreForces", TyreForces._fields, TYRE_OUTPUTS, "field",
                           "; sign (ISO-W)")


def tyre_spec() -> str:
    """The specification columns (registry `tyre.spec.SPEC_UNITS`) with their values for the
    shipped MF 6.1 example at 3 kN and at FNOMIN (computed here, in one compiled call)."""
    import math

    import numpy as np

    from diffsusp.tyre.spec import SPEC_UNITS

    _check_described("tyre.spec.SPEC_UNITS", SPEC_UNITS, TYRE_SPEC)
    values = _tyre_example()["spec"]
    rows = ["| column | definition; sign | unit | MF 6.1 example, 3 kN | at FNOMIN |",
            "|---|---|---|---|---|"]
    for k, unit in SPEC_UNITS.items():
        v = np.asarray(values[k], dtype=float)
        shown = [f"{x:.4g}" for x in v]
        if unit == "rad":
            shown = [f"{x:.4g} ({math.degrees(x):.3g}°)" for x in v]
        rows.append(f"| `{k}` | {_cell(TYRE_SPEC[k])} | {unit} | {shown[0]} | {shown[1]} |")
    return "\n".join(rows) + "\n"


def tyre_vertical() -> str:
    from diffsusp.tyre.vertical import VerticalState

    return _quantity_table("tyre.vertical.VerticalState", VerticalState._fields, TYRE_VERTICAL,
                           "field")


def tyre_poly_inputs() -> str:
    from diffsusp.tyre.poly import INPUT_UNITS

    _check_described("tyre.poly.INPUT_UNITS", INPUT_UNITS, TYRE_POLY)
    rows = ["| key | symbol | definition; sign (PSA) | unit |", "|---|---|---|---|"]
    for k, unit in INPUT_UNITS.items():
        sym, text = TYRE_POLY[k]
        rows.append(f"| `{k}` | {sym} | {_cell(text)} | {unit} |")
    return "\n".join(rows) + "\n"


def tyre_onboard() -> str:
    from diffsusp.tyre.onboard import NAMES, QUANTITIES

    _check_described("tyre.onboard.QUANTITIES", QUANTITIES, TYRE_ONBOARD)
    rows = ["| quantity | symbol | definition; sign | unit |", "|---|---|---|---|"]
    for q in QUANTITIES:
        sym, text, unit = TYRE_ONBOARD[q]
        rows.append(f"| `{q}` | {sym} | {_cell(text)} | {unit} |")
    rows.append("")
    rows.append("Coefficients (`onboard.NAMES`): " + ", ".join(f"`{n}`" for n in NAMES) + ".")
    return "\n".join(rows) + "\n"


TYRE_FIGURES = "figures/tyre"  # relative to reference/tyre.md


def _tyre_example() -> dict:
    """The shipped MF 6.1 example (`tyre.example_path("mf61")`) at 3 kN and FNOMIN: its
    specification quantities (one compiled call) and the figures of the tyre reference."""
    if "tyre" in _FIGURE_CACHE:
        return _FIGURE_CACHE["tyre"]
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    from diffsusp import tyre
    from diffsusp.io.tir import read_tir

    model = tyre.MagicFormula6.from_tir(read_tir(tyre.example_path("mf61")))
    fnom = float(model["FNOMIN"])
    spec = {k: np.asarray(v) for k, v in tyre.specification(model, jnp.array([3000.0, fnom])
                                                             ).items()}
    alpha = np.radians(np.linspace(-15.0, 15.0, 121))
    kappa = np.linspace(-0.15, 0.15, 121)
    gamma = np.radians(np.linspace(-6.0, 6.0, 61))
    pure = tyre.evaluate(model, fnom, 0.0, jnp.asarray(alpha), combined=False)
    longi = tyre.evaluate(model, fnom, jnp.asarray(kappa), 0.0, combined=False)
    camber = tyre.evaluate(model, fnom, 0.0, 0.0, jnp.asarray(gamma), combined=False)
    i = 1  # FNOMIN
    png = {}
    deg = 180.0 / np.pi
    fy, mz = np.asarray(pure.fy), np.asarray(pure.mz) / 1e3
    y0 = float(spec["fy_at_zero"][i])
    k = float(spec["cornering_stiffness"][i])
    png["fy_alpha"] = _small_plot(
        alpha * deg, fy, "slip angle α (deg)", "F_y (N)",
        f"K_yα = {k / deg:.4g} N/deg; peak {float(spec['fy_peak'][i]):.4g} N",
        tangent=(0.0, y0, k / deg),
        mark=(float(spec["alpha_at_fy_peak"][i]) * deg, float(spec["fy_peak"][i])))
    kz = float(spec["aligning_stiffness"][i]) / 1e3
    png["mz_alpha"] = _small_plot(
        alpha * deg, mz, "slip angle α (deg)", "M_z (N·m)",
        f"K_zα = {kz / deg:.4g} N·m/deg; trail {float(spec['pneumatic_trail'][i]):.3g} mm",
        tangent=(0.0, float(spec["mz_at_zero"][i]) / 1e3, kz / deg),
        mark=(float(spec["alpha_at_mz_peak"][i]) * deg, float(spec["mz_peak"][i]) / 1e3))
    kx = float(spec["slip_stiffness"][i])
    png["fx_kappa"] = _small_plot(
        kappa, np.asarray(longi.fx), "slip ratio κ (-)", "F_x (N)", f"K_xκ = {kx:.4g} N",
        tangent=(0.0, float(spec["fx_at_zero"][i]), kx))
    kg = float(spec["camber_stiffness"][i])
    png["fy_gamma"] = _small_plot(
        gamma * deg, np.asarray(camber.fy), "inclination γ (deg)", "F_y (N)",
        f"K_yγ = {kg / deg:.4g} N/deg", tangent=(0.0, y0, kg / deg))
    png["mx_my"] = _small_plot(
        alpha * deg, np.asarray(pure.mx) / 1e3, "slip angle α (deg)", "moment (N·m)",
        "M_x (solid), M_y (dashed)", second=np.asarray(pure.my) / 1e3 + 0 * alpha)
    png["iso_w"] = _iso_w_sketch()
    png["poly_delta"] = _poly_figure()
    _FIGURE_CACHE["tyre"] = {"spec": spec, "png": png}
    return _FIGURE_CACHE["tyre"]


def _small_plot(x, y, xlabel, ylabel, title, *, tangent=None, mark=None, second=None):
    import io

    import numpy as np
    from matplotlib.figure import Figure

    fig = Figure(figsize=(3.6, 2.5), dpi=100, layout="constrained")
    ax = fig.add_subplot()
    ax.tick_params(labelsize=7)
    ax.plot(x, y, "-", color="0.3", lw=1.2)
    if second is not None:
        ax.plot(x, second, "--", color="0.3", lw=1.2)
    if tangent is not None:
        x0, y0, slope = tangent
        span = min(0.25 * (np.max(x) - np.min(x)),  # short: the curve stays readable
                   0.3 * (np.max(y) - np.min(y)) / max(abs(slope), 1e-300))
        tx = np.array([x0 - span, x0 + span])
        ax.plot(tx, y0 + slope * (tx - x0), "-", color="C3", lw=1.5)
    if mark is not None and np.all(np.isfinite(mark)):
        ax.plot([mark[0]], [mark[1]], "o", color="C3", ms=4)
    ax.axhline(0.0, color="0.7", lw=0.6)
    ax.axvline(0.0, color="0.7", lw=0.6)
    ax.set_title(title, fontsize=7, color="C3")
    ax.set_xlabel(xlabel, fontsize=7)
    ax.set_ylabel(ylabel, fontsize=7)
    ax.grid(True, lw=0.3)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def _iso_w_sketch():
    """Top view of a tyre in ISO-W: heading x, y to the left, the wheel's velocity at a
    positive slip angle α, and the lateral force it produces (to the right: F_y < 0)."""
    import io

    import numpy as np
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    fig = Figure(figsize=(3.4, 3.0), dpi=100, layout="constrained")
    ax = fig.add_subplot()
    ax.add_patch(Rectangle((-1.0, -0.35), 2.0, 0.7, fc="0.85", ec="0.3"))
    kw = dict(head_width=0.08, length_includes_head=True)
    ax.arrow(0, 0, 1.6, 0, color="k", **kw)
    ax.text(1.62, -0.05, "x (heading)", fontsize=7, va="top")
    ax.arrow(0, 0, 0, 1.3, color="k", **kw)
    ax.text(0.05, 1.3, "y (left)", fontsize=7)
    a = np.radians(25.0)
    ax.arrow(0, 0, 1.4 * np.cos(a), 1.4 * np.sin(a), color="C0", **kw)
    ax.text(1.3 * np.cos(a), 1.3 * np.sin(a) + 0.08, "V (wheel over road)", fontsize=7,
            color="C0", ha="right")
    t = np.linspace(0, a, 20)
    ax.plot(0.7 * np.cos(t), 0.7 * np.sin(t), color="C0", lw=0.8)
    ax.text(0.75, 0.12, "α > 0", fontsize=7, color="C0")
    ax.arrow(0.0, 0.0, 0.0, -1.0, color="C3", width=0.02, **kw)
    ax.text(0.08, -0.95, "F_y < 0", fontsize=7, color="C3")
    ax.text(0.45, -0.55, "z up, out of the page\nM_z > 0 turns x towards V", fontsize=7,
            va="top")
    ax.set_xlim(-1.2, 2.4)
    ax.set_ylim(-1.2, 1.6)
    ax.set_aspect("equal")
    ax.axis("off")
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def _poly_figure():
    """F_y of the thesis's Dunlop R16 polynomial (Annex G, 2 bar) against δ′ at three loads,
    with the slip angle δ = −atan(δ′/R_r) on the top axis (R_r = 0.294 m)."""
    import io

    import numpy as np
    from matplotlib.figure import Figure

    from diffsusp.tyre import poly

    fy = poly.PolynomialModel.from_annex_g("dunlop_r16", 2.0, "Fy")
    dp = np.linspace(-0.02, 0.02, 81)
    fig = Figure(figsize=(3.6, 2.7), dpi=100, layout="constrained")
    ax = fig.add_subplot()
    ax.tick_params(labelsize=7)
    for load in (3.0, 4.5, 6.0):
        ax.plot(1e3 * dp, np.asarray(fy({"fz": np.full_like(dp, load), "delta": dp})), lw=1.1,
                label=f"{load} kN")
    ax.set_xlabel("δ′ (mm)", fontsize=7)
    ax.set_ylabel("F_y (N)", fontsize=7)
    ax.legend(fontsize=6)
    ax.grid(True, lw=0.3)
    top = ax.secondary_xaxis("top", functions=(lambda d: -np.degrees(np.arctan(d / 294.0)),
                                               lambda a: -294.0 * np.tan(np.radians(a))))
    top.set_xlabel("δ (deg, PSA)", fontsize=7)
    top.tick_params(labelsize=7)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def cli_reference() -> str:
    """Markdown reference of every verb of `diffsusp`, from the Typer app."""
    import typer
    import typer.cli

    from diffsusp.cli import app

    command = typer.main.get_command(app)
    ctx = typer.Context(command)
    text = typer.cli.get_docs_for_click(obj=command, ctx=ctx, name="diffsusp", title=None)
    # Typer titles the page with a level-1 heading: the page has its own.
    return re.sub(r"\A# .*\n", "", text.lstrip())


GENERATORS = {"metrics": metrics_table, "cli": cli_reference, "tyre_inputs": tyre_inputs,
              "tyre_outputs": tyre_outputs, "tyre_spec": tyre_spec,
              "tyre_vertical": tyre_vertical, "tyre_poly_inputs": tyre_poly_inputs,
              "tyre_onboard": tyre_onboard}


# -- notebooks ----------------------------------------------------------------------------------

def source_hash(source: pathlib.Path) -> str:
    return hashlib.sha256(pathlib.Path(source).read_bytes()).hexdigest()


def saved_source_hash(saved: pathlib.Path):
    """The source SHA-256 an executed notebook saved by `save_executed` was stamped with."""
    import nbformat

    return nbformat.read(saved, as_version=4).metadata.get("diffsusp", {}).get("source_sha256")


def save_executed(nb, source: pathlib.Path) -> pathlib.Path:
    """Save an executed notebook (an `nbformat` node) of `notebooks/<source>` for the site, as
    `build/notebooks/<stem>.ipynb`, stamped with its source's SHA-256 and the time (written to
    a temporary name, then renamed: a build running meanwhile reads the old or the new)."""
    import nbformat

    source = pathlib.Path(source)
    nb.metadata["diffsusp"] = {
        "source": f"notebooks/{source.name}", "source_sha256": source_hash(source),
        "executed": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")}
    EXECUTED.mkdir(parents=True, exist_ok=True)
    path = EXECUTED / f"{source.stem}.ipynb"
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    nbformat.write(nb, tmp)
    os.replace(tmp, path)
    return path


def notebook_page(source: pathlib.Path, out_dir: pathlib.Path):
    """Write the notebook the site shows for `source` to `out_dir/<stem>.ipynb`: its executed
    copy (`save_executed`) when that copy's source hash is the source's, else the source
    without outputs; a note after the title says which. Returns (path, executed)."""
    import jupytext
    import nbformat

    source = pathlib.Path(source)
    saved = EXECUTED / f"{source.stem}.ipynb"
    nb, executed = None, False
    if saved.is_file():
        nb = nbformat.read(saved, as_version=4)
        stamp = nb.metadata.get("diffsusp", {})
        executed = stamp.get("source_sha256") == source_hash(source)
    run = f"`python -m pytest -n 0 tests/test_notebooks.py -k {source.stem}`"
    if executed:
        note = (f"*Executed by the test suite ({stamp['executed']}) from "
                f"`notebooks/{source.name}`; the outputs below are that run's.*")
    else:
        stale = nb is not None
        nb = jupytext.read(source)
        note = ("> **This page shows the notebook without its outputs**: "
                + ("its saved run is older than its source. " if stale else
                   "it has not been executed on the machine that built the site. ")
                + f"Run {run} (or the whole of `tests/test_notebooks.py`), then `mkdocs build`, "
                f"to see them; or open `notebooks/{source.name}` with Jupyter (jupytext).")
    cell = nbformat.v4.new_markdown_cell(note, id="diffsusp-site-note")
    if nb.nbformat_minor < 5:  # cell ids came with nbformat 4.5
        cell.pop("id")
    first = 1 if nb.cells and nb.cells[0].cell_type == "markdown" else 0
    nb.cells.insert(first, cell)
    out_dir = pathlib.Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"{source.stem}.ipynb"
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    nbformat.write(nb, tmp)
    os.replace(tmp, path)
    return path, executed


def render_notebook(path: pathlib.Path) -> str:
    """The HTML body mkdocs-jupyter makes of a notebook for its page (not executed)."""
    from mkdocs_jupyter.convert import nb2html

    return nb2html(str(path), execute=False)


def html_text(text: str) -> str:
    """Visible text of an HTML fragment (scripts, styles and tags removed, entities decoded)."""
    text = re.sub(r"<(script|style)\b.*?</\1>", "", text, flags=re.S)
    return html.unescape(re.sub(r"<[^>]+>", "", text))


@event_priority(50)  # before mkdocs-jupyter's on_files, which makes pages of the .ipynb files
def on_files(files, config):
    """Add `notebooks/<stem>.ipynb` (from `build/docs-pages/`) for every notebook."""
    for source in sorted(NOTEBOOKS.glob("[0-9]*.py")):
        path, _ = notebook_page(source, PAGES / "notebooks")
        files.append(File(f"notebooks/{path.name}", src_dir=str(PAGES),
                          dest_dir=config["site_dir"],
                          use_directory_urls=config["use_directory_urls"]))
    for name, png in _figures().items():
        files.append(File.generated(config, f"reference/{FIGURES}/{name}.png", content=png))
    for name, png in _tyre_example()["png"].items():
        files.append(File.generated(config, f"reference/{TYRE_FIGURES}/{name}.png", content=png))
    return files


def on_page_markdown(markdown, page, config, files):  # noqa: ARG001 (mkdocs hook signature)
    def replace(match):
        try:
            generate = GENERATORS[match.group(1)]
        except KeyError:
            raise ValueError(f"{page.file.src_path}: unknown generated block "
                             f"{match.group(1)!r} (known: {sorted(GENERATORS)})") from None
        return generate()

    return _MARKER.sub(replace, markdown)
