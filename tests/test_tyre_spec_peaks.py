"""The specification's friction quantities (docs/reference/tyre.md): the braking F_x peak and the
friction coefficients μ_x, μ_y, checked against a dense grid of the model itself; and the
`tyre spec` table, one row per quantity and one column per load, within 100 columns whatever
the file (no column cut)."""

import pathlib

import jax.numpy as jnp
import numpy as np
from typer.testing import CliRunner

from diffsusp.cli import app
from diffsusp.io.tir import read_tir
from diffsusp.tyre import mf6, specification

DATA = pathlib.Path(__file__).parents[1] / "diffsusp" / "tyre" / "data"
FEDA = DATA / "335_65R22_5_G275MSA_70psi.tir"


def test_friction_peaks_and_the_table(tmp_path):
    model = mf6.MagicFormula6.from_tir(read_tir(FEDA))
    fz = np.array([0.5, 1.0]) * float(model["FNOMIN"])
    spec = {k: np.asarray(v) for k, v in specification(model, jnp.asarray(fz)).items()}
    kappa = np.linspace(-0.5, 0.0, 20001)
    for i, load in enumerate(fz):
        fx = np.asarray(mf6.evaluate(model, load, kappa, 0.0, 0.0, combined=False).fx)
        j = int(np.argmin(fx))
        assert 0 < j < kappa.size - 1  # a braking peak inside the range
        np.testing.assert_allclose(spec["fx_peak"][i], fx[j], rtol=1e-7)
        assert abs(spec["kappa_at_fx_peak"][i] - kappa[j]) < 1e-3
        np.testing.assert_allclose(spec["mu_x"][i], abs(fx[j]) / load, rtol=1e-7)
        assert 0.5 < spec["mu_x"][i] < 1.5
    # μ_y where F_y has a peak inside (0, 0.35]: the MF 6.1 example file
    m61 = mf6.MagicFormula6.from_tir(read_tir(DATA / "MagicFormula61_Paramerters.tir"))
    s61 = specification(m61, jnp.asarray([float(m61["FNOMIN"])]))
    alpha = np.linspace(0.0, 0.35, 20001)
    fy = np.asarray(mf6.evaluate(m61, float(m61["FNOMIN"]), 0.0, alpha, 0.0,
                                 combined=False).fy)
    peak = fy[np.argmax(np.sign(fy[1] - fy[0]) * fy)]
    np.testing.assert_allclose(float(s61["mu_y"][0]), abs(peak) / float(m61["FNOMIN"]),
                               rtol=1e-7)

    result = CliRunner().invoke(app, ["tyre", "spec", str(FEDA), "--loads",
                                      "6000,9000,12000,15000,18000"], env={"COLUMNS": "100"})
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert max(len(line.rstrip()) for line in lines) <= 100, result.output
    row = next(line for line in lines if line.strip().startswith("mu_x"))
    assert len(row.split()) == 2 + 5 and "…" not in result.output  # a number per load, uncut


def test_eval_grid_stays_in_the_files_ranges(tmp_path):
    """`tyre eval --grid` on the FEDA file (ALPMAX 11.2°, FZMAX 1.41 FNOMIN) evaluates inside
    its ranges: no saturated point, no range warning (the grid was ±15°, to 1.5 FNOMIN)."""
    from diffsusp.io.tables import read_table

    model = mf6.MagicFormula6.from_tir(read_tir(FEDA))
    out = tmp_path / "grid.csv"
    result = CliRunner().invoke(app, ["tyre", "eval", str(FEDA), "--grid", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "beyond" not in result.output, result.output
    table = read_table(out)
    sa, fz = np.asarray(table["SA"]), np.asarray(table["FZ"])
    lim = model.limit
    assert lim["ALPMIN"] <= sa.min() < 0 < sa.max() <= lim["ALPMAX"]
    assert lim["FZMIN"] <= fz.min() < fz.max() <= lim["FZMAX"] and sa.size == 93
