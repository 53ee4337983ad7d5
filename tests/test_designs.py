"""The design batch (kc.design_batch): many designs × the same load cases in one compiled
program, equal to a loop of kc.evaluate, and compiled once per shape. spec: stiffness §2.7."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.extend.core import jaxprs_in_params

from diffsusp import kc
from diffsusp.errors import InputError
from diffsusp.kc import designs
from diffsusp.models import TABLE_5_1, pseudo_mcpherson

DESIGN_BATCH_BUDGET = 7500  # jaxpr equations: 7 285 (kc.evaluate alone: 6 988, KC_BUDGET 7 000)


def _where(m):
    return m.bushings.k_trans, m.springs.k


def equations(jaxpr) -> int:
    """Equations of a jaxpr, counted through loops and sub-programs (as
    tests/test_program_size.py)."""
    return sum(1 + sum(equations(sub) for sub in jaxprs_in_params(e.params))
               for e in jaxpr.eqns)


@pytest.fixture(scope="module")
def batch():
    """3 designs (the model's own, and two with the bushings ±20 % and the spring ±5 %) × 3
    cases of Table 5-1 on the pseudo-McPherson, twice (new values, another lambda), counting
    the traces of the batch; and the same designs by a loop of kc.evaluate."""
    mech = pseudo_mcpherson()
    ev = kc.load_table(mech, TABLE_5_1[:3])
    rng = np.random.default_rng(0)
    kt, ks = np.asarray(mech.bushings.k_trans), np.asarray(mech.springs.k)
    k_trans = np.stack([kt] + [kt * rng.uniform(0.8, 1.2, kt.shape) for _ in range(2)])
    k_spring = np.stack([ks] + [ks * rng.uniform(0.95, 1.05, ks.shape) for _ in range(2)])
    calls = []
    real = designs.metrics_at

    def counting(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(designs, "metrics_at", counting)
        out = kc.design_batch(ev, _where, (k_trans, k_spring))
        first = len(calls)
        flat = np.concatenate([k_trans[::-1].reshape(3, -1) * 1.01, k_spring[::-1]], axis=1)
        again = kc.design_batch(ev, lambda m: (m.bushings.k_trans, m.springs.k), flat)
        second = len(calls) - first
    sel = kc.select(ev.rig.mech, _where)
    loop = []
    for theta in (np.concatenate([a.reshape(3, -1) for a in (k_trans, k_spring)], axis=1),
                  flat):
        loop.append([kc.evaluate(eqx.tree_at(lambda r: r.mech, ev.rig,
                                             sel.apply(ev.rig.mech, th)), ev.loads)
                     for th in theta])
    return ev, (out, again), loop, (first, second)


def test_design_batch_equals_a_loop_of_evaluate(batch):
    """Every metric, derivative metric and compliance matrix of every design equals
    kc.evaluate on that design, for both sets of designs."""
    _, outs, loops, _ = batch
    for out, loop in zip(outs, loops, strict=True):
        assert out.converged.all() and out.usable.all()
        assert set(out.metrics) == set(loop[0][1])
        for d, (sol, metrics, compliance) in enumerate(loop):
            np.testing.assert_allclose(np.asarray(out.solution.q[d]), np.asarray(sol.q),
                                       rtol=1e-9, atol=1e-9)
            np.testing.assert_array_equal(np.asarray(out.solution.stable[d]),
                                          np.asarray(sol.stable))
            for k, v in metrics.items():
                np.testing.assert_allclose(out.metrics[k][d], np.asarray(v), rtol=1e-8,
                                           atol=1e-12, err_msg=k)
            for k, v in compliance.items():
                np.testing.assert_allclose(out.compliance[k][d], np.asarray(v), rtol=1e-8,
                                           atol=1e-12 * np.max(np.abs(v)), err_msg=k)
        # the designs differ: the batch is not one design repeated
        assert np.ptp(out.metrics["lateral_compliance_steer"], axis=0).max() > 0


def test_design_batch_traces_once_per_shape(batch):
    """The second set of designs (new values, a new lambda selecting the same leaves) reuses
    the program: the batch body is traced on the first call only."""
    _, _, _, (first, second) = batch
    assert first >= 1
    assert second == 0


def test_design_batch_rejects_bad_values(batch):
    ev = batch[0]
    with pytest.raises(InputError, match="values must be"):
        kc.design_batch(ev, _where, np.zeros((2, 5)))
    with pytest.raises(InputError, match="one array per selected leaf"):
        kc.design_batch(ev, _where, (np.zeros((2, 3, 3)),))


def test_design_batch_program_within_budget(batch):
    """The batch's program (tracing only): one kc.evaluate in a loop, nothing per design."""
    ev = batch[0]
    sel = kc.select(ev.rig.mech, _where)
    theta = jnp.tile(sel.values(ev.rig.mech), (2, 1))
    q0 = jnp.zeros((ev.loads.n_cases, ev.rig.mech.n_coordinates))
    closed = jax.make_jaxpr(lambda th: designs._batch(ev.rig, ev.loads, sel, th, q0, 1e-12,
                                                      1e-10, 50, None))(theta)
    size = equations(closed.jaxpr)
    assert 1000 < size <= DESIGN_BATCH_BUDGET, size
