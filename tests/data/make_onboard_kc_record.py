"""Write tests/data/onboard_kc_sine.npz: the noise-free sensor channels (float32) of the
synthetic car with the 30-DOF K&C kinematics (the shipped pseudo-McPherson tables) and the
Magic-Formula-like tyre (`vehicle.MagicTyre`), 6 s of steering-wheel sine at 1 kHz. Run from the
repository root: `python tests/data/make_onboard_kc_record.py`."""

import pathlib

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

from diffsusp.tyre import onboard, vehicle, vehicle_kc  # noqa: E402

car = vehicle.Vehicle(kinematics=vehicle_kc.load_tables(), tyre=vehicle.MagicTyre())
sensors = vehicle.Sensors()
truth = vehicle.channels(car, sensors, vehicle.simulate(car, duration=6.0))
per_sample = [k for k in onboard.PER_SAMPLE if k in truth and k != "time"] + ["true_fz"]
np.savez_compressed(pathlib.Path(__file__).parent / "onboard_kc_sine.npz",
                    t0=float(truth["time"][0]), rate=1000.0,
                    **{k: np.asarray(truth[k], np.float32) for k in per_sample})
