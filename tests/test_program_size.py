"""Deterministic budgets on the size of the main compiled programs (jaxpr equations, counted
recursively through loops and sub-programs). Program size, not arithmetic, was what made
solve_statics slow to compile (17 753 equations for pseudo_mcpherson before the kernel was
restructured): a change that makes these programs grow again fails here, long before anyone
times it. Tracing only; nothing is compiled."""

import jax
import jax.numpy as jnp
import pytest
from jax.extend.core import jaxprs_in_params

import diffsusp as ds
from diffsusp.kc import events
from diffsusp.models import pseudo_mcpherson, thesis_load_cases

SOLVE_BUDGET = 2500  # batched solve_statics, pseudo_mcpherson, 13 cases (17 753 before)
KC_BUDGET = 7000  # kc.evaluate of the Table 5-1 event: the solve + all metrics and derivatives


def equations(jaxpr) -> int:
    n = 0
    for eqn in jaxpr.eqns:
        n += 1 + sum(equations(sub) for sub in jaxprs_in_params(eqn.params))
    return n


@pytest.fixture(scope="module")
def mech():
    return pseudo_mcpherson()


def test_solve_statics_program_within_budget(mech):
    loads = thesis_load_cases(mech)
    closed = jax.make_jaxpr(lambda l: ds.solve_statics(mech, l, throw=False))(loads)
    size = equations(closed.jaxpr)
    assert 500 < size <= SOLVE_BUDGET, size


def test_kc_evaluation_program_within_budget(mech):
    rig = events.force_rig(mech)
    loads = events.event_loads(rig, 13, vertical=jnp.linspace(1500.0, 7500.0, 13))
    closed = jax.make_jaxpr(lambda l: events.evaluate(rig, l))(loads)
    size = equations(closed.jaxpr)
    assert 1000 < size <= KC_BUDGET, size
