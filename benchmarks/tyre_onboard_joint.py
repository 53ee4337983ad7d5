"""Monte-Carlo of the joint vehicle + tyre identification ((4-1)…(4-3), spec tyre §5.1,
`diffsusp.tyre.onboard_joint`) on the synthetic car with the 30-DOF K&C kinematics and a tyre the
reduced model was not written against (`vehicle.MagicTyre`): the noise-free record
(tests/data/onboard_kc_sine.npz, 6 s of steering-wheel sine) with N noise draws.

Per estimated vehicle parameter and tyre quantity (K_δ front and rear, K_φ, K_γ at the axles'
mean loads): the share of draws that report it identified (|x|/σ ≥ 3.29 and not hinging on the
held relaxation); against the noise-free record's own fit (what σ covers: the noise) the bias
and the spread over the mean σ and the share within 3σ; against the physical truth (the
MagicTyre's stiffnesses, the car's inertia) the same, the difference being the reduced model's
structure error, which σ does not cover. Run: python benchmarks/tyre_onboard_joint.py [N]"""

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
QUANTITIES = ("K_delta_front", "K_delta_rear", "K_phi", "K_gamma")
VEHICLE = ("I_zz", "I_xz", "m_x_G", "m_z_G")


def load():
    car = V.Vehicle(kinematics=K.load_tables(), tyre=V.MagicTyre())
    sens = V.Sensors()
    truth = V.load_channels(DATA, car, sens)
    return car, sens, truth


def reference(car, truth):
    """The true vehicle parameters and physical quantities (K_δ front and rear, K_φ, L_R, K_γ
    at the axles' mean loads)."""
    tr = J.truth(car)
    fz = np.asarray(truth["true_fz"]).mean(axis=0) / 1000.0
    loads = (float(fz[:2].mean()), float(fz[2:].mean()))
    kd, kp, kg, lr = (np.asarray(a) for a in car.tyre.stiffnesses(jnp.asarray(loads)))
    return tr, loads, np.array([kd[0], kd[1], kp[0], lr[0], kg[0]])


def summarise(rep, C):
    """The report's tyre quantities and vehicle parameters, their σ and whether identified."""
    rows = [0, 1, 2, 4]  # K_delta front, rear, K_phi, K_gamma (L_R held)
    q = (C @ rep.x[:8])[rows]
    qs = np.sqrt(np.einsum("ij,jk,ik->i", C, rep.covariance[:8, :8], C))[rows]
    shift = (C @ rep.relaxation_shift[:8])[rows]
    idx = [J.NAMES.index(v) for v in VEHICLE]
    ok = rep.converged and bool(rep.consistency.consistent)
    ident = np.concatenate([(np.abs(q) / qs >= 3.29) & (np.abs(shift) <= qs),
                            rep.is_identified[idx]]) & ok
    return (np.concatenate([q, rep.x[idx]]), np.concatenate([qs, rep.sigmas[idx]]), ident)


def stats(est, sig, ref):
    z = (est - ref) / sig
    return {"bias_over_sigma": float((est.mean() - ref) / sig.mean()),
            "spread_over_sigma": float(est.std(ddof=1) / sig.mean()),
            "within_3sigma": float(np.mean(np.abs(z) < 3))}


def run(n_draws, seed=0):
    car, sens, truth = load()
    tr, loads, exact = reference(car, truth)
    tv = (float(car.tyre_stiffness), float(car.tyre_radius), float(car.tyre_damping))
    C = O.quantities(loads)
    clean = {k: truth[k] for k in O.CHANNELS}
    ref_fit, _, _ = summarise(J.identify(clean, mass=tr["mass"], tyre_vertical=tv, delay=0.0,
                                         kinematics=car.kinematics), C)
    phys = np.concatenate([exact[[0, 1, 2, 4]], [tr[v] for v in VEHICLE]])
    est, sig, ident, cpu, ok = [], [], [], [], []
    for key in jax.random.split(jax.random.key(seed), n_draws):
        data = V.add_noise(clean, sens, key)
        t0 = time.process_time()
        rep = J.identify(data, mass=tr["mass"], tyre_vertical=tv, delay=0.0,
                         kinematics=car.kinematics)
        cpu.append(time.process_time() - t0)
        ok.append(rep.converged and bool(rep.consistency.consistent))
        e, s, i = summarise(rep, C)
        est.append(e)
        sig.append(s)
        ident.append(i)
    est, sig, ident = np.array(est), np.array(sig), np.array(ident)
    out = {"draws": n_draws, "converged_and_consistent": float(np.mean(ok)),
           "held": {k: v for k, v in J.DEFAULT_HELD.items()},
           "cpu_first_s": cpu[0],
           "cpu_median_s": float(np.median(cpu[1:])) if n_draws > 1 else None}
    bar = 3.0 / np.sqrt(n_draws)
    for k, name in enumerate(QUANTITIES + VEHICLE):
        noise = stats(est[:, k], sig[:, k], ref_fit[k])
        truth_ = stats(est[:, k], sig[:, k], phys[k])
        out[name] = {"truth": float(phys[k]), "noise_free_fit": float(ref_fit[k]),
                     "mean": float(est[:, k].mean()), "mean_sigma": float(sig[:, k].mean()),
                     "identified": float(ident[:, k].mean()),
                     "against_noise_free_fit": noise, "against_truth": truth_,
                     "noise_bar_met": bool(noise["within_3sigma"] >= 0.97
                                           and 0.67 <= noise["spread_over_sigma"] <= 1.5
                                           and abs(noise["bias_over_sigma"]) < bar),
                     "truth_bar_met": bool(truth_["within_3sigma"] >= 0.97
                                           and 0.67 <= truth_["spread_over_sigma"] <= 1.5
                                           and abs(truth_["bias_over_sigma"]) < bar)}
    return out


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 100
    res = run(n)
    print(json.dumps(res, indent=1))
    (RESULTS / "tyre_onboard_joint.json").write_text(json.dumps(res, indent=1) + "\n")
