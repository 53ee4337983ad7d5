"""The rehearsal (`diffsusp.identify.rehearse`): its statistics against a scenario whose answer is
known exactly (a linear-Gaussian toy, calibrated and overclaiming), a small rehearsal of the
direct method on random truths (no wrong "identified"), and the CLI's bad inputs (exit 2)."""

import dataclasses
import json

import numpy as np
import pytest
from typer.testing import CliRunner

from diffsusp.cli import app
from diffsusp.errors import InputError
from diffsusp.identify import SuspensionScenario, rehearse
from diffsusp.identify.report import IdentificationReport
from diffsusp.models import isolated_bushing


@dataclasses.dataclass
class _ToyReport(IdentificationReport):
    names: tuple
    estimates: np.ndarray
    sigmas: np.ndarray
    identifiable: np.ndarray
    family = "toy"

    @property
    def sigma_pct(self):
        return 100 * self.sigmas / np.abs(self.estimates)

    @property
    def estimate_units(self):
        return ("-",) * len(self.names)

    combinations = ()
    residuals = {}


class _Toy:
    """Estimate = truth + N(0, σ_true²), reported with σ_reported; parameter 'b' is never
    determined."""

    method = "toy"
    names = ("a", "b")

    def __init__(self, sigma_true, sigma_reported):
        self.sigma_true, self.sigma_reported = sigma_true, sigma_reported

    def draw(self, rng, n):
        return rng.uniform(1.0, 2.0, size=(n, 2))

    def identify(self, truths, rng):
        out = []
        for t in truths:
            est = t + rng.normal(0.0, self.sigma_true, size=2)
            out.append(_ToyReport(self.names, est, np.full(2, self.sigma_reported),
                                  np.array([True, False])))
        return out


def test_statistics_of_a_calibrated_and_an_overclaiming_method():
    good = rehearse(_Toy(0.01, 0.01), n=2000, seed=3)
    a, b = good.parameters
    assert a.identified_rate == 1.0 and b.identified_rate == 0.0 and b.identified == 0
    for got, want in zip(a.coverage, (0.683, 0.954, 0.997), strict=True):
        assert abs(got - want) < 3 * np.sqrt(want * (1 - want) / 2000) + 1e-3
    assert abs(a.bias) < 0.1 and abs(a.spread - 1.0) < 0.05
    assert a.false_identified_rate < 0.01
    # a σ reported 3x too small: a third of the claims are wrong, and the harness says so
    bad = rehearse(_Toy(0.03, 0.01), n=2000, seed=3).parameters[0]
    assert bad.coverage[2] < 0.7 and bad.false_identified_rate > 0.3
    assert abs(bad.spread - 3.0) < 0.15
    text = good.table()
    assert "a: identified in 100 % of truths" in text and "b: the planned experiment never" in text
    assert json.loads(good.to_json())["parameters"][0]["parameter"] == "a"


def test_harness_refuses_bad_scenarios():
    with pytest.raises(InputError, match="at least one random truth"):
        rehearse(_Toy(0.01, 0.01), n=0)
    mech = isolated_bushing()
    loads = mech.loads(forces={"tip": np.ones((3, 3))})
    with pytest.raises(InputError, match="positive σ"):
        SuspensionScenario("direct", mech, loads, noise=0.0)
    with pytest.raises(InputError, match="spread of 0"):
        SuspensionScenario("direct", mech, loads, spread=(1.0, 1.0))
    with pytest.raises(InputError, match="unknown method"):
        SuspensionScenario("guess", mech, loads)


def test_a_small_direct_rehearsal_claims_nothing_wrong(tmp_path):
    """20 random truths (×0.5–2 on the six stiffnesses) of the isolated bushing, three load
    cases, landmarks with σ = 0.05 mm: the rotational stiffnesses identified in most truths
    (the translations, σ ≈ 10–20 % with three cases, in some), and at most 2 of 20 claims per
    parameter outside 3σ (a calibrated σ gives 3 or more with probability 2e-5; a σ half the
    true one, 2.7 on average: an overclaiming method fails here)."""
    mech = isolated_bushing()
    force = np.array([[30.0, -20.0, 50.0], [-12.0, 8.0, 4.0], [6.0, 3.0, -9.0]])
    moment = np.array([[2e4, -1e4, 3e4], [-5e3, 1e4, 2e3], [3e3, 4e3, -6e3]])
    loads = mech.loads(forces={"tip": force}, moments={"tip": moment})
    report = rehearse(SuspensionScenario("direct", mech, loads), n=20, seed=11)
    assert report.failed == 0 and report.consistent_rate >= 0.9
    for p in report.parameters:
        assert p.false_identified <= 2, p
        if p.name.startswith("bush.Kr"):
            assert p.identified >= 15 and p.coverage[2] >= 0.9, p
    report.write(tmp_path / "r.csv")
    report.write(tmp_path / "r.json")
    assert len((tmp_path / "r.csv").read_text().splitlines()) == 1 + len(report.parameters)


@pytest.mark.parametrize("args, message", [
    (["direct", "isolated_bushing", "--n", "0"], "at least 1 random truth"),
    (["direct", "isolated_bushing", "--noise", "0"], "positive landmark σ"),
    (["direct", "isolated_bushing", "--spread", "1,1"], "0 < low < high"),
    (["direct", "isolated_bushing", "--params", "bush.Kqq"], "unknown parameter"),
    (["iterative", "isolated_bushing", "--out", "r.txt"], "rehearsal"),
    (["onboard", "synthetic", "--n", "0"], "at least 1 random truth"),
    (["onboard", "synthetic", "--spread", "0"], "relative spread in (0, 1)"),
    (["onboard", "synthetic", "--noise", "0"], "positive factor"),
    (["onboard", "synthetic", "--params", "b_L_9"], "unknown parameter"),
    (["onboard", "my_car.json"], "MODEL must be one of synthetic"),
    (["onboard", "synthetic", "--delay", "-0.1"], "--delay must be"),
])
def test_cli_bad_input_exits_2(args, message):
    result = CliRunner().invoke(app, ["rehearse", *args])
    assert result.exit_code == 2, result.output
    assert message in " ".join(result.output.split())


def test_cli_onboard_rehearsal(tmp_path):
    """`diffsusp rehearse onboard synthetic`: 2 random tyres of the synthetic car (only the
    relaxation's b_L_1 and the cornering b_delta_1 drawn), a 2 s sine, the Correvit 50 ms
    late: the same table, `--json` and `--out` as the other methods, one row per coefficient of
    the reduced model, every truth identified (none failed)."""
    out = tmp_path / "onboard.csv"
    result = CliRunner().invoke(app, [
        "rehearse", "onboard", "synthetic", "--n", "2", "--duration", "2", "--delay", "0.05",
        "--params", "b_L_1,b_delta_1", "--seed", "3", "--json", "--out", str(out)])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.output)
    from diffsusp.tyre.onboard import NAMES

    assert doc["method"] == "onboard" and doc["truths"] == 2 and doc["failed"] == 0, doc
    assert [p["parameter"] for p in doc["parameters"]] == list(NAMES)
    # the cornering stiffness's linear term is identified in both truths, within 3σ
    row = {p["parameter"]: p for p in doc["parameters"]}["b_delta_1"]
    assert row["identified"] == 2 and row["false_identified"] == 0, row
    assert len(out.read_text().splitlines()) == 1 + len(NAMES)
