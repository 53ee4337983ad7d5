"""Figures (diffsusp.plot): K&C curves and sensitivity bars, written as PNG and SVG.

The events here are built from known arrays (no solve): what is tested is what the figures
show — display units (deg, deg/m), labelled axes with units, one line per event and per axle
corner, measured data as markers, files that exist and are not empty.
"""

import numpy as np
import pytest
from matplotlib.figure import Figure

from diffsusp import kc, plot

TRAVEL = np.linspace(-80.0, 80.0, 9)


def event(label, toe_slope, axle=False):
    """A parallel-travel event with toe = slope·travel (rad), camber = −2·slope·travel."""
    metrics = {"toe": toe_slope * TRAVEL, "camber": -2 * toe_slope * TRAVEL,
               "half_track_change": 0.01 * TRAVEL**2}
    if axle:
        metrics = {f"{side}/{k}": v for side in ("left", "right") for k, v in metrics.items()}
    return kc.KCEvent(name="parallel_travel", x=TRAVEL, x_name="wheel_travel", x_unit="mm",
                      metrics=metrics, compliance={}, solution=None, loads=None, rig=None,
                      label=label, held="wheel height")


def test_kc_curves_models_and_measurements(tmp_path):
    events = [event("model A", 1e-4), event("model B", 2e-4)]
    measured = {"label": "rig", "x": TRAVEL[::2], "toe": 1.1e-4 * TRAVEL[::2]}
    fig = plot.kc_curves(events, ["toe", "camber"], measured=measured, title="K&C")
    assert isinstance(fig, Figure)
    top, bottom = fig.axes
    assert top.get_ylabel() == "toe angle (toe-in +) (deg)"
    assert bottom.get_ylabel() == "camber angle (top outboard +) (deg)"
    assert bottom.get_xlabel() == "wheel travel (mm)"
    # Two model lines and the measured markers on the toe panel, in degrees.
    lines = top.get_lines()
    assert [ln.get_label() for ln in lines] == ["model A", "model B", "rig"]
    np.testing.assert_allclose(lines[1].get_ydata(), np.degrees(2e-4 * TRAVEL))
    np.testing.assert_allclose(lines[2].get_xdata(), TRAVEL[::2])
    assert lines[2].get_linestyle() == "None"
    assert len(bottom.get_lines()) == 2  # no measured camber
    assert [t.get_text() for t in top.get_legend().get_texts()] == ["model A", "model B", "rig"]
    paths = plot.save(fig, tmp_path / "figs" / "travel")
    assert [p.suffix for p in paths] == [".png", ".svg"]
    for p in paths:
        assert p.exists() and p.stat().st_size > 10_000, p
    assert paths[0].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert b"<svg" in paths[1].read_bytes()[:2000]


def test_save_lays_out_once_and_writes_what_savefig_writes(tmp_path):
    """`save` computes the constrained layout once for both formats: the PNG is the one
    `savefig` writes with the layout computed for it, and the figure keeps its layout engine."""
    figs = [plot.kc_curves(event("model A", 1e-4), title="K&C") for _ in range(2)]
    engine = figs[0].get_layout_engine()
    png, _ = plot.save(figs[0], tmp_path / "saved")
    assert figs[0].get_layout_engine() is engine
    figs[1].savefig(tmp_path / "plain.png", dpi=120)
    assert png.read_bytes() == (tmp_path / "plain.png").read_bytes()


def test_kc_curves_axle_corners_and_given_axes():
    fig = Figure()
    ax = fig.subplots()
    out = plot.kc_curves(event("axle", 1e-4, axle=True), "toe", ax=ax)
    assert out is fig
    assert [ln.get_label() for ln in ax.get_lines()] == ["axle (left)", "axle (right)"]
    with pytest.raises(KeyError, match="no metric 'bump_steer'"):
        plot.kc_curves(event("a", 1e-4), "bump_steer")
    with pytest.raises(ValueError, match="one per metric"):
        plot.kc_curves(event("a", 1e-4), ["toe", "camber"], ax=ax)


def test_derivative_units_are_shown_in_display_units():
    ev = event("a", 1e-4)
    ev.metrics["bump_steer"] = np.full(TRAVEL.size, 5e-5)  # rad/mm
    fig = plot.kc_curves(ev, "bump_steer")
    ax = fig.axes[0]
    assert ax.get_ylabel() == "bump steer (toe per travel) (deg/m)"
    np.testing.assert_allclose(ax.get_lines()[0].get_ydata(), np.degrees(5e-5) * 1e3)


def test_sensitivity_bars(tmp_path):
    values = [0.2, -1.5, 0.7, 0.0]
    names = ["k_A_x", "k_B_y", "spring", "k_F_z"]
    fig = plot.sensitivity_bars(values, names, title="toe at 4500 N")
    ax = fig.axes[0]
    # Largest magnitude on top (highest y), negative bars in a second colour.
    labels = [t.get_text() for t in ax.get_yticklabels()]
    assert labels == ["k_B_y", "spring", "k_A_x", "k_F_z"]
    widths = [bar.get_width() for bar in ax.patches]
    np.testing.assert_allclose(widths, [-1.5, 0.7, 0.2, 0.0])
    assert ax.patches[0].get_facecolor() != ax.patches[1].get_facecolor()
    assert ax.get_xlabel() == "normalised sensitivity" and ax.get_title() == "toe at 4500 N"
    top2 = plot.sensitivity_bars(values, names, top=2)
    assert len(top2.axes[0].patches) == 2
    paths = plot.save(fig, tmp_path / "bars")
    assert all(p.stat().st_size > 5_000 for p in paths)
    with pytest.raises(ValueError, match="4 values for 3 names"):
        plot.sensitivity_bars(values, names[:3])


def test_kc_curves_legend_beside_the_axes_with_an_axles_long_label():
    """An axle's default label (its two corners' model names, ~90 characters) wraps and its
    legend stands beside the panel, not on the curves."""
    label = "axle(left/=Chrono double wishbone with bushings; right/=Chrono double wishbone)"
    fig = plot.kc_curves(event(label, 1e-4, axle=True), ["toe", "camber"])
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    for ax in fig.axes:
        legend = ax.get_legend()
        texts = [t.get_text() for t in legend.get_texts()]
        assert all(max(len(line) for line in t.splitlines()) <= plot.LEGEND_WIDTH for t in texts)
        assert texts[0].replace("\n", " ") == f"{label} (left)"
        box, panel = legend.get_window_extent(renderer), ax.get_window_extent(renderer)
        assert box.x0 >= panel.x1  # beside the panel
