"""One front door for identification (issue 11; DESIGN.md "Identification"): `direct`,
`iterative` and `least_squares` take the same measurement object and the same selection, and
return reports with the same base API.

The data set is the thesis's pseudo-McPherson under the 13 cases of Table 5-1, measured by
four landmarks per part (noise-free, `measure.synthesize`), the stiffnesses of bushings A and B
to identify (spec stiffness §7 R5). The programs are those of test_direct, test_iterative and
test_fit on the same model and load table (the solve, the iterative regression, the
least-squares equilibria); new are only the direct system of this selection and the residuals
of these landmarks.
"""

import json
import math

import matplotlib.figure
import numpy as np
import pytest

from diffsusp import identify, measure
from diffsusp.errors import InputError
from diffsusp.identify import Params
from diffsusp.identify.report import IdentificationReport
from diffsusp.models import pseudo_mcpherson, thesis_load_cases

A_B = ("bushing_A", "bushing_B")
DEG = math.pi / 180


@pytest.fixture(scope="module")
def case():
    ref = pseudo_mcpherson()
    data = measure.synthesize(ref, thesis_load_cases(ref), seed=0)
    params = Params.bushing_stiffness(ref, A_B)
    truth = np.asarray(params.values(ref))
    start = params.apply(ref, 1.5 * params.start)  # every A, B stiffness 50 % off
    reports = {
        "direct": identify.direct(start, data, params)[1],
        "iterative": identify.iterative(start, data, params)[1],
        "least_squares": identify.least_squares(start, data, params.with_start(1.5 * truth))[1],
    }
    return ref, data, params, truth, reports


def test_three_methods_one_measurement_one_selection_one_report_api(case):
    ref, data, params, truth, reports = case
    truth = dict(zip(params.names, truth, strict=True))
    units = dict(zip(params.names, params.units(ref), strict=True))
    for method, report in reports.items():
        assert isinstance(report, IdentificationReport) and report.family == method
        # The same parameters, named alike, in the model's units.
        assert set(report.names) == set(params.names), method
        got = dict(zip(report.names, report.estimates, strict=True))
        assert dict(zip(report.names, report.estimate_units, strict=True)) == units
        ok = dict(zip(report.names, report.identifiable, strict=True))
        # The influential stiffnesses (Ktx along the arms, spec §2.7) by every method:
        # exactly by the two that solve the equations, to the loop's 1 % stop by the
        # iterative one (spec §2.5).
        tol = 0.02 if method == "iterative" else 1e-6
        for name in ("bushing_A.Ktx", "bushing_B.Ktx"):
            assert ok[name], (method, name)
            assert got[name] == pytest.approx(truth[name], rel=tol), (method, name)
        if method != "iterative":
            for name in params.names:
                if ok[name]:
                    assert got[name] == pytest.approx(truth[name], rel=1e-6), (method, name)
        # σ and σ % agree with each other; rows, JSON and residuals share one layout.
        sig, pct = np.asarray(report.sigmas), np.asarray(report.sigma_pct)
        both = np.isfinite(sig) & np.isfinite(pct)
        assert both.any(), method
        np.testing.assert_allclose(pct[both], 100 * sig[both] / np.abs(report.estimates[both]),
                                   rtol=1e-12)
        rows = report.rows()
        assert [r["parameter"] for r in rows] == list(report.names)
        summary = json.loads(report.to_json())
        assert summary["method"] == method and summary["parameters"] == rows
        assert set(summary) == {"method", "parameters", "combinations", "residual_rms",
                                "consistency"}
        # Issue 12: every report says whether the identified model reproduces the data
        # (noise-free here: the exact methods do; the iterative loop stops at a 1 % change).
        check = summary["consistency"]
        assert check["dof"] > 0 and set(check["case_rms"]) == set(data.cases), method
        if method != "iterative":
            assert check["consistent"] and report.is_identified.any(), method
        assert [r["identified"] for r in rows] == report.is_identified.tolist()
        assert report.residuals and all(
            r.raw.shape == r.whitened.shape for r in report.residuals.values())
        # Noise-free data: the model reproduces the measurements (the iterative method: in
        # the directions it identified, up to its offsets E0 (eq. 5.17), within the arm's
        # σ = 0.05 mm: its loop stops at a 1 % change, spec §2.5).
        if method == "iterative":
            res = report.residuals["deformations"].raw[:, report.identified]
            assert np.abs(res).max() < measure.ARM_SIGMA, np.abs(res).max()
        else:
            assert max(summary["residual_rms"].values()) < 1e-6, (method, summary)
    # What the landmarks do not determine is named in the combinations the data cannot see.
    fit = reports["least_squares"]
    assert fit.unidentifiable and all(n in " ".join(fit.combinations) for n in fit.unidentifiable)
    assert isinstance(reports["least_squares"].plot(), matplotlib.figure.Figure)


def test_the_measurement_conversions_name_what_is_missing(case):
    ref, data, params, _, _ = case
    # Deformations from the measured poses are the bushings' own (spec stiffness §2.2).
    defo = measure.as_deformations(ref, data, A_B)
    d_t, d_r = measure.bushing_deformations(ref, data, A_B)
    np.testing.assert_array_equal(np.asarray(defo.measured)[..., :3], d_t)
    np.testing.assert_array_equal(np.asarray(defo.measured)[..., 3:], d_r)
    # A Deformations measurement carries no poses: the direct method says what it needs.
    with pytest.raises(InputError, match="the direct method needs measured part poses"):
        identify.direct(ref, defo)
    with pytest.raises(InputError, match="the iterative method identifies bushing stiffnesses"):
        identify.iterative(ref, data, lambda m: m.springs.k)
    with pytest.raises(InputError, match="params= or where=, not both"):
        identify.direct(ref, data, params, where=lambda m: m.bushings.k_trans)
    # A Params entry the direct method cannot identify is named as such.
    with pytest.raises(InputError, match="where= selected something"):
        identify.direct(ref, data, Params.bushing_centres(ref, ["bushing_A"]))
    # Units are metadata of the mechanism's fields.
    assert Params.bushing_centres(ref, ["bushing_A"]).units(ref) == ("mm",) * 3
    assert params.units(ref) == ("N/mm",) * 3 + ("N·mm/rad",) * 3 + ("N/mm",) * 3 + (
        "N·mm/rad",) * 3
