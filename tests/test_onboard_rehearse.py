"""The rehearsal of the on-board tyre identification (`diffsusp.tyre.onboard_rehearse`; issue 27,
spec tyre §5.3–5.5): a small rehearsal of the user's experiment — 3 random tyres ±20 % around
the synthetic car's, each driving a short steering-wheel sine with a 100 ms late Correvit and the
sensors' noise, identified by the default pipeline. The 200-truth runs are
benchmarks/rehearse_onboard.py (numbers in benchmarks/README.md)."""

import dataclasses

import numpy as np
import pytest

from diffsusp.errors import InputError
from diffsusp.identify.rehearse import rehearse
from diffsusp.tyre import onboard
from diffsusp.tyre.onboard_rehearse import OnboardScenario

N = 3


class Replay:
    """The scenario's truths and reports again, with every σ scaled by `factor` (the reports'
    verdicts recomputed from the scaled σ): a rehearsal of a pipeline whose σ were wrong."""

    def __init__(self, scenario, truths, reports, factor):
        self.method, self.names = scenario.method, scenario.names
        self._truths, self._reports, self._factor = truths, reports, factor

    def draw(self, rng, n):
        return self._truths

    def identify(self, truths, rng):
        return [dataclasses.replace(r, fit=dataclasses.replace(
            r.fit, sigma=np.asarray(r.fit.sigma) * self._factor)) for r in self._reports]


class Keep(OnboardScenario):
    def identify(self, truths, rng):
        self.truths, self.reports = np.asarray(truths), super().identify(truths, rng)
        return self.reports


def test_rehearsal_of_a_late_correvit():
    """3 truths, a 3 s sine, Correvit 100 ms late: one report per truth, the delay found and
    removed (within 5 ms), the camber stiffness b_gamma_1 (the best determined coefficient)
    identified for every truth and within 3 reported σ of it — and not with σ 3× too small
    (the same reports with σ/3: claims outside 3σ). The truths are ±20 % draws around the
    start, none equal to it. Bad scenarios are clear errors."""
    sc = Keep(duration=3.0, delay=0.1, batch=N)
    rep = rehearse(sc, N, seed=4)
    assert rep.n == N and rep.failed == 0
    start = sc.start()
    assert np.all(np.abs(sc.truths - start) <= 0.2 * np.abs(start) + 1e-12)
    assert np.all(sc.truths[:, start != 0] != start[start != 0])
    assert all(abs(r.delay - 0.1) < 0.005 for r in sc.reports)
    rows = {r["parameter"]: r for r in rep.rows()}
    g = rows["b_gamma_1"]
    assert g["identified"] == N and g["coverage_3s"] == 1.0 and g["false_identified"] == 0, g
    k = onboard.NAMES.index("b_gamma_1")
    z = [(r.estimates[k] - t[k]) / r.sigmas[k] for r, t in zip(sc.reports, sc.truths,
                                                                 strict=True)]
    assert np.all(np.abs(z) <= 3.0), z
    bad = rehearse(Replay(sc, sc.truths, sc.reports, 1 / 3), N, seed=4)
    g_bad = {r["parameter"]: r for r in bad.rows()}["b_gamma_1"]
    assert g_bad["false_identified"] >= 1, g_bad
    for kwargs, match in (({"spread": 0.0}, "spread"), ({"delay": -0.1}, "delay"),
                          ({"grouping": "middle"}, "grouping"), ({"batch": 0}, "batch")):
        with pytest.raises(InputError, match=match):
            OnboardScenario(**kwargs)
    with pytest.raises(InputError, match="at least one"):
        rehearse(OnboardScenario(), 0)
