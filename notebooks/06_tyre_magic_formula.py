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
# # 06 — Tyre forces: the Magic Formula, evaluated and fitted
#
# - the thesis's twelve identified 1989 sets (Tables 14–29: 4 tyres × 3 pressures) compared:
#   F_y and M_z vs slip angle at 4.5 kN, and the similarity normalisation collapsing the F_y
#   curves of one tyre at all loads onto one primitive;
# - a `.tir` property file (MF 6.1) evaluated in combined slip, with its specification
#   quantities (exact derivatives);
# - a fit from noisy synthetic bench data with its report: σ, σ %, what the data cannot see;
# - the tyre on the K&C rig: the pseudo-McPherson's wheel at commanded slip angles, where the
#   cornering force and aligning torque turn and tilt the wheel (compliance steer and camber),
#   with the exact sensitivities of F_y to every bushing stiffness.
#
# Units: the 1989 sets are in the thesis's units (F_z kN, slip in degrees, M_z N·m); the MF 6.x
# interface is the library's (N, rad, N·mm).

# %%
import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np

from diffsusp.io.tir import read_tir
from diffsusp.tyre import (
    MagicFormula6,
    MagicFormula89,
    evaluate,
    example_path,
    mf89,
    specification,
    thesis_sets,
)
from diffsusp.tyre import fit as F
from diffsusp.tyre.spec import similarity, similarity_primitive

# %% [markdown]
# ## The thesis's twelve sets at 4.5 kN
# Tables 14–17 are the Dunlop R16 (the thesis captions them "Michelin"; spec §0.5.8). Every F_y
# set has C = a0 = 1: D_y is an asymptote, not a peak (with C = 1 and E < 1 the curve is monotone).

# %%
delta = jnp.linspace(-12.0, 12.0, 121)
fig, axes = plt.subplots(1, 2, figsize=(11, 4))
rows = []
for tyre in thesis_sets.TYRES:
    for p in thesis_sets.PRESSURES:
        m = MagicFormula89.from_thesis(tyre, p)
        mac = mf89.macro(m, 4.5)
        rows.append((tyre, p, float(mac["Dy"]), float(mac["BCDy"]), float(mac["BCDz"])))
        axes[0].plot(delta, mf89.fy0(m, delta, 4.5), lw=1, label=f"{tyre} {p} bar")
        axes[1].plot(delta, mf89.mz0(m, delta, 4.5), lw=1)
axes[0].set(xlabel="slip angle [deg]", ylabel="F_y [N]", title="F_y at 4.5 kN")
axes[1].set(xlabel="slip angle [deg]", ylabel="M_z [N·m]", title="M_z at 4.5 kN")
axes[0].legend(fontsize=6)
fig.tight_layout()
print(f"{'tyre':<14}{'bar':>5}{'D_y [N]':>10}{'BCD_y [N/deg]':>15}{'BCD_z [N·m/deg]':>17}")
for t, p, d, k, kz in rows:
    print(f"{t:<14}{p:>5}{d:>10.0f}{k:>15.0f}{kz:>17.1f}")

# %% [markdown]
# ## Similarity: the normalised F_y curves of one tyre collapse
# X̄ = BCD_y(δ + S_h)/D_y, F̄_y = (F_y − S_v)/D_y (2-119, 2-120, in the (x + S_h) convention of
# (B-9)); with C_y and E_y independent of load the curves at every load lie on P_Fy(X̄).

# %%
m = MagicFormula89.from_thesis("michelin_r16", 2.5)
fig, ax = plt.subplots(figsize=(6, 4))
for fz in (2.0, 3.5, 4.5, 6.0):
    mac = mf89.macro(m, fz)
    X, Fb, _, _ = similarity(delta, mf89.fy0(m, delta, fz), mf89.mz0(m, delta, fz),
                             D_y=mac["Dy"], BCD_y=mac["BCDy"], S_hy=mac["Shy"], S_vy=mac["Svy"],
                             BCD_z=mac["BCDz"], S_hz=mac["Shz"], S_vz=mac["Svz"])
    ax.plot(X, Fb, ".", ms=3, label=f"{fz} kN")
X = jnp.linspace(-8, 8, 200)
ax.plot(X, similarity_primitive(X, mac["Cy"], mac["Ey"]), "k-", lw=1, label="P_Fy")
ax.set(xlabel="X̄", ylabel="F̄_y")
ax.legend()

# %% [markdown]
# ## A `.tir` file: MF 6.1 in combined slip, and its specification quantities

# %%
tir = read_tir(example_path("mf61"))
tyre = MagicFormula6.from_tir(tir)
alpha = jnp.radians(jnp.linspace(-15, 15, 121))
fig, ax = plt.subplots(figsize=(6, 4))
for kappa in (0.0, 0.05, 0.1, 0.2):
    f = evaluate(tyre, 6752.0, kappa, alpha)
    ax.plot(jnp.degrees(alpha), f.fy, label=f"κ = {kappa}")
ax.set(xlabel="slip angle [deg]", ylabel="F_y [N]", title="MF 6.1, F_z = FNOMIN")
ax.legend()
spec = specification(tyre, jnp.array([3000.0, 6752.0, 10000.0]))
for i, fz in enumerate(np.asarray(spec["fz"])):
    k = float(spec["cornering_stiffness"][i]) * np.pi / 180
    print(f"F_z {fz:6.0f} N: cornering stiffness {k:8.1f} N/deg, "
          f"trail {float(spec['pneumatic_trail'][i]):5.1f} mm, peak F_y "
          f"{float(spec['fy_peak'][i]):7.0f} N at "
          f"{np.degrees(float(spec['alpha_at_fy_peak'][i])):4.1f} deg")

# %% [markdown]
# ## Fit from noisy synthetic bench data
# Pure lateral data from the file at four loads and three cambers, 1 % noise; eight lateral
# coefficients fitted from a start 30 % off with a Huber loss, plus PPY1 (a pressure term) that a
# single-pressure test cannot see — the report says so.

# %%
names = ["PCY1", "PDY1", "PDY2", "PEY1", "PKY1", "PKY2", "PHY1", "PVY1", "PPY1"]
fz = np.repeat([3000.0, 5000.0, 7000.0, 9000.0], 3 * 41)
ia = np.tile(np.repeat([-0.04, 0.0, 0.04], 41), 4)
sa = np.tile(np.linspace(-0.3, 0.3, 41), 12)
z = np.zeros(fz.size)
inputs = F.BenchData(*(jnp.asarray(v) for v in (fz, z, sa, ia, z + 16.6e3, z + 2.6e5)),
                     jnp.zeros((1, fz.size)), jnp.ones((1, fz.size), bool), ("FY",))
sigma = 0.01 * float(np.ptp(np.asarray(F.simulate(tyre, inputs, combined=False).measured)))
data = F.simulate(tyre, inputs, noise={"FY": sigma}, seed=1, combined=False)
start = tyre.replace(**{k: 1.3 * float(tyre[k]) for k in names})
fitted, report = F.fit(start, data, names, noise={"FY": sigma}, combined=False)
print(report.table())
print("true values:", {k: round(float(tyre[k]), 6) for k in names})

# %%
figures = F.plot_fit(fitted, data, combined=False)

# %% [markdown]
# ## The tyre on the K&C rig
# The MF 6.1 tyre at the pseudo-McPherson's contact patch (`diffsusp.tyre.rig`), F_z = 4.5 kN, at
# commanded slip angles (ISO-W: the slip angle the tyre would have on a rigid suspension; a
# positive α pushes the tyre to its right, here inboard on the left wheel). The tyre's force
# and aligning torque deflect the bushings: the wheel steers (the effective α differs from the
# command) and cambers (the inclination changes), and the tyre answers with another force —
# one coupled equilibrium, solved by Newton with exact Jacobians. `jax.jacfwd` through it gives
# the exact sensitivity of F_y to each bushing stiffness (implicit differentiation of the
# coupled root, no finite differences), in the same compiled program.

# %%
import equinox as eqx

from diffsusp.models import pseudo_mcpherson
from diffsusp.tyre import rig as tyre_rig

rig = tyre_rig.tyre_rig(pseudo_mcpherson(), tyre)
commands = jnp.radians(jnp.array([-4.0, -2.0, 1.0, 3.0]))


@eqx.filter_jit
def cornering(k_trans, k_rot):
    def f(kt, kr):
        mech = eqx.tree_at(lambda m: (m.bushings.k_trans, m.bushings.k_rot), rig.mech, (kt, kr))
        sol = tyre_rig.solve(eqx.tree_at(lambda r: r.mech, rig, mech), commands, fz=4500.0,
                             throw=False)
        return jnp.stack([sol.forces.fy, sol.forces.mz, sol.slip_angle, sol.inclination,
                          sol.status.astype(float)])

    return f(k_trans, k_rot), jax.jacfwd(lambda kt, kr: f(kt, kr)[0], argnums=(0, 1))(
        k_trans, k_rot)


b = rig.mech.bushings
value, (d_kt, d_kr) = cornering(b.k_trans, b.k_rot)
rigid = evaluate(tyre, 4500.0, 0.0, commands, value[3])  # the same inclination, no steer
for i, a in enumerate(np.degrees(np.asarray(commands))):
    print(f"α_cmd {a:5.1f}°: α {np.degrees(float(value[2, i])):6.3f}°, γ "
          f"{np.degrees(float(value[3, i])):6.3f}°, F_y {float(value[0, i]):7.0f} N "
          f"(rigid steer {float(rigid.fy[i]):7.0f} N), M_z {float(value[1, i]) / 1e3:6.1f} N·m"
          f", converged {int(value[4, i]) == 0}")

# %% [markdown]
# Normalised sensitivities (K/F_y)·∂F_y/∂K at α_cmd = 3°: which bushing stiffnesses set the
# cornering force the wheel delivers (bushing F has no torsional stiffness, K_rz = 0).

# %%
case = 3
names = [f"{n}.{a}" for n in b.names for a in ("Kx", "Ky", "Kz", "Krx", "Kry", "Krz")]
k_all = np.concatenate([np.asarray(b.k_trans), np.asarray(b.k_rot)], axis=1).ravel()
d_all = np.concatenate([np.asarray(d_kt)[case], np.asarray(d_kr)[case]], axis=1).ravel()
normalised = k_all * d_all / float(value[0, case])
order = np.argsort(-np.abs(normalised))[:10]
fig, ax = plt.subplots(figsize=(6, 3.5))
ax.barh([names[i] for i in order][::-1], normalised[order][::-1])
ax.set(xlabel="(K / F_y) · ∂F_y/∂K", title="F_y at α_cmd = 3°, pseudo-McPherson")
fig.tight_layout()
