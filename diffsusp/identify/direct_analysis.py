"""What the data determine in the direct identification (spec stiffness §1.11–1.14, §7 R3):
the identifiability of each unknown from the unweighted equations (no effect, independent, or
only in an identifiable combination such as `bushing_1.Krx + bushing_2.Krx`), and the verdict
per unknown from its σ% at the model's values (the start: `report.sigma_pct_at_start`, the one
rule of the suspension methods).
"""

import dataclasses

import numpy as np

from ..lsq import format_combination
from .report import bar_reason, sigma_pct_at_start, within_bar

__all__: list[str] = []  # used by `identify.direct`


RELATION_TOL = 1e-3
"""Terms of an identifiable combination whose coefficient is below this, on unit-norm columns,
are dropped from the printed relation: columns dependent only up to the identifiability
threshold regroup with tiny spurious coefficients on unrelated unknowns."""


@dataclasses.dataclass(frozen=True)
class _Structure:
    """What the (unweighted) equations determine: the kept (base) unknowns, the unknowns
    determined alone, and the combinations of several unknowns (kept index, coefficients)."""

    kept: np.ndarray
    alone: np.ndarray
    relation_of: list
    relations: tuple  # (kept index j, coefficient row g)


def structure_of(fit, negligible: np.ndarray) -> _Structure:
    """Identifiability from an `lsq.Fit` of the unweighted equations, with the relations
    cleaned of spurious terms (`RELATION_TOL`) and the no-effect unknowns left out."""
    p = len(fit.names)
    kept = np.asarray(fit.kept, bool) & ~negligible
    scale = np.asarray(fit.scale, float)
    gamma = np.asarray(fit.regrouping, float)
    gamma_unit = gamma * scale[None, :] / np.where(scale > 0, scale, 1.0)[:, None]
    clean = np.where((np.abs(gamma_unit) > RELATION_TOL) & ~negligible[None, :], gamma, 0.0)
    relation_of = [None] * p
    relations = []
    for j in np.flatnonzero(kept):
        others = [k for k in np.flatnonzero(clean[j]) if k != j]
        if not others:
            continue
        for k in [j, *others]:
            relation_of[k] = int(j)
        relations.append((int(j), clean[j]))
    alone = kept & np.array([relation_of[i] is None for i in range(p)], dtype=bool)
    return _Structure(kept, alone, relation_of, tuple(relations))


@dataclasses.dataclass(frozen=True)
class _Analysis:
    identifiable: np.ndarray  # (p,) determined alone (and not eliminated)
    sigma: np.ndarray  # (p,)
    sigma_pct: np.ndarray  # (p,) at the estimate (reported)
    gate_pct: np.ndarray  # (p,) at the model's values (judged: `sigma_pct_at_start`)
    relations: tuple  # (text, value, sigma)
    status: tuple


def analyse(structure: _Structure, fit, negligible, eliminated, max_sigma_pct,
             hold, prior) -> _Analysis:
    """Statistics of the estimate `fit` (weighted or not) on the `structure` of the equations;
    σ % judged at `prior`, the model's values (the linear σ does not depend on θ)."""
    p = len(fit.names)
    x = np.asarray(fit.x, float)
    cov = np.asarray(fit.covariance, float)
    at_bound = np.asarray(fit.at_bound, bool)
    identifiable = structure.alone & ~eliminated & ~at_bound
    sigma = np.where(identifiable, np.sqrt(np.maximum(np.diag(cov), 0.0)), np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        pct = np.where(identifiable, 100.0 * sigma / np.abs(x), np.nan)
    gate = sigma_pct_at_start(sigma, prior)
    passes = within_bar(gate, max_sigma_pct)
    texts = {}
    relations = []
    for j, g in structure.relations:
        text = format_combination(g, fit.names, j)
        texts[j] = text
        relations.append((text, float(g @ x), float(np.sqrt(max(g @ cov @ g, 0.0)))))
    status = []
    for i in range(p):
        if negligible[i]:
            status.append("not identifiable: no effect on the equations")
        elif eliminated[i]:
            status.append("not determined: held at "
                          + ("the model's value" if hold == "model" else "0"))
        elif at_bound[i]:
            status.append("at its bound (0)")
        elif structure.relation_of[i] is not None:
            status.append(f"not identifiable alone: in {texts[structure.relation_of[i]]}")
        elif not identifiable[i]:
            status.append("not identifiable")
        elif not passes[i]:
            status.append("not determined: " + bar_reason(gate[i], max_sigma_pct))
        else:
            status.append("identified")
    return _Analysis(identifiable, sigma, pct, gate, tuple(relations), tuple(status))
