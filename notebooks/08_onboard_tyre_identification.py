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
# # 08 — Tyre identification from on-board vehicle measurements
#
# The thesis's chapter 4 on a synthetic car (`diffsusp.tyre.vehicle`, the 12-DOF model of
# §5.2 driving a steering-wheel sine with a known tyre): the body's ground plane and twist from
# four lasers, an inertial unit and a Correvit, the tyre inputs of each wheel, and the reduced
# lateral model (4-16…4-18) pooled over the four wheels. The Correvit is 100 ms late: the
# naive pipeline gets the camber stiffness's sign wrong (as the thesis did); the delay,
# estimated from kinematic consistency with the inertial unit, is removed and the sign comes
# back. The coefficients come from instrumental variables (the even samples' regressors are
# the instruments of the odd samples' rows and vice versa): every regressor is measured, and
# ordinary least squares would be biased by about one σ. A short record (6 s) keeps the
# notebook cheap; `benchmarks/tyre_onboard.py` runs 60 s. Units SI (m, N, s, rad); F_z in kN in
# the load polynomials.

# %%
import jax

jax.config.update("jax_enable_x64", True)
import pathlib

import matplotlib.pyplot as plt
import numpy as np

import diffsusp
from diffsusp.tyre import onboard, vehicle

car, sensors = vehicle.Vehicle(), vehicle.Sensors()
record = vehicle.simulate(car, duration=6.0)
data = vehicle.measure(car, sensors, record, jax.random.key(0), delay=0.1)
print("true:", dict(zip(vehicle.TYRE_NAMES, np.asarray(car.tyre.vector()), strict=True)))

# the tests use this record without simulating it (tests/data/onboard_sine.npz, float32):
# it must still be what the simulation gives
shipped = pathlib.Path(diffsusp.__file__).parents[1] / "tests" / "data" / "onboard_sine.npz"
if shipped.exists():
    clean = vehicle.channels(car, sensors, record)
    with np.load(shipped) as z:
        for k in ("lasers", "correvit", "imu_omega", "wrench", "spin", "true_fz"):
            ref = np.asarray(clean[k])
            assert np.allclose(z[k], ref, rtol=1e-6, atol=1e-6 * np.abs(ref).max()), k

# %% [markdown]
# ## Naive pipeline (no delay removed) and with the estimated delay

# %%
naive = onboard.identify(data, groupings=("all",), camber=(True,), delay=0.0)
fixed = onboard.identify(data, groupings=("all",), camber=(True,))
k = onboard.NAMES.index("b_gamma_1")
print(f"estimated Correvit delay: {1000 * fixed['delay']:.1f} ms (true 100 ms)")
print(f"camber coefficient b_gamma_1: naive {naive['reports'][0].fit.x[k]:.0f}, "
      f"delay removed {fixed['reports'][0].fit.x[k]:.0f}, true {float(car.tyre.b_gamma_1):.0f}")
print(fixed["reports"][0].table())

# %%
t = np.asarray(record.time)
fig, ax = plt.subplots(2, 1, figsize=(9, 5), sharex=True)
ax[0].plot(t, np.degrees(np.asarray(record.steer)), lw=0.7)
ax[0].set_ylabel("front steer [deg]")
ax[1].plot(t, np.asarray(data["true_fy"])[:, 0], lw=0.7, label="F_y front left")
ax[1].plot(t, np.asarray(data["true_gamma"])[:, 0] * 1e5, lw=0.7, label="camber × 1e5")
ax[1].set_xlabel("t [s]")
ax[1].legend()
fig.tight_layout()

# %% [markdown]
# ## The 30-DOF input kinematics: K&C tables computed by `kc`
#
# The thesis's 30-DOF model takes each wheel carrier's toe, camber, track and wheelbase changes
# from K&C tables (§5.2, Table 30). `vehicle_kc.kc_tables()` computes them with `kc` on the
# built-in pseudo-McPherson (travel ±60 mm × lateral force ±3 kN, 15 cases); the library ships
# them (`load_tables()`, checked against `kc` by the tests). The interpolant is C¹, so the
# poses are differentiable; `Vehicle(kinematics=…)` drives the synthetic car with them and
# `onboard.identify(…, kinematics=…)` (CLI: `--kinematics kc`) uses them in the pipeline. The
# joint vehicle + tyre identification without the wheels' lateral forces, (4-3), is
# `onboard_joint.identify` (CLI: `--joint --mass … --tyre-vertical …`): the even and the odd
# samples' residuals' cross product minimised (the noise in the regressors does not pull it),
# σ by a sandwich clustered over one window's rows, the relaxation L_R held (a steering sine
# does not pin it) and every estimate that hinges on it (here K_φ) reported not determined.
# Its Monte-Carlo (`benchmarks/tyre_onboard_joint.py`, 100 draws of a 6 s sine on the 30-DOF
# car with a Magic-Formula-like tyre): K_δ front and rear, K_γ and I_zz identified in every
# draw, within 3σ of the truth in 98–100 %, spread/σ 0.76–1.04. Below: that car driven with
# the tables, measured with noise, and the joint fit (its K&C conditioning compiles for about
# 15 s on first use).

# %%
from diffsusp.tyre import vehicle_kc

tables = vehicle_kc.load_tables()
travel = np.linspace(-0.07, 0.07, 57)
# one compiled look-up for every curve (front axle: 0)
curve = jax.jit(jax.vmap(lambda z, f: tables.lookup(0, z, f), in_axes=(0, None)))
fig, ax = plt.subplots(1, 2, figsize=(9, 3))
for f in (-3000.0, 0.0, 3000.0):
    vals = np.asarray(curve(travel, f))
    ax[0].plot(1000 * travel, np.degrees(vals[:, 0]), label=f"F_lat {f:+.0f} N")
    ax[1].plot(1000 * travel, np.degrees(vals[:, 1]))
ax[0].set(xlabel="travel [mm]", ylabel="toe [deg]")
ax[1].set(xlabel="travel [mm]", ylabel="camber [deg]")
ax[0].legend()
fig.tight_layout()

# %%
from diffsusp.tyre import onboard_joint

car_kc = vehicle.Vehicle(kinematics=tables, tyre=vehicle.MagicTyre())
data_kc = vehicle.measure(car_kc, sensors, vehicle.simulate(car_kc, duration=6.0),
                          jax.random.key(1), delay=0.0)
truth = onboard_joint.truth(car_kc)
joint = onboard_joint.identify(
    data_kc, mass=truth["mass"], delay=0.0, kinematics=car_kc.kinematics,
    tyre_vertical=(car_kc.tyre_stiffness, car_kc.tyre_radius, car_kc.tyre_damping))
print(joint.table())  # value, σ, status and why, the consistency verdict
print(f"true I_zz {truth['I_zz']:.0f} kg·m²")
