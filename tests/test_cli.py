"""The `diffsusp` command (Typer's test runner)."""

from typer.testing import CliRunner

from diffsusp.cli import app


def test_demo_prints_the_thesis_table():
    result = CliRunner().invoke(app, ["demo"])
    assert result.exit_code == 0, result.output
    out = result.output
    assert "Table 5-1" in out
    # 13 rows, all converged, and the timing line.
    assert out.count(" ok") >= 13
    assert "equilibria/s" in out
    # The 4500 N case is the design position: no vertical displacement (to print precision).
    row3 = next(line.split() for line in out.splitlines() if line.split()[:2] == ["3", "4500"])
    assert abs(float(row3[6])) < 0.005  # Δz in mm
    assert row3[-1] == "ok"


def test_no_arguments_shows_help():
    result = CliRunner().invoke(app, [])
    assert "demo" in result.output
