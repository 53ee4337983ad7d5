"""The least-squares report: `Fit` (estimates, σ, σ %, identifiability, base-parameter
relations, the table) and the elimination log's `Step` (spec: guaranteed_least_squares §3.6–3.9,
§7 items 5–9). Importable from `diffsusp.lsq` and `diffsusp.lsq.fit`.
"""

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np

from ..errors import InputError, index_of
from . import core

# --------------------------------------------------------------------------------------------
# Report objects


@dataclasses.dataclass(frozen=True)
class Step:
    """One iteration of the elimination loop (spec §3.9)."""

    iteration: int
    removed: str
    reason: str
    confidence: float  # IC of the removed parameter's combination before removal
    sigma_pct: float  # σ% of that combination before removal
    residual_before: float
    residual_after: float
    relations: tuple[str, ...]  # the printed relations after removal

    @property
    def residual_increase_pct(self) -> float:
        if self.residual_before == 0:
            return 0.0 if self.residual_after == 0 else float("inf")
        return 100.0 * (self.residual_after / self.residual_before - 1.0)

    def __str__(self) -> str:
        rel = "; ".join(self.relations) if self.relations else "no regrouping"
        return (f"{self.iteration}. removed {self.removed} ({self.reason}): residual "
                f"{self.residual_before:.6g} -> {self.residual_after:.6g} "
                f"({self.residual_increase_pct:+.3g} %); {rel}")


@dataclasses.dataclass(frozen=True)
class Fit:
    """A least-squares fit with its identifiability report (spec §3.6–3.9, §8.4).

    **Per parameter (p,)**: `x` (original units), `sigma` (nan where not identifiable, fixed or
    at a bound), `sigma_pct` (100·σ/|x|), `confidence` (the confidence index IC of the
    combination the parameter carries; nan where not kept), `identifiable` (individually
    determined by the data), `kept` (a column of the reduced, base-parameter model), `fixed`
    (held at its prior: eliminated or given in `fixed=`), `at_bound` (bounded solves).

    **Relations**: `relations` (list of str) are the identifiable combinations that involve more
    than one parameter, e.g. "Krx1 + Krx2" or "a - 0.07413 b"; `relation_values` and
    `relation_sigma` are aligned with it. `regrouping` (p, p) holds every combination: row j
    (j kept) gives c_j = Σ_k regrouping[j, k]·x_k, with value `combination_values[j]` and σ
    `combination_sigma[j]` (nan where not kept).

    **Whole fit**: `rank`, `n` (rows), `dof`, `residuals` (y − W x, unweighted; None for a
    streamed fit), `residual_norm` (weighted), `residual_sigma` (σ̂ of the weighted residual),
    `residual_norm_full` (‖ρ_min‖ of the full model), `singular_values` (of the weighted W as
    given, the thesis's "100 % / 5.2 %"), `singular_values_scaled` (columns at unit norm) and
    `condition` (of the scaled W: independent of units), `diagonal` (|R_ii|/‖W_i‖) and the
    `threshold` of the identifiability test, `covariance` (p, p), `R` ((p+1)×(p+1) R-factor of
    the weighted [W, −y]), `method`, `block_weights`, `log` (elimination steps).
    """

    names: tuple[str, ...]
    x: np.ndarray
    sigma: np.ndarray
    sigma_pct: np.ndarray
    confidence: np.ndarray
    identifiable: np.ndarray
    kept: np.ndarray
    fixed: np.ndarray
    at_bound: np.ndarray
    rank: int
    relations: list[str]
    relation_values: np.ndarray
    relation_sigma: np.ndarray
    regrouping: np.ndarray
    combination_values: np.ndarray
    combination_sigma: np.ndarray
    covariance: np.ndarray
    n: int
    dof: float
    residuals: np.ndarray | None
    residual_norm: float
    residual_sigma: float
    residual_norm_full: float
    singular_values: np.ndarray
    singular_values_scaled: np.ndarray
    condition: float
    diagonal: np.ndarray
    threshold: float
    scale: np.ndarray
    R: np.ndarray
    method: str
    iterations: int = 0
    converged: bool = True
    block_weights: np.ndarray | None = None
    block_sigma: np.ndarray | None = None
    log: tuple[Step, ...] = ()

    # ---- derived views

    @property
    def p(self) -> int:
        return len(self.names)

    @property
    def essential(self) -> np.ndarray:
        """Kept combinations not below IC = 0.1 (spec §3.8: those can be neglected; an
        undefined IC, e.g. on exact data, does not make a parameter negligible)."""
        return self.kept & ~(self.confidence < core.IC_ESSENTIAL)

    def interval(self, k: float = 1.0) -> np.ndarray:
        """(p, 2) interval x ± k·σ (k = 1: the 68 % Gaussian interval of spec §3.8)."""
        return np.stack([self.x - k * self.sigma, self.x + k * self.sigma], axis=1)

    @property
    def contains_zero(self) -> np.ndarray:
        """The 68 % interval contains 0 (σ% > 100): the parameter may be set to 0."""
        lo, hi = self.interval().T
        return (lo <= 0) & (hi >= 0)

    def value(self, name: str) -> float:
        return float(self.x[self.index(name)])

    def index(self, name: str) -> int:
        """The position of parameter `name` (`InputError` naming the known ones otherwise)."""
        return index_of(self.names, name)

    def combination(self, name: str) -> str:
        """The printed combination estimated by the kept parameter `name` (itself if alone)."""
        j = self.index(name)
        if not self.kept[j]:
            raise InputError(f"parameter {name!r} is not kept in the reduced model; its value is "
                             "its prior. Ask for one of the kept parameters.")
        return format_combination(self.regrouping[j], self.names, j)

    def reinject(self, priors: Mapping[str, float]) -> np.ndarray:
        """Parameters consistent with the fit once some are given a-priori values (spec §3.6,
        §7 item 10): every identifiable combination c = Γ x keeps its value, the given
        parameters take their priors and the others change as little as possible (in unit-norm
        column coordinates). E.g. with c = a − 0.0742 b: prior b = 1 gives a = c + 0.0742;
        prior a = 5 gives b = (c − 5)/(−0.0742). Raises InputError if the priors contradict a
        combination (all its parameters given)."""
        given = np.zeros(self.p, bool)
        x = self.x.copy()
        for name, value in priors.items():
            i = self.index(name)
            given[i] = True
            x[i] = float(value)
        G = self.regrouping[self.kept]
        c = self.combination_values[self.kept]
        free = ~given
        r = c - G @ x
        A = G[:, free] * self.scale[free][None, :]
        delta, *_ = np.linalg.lstsq(A, r, rcond=None)
        x[free] += delta * self.scale[free]
        miss = np.abs(G @ x - c)
        tol = 1e-8 * (np.abs(G) @ np.abs(x) + np.abs(c) + 1e-300)
        bad = np.nonzero(miss > tol)[0]
        if len(bad):
            j = np.nonzero(self.kept)[0][bad[0]]
            raise InputError(
                f"the priors {dict(priors)} contradict the identified combination "
                f"{format_combination(self.regrouping[j], self.names, j)} = "
                f"{self.combination_values[j]:.6g}; leave at least one of its parameters free.")
        return x

    # ---- output

    def table(self) -> str:
        """A readable report: parameters, σ, σ%, IC, status; relations; singular values."""
        lines = [
            f"least squares ({self.method}): {self.n} rows, {self.p} parameters, rank "
            f"{self.rank}, dof {self.dof:g}",
            f"residual norm {self.residual_norm:.6g}, residual sigma {self.residual_sigma:.4g}, "
            f"condition (unit-norm columns) {self.condition:.3g}",
        ]
        width = max([9] + [len(n) for n in self.names])
        lines.append(f"{'parameter':<{width}}  {'value':>13}  {'sigma':>10}  {'sigma%':>8}  "
                     f"{'IC':>6}  status")
        for i, name in enumerate(self.names):
            lines.append(f"{name:<{width}}  {self.x[i]:>13.6g}  {_num(self.sigma[i], '.3g'):>10}"
                         f"  {_pct(self.sigma_pct[i]):>8}  {_num(self.confidence[i], '.3f'):>6}"
                         f"  {self.status(i)}")
        if self.relations:
            lines.append("identifiable combinations:")
            for text, v, s in zip(self.relations, self.relation_values, self.relation_sigma,
                                  strict=True):
                spread = (f" +- {s:.3g} ({_pct(100 * s / abs(v)) if v else '-'})"
                          if np.isfinite(s) else "")
                lines.append(f"  {text} = {v:.6g}{spread}")
        sv = self.singular_values / self.singular_values[0] if self.singular_values[0] > 0 \
            else self.singular_values
        lines.append("singular values of W (% of largest): "
                     + ", ".join(f"{100 * s:.3g}" for s in sv))
        for step in self.log:
            lines.append(f"  {step}")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.table()

    def status(self, i: int) -> str:
        """The status of parameter `i` in words ("" when identified): fixed at its prior, at a
        bound, not identifiable (with the combination it is in), not essential."""
        name_rel = None
        for text, j in zip(self.relations, np.nonzero(self.nontrivial())[0], strict=True):
            if self.regrouping[j, i] != 0:
                name_rel = text
        if self.fixed[i]:
            return "fixed at prior" + (f" (in {name_rel})" if name_rel else "")
        if self.at_bound[i]:
            return "at bound"
        if not self.identifiable[i]:
            if name_rel:
                return f"not identifiable: in {name_rel}"
            if not np.any(self.regrouping[:, i]) and self.diagonal[i] == 0:
                return "not identifiable: no effect on the data"
            return "not identifiable"
        if self.kept[i] and not self.essential[i]:
            return "not essential (IC < 0.1)"
        return ""

    def nontrivial(self) -> np.ndarray:
        """Which kept parameters estimate a combination with others (a row of `regrouping`
        beyond its diagonal): the `relations` printed, in order."""
        off = self.regrouping.copy()
        np.fill_diagonal(off, 0.0)
        return self.kept & np.any(off != 0, axis=1)

    def to_dict(self) -> dict:
        """JSON-ready dictionary (nan → None)."""
        def lst(a):
            return [None if (isinstance(v, float) and not np.isfinite(v)) else v
                    for v in np.asarray(a).tolist()]
        return {
            "method": self.method, "names": list(self.names), "x": lst(self.x),
            "sigma": lst(self.sigma), "sigma_pct": lst(self.sigma_pct),
            "confidence": lst(self.confidence), "identifiable": lst(self.identifiable),
            "kept": lst(self.kept), "fixed": lst(self.fixed), "at_bound": lst(self.at_bound),
            "rank": self.rank, "relations": [
                {"combination": t, "value": float(v), "sigma": _none(s)}
                for t, v, s in zip(self.relations, self.relation_values, self.relation_sigma,
                                   strict=True)],
            "n": self.n, "dof": self.dof, "residual_norm": self.residual_norm,
            "residual_sigma": _none(self.residual_sigma),
            "singular_values": lst(self.singular_values),
            "singular_values_scaled": lst(self.singular_values_scaled),
            "condition": _none(self.condition), "threshold": self.threshold,
            "block_weights": None if self.block_weights is None else lst(self.block_weights),
            "log": [dataclasses.asdict(s) for s in self.log],
        }


def _none(v):
    v = float(v)
    return v if np.isfinite(v) else None


def _num(v, fmt):
    return "-" if not np.isfinite(v) else format(v, fmt)


def _pct(v):
    return "-" if not np.isfinite(v) else f"{v:.3g}%"


def format_combination(coefficients: np.ndarray, names: Sequence[str], j: int) -> str:
    """"a - 0.07413 b", "Krx1 + Krx2": the kept parameter j first (coefficient 1), then the
    regrouped ones in column order with 4 significant digits (±1 printed as a bare sign)."""
    parts = [names[j]]
    for k, c in enumerate(coefficients):
        if k == j or c == 0:
            continue
        mag = format(abs(c), ".4g")
        parts.append(("- " if c < 0 else "+ ") + (names[k] if mag == "1" else f"{mag} {names[k]}"))
    return " ".join(parts)
