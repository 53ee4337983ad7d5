"""Monte-Carlo of the joint vehicle + tyre identification ((4-1)…(4-3), spec tyre §5.1,
`diffsusp.tyre.onboard_joint`) on the synthetic car with the 30-DOF K&C kinematics and a tyre the
reduced model was not written against (`vehicle.MagicTyre`): the noise-free record
(tests/data/onboard_kc_sine.npz, 6 s of steering-wheel sine) with N noise draws; per estimated
parameter and physical quantity, the mean error over the mean σ (bias), the spread over the mean
σ, and the share of draws within 3σ. Run: python benchmarks/tyre_onboard_joint.py [N]"""

import json
import pathlib
import sys
import time

import jax
from _common import RESULTS

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from diffsusp.tyre import onboard as O  # noqa: E402
from diffsusp.tyre import onboard_joint as J  # noqa: E402
from diffsusp.tyre import vehicle as V  # noqa: E402
from diffsusp.tyre import vehicle_kc as K  # noqa: E402

DATA = pathlib.Path(__file__).parents[1] / "tests" / "data" / "onboard_kc_sine.npz"


def load():
    car = V.Vehicle(kinematics=K.load_tables(), tyre=V.MagicTyre())
    sens = V.Sensors()
    with np.load(DATA) as z:
        truth = {k: jnp.asarray(z[k], float) for k in z.files if k not in ("t0", "rate")}
        n = z["lasers"].shape[0]
        truth["time"] = jnp.asarray(float(z["t0"]) + np.arange(n) / float(z["rate"]))
    truth.update(laser_positions=sens.lasers, correvit_position=sens.correvit,
                 imu_position=sens.imu, corners=car.corners, rolling_radius=car.rolling_radius)
    return car, sens, truth


def reference(car, truth):
    """The true vehicle parameters and physical quantities (K_δ front and rear, K_φ, L_R, K_γ
    at the axles' mean loads)."""
    tr = J.truth(car)
    fz = np.asarray(truth["true_fz"]).mean(axis=0) / 1000.0
    loads = (float(fz[:2].mean()), float(fz[2:].mean()))
    kd, kp, kg, lr = (np.asarray(a) for a in car.tyre.stiffnesses(jnp.asarray(loads)))
    return tr, loads, np.array([kd[0], kd[1], kp[0], lr[0], kg[0]])


def run(n_draws, seed=0):
    car, sens, truth = load()
    tr, loads, exact = reference(car, truth)
    tv = (float(car.tyre_stiffness), float(car.tyre_radius), float(car.tyre_damping))
    C = O.quantities(loads)
    names = list(O.QUANTITIES) + [v for v in J.VEHICLE if v not in J.DEFAULT_HELD]
    ref = np.concatenate([exact, [tr[v] for v in names[5:]]])
    est, sig, cpu = [], [], []
    keys = jax.random.split(jax.random.key(seed), n_draws)
    for key in keys:
        data = V.add_noise({k: truth[k] for k in O.CHANNELS}, sens, key)
        t0 = time.process_time()
        rep = J.identify(data, mass=tr["mass"], tyre_vertical=tv, delay=0.0,
                         kinematics=car.kinematics)
        cpu.append(time.process_time() - t0)
        cov = rep.covariance
        q = C @ rep.x[:8]
        qs = np.sqrt(np.einsum("ij,jk,ik->i", C, cov[:8, :8], C))
        idx = [J.NAMES.index(v) for v in names[5:]]
        est.append(np.concatenate([q, rep.x[idx]]))
        sig.append(np.concatenate([qs, rep.sigmas[idx]]))
    est, sig = np.array(est), np.array(sig)
    z = (est - ref) / sig
    out = {"draws": n_draws, "cpu_first_s": cpu[0],
           "cpu_median_s": float(np.median(cpu[1:])) if n_draws > 1 else None}
    for k, name in enumerate(names):
        out[name] = {"truth": float(ref[k]), "mean": float(est[:, k].mean()),
                     "bias_over_sigma": float((est[:, k].mean() - ref[k]) / sig[:, k].mean()),
                     "spread_over_sigma": float(est[:, k].std(ddof=1) / sig[:, k].mean()),
                     "within_3sigma": float(np.mean(np.abs(z[:, k]) < 3))}
    return out


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 40
    res = run(n)
    print(json.dumps(res, indent=1))
    (RESULTS / "tyre_onboard_joint.json").write_text(json.dumps(res, indent=1))
