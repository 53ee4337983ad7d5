"""Benchmark of the on-board tyre identification (spec tyre §5.3–5.5): the pipeline over the
thesis's 60 s steering-wheel sine at 1 kHz (ground plane, body twist, tyre inputs of 4 wheels, delay
estimate, both half-rate records, pooled instrumental-variable regression), after
compilation; and a plain NumPy per-instant baseline of the
body-twist step for the ratio. Run: python benchmarks/tyre_onboard.py"""

import json
import os
import platform
import time

import jax  # noqa: E402
from _common import RESULTS, samples  # noqa: E402

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from diffsusp.tyre import onboard as O  # noqa: E402
from diffsusp.tyre import vehicle as V  # noqa: E402


def main():
    veh, sens = V.Vehicle(), V.Sensors()
    t0 = time.process_time()
    rec = jax.block_until_ready(V.simulate(veh, duration=60.0))
    sim_cpu = time.process_time() - t0
    truth = V.channels(veh, sens, rec)
    data = dict(V.add_noise(truth, sens, jax.random.key(0), delay=0.1))
    data = O.check({k: data[k] for k in O.CHANNELS})
    opts = O.Options()
    half, dt = 25, 1e-3
    kernels = O._kernels(opts.window, 2 * half + 1, dt)

    @jax.jit
    def pipeline(d):
        normal, R = O.ground_plane(d["lasers"], d["laser_positions"], d["laser_window_ok"],
                                   kernels[0])
        delay = O.correvit_delay(d, normal, R, kernels, dt=dt)
        sig, ok = O.split_signals(d, opts, half=12, dt=2 * dt, correvit_delay_s=delay)
        (W_e, y_e), (W_o, y_o) = (O.regressor({k: v[h] for k, v in sig.items()},
                                              np.arange(4)) for h in (0, 1))
        return O.iv_solve(W_e, y_e, W_o, y_o, jnp.repeat(ok, 4), 4)[0], delay

    t0 = time.process_time()
    jax.block_until_ready(pipeline(data))
    compile_cpu = time.process_time() - t0
    wall, cpu, (x, delay) = samples(lambda: pipeline(data), 5)

    # NumPy baseline: the per-instant weighted LS of the body twist alone (4-12, 4-13)
    d = {k: np.asarray(v) for k, v in data.items()}
    n = len(d["time"])
    C0 = d["imu_position"]
    t1 = time.perf_counter()
    for t in range(0, n, 10):  # a tenth of the instants, scaled below
        rows = np.vstack([np.hstack([np.eye(3), -_skew(C0)]), np.hstack([np.zeros((3, 3)),
                                                                          np.eye(3)])])
        y = np.concatenate([d["imu_velocity"][t], d["imu_omega"][t]])
        np.linalg.lstsq(rows, y, rcond=None)
    numpy_twist = (time.perf_counter() - t1) * 10
    out = {"record_s": 60.0, "rate_hz": 1000, "simulate_cpu_s": sim_cpu,
           "pipeline_compile_cpu_s": compile_cpu, "pipeline_wall_s": wall,
           "pipeline_cpu_s": cpu, "delay_estimate_s": float(delay),
           "numpy_twist_only_wall_s": numpy_twist,
           "load": os.getloadavg(), "machine": platform.machine()}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "tyre_onboard.json").write_text(json.dumps(out, indent=2))
    print(json.dumps(out, indent=2))


def _skew(a):
    return np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])


if __name__ == "__main__":
    main()
