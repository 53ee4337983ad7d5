"""Magic Formula coefficients from bench data: robust Levenberg–Marquardt with exact Jacobians.

spec: tyre §7 E item 22 (nonlinear least-squares refinement), §7 D item 18 (the report of the
guaranteed least squares), issue 15 item 3. The same report style as the suspension fits: σ, σ %,
identifiable or not, the combinations the data determine (from `diffsusp.lsq` on the
linearisation at the optimum).

```python
data = tyre.fit.bench_data(io.read_table("bench.csv"))            # FZ, SA, ..., FY [N], ...
fitted, report = tyre.fit.fit(start, data, names=tyre.fit.GROUPS["pure_lateral"],
                              channels=("FY",), noise={"FY": 20.0}, loss="huber")
print(report.table()); fitted.to_tir(template)
```

**Method.** Residuals z = (model − measured)/σ per channel (whitened by the channel's noise σ,
in the channel's units: N, N·mm), passed through the robust loss as r = sgn(z)·√(2ρ(z)) so that
Σr² = 2Σρ(z): Huber ρ = z²/2 (|z| ≤ k), k|z| − k²/2 beyond; Cauchy ρ = (k²/2)·log(1 + (z/k)²);
"linear" the plain sum of squares. `optimistix.LevenbergMarquardt` minimises Σr² with the
Jacobian by forward-mode autodiff (exact). **Bounds by reparametrisation**: the shape factors
and peak frictions that must be positive (`POSITIVE`: p_Cx1, p_Cy1, q_Cz1, r_Cx1, r_Cy1, p_Dx1,
p_Dy1) are fitted as x = x₀·exp(u), the others as x = x₀ + s·u with s = max(|x₀|, 0.1) (scaling
only). The curvature factors (E_x, E_y, E_t ≤ 1) and C, D > 0 are **checked over the data's
range** after the fit and reported in `report.violations`.

**Report.** At the optimum the robust residuals are linearised in the coefficients (Jacobian J
in coefficient space) and `diffsusp.lsq.solve(J, J·x̂ − r, prior=x̂)` gives σ (from
(JᵀJ)⁻¹·σ̂²; σ̂² = Σr²/(n − rank), ≈ 1 when the noise σ's are right), σ %, correlations,
which coefficients are identifiable and the identifiable combinations of the others (relative
threshold `threshold` on unit-norm columns, default 1e-8).
"""

import dataclasses
import json
import math
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .. import lsq
from ..errors import InputError, ModelWarning
from . import mf6, mf89

__all__ = ["BenchData", "TyreFitReport", "bench_data", "default_groups", "read_bench",
           "read_bench_table", "input_columns", "simulate", "fit", "fit_many", "GROUPS",
           "POSITIVE", "CHANNELS", "COLUMN_ALIASES", "check_constraints", "plot_fit"]

CHANNELS = ("FX", "FY", "MX", "MY", "MZ")
"""Measured channels: forces [N], moments [N·mm] (library units)."""
POSITIVE = frozenset({"PCX1", "PCY1", "QCZ1", "RCX1", "RCY1", "PDX1", "PDY1"})

GROUPS = {
    "pure_longitudinal": ("PCX1 PDX1 PDX2 PDX3 PEX1 PEX2 PEX3 PEX4 PKX1 PKX2 PKX3 PHX1 PHX2 "
                          "PVX1 PVX2").split(),
    "pure_lateral": ("PCY1 PDY1 PDY2 PDY3 PEY1 PEY2 PEY3 PEY4 PEY5 PKY1 PKY2 PKY3 PKY4 PKY5 "
                     "PKY6 PKY7 PHY1 PHY2 PVY1 PVY2 PVY3 PVY4").split(),
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


def _unit_scale(col: str, unit: str | None, path) -> float:
    from ..io.tables import unit_factor

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
        return np.asarray(table[canon[c]], dtype=float) * _unit_scale(
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
    import os

    from ..errors import ModelFileError
    from ..io.tables import Table, read_table, split_header

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
            cols[c] = np.asarray(table[name], float) * _unit_scale(c, table.units.get(name),
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
    if isinstance(model, mf6.MagicFormula6):
        vx = jnp.where(jnp.isnan(data.vx), model["LONGVL"], data.vx)
        p = jnp.where(jnp.isnan(data.pressure), model["INFLPRES"], data.pressure)
        out = mf6.evaluate(model, data.fz, data.kappa, data.alpha, data.gamma, vx, p,
                           combined=combined, outputs=tuple(c.lower() for c in data.channels))
        d = {"FX": out.fx, "FY": out.fy, "MX": out.mx, "MY": out.my, "MZ": out.mz}
    elif isinstance(model, mf89.MagicFormula89):
        if combined:
            fx, fy, mz = mf89.evaluate(model, data.fz, data.kappa, data.alpha, data.gamma)
        else:
            deg = 180.0 / math.pi
            fz = data.fz / 1000.0
            fx = mf89.fx0(model, data.kappa, fz)
            fy = mf89.fy0(model, data.alpha * deg, fz, data.gamma * deg)
            mz = 1000.0 * mf89.mz0(model, data.alpha * deg, fz, data.gamma * deg)
        d = {"FX": fx, "FY": fy, "MZ": mz}
    else:
        raise TypeError(f"a MagicFormula6 or MagicFormula89, got {type(model).__name__}")
    try:
        return jnp.stack([jnp.broadcast_to(d[c], data.fz.shape) for c in data.channels])
    except KeyError as e:
        raise InputError(f"channel {e.args[0]} is not an output of {type(model).__name__}"
                         ) from None


def simulate(model, data: BenchData, *, noise: dict | None = None, seed: int = 0,
             combined: bool = True) -> BenchData:
    """The data's inputs with the model's outputs as measurements, plus Gaussian noise of σ
    `noise[channel]` (channel units: N, N·mm). For tests, examples and benchmarks."""
    y = np.array(_predict(model, data, combined))
    rng = np.random.default_rng(seed)
    for k, c in enumerate(data.channels):
        s = (noise or {}).get(c, 0.0)
        y[k] = y[k] + s * rng.standard_normal(y.shape[1])
    return BenchData(data.fz, data.kappa, data.alpha, data.gamma, data.vx, data.pressure,
                     jnp.asarray(y), jnp.ones(y.shape, bool), data.channels)


LOSSES = ("linear", "huber", "cauchy")


def _robust(z, code, k):
    """sgn(z)·√(2ρ(z)) for the loss `LOSSES[code]` (traced: one compiled program for all)."""
    a = jnp.abs(z)
    safe = jnp.maximum(a, k)
    huber = jnp.where(a <= k, z, jnp.sign(z) * jnp.sqrt(2.0 * k * safe - k * k))
    small = a < 1e-8 * k
    zs = jnp.where(small, 1.0, z)
    cauchy = jnp.where(small, z, jnp.sign(zs) * k * jnp.sqrt(jnp.log1p((zs / k) ** 2)))
    return jnp.where(code == 0, z, jnp.where(code == 1, huber, cauchy))


class _Problem(eqx.Module):
    model: eqx.Module
    data: BenchData
    x0: jax.Array
    scale: jax.Array
    positive: jax.Array
    sigma: jax.Array
    loss_code: jax.Array
    k: jax.Array
    names: tuple[str, ...] = eqx.field(static=True)
    combined: bool = eqx.field(static=True)

    @property
    def loss(self) -> str:
        return LOSSES[int(self.loss_code)]

    def x_of(self, u):
        return jnp.where(self.positive, self.x0 * jnp.exp(u), self.x0 + self.scale * u)

    def with_x(self, x):
        c = dict(self.model.coefficients)
        for i, n in enumerate(self.names):
            c[n] = x[i]
        return type(self.model)(c, *_static(self.model))

    def whitened(self, x):
        pred = _predict(self.with_x(x), self.data, self.combined)
        z = (pred - self.data.measured) / self.sigma[:, None]
        return jnp.where(self.data.valid, z, 0.0)

    def residual_x(self, x):
        return _robust(self.whitened(x), self.loss_code, self.k).ravel()

    def residual_u(self, u, _args=None):
        return self.residual_x(self.x_of(u))


def _static(model):
    if isinstance(model, mf6.MagicFormula6):
        return (model.version, model.limits)
    return ()


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


@dataclasses.dataclass
class TyreFitReport:
    """The result of a Magic Formula fit (same base API as the suspension fits).

    **Fields:** `names`, `start`, `values` (fitted coefficients, library units), `sigma`,
    `sigma_pct`, `identifiable` (bool per coefficient), `correlation` (p, p; NaN rows for
    non-identifiable ones), `combinations` (text of the identifiable combinations of the
    others), `linear` (the `diffsusp.lsq.Fit` of the linearisation: every detail), `rms` (per
    channel, unweighted, channel units, valid points), `n_points` (valid per channel),
    `residual_sigma` (σ̂ of the whitened robust residual: ≈ 1 when the noise σ's are right),
    `steps`, `converged`, `loss`, `violations` (constraint checks over the data's range).
    """

    names: tuple[str, ...]
    start: np.ndarray
    values: np.ndarray
    sigma: np.ndarray
    sigma_pct: np.ndarray
    identifiable: np.ndarray
    correlation: np.ndarray
    combinations: list[str]
    linear: lsq.Fit
    rms: dict[str, float]
    n_points: dict[str, int]
    residual_sigma: float
    steps: int
    converged: bool
    loss: str
    violations: list[str]

    @property
    def unidentifiable(self) -> tuple[str, ...]:
        return tuple(n for n, ok in zip(self.names, self.identifiable, strict=True)
                     if not ok)

    def value(self, name: str) -> float:
        return float(self.values[self.names.index(name)])

    def table(self) -> str:
        lines = [f"Magic Formula fit ({self.loss} loss): {'converged' if self.converged else 'NOT converged'} in {self.steps} steps; "  # noqa: E501
                 f"residual sigma {self.residual_sigma:.4g} (whitened)",
                 "rms: " + ", ".join(f"{c} {v:.4g} ({self.n_points[c]} points)"
                                     for c, v in self.rms.items())]
        w = max(9, *(len(n) for n in self.names))
        lines.append(f"{'parameter':<{w}}  {'start':>12}  {'value':>12}  {'sigma':>10}  "
                     f"{'sigma%':>8}  status")
        for i, n in enumerate(self.names):
            status = "" if self.identifiable[i] else self.linear._status(i) or "not identifiable"
            s = f"{self.sigma[i]:.3g}" if np.isfinite(self.sigma[i]) else "-"
            sp = f"{self.sigma_pct[i]:.3g}%" if np.isfinite(self.sigma_pct[i]) else "-"
            lines.append(f"{n:<{w}}  {self.start[i]:>12.6g}  {self.values[i]:>12.6g}  "
                         f"{s:>10}  {sp:>8}  {status}")
        if self.combinations:
            lines.append("identifiable combinations:")
            lines += [f"  {c}" for c in self.combinations]
        if self.violations:
            lines.append("constraint checks over the data's range:")
            lines += [f"  {v}" for v in self.violations]
        return "\n".join(lines)

    def __str__(self):
        return self.table()

    def to_dict(self) -> dict:
        def f(v):
            return None if not np.isfinite(v) else float(v)
        return {"names": list(self.names), "start": [float(v) for v in self.start],
                "values": [float(v) for v in self.values], "sigma": [f(v) for v in self.sigma],
                "sigma_pct": [f(v) for v in self.sigma_pct],
                "identifiable": [bool(v) for v in self.identifiable],
                "combinations": self.combinations, "rms": self.rms, "n_points": self.n_points,
                "residual_sigma": self.residual_sigma, "steps": self.steps,
                "converged": self.converged, "loss": self.loss, "violations": self.violations}

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2)

    def to_frame(self):
        import pandas as pd
        return pd.DataFrame({"start": self.start, "value": self.values, "sigma": self.sigma,
                             "sigma_pct": self.sigma_pct, "identifiable": self.identifiable},
                            index=list(self.names))


def check_constraints(model, data: BenchData) -> list[str]:
    """The usual physical constraints over the data's range of load (and camber, pressure):
    C_x, C_y, C_t > 0, D_x, D_y > 0 (μ > 0), E_x, E_y ≤ 1 (MF 6.x names; spec: tyre §7 C)."""
    if not isinstance(model, mf6.MagicFormula6):
        return []
    c = {k: float(v) for k, v in model.coefficients.items()}
    fz = np.linspace(float(jnp.min(data.fz)), float(jnp.max(data.fz)), 21)
    g = np.linspace(float(jnp.min(data.gamma)), float(jnp.max(data.gamma)), 7)[:, None]
    dfz = (fz - c["LFZO"] * c["FNOMIN"]) / (c["LFZO"] * c["FNOMIN"])
    out = []
    for name, v in (("C_x = PCX1·LCX", c["PCX1"] * c["LCX"]), ("C_y = PCY1·LCY",
                                                              c["PCY1"] * c["LCY"]),
                    ("C_t = QCZ1", c["QCZ1"])):
        if v <= 0:
            out.append(f"{name} = {v:.4g} is not > 0")
    mux = (c["PDX1"] + c["PDX2"] * dfz) * (1 - c["PDX3"] * g**2)
    muy = (c["PDY1"] + c["PDY2"] * dfz) * (1 - c["PDY3"] * g**2)
    for name, v in (("mu_x (D_x/F_z)", mux), ("mu_y (D_y/F_z)", muy)):
        if np.min(v) <= 0:
            out.append(f"{name} reaches {np.min(v):.4g} <= 0 in the data's range")
    ex = (c["PEX1"] + c["PEX2"] * dfz + c["PEX3"] * dfz**2)[None, :] * (
        1 - c["PEX4"] * np.array([[-1.0], [1.0]]))
    ey = (c["PEY1"] + c["PEY2"] * dfz) * (1 + c["PEY5"] * g**2 - (c["PEY3"] + c["PEY4"] * g))
    ey2 = (c["PEY1"] + c["PEY2"] * dfz) * (1 + c["PEY5"] * g**2 + (c["PEY3"] + c["PEY4"] * g))
    for name, v in (("E_x", ex), ("E_y", np.concatenate([ey, ey2]))):
        if np.max(v) > 1:
            out.append(f"{name} reaches {np.max(v):.4g} > 1 in the data's range (clipped at 1)")
    return out


def _prepare(model, data, names, noise, loss, loss_scale, combined):
    names = tuple(names)
    if loss not in LOSSES:
        raise InputError(f"loss {loss!r}: one of {', '.join(LOSSES)}")
    unknown = [n for n in names if n not in model.coefficients]
    if unknown:
        raise InputError(f"unknown coefficient(s) {', '.join(unknown)} for "
                         f"{type(model).__name__}")
    x0 = np.array([float(model.coefficients[n]) for n in names])
    positive = np.array([n in POSITIVE for n in names])
    bad = positive & (x0 <= 0)
    if bad.any():
        raise InputError(f"start values of {', '.join(np.array(names)[bad])} must be > 0 "
                         "(fitted as x0·exp(u))")
    meas = np.asarray(data.measured)
    valid = np.asarray(data.valid)
    sig = []
    for k, c in enumerate(data.channels):
        if noise is not None and c in noise:
            sig.append(float(noise[c]))
        else:
            v = meas[k][valid[k]]
            spread = float(v.max() - v.min()) if v.size else 0.0
            sig.append(0.01 * spread if spread > 0 else 1.0)
    return _Problem(model, data, jnp.asarray(x0), jnp.asarray(np.maximum(np.abs(x0), 0.1)),
                    jnp.asarray(positive), jnp.asarray(sig), jnp.asarray(LOSSES.index(loss)),
                    jnp.asarray(float(loss_scale)), names, combined)


def _report(problem, x, steps, ok, threshold):
    names = problem.names
    r, J = (np.asarray(a) for a in _linearise(problem, jnp.asarray(x)))
    x = np.asarray(x)
    rows = np.asarray(problem.data.valid).ravel()
    lin = lsq.solve(J[rows], J[rows] @ x - r[rows], names=names, prior=x, threshold=threshold)
    cov = np.asarray(lin.covariance)
    sd = np.sqrt(np.abs(np.diag(cov)))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sd, sd)
    ident = np.asarray(lin.identifiable, bool)
    corr[~ident, :] = np.nan
    corr[:, ~ident] = np.nan
    sigma = np.where(ident, np.asarray(lin.sigma), np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        pct = 100.0 * sigma / np.abs(x)
    fitted = problem.with_x(jnp.asarray(x))
    pred = np.asarray(_predict(fitted, problem.data, problem.combined))
    meas, valid = np.asarray(problem.data.measured), np.asarray(problem.data.valid)
    rms = {c: float(np.sqrt(np.mean((pred[k] - meas[k])[valid[k]] ** 2)))
           for k, c in enumerate(problem.data.channels)}
    npts = {c: int(valid[k].sum()) for k, c in enumerate(problem.data.channels)}
    return fitted, TyreFitReport(
        names, np.asarray(problem.x0), x, sigma, pct, ident, corr, list(lin.relations), lin,
        rms, npts, float(lin.residual_sigma), int(steps), bool(ok), problem.loss,
        check_constraints(fitted, problem.data))


def fit(model, data: BenchData, names, *, noise: dict | None = None, loss: str = "huber",
        loss_scale: float = 1.345, combined: bool = True, max_steps: int = 200,
        rtol: float = 1e-9, atol: float = 1e-9, threshold: float = 1e-8):
    """Fit the coefficients `names` of `model` (a `MagicFormula6` or `MagicFormula89`) to `data`.

    **Arguments:** `names` (e.g. `GROUPS["pure_lateral"]`; the others stay at the model's
    values: fitting mode by mode is a sequence of calls, jointly one call with the union);
    `noise` per channel σ [N or N·mm] (default 1 % of the channel's range); `loss` "huber",
    "cauchy" or "linear", `loss_scale` k in units of σ; `combined=False` fits the pure-slip
    functions (data at zero of the other slip); LM tolerances; `threshold` of identifiability.

    **Returns:** (fitted model, `TyreFitReport`). See the module docstring for the method.
    """
    problem = _prepare(model, data, names, noise, loss, loss_scale, combined)
    u0 = jnp.zeros(len(problem.names))
    x, steps, ok = _solve(problem, u0, max_steps, rtol, atol)
    return _report(problem, x, steps, ok, threshold)


def default_groups(model, channels) -> list[str]:
    """The coefficient groups fitted, in order, when none are named (`diffsusp tyre fit`, the
    fleet's tyre fits): `mf1989_lateral` for a 1989 tyre (`MagicFormula89`), otherwise
    pure_lateral, pure_longitudinal and pure_aligning as the bench data's `channels` allow."""
    from .mf89 import MagicFormula89

    if isinstance(model, MagicFormula89):
        return ["mf1989_lateral"]
    return [g for g, ch in (("pure_lateral", "FY"), ("pure_longitudinal", "FX"),
                            ("pure_aligning", "MZ")) if ch in channels]


def fit_many(models, datas, names, *, noise: dict | None = None, loss: str = "huber",
             loss_scale: float = 1.345, combined: bool = True, max_steps: int = 200,
             rtol: float = 1e-9, atol: float = 1e-9, threshold: float = 1e-8):
    """Many tyres in one batched (vmapped) call: `models` and `datas` are sequences of equal
    length whose data have equal shapes (pad with `valid=False` rows otherwise). Returns lists
    of fitted models and reports."""
    problems = [_prepare(m, d, names, noise, loss, loss_scale, combined)
                for m, d in zip(models, datas, strict=True)]
    stacked = jax.tree.map(lambda *a: jnp.stack(a), *problems)
    u0 = jnp.zeros((len(problems), len(problems[0].names)))
    X, S, OK = _solve_many(stacked, u0, max_steps, rtol, atol)
    out = [_report(p, X[i], S[i], OK[i], threshold) for i, p in enumerate(problems)]
    return [o[0] for o in out], [o[1] for o in out]


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
