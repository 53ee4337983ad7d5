"""A batch split over several devices gives the single-device result (issue: both cores, and
many devices). JAX fixes the number of CPU devices when it starts, so the check runs in a fresh
interpreter with two host devices; a small model keeps its compilation short."""

import json
import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent("""
    import json
    import jax
    jax.config.update("jax_num_cpu_devices", 2)
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import diffsusp as ds

    b = ds.MechanismBuilder("ball mount")
    b.part("link")
    b.joint("ball", "spherical", parts=("link", "ground"), at=(0, 0, 0))
    b.bushing("bush", parts=("link", "ground"), at=(120, 40, -10), reuler_deg=(30, 20, 10),
              k_trans=(1000, 2000, 300), k_rot=np.array([4000, 1500, 800]) * 180 / np.pi)
    b.marker("tip", "link", (250, 30, 20))
    b.load_point("load", marker="tip")
    mech = b.build()
    force = np.random.default_rng(0).normal(size=(7, 3)) * 300.0  # 7: one device gets a pad
    loads = mech.loads(forces={"load": force})
    one = ds.solve_statics(mech, loads)
    two = ds.solve_statics(mech, loads, devices=2)
    ds.statics.use_devices("all")
    default = ds.solve_statics(mech, loads)
    print(json.dumps(dict(
        devices=len(jax.devices()),
        shards=len(two.q.sharding.device_set),
        q=float(np.max(np.abs(np.asarray(one.q) - np.asarray(two.q)))),
        default=float(np.max(np.abs(np.asarray(one.q) - np.asarray(default.q)))),
        status=np.asarray(two.status).tolist(), shape=list(two.q.shape),
    )))
""")


def test_batch_split_over_two_devices_equals_one_device():
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True,
                         timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    res = json.loads(out.stdout.strip().splitlines()[-1])
    assert res["devices"] == 2
    assert res["shards"] == 2  # the result really lives on both devices
    assert res["shape"] == [7, 6]
    assert res["status"] == [0] * 7
    assert res["q"] < 1e-12 and res["default"] < 1e-12
