"""The batched bench identification (`diffsusp.tyre.bench_batch.identify_many`; spec:
tyre §3.3–3.5): one compiled program for many data sets runs the library's structure search
(σ % under the noise-model sandwich σ, F-test) and two-step estimate; the reference is the
library's NumPy search set by set (`bench.identify_output`)."""

import pathlib

import numpy as np
import pytest
from test_tyre_bench import SEGMENTS_25  # tests/ is on sys.path (pytest)

from diffsusp.tyre import annex_g, bench, bench_batch, poly

DATA = pathlib.Path(__file__).parent / "data"
FY = poly.JUST_NECESSARY["Fy"]
MZ = poly.JUST_NECESSARY["Mz"]


def _table10():
    """The shipped noise-free Dunlop R16 2.5 bar campaign (tests/test_tyre_bench.py
    `_generate_campaign_25`: slip sines at three loads and cambers, load sines, medium slip
    ramps, 2 speeds, 54 segments of 1 s at 200 Hz), time and segment columns rebuilt."""
    z = np.load(DATA / "tyre_flat_trac_table10.npz")
    table = {c: np.asarray(z[c], dtype=float) for c in z.files}
    n_seg = len(table["FY"]) // 200
    table["t"] = np.tile(np.arange(200) / 200.0, n_seg)
    table["segment"] = np.repeat(np.arange(n_seg, dtype=float), 200)
    return table


def _noisy(table, seed, fy_noise=6.0):
    """A tyre of the campaign: the bench's white noise on F_y, M_z (σ 6 N, 0.6 N·m)."""
    rng = np.random.default_rng(seed)
    out = dict(table)
    out["FY"] = table["FY"] + fy_noise * rng.standard_normal(len(table["FY"]))
    out["MZ"] = table["MZ"] + 600.0 * rng.standard_normal(len(table["FY"]))
    return out


@pytest.fixture(scope="module")
def campaign():
    """Three data sets of one shape (three noise draws; one with 3× the F_y noise), their
    library F_y identification set by set, and the batched identification of the three in
    one program (`lax.map`)."""
    base = _table10()
    tables = [_noisy(base, 0), _noisy(base, 1), _noisy(base, 2, fy_noise=18.0)]
    conds = [bench.condition(t) for t in tables]
    fy = [bench.identify_output(c, "Fy", FY) for c in conds]
    batched = bench_batch.identify_many(tables, degrees=FY, optimize=False)
    return tables, conds, fy, batched


def _agree(batch, lib, rtol):
    """The batched report is the library's: the same kept, removed and not identifiable
    coefficients, the same excused faults, x, σ, K_y and its σ within `rtol`."""
    assert sorted(batch.reduced.names) == sorted(lib.reduced.names)
    assert set(batch.removed) == set(lib.removed)
    assert set(batch.not_identifiable) == set(lib.not_identifiable)
    assert batch.excused == lib.excused
    order = [batch.reduced.names.index(n) for n in lib.reduced.names]
    np.testing.assert_allclose(batch.reduced.x[order], lib.reduced.x, rtol=rtol)
    np.testing.assert_allclose(batch.reduced.sigma[order], lib.reduced.sigma, rtol=rtol)
    for f in ("compliance", "compliance_sigma", "compliance_sigma_step2", "noise_sigma"):
        assert getattr(batch, f) == pytest.approx(getattr(lib, f), rel=rtol), f


def test_batched_search_is_the_library_search(campaign):
    """Three sets in one program (`lax.map`): the structure, coefficients, σ and K_y of the
    library's NumPy search set by set. Measured: x within 1e-9, σ and K_y within 1e-11
    relative (rounding: e.g. the instrumental-variable normal matrix is inverted by LU in the
    program, through a QR in NumPy)."""
    _, _, fy, res = campaign
    assert res.exact == {}  # no behaviour rule removes anything: every fault is excused
    for b, lib in zip(res.reports, fy, strict=True):
        _agree(b, lib, 1e-8)
        assert b.fit is None and lib.fit is not None  # traced: no lsq.Fit per set
    np.testing.assert_array_equal(res.kept.sum(axis=1), [len(r.reduced.names) for r in fy])
    np.testing.assert_allclose(res.stiffness, [r.stiffness for r in fy], rtol=1e-10)
    # the search is per set: the noisier third set keeps another structure
    assert sorted(fy[2].reduced.names) != sorted(fy[0].reduced.names)


def test_loop_over_sets_equals_the_map(campaign):
    """The one-set program called per set (the loop over sets), from the conditioned data
    (the other entry point), gives the mapped program's result (`lax.map`: the same
    operations, one set at a time inside one program): the same removals in the same order,
    the numbers to rounding (measured 8e-10 relative on x: another compiled program, and
    the conditioning in NumPy instead of the program)."""
    conds, ref = campaign[1][:2], campaign[3]
    res = bench_batch.identify_many(conds, degrees=FY, batch="loop", optimize=False)
    for b, r in zip(res.reports, ref.reports, strict=False):
        assert b.removed == r.removed  # the same removals in the same order
        _agree(b, r, 1e-8)
    # M_z (`mz=True`): the library's M_z identification per set, instrumented by the batched
    # F_y; K_{Mz,y} of the Dunlop R16 at 2.5 bar (G.2) within its σ
    res = bench_batch.identify_many(conds[:1], degrees=FY, batch="loop", optimize=False,
                                    mz=True)
    rep = res.mz_reports[0]
    assert rep.output == "Mz" and rep.fit is not None
    k_mz = annex_g.lateral_stiffness("dunlop_r16", 2.5, "Mz")
    assert abs(rep.compliance - 1 / k_mz) < 3 * rep.compliance_sigma


def test_behaviour_fault_goes_through_the_exact_search(campaign):
    """Without the σ % rule (`sigma_pct_threshold=None`) only the behaviour rules remove
    coefficients (with σ % ≤ 10 % every kept coefficient passes the F-test: F ≥ 100 > 10.8,
    so the rules can only excuse a fault): a set on which a rule removes a coefficient (here
    the load-sign rule) goes through the library's exact search, whose report it returns."""
    cond = campaign[1][0]
    res = bench_batch.identify_many([cond], degrees=FY, batch="loop", optimize=False,
                                    sigma_pct_threshold=None)
    assert list(res.exact) == [0]
    assert res.exact[0].startswith("behaviour rule 'sign'")
    rep = res.reports[0]
    assert rep.fit is not None  # the library's report (its lsq.Fit)
    assert any(r.startswith("behaviour: sign rule") for r in rep.removed.values())
    np.testing.assert_array_equal(res.kept[0], [n in rep.reduced.names for n in res.names])


PROGRAMME = SEGMENTS_25
"""The programme of the shipped campaign (`_table10`): the batched program compiles once."""


def test_rehearsal_of_a_bench_campaign(campaign):
    """`bench_batch.BenchScenario` (the rehearsal contract): random tyres around the Dunlop
    R16 at 2.5 bar (coefficients ±20 %, K_y × 0.5–2), the shipped campaign's programme,
    σ_FY = 2 N + 1 %·|F_y|, identified batched. With the search's reduced σ 38 of 170
    "identified" coefficients were outside 3 σ over 20 tyres (a kept coefficient stands in
    for aliased terms the search removed); with the σ of every candidate term and the
    search's shift, none (200 tyres: benchmarks/rehearse_bench.py). Bad input: clear errors."""
    from diffsusp.errors import InputError

    p = 2.5
    sc = bench_batch.BenchScenario(
        fy=poly.PolynomialModel.from_annex_g("dunlop_r16", p, "Fy"),
        mz=poly.PolynomialModel.from_annex_g("dunlop_r16", p, "Mz"),
        k_fy=annex_g.lateral_stiffness("dunlop_r16", p, "Fy"),
        k_mz=annex_g.lateral_stiffness("dunlop_r16", p, "Mz"), segments=PROGRAMME,
        noise={"FY": (2.0, 0.01), "MZ": (600.0, 0.0), "FX": 3.0, "FZ": 3.0})
    rng = np.random.default_rng(27)
    truths = sc.draw(rng, 3)  # three: the shape of `campaign`'s batch, one compiled program
    assert truths.shape == (3, len(sc.names)) and sc.names[-1] == "K_Fy_y"
    reports = sc.identify(truths, rng)
    claims = false = 0
    for t, rep in zip(truths, reports, strict=True):
        assert rep.names == sc.names
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.abs(rep.estimates - t) / rep.sigmas
        ident = rep.is_identified
        claims += int(ident.sum())
        false += int(np.sum(ident & ~(z <= 3)))
        if rep.consistency.consistent:  # the searched model's K_y is determined
            assert ident[-1] and z[-1] <= 3
    assert claims >= 15 and false == 0, (claims, false)
    with pytest.raises(InputError, match="spread"):
        bench_batch.BenchScenario(sc.fy, sc.mz, sc.k_fy, sc.k_mz, PROGRAMME, spread=0.0)
    with pytest.raises(InputError, match="at least one truth"):
        sc.draw(rng, 0)
