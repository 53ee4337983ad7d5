"""Sensitivities of K&C metrics (exact, second order through the equilibrium where needed) and
experiment design. spec: stiffness §2.7, §3; guaranteed_least_squares §3.8."""

import dataclasses
import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffsusp as ds
from diffsusp import kc
from diffsusp.identify import design_experiment, sensitivity, sensitivity_metrics
from diffsusp.identify.params import Params
from diffsusp.models import isolated_bushing, pseudo_mcpherson, two_bushing_coupler


def test_second_derivative_through_the_equilibrium_matches_differences():
    """d²q/dk²: the implicit JVP rule is itself differentiable (no stop_gradient)."""
    mech = two_bushing_coupler()
    loads = mech.loads(forces={"coupler_middle": jnp.array([[300.0, -200, 500],
                                                            [100, 50, -300]])})
    k0 = float(mech.bushings.k_trans[0, 0])

    def out(k):
        m = eqx.tree_at(lambda x: x.bushings.k_trans, mech, mech.bushings.k_trans.at[0, 0].set(k))
        return ds.solve_statics(m, loads).q.sum(axis=1)

    d1 = jax.jacfwd(out)

    def d1_and_d2(k):
        """dq/dk and d²q/dk² at k, from one compiled program (the forward-mode derivative of
        d1, whose primal output is d1 itself), evaluated at the three points below."""
        return jax.jvp(d1, (k,), (1.0,))

    h = 1e-3 * k0
    fd = (np.asarray(d1_and_d2(k0 + h)[0]) - np.asarray(d1_and_d2(k0 - h)[0])) / (2 * h)
    d2 = d1_and_d2(k0)[1]
    np.testing.assert_allclose(np.asarray(d2), fd, rtol=1e-5)
    assert np.all(np.abs(fd) > 0)


@pytest.fixture(scope="module")
def travel():
    """Five points of a ±40 mm parallel travel, and the parameters notebooks 01 and 04 use (the
    same compiled programs: the persistent compilation cache shares them)."""
    mech = pseudo_mcpherson()
    ev = kc.parallel_travel(mech, travel=jnp.linspace(-40.0, 40.0, 5))
    stiffness = (Params.bushing_stiffness(mech, ["bushing_A", "bushing_B"])
                 + Params.leaves(mech, lambda m: m.springs.k))
    mask = np.zeros(mech.markers.position.shape, bool)
    mask[mech.markers.index("tie_rod.j"), 2] = True
    hardpoint = Params.leaves(mech, lambda m: m.markers.position, mask=mask)
    return ev, stiffness, hardpoint


def _finite_differences(rig, loads, params, names, rel=1e-4):
    """Central differences of the statics (kc.evaluate at θ ± h, one parameter at a time;
    h = rel·|θ|, or 0.01 mm for `rel=None`)."""
    theta = np.asarray(params.values(rig.mech))
    out = {n: np.zeros((loads.n_cases, len(theta))) for n in names}
    for j in range(len(theta)):
        h = 0.01 if rel is None else rel * abs(theta[j])
        vals = []
        for s in (1, -1):
            th = theta.copy()
            th[j] += s * h
            r = eqx.tree_at(lambda r_: r_.mech, rig, params.apply(rig.mech, jnp.asarray(th)))
            vals.append(kc.evaluate(r, loads)[1])
        for n in names:
            out[n][:, j] = (np.asarray(vals[0][n]) - np.asarray(vals[1][n])) / (2 * h)
    return out


GEOMETRIC = ("toe", "camber", "wheel_centre_x", "wheel_centre_y", "half_track_change",
             "vertical_force", "caster", "kingpin_inclination", "scrub_radius")


def test_metric_sensitivities_match_finite_differences(travel):
    ev, params, _ = travel
    rep = sensitivity(ev, params, derivatives=False)
    fd = _finite_differences(ev.rig, ev.loads, params, GEOMETRIC)
    for name in GEOMETRIC:
        scale = np.abs(fd[name]).max()
        assert scale > 0, name
        np.testing.assert_allclose(rep.jacobian[name], fd[name], atol=1e-5 * scale,
                                   err_msg=name)
    # Elasticities are the Jacobian times θ over the metric's largest magnitude.
    theta = np.asarray(params.values(ev.rig.mech))
    np.testing.assert_allclose(rep.elasticity["toe"], rep.jacobian["toe"] * theta
                               / np.abs(rep.values["toe"]).max(), rtol=1e-12)
    # The ranking puts the most influential parameter first: toe under travel is set by the
    # bushings' compliance to the spring force.
    ranked = rep.ranked("vertical_force")
    assert ranked[0][0] == "spring.k"
    assert abs(ranked[0][1]) >= max(abs(v) for _, v in ranked[1:])


def test_sensitivity_metrics_default_to_the_registry_choice(travel):
    """The default metrics are the event's metrics the K&C registry marks for sensitivity;
    without derivatives the derivative ones are left out; asked names are checked."""
    from diffsusp.errors import InputError
    from diffsusp.kc.metrics import METRICS

    ev = travel[0]
    names = sensitivity_metrics(ev)
    expected = sorted(k for k in ev.metrics if k in METRICS and METRICS[k].sensitivity)
    assert list(names) == expected and {"toe", "camber", "bump_steer"} <= set(names)
    geometric = sensitivity_metrics(ev, derivatives=False)
    assert list(geometric) == [k for k in expected if not METRICS[k].derivative]
    assert "bump_steer" not in geometric and "toe" in geometric
    assert sensitivity_metrics(ev, ["toe", "camber"]) == ("toe", "camber")
    with pytest.raises(InputError, match=r"unknown metric\(s\) \['bump_steer'\]"):
        sensitivity_metrics(ev, ["bump_steer"], derivatives=False)


@pytest.mark.slow
def test_bump_steer_sensitivity_to_a_hardpoint_matches_finite_differences(travel):
    """A derivative metric (bump steer) differentiated with respect to a hardpoint (the tie rod's
    outer ball joint height): second order through the equilibrium, exact."""
    ev, _, hardpoint = travel
    rep = sensitivity(ev, hardpoint, metrics=["bump_steer", "toe"])
    fd = _finite_differences(ev.rig, ev.loads, hardpoint, ("bump_steer", "toe"), rel=None)
    for name in ("bump_steer", "toe"):
        scale = np.abs(fd[name]).max()
        assert scale > 0, name
        np.testing.assert_allclose(rep.jacobian[name], fd[name], atol=1e-5 * scale,
                                   err_msg=name)


def test_experiment_design_picks_one_case_per_direction_with_closed_form_sigma():
    """Isolated bushing (K = 100 N/mm): a force at the bushing centre along one axis of the
    bushing's J frame informs only that axis's stiffness. Candidates: 100 N and 300 N along each
    axis. Three cases suffice; the 300 N ones are chosen, and σ(K)/K = σ / (δ·√m) with
    δ = 3 mm the deformation and m the markers on the part (all translate by δ)."""
    mech = isolated_bushing()
    r_j = np.asarray(mech.markers.orientation[mech.bushings.j_marker[0]])
    forces = [f * r_j[:, a] for f in (100.0, 300.0) for a in range(3)]
    candidates = mech.loads(forces={"centre": jnp.asarray(np.array(forces))})
    params = Params.leaves(mech, lambda m: m.bushings.k_trans)
    rep = design_experiment(mech, candidates, params, 3, sigma=0.05)
    assert sorted(rep.chosen) == [3, 4, 5]
    assert np.isinf(rep.sigma[0]).sum() == 2  # two axes undetermined after the first case
    m = int(np.sum(np.asarray(mech.markers.part) >= 0))
    np.testing.assert_allclose(rep.sigma[-1], 0.05 / (3.0 * np.sqrt(m)), rtol=1e-9)
    assert rep.relative.all() and "%" in rep.table()
    # By the σ criterion, the same three.
    rep = design_experiment(mech, candidates, params, 3, criterion="sigma")
    assert sorted(rep.chosen) == [3, 4, 5]
    # The table shows the targets' full names (cut at 12 characters, they read alike), and
    # continues a plan: one row per case, the given ones first, also when n == len(start).
    names = ("lca_bushing.Ktx", "lca_bushing.Kty", "lca_bushing.Krz")
    table = dataclasses.replace(rep, targets=names).table()
    assert table.splitlines()[0].split()[4:] == list(names)
    for start, n in (((3, 4, 5), 3), ((0,), 3)):
        plan = design_experiment(mech, candidates, params, n, start=start, criterion="sigma")
        assert plan.chosen[:len(start)] == start and len(plan.chosen) == n
        assert plan.sigma.shape == (n, 3) and plan.logdet.shape == (n,)
        rows = plan.table().splitlines()
        assert len(rows) == n + 2 and rows[1].split()[0] == "1*"
    np.testing.assert_allclose(plan.sigma[0][[1, 2]], np.inf)  # case 0 alone: axis 0 only
    np.testing.assert_allclose(plan.sigma[-1], rep.sigma[-1] * np.array([3.0, 1.0, 1.0]),
                               rtol=1e-9)  # 100 N along axis 0 instead of 300 N: σ × 3
    with pytest.raises(ds.InputError, match="counts the start cases"):
        design_experiment(mech, candidates, params, 1, start=(3, 4))
    with pytest.raises(ds.InputError, match="criterion"):
        design_experiment(mech, candidates, params, 3, criterion="A")


def test_sensitivity_command(tmp_path):
    """`diffsusp sensitivity`: ranked table, JSON Jacobians equal to the library's, figures,
    and bad input (exit 2)."""
    from typer.testing import CliRunner

    from diffsusp.cli import app

    args = ["sensitivity", "pseudo_mcpherson", "--travel", "-40:40:5", "--no-derivatives",
            "--metric", "toe", "--metric", "camber"]
    runner = CliRunner()
    result = runner.invoke(app, [*args, "--out", str(tmp_path), "--top", "3"])
    assert result.exit_code == 0, result.output
    assert "bushing_A.Ktx" in result.output or "bushing_B.Ktx" in result.output
    assert (tmp_path / "sensitivity_toe.png").stat().st_size > 0
    out = json.loads(runner.invoke(app, [*args, "--json"]).output)
    assert set(out["metrics"]) == {"toe", "camber"}
    # the table is narrow and uncut: every ranked parameter with its number (a
    # column per rank would cut them, "1.1992e…", even at 200 columns)
    table = runner.invoke(app, args, env={"COLUMNS": "100"}).output
    rows = [line for line in table.splitlines() if "bushing_" in line or "spring." in line]
    assert "…" not in table and max(len(line.rstrip()) for line in rows) <= 60
    for name in ("toe", "camber"):
        for p, v in out["metrics"][name]["ranked"][:5]:
            assert any(p in line and f"{v:+.4g}" in line for line in table.splitlines()), p
    mech = pseudo_mcpherson()
    # The spring rate's column against a central difference of two re-runs of the event (the
    # same compiled program).
    j = out["params"].index("spring.k")
    k = float(mech.springs.k[0])
    toe = [np.asarray(kc.parallel_travel(
        eqx.tree_at(lambda m: m.springs.k, mech, mech.springs.k.at[0].set(k + s * 1e-4 * k)),
        travel=jnp.linspace(-40.0, 40.0, 5)).metrics["toe"]) for s in (1, -1)]
    fd = (toe[0] - toe[1]) / (2e-4 * k)
    np.testing.assert_allclose(np.asarray(out["metrics"]["toe"]["jacobian"])[:, j], fd,
                               rtol=1e-5, atol=1e-6 * np.abs(fd).max())
    for bad, message in ((["--params", "all"], "'all' is not one of"),
                         (["--metric", "nope"], "unknown metric(s) ['nope']")):
        result = runner.invoke(app, ["sensitivity", "pseudo_mcpherson", "--no-derivatives",
                                     "--travel", "-40:40:5", *bad])
        assert result.exit_code == 2, result.output
        assert message in " ".join(result.output.split())
