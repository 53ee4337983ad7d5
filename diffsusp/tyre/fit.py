"""Magic Formula coefficients from bench data: a staged robust Levenberg–Marquardt with exact
Jacobians, from a start file of either sign convention, with a verdict per coefficient.

spec: tyre §7 E item 22 (nonlinear least-squares refinement), §7 D item 18 (the report of the
guaranteed least squares), tyre §7 C (the coefficients' roles and constraints). The report is an
`diffsusp.identify.report.IdentificationReport`: per coefficient value, σ, σ % and one status
(identified / not determined with its reason / held / not seen), per fit a consistency verdict.

```python
data = tyre.fit.read_bench("bench.csv")                        # FZ, SA, IA, ..., FY [N], ...
fitted, report = tyre.fit.fit(start, data, tir=start_tir)      # default groups, noise estimated
print(report.table()); write_tir(fitted.to_tir(start_tir), "fitted.tir")
```

**Start.** Any sign of a start coefficient: the peak frictions, shape factors and stiffness
scales (`SIGNED_LOG`) are fitted as x = x₀·exp(u) — magnitude free, sign kept (the PAC2002
convention writes PDY1, PKY1 < 0) — the others as x = x₀ + s·u, s = max(|x₀|, 0.1). The
coefficients the start file does not use (0, or absent from its .tir) are held (`default_hold`).
Starting values of the scale coefficients come from the data (`fit_start.data_start`: peak,
slope at the origin and trail per load, as the fitting tools of the trade do), then the staged
strategy (`fit`): per channel the zero-camber coefficients on the zero-camber sweeps, the camber
ones, the channel's all, then everything jointly; a second start and two ridge probes look for
an equally good optimum elsewhere. The fit's validity ranges become the data's (`with_ranges`);
during the fit no input is saturated (a measured tyre saturates nothing; FNOMIN is held, so a
start at another nominal load gives the truth in that normalisation: `fit_start.renormalise`).

**Residuals.** z = (model − measured)/σᵢ with the noise model σᵢ = a + b·|Fᵢ| per channel
(given, or estimated from the sweeps' third differences: `fit_start.estimate_noise`), through
the robust loss as r = sgn(z)·√(2ρ(z)): Huber ρ = z²/2 (|z| ≤ k), k|z| − k²/2 beyond; Cauchy
ρ = (k²/2)·log(1 + (z/k)²); "linear" the plain sum of squares. `optimistix.LevenbergMarquardt`
minimises Σr², the Jacobian by forward-mode autodiff.

**Report.** σ from the M-estimator's sandwich covariance on the whitened residuals (robust to a
misjudged noise shape and to outliers; HC3: each point's score over (1 − leverage)², the
small-sample correction), over the inliers (points beyond 5σ of the robust fit left out);
identifiability and the identifiable combinations from `diffsusp.lsq` on the linearisation;
*determined* = identifiable, σ % ≤ `MAX_SIGMA_PCT`, no equally good optimum 3σ away, and no
curvature factor clipped at 1 in the data's range leaning on it (noisy data). The consistency
verdict compares the inlier residuals with the data-only noise estimate (F law): a fit far above
the noise "does not fit the data" and calls nothing identified. Constraint checks over the data's
range (C > 0, |μ| > 0 without a change of sign, E ≤ 1) in `report.violations`.
"""

import dataclasses
import json
import math
import os
import warnings
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .. import lsq
from ..errors import InputError, ModelFileError, ModelWarning
from ..identify.report import (
    CONSISTENCY_ALPHA,
    Consistency,
    IdentificationReport,
    MeasurementResiduals,
    chi2_quantile,
)
from ..io.tables import Table, read_table, split_header, unit_factor
from ..lsq import LOSSES, robust
from . import fit_start, mf6
from .fit_start import noise_sigma

__all__ = ["BenchData", "TyreFitReport", "bench_data", "default_groups", "default_names",
           "default_hold", "read_bench", "read_bench_table", "input_columns", "simulate",
           "bench_programme", "with_ranges", "fit", "fit_many", "FitRehearsal", "GROUPS",
           "POSITIVE", "SIGNED_LOG", "CAMBER", "MAX_SIGMA_PCT", "CHANNELS", "COLUMN_ALIASES",
           "check_constraints", "plot_fit", "fit_groups", "model_bench_data", "group_params",
           "check_varies", "MF1989_START"]

CHANNELS = ("FX", "FY", "MX", "MY", "MZ")
"""Measured channels: forces [N], moments [N·mm] (library units)."""
POSITIVE = frozenset({"PCX1", "PCY1", "QCZ1", "RCX1", "RCY1", "PDX1", "PDY1"})

GROUPS = {
    "pure_longitudinal": ("PCX1 PDX1 PDX2 PDX3 PEX1 PEX2 PEX3 PEX4 PKX1 PKX2 PKX3 PHX1 PHX2 "
                          "PVX1 PVX2").split(),
    "pure_lateral": ("PCY1 PDY1 PDY2 PDY3 PEY1 PEY2 PEY3 PEY4 PEY5 PKY1 PKY2 PKY3 PKY4 PKY5 "
                     "PKY6 PKY7 PHY1 PHY2 PHY3 PVY1 PVY2 PVY3 PVY4").split(),
    "pure_aligning": ("QBZ1 QBZ2 QBZ3 QBZ4 QBZ5 QBZ9 QBZ10 QCZ1 QDZ1 QDZ2 QDZ3 QDZ4 QDZ6 QDZ7 "
                      "QDZ8 QDZ9 QDZ10 QDZ11 QEZ1 QEZ2 QEZ3 QEZ4 QEZ5 QHZ1 QHZ2 QHZ3 QHZ4").split(),
    "combined_longitudinal": "RBX1 RBX2 RBX3 RCX1 REX1 REX2 RHX1".split(),
    "combined_lateral": ("RBY1 RBY2 RBY3 RBY4 RCY1 REY1 REY2 RHY1 RHY2 RVY1 RVY2 RVY3 RVY4 RVY5 "
                         "RVY6").split(),
    "pressure": "PPX1 PPX2 PPX3 PPX4 PPY1 PPY2 PPY3 PPY4 PPY5 PPZ1 PPZ2".split(),
    "overturning": "QSX1 QSX2 QSX3 QSX4 QSX5 QSX6 QSX7 QSX8 QSX9 QSX10 QSX11 QSX12 QSX13 QSX14"
                   .split(),
    "mf1989_lateral": "a0 a1 a2 a3 a4 a5 a6 a7 a8 a9 a10 a111 a112 a12 a13".split(),
    "mf1989_aligning": [f"c{i}" for i in range(18)],
    "mf1989_longitudinal": [f"b{i}" for i in range(13)],
}
"""Coefficient groups for fitting mode by mode (MF 6.x names, and the 1989 set)."""

COLUMN_ALIASES = {
    "FZ": "FZ", "FZW": "FZ", "LOAD": "FZ", "NFZ": "FZ", "FZ_N": "FZ",
    "SA": "SA", "ALPHA": "SA", "SLIP_ANGLE": "SA", "SLIPANGLE": "SA",
    "SL": "SL", "KAPPA": "SL", "SR": "SL", "SLIP_RATIO": "SL", "LONGSLIP": "SL",
    "IA": "IA", "GAMMA": "IA", "CAMBER": "IA", "INCLINATION": "IA",
    "P": "P", "PRESSURE": "P", "INFLATION_PRESSURE": "P",
    "VX": "VX", "V": "VX", "SPEED": "VX", "VELOCITY": "VX",
    "FX": "FX", "FXW": "FX", "FY": "FY", "FYW": "FY", "MX": "MX", "MXW": "MX", "MY": "MY",
    "MYW": "MY", "MZ": "MZ", "MZW": "MZ",
}
"""Common bench channel names (TTC, TYDEX-like, MFeval) → the canonical column (case-insensitive
match)."""

_DEFAULT_UNITS = {"FZ": "N", "SA": "rad", "SL": "-", "IA": "rad", "P": "Pa", "VX": "m/s",
                  "FX": "N", "FY": "N", "MX": "N·m", "MY": "N·m", "MZ": "N·m"}
_PRESSURE = {"Pa": 1.0, "kPa": 1e3, "MPa": 1e6, "bar": 1e5, "psi": 6894.757293168}
_SPEED = {"m/s": 1e3, "mm/s": 1.0, "km/h": 1e6 / 3600.0, "kph": 1e6 / 3600.0,
          "mph": 1609.344e3 / 3600.0}


class BenchData(eqx.Module):
    """Bench measurements in library units, one row per point.

    **Fields:** inputs `fz` [N], `kappa` [-], `alpha` [rad], `gamma` [rad], `vx` [mm/s],
    `pressure` [Pa]; `measured` (c, n) in [N] / [N·mm] for the static `channels`; `valid`
    (c, n) bool (False: NaN or excluded).
    """

    fz: jax.Array
    kappa: jax.Array
    alpha: jax.Array
    gamma: jax.Array
    vx: jax.Array
    pressure: jax.Array
    measured: jax.Array
    valid: jax.Array
    channels: tuple[str, ...] = eqx.field(static=True)

    @property
    def n(self) -> int:
        return int(self.fz.shape[-1])

    def channel(self, name: str) -> jax.Array:
        return self.measured[self.channels.index(name)]


def unit_scale(col: str, unit: str | None, path) -> float:
    unit = unit if unit is not None else _DEFAULT_UNITS[col]
    try:
        if col == "P":
            return _PRESSURE[unit]
        if col == "VX":
            return _SPEED[unit]
        dim = {"FZ": "force", "FX": "force", "FY": "force", "SA": "angle", "IA": "angle",
               "SL": "dimensionless", "MX": "moment", "MY": "moment", "MZ": "moment"}[col]
        return unit_factor(unit, dim)
    except (KeyError, ValueError):
        known = {"P": list(_PRESSURE), "VX": list(_SPEED)}.get(col, "a unit of the right kind")
        raise InputError(f"{path or '<table>'}: column {col} has unit [{unit}]; expected "
                         f"{known}") from None


def bench_data(table, *, channels=None, mapping: dict | None = None, defaults: dict | None = None
               ) -> BenchData:
    """Bench data from a `diffsusp.io.Table` (CSV/Parquet with units in the header, e.g.
    `FZ [N], SA [deg], SL [-], IA [deg], P [kPa], VX [km/h], FY [N], MZ [N·m]`).

    Column names are matched case-insensitively through `COLUMN_ALIASES` and `mapping` (your
    name → canonical). Columns without a unit are in the issue's table convention: FZ [N],
    SL [-], SA, IA [rad], P [Pa], VX [m/s], forces [N], moments [N·m]. Missing inputs take
    `defaults` (library units: SL, SA, IA = 0; P and VX must then be given to the model's
    evaluation, so they default to NaN = "the model's INFLPRES / LONGVL"); a missing measured
    channel among `channels` is an error. Rows with a NaN input are excluded from every channel,
    a NaN measurement from its channel only: each exclusion is warned (`ModelWarning`) with the
    file and line of the first rows.
    """
    path = getattr(table, "path", None)
    canon = {}
    user = {k.upper(): v.upper() for k, v in (mapping or {}).items()}
    for name in table.names:
        key = name.upper()
        c = user.get(key) or COLUMN_ALIASES.get(key)
        if c is not None:
            if c in canon:
                raise InputError(f"{path or '<table>'}: columns {canon[c]!r} and {name!r} both "
                                 f"map to {c}; drop one or pass mapping=")
            canon[c] = name
    if channels is None:
        channels = tuple(c for c in CHANNELS if c in canon)
    channels = tuple(c.upper() for c in channels)
    if "FZ" not in canon:
        raise InputError(f"{path or '<table>'}: no vertical load column (FZ); columns are "
                         f"{', '.join(table.names)}")
    missing = [c for c in channels if c not in canon]
    if missing or not channels:
        raise InputError(f"{path or '<table>'}: measured channel(s) "
                         f"{', '.join(missing) or '(none)'} missing; columns are "
                         f"{', '.join(table.names)} (FX, FY, MZ, MX, MY with units in brackets)")
    n = table.n_rows
    defaults = {"SL": 0.0, "SA": 0.0, "IA": 0.0, "P": math.nan, "VX": math.nan,
                **(defaults or {})}

    def column(c):
        if c not in canon:
            return np.full(n, defaults[c], dtype=float)
        return np.asarray(table[canon[c]], dtype=float) * unit_scale(
            c, table.units.get(canon[c]), path)

    inputs = {c: column(c) for c in ("FZ", "SL", "SA", "IA", "P", "VX")}
    measured = np.stack([column(c) for c in channels])
    bad_in = np.zeros(n, bool)
    for c in ("FZ", "SL", "SA", "IA"):
        bad_in |= ~np.isfinite(inputs[c])
    for c in ("P", "VX"):
        if c in canon:
            bad_in |= ~np.isfinite(inputs[c])
    valid = np.isfinite(measured) & ~bad_in[None, :]
    for k, c in enumerate(channels):
        rows = np.flatnonzero(~valid[k])
        if rows.size:
            where = ", ".join(table.where(int(r))[0] for r in rows[:3])
            warnings.warn(f"{path or '<table>'}: {rows.size} row(s) excluded from {c} (NaN in "
                          f"an input or in {c}): {where}{' ...' if rows.size > 3 else ''}",
                          ModelWarning, stacklevel=2)
    if not valid.any():
        raise InputError(f"{path or '<table>'}: no valid row to fit")
    meas = np.where(valid, measured, 0.0)
    clean = {c: np.where(np.isfinite(v), v, 0.0 if c in ("SL", "SA", "IA", "FZ") else v)
             for c, v in inputs.items()}
    return BenchData(*(jnp.asarray(clean[c]) for c in ("FZ", "SL", "SA", "IA", "VX", "P")),
                     jnp.asarray(meas), jnp.asarray(valid), channels)


def read_bench_table(path):
    """A `diffsusp.io.Table` of a bench CSV or Parquet file, units as written.

    CSV is read here rather than by `diffsusp.io.read_table` because the pressure and speed
    units (kPa, bar, psi, km/h, m/s) are not table units of the library: one header row
    `NAME [unit]`, comma separated, `#` comment lines and blank lines skipped, numbers as
    Python's float reads them (`nan` allowed: an explicit exclusion); anything else is an error
    naming the file, the line and the column. Parquet goes through `read_table` (P in Pa and VX
    in m/s without unit metadata)."""
    path = os.fspath(path)
    if not path.lower().endswith(".csv"):
        return read_table(path)
    try:
        with open(path, encoding="utf-8-sig") as f:
            lines = f.read().splitlines()
    except OSError as e:
        raise ModelFileError(f"cannot read the file: {e.strerror}", path=path) from None
    header, rows, numbers = None, [], []
    for i, line in enumerate(lines, start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        cells = [c.strip() for c in line.split(",")]
        if header is None:
            header = (i, [split_header(c) for c in cells])
            continue
        if len(cells) != len(header[1]):
            raise ModelFileError(f"{len(cells)} cells, the header has {len(header[1])}",
                                 path=path, line=i)
        vals = []
        for cell, (name, _) in zip(cells, header[1], strict=True):
            try:
                vals.append(float(cell))
            except ValueError:
                raise ModelFileError(f"{cell!r} is not a number", path=path, line=i,
                                     field=name) from None
        rows.append(i)
        numbers.append(vals)
    if header is None or not rows:
        raise ModelFileError("no header and data rows", path=path)
    arr = np.array(numbers, dtype=float).reshape(len(rows), len(header[1]))
    names = [n for n, _ in header[1]]
    if len(set(names)) != len(names):
        raise ModelFileError("duplicate column names", path=path, line=header[0])
    return Table({n: arr[:, k] for k, n in enumerate(names)}, dict(header[1]), path,
                 tuple(rows), header[0])


def model_bench_data(model, table) -> tuple[BenchData, list[str]]:
    """Bench data of `table` (`bench_data`) for what `model` evaluates: the measured channels
    the model has no output for (`AbstractTyre.channels`: MX, MY for the 1989 set) are left
    out and returned, as long as another channel remains (else every channel is kept, and
    the fit names the missing output). Returns (the data, the channels left out)."""
    present = [ch for ch in CHANNELS
               if any(COLUMN_ALIASES.get(n.upper()) == ch for n in table.names)]
    left = [ch for ch in present if ch not in model.channels]
    if left and len(left) < len(present):
        return bench_data(table, channels=[ch for ch in present if ch in model.channels]), left
    return bench_data(table), []


def read_bench(path, *, channels=None, mapping: dict | None = None,
               defaults: dict | None = None) -> BenchData:
    """Bench data from a CSV or Parquet file (`read_bench_table`, then `bench_data`)."""
    return bench_data(read_bench_table(path), channels=channels, mapping=mapping,
                      defaults=defaults)


def input_columns(table) -> dict[str, np.ndarray]:
    """The input columns of a table in library units (FZ N, SL -, SA and IA rad, P Pa, VX mm/s;
    missing SL/SA/IA = 0, missing P and VX = NaN: the model's INFLPRES and LONGVL). A NaN input
    is an error naming the file and line (evaluation, unlike fitting, excludes nothing)."""
    path = getattr(table, "path", None)
    cols = {}
    for name in table.names:
        c = COLUMN_ALIASES.get(name.upper())
        if c in ("FZ", "SL", "SA", "IA", "P", "VX"):
            cols[c] = np.asarray(table[name], float) * unit_scale(c, table.units.get(name),
                                                                   path)
    if "FZ" not in cols:
        raise InputError(f"{path or '<table>'}: no FZ column; columns are "
                         f"{', '.join(table.names)}")
    n = len(cols["FZ"])
    for c in ("SL", "SA", "IA"):
        cols.setdefault(c, np.zeros(n))
    for c in ("P", "VX"):
        cols.setdefault(c, np.full(n, np.nan))
    bad = np.zeros(n, bool)
    for c in ("FZ", "SL", "SA", "IA"):
        bad |= ~np.isfinite(cols[c])
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InputError(f"{path or '<table>'}: {table.where(i)[0]}: NaN input "
                         f"({int(bad.sum())} row(s))")
    return cols


def _predict(model, data: BenchData, combined: bool) -> jax.Array:
    """(c, n) model outputs for the data's channels, library units."""
    d = model.forces(data.fz, data.kappa, data.alpha, data.gamma, data.vx, data.pressure,
                     combined=combined, channels=data.channels)
    try:
        return jnp.stack([jnp.broadcast_to(d[c], data.fz.shape) for c in data.channels])
    except KeyError as e:
        raise InputError(f"channel {e.args[0]} is not an output of {type(model).__name__}"
                         ) from None


def _noise_pair(value) -> tuple[float, float]:
    """(a, b) of σ = a + b·|F| from a float σ or an (a, b) pair."""
    if isinstance(value, tuple | list | np.ndarray):
        a, b = (float(v) for v in value)
    else:
        a, b = float(value), 0.0
    if not (a >= 0 and b >= 0 and a + b > 0 and math.isfinite(a + b)):
        raise InputError(f"noise {value!r}: σ = a + b·|F| needs a ≥ 0, b ≥ 0, not both 0")
    return a, b


def simulate(model, data: BenchData, *, noise: dict | None = None, seed: int = 0,
             combined: bool = True, outliers: float = 0.0) -> BenchData:
    """The data's inputs with the model's outputs as measurements, plus Gaussian noise:
    `noise[channel]` a σ or an (a, b) pair for σ = a + b·|F| (channel units: N, N·mm), and a
    fraction `outliers` of gross spikes (30–60 σ of the point, either sign). For tests,
    examples, benchmarks and rehearsals."""
    y = np.array(_predict(model, data, combined))
    rng = np.random.default_rng(seed)
    for k, c in enumerate(data.channels):
        if c not in (noise or {}):
            continue
        a, b = _noise_pair(noise[c])
        s = a + b * np.abs(y[k])
        y[k] = y[k] + s * rng.standard_normal(y.shape[1])
        if outliers > 0:
            bad = rng.choice(y.shape[1], size=int(round(outliers * y.shape[1])), replace=False)
            y[k, bad] += rng.choice([-1.0, 1.0], bad.size) * rng.uniform(30, 60, bad.size) * s[bad]
    return BenchData(data.fz, data.kappa, data.alpha, data.gamma, data.vx, data.pressure,
                     jnp.asarray(y), jnp.ones(y.shape, bool), data.channels)


def bench_programme(model, *, loads=None, cambers=None, n_slip: int = 31,
                    channels=("FX", "FY", "MZ"), kappa_range=(-0.3, 0.3)) -> BenchData:
    """A steady-state bench programme over a property file's ranges (inputs only; fill the
    measurements with `simulate`). Per load: lateral sweeps α ∈ [ALPMIN, ALPMAX] (κ = 0) at
    each camber, and a longitudinal sweep κ within [KPUMIN, KPUMAX] ∩ `kappa_range` at γ = 0,
    `n_slip` points each; every channel measured on every row. Defaults: four loads over
    [FZMIN, FZMAX] (FNOMIN/2 … 1.5·FNOMIN when the file has no range), cambers 0, ±CAMMAX/2,
    ±CAMMAX (±0.1 rad without a range). The files' ranges are those their fitters measured."""
    lim = model.limit
    fnom = model.nominal_load

    def rng(lo, hi, dlo, dhi):
        lo = lim.get(lo, -math.inf)
        hi = lim.get(hi, math.inf)
        return (lo if math.isfinite(lo) else dlo), (hi if math.isfinite(hi) else dhi)

    if loads is None:
        lo, hi = rng("FZMIN", "FZMAX", 0.5 * fnom, 1.5 * fnom)
        lo = lo if lo > 0 else 0.5 * fnom
        loads = np.linspace(lo, hi, 4)
    if cambers is None:
        clo, chi = rng("CAMMIN", "CAMMAX", -0.1, 0.1)
        cambers = sorted({0.0, clo, 0.5 * clo, 0.5 * chi, chi})
    alo, ahi = rng("ALPMIN", "ALPMAX", -0.25, 0.25)
    klo, khi = rng("KPUMIN", "KPUMAX", *kappa_range)
    klo, khi = max(klo, kappa_range[0]), min(khi, kappa_range[1])
    sa = np.linspace(alo, ahi, n_slip)
    kp = np.linspace(klo, khi, n_slip)
    rows = []
    for fz in loads:
        for g in cambers:
            rows += [(fz, 0.0, a, g) for a in sa]
        if "FX" in channels and khi > klo:
            rows += [(fz, k, 0.0, 0.0) for k in kp]
    r = np.array(rows, float).T
    n = r.shape[1]
    nan = np.full(n, np.nan)
    return BenchData(*(jnp.asarray(v) for v in (r[0], r[1], r[2], r[3], nan, nan)),
                     jnp.zeros((len(channels), n)), jnp.ones((len(channels), n), bool),
                     tuple(channels))


def with_ranges(model, data: BenchData):
    """`model` with its validity ranges (FZMIN … CAMMAX) set to the data's (a fitted file is
    valid where it was measured, and the fit must not saturate a measured input: MF-Tyre
    raises F_z to FZMIN in M_z, clips slips at their ranges). A model without ranges (the 1989
    set) is returned as is (`AbstractTyre.with_limits`)."""
    lim = dict(model.limit)

    def span(v):
        v = np.asarray(v, float)
        return float(np.min(v)), float(np.max(v))

    (fmin, fmax), (kmin, kmax), (amin, amax), (gmin, gmax) = (
        span(data.fz), span(data.kappa), span(data.alpha), span(data.gamma))
    lim.update(FZMIN=fmin, FZMAX=fmax, KPUMIN=kmin, KPUMAX=kmax, ALPMIN=amin, ALPMAX=amax,
               CAMMIN=gmin, CAMMAX=gmax)
    return model.with_limits(lim)


def _open_ranges(model):
    """The model with no validity ranges (the fit's compiled program is shared by files)."""
    return model.with_limits(mf6.LIMITS)


class _Problem(eqx.Module):
    model: eqx.Module
    data: BenchData
    x0: jax.Array
    scale: jax.Array
    positive: jax.Array
    free: jax.Array
    rows: jax.Array
    sigma: jax.Array
    loss_code: jax.Array
    k: jax.Array
    names: tuple[str, ...] = eqx.field(static=True)
    combined: bool = eqx.field(static=True)

    @property
    def loss(self) -> str:
        return list(LOSSES)[int(self.loss_code)]

    def x_of(self, u):
        u = jnp.where(self.free, u, 0.0)
        return jnp.where(self.positive, self.x0 * jnp.exp(u), self.x0 + self.scale * u)

    def with_x(self, x):
        c = dict(self.model.coefficients)
        for i, n in enumerate(self.names):
            c[n] = x[i]
        return self.model.with_coefficients(c)

    def whitened(self, x):
        pred = _predict(self.with_x(x), self.data, self.combined)
        z = (pred - self.data.measured) / self.sigma
        return jnp.where(self.data.valid & self.rows, z, 0.0)

    def residual_x(self, x):
        return robust(self.whitened(x), self.loss_code, self.k).ravel()

    def residual_u(self, u, _args=None):
        return self.residual_x(self.x_of(u))


def _solve_impl(problem: _Problem, u0, max_steps: int, rtol: float, atol: float):
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    sol = optx.least_squares(problem.residual_u, solver, u0, max_steps=max_steps, throw=False)
    return problem.x_of(sol.value), sol.stats["num_steps"], sol.result == optx.RESULTS.successful


def _linearise_impl(problem: _Problem, x):
    """Robust residuals and their Jacobian in coefficient space at x (for the report)."""
    return problem.residual_x(x), jax.jacfwd(problem.residual_x)(x)


_solve = eqx.filter_jit(_solve_impl)
_solve_many = eqx.filter_jit(eqx.filter_vmap(_solve_impl, in_axes=(eqx.if_array(0), 0, None,
                                                                      None, None)))
_linearise = eqx.filter_jit(_linearise_impl)
_predict_jit = eqx.filter_jit(_predict)


MAX_SIGMA_PCT = 100.0
"""A coefficient whose σ exceeds its own magnitude (σ % > 100) is *not determined*: the data
cannot tell it from zero."""

CAMBER = frozenset(("PDY3 PEY4 PEY5 PKY3 PKY5 PKY6 PKY7 PHY3 PVY3 PVY4 PDX3 PPY5 QBZ4 QBZ5 "
                    "QDZ3 QDZ4 QDZ8 QDZ9 QDZ10 QDZ11 QEZ5 QHZ3 QHZ4 a5 a6 a9 a10 a111 a112 "
                    "a12 a13 c5 c6 c7 c14 c15 c16 c17").split())
"""The camber coefficients: fitted after the zero-camber ones in the staged strategy."""

CURVATURE = frozenset(("PEX1 PEX2 PEX3 PEX4 PEY1 PEY2 PEY3 PEY4 PEY5 QEZ1 QEZ2 QEZ3 QEZ4 QEZ5 "
                       "REX1 REX2 REY1 REY2").split())
"""The curvature factors E (MF 6.x): restarted with the camber terms in the second opinion."""


def _channel_of(name: str) -> str:
    """The channel a coefficient is fitted on first (its own force or moment)."""
    if name[0] in "abc" and name[1:].isdigit():
        return {"a": "FY", "b": "FX", "c": "MZ"}[name[0]]
    if name.startswith("QSX"):
        return "MX"
    if name.startswith("QSY"):
        return "MY"
    if name.startswith(("Q", "PPZ")):
        return "MZ"
    return "FX" if name[2:3] == "X" or name[:3] == "PPX" else "FY"


@dataclasses.dataclass
class TyreFitReport(IdentificationReport):
    """The result of a Magic Formula fit, an `IdentificationReport` (statuses, rows, writers as
    every identification).

    **Fields:** `names`, `start` (after the data's starting values), `file_start` (the start
    model's), `values` (fitted coefficients, library units), `sigma`, `sigma_pct`,
    `identifiable` (determined: identifiable in the linearisation and σ % ≤ `MAX_SIGMA_PCT`),
    `held` (held at the start value), `reasons` (why not determined), `correlation`,
    `combinations`, `linear` (the `diffsusp.lsq.Fit` of the linearisation), `rms` (per channel,
    unweighted, channel units), `n_points`, `residual_sigma` (σ̂ of the whitened robust residual:
    ≈ 1 when the noise model is right), `noise` (per channel (a, b) of σ = a + b·|F|, the
    yardstick of the consistency check), `noise_source` ("given" or "estimated from the
    sweeps"), `steps`, `converged` (the optimiser stopped on its tolerance), `consistency`
    (does the fitted model reproduce the data within the noise), `loss`, `violations`,
    `stages` (the strategy's stages: text).
    """

    family: ClassVar[str] = "mf_fit"
    names: tuple[str, ...]
    start: np.ndarray
    file_start: np.ndarray
    values: np.ndarray
    sigma: np.ndarray
    sigma_pct: np.ndarray
    identifiable: np.ndarray
    held: np.ndarray
    reasons: tuple[str, ...]
    correlation: np.ndarray
    combinations: list[str]
    linear: lsq.Fit
    rms: dict[str, float]
    n_points: dict[str, int]
    residual_sigma: float
    noise: dict[str, tuple[float, float]]
    noise_source: str
    steps: int
    converged: bool
    loss: str
    violations: list[str]
    stages: list[str]
    consistency: Consistency | None = None
    whitened_residuals: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    raw_residuals: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    """Per channel model − measured (channel units; 0 where not valid)."""

    # ---- the shared report interface (model units = library units)
    @property
    def estimates(self) -> np.ndarray:
        return self.values

    @property
    def sigmas(self) -> np.ndarray:
        return self.sigma

    @property
    def estimate_units(self) -> tuple[str, ...]:
        return tuple("-" for _ in self.names)

    @property
    def residuals(self) -> dict:
        return {c: MeasurementResiduals(raw=self.raw_residuals.get(c, np.zeros_like(w)),
                                        whitened=w)
                for c, w in self.whitened_residuals.items()}

    @property
    def status_list(self) -> tuple[str, ...]:
        """Per coefficient: identified / not determined / held / not seen (the base's
        `statuses`: one rule for every identification)."""
        return tuple(self.statuses)

    @property
    def stop_reason(self) -> str:
        return (f"converged in {self.steps} steps" if self.converged else
                f"max_steps reached ({self.steps} steps in all)")

    @property
    def verdict(self) -> str:
        """One line: the fit's outcome."""
        if self.consistency is not None and not self.consistency.consistent:
            return "does not fit the data: " + self.consistency.verdict
        head = "fits the data" if self.converged else \
            "fits the data (the optimiser stopped at max_steps)"
        return head + ("" if self.consistency is None else ": " + self.consistency.verdict)

    @property
    def unidentifiable(self) -> tuple[str, ...]:
        return tuple(n for n, ok, h in zip(self.names, self.identifiable, self.held,
                                           strict=True) if not ok and not h)

    def value(self, name: str) -> float:
        return float(self.values[self.names.index(name)])

    def table(self) -> str:
        st, why = self.status_list, self.status_reasons
        lines = [f"Magic Formula fit ({self.loss} loss): {self.verdict}",
                 f"optimiser: {'converged' if self.converged else 'NOT converged'} in "
                 f"{self.steps} steps; whitened residual sigma {self.residual_sigma:.4g} "
                 f"(against the noise model below)",
                 "rms: " + ", ".join(f"{c} {v:.4g} ({self.n_points[c]} points)"
                                     for c, v in self.rms.items()),
                 f"noise ({self.noise_source}): " + ", ".join(
                     f"{c} {a:.4g} + {b:.4g}·|{c}|" for c, (a, b) in self.noise.items())]
        w = max(9, *(len(n) for n in self.names))
        lines.append(f"{'parameter':<{w}}  {'start':>12}  {'value':>12}  {'sigma':>10}  "
                     f"{'sigma%':>9}  status")
        for i, n in enumerate(self.names):
            s = f"{self.sigma[i]:.3g}" if np.isfinite(self.sigma[i]) else "-"
            sp = f"{self.sigma_pct[i]:.3g}%" if np.isfinite(self.sigma_pct[i]) else "-"
            if np.isfinite(self.sigma_pct[i]) and self.sigma_pct[i] > 1e4:
                sp = ">1e4%"
            note = f" ({why[i]})" if why[i] and st[i] != "identified" else ""
            lines.append(f"{n:<{w}}  {self.start[i]:>12.6g}  {self.values[i]:>12.6g}  "
                         f"{s:>10}  {sp:>9}  {st[i]}{note}")
        if self.combinations:
            lines.append("identifiable combinations:")
            lines += [f"  {c}" for c in self.combinations]
        if self.violations:
            lines.append("constraint checks over the data's range:")
            lines += [f"  {v}" for v in self.violations]
        if self.stages:
            lines.append("strategy: " + "; ".join(self.stages))
        return "\n".join(lines)

    def __str__(self):
        return self.table()

    def summary(self) -> dict:
        out = super().summary()
        st, why = self.status_list, self.status_reasons
        for row, s, r, h in zip(out["parameters"], st, why, self.held, strict=True):
            row["status"] = s
            row["reason"] = r
            row["held"] = bool(h)
            row["identified"] = s == "identified"
        out.update(verdict=self.verdict, noise={c: list(v) for c, v in self.noise.items()},
                   noise_source=self.noise_source, rms=self.rms, n_points=self.n_points,
                   residual_sigma=_num(self.residual_sigma), steps=self.steps,
                   converged=self.converged, loss=self.loss, violations=self.violations,
                   stages=self.stages)
        return out

    def to_dict(self) -> dict:
        def f(v):
            return _num(v)
        d = self.summary()
        d.update({"names": list(self.names), "start": [float(v) for v in self.start],
                  "values": [float(v) for v in self.values],
                  "sigma": [f(v) for v in self.sigma],
                  "sigma_pct": [f(v) for v in self.sigma_pct],
                  "identifiable": [bool(v) for v in self.identifiable],
                  "statuses": list(self.status_list)})
        return d

    def to_json(self, **kwargs) -> str:
        return json.dumps(self.to_dict(), **({"indent": 2} | kwargs))

    def to_frame(self):
        import pandas as pd
        return pd.DataFrame({"start": self.start, "value": self.values, "sigma": self.sigma,
                             "sigma_pct": self.sigma_pct, "identifiable": self.identifiable,
                             "status": self.status_list},
                            index=list(self.names))


def _num(v):
    v = float(v)
    return v if math.isfinite(v) else None


def check_constraints(model, data: BenchData) -> list[str]:
    """The physical constraints `model` breaks over the data's range of load and camber
    (`AbstractTyre.constraint_violations`; MF 6.x: C > 0, |μ| > 0 without a change of sign,
    E ≤ 1, spec: tyre §7 C)."""
    return model.constraint_violations(data.fz, data.gamma)


SIGNED_LOG = frozenset(POSITIVE | {"PKY1", "PKX1", "QDZ1"})
"""Coefficients fitted as x = x₀·exp(u): magnitude free, sign kept from the start (either sign:
the PAC2002 convention writes PDY1, PKY1 < 0)."""


def _prepare(model, data, names, noise, loss, loss_scale, combined, hold=()):
    names = tuple(names)
    if loss not in LOSSES:
        raise InputError(f"loss {loss!r}: one of {', '.join(LOSSES)}")
    unknown = [n for n in names if n not in model.coefficients]
    if unknown:
        raise InputError(f"unknown coefficient(s) {', '.join(unknown)} for "
                         f"{type(model).__name__}")
    x0 = np.array([float(model.coefficients[n]) for n in names])
    if not np.all(np.isfinite(x0)):
        raise InputError("start values must be finite: " + ", ".join(
            n for n, v in zip(names, x0, strict=True) if not np.isfinite(v)))
    positive = np.array([n in SIGNED_LOG for n in names]) & (x0 != 0)
    sigma = noise_sigma(noise, data)
    free = np.array([n not in set(hold) for n in names])
    return _Problem(_open_ranges(model), data, jnp.asarray(x0),
                    jnp.asarray(np.maximum(np.abs(x0), 0.1)), jnp.asarray(positive),
                    jnp.asarray(free), jnp.ones(np.shape(data.measured), bool),
                    jnp.asarray(sigma), jnp.asarray(LOSSES[loss]),
                    jnp.asarray(float(loss_scale)), names, combined)


def _noise_models(data, noise):
    """{channel: (a, b)}, the source text, and per channel the number of third differences
    behind an estimate (0 when given)."""
    given = {c.upper(): _noise_pair(v) for c, v in (noise or {}).items()}
    est = fit_start.estimate_noise(data) if len(given) < len(data.channels) else {}
    out, counts = {}, {}
    for k, c in enumerate(data.channels):
        if c in given:
            out[c], counts[c] = given[c], 0
        elif c in est:
            out[c], counts[c] = est[c][:2], est[c][2]
        else:  # no sweep to estimate from: 1 % of the range, judged by the residual only
            v = np.asarray(data.measured)[k][np.asarray(data.valid)[k]]
            out[c], counts[c] = (0.01 * float(np.ptp(v)) if v.size and np.ptp(v) > 0
                                 else 1.0, 0.0), 0
    given_all = all(c in given for c in data.channels)
    src = "given" if given_all else ("estimated from the sweeps" if not given else
                                     "given for " + ", ".join(given) + ", else estimated")
    return out, src, counts


def _stage_plan(problem, strategy):
    """(label, free mask, row mask) of each stage (see `fit`)."""
    names = problem.names
    free = np.asarray(problem.free)
    valid = np.asarray(problem.data.valid)
    chans = problem.data.channels
    flat = np.abs(np.asarray(problem.data.gamma)) < 1e-9
    all_rows = np.ones_like(valid)
    if strategy == "joint":
        return [("joint", free, all_rows)]
    plan = []
    order = [c for c in ("FY", "FX", "MZ", "MX", "MY") if c in chans]
    for ch in order:
        own = np.array([_channel_of(n) == ch for n in names]) & free
        if not own.any():
            continue
        k = chans.index(ch)
        rows_ch = np.zeros_like(valid)
        rows_ch[k] = True
        camber = np.array([n in CAMBER for n in names])
        if (flat & valid[k]).sum() > 4 and (own & ~camber).any():
            r = rows_ch.copy()
            r[k] &= flat
            plan.append((f"{ch} at zero camber", own & ~camber, r))
        if (own & camber).any():
            plan.append((f"{ch} camber terms", own & camber, rows_ch))
        plan.append((f"{ch} all", own, rows_ch))
    plan.append(("joint", free, all_rows))
    return plan


def _run(problem, strategy, max_steps, rtol, atol):
    """The stages of `strategy` from the problem's x0; returns (x, steps, converged, labels)."""
    x = problem.x0
    total, ok, labels = 0, False, []
    for label, free, rows in _stage_plan(problem, strategy):
        p = eqx.tree_at(lambda q: (q.x0, q.free, q.rows), problem,
                        (jnp.asarray(x), jnp.asarray(free), jnp.asarray(rows)))
        x, steps, ok = _solve(p, jnp.zeros(len(problem.names)), max_steps, rtol, atol)
        total += int(steps)
        labels.append(f"{label} ({int(free.sum())} free, {int(steps)} steps)")
    return x, total, bool(ok), labels


def _consistency(problem, x, noise_counts, n_determined, alpha=CONSISTENCY_ALPHA):
    """The fitted model against the data in units of the noise model (see `fit`)."""
    z = np.asarray(_whitened(problem, jnp.asarray(x)))
    valid = np.asarray(problem.data.valid)
    chans = problem.data.channels
    inlier = valid & (np.abs(z) <= OUTLIER_Z)
    n_out = int((valid & ~inlier).sum())
    n = int(inlier.sum())
    chi2 = float(np.sum(np.where(inlier, z, 0.0) ** 2))
    dof = max(n - int(n_determined), 1)
    rms = np.array([math.sqrt(np.sum(np.where(inlier[k], z[k], 0) ** 2)
                              / max(inlier[k].sum(), 1)) for k in range(len(chans))])
    n_diff = sum(noise_counts.values())
    if n_diff > 0:
        from scipy.stats import f as f_law
        # the noise yardstick is itself estimated: a variance ratio (F law), ~n/2.3 dof
        critical = dof * float(f_law.ppf(1.0 - alpha, dof, max(n_diff / 2.31, 1.0)))
        note = ("χ² of the inlier residuals (|z| ≤ 5) against the noise model estimated from "
                "the sweeps' third differences (F law)")
    else:
        critical = chi2_quantile(dof, alpha)
        note = "χ² of the inlier residuals (|z| ≤ 5) against the given noise"
    frac = n_out / max(int(valid.sum()), 1)
    consistent = bool(chi2 <= critical and frac <= MAX_OUTLIER_FRACTION)
    if frac > MAX_OUTLIER_FRACTION:
        note += f"; {100 * frac:.3g} % of the points beyond 5σ (more than outliers)"
    return Consistency(chi2=chi2, n_residuals=n, n_parameters=int(n_determined), dof=dof,
                       critical=critical, case_rms=rms, cases=chans, failed_cases=(),
                       consistent=consistent, measurements=chans, alpha=alpha, note=note), z


OUTLIER_Z = 5.0
MAX_OUTLIER_FRACTION = 0.05
"""Beyond 5 % of the points outside ±5σ the misfit is no longer a few outliers."""

_whitened = eqx.filter_jit(lambda problem, x: problem.whitened(x))


def _psi(z, code, k):
    """ρ'(z) and ρ''(z) of the loss (the M-estimator's ψ and ψ')."""
    if code == 0:
        return z, np.ones_like(z)
    if code == 1:
        inside = np.abs(z) <= k
        return np.clip(z, -k, k), inside.astype(float)
    q = (z / k) ** 2
    return z / (1.0 + q), (1.0 - q) / (1.0 + q) ** 2


def _report(problem, x, steps, ok, threshold, file_start, noise, noise_src, noise_counts,
            stages):
    """The report at x. Covariance: the M-estimator's sandwich on the whitened residuals z
    (Huber 1981, §7.6; HC3 small-sample correction, MacKinnon & White 1985):
    (Σψ'ᵢJᵢJᵢᵀ)⁻¹(Σψᵢ²/(1 − hᵢ)²·JᵢJᵢᵀ)(Σψ'ᵢJᵢJᵢᵀ)⁻¹, hᵢ the leverage, over the valid points
    (the linear loss: White's heteroscedasticity-consistent covariance); identifiability and
    combinations from `diffsusp.lsq` on J_z. The report's residual σ is
    √κ, κ = [Σψ²/(n − p)]/[mean ψ']² (≈ 1 when the noise model is right)."""
    names = problem.names
    r, J = (np.asarray(a) for a in _linearise(problem, jnp.asarray(x)))
    z = np.asarray(_whitened(problem, jnp.asarray(x))).ravel()
    code, k = int(problem.loss_code), float(problem.k)
    psi, dpsi = _psi(z, code, k)
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.where(np.abs(r) > 1e-300, psi / r, 1.0)   # dr/dz = ψ/r
    slope = np.where(np.isfinite(slope) & (slope > 0), slope, 1.0)
    J = J / slope[:, None]
    x = np.asarray(x)
    free = np.asarray(problem.free)
    rows = (np.asarray(problem.data.valid) & np.asarray(problem.rows)).ravel()
    Jf = J[rows][:, free]
    lin = lsq.solve(Jf, Jf @ x[free] - z[rows], names=tuple(np.array(names)[free]),
                    prior=x[free], threshold=threshold)
    p = len(names)
    fi = np.flatnonzero(free)
    idl = np.asarray(lin.identifiable, bool)
    n_rows = int(rows.sum())
    kappa = (float(np.sum(psi[rows] ** 2)) / max(n_rows - int(idl.sum()), 1)
             / max(float(np.mean(dpsi[rows])), 1e-3) ** 2)
    cov = np.full((p, p), np.nan)
    if idl.any():
        # sandwich (HC3): bread (Σψ'·JᵢJᵢᵀ)⁻¹, meat Σψᵢ²·JᵢJᵢᵀ — right also when the noise
        # model's shape is not (σ = a + b|F| estimated, outliers down-weighted)
        Ji = Jf[:, idl]
        sc = np.linalg.norm(Ji, axis=0)
        sc = np.where(sc > 0, sc, 1.0)
        Js = Ji / sc
        w1 = np.maximum(dpsi[rows], 0.0)
        bread = np.linalg.pinv(Js.T @ (Js * w1[:, None]))
        # HC3: each point's ψ² over (1 − h)², h its leverage ψ'·Jᵢᵀ·bread·Jᵢ (a point that
        # pulls the fit towards itself shows a residual smaller than its noise)
        lev = np.clip(w1 * np.einsum("ij,jk,ik->i", Js, bread, Js), 0.0, 0.99)
        meat = (Js * (psi[rows] ** 2 / (1.0 - lev) ** 2)[:, None]).T @ Js
        hc = bread @ meat @ bread
        cov[np.ix_(fi[idl], fi[idl])] = hc / np.outer(sc, sc)
    robust_sigma = math.sqrt(kappa)
    sd = np.sqrt(np.abs(np.diag(cov)))
    ident_lin = np.zeros(p, bool)
    ident_lin[fi] = np.asarray(lin.identifiable, bool)
    sigma = np.where(ident_lin, sd, np.nan)
    for j in np.flatnonzero(~idl):   # inf: no information at all (a null column)
        if (lin.status(int(j)) or "").endswith("no effect on the data"):
            sigma[fi[j]] = np.inf
    with np.errstate(divide="ignore", invalid="ignore"):
        pct = 100.0 * sigma / np.abs(x)
    reasons = []
    determined = np.zeros(p, bool)
    for i in range(p):
        if not free[i]:
            reasons.append("held at the start value")
            continue
        j = int(np.flatnonzero(fi == i)[0])
        if not ident_lin[i]:
            reasons.append(lin.status(j) or "not identifiable")
        elif not (pct[i] <= MAX_SIGMA_PCT):
            reasons.append(f"σ % = {pct[i]:.3g} > {MAX_SIGMA_PCT:g}: the data do not fix its "
                           "value")
        else:
            determined[i] = True
            reasons.append("")
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sd, sd)
    corr[~determined, :] = np.nan
    corr[:, ~determined] = np.nan
    fitted = problem.with_x(jnp.asarray(x))
    pred = np.asarray(_predict_jit(fitted, problem.data, problem.combined))
    meas, valid = np.asarray(problem.data.measured), np.asarray(problem.data.valid)
    rms = {c: float(np.sqrt(np.mean((pred[k] - meas[k])[valid[k]] ** 2)))
           for k, c in enumerate(problem.data.channels)}
    npts = {c: int(valid[k].sum()) for k, c in enumerate(problem.data.channels)}
    cons, z = _consistency(problem, x, noise_counts, int(determined.sum()))
    return fitted, TyreFitReport(
        names, np.asarray(problem.x0), np.asarray(file_start), x, sigma, pct, determined,
        ~free, tuple(reasons), corr, list(lin.relations), lin, rms, npts,
        robust_sigma, dict(noise), noise_src, int(steps), bool(ok), problem.loss,
        check_constraints(fitted, problem.data), list(stages), consistency=cons,
        raw_residuals={c: np.where(valid[k], pred[k] - meas[k], 0.0)
                       for k, c in enumerate(problem.data.channels)},
        whitened_residuals={c: z[k] for k, c in enumerate(problem.data.channels)})


def default_hold(model, names, tir=None) -> tuple[str, ...]:
    """The coefficients held at the start by default: those the start file does not use
    (exactly 0, or absent from `tir`, the start's property file, when given). A fitter chose
    the file's structure (no shift, no camber term): the fit keeps it; name a coefficient in
    `free=` to fit it anyway."""
    out = []
    for n in names:
        if float(model.coefficients[n]) == 0.0:
            out.append(n)
        elif tir is not None and n not in tir:
            out.append(n)
    return tuple(out)


def default_names(model, channels) -> list[str]:
    """The coefficients of `default_groups` present in the model."""
    return [n for g in default_groups(model, channels) for n in GROUPS[g]
            if n in model.coefficients]


def fit(model, data: BenchData, params=None, *, noise: dict | None = None,
        loss: str = "huber", loss_scale: float = 1.345, combined: bool = True,
        max_steps: int = 200, rtol: float = 1e-10, atol: float = 1e-10,
        threshold: float = 1e-8, strategy: str = "staged", start_from_data: bool = True,
        hold=None, free=(), tir=None, second_start: bool = True):
    """Fit the coefficients `params` of `model` (an `AbstractTyre`: `MagicFormula6`,
    `MagicFormula89`) to `data`.

    spec: tyre §7 E item 22, §7 D item 18; the start and noise: `diffsusp.tyre.fit_start`.

    **Arguments:** `params` the coefficients fitted, a sequence of names (the selector every
    identification takes; default `default_names`: the `default_groups` the data's channels
    allow; the others stay at the model's values); `hold` the names kept at the start value
    (default: with `params` not given, `default_hold` — those the start file does not use, 0 or
    absent from `tir`; with `params` given, none) less `free`; `noise` per channel σ or (a, b)
    for σ = a + b·|F| [N or N·mm] (default: estimated from the sweeps,
    `fit_start.estimate_noise`); `loss` "huber", "cauchy" or "linear",
    `loss_scale` k in units of σ; `combined=False` fits the pure-slip functions;
    `strategy` "staged" (default) or "joint"; `start_from_data` the data's starting values of
    the scale coefficients (`fit_start.data_start`); LM tolerances; `threshold` of
    identifiability.

    **Strategy "staged"**: after the data's starting values, per channel (F_y, F_x, M_z) its
    own coefficients on its own data: first the zero-camber ones on the zero-camber sweeps,
    then the camber ones with the others fixed, then all of the channel's together; last the
    joint fit of every coefficient on every channel. Every stage runs the same compiled
    Levenberg–Marquardt program (free coefficients and rows as masks).

    **Second start** (`second_start`, staged only): the joint fit is also run from the start
    file's own values, and from the fit with its camber and curvature coefficients (`CAMBER`,
    `CURVATURE`) back at the file's values (E_y → 0 lets PEY3, PEY4 trade with the camber
    shifts: a staged fit can settle in a basin of the camber terms far worse than the truth's);
    the best optimum is kept, and when another fits the data equally well (objectives within
    the χ² quantile of as many dof as free coefficients) a coefficient on which they differ by
    more than 3σ is *not determined*: the data do not tell the two apart (a nonlinear ridge no
    linearised σ shows, e.g. E_y's PEY1·(1 − PEY3·sgn α)). Two ridge probes 4σ along the least
    determined direction are second opinions too; one that goes down to a better optimum
    becomes the fit (once).

    **Noise and verdict.** Residuals are whitened by σ = a + b·|F| per point. With the noise
    estimated, the fit is polished once with the noise model re-estimated from its residuals
    (the scale the covariance uses); the consistency check compares the inlier residuals
    (|z| ≤ 5) with the data-only estimate: a fit whose χ² is beyond the F-law bound, or with
    more than 5 % of its points beyond 5σ, "does not fit the data" and calls nothing
    identified. **Outliers:** with a robust loss, points beyond 5σ of the (polished) fit — at
    most 5 % of them — are left out, the noise model re-estimated from the inliers and the fit
    polished on them (`_reject_outliers`); the covariance is over the inliers.

    **Returns:** (fitted model with the data's validity ranges, `TyreFitReport`).
    """
    if strategy not in ("staged", "joint"):
        raise InputError(f"strategy {strategy!r}: 'staged' or 'joint'")
    named = params is not None
    names = tuple(default_names(model, data.channels) if params is None else params)
    unknown = [n for n in (*names, *free, *(hold or ())) if n not in model.coefficients]
    if unknown:
        raise InputError(f"unknown coefficient(s) {', '.join(unknown)} for "
                         f"{type(model).__name__}")
    if hold is None:
        hold = () if named else default_hold(model, names, tir)
    hold = tuple(n for n in hold if n not in set(free))
    file_start = np.array([float(model.coefficients[n]) for n in names])
    noise_ab, noise_src, counts = _noise_models(data, noise)
    start = model
    if start_from_data:
        new = _open_ranges(model).data_start(data, [n for n in names if n not in hold],
                                             lambda m: _predict_jit(m, data, combined))
        if new:
            start = model.replace(**new)
    problem = _prepare(start, data, names, noise_ab, loss, loss_scale, combined, hold)
    x, steps, ok, labels = _run(problem, strategy, max_steps, rtol, atol)
    if noise_src != "given":
        # polish with the noise re-estimated from the residuals (the covariance's scale)
        pred = np.asarray(_predict_jit(problem.with_x(x), data, combined))
        res = np.asarray(data.measured) - pred
        refit = dict(noise_ab)
        for k, c in enumerate(data.channels):
            if c in (noise or {}):
                continue
            v = np.asarray(data.valid)[k]
            if v.sum() >= 12:
                refit[c] = fit_start.scale_model(res[k][v], np.abs(pred[k][v]))
        sig = fit_start.noise_sigma(refit, data)
        p2 = eqx.tree_at(lambda q: (q.x0, q.sigma), problem, (x, jnp.asarray(sig)))
        x, s2, ok = _solve(p2, jnp.zeros(len(names)), max_steps, rtol, atol)
        steps += int(s2)
        labels.append(f"polish with the residuals' noise ({int(s2)} steps)")
        # the yardstick of the verdict stays the data-only estimate
        problem = eqx.tree_at(lambda q: q.x0, p2, problem.x0)
        problem_cov = p2
    else:
        problem_cov = problem
    if loss != "linear":
        x, problem_cov, lab, s3, ok3 = _reject_outliers(problem_cov, x, data, noise, max_steps,
                                                        rtol, atol)
        labels += lab
        steps += s3
        ok = ok if ok3 is None else ok3
    others = []
    if second_start and strategy == "staged":
        # second opinions: the joint fit from the start file's own values (another basin), and
        # from the fit with its camber and curvature coefficients back at the file's values
        # (the E_y ridge PEY1 -> 0 leaves PEY3, PEY4 free to trade with the camber shifts:
        # a staged fit can settle in a basin of camber terms far worse than the truth's)
        restart = np.array([n in CAMBER or n in CURVATURE for n in names])
        starts = [("joint from the file's values", np.asarray(file_start))]
        if restart.any():
            starts.append(("camber and curvature terms from the file's values",
                           np.where(restart, np.asarray(file_start), np.asarray(x))))
        s_main = float(_objective(problem_cov, jnp.asarray(x)))
        for what, x_start in starts:
            pa = eqx.tree_at(lambda q: q.x0, problem_cov, jnp.asarray(x_start))
            xa, sa, oka, _ = _run(pa, "joint", max_steps, rtol, atol)
            s_alt = float(_objective(problem_cov, xa))
            labels.append(f"second start: {what} ({sa} steps, objective {s_alt:.6g} vs "
                          f"{s_main:.6g})")
            if s_alt < s_main:
                others.append(np.asarray(x))
                x, ok, s_main = xa, oka, s_alt
                labels.append("the second start fits better: kept")
            else:
                others.append(np.asarray(xa))
        s_main = float(_objective(problem_cov, jnp.asarray(x)))
        others = [(xo, abs(float(_objective(problem_cov, jnp.asarray(xo))) - s_main))
                  for xo in others]
    for attempt in range(2):
        _, report = _report(problem_cov, x, steps, ok, threshold, file_start, noise_ab,
                            noise_src, counts, labels)
        for xo, gap in others:
            _second_opinion(report, xo, gap)
        if not second_start:
            break
        probes = _ridge_probes(problem_cov, report, max_steps, rtol, atol)
        labels += [lab for _, _, lab in probes]
        s_main = float(_objective(problem_cov, jnp.asarray(x)))
        s_probe = [float(_objective(problem_cov, jnp.asarray(xp))) for xp, _, _ in probes]
        if attempt == 0 and probes and min(s_probe) < s_main - 1e-6 * max(abs(s_main), 1.0):
            # a probe went down the ridge to a better optimum: the report is made there, the
            # first optimum and the other probe are second opinions
            j = int(np.argmin(s_probe))
            others = [(xo, None) for xo, _ in others] + [(np.asarray(x), None)] + [
                (xp, None) for k, (xp, _, _) in enumerate(probes) if k != j]
            x = jnp.asarray(probes[j][0])
            s_main = s_probe[j]
            others = [(xo, abs(float(_objective(problem_cov, jnp.asarray(xo))) - s_main))
                      for xo, _ in others]
            labels.append(f"ridge probe {'+-'[j]}4σ fits better: kept, report made there")
            continue
        for xp, gp, _ in probes:
            _second_opinion(report, xp, gp)
        break
    report.stages = list(labels)
    exact = all(v <= 1e-9 * max(float(np.ptp(np.asarray(data.measured)[k])), 1.0)
                for k, v in enumerate(report.rms.values()))
    if not exact:   # with exact data the optimum is exact, clip or not
        _clipped_curvature(report)
        labels += _profile_curvature(problem_cov, report, max_steps, rtol, atol)
        report.stages = list(labels)
    if problem_cov is not problem:
        cons, z = _consistency(problem, np.asarray(x), counts, int(report.identifiable.sum()))
        report.consistency = cons
        report.whitened_residuals = {c: z[k] for k, c in enumerate(data.channels)}
    report.start = np.asarray(problem.x0)
    return with_ranges(model.replace(**{n: float(v) for n, v in zip(names, x, strict=True)}),
                       data), report


def _reject_outliers(problem, x, data, noise, max_steps, rtol, atol):
    """Points beyond `OUTLIER_Z` of the robust fit at x left out, the noise model re-estimated
    from the inliers' residuals (where it is estimated) and the fit polished on the inliers:
    (x, problem with the inlier rows, stage labels, steps, converged or None). A Huber loss
    bounds an outlier's pull at k·σ but keeps it: with 2 % spikes of 30–60σ the camber shifts'
    errors spread 1.2 of their sandwich σ in the rehearsal of 200 FEDA truths (0.96 without
    spikes); a point beyond 5σ of a robust fit is not a sample of the noise model and carries
    no information on the coefficients (a hard-redescending M-estimator after the Huber
    start, spec: tyre §7 E item 22). More than `MAX_OUTLIER_FRACTION` beyond 5σ is a misfit,
    not outliers: nothing is left out (the verdict says so)."""
    z = np.asarray(_whitened(problem, jnp.asarray(x)))
    valid = np.asarray(data.valid) & np.asarray(problem.rows)
    keep = valid & (np.abs(z) <= OUTLIER_Z)
    n_out = int((valid & ~keep).sum())
    if n_out == 0 or n_out > MAX_OUTLIER_FRACTION * max(int(valid.sum()), 1):
        return x, problem, [], 0, None   # none, or more than outliers: the verdict says so
    sigma = np.asarray(problem.sigma)
    labels = []
    if not all(c in (noise or {}) for c in data.channels):
        pred = np.asarray(_predict_jit(problem.with_x(jnp.asarray(x)), data, problem.combined))
        res = np.asarray(data.measured) - pred
        refit = {}
        for k, c in enumerate(data.channels):
            if c not in (noise or {}) and keep[k].sum() >= 12:
                refit[c] = fit_start.scale_model(res[k][keep[k]], np.abs(pred[k][keep[k]]))
        if refit:
            sigma = np.where(np.isin(np.arange(len(data.channels)),
                                     [data.channels.index(c) for c in refit])[:, None],
                             fit_start.noise_sigma(refit, data), sigma)
    p3 = eqx.tree_at(lambda q: (q.x0, q.rows, q.sigma), problem,
                     (jnp.asarray(x), jnp.asarray(keep), jnp.asarray(sigma)))
    x3, s3, ok3 = _solve(p3, jnp.zeros(len(problem.names)), max_steps, rtol, atol)
    labels.append(f"{n_out} outlier(s) beyond {OUTLIER_Z:g}σ left out, noise re-estimated, "
                  f"polished on the inliers ({int(s3)} steps)")
    return x3, p3, labels, int(s3), bool(ok3)


def _objective(problem, x) -> float:
    """Σr² of the robust residuals at x (from the compiled whitened residuals)."""
    z = np.asarray(_whitened(problem, jnp.asarray(x)))
    code, k = int(problem.loss_code), float(problem.k)
    if code == 0:
        return float(np.sum(z * z))
    if code == 1:
        a = np.abs(z)
        return float(np.sum(np.where(a <= k, z * z, 2.0 * k * a - k * k)))
    return float(np.sum(k * k * np.log1p((z / k) ** 2)))


def _ridge_probes(problem, report, max_steps, rtol, atol):
    """Restarts 4σ away along the least determined direction of the determined coefficients
    (both ways): (optimum, |objective difference|, label) of each. A valley the linearisation
    does not see (e.g. a curvature factor clipped at 1 over part of the data) brings a probe to
    another optimum as good as the first, 3σ or more away."""
    det = np.asarray(report.identifiable, bool)
    if det.sum() < 2:
        return []
    cov = np.asarray(report.correlation)[np.ix_(det, det)]
    sd = np.asarray(report.sigma)[det]
    if not np.all(np.isfinite(cov)) or not np.all(np.isfinite(sd)):
        return []
    w, v = np.linalg.eigh(cov)
    x = np.asarray(report.values)
    s0 = float(_objective(problem, jnp.asarray(x)))
    out = []
    for sign in (1.0, -1.0):
        d = np.zeros_like(x)
        d[det] = sign * 4.0 * math.sqrt(max(w[-1], 0.0)) * v[:, -1] * sd
        p = eqx.tree_at(lambda q: q.x0, problem, jnp.asarray(x + d))
        xp, sp, _ = _solve(p, jnp.zeros(x.size), max_steps, rtol, atol)
        s1 = float(_objective(problem, xp))
        out.append((np.asarray(xp), abs(s1 - s0),
                    f"ridge probe {'+' if sign > 0 else '-'}4σ ({int(sp)} steps, objective "
                    f"{s1:.6g} vs {s0:.6g})"))
    return out


def _clipped_curvature(report):
    """A curvature factor clipped at 1 over part of the data (E_x, E_y > 1: MF-Tyre's limit)
    leaves its coefficients without a smooth optimum: the data beyond the clip only say E ≥ 1,
    and the linearised σ misses it. Their coefficients are then not determined."""
    groups = {"E_y": ("PEY1", "PEY2", "PEY3", "PEY4", "PEY5"),
              "E_x": ("PEX1", "PEX2", "PEX3", "PEX4")}
    ident = np.asarray(report.identifiable).copy()
    reasons = list(report.reasons)
    for v in report.violations:
        for e, coeffs in groups.items():
            if v.startswith(e):
                for i, n in enumerate(report.names):
                    if n in coeffs and ident[i]:
                        ident[i] = False
                        reasons[i] = (f"{e} reaches the clip at 1 in the data's range: beyond "
                                      "it the data only say E ≥ 1")
                # what leans on those coefficients (|correlation| > 0.5) inherits the doubt
                idx = [i for i, n in enumerate(report.names) if n in coeffs]
                corr = np.nan_to_num(np.asarray(report.correlation)[:, idx])
                for i in np.flatnonzero(ident & np.any(np.abs(corr) > 0.5, axis=1)):
                    ident[i] = False
                    reasons[i] = (f"correlated with the curvature {e}, which reaches the clip "
                                  "at 1 in the data's range")
    report.identifiable = ident
    report.reasons = tuple(reasons)


PROFILE_RATIO = 0.5
"""A curvature factor whose profile rises less than this fraction of the linearised objective
at 3σ is not determined (`_profile_curvature`)."""


def _profile_curvature(problem, report, max_steps, rtol, atol):
    """σ of the determined curvature factors (`CURVATURE`) from their profile: each is fixed
    3σ either side, the other coefficients refitted, and the rise of the objective compared
    with the linearisation's, (3σ)²/[(JᵀJ)⁻¹]ᵢᵢ. E enters as a product (PEY1·(1 − (PEY3 +
    PEY4·γ)·sgn α)) clipped at 1: the likelihood is a curved ridge (PEY4 ∝ 1/PEY1 at a fixed
    camber asymmetry), along which the linearised σ understates the spread (a PEY4 claimed at
    8σ in the 200-truth outlier rehearsal). Where the profile rises less, σ is scaled by
    √(linear rise / profile rise) (the profile's 3σ point), and the coefficients correlated with
    it beyond 0.5 take the same scale; a factor whose profile rises less than `PROFILE_RATIO`
    of the linearised rise (the ridge flattens further out: no σ describes it), or whose σ %
    then exceeds `MAX_SIGMA_PCT`, is not determined."""
    names = report.names
    det = np.asarray(report.identifiable, bool)
    todo = [i for i, n in enumerate(names) if n in CURVATURE and det[i]]
    if not todo:
        return []
    x = np.asarray(report.values, float)
    free = ~np.asarray(report.held, bool) & det
    r, J = (np.asarray(a) for a in _linearise(problem, jnp.asarray(x)))
    rows = (np.asarray(problem.data.valid) & np.asarray(problem.rows)).ravel()
    Jf = J[rows][:, free]
    info = np.linalg.pinv(Jf.T @ Jf)
    fi = np.flatnonzero(free)
    s0 = float(_objective(problem, jnp.asarray(x)))
    sigma = np.asarray(report.sigma, float).copy()
    corr = np.nan_to_num(np.asarray(report.correlation, float))
    labels, scale, flat = [], np.ones(len(names)), []
    for i in todo:
        j = int(np.flatnonzero(fi == i)[0])
        lin = (3.0 * sigma[i]) ** 2 / max(float(info[j, j]), 1e-300)
        rise = math.inf
        for sign in (1.0, -1.0):
            x_fix = x.copy()
            x_fix[i] += sign * 3.0 * sigma[i]
            f = np.asarray(problem.free).copy()
            f[i] = False
            p = eqx.tree_at(lambda q: (q.x0, q.free, q.scale), problem,
                            (jnp.asarray(x_fix), jnp.asarray(f),
                             jnp.asarray(np.maximum(np.abs(x_fix), 0.1))))
            xp, _, _ = _solve(p, jnp.zeros(len(names)), max_steps, rtol, atol)
            rise = min(rise, float(_objective(problem, xp)) - s0)
        ratio = max(rise, 1e-12) / lin
        labels.append(f"profile of {names[i]}: objective +{rise:.3g} at 3σ (linearised "
                      f"+{lin:.3g})")
        if ratio < 1.0:
            scale[i] = max(scale[i], 1.0 / math.sqrt(ratio))
            for k in np.flatnonzero(det & (np.abs(corr[i]) > 0.5)):
                scale[k] = max(scale[k], 1.0 / math.sqrt(ratio))
        if ratio < PROFILE_RATIO:
            flat.append(i)
    if np.any(scale > 1.0):
        sigma = sigma * scale
        with np.errstate(divide="ignore", invalid="ignore"):
            pct = 100.0 * sigma / np.abs(x)
        ident = det.copy()
        reasons = list(report.reasons)
        for k in np.flatnonzero(det & (scale > 1.0)):
            if k in flat:
                ident[k] = False
                reasons[k] = ("its profile rises less than half the linearised objective at "
                              "3σ (a curved ridge): the data do not fix it within any σ")
            elif not pct[k] <= MAX_SIGMA_PCT:
                ident[k] = False
                reasons[k] = (f"σ % = {pct[k]:.3g} > {MAX_SIGMA_PCT:g} from the curvature "
                              "factors' profile: the data do not fix its value")
        report.sigma, report.sigma_pct = sigma, pct
        report.identifiable, report.reasons = ident, tuple(reasons)
    return labels


def _second_opinion(report, x_other, gap):
    """Mark the determined coefficients on which an equally good second optimum differs by more
    than 3σ as not determined (see `fit`)."""
    free = ~np.asarray(report.held)
    bound = chi2_quantile(max(int(free.sum()), 1))
    if not gap <= bound:
        return
    reasons = list(report.reasons)
    ident = np.asarray(report.identifiable).copy()
    for i in np.flatnonzero(ident):
        d = abs(float(x_other[i]) - float(report.values[i]))
        # beyond 3σ and beyond the solver's precision (two exact fits agree to ~1e-9)
        if d > 3.0 * report.sigma[i] and d > 1e-7 * abs(float(report.values[i])) + 1e-12:
            ident[i] = False
            reasons[i] = (f"a second optimum fits the data as well (Δobjective {gap:.3g}) at "
                          f"{float(x_other[i]):.6g}, {d / report.sigma[i]:.3g}σ away: the data "
                          "do not tell the two apart")
    report.identifiable = ident
    report.reasons = tuple(reasons)


def default_groups(model, channels) -> list[str]:
    """The coefficient groups fitted, in order, when none are named (`diffsusp tyre fit`, the
    fleet's tyre fits): `mf1989_lateral` for a 1989 tyre (`MagicFormula89`), otherwise
    pure_lateral, pure_longitudinal and pure_aligning as the bench data's `channels` allow."""
    return model.default_groups(channels)


MF1989_START = {"a0": 1.3, "a1": -20.0, "a2": 1300.0, "a3": 2000.0, "a4": 8.0, "a7": 0.3,
                "c0": 2.4, "c1": 4.0, "c3": -1.0, "c4": -10.0, "c9": 0.5}
"""The start of a 1989-set fit without a start file (`diffsusp tyre fit --model mf1989`): a
passenger-car tyre's order of magnitude, thesis units (the other coefficients 0, λ's 1)."""


def group_params(model, groups) -> list[str]:
    """The coefficients of the `GROUPS` named in `groups` that `model` has, in order, once
    each."""
    return list(dict.fromkeys(n for g in groups for n in GROUPS[g] if n in model.coefficients))


def check_varies(data: BenchData, n_free: int, where: str = "") -> None:
    """Bench data with fewer distinct input points (FZ, SL, SA, IA, VX, P over the rows kept)
    than `n_free` free coefficients cannot determine them: an `InputError` (prefixed by
    `where`, e.g. the file) before anything is compiled (10⁶ rows of one repeated point would
    run for minutes)."""
    keep = np.asarray(data.valid).any(axis=0)
    pts = np.stack([np.asarray(v)[keep] for v in (data.fz, data.kappa, data.alpha,
                                                  data.gamma, data.vx, data.pressure)], 1)
    distinct = np.unique(np.nan_to_num(pts, nan=-1.0), axis=0).shape[0]
    if distinct < max(n_free, 2):
        raise InputError(f"{where}the data hold {distinct} distinct input point(s) (FZ, SL, "
                         f"SA, IA, VX, P) in {int(keep.sum())} rows, fewer than the {n_free} "
                         "coefficients to fit; a fit needs sweeps of slip and load")


def fit_groups(model, data: BenchData, groups=None, *, free=(), tir=None, where: str = "",
               **options):
    """Fit the coefficient groups `groups` (keys of `GROUPS`; default `default_groups`)
    together, as `diffsusp tyre fit --mode` does: the groups' coefficients the model has
    (`group_params`), those the start file does not use held (`default_hold` with `tir`, the
    start's property file) unless named in `free`, the data checked to vary enough for them
    (`check_varies`, its message prefixed by `where`); `options` go to `fit`. Returns (the
    groups, the fitted model, the `TyreFitReport`)."""
    groups = list(groups or default_groups(model, data.channels))
    names = group_params(model, groups)
    free = tuple(free)
    bad = [n for n in free if n not in names]
    if bad:
        raise InputError(f"free {', '.join(bad)}: not among the fitted coefficients of "
                         f"{', '.join(groups)}")
    hold = default_hold(model, names, tir)
    check_varies(data, len([n for n in names if n not in hold or n in free]), where)
    fitted, report = fit(model, data, names, hold=hold, free=free, tir=tir, **options)
    return groups, fitted, report


def fit_many(models, datas, params, *, noise: dict | None = None, loss: str = "huber",
             loss_scale: float = 1.345, combined: bool = True, max_steps: int = 200,
             rtol: float = 1e-10, atol: float = 1e-10, threshold: float = 1e-8, hold=()):
    """Many tyres in one batched (vmapped) call of the joint strategy: `models` and `datas`
    are sequences of equal length whose data have equal shapes (pad with `valid=False` rows
    otherwise); `params` the coefficients fitted (a sequence of names, as `fit`); `noise` given
    (σ or (a, b) per channel; default: estimated per data set). Returns lists of fitted models
    and reports."""
    names = tuple(params)
    preps = []
    for m, d in zip(models, datas, strict=True):
        ab, src, counts = _noise_models(d, noise)
        preps.append((_prepare(m, d, names, ab, loss, loss_scale, combined, hold), ab, src,
                      counts))
    problems = [p[0] for p in preps]
    stacked = jax.tree.map(lambda *a: jnp.stack(a), *problems)
    u0 = jnp.zeros((len(problems), len(names)))
    X, S, OK = _solve_many(stacked, u0, max_steps, rtol, atol)
    out = []
    for i, (p, ab, src, counts) in enumerate(preps):
        _, rep = _report(p, X[i], S[i], OK[i], threshold, np.asarray(p.x0), ab, src,
                         counts, ["joint (batched)"])
        fitted = with_ranges(models[i].replace(**{n: float(v) for n, v in
                                                  zip(names, X[i], strict=True)}), datas[i])
        out.append((fitted, rep))
    return [o[0] for o in out], [o[1] for o in out]


class FitRehearsal:
    """A rehearsal of a Magic Formula fit (the scenario of `diffsusp.identify.rehearse`): random
    truths around the user's start file, the user's bench programme simulated with the user's
    noise, fitted with the user's options from the start file.

    **Arguments:** `start_model` (the start file's model), `programme` (a `BenchData` whose
    inputs and channels are the planned bench programme, e.g. `bench_programme`), `params` (the
    coefficients whose truths are drawn; default the ones `fit` estimates: `default_names` less
    `default_hold`), `spread` (relative: truths x₀·(1 + spread·U(−1, 1)), default ±20 %),
    `noise` per channel σ or (a, b) for σ = a + b·|F| (default 20 N + 1 % |F| on forces, 20 N·m
    + 1 % on moments), `outliers` (fraction of gross spikes), `fit_noise` the noise the fit is
    told (default None: estimated from the sweeps, as a user without a noise figure runs it),
    `loss`, `strategy`, `tir` (the start's property file: its absent coefficients are held),
    `centre` (the model the truths are drawn around, default the start: e.g. a neighbouring
    file written for the start's FNOMIN, `fit_start.renormalise`, to rehearse a fit from
    another file; its other coefficients are the truths' too).

    Each truth is simulated with its validity ranges opened to the programme (a measured tyre
    saturates nothing) and fitted by `fit`; `identify` returns the reports in the truths'
    order.
    """

    method = "mf-fit"

    def __init__(self, start_model, programme: BenchData, params=None, *, spread: float = 0.2,
                 noise: dict | None = None, outliers: float = 0.0, fit_noise=None,
                 loss: str = "huber", strategy: str = "staged", tir=None, centre=None):
        if not (spread > 0 and math.isfinite(spread)):
            raise InputError(f"spread {spread!r}: a relative spread > 0 (0.2 = ±20 %)")
        if not 0.0 <= outliers < 0.5:
            raise InputError(f"outliers {outliers!r}: a fraction in [0, 0.5)")
        fitted_names = default_names(start_model, programme.channels)
        self.hold = default_hold(start_model, fitted_names, tir)
        names = ([n for n in fitted_names if n not in self.hold] if params is None
                 else list(params))
        unknown = [n for n in names if n not in start_model.coefficients]
        if unknown:
            raise InputError(f"unknown coefficient(s) {', '.join(unknown)}")
        self.names = tuple(names)
        self.fit_names = tuple(dict.fromkeys((*fitted_names, *self.names)))
        self.hold = tuple(n for n in self.hold if n not in self.names)
        if noise is None:
            noise = {c: (20.0, 0.01) if c.startswith("F") else (20e3, 0.01)
                     for c in programme.channels}
        self.noise = {c: _noise_pair(v) for c, v in noise.items()}
        self.start, self.programme, self.spread = start_model, programme, float(spread)
        self.outliers, self.fit_noise, self.loss, self.strategy = (outliers, fit_noise, loss,
                                                                   strategy)
        self.centre = start_model if centre is None else centre
        if self.centre.nominal_load != start_model.nominal_load:
            raise InputError(f"centre FNOMIN {self.centre.nominal_load:g} N, the start's "
                             f"{start_model.nominal_load:g} N: the fit holds FNOMIN, so "
                             "write the centre for the start's (fit_start.renormalise)")
        self.x0 = np.array([float(self.centre[n]) for n in self.names])

    def draw(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """(n, p) truths x₀·(1 + spread·U(−1, 1))."""
        if int(n) < 1:
            raise InputError(f"{n} truths: at least 1")
        return self.x0 * (1.0 + self.spread * rng.uniform(-1.0, 1.0, (int(n), self.x0.size)))

    def truth_model(self, truth):
        return with_ranges(self.centre.replace(**dict(zip(self.names, map(float, truth),
                                                         strict=True))), self.programme)

    def identify(self, truths: np.ndarray, rng: np.random.Generator) -> list:
        reports = []
        for truth in np.atleast_2d(truths):
            data = simulate(self.truth_model(truth), self.programme, noise=self.noise,
                            seed=int(rng.integers(2**31)), outliers=self.outliers)
            _, rep = fit(self.start, data, self.fit_names, noise=self.fit_noise,
                         loss=self.loss, strategy=self.strategy, hold=self.hold)
            reports.append(rep)
        return reports


def plot_fit(model, data: BenchData, *, combined: bool = True, folder=None) -> dict:
    """Measured (dots) vs fitted (lines) against slip angle, one curve per (load, camber) group,
    one figure per channel; returns {channel: matplotlib Figure} and, with `folder`, writes
    `<channel>_measured_vs_fitted.png` there (figures closed after writing)."""
    import pathlib

    import matplotlib.pyplot as plt

    pred = np.asarray(_predict(model, data, combined))
    fz = np.round(np.asarray(data.fz), -1)
    ia = np.round(np.degrees(np.asarray(data.gamma)), 1)
    x = np.degrees(np.asarray(data.alpha))
    figures = {}
    for k, ch in enumerate(data.channels):
        fig, ax = plt.subplots(figsize=(7, 4.5))
        valid = np.asarray(data.valid[k])
        meas = np.asarray(data.measured[k])
        for load in np.unique(fz):
            for cam in np.unique(ia):
                sel = (fz == load) & (ia == cam) & valid
                if not sel.any():
                    continue
                order = np.argsort(x[sel])
                line, = ax.plot(x[sel][order], pred[k][sel][order], "-", lw=1,
                                label=f"{load:.0f} N, {cam:g}°")
                ax.plot(x[sel][order], meas[sel][order], ".", ms=3, color=line.get_color())
        ax.set_xlabel("slip angle [deg]")
        ax.set_ylabel(f"{ch} [{'N' if ch.startswith('F') else 'N·mm'}]")
        ax.set_title(f"{ch}: measured (dots) vs fitted")
        ax.legend(fontsize=6, ncol=2)
        fig.tight_layout()
        figures[ch] = fig
        if folder is not None:
            folder = pathlib.Path(folder)
            folder.mkdir(parents=True, exist_ok=True)
            fig.savefig(folder / f"{ch.lower()}_measured_vs_fitted.png", dpi=120)
            plt.close(fig)
    return figures
