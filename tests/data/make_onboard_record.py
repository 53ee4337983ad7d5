"""Writes onboard_sine.npz: the noise-free sensor channels of the synthetic 12-DOF car
(`diffsusp.tyre.vehicle`, default Vehicle and Sensors) driving a 6 s steering-wheel sine
0.2 → 6 Hz at 25 m/s, 1 kHz, in float32 (every channel's rounding is below 1e-4 of its sensor's
noise σ). tests/test_tyre_onboard.py adds the noise; shipping the record spares each test run
the simulation's compilation (≈ 13 s of CPU); notebook 08 runs the simulation itself and checks
it against this file. Run from the repository root: python tests/data/make_onboard_record.py"""

import pathlib

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

from diffsusp.tyre import vehicle as V  # noqa: E402

DURATION = 6.0
PATH = pathlib.Path(__file__).parent / "onboard_sine.npz"
KEEP = ("lasers", "correvit", "imu_omega", "imu_velocity", "imu_specific_force", "travel",
        "steer", "spin", "wrench", "true_fz")


def record():
    veh, sens = V.Vehicle(), V.Sensors()
    return V.channels(veh, sens, V.simulate(veh, duration=DURATION))


def main():
    truth = record()
    t = np.asarray(truth["time"])
    np.savez_compressed(PATH, t0=t[0], rate=1.0 / (t[1] - t[0]),
                        **{k: np.asarray(truth[k], np.float32) for k in KEEP})


if __name__ == "__main__":
    main()
