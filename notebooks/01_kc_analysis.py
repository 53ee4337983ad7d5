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
# # 01 — K&C analysis of a half axle
#
# Build (here: load) a suspension model, run the standard kinematics & compliance events,
# compare two designs on the same axes, read the derivative metrics, and take the exact
# derivative of bump steer with respect to a hardpoint.
#
# Units inside: mm, N, N·mm, rad. Metrics follow the Adams/Car conventions per side (toe-in
# positive, camber top-out positive); `diffsusp.kc.metrics` documents every definition.

# %%
# %matplotlib inline
import jax

jax.config.update("jax_enable_x64", True)
import equinox as eqx
import jax.numpy as jnp
import numpy as np

import diffsusp
from diffsusp import kc, plot
from diffsusp.identify import sensitivity
from diffsusp.identify.params import Params

# %% [markdown]
# ## The model
#
# The thesis's pseudo-McPherson test half axle ships as a native model file; `load_model`
# also reads Adams datasets (`.adm`) and Chrono::Vehicle JSON templates.

# %%
mech = diffsusp.load_model("pseudo_mcpherson")
print(mech.describe())
print(diffsusp.validate(mech))

# %% [markdown]
# ## Parallel wheel travel, ±80 mm
#
# 161 equilibria, solved as one compiled batch; every metric, and the derivative metrics
# (bump steer, bump camber, wheel rate...) by forward-mode differentiation through the
# equilibrium.

# %%
travel = kc.parallel_travel(mech, travel=jnp.linspace(-80.0, 80.0, 161), label="nominal")
at_design = int(np.argmin(np.abs(travel.x)))
for name in ("toe", "camber", "half_track_change", "bump_steer", "bump_camber", "wheel_rate",
             "roll_centre_height"):
    print(f"{name:>20}: {kc.display(name, travel.metrics[name][at_design]):+.4g} "
          f"{kc.display_unit(name)}")

# %% [markdown]
# A second design on the same axes: bushing B (front arm) twice as stiff.

# %%
b = mech.bushings.index("bushing_B")
stiff = eqx.tree_at(lambda m: (m.bushings.k_trans, m.bushings.k_rot), mech,
                    (mech.bushings.k_trans.at[b].multiply(2.0),
                     mech.bushings.k_rot.at[b].multiply(2.0)))
travel_stiff = kc.parallel_travel(stiff, travel=travel.x, label="bushing B ×2")
fig = plot.kc_curves([travel, travel_stiff], ["toe", "camber", "half_track_change"],
                     title="parallel wheel travel")
fig

# %% [markdown]
# ## Compliance: lateral and longitudinal force at the contact patch
#
# At the design vertical load (4 500 N), lateral force ±4 000 N (inboard positive) and
# longitudinal force ±4 000 N (braking positive), 13 points each: the batched solve has the
# shape of the 13 load cases of Table 5-1, so both events reuse that compiled program.

# %%
forces = jnp.linspace(-4000.0, 4000.0, 13)
lateral = kc.lateral_force(mech, forces, label="nominal")
longitudinal = kc.longitudinal_force(mech, forces, label="nominal")
fig = plot.kc_curves([lateral], ["toe", "camber"], title="lateral force")
fig

# %%
fig = plot.kc_curves([longitudinal], ["toe", "camber"], title="longitudinal force")
fig

# %%
mid = len(forces) // 2
for name in ("lateral_compliance_steer", "lateral_compliance_camber"):
    print(f"{name}: {kc.display(name, lateral.metrics[name][mid]):+.4g} {kc.display_unit(name)}")
for name in ("longitudinal_compliance_steer", "longitudinal_compliance_camber"):
    print(f"{name}: {kc.display(name, longitudinal.metrics[name][mid]):+.4g} "
          f"{kc.display_unit(name)}")

# %% [markdown]
# ## The exact derivative of bump steer with respect to a hardpoint
#
# Raising the tie rod's outer ball joint (L6 on the hub carrier: the marker `tie_rod.j` of the
# tie-rod joint; the marker `L6_tie_rod_outer` only labels the point) changes the bump steer. Its
# derivative with respect to the joint's height is a second derivative of the equilibrium
# (bump steer is already a derivative along the travel): `identify.sensitivity` computes it
# exactly by nested forward-mode differentiation through the implicit equilibrium. We check it
# against a central difference of two full re-analyses.

# %%
L6 = mech.markers.index("tie_rod.j")
mask = np.zeros(mech.markers.position.shape, bool)
mask[L6, 2] = True
hardpoint = Params.leaves(mech, lambda m: m.markers.position, mask=mask)
points = kc.parallel_travel(mech, travel=jnp.linspace(-40.0, 40.0, 5))
sens = sensitivity(points, hardpoint, metrics=["bump_steer", "toe"])
exact = sens.jacobian["bump_steer"][:, 0]


def bump_steer_with_l6_height(dz):
    moved = eqx.tree_at(lambda m: m.markers.position, mech,
                        mech.markers.position.at[L6, 2].add(dz))
    return np.asarray(kc.parallel_travel(moved, travel=points.x).metrics["bump_steer"])


h = 0.01  # mm
central = (bump_steer_with_l6_height(h) - bump_steer_with_l6_height(-h)) / (2 * h)
for x, e, c in zip(points.x, exact, central, strict=True):
    print(f"travel {x:+5.0f} mm: d(bump steer)/dz_L6 = {np.degrees(e) * 1e3:+.5f} "
          f"mdeg/mm per mm (central difference {np.degrees(c) * 1e3:+.5f})")
