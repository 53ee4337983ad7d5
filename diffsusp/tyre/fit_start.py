"""What the bench data say before any fit: the noise of each channel and starting values of the
Magic Formula's scale coefficients (private helpers of `diffsusp.tyre.fit`).

spec: tyre §7 E item 22 (the refinement needs a start in the basin of the optimum), tyre §7 C
(the coefficients' roles: D = μ·F_z the peak, B·C·D = K the slope at the origin).

**Sweeps.** Bench programmes are sweeps: one slip varied at fixed load, camber and pressure.
Rows are grouped into sweeps by (load within 2 %, camber, pressure, which slip varies: lateral
when κ = 0, longitudinal when α = 0) and ordered by the varied slip.

**Noise from the data alone** (`estimate_noise`). Within a sweep the measured curve is smooth
at the slip step of a bench programme: the normalised third difference
d = (y₃ − 3y₂ + 3y₁ − y₀)/√20 of four neighbours removes any quadratic and leaves the noise
(variance σ² for white noise of σ); on coarse sweeps, where the curve's own bending shows in
the third differences, the fifth (a quartic removed, /√252). Force rigs' noise grows with the
force, so per channel the model σ = a + b·|F| is fitted to the robust scale 1.4826·median|d|
of up to six groups of differences ordered by the measured level. Medians keep the estimate
within about 10 % with a few percent of gross outliers (each spoils four differences). The
estimate does not use the Magic Formula at all: it is the yardstick the fit's residual is
judged against.

**Starting values from the data** (`data_start`). At zero camber, per load: the peak |F| (the
friction μ·F_z, sign kept from the start file: the sign of D is a convention, D·B is what the
data fix), the slope at the origin (a cubic through the central third of the sweep: K), and for
M_z the trail −M_z/F_y near α = 0 (D_t). The start model's own values of the same estimators
at the same points give per-load ratios data/model; the load polynomials of μ (PDY1, PDY2;
PDX1, PDX2), of the slip stiffness (PKX1, PKX2; PKY1 scaled) and of the peak trail (QDZ1,
QDZ2) are refitted through those ratios. A start file of another tyre (another nominal load,
other friction, stiffness, trail) is brought to the data's level this way before the least
squares.
"""

import math

import numpy as np

__all__ = ["sweeps", "estimate_noise", "noise_sigma", "data_start"]


def sweeps(fz, kappa, alpha, gamma, pressure) -> list[tuple[str, np.ndarray]]:
    """(kind, row indices ordered by the varied slip) per sweep of at least 4 rows; kind is
    "lateral" (κ = 0, α varied) or "longitudinal" (α = 0, κ varied)."""
    fz, kappa, alpha, gamma = (np.asarray(v, float) for v in (fz, kappa, alpha, gamma))
    p = np.nan_to_num(np.asarray(pressure, float), nan=-1.0)
    lateral = kappa == 0.0
    longitudinal = (alpha == 0.0) & ~lateral
    level = np.round(np.log(np.maximum(np.abs(fz), 1.0)) / 0.02)
    out = []
    for kind, sel, slip in (("lateral", lateral, alpha), ("longitudinal", longitudinal, kappa)):
        idx = np.flatnonzero(sel)
        if idx.size == 0:
            continue
        keys = np.stack([level[idx], np.round(gamma[idx], 6), np.round(p[idx], 0)], axis=1)
        _, group = np.unique(keys, axis=0, return_inverse=True)
        for g in np.unique(group):
            rows = idx[group.ravel() == g]
            rows = rows[np.argsort(slip[rows], kind="stable")]
            if rows.size >= 4 and np.ptp(slip[rows]) > 0:
                out.append((kind, rows))
    return out


def _differences(y, rows, order=3):
    """The normalised `order`-th differences of a sweep's values (variance σ² for white noise of
    σ: the binomial weights over √C(2k, k)) and the mean |level| of each window."""
    v = y[rows]
    w = np.array([(-1.0) ** (order - j) * math.comb(order, j) for j in range(order + 1)])
    d = np.convolve(v, w / math.sqrt(math.comb(2 * order, order)), mode="valid")
    level = np.convolve(np.abs(v), np.full(order + 1, 1.0 / (order + 1)), mode="valid")
    return d, level


def _third_differences(y, rows):
    return _differences(y, rows, 3)


COARSE_RATIO = 1.15
"""The third differences' robust scale beyond this multiple of the fifth differences': the
sweeps are coarse for the curve (its own bending shows in the third differences)."""

DOF_FACTOR = {3: 1.0, 5: 4.4 / 5.7}
"""Differences of order k worth as many third differences (the median scale of 9 sweeps of 41
points of white noise: variance 2·4.4/n for third, 2·5.7/n for fifth differences)."""


def estimate_noise(data) -> dict[str, tuple[float, float, int]]:
    """Per channel (a, b, n) of the noise model σ = a + b·|F| from the sweeps' differences
    (see the module docstring), n the number of third differences the estimate is worth (the
    F law of the consistency check); channels without a sweep are left out.

    Third differences remove a quadratic; at the slip step of a coarse programme the curve's
    own third derivative shows in them (33–39 N on exact data of the FEDA tyre with 21 slip
    angles over ±0.2 rad, 11 N with 31): where their robust scale exceeds the fifth
    differences' by `COARSE_RATIO`, the fifth differences (a quartic removed: 3–4 N, 0.5 N)
    are used. On fine sweeps the third differences stay (a spike spoils four differences,
    not six)."""
    sw = sweeps(data.fz, data.kappa, data.alpha, data.gamma, data.pressure)
    meas, valid = np.asarray(data.measured), np.asarray(data.valid)
    out = {}
    for k, ch in enumerate(data.channels):
        per_order = {}
        for order in (3, 5):
            ds, ls = [], []
            for _, rows in sw:
                rows = rows[valid[k][rows]]
                if rows.size >= order + 1:
                    d, lev = _differences(meas[k], rows, order)
                    ds.append(d)
                    ls.append(lev)
            if ds:
                per_order[order] = (np.concatenate(ds), np.concatenate(ls))
        if 3 not in per_order:
            continue
        order = 3
        if 5 in per_order and per_order[5][0].size >= 30:
            s3, s5 = (1.4826 * float(np.median(np.abs(per_order[o][0]))) for o in (3, 5))
            if s3 > COARSE_RATIO * s5:
                order = 5
        d, lev = per_order[order]
        out[ch] = (*scale_model(d, lev), int(round(d.size * DOF_FACTOR[order])))
    return out


def scale_model(d, lev):
    """a, b of σ = a + b·level from robust group scales (medians), b ≥ 0, a > 0."""
    n_groups = int(min(6, max(1, d.size // 30)))
    order = np.argsort(lev)
    groups = np.array_split(order, n_groups)
    s = np.array([1.4826 * np.median(np.abs(d[g])) for g in groups])
    L = np.array([np.median(lev[g]) for g in groups])
    w = np.array([g.size for g in groups], float)
    floor = 1e-12 * max(float(np.max(lev)), 1.0)
    if n_groups >= 2 and np.ptp(L) > 0:
        A = np.stack([np.ones_like(L), L], axis=1) * np.sqrt(w)[:, None]
        a, b = np.linalg.lstsq(A, s * np.sqrt(w), rcond=None)[0]
        if b < 0:
            a, b = float(np.sum(w * s) / np.sum(w)), 0.0
        elif a < 0:
            a, b = 0.0, float(np.sum(w * s * L) / np.sum(w * L * L))
    else:
        a, b = float(np.median(s)), 0.0
    # a floor proportional to the scale: σ never 0 at F = 0 (weights stay finite)
    a = max(float(a), 0.02 * float(b) * float(np.median(lev)), floor)
    return a, float(b)


def noise_sigma(noise_ab: dict, data) -> np.ndarray:
    """(c, n) σ per point from {channel: (a, b)} at the measured level |F| (1 for a channel
    without a model)."""
    meas = np.abs(np.asarray(data.measured))
    out = np.ones_like(meas)
    for k, ch in enumerate(data.channels):
        if ch in noise_ab:
            a, b = noise_ab[ch][:2]
            out[k] = a + b * meas[k]
    return out


def _median3(y):
    """Running median of three neighbours (ends kept): a spike does not make a peak or a
    slope."""
    y = np.asarray(y, float)
    if y.size < 3:
        return y
    out = y.copy()
    out[1:-1] = np.median(np.stack([y[:-2], y[1:-1], y[2:]]), axis=0)
    return out


def _central_slope(x, y):
    """Slope at x = 0 of a cubic through the central third of a sweep (at least 4 points)."""
    half = np.max(np.abs(x))
    sel = np.abs(x) <= max(half / 3.0, np.sort(np.abs(x))[min(3, x.size - 1)])
    xs, ys = x[sel], y[sel]
    deg = int(min(3, xs.size - 1))
    return float(np.polyfit(xs, ys, deg)[-2]) if deg >= 1 else math.nan


def _per_load(data, pred, channel, kind, what):
    """Per zero-camber sweep of `kind`: (F_z, data value, model value) of `what` ("peak",
    "slope", "trail")."""
    if channel not in data.channels or (what == "trail" and "FY" not in data.channels):
        return []
    k = data.channels.index(channel)
    meas, valid = np.asarray(data.measured), np.asarray(data.valid)
    fz, g = np.asarray(data.fz), np.asarray(data.gamma)
    slip = np.asarray(data.alpha if kind == "lateral" else data.kappa)
    out = []
    for kd, rows in sweeps(data.fz, data.kappa, data.alpha, data.gamma, data.pressure):
        if kd != kind or abs(float(np.median(g[rows]))) > 1e-9:
            continue
        rows = rows[valid[k][rows]]
        if rows.size < 5:
            continue
        x = slip[rows]
        vals = []
        for y in (_median3(meas[k][rows]), pred[k][rows]):
            if what == "peak":
                vals.append(float(np.max(np.abs(y))))
            elif what == "slope":
                vals.append(_central_slope(x, y))
            else:
                j = data.channels.index("FY")
                fy = _median3(meas[j][rows]) if not vals else pred[j][rows]
                sel = np.abs(x) <= max(np.max(np.abs(x)) / 6.0, np.sort(np.abs(x))[2])
                sel &= np.abs(fy) > 1e-9 * np.max(np.abs(fy))
                vals.append(-_central_slope(x[sel], y[sel]) / _central_slope(x[sel], fy[sel])
                            if sel.sum() >= 4 else math.nan)
        if all(np.isfinite(vals)) and vals[1] != 0:
            out.append((float(np.median(fz[rows])), vals[0], vals[1]))
    return out


def _refit_linear(c, names, dfz_of, rows):
    """New (c0, c1) of a load polynomial c0 + c1·df_z that multiplies the model's value by the
    per-load ratio data/model; None without usable rows. One load: c0, c1 both scaled."""
    c0, c1 = (float(c[n]) for n in names)
    if not rows:
        return None
    dfz = np.array([dfz_of(f) for f, _, _ in rows])
    ratio = np.array([d / m for _, d, m in rows])
    target = ratio * (c0 + c1 * dfz)
    if len(rows) == 1 or np.ptp(dfz) < 1e-6:
        r = float(np.median(ratio))
        return (c0 * r, c1 * r) if r > 0 else None
    A = np.stack([np.ones_like(dfz), dfz], axis=1)
    n0, n1 = np.linalg.lstsq(A, target, rcond=None)[0]
    if not (np.isfinite(n0) and np.isfinite(n1)) or n0 * c0 <= 0:
        return None  # the sign convention of the start file is kept
    return float(n0), float(n1)


def data_start(model, data, names, predict) -> dict[str, float]:
    """Starting values (library units) of the scale coefficients among `names` from the data's
    zero-camber sweeps (module docstring); `predict(model)` gives the model's (c, n) outputs at
    the data's inputs. Coefficients the data cannot inform are not returned."""
    c = {k: float(v) for k, v in model.coefficients.items()}
    fz0 = c["LFZO"] * c["FNOMIN"]

    def dfz_of(f):
        return (f - fz0) / fz0

    out = {}
    pred = np.asarray(predict(model))
    plan = [("FY", "lateral", "peak", ("PDY1", "PDY2")),
            ("FX", "longitudinal", "peak", ("PDX1", "PDX2")),
            ("FX", "longitudinal", "slope", ("PKX1", "PKX2"))]
    for ch, kind, what, pair in plan:
        if pair[0] not in names:
            continue
        new = _refit_linear(c, pair, dfz_of, _per_load(data, pred, ch, kind, what))
        if new is not None:
            out[pair[0]] = new[0]
            if pair[1] in names:
                out[pair[1]] = new[1]
    if "PKY1" in names:
        rows = _per_load(data, pred, "FY", "lateral", "slope")
        ratio = [d / m for _, d, m in rows]
        if ratio and np.median(ratio) > 0:
            out["PKY1"] = c["PKY1"] * float(np.median(ratio))
    if out:  # the trail against the start's F_y scaled as above
        model = model.replace(**out)
        pred = np.asarray(predict(model))
        c.update(out)
    if "QDZ1" in names:
        new = _refit_linear(c, ("QDZ1", "QDZ2"), dfz_of,
                            _per_load(data, pred, "MZ", "lateral", "trail"))
        if new is not None:
            out["QDZ1"] = new[0]
            if "QDZ2" in names:
                out["QDZ2"] = new[1]
    return out


_LINEAR = (("PDX1", "PDX2"), ("PDY1", "PDY2"), ("PEY1", "PEY2"), ("PHX1", "PHX2"),
           ("PVX1", "PVX2"), ("PHY1", "PHY2"), ("PVY1", "PVY2"), ("PVY3", "PVY4"),
           ("QHZ1", "QHZ2"), ("QHZ3", "QHZ4"), ("QDZ6", "QDZ7"), ("QDZ8", "QDZ9"),
           ("QDZ10", "QDZ11"), ("PKY6", "PKY7"), ("PKX1", "PKX2"))
_QUADRATIC = (("PEX1", "PEX2", "PEX3"), ("QBZ1", "QBZ2", "QBZ3"), ("QEZ1", "QEZ2", "QEZ3"))


def renormalise(model, fnomin: float):
    """The same pure-slip F_x, F_y, M_z model written for another nominal load `fnomin` [N]:
    the load polynomials in df_z = (F_z − F'_z0)/F'_z0 re-expanded (exactly) in the new df_z,
    the stiffness terms PKY1, PKY2 (and PKY5) and the trail peak (QDZ1, QDZ2) scaled, the
    exponential PKX3 rescaled into PKX1, PKX2. Two files that differ only in FNOMIN describe the
    same tyre: a fit holds FNOMIN at the start file's, so its coefficients are the truth's in
    that normalisation (spec: tyre §7 C). Exact (to rounding) for MF 5.2 (FITTYP 5/6, the
    PAC2002 files); MF 6.x pressure and turn-slip terms and the combined-slip coefficients are
    not re-expanded."""
    c = {k: float(v) for k, v in model.coefficients.items()}
    s = float(fnomin) / c["FNOMIN"]   # df_z,old = (s − 1) + s·df_z,new
    d0, d1 = s - 1.0, s
    new = {"FNOMIN": float(fnomin)}
    for a, b in _LINEAR:
        new[a], new[b] = c[a] + c[b] * d0, c[b] * d1
    for a, b, q in _QUADRATIC:
        new[a] = c[a] + c[b] * d0 + c[q] * d0 * d0
        new[b] = c[b] * d1 + 2.0 * c[q] * d0 * d1
        new[q] = c[q] * d1 * d1
    e = math.exp(c["PKX3"] * d0)
    new["PKX1"], new["PKX2"] = new["PKX1"] * e, new["PKX2"] * e
    new["PKX3"] = c["PKX3"] * d1
    for k in ("PKY1", "PKY2", "PKY5"):
        new[k] = c[k] / s
    # D_t = poly·F_z·R0/F'_z0: the polynomial times s
    new["QDZ1"], new["QDZ2"] = s * (c["QDZ1"] + c["QDZ2"] * d0), s * c["QDZ2"] * d1
    return model.replace(**new)
