"""Figures (matplotlib): K&C curves of models and measurements, sensitivity bars, and the
identification figures (convergence histories, measured vs model per load case).

Every function returns a `matplotlib.figure.Figure` (made without pyplot, so nothing is kept in a
global figure list; in a notebook it displays as the cell's value) and accepts `ax=` to draw into
existing axes. Values are shown in display units (deg, deg/m, deg/kN, N/mm; see
`diffsusp.kc.METRICS`); events hold internal units. `save(fig, stem)` writes PNG and SVG.

matplotlib is imported when the first figure is made, not with this module (the identification
reports import it; a report that is only printed never loads matplotlib). Without a display (no
`DISPLAY`, no `MPLBACKEND`, not in a notebook kernel), the Agg backend is selected then.
"""

from __future__ import annotations

import os
import pathlib
import sys
import textwrap
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from .kc.metrics import METRICS, display

if TYPE_CHECKING:
    from matplotlib.figure import Figure


_BACKEND_CHOSEN = []


def _figure(**kwargs) -> Figure:
    """A new `matplotlib.figure.Figure` (no pyplot); the backend is chosen once, at the first."""
    import matplotlib

    if not _BACKEND_CHOSEN:
        _BACKEND_CHOSEN.append(True)
        if (sys.platform.startswith("linux") and not os.environ.get("DISPLAY")
                and not os.environ.get("WAYLAND_DISPLAY") and not os.environ.get("MPLBACKEND")
                and "ipykernel" not in sys.modules):
            matplotlib.use("Agg")
    from matplotlib.figure import Figure

    return Figure(**kwargs)

_X_LABELS = {
    "wheel_travel": "wheel travel",
    "vertical_force": "vertical force",
    "lateral_force": "lateral force (inboard +)",
    "longitudinal_force": "longitudinal force (braking +)",
    "braking_force": "braking force",
    "traction_force": "traction force",
    "aligning_torque": "aligning torque (toe-out +)",
    "rack_travel": "rack travel (left +)",
    "case": "load case",
}
_X_DISPLAY = {"N·mm": ("N·m", 1e-3)}


def _metric_label(name: str) -> str:
    unit, shown, _, description = METRICS.get(name, ("", "", 1.0, name.replace("_", " ")))
    return f"{description} ({shown})" if shown not in ("", "-") else description


def _x_of(ev):
    unit, scale = _X_DISPLAY.get(ev.x_unit, (ev.x_unit, 1.0))
    label = _X_LABELS.get(ev.x_name, ev.x_name.replace("_", " "))
    return np.asarray(ev.x) * scale, f"{label} ({unit})" if unit else label


def _series(ev, metric):
    """(label suffix, values) for `metric` in an event: one series, or one per axle corner."""
    if metric in ev.metrics:
        return [("", ev.metrics[metric])]
    found = [(k.split("/")[0], v) for k, v in ev.metrics.items()
             if "/" in k and k.rsplit("/", 1)[1] == metric]
    if not found:
        raise KeyError(
            f"event '{ev.name}' ({ev.label}) has no metric '{metric}'; it has: "
            f"{', '.join(sorted(ev.metrics))}."
        )
    return found


def _new_axes(n: int, ax, width=6.4, height=2.6):
    if ax is None:
        fig = _figure(figsize=(width, height * n + 0.6), layout="constrained")
        axes = fig.subplots(n, 1, squeeze=False)[:, 0]
        return fig, list(axes)
    axes = list(ax) if isinstance(ax, Sequence | np.ndarray) else [ax]
    if len(axes) != n:
        raise ValueError(f"ax= must give {n} axes (one per metric); got {len(axes)}.")
    return axes[0].figure, axes


LEGEND_WIDTH = 32
"""Characters per legend line of `kc_curves` (longer labels wrap)."""


def kc_curves(events, metrics=("toe", "camber", "half_track_change"), *, labels=None,
              measured=None, ax=None, title: str | None = None) -> Figure:
    """K&C curves: each metric against the events' input, one panel per metric, one line per
    event (and per corner of an axle), measured data as markers on the same axes.

    **Arguments:**

    - `events`: a `KCEvent` or a list of them (e.g. several models under the same event).
    - `metrics`: metric names (see `diffsusp.kc.METRICS`), e.g. ('toe', 'camber') or
      ('steer', 'camber') for a lateral-force event.
    - `labels`: legend labels, one per event (default: each event's `label`).
    - `measured`: a dict or list of dicts, each {'label': str, 'x': array (the events' input,
      internal units), metric: array (internal units), ...}; metrics it lacks are skipped.
    - `ax`: one Axes per metric (a single Axes for one metric).
    - `title`: figure title.

    **Returns:** the Figure.
    """
    events = list(events) if isinstance(events, list | tuple) else [events]
    if not events:
        raise ValueError("kc_curves needs at least one event.")
    metrics = [metrics] if isinstance(metrics, str) else list(metrics)
    labels = labels or [ev.label for ev in events]
    if len(labels) != len(events):
        raise ValueError(f"labels: {len(labels)} given for {len(events)} events.")
    measured = [] if measured is None else (
        [measured] if isinstance(measured, dict) else list(measured))
    fig, axes = _new_axes(len(metrics), ax)
    xlabel = None
    for a, metric in zip(axes, metrics, strict=True):
        for ev, label in zip(events, labels, strict=True):
            x, xlabel = _x_of(ev)
            for suffix, values in _series(ev, metric):
                name = f"{label} ({suffix})" if suffix else label
                a.plot(x, display(metric, values), marker="." if x.size < 30 else None,
                       label=textwrap.fill(name, LEGEND_WIDTH))
        for data in measured:
            if metric not in data:
                continue
            scale = _X_DISPLAY.get(events[0].x_unit, ("", 1.0))[1]
            a.plot(np.asarray(data["x"]) * scale, display(metric, data[metric]), "o",
                   mfc="none", label=data.get("label", "measured"))
        a.set_ylabel(_metric_label(metric))
        a.grid(True, alpha=0.3)
        # beside the axes, not on them: an axle's default label (its two corners' model
        # names) runs to ~90 characters and would squeeze the curves
        a.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.02, 1.0),
                 borderaxespad=0.0)
    for a in axes:
        a.set_xlabel(xlabel)
    if title:
        fig.suptitle(title)
    return fig


def sensitivity_bars(values, names, *, ax=None, title: str | None = None,
                     xlabel: str = "normalised sensitivity", sort: bool = True,
                     top: int | None = None) -> Figure:
    """Horizontal bar chart of sensitivities (e.g. ∂metric/∂parameter × parameter/metric), the
    largest magnitude on top; positive and negative values in two colours.

    **Arguments:** `values` (n,), `names` (n,), `ax`, `title`, `xlabel`, `sort` (by |value|),
    `top` (keep the `top` largest).

    **Returns:** the Figure.
    """
    values = np.asarray(values, dtype=float).ravel()
    names = [str(n) for n in names]
    if values.size != len(names):
        raise ValueError(f"sensitivity_bars: {values.size} values for {len(names)} names.")
    order = np.argsort(-np.abs(np.nan_to_num(values))) if sort else np.arange(values.size)
    if top is not None:
        order = order[:top]
    values, names = values[order], [names[i] for i in order]
    if ax is None:
        fig = _figure(figsize=(6.4, 0.6 + 0.32 * max(len(names), 1)), layout="constrained")
        ax = fig.subplots()
    else:
        fig = ax.figure
    y = np.arange(len(names))[::-1]
    colours = np.where(values >= 0, "tab:blue", "tab:red")
    ax.barh(y, values, color=colours)
    ax.set_yticks(y, names)
    ax.axvline(0.0, color="black", lw=0.8)
    ax.set_xlabel(xlabel)
    ax.grid(True, axis="x", alpha=0.3)
    if title:
        ax.set_title(title)
    return fig


def convergence(histories: dict, *, ylabel: str, log: bool = True, xlabel: str = "iteration",
                title: str | None = None, ax=None) -> Figure:
    """Convergence of an identification: one line per named history (label → values per
    iteration or step), e.g. each stiffness relative to its final value, or the loss.

    **Returns:** the Figure.
    """
    if ax is None:
        fig = _figure(figsize=(6.4, 3.6), layout="constrained")
        ax = fig.subplots()
    else:
        fig = ax.figure
    for label, values in histories.items():
        values = np.asarray(values, dtype=float)
        ax.plot(np.arange(1, values.size + 1), values, marker=".", label=str(label))
    if log:
        ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    if len(histories) <= 16:
        ax.legend(fontsize="x-small", ncols=2 if len(histories) > 6 else 1)
    if title:
        ax.set_title(title)
    return fig


def case_comparison(series: dict, channels: Sequence[tuple[str, str]], *, measured: str =
                    "measured", title: str | None = None, ax=None) -> Figure:
    """Measured vs model, load case by load case: one panel per channel, the measured values as
    markers and each model (e.g. start and identified) as a line.

    **Arguments:** `series`: label → {channel: (cases,) values, in the units shown}; the entry
    labelled `measured` is drawn as markers. `channels`: (key, axis label with unit) pairs.

    **Returns:** the Figure.
    """
    fig, axes = _new_axes(len(channels), ax)
    for a, (key, label) in zip(axes, channels, strict=True):
        for name, values in series.items():
            if key not in values:
                continue
            v = np.asarray(values[key], dtype=float)
            x = np.arange(1, v.size + 1)
            if name == measured:
                a.plot(x, v, "o", mfc="none", ms=8, label=name)
            else:  # load cases are categorical: a tick per case, no line between them
                a.plot(x, v, ls="none", marker="_", ms=12, mew=2, label=name)
        a.set_ylabel(label)
        a.grid(True, alpha=0.3)
        a.legend(fontsize="small")
    axes[-1].set_xlabel("load case")
    if title:
        fig.suptitle(title)
    return fig


def save(fig: Figure, stem, formats=("png", "svg"), dpi: int = 120) -> list[pathlib.Path]:
    """Write `fig` as `<stem>.png` and `<stem>.svg` (parent folders created); returns the
    paths."""
    stem = pathlib.Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    paths = []
    engine = fig.get_layout_engine()
    if engine is not None and len(formats) > 1:
        # The layout (constrained: ~40 % of a save) is computed once, at the raster's
        # resolution (the PNG is the one `savefig` writes), not once per format; the figure
        # gets its engine back afterwards.
        shown_dpi = fig.dpi
        fig.set_dpi(dpi)
        try:
            engine.execute(fig)
        finally:
            fig.set_dpi(shown_dpi)
        fig.set_layout_engine("none")
    try:
        for fmt in formats:
            path = stem.with_suffix("." + fmt)
            fig.savefig(path, dpi=dpi)
            paths.append(path)
    finally:
        if engine is not None and fig.get_layout_engine() is not engine:
            fig.set_layout_engine(engine)
    return paths
