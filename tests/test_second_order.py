"""Second-order sensitivities of K&C metrics (kc.hessian_vector_product): Hessian-vector products
through the equilibrium against central differences of the exact gradients, on two models.
spec: stiffness §2.7, §3."""

from types import SimpleNamespace

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

from diffsusp import kc
from diffsusp.errors import InputError
from diffsusp.identify import least_squares, predict, sensitivity
from diffsusp.identify.data import Landmarks
from diffsusp.identify.params import Params
from diffsusp.models import double_wishbone, isolated_bushing, pseudo_mcpherson

METRICS = ("bump_steer", "wheel_rate", "lateral_compliance_steer")


def _where(m):
    return m.bushings.k_trans, m.springs.k, m.markers.position


def _richardson(f, h):
    """Central difference of f along its argument, Richardson-extrapolated from steps h and
    h/2 (error O(h⁴))."""
    def central(s):
        return (f(s) - f(-s)) / (2 * s)
    return (4 * central(h / 2) - central(h)) / 3


def _case(mech, hardpoint, via_identify):
    """A ±30 mm parallel travel (3 points: the rig and its loads, without running the event),
    θ = every bushing translational stiffness, the spring rate and every marker position, and
    v: +1 relative on the first bushing's Ktx, −0.5 relative on the spring, +1 mm on
    `hardpoint`'s z. Through `kc.hessian_vector_product` with a `where` selector, or through
    `identify.sensitivity(..., direction=v)` with a `Params` selection of the same leaves. One
    compiled program per model serves the products and the differences (new θ, new v)."""
    rig = kc.travel_rig(mech)
    loads = kc.events.event_loads(rig, 3, travel=np.linspace(-30.0, 30.0, 3))
    k_h = rig.mech.markers.index(hardpoint)
    if via_identify:
        sel = Params.leaves(rig.mech, _where)
        names = (f"{rig.mech.bushings.names[0]}.Ktx", "spring.k", f"{hardpoint}.z")

        def run(r, v):
            rep = sensitivity(r, sel, loads=loads, metrics=METRICS, direction=v)
            return SimpleNamespace(params=rep.params, values=rep.values,
                                   gradient=rep.jacobian, hvp=rep.hvp)
    else:
        sel = kc.select(rig.mech, _where)
        names = (".bushings.k_trans[0,0]", ".springs.k[0]", f".markers.position[{k_h},2]")

        def run(r, v):
            return kc.hessian_vector_product(r, sel, v, loads=loads, metrics=METRICS)
    theta = np.asarray(sel.values(rig.mech))
    picks = [sel.names.index(n) for n in names]
    v = np.zeros(theta.size)
    v[picks] = [theta[picks[0]], -0.5 * theta[picks[1]], 1.0]
    out = run(rig, v)
    cache = {}

    def grads(s):  # the exact gradients (and values) at θ + s·v: the same compiled program
        if s not in cache:
            cache[s] = run(eqx.tree_at(lambda r_: r_.mech, rig,
                                       sel.apply(rig.mech, jnp.asarray(theta + s * v))), v)
        return cache[s]

    h = 2e-3
    fd_hvp = {m: _richardson(lambda s, m=m: grads(s).gradient[m], h) for m in METRICS}
    fd_dir = {m: _richardson(lambda s, m=m: grads(s).values[m], h) for m in METRICS}
    n = len(mech.bushings.names)
    groups = [np.arange(3 * n), np.arange(3 * n, 3 * n + 1), np.arange(3 * n + 1, theta.size)]
    return SimpleNamespace(out=out, fd_hvp=fd_hvp, fd_dir=fd_dir, v=v, picks=picks,
                           groups=groups, rig=rig, loads=loads, sel=sel)


@pytest.fixture(scope="module")
def double_wishbone_case():
    return _case(double_wishbone(bushings=True), "tierod_upright", via_identify=False)


@pytest.fixture(scope="module", params=["pseudo_mcpherson", "double_wishbone"])
def case(request):
    if request.param == "pseudo_mcpherson":
        return _case(pseudo_mcpherson(), "tie_rod.j", via_identify=True)
    return request.getfixturevalue("double_wishbone_case")


def test_hessian_vector_products_match_differences_of_the_exact_gradients(case):
    """∇²m·v of bump steer, wheel rate and lateral compliance steer, at every case and for
    every parameter, equals the central difference of the exact gradients ∇m(θ ± h·v) to
    1e-6 relative (per metric and case, relative to the largest entry of that parameter
    group: bushing stiffnesses, spring rate, positions)."""
    n_k = len(case.out.params)
    for m in METRICS:
        hvp, fd = case.out.hvp[m], case.fd_hvp[m]
        assert np.all(np.isfinite(hvp)) and hvp.shape == (3, n_k)
        for g in case.groups:
            scale = np.max(np.abs(fd[:, g]), axis=1, keepdims=True)
            assert np.all(scale > 0), m
            err = np.abs(hvp[:, g] - fd[:, g]) / scale
            assert np.max(err) < 1e-6, (m, float(np.max(err)))
        # the use case: how the sensitivity to the hardpoint changes along v, not zero
        assert np.all(np.abs(hvp[:, case.picks[2]]) > 0)


def test_gradients_match_differences_of_the_metrics(case):
    """The gradient itself along v against central differences of the metric values (the
    second order rests on an exact first order)."""
    for m in METRICS:
        along = case.out.gradient[m] @ case.v
        np.testing.assert_allclose(along, case.fd_dir[m], rtol=1e-6,
                                   atol=1e-9 * np.max(np.abs(case.fd_dir[m])))


def test_hessian_is_symmetric_across_directions(double_wishbone_case):
    """Unit directions e_i, e_j: (∇²m·e_i)_j = (∇²m·e_j)_i — a bushing stiffness and a
    hardpoint of the double wishbone, from the program of the fixture (new v: no new
    compile)."""
    rig, loads, sel = (double_wishbone_case.rig, double_wishbone_case.loads,
                       double_wishbone_case.sel)
    i = ".bushings.k_trans[0,0]"
    j = f".markers.position[{rig.mech.markers.index('tierod_upright')},2]"
    a = kc.hessian_vector_product(rig, sel, i, loads=loads, metrics=METRICS)
    b = kc.hessian_vector_product(rig, sel, j, loads=loads, metrics=METRICS)
    ii, jj = sel.names.index(i), sel.names.index(j)
    for m in METRICS:
        np.testing.assert_allclose(a.hvp[m][:, jj], b.hvp[m][:, ii], rtol=1e-8)
    with pytest.raises(InputError, match="unknown parameter"):
        kc.hessian_vector_product(rig, sel, "nope", loads=loads, metrics=METRICS)
    with pytest.raises(InputError, match="unknown metric"):
        kc.hessian_vector_product(rig, sel, i, loads=loads, metrics=("bump_steering",))
    with pytest.raises(InputError, match="shape"):
        kc.hessian_vector_product(rig, sel, np.ones(3), loads=loads, metrics=METRICS)
    with pytest.raises(InputError, match="float leaf|array leaves"):
        kc.select(rig.mech, lambda m: "spring")


# ----------------------------------------------------------------------------- covariance


def test_least_squares_curvature_check_flags_model_mismatch_not_noise():
    """Gauss–Newton (JᵀJ)⁻¹ against the full Hessian JᵀJ + Σ rᵢ∇²rᵢ (the HVPs through the
    equilibrium) at the estimate. Isolated bushing, 6 light load cases, 3 landmarks, its six
    stiffnesses and its centre. Noise only (0.05 mm): the curvature term leaves σ alone. A
    2 mm probe bias on x (40σ, the model cannot explain it): it changes σ by far more than
    the 10 % threshold, and the report says so."""
    mech = isolated_bushing()
    rng = np.random.default_rng(5)
    loads = mech.loads(forces={"tip": 0.1 * rng.uniform(-300, 300, size=(6, 3))},
                       moments={"tip": 0.1 * rng.uniform(-2e4, 2e4, size=(6, 3))})
    points = np.array([[-300.0, 0, 0], [-150, 40, 0], [-100, 0, 50]])

    def landmarks(values):
        return Landmarks(loads, ("arm",) * 3, points, values, 0.05)

    params = Params.bushing_stiffness(mech) + Params.bushing_centres(mech, ("bush",))
    truth = np.asarray(params.start) * np.r_[np.linspace(0.8, 1.2, 6), np.ones(3)]
    truth[6:] += [1.0, -0.5, 0.3]
    pred = np.asarray(predict(params.apply(mech, jnp.asarray(truth)),
                              landmarks(np.zeros((6, 3, 3))))["landmarks"])
    noise = rng.normal(0, 0.05, pred.shape)
    _, clean = least_squares(mech, landmarks(pred + noise), params, curvature=True)
    assert clean.consistency.consistent
    check = clean.curvature
    assert check.positive_definite and not check.matters
    assert np.max(np.abs(check.ratio - 1)) < 0.05
    assert "does not change" in clean.table()
    bias = np.zeros_like(pred)
    bias[..., 0] = 2.0 * np.sign(pred[..., 0] - pred[..., 0].mean())
    _, wrong = least_squares(mech, landmarks(pred + bias + noise), params, curvature=True)
    assert not wrong.consistency.consistent
    assert wrong.curvature.matters
    assert np.max(np.abs(wrong.curvature.ratio - 1)) > 0.3
    assert np.max(wrong.curvature.curvature_share) > 0.5
    assert "changes σ by more than 10 %" in wrong.table()
    # the GN σ of the check is the report's own
    np.testing.assert_allclose(check.sigma_gauss_newton, clean.sigma, rtol=1e-6)
