"""`tyre.evaluate` announces its limit saturation once per eager call (module
docstring of `diffsusp.tyre.mf6`, "Modes"), silently traced under jit / vmap / grad, and the CLI
(which runs `check_limits` on the table first) does not announce it twice."""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from typer.testing import CliRunner

from diffsusp.cli import app
from diffsusp.errors import ModelWarning
from diffsusp.io.tir import read_tir
from diffsusp.tyre import MagicFormula6, evaluate, example_path

jax.config.update("jax_enable_x64", True)


@pytest.fixture(scope="module")
def truck():
    """Chrono's FED truck tyre (MF-Tyre 5.0 / PAC2002): KPUMAX = 0, as exported."""
    m = MagicFormula6.from_tir(read_tir(example_path("truck_60psi")))
    assert m.limit["KPUMAX"] == 0.0 and m.limit["ALPMAX"] == pytest.approx(0.19769)
    return m


def test_saturation_warns_once_per_call(truck):
    fz = np.full(6, 20000.0)
    kappa = np.array([0.0, 0.05, 0.1, -0.05, 0.2, 0.0])   # three driving slips, rows 1, 2, 4
    alpha = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.3])      # one beyond ALPMAX, row 5
    with pytest.warns(ModelWarning) as rec:
        f = evaluate(truck, fz, kappa, alpha)
    assert len(rec) == 1, [str(r.message) for r in rec]   # one per call, not per row or limit
    msg = str(rec[0].message)
    assert "3 value(s) of SL beyond KPUMAX = 0 [LONG_SLIP_RANGE] (first at row 1)" in msg, msg
    assert "1 value(s) of SA beyond ALPMAX = 0.19769 [SLIP_ANGLE_RANGE] (first at row 5)" in msg
    assert "KPUMIN" not in msg and "FZMAX" not in msg     # braking and the load are inside
    assert rec[0].filename == __file__                    # points at the caller's line
    fx = np.asarray(f.fx)
    assert fx[3] < -1000.0                                # braking: a real force
    np.testing.assert_array_equal(fx[[1, 2, 4]], fx[0])   # driving slip: F_x(κ = 0), no more
    # a second call warns again (once per call, not once per session)
    with pytest.warns(ModelWarning, match="3 value"):
        evaluate(truck, fz, kappa, 0.0)
    # inside the ranges, with limits=False, with announce=False: nothing
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        g = evaluate(truck, fz, np.minimum(kappa, 0.0), np.minimum(alpha, 0.19))
        evaluate(truck, 5000.0, -0.1, 0.05, 0.01)
        h = evaluate(truck, fz, kappa, alpha, limits=False)
        evaluate(truck, fz, kappa, alpha, announce=False)
    np.testing.assert_array_equal(np.asarray(g.fx), fx)   # the saturation is a clip at KPUMAX
    assert np.asarray(h.fx)[2] > 1000.0                    # unsaturated: a driving force


def test_saturation_silent_and_traceable_when_traced(truck):
    fz = jnp.full(3, 20000.0)
    kappa = jnp.array([0.0, 0.1, 0.2])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        jitted = jax.jit(lambda k: evaluate(truck, fz, k, 0.0, outputs=("fx",)).fx)(kappa)
        mapped = jax.vmap(lambda k: evaluate(truck, 20000.0, k, 0.0, outputs=("fx",)).fx)(kappa)
        d_kappa = jax.grad(lambda k: evaluate(truck, 20000.0, k, 0.0, outputs=("fx",)).fx)(0.1)
        # concrete inputs, traced coefficients (a fit's Jacobian): nothing either
        d_model = jax.grad(lambda m: evaluate(m, 20000.0, 0.1, 0.0, outputs=("fx",)).fx)(truck)
    np.testing.assert_array_equal(np.asarray(jitted), np.asarray(mapped))
    assert np.asarray(jitted)[1] == np.asarray(jitted)[0]
    assert float(d_kappa) == 0.0                           # saturated: flat beyond KPUMAX
    assert any(float(v) != 0.0 for v in d_model.coefficients.values())


def test_cli_eval_warns_once(tmp_path):
    """`tyre eval` names the table once per limit (check_limits), not again from `evaluate`."""
    inp = tmp_path / "drive.csv"
    inp.write_text("FZ [N],SL [-],SA [rad]\n20000,0.1,0\n20000,0.2,0.01\n")
    r = CliRunner().invoke(app, ["tyre", "eval", str(example_path("truck_60psi")),
                                 "--inputs", str(inp)])
    text = " ".join(r.output.split())
    assert r.exit_code == 0, r.output
    assert "drive.csv: 2 value(s) of SL beyond KPUMAX = 0" in text, text
    assert text.count("beyond KPUMAX") == 1 and "evaluate: inputs saturated" not in text, text
