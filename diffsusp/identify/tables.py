"""Report tables in the thesis's units (spec stiffness ch. 4: rotational stiffnesses per degree)
and the figures of the `iterative` and `least_squares` identifications: the rows the CLI writes
to its CSV reports (a file format: the columns stay as they are), the rows of the estimate at
an interruption, and the convergence and measured-vs-model figures.

The reports' own `rows()` (`IdentificationReport.rows`) are the common API in model units;
these are the per-method tables of `diffsusp identify iterative|fit`.
"""

from collections.abc import Sequence

import numpy as np

from .. import kc, plot
from ..errors import InputError
from ..geometry import DEG
from ..kc.metrics import corner_geometry
from ..model import Mechanism
from ..statics import part_poses, solve_statics
from ._iterative import AXES, IterationRecord, IterativeReport
from ._least_squares import FitReport, StepRecord
from .params import Params
from .selection import ROTATIONAL, display_value


def _stiffness_display(axis: str) -> tuple[float, str]:
    return (DEG, "N*mm/deg") if axis in ROTATIONAL else (1.0, "N/mm")


def interrupted_iterative_rows(mech0: Mechanism, names: Sequence[str],
                               record: IterationRecord | None) -> list[dict]:
    """The estimate of the last finished iteration (`record`; None: none finished, no rows),
    one row per bushing × axis: parameter, value, unit, start (from `mech0`), status
    'interrupted'."""
    if record is None:
        return []
    rows = []
    for b, name in enumerate(names):
        index = mech0.bushings.index(name)
        for a, axis in enumerate(AXES):
            scale, unit = _stiffness_display(axis)
            start = (mech0.bushings.k_trans if a < 3 else mech0.bushings.k_rot)[index][a % 3]
            rows.append(dict(parameter=f"{name}.{axis}",
                             value=float(record.stiffness[b, a] * scale), unit=unit,
                             start=float(start) * scale, status="interrupted"))
    return rows


def interrupted_fit_rows(params: Params, record: StepRecord | None) -> list[dict]:
    """The estimate after the last accepted LM step (`record`; None: no rows): parameter,
    value, unit, start, step, status 'interrupted'."""
    if record is None:
        return []
    rows = []
    for k, name in enumerate(params.names):
        value, unit = display_value(name, float(record.estimate[k]))
        rows.append(dict(parameter=name, value=value, unit=unit,
                         start=float(display_value(name, float(params.start[k]))[0]),
                         step=record.step, status="interrupted"))
    return rows


def case_channels(mech: Mechanism, q):
    """Per-case channels for the measured-vs-model figure: toe, camber (deg) and wheel-centre
    height (mm) of the model's wheel corner when it has one, else the displacement of each of
    the first three parts' frame origins (mm). `q`: (cases, n) public coordinates. Returns
    (values by channel, [(channel, label)], the wheel's part index or None)."""
    import jax


    try:
        rc = kc.default_corner(mech).resolve(mech)
    except (InputError, KeyError, ValueError):
        rc = None
    if rc is not None:
        geo = jax.vmap(lambda qq: corner_geometry(mech, rc, qq))(q)
        return ({"toe": np.degrees(np.asarray(geo["toe"])),
                 "camber": np.degrees(np.asarray(geo["camber"])),
                 "wheel_centre_z": np.asarray(geo["wheel_centre_z"])},
                [("toe", "toe (deg, in +)"), ("camber", "camber (deg)"),
                 ("wheel_centre_z", "wheel centre z (mm)")], mech.markers.part[rc.wheel_centre])
    _, trans = part_poses(mech, q)
    trans = np.asarray(trans)
    parts = mech.parts[:3]
    values = {part: np.linalg.norm(trans[:, p], axis=-1) for p, part in enumerate(parts)}
    return values, [(part, f"{part} displacement (mm)") for part in parts], None


def comparison_figure(mech_start: Mechanism, mech_fitted: Mechanism, meas, title: str):
    """Measured vs start vs identified model per load case (`case_channels`; the measured
    series only where the channel's parts are measured). Returns the matplotlib Figure."""
    series = {}
    values, channels, wheel_part = case_channels(mech_fitted, meas.coordinates(
        mech_fitted, unmeasured="design"))
    measured_parts = set(meas.parts)
    if wheel_part is not None and mech_fitted.parts[wheel_part] in measured_parts:
        series["measured"] = values
    elif wheel_part is None:
        series["measured"] = {k: v for k, v in values.items() if k in measured_parts}
    for label, m in (("start model", mech_start), ("identified", mech_fitted)):
        sol = solve_statics(m, meas.loads, throw=False)
        series[label] = case_channels(m, sol.q)[0]
    return plot.case_comparison(series, channels, title=title)


def iterative_figures(report: IterativeReport, mech0: Mechanism, fitted: Mechanism,
                      meas) -> dict:
    """{'iterative_convergence': |K/K_final − 1| per identified direction and iteration,
    'iterative_cases': `comparison_figure`} (matplotlib Figures)."""
    k = np.stack([r.stiffness for r in report.history])  # (iterations, n, 6)
    ok = np.asarray(report.identified, dtype=bool)
    histories = {f"{name}.{axis}": np.abs(k[:, b, a] / report.stiffness[b, a] - 1.0) + 1e-16
                 for b, name in enumerate(report.bushings) for a, axis in enumerate(AXES)
                 if ok[b, a]}
    return {"iterative_convergence": plot.convergence(
                histories, ylabel="|K / K_final − 1|",
                title=f"{fitted.name}: iterative identification"),
            "iterative_cases": comparison_figure(mech0, fitted, meas,
                                                 f"{fitted.name}: measured vs identified")}


def fit_figures(report: FitReport, mech0: Mechanism, fitted: Mechanism, meas) -> dict:
    """{'fit_convergence': the loss ½Σr² at each accepted LM step, 'fit_cases':
    `comparison_figure`} (matplotlib Figures)."""
    loss = np.array([r.trial_loss for r in report.history], dtype=float)
    accepted = np.array([r.accepted for r in report.history], dtype=bool)
    losses = {"loss ½Σr² at the estimate": np.where(accepted, np.maximum(loss, 1e-300),
                                                    np.nan).tolist()}
    return {"fit_convergence": plot.convergence(losses, ylabel="loss", xlabel="LM step",
                                                title=f"{fitted.name}: least-squares fit"),
            "fit_cases": comparison_figure(mech0, fitted, meas,
                                           f"{fitted.name}: measured vs identified")}


__all__ = ["case_channels", "comparison_figure", "fit_figures", "interrupted_fit_rows",
           "interrupted_iterative_rows", "iterative_figures"]
