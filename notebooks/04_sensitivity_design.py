# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 04 — Sensitivity of K&C metrics and experiment design
#
# Which parameters of the pseudo-McPherson half axle does each K&C metric depend on, and which
# load cases should a rig test run so that the stiffnesses we care about are well determined?
#
# - `identify.sensitivity` differentiates every K&C metric with respect to every selected
#   parameter *exactly*, in forward mode through the implicitly differentiated equilibrium
#   (no finite differences), and normalises the result into elasticities.
# - `identify.design_experiment` picks, from candidate load cases, the ones that best determine
#   chosen parameters from landmark measurements (σ = 0.05 mm, the portable arm of the thesis),
#   and shows what each added case buys.
#
# Units: mm, N, N·mm, rad inside; tables print stiffnesses as the thesis does.

# %%
# %matplotlib inline
import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import numpy as np

from diffsusp import kc
from diffsusp.identify import design_experiment, sensitivity
from diffsusp.identify.params import Params
from diffsusp.models import TABLE_4_4, TABLE_5_1, pseudo_mcpherson, thesis_load_cases

mech = pseudo_mcpherson()
params = (Params.bushing_stiffness(mech, ["bushing_A", "bushing_B"])
          + Params.leaves(mech, lambda m: m.springs.k))
print(len(params), "parameters:", ", ".join(params.names))

# %% [markdown]
# ## Sensitivities along a parallel wheel travel
#
# Five points of a ±40 mm parallel travel. `derivatives=False` differentiates the geometric
# metrics (toe, camber, wheel-centre position, contact patch, vertical force...); with the
# default `derivatives=True` the derivative metrics (bump steer, wheel rate, ...) are
# differentiated too — exact second derivatives of the equilibrium, at the price of a longer
# compile.

# %%
travel = kc.parallel_travel(mech, travel=jnp.linspace(-40.0, 40.0, 5))
sens = sensitivity(travel, params, derivatives=False)
print(sens.table(["toe", "camber", "half_track_change", "vertical_force"], top=4))

# %% [markdown]
# The vertical force a wheel needs to reach a given travel is, as expected, the spring's
# business; toe and camber under travel depend on the bushings that the spring force deflects.

# %%
fig = sens.plot("toe", top=10)
fig

# %% [markdown]
# ## Sensitivities under the thesis load cases (Table 5-1)
#
# Steer and camber under lateral and longitudinal loads at the contact patch are what the
# thesis identified the bushings from (spec stiffness §2.7): here are their sensitivities at the
# ±4000 N lateral cases.

# %%
cases = kc.load_table(mech, TABLE_5_1)
sens_f = sensitivity(cases, params, metrics=["toe", "camber"], derivatives=False)
for case in (5, 8):
    print(f"case {case + 1} {TABLE_5_1[case]}: toe ←",
          ", ".join(f"{p} {v:+.3f}" for p, v in sens_f.ranked("toe", case)[:4]))

# %% [markdown]
# Ktx of bushings A and B (along the arms) dominate, which is why the thesis found them
# "correct from the first iteration"; Krx never appears: it is not loaded in service.
#
# ## Experiment design: which cases determine the arm bushings?
#
# Candidates: the 13 cases of Table 5-1 and the 17 of Table 4.4 (30 cases). Target: the
# translational stiffnesses of bushings A and B and the spring rate; the other stiffnesses are
# nuisance parameters. Measurements: every marker of the moving parts, σ = 0.05 mm.

# %%
candidates_table = np.concatenate([TABLE_5_1, TABLE_4_4])
candidates = thesis_load_cases(mech, candidates_table)
targets = [f"bushing_{b}.{a}" for b in "AB" for a in ("Ktx", "Kty", "Ktz")] + ["spring.k"]
plan = design_experiment(mech, candidates, params, 6, sigma=0.05, targets=targets,
                         criterion="sigma")
print(plan.table())
print("chosen (F_vert, F_lat, F_long):")
for c in plan.chosen:
    print("  ", candidates_table[c])

# %% [markdown]
# Each row is what adding one more case buys: the σ% of every target after the addition
# ('—' while a parameter is not yet determined). A handful of well-chosen cases determines the
# influential stiffnesses; the weakly loaded directions stay poorly determined whatever is
# added — the identifiability limit the thesis met (spec stiffness §2.7, §2.10).
