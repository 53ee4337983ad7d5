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
# # 09 — A fleet: many identifications on a Dask cluster
#
# One identification is one data set → one report. A Monte-Carlo study of the measurement
# noise, 100 axles off a production line or a design study is *many* of them, independent of
# each other: `diffsusp.fleet` runs one recipe (`direct`, `iterative`, `least_squares`) on
# every data set, in this process or on a Dask cluster, batches data sets of the same shape,
# streams every report to disk as it finishes, and skips on a re-run what is done.
#
# Here: noise draws of the pseudo-McPherson's landmark measurements (σ = 0.05 mm, the thesis's
# measuring arm), identified by the direct method, and the scatter of each estimate against the
# σ that each report gives (linearised, from the generalised least squares). A ratio above 1
# says the reported σ is optimistic: the landmark noise also enters the regressors (errors in
# variables), which the linear method's σ does not count.
#
# **Size.** The test suite executes this notebook, so it runs 40 draws on a local cluster of
# one worker thread (a worker shares this kernel's compiled programs). Set `N_DRAWS = 1000` and
# `WORKERS = 2` (processes) for the full study; `benchmarks/fleet.py` measures 1 000
# least-squares fits in-process and on two worker processes.

# %%
import jax

jax.config.update("jax_enable_x64", True)
import csv
import inspect
import json
import pathlib
import tempfile

import distributed
import equinox as eqx
import numpy as np

from diffsusp import fleet, identify, measure
from diffsusp.models import pseudo_mcpherson, thesis_load_cases

N_DRAWS = 40
WORKERS = None  # None: one worker thread in this kernel; 2: two worker processes

# %% [markdown]
# ## The data sets
#
# The thesis's 13 load cases, four landmarks per part, registered back to part poses
# (`measure.synthesize`); each draw adds independent Gaussian noise to every landmark coordinate
# and is written as the table a measuring arm would give (`measure.write_measurements`).

# %%
mech = pseudo_mcpherson()
exact = measure.synthesize(mech, thesis_load_cases(mech),
                           layout=measure.place_landmarks(mech, seed=0))
folder = pathlib.Path(tempfile.mkdtemp(prefix="fleet09-"))
draw = eqx.filter_jit(lambda key: measure.add_noise(  # one compiled program for every draw
    exact, measure.GaussianNoise(landmarks=0.05), key))
for seed in range(N_DRAWS):
    measure.write_measurements(draw(jax.random.PRNGKey(1000 + seed)),
                               folder / f"draw{seed:04d}.csv", mech)
print(f"{N_DRAWS} tables in {folder}, e.g. {sorted(folder.iterdir())[0].name}")

# %% [markdown]
# ## The fleet
#
# A Dask `LocalCluster` here; on an existing cluster, `distributed.Client("tcp://head:8786")`
# (or `fleet.run(..., scheduler="tcp://head:8786")`) instead — nothing else changes. The recipe's
# options are `identify.direct`'s: the undetermined unknowns held at the model's values and the
# weak ones eliminated, the recommended way for noisy data (notebook 02).

# %%
options = {"hold": "model", "eliminate": True}
if "polish" in inspect.signature(identify.direct).parameters:
    options["polish"] = False  # the linear method alone: its σ is the one studied here
out = folder / "fleet"
processes = WORKERS is not None
with distributed.LocalCluster(n_workers=WORKERS or 1, threads_per_worker=1,
                              processes=processes, dashboard_address=":0") as cluster, \
        distributed.Client(cluster) as client:
    result = fleet.run("direct", str(folder / "draw*.csv"), out, model=mech, options=options,
                       batch_size=25, client=client)
print(result.text())
print(fleet.status(out).text())

# %% [markdown]
# Every report is on disk as soon as its batch is done (`out/reports/draw0000.json`: the JSON
# of `diffsusp identify direct --out`), with a journal line; `summary.csv` has one row per data
# set. A second run finds everything done (same content hashes) and does nothing:

# %%
again = fleet.run("direct", str(folder / "draw*.csv"), out, model=mech, options=options,
                  batch_size=25)
print(f"re-run: {again.skipped} of {again.total} already done, {again.batches} batches run")

# %% [markdown]
# ## Scatter against the reported σ
#
# For the unknowns the data determine, the standard deviation of the estimates over the draws
# (the Monte-Carlo truth) against the root-mean-square of the σ each report gives. Agreement
# within the Monte-Carlo's own uncertainty (≈ 1/√(2N) relative: 11 % for 40 draws, 2 % for
# 1 000) says the reported σ can be trusted for one data set.

# %%
with open(out / "summary.csv", newline="") as f:
    rows = [r for r in csv.DictReader(f) if r["status"] == "ok"]
names = ("bushing_A.Ktx", "bushing_B.Ktx", "spring.K", "spring.KL0")
values = np.array([[float(r[n]) for n in names] for r in rows])
sigmas, identified = [], []
for r in rows:
    params = {p["parameter"]: p for p in
              json.loads((out / "reports" / f"{r['item']}.json").read_text())["parameters"]}
    sigmas.append([params[n]["sigma"] or np.nan for n in names])
    identified.append([params[n]["identified"] for n in names])
sigmas, identified = np.array(sigmas, float), np.array(identified)
true = np.array([mech_value for mech_value in
                 (params[n]["prior"] for n in names)])  # the model's values: the truth here
print(f"{len(rows)} draws identified")
print(f"{'unknown':<15} {'true':>9} {'mean':>9} {'MC std':>9} {'rms σ':>9} {'ratio':>6} "
      f"{'identified':>10}")
for k, name in enumerate(names):
    mc = values[:, k].std(ddof=1)
    rms = np.sqrt(np.nanmean(sigmas[:, k] ** 2))
    print(f"{name:<15} {true[k]:9.4g} {values[:, k].mean():9.4g} {mc:9.3g} {rms:9.3g} "
          f"{mc / rms:6.2f} {identified[:, k].mean():10.0%}")

# %%
import matplotlib.pyplot as plt

fig, axes = plt.subplots(1, len(names), figsize=(13, 3))
for k, (ax, name) in enumerate(zip(axes, names, strict=True)):
    rms = np.sqrt(np.nanmean(sigmas[:, k] ** 2))
    ax.hist(values[:, k], bins=15, density=True, alpha=0.6)
    grid = np.linspace(values[:, k].min(), values[:, k].max(), 200)
    mean = values[:, k].mean()
    ax.plot(grid, np.exp(-0.5 * ((grid - mean) / rms) ** 2) / (rms * np.sqrt(2 * np.pi)))
    ax.axvline(true[k], color="k", lw=0.8)
    ax.set_title(name, fontsize=9)
axes[0].set_ylabel("density (curve: the reported σ)")
fig.tight_layout()
fig

# %% [markdown]
# ## From the shell
#
# ```
# diffsusp fleet direct --items 'tables/*.csv' --out out/ --model pseudo_mcpherson \
#     --option hold=model --option eliminate=true --workers 2
# diffsusp fleet direct ... --scheduler tcp://head:8786     # an existing Dask cluster
# diffsusp fleet status out/
# ```
