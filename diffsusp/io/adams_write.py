"""Writing Adams datasets (.adm): a complete dataset from a `Mechanism`, or identified
stiffnesses written into the dataset the model came from (spec stiffness §4.1, §6 item 10).
`diffsusp.io.adams` re-exports `write_adm`."""

import warnings
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from ..errors import ModelError, ModelWarning
from ..geometry import matrix_to_reuler_deg
from ..model import Mechanism
from ..model.builder import frame_from_axes
from .adams_common import (
    fmt,
    read_source,
)
from .adams_plan import parse_adm


def write_adm(mech: Mechanism, path, *, template=None) -> str:
    """Write `mech` as an Adams dataset; returns the text written.

    - With `template` (the path or text of the .adm the mechanism came from): the template's
      text is kept and only stiffnesses are updated, in the template's units — BUSHING K and KT
      of the bushings named like `mech`'s, SPRINGDAMPER K and LENGTH of its springs, and the Y
      values of A/Car bushing splines (``<bushing>_{fx..tz}_spline``, Y = −K·X, spec stiffness
      §4.3, X of torque splines in rad). This is the thesis's workflow of writing identified
      stiffnesses back.
    - Without: a complete dataset in mm, N: one PART per part, one MARKER per marker (QP and
      REULER in degrees, global at design), JOINT/JPRIM for joints, GCON DM(i, j) − L for
      distance joints, BUSHING, SPRINGDAMPER, a two-body TRANSLATIONAL SFORCE per stop
      (`stop_function`: k·p + cubic·p³ of MAX(0, …) of DM(i, j), exact; so a Chrono
      `Spring Curve Data` spring, read as a linear spring plus stops at its knots, is written
      exactly), a zero GFORCE per load point (the user's loads go in load cases) and a MOTION
      per driver. `read_adm` of the result gives the same mechanism. Laws outside the .adm
      subset (nonlinear tables, cubic laws, bushing splines or translational offsets) raise
      `ModelError`.

    **Arguments:** `mech`; `path` (file to write, or None to only return the text);
    `template` (path or text).
    """
    text = _write_with_template(mech, template) if template is not None else _write_full(mech)
    if path is not None:
        Path(path).write_text(text)
    return text


def _write_full(mech: Mechanism) -> str:
    out = [f"ADAMS/View model name: {mech.name}",
           "UNITS/FORCE = NEWTON, MASS = KILOGRAM, LENGTH = MILLIMETER, TIME = SECOND",
           "! adams_view_name='ground'", "PART/1, GROUND"]
    for k, part in enumerate(mech.parts):
        out += [f"! adams_view_name='{part}'", f"PART/{k + 2}"]
    pos = np.asarray(mech.markers.position, float)
    rot = np.asarray(mech.markers.orientation, float)
    ids = {}
    for k, name in enumerate(mech.markers.names):
        ids[k] = k + 1
        part = mech.markers.part[k]
        line = f"MARKER/{k + 1}, PART = {1 if part < 0 else part + 2}"
        line += ", QP = " + ", ".join(fmt(v) for v in pos[k])
        if not np.allclose(rot[k], np.eye(3), rtol=0, atol=1e-15):
            angles = np.asarray(matrix_to_reuler_deg(jnp.asarray(rot[k])))
            line += ", REULER = " + ", ".join(fmt(a) + "D" for a in angles)
        out += [f"! adams_view_name='{name}'", line]
    next_id = len(mech.markers.names) + 1
    aux = []

    def aux_marker(position=(0.0, 0.0, 0.0), rotation=None, floating=False):
        nonlocal next_id
        ident = next_id
        next_id += 1
        line = f"MARKER/{ident}, PART = 1"
        if floating:
            line += ", FLOATING"
        else:
            line += ", QP = " + ", ".join(fmt(v) for v in position)
            if rotation is not None and not np.allclose(rotation, np.eye(3), rtol=0, atol=1e-15):
                angles = np.asarray(matrix_to_reuler_deg(jnp.asarray(rotation)))
                line += ", REULER = " + ", ".join(fmt(a) + "D" for a in angles)
        aux.append(line)
        return ident

    elements = []
    j = mech.joints
    adams_joint = {"spherical": "JOINT/{}, SPHERICAL", "revolute": "JOINT/{}, REVOLUTE",
                   "cylindrical": "JOINT/{}, CYLINDRICAL",
                   "translational": "JOINT/{}, TRANSLATIONAL",
                   "universal": "JOINT/{}, UNIVERSAL", "fixed": "JOINT/{}, FIXED",
                   "inline": "JPRIM/{}, INLINE", "inplane": "JPRIM/{}, INPLANE",
                   "perpendicular": "JPRIM/{}, PERPENDICULAR"}
    for k, (name, kind) in enumerate(zip(j.names, j.kind, strict=True)):
        i_id, j_id = ids[j.i_marker[k]], ids[j.j_marker[k]]
        elements.append(f"! adams_view_name='{name}'")
        if kind == "distance":
            length = float(np.linalg.norm(pos[j.i_marker[k]] - pos[j.j_marker[k]]))
            elements.append(f"GCON/{k + 1}, I = {i_id}, FUNCTION = DM({i_id}, {j_id}) - "
                            f"{fmt(length)}")
        else:
            elements.append(adams_joint[kind].format(k + 1) + f", I = {i_id}, J = {j_id}")
    b = mech.bushings
    for k, name in enumerate(b.names):
        arrays = {f: np.asarray(getattr(b, f)[k], float) for f in
                  ("k_trans", "k_rot", "cubic_trans", "cubic_rot", "offset_trans", "offset_rot",
                   "preload_force", "preload_torque")}
        if any(b.spline_axes[k]) or np.any(arrays["cubic_trans"]) or np.any(
                arrays["cubic_rot"]) or np.any(arrays["offset_trans"]):
            raise ModelError(f"bushing '{name}' has a spline, cubic or offset law, which the "
                             ".adm subset (linear BUSHING) cannot express.")
        i_id, j_id = ids[b.i_marker[k]], ids[b.j_marker[k]]
        elements.append(f"! adams_view_name='{name}'")
        torsion = (not np.any(arrays["k_trans"]) and not np.any(arrays["k_rot"][:2])
                   and not np.any(arrays["preload_force"])
                   and not np.any(arrays["preload_torque"][:2])
                   and not np.any(arrays["offset_rot"][:2]))
        if np.any(arrays["offset_rot"]) and not torsion:
            raise ModelError(f"bushing '{name}' has rotational offsets on more than its z axis; "
                             "the .adm subset cannot express them.")
        if torsion and np.any(arrays["offset_rot"]):
            elements.append(
                f"SPRINGDAMPER/{k + 1}, ROTATIONAL, I = {i_id}, J = {j_id}, "
                f"KT = {fmt(arrays['k_rot'][2])}, CT = 0, ANGLE = {fmt(arrays['offset_rot'][2])}"
                f", TORQUE = {fmt(arrays['preload_torque'][2])}")
            continue
        line = (f"BUSHING/{k + 1}, I = {i_id}, J = {j_id}, K = "
                + ", ".join(fmt(v) for v in arrays["k_trans"]) + ", C = 0, 0, 0, KT = "
                + ", ".join(fmt(v) for v in arrays["k_rot"]) + ", CT = 0, 0, 0")
        if np.any(arrays["preload_force"]):
            line += ", FORCE = " + ", ".join(fmt(v) for v in arrays["preload_force"])
        if np.any(arrays["preload_torque"]):
            line += ", TORQUE = " + ", ".join(fmt(v) for v in arrays["preload_torque"])
        elements.append(line)
    s = mech.springs
    offset = len(b.names)
    for k, name in enumerate(s.names):
        i_id, j_id = ids[s.i_marker[k]], ids[s.j_marker[k]]
        free = float(s.free_length[k])
        if s.tabulated[k]:
            x, y = np.asarray(s.table_x[k], float), np.asarray(s.table_y[k], float)
            slope = (y[-1] - y[0]) / (x[-1] - x[0])
            intercept = y[0] - slope * x[0]
            if not np.allclose(y, intercept + slope * x, rtol=1e-12, atol=1e-9):
                raise ModelError(f"spring '{name}' has a nonlinear table, which the .adm "
                                 "subset cannot express.")
            # tension = slope·(ℓ − free) + intercept = K·(ℓ − LENGTH) − FORCE
            k_value, length, force = slope, free, -intercept
        else:
            k_value, length, force = float(s.k[k]), free, 0.0
        elements += [f"! adams_view_name='{name}'",
                     f"SPRINGDAMPER/{offset + k + 1}, TRANSLATIONAL, I = {i_id}, J = {j_id}, "
                     f"K = {fmt(k_value)}, C = 0, LENGTH = {fmt(length)}, FORCE = {fmt(force)}"]
    st = mech.stops
    for k, name in enumerate(st.names):
        elements += [f"! adams_view_name='{name}'",
                     f"SFORCE/{k + 1}, TRANSLATIONAL, I = {ids[st.i_marker[k]]}, "
                     f"J = {ids[st.j_marker[k]]}, FUNCTION = "
                     + stop_function(st.kind[k], float(st.length[k]), float(st.k[k]),
                                     float(st.cubic[k]), ids[st.i_marker[k]],
                                     ids[st.j_marker[k]])]
    lp = mech.load_points
    for k, name in enumerate(lp.names):
        jfloat = aux_marker(floating=True)
        rm = ids[lp.frame[k]] if lp.frame[k] >= 0 else aux_marker()
        elements += [f"! adams_view_name='{name}'",
                     f"GFORCE/{k + 1}, I = {ids[lp.marker[k]]}, JFLOAT = {jfloat}, RM = {rm}",
                     ", FX = 0\\", ", FY = 0\\", ", FZ = 0\\", ", TX = 0\\", ", TY = 0\\",
                     ", TZ = 0"]
    d = mech.drivers
    for k, name in enumerate(d.names):
        direction = np.asarray(d.direction[k], float)
        j_id = aux_marker(pos[d.marker[k]], frame_from_axes(direction))
        elements += [f"! adams_view_name='{name}'",
                     f"MOTION/{k + 1}, I = {ids[d.marker[k]]}, J = {j_id}, Z, FUNCTION = 0"]
    return "\n".join(out + aux + elements + ["END", ""])


def stop_function(kind: str, length: float, k: float, cubic: float, i: int, j: int) -> str:
    """The SFORCE FUNCTION of a one-sided stop (`diffsusp.model.Stops`) on markers i, j:
    k·p + cubic·p³ with the penetration p = MAX(0, length − DM(i, j)) of a bump stop (a
    positive SFORCE pushes the markers apart) or p = MAX(0, DM(i, j) − length) of a rebound
    stop (the force negated: it pulls them together). Exact, where the Akima spline of an
    AKISPL spring would round the kinks of a piecewise-linear law (Chrono's `Spring Curve
    Data`); `diffsusp.io.adams.stop_of_function` reads it back."""
    dm = f"DM({i}, {j})"
    p = (f"MAX(0, {fmt(length)} - {dm})" if kind == "bump"
         else f"MAX(0, {dm} - {fmt(length)})")
    law = f"{fmt(k)} * {p}" + (f" + {fmt(cubic)} * {p}**3" if cubic else "")
    return law if kind == "bump" else f"-({law})"


def _write_with_template(mech: Mechanism, template) -> str:
    text, path = read_source(template, "Adams dataset")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ModelWarning)
        model = parse_adm(text)
    lines = text.splitlines()
    edits: list[tuple[int, int, int, str]] = []
    lf, ff = model.length_to_mm, model.force_to_n
    plan = model.plan
    names = {s.line: n for s, _, (n, *_), _ in plan.calls}

    def replace(s, key, values):
        arg = s.arguments.get(key)
        if arg is not None and len(arg.values) == len(values):
            for v, new in zip(arg.values, values, strict=True):
                edits.append((v.line, v.start, v.end, fmt(new)))
        else:
            if arg is not None:
                raise ModelError(f"{s.label}: {key} has {len(arg.values)} value(s) in the "
                                 f"template; expected {len(values)}.")
            last = s.end_line
            edits.append((last, len(lines[last - 1]), len(lines[last - 1]),
                          f", {key} = " + ", ".join(fmt(v) for v in values)))

    bushings, springs = mech.bushings, mech.springs
    for s in model.statements:
        name = names.get(s.line)
        if s.keyword == "BUSHING" and name in bushings.names:
            k = bushings.index(name)
            replace(s, "K", np.asarray(bushings.k_trans[k]) * lf / ff)
            replace(s, "KT", np.asarray(bushings.k_rot[k]) / (ff * lf))
        elif (s.keyword == "SPRINGDAMPER" and "ROTATIONAL" not in s.flags
              and name in springs.names):
            k = springs.names.index(name)
            if springs.tabulated[k]:
                raise ModelError(f"spring '{name}' is tabulated; its SPRINGDAMPER cannot be "
                                 "updated.")
            k_file = float(springs.k[k]) * lf / ff
            force = plan.reals(s, "FORCE", 1, default=(0,))[0]
            replace(s, "K", [k_file])
            replace(s, "LENGTH", [float(springs.free_length[k]) / lf - force / k_file])
    for stem, group in model.spline_bushings().items():
        target = stem if stem in bushings.names else next(
            (n for n in bushings.names if stem.endswith("_" + n)), None)
        if target is None:
            continue
        k = bushings.index(target)
        for axis, spline in group.items():
            a = "xyz".index(axis[1])
            if axis[0] == "t":
                slope = float(bushings.k_trans[k, a]) * lf / ff
            else:
                slope = float(bushings.k_rot[k, a]) / (ff * lf)
            s = next(st for st in model.statements
                     if st.keyword == "SPLINE" and st.id == spline.id)
            replace(s, "Y", -slope * spline.x)
    for line, start, end, new in sorted(edits, key=lambda e: (e[0], -e[1])):
        row = lines[line - 1]
        lines[line - 1] = row[:start] + new + row[end:]
    return "\n".join(lines) + "\n"
