"""The statics Newton as a solver: one status vocabulary, library errors for bad values, one
compiled program per `solve_statics` call with the flags from the Newton's own Jacobian, the
size of that program, and second derivatives (forward over reverse) through the equilibrium.

Cheap on purpose: the 13 thesis cases of pseudo_mcpherson share their programs with the other
statics files (the run's compilation cache); the derivative checks use the 3-part
two_bushing_coupler."""

import logging
import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffsusp as ds
from diffsusp.errors import InputError, ModelError
from diffsusp.models import pseudo_mcpherson, thesis_load_cases, two_bushing_coupler
from diffsusp.statics import STATUS_TEXT, Status, checks
from diffsusp.statics import solve as solve_module

sys.path.insert(0, str(__import__("pathlib").Path(__file__).parent))
from test_program_size import SOLVE_BUDGET, equations  # noqa: E402

FLAGS_BUDGET = 260  # equations the flags add to the solve (stability from the last Jacobian,
# projected angles, validity); the flagged program stays within SOLVE_BUDGET too


@pytest.fixture(scope="module")
def mcpherson():
    mech = pseudo_mcpherson()
    return mech, thesis_load_cases(mech)


@pytest.fixture(scope="module")
def coupler():
    return two_bushing_coupler()


def test_status_vocabulary_is_one_table():
    codes = [int(s) for s in Status]
    assert codes == sorted(set(codes)) and Status.CONVERGED == 0
    assert STATUS_TEXT == {int(s): s.text for s in Status}
    assert all(isinstance(s.text, str) and s.text for s in Status)
    assert Status(3) is Status.STALLED and "stalled" in Status(3).text


def test_no_status_is_compared_with_a_bare_number():
    """Every status comparison of the library names a `Status` member (AST scan): a bare
    `status == 0` is a second status table in disguise."""
    import ast
    import pathlib

    bare = []
    for path in sorted((pathlib.Path(ds.__file__).parent).rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Compare) and "status" in ast.unparse(node.left).lower():
                for right in node.comparators:
                    value = right.operand if isinstance(right, ast.UnaryOp) else right
                    if isinstance(value, ast.Constant) and isinstance(value.value, int):
                        bare.append(f"{path.name}:{node.lineno} {ast.unparse(node)}")
    assert not bare, bare


def test_bad_values_raise_library_errors(coupler):
    loads = coupler.loads(forces={"coupler_middle": np.array([[0.0, 0.0, 100.0]] * 3)})
    bad = eqx.tree_at(lambda m: m.bushings.k_trans, coupler,
                      coupler.bushings.k_trans.at[0, 0].set(jnp.nan))
    with pytest.raises(ModelError, match="non-finite"):
        ds.solve_statics(bad, loads)
    negative = eqx.tree_at(lambda m: m.bushings.k_rot, coupler,
                           coupler.bushings.k_rot.at[1, 2].set(-1.0))
    with pytest.raises(ModelError, match="k_rot"):
        ds.solve_statics(negative, loads)
    with pytest.raises(InputError, match="devices must be"):
        ds.solve_statics(coupler, loads, devices="two")
    with pytest.raises(InputError, match="local device"):
        ds.solve_statics(coupler, loads, devices=64)
    with pytest.raises(InputError, match="q0 must have 18"):
        ds.solve_statics(coupler, loads, q0=np.zeros(7))
    with pytest.raises(InputError, match="leading case axis"):
        ds.solve_sweep(coupler, coupler.loads(forces={"coupler_middle": [0.0, 0.0, 1.0]}))
    with pytest.raises(InputError, match="chunk"):
        next(ds.statics.solve_statics_chunks(coupler, loads, chunk=0))


def test_one_program_per_call_with_the_flags_of_the_newton_jacobian(mcpherson, caplog):
    mech, loads = mcpherson
    # 11 cases: a table size no other test solves, so that this call compiles its program here.
    loads = jax.tree.map(lambda a: a[:11], loads)
    jax.config.update("jax_log_compiles", True)
    try:
        with caplog.at_level(logging.WARNING, logger="jax"):
            sol = ds.solve_statics(mech, loads)
    finally:
        jax.config.update("jax_log_compiles", False)
    compiled = [r.getMessage() for r in caplog.records if r.getMessage().startswith("Compiling")]
    assert len(compiled) == 1 and "_solve_batch" in compiled[0], compiled
    assert np.all(np.asarray(sol.status) == Status.CONVERGED)
    # The flags from the Newton's last (twist) Jacobian agree with the separate checks on the
    # Gibbs linearisation (SVD null space) and the bushing states: margins in sign and size.
    n = mech.topology.n

    @jax.jit
    def margins(loads_, q, lam):
        def one(l, q1, lam1):
            y = jnp.concatenate([ds.statics.to_internal(mech, q1), lam1])
            twist = ds.statics.kernel.assemble_twist(mech, l, y[:n], y[n:])[1]
            return (checks.kkt_stability_margin(mech, twist),
                    checks.stability_margin(mech, l, q1, lam1), checks.law_validity(mech, q1))
        return jax.vmap(one)(loads_, q, lam)

    newton, gibbs, ratio = map(np.asarray, margins(loads, sol.q, sol.multipliers))
    np.testing.assert_array_equal(np.asarray(sol.stable), gibbs > checks.STABILITY_TOLERANCE)
    np.testing.assert_array_equal(np.asarray(sol.law_valid), ratio <= 1.0)
    assert np.all(newton > checks.STABILITY_TOLERANCE) and np.all(ratio > 0.01)
    assert np.all((0.2 < newton / gibbs) & (newton / gibbs < 5.0)), newton / gibbs


def test_flagged_program_within_budget(mcpherson):
    mech, loads = mcpherson
    tol = solve_module._Tolerances(rtol=1e-12, atol=1e-10, max_steps=50)
    q0 = np.zeros(mech.n_coordinates)
    sizes = [equations(jax.make_jaxpr(lambda l, f=flags: solve_module._solve_batch(
        mech, l, q0, tol, f, 4096, False))(loads).jaxpr) for flags in (False, True)]
    assert sizes[1] <= SOLVE_BUDGET and 0 < sizes[1] - sizes[0] <= FLAGS_BUDGET, sizes


def test_forward_over_reverse_through_the_equilibrium(coupler):
    """jax.jvp of jax.grad of an equilibrium output (a Hessian-vector product in the bushing
    stiffnesses) against central differences of the exact gradient."""
    loads = coupler.loads(forces={"coupler_middle": [[150.0, -80.0, 400.0], [-60.0, 120.0, 250.0]]},
                          moments={"coupler_middle": [[3e3, 0.0, -2e3], [0.0, 4e3, 1e3]]})
    k0 = jnp.concatenate([coupler.bushings.k_trans.ravel(), coupler.bushings.k_rot.ravel()])

    def output(k):
        m = eqx.tree_at(lambda m_: (m_.bushings.k_trans, m_.bushings.k_rot), coupler,
                        (k[:6].reshape(2, 3), k[6:].reshape(2, 3)))
        q = ds.solve_statics(m, loads).q
        return jnp.sum(q[:, :3] ** 2) + 1e4 * jnp.sum(q[:, 3:] ** 2)

    direction = jnp.asarray(np.random.default_rng(3).normal(size=k0.size)) * k0
    # One program: its primal output is the exact gradient, its tangent the product.
    grad_hvp = jax.jit(lambda k: jax.jvp(jax.grad(output), (k,), (direction,)))
    hvp = grad_hvp(k0)[1]
    h = 1e-4
    central = (grad_hvp(k0 + h * direction)[0] - grad_hvp(k0 - h * direction)[0]) / (2 * h)
    np.testing.assert_allclose(hvp, central, rtol=1e-6, atol=1e-6 * float(jnp.max(jnp.abs(hvp))))
