"""Conditioning options of the bench table (thesis §1.3.3, §1.3.6.3; spec tyre §3.4): the
trapezoid integral of a channel and the selection of the samples that satisfy predicates.

The thesis's conditioning "retains only the trajectories that meet the model's hypotheses"
(§1.3.3: form packets of trajectories by user-defined criteria) and estimates the dynamic
quantities, "derivatives and integrals of a signal, by the trapezoid and centred-difference
methods". Its example (§1.3.6.3), the cornering stiffness of the linear model (1-1…1-5),
keeps the samples with load and slip variations only, a slip within ±1° and a steady state
(the slip rate near 0).

- `trapezoid(table, channel)`: ∫ channel dt per run (segment), by the trapezoid rule on the
  table's own time. Two integrals a bench engineer asks for: the distance rolled s = ∫V_T dt
  (a tyre's transient after a change of slip or load settles within a few relaxation lengths
  of distance, not of time) and the wheel angle θ = ∫ω dt (the phase of the wheel
  non-uniformity disturbance, spec §4.2, first order in θ).
- `select(table, bounds)`: the samples where every predicate holds, a predicate a range
  [lo, hi] of a channel (`"steer"`), of its time derivative (`"d:steer"`, the five-point
  centred difference of the conditioning) or of its integral (`"int:speed"`); the maximal
  runs of selected samples inside each segment cut into segments of a common length (the
  conditioning is batched over equal segments and filters each on its own), shorter runs
  dropped. `bench.identify` then runs on the selection: §1.3.6's small-slip steady samples
  (`{"steer": (-1°, 1°), "d:steer": (-ε, ε)}`), or the runs past their first metres
  (`{"int:speed": (s₀, inf)}`).

`diffsusp tyre identify --select CHANNEL:LO:HI` (repeatable, the table's library units:
rad, rad/s, mm, mm/s, N…) applies `select` before the identification.
"""

from collections.abc import Callable, Mapping

import numpy as np

from ..errors import InputError
from .bench_condition import centred_derivative

__all__ = ["trapezoid", "select", "parse_bound"]


def _runs(table: Mapping) -> list[np.ndarray]:
    """The row indices of each segment (contiguous rows of one `segment` value, in order)."""
    seg = np.asarray(table["segment"], float)
    if seg.ndim != 1 or len(seg) == 0:
        raise InputError("bench table: 'segment' must be a non-empty 1-D column")
    cut = np.flatnonzero(np.diff(seg) != 0) + 1
    runs = np.split(np.arange(len(seg)), cut)
    ids = [seg[r[0]] for r in runs]
    if len(set(ids)) != len(ids):
        raise InputError("bench table: the rows of a segment must be contiguous (sort by "
                         "segment, then time).")
    return runs


def _column(table: Mapping, channel: str) -> np.ndarray:
    if channel not in table:
        raise InputError(f"bench table: no channel {channel!r} (it has {', '.join(table)})")
    return np.asarray(table[channel], float)


def trapezoid(table: Mapping, channel: str) -> np.ndarray:
    """The running integral ∫ channel dt from the start of each segment (0 at its first row),
    by the trapezoid rule on the table's `t` [s] (thesis §1.3.3): one value per row, in the
    channel's unit × s (e.g. `speed` [mm/s] → the distance rolled [mm], `omega` [rad/s] → the
    wheel angle [rad])."""
    t, v = _column(table, "t"), _column(table, channel)
    out = np.zeros_like(v)
    for r in _runs(table):
        out[r[1:]] = np.cumsum(0.5 * (v[r[1:]] + v[r[:-1]]) * np.diff(t[r]))
    return out


def _derivative(table: Mapping, channel: str) -> np.ndarray:
    t, v = _column(table, "t"), _column(table, channel)
    out = np.zeros_like(v)
    for r in _runs(table):
        if len(r) < 5:
            raise InputError(f"bench table: a segment of {len(r)} rows is too short for the "
                             "derivative of a predicate (at least 5)")
        out[r] = centred_derivative(v[r], float(np.median(np.diff(t[r]))))
    return out


def _quantity(table: Mapping, key: str) -> np.ndarray:
    if key.startswith("d:"):
        return _derivative(table, key[2:])
    if key.startswith("int:"):
        return trapezoid(table, key[4:])
    return _column(table, key)


def select(table: Mapping, bounds: Mapping[str, tuple[float, float]] | None = None, *,
           predicate: Callable[[Mapping], np.ndarray] | None = None,
           duration: float = 0.5) -> dict[str, np.ndarray]:
    """The bench table restricted to the samples where every predicate holds (thesis
    §1.3.6.3): `bounds` maps a quantity to its range [lo, hi] (inclusive; ±inf for one side):
    a channel (`"steer"`), its time derivative (`"d:steer"`, five-point centred differences
    per segment) or its running integral from the segment's start (`"int:speed"`,
    `trapezoid`); `predicate` (optional) a function of the table returning a boolean per row,
    and-ed with them. Each maximal run of selected rows inside a segment is cut into whole
    segments of `duration` [s] (the conditioning filters equal segments; the tail of a run and
    runs shorter than `duration` are dropped), numbered 0, 1, … in order; every column is
    kept, rows as they are. Raises `InputError` when nothing is left."""
    cols = {k: np.asarray(v) for k, v in table.items()}
    n = len(_column(cols, "t"))
    keep = np.ones(n, bool)
    for key, rng in (bounds or {}).items():
        lo, hi = (float(x) for x in rng)
        if not lo <= hi:
            raise InputError(f"select {key!r}: the range [{lo:g}, {hi:g}] is empty")
        q = _quantity(cols, key)
        keep &= (q >= lo) & (q <= hi)
    if predicate is not None:
        mask = np.asarray(predicate(cols), bool)
        if mask.shape != (n,):
            raise InputError(f"select: the predicate returned shape {mask.shape}, not ({n},)")
        keep &= mask
    t = _column(cols, "t")
    rows, pieces = [], 0
    for r in _runs(cols):
        step = float(np.median(np.diff(t[r]))) if len(r) > 1 else np.inf
        m = int(round(duration / step)) if np.isfinite(step) else 0
        if m < 1:
            raise InputError(f"select: duration {duration:g} s is shorter than one sample")
        k = keep[r]
        edges = np.flatnonzero(np.diff(np.r_[0, k.astype(int), 0]))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            for c in range((b - a) // m):
                rows.append(r[a + c * m:a + (c + 1) * m])
                pieces += 1
    if not rows:
        raise InputError(f"select: no run of {duration:g} s satisfies "
                         + ", ".join(f"{k} in [{lo:g}, {hi:g}]" for k, (lo, hi) in
                                     (bounds or {}).items())
                         + (" and the predicate" if predicate is not None else "")
                         + "; widen the ranges or shorten the duration.")
    idx = np.concatenate(rows)
    out = {k: v[idx] for k, v in cols.items()}
    out["segment"] = np.repeat(np.arange(pieces, dtype=float), [len(r) for r in rows])
    return out


def parse_bound(text: str) -> tuple[str, tuple[float, float]]:
    """"CHANNEL:LO:HI" (the CLI's `--select`; LO or HI may be empty for ∓inf) → (channel,
    (lo, hi)). CHANNEL may be `d:NAME` or `int:NAME`."""
    parts = text.rsplit(":", 2)
    if len(parts) != 3 or not parts[0]:
        raise InputError(f"--select {text!r}: write CHANNEL:LO:HI (e.g. steer:-0.01745:0.01745"
                         ", d:steer:-0.01:0.01, int:speed:500:)")
    try:
        lo = float(parts[1]) if parts[1].strip() else -np.inf
        hi = float(parts[2]) if parts[2].strip() else np.inf
    except ValueError:
        raise InputError(f"--select {text!r}: LO and HI must be numbers (or empty)") from None
    if not lo <= hi:
        raise InputError(f"--select {text!r}: the range [{lo:g}, {hi:g}] is empty")
    return parts[0], (lo, hi)
