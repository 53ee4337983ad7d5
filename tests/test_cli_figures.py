"""The figures the CLI saves are the library reports' `plot()` (a thin CLI): the
on-board tyre report's residual figure shows the fit's residuals, written by `diffsusp.plot.save`
under the CLI's file name."""

import numpy as np

from diffsusp import lsq
from diffsusp.cli.tyre_onboard import _figures
from diffsusp.tyre.onboard import Report


def test_onboard_report_plot_and_cli_figure(tmp_path):
    rng = np.random.default_rng(0)
    W = rng.normal(size=(30, 2))
    y = W @ np.array([1.0, -2.0]) + 0.1 * rng.normal(size=30)
    fit = lsq.solve(W, y, names=["a", "b"])
    report = Report("front", False, 0.0, fit, 30, 0)
    (line,) = report.plot().axes[0].lines
    x = np.linalg.lstsq(W, y, rcond=None)[0]
    np.testing.assert_allclose(line.get_ydata(), y - W @ x, rtol=1e-9, atol=1e-12)
    _figures({"reports": [report]}, tmp_path / "figs")
    assert (tmp_path / "figs" / "onboard_front_nocamber.png").stat().st_size > 1000
