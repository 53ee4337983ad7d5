"""The `diffsusp` command (Typer's test runner)."""

from typer.testing import CliRunner

from diffsusp.cli import app


def test_demo_prints_the_thesis_table_and_writes_the_figures(tmp_path):
    result = CliRunner().invoke(app, ["demo", "--out", str(tmp_path)])
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
    assert "bump_steer" in out and "wheel_rate" in out
    for stem in ("parallel_travel", "table_5_1"):
        for ext in ("png", "svg"):
            assert (tmp_path / f"{stem}.{ext}").stat().st_size > 10_000


def test_no_arguments_shows_help():
    result = CliRunner().invoke(app, [])
    assert "demo" in result.output
