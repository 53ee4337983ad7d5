"""The report of the direct method (`identify.direct`): values in the units of the thesis's
tables, σ, σ%, verdicts, identifiable combinations, derived quantities, residuals per case,
its table, dict/JSON rows and plot. spec: stiffness §1.10–1.14 (what the thesis's tables
print); the base API every method shares is `identify.report`."""

import dataclasses
import math
from typing import ClassVar

import numpy as np

from ..errors import index_of
from ..geometry import DEG
from .report import AT_START, Consistency, IdentificationReport, MeasurementResiduals

__all__ = ["DirectReport"]

# Table units in degrees → the model's radians: the factor on the value.
_DEG_POWER = {"N·mm/deg": 1.0 / DEG, "N·mm/deg³": DEG**-3}

INCONSISTENT_STATUS = "determined, but not identified: the model is inconsistent with the data"
"""The status of an unknown the data determine when the identified model does not reproduce
the measurements (`Consistency.verdict`: "no value is reported as identified")."""


@dataclasses.dataclass(frozen=True)
class DirectReport(IdentificationReport):
    """What the direct identification found (values in the units of the thesis's tables).

    **Per unknown (p,)**, aligned with `names`: `values` (the least-squares solution; for the
    basic method non-identifiable ones are 0, the thesis's zeros), `sigma`, `sigma_pct`,
    `identified` (individually determined by the data with σ% ≤ `max_sigma_pct` at the
    model's values, `gate_sigma_pct`; `sigma_pct` is at the estimate),
    `identifiable` (individually determined, whatever its σ%), `status` (a phrase: e.g.
    "identified (polished through the equilibrium)", "held at the model's value in the
    polish (linear estimate …)"), `units`, `prior` (the model's values). After a polish
    (`polished`, the `FitReport`), `values` are those of the returned model and
    `linear_values` the linear estimate.

    **Also:** `relations` [(combination, value, σ)] — the combinations of several unknowns the
    data determine (e.g. "bushing_1.Krx + bushing_2.Krx"); `derived` {name: (value, σ, unit)}
    (spring free lengths L0 = K·L0/K, bushing offsets δ0); `case_residuals` (cases,) the norm
    of each case's equation residual (N) and `case_scale` (cases,) the norm of its right-hand
    side; `cases` labels; `notes` (measurement exclusions, warnings); `fit` the `lsq.Fit` of
    the estimate; `method`; `rank` (of the unweighted equations); `n_equations`; `weighted`.
    """

    names: tuple[str, ...]
    values: np.ndarray
    sigma: np.ndarray
    sigma_pct: np.ndarray
    identified: np.ndarray
    identifiable: np.ndarray
    status: tuple[str, ...]
    units: tuple[str, ...]
    prior: np.ndarray
    relations: tuple[tuple[str, float, float], ...]
    derived: dict
    case_residuals: np.ndarray
    case_scale: np.ndarray
    cases: tuple[str, ...]
    notes: tuple[str, ...]
    fit: object
    method: str
    rank: int
    n_equations: int
    max_sigma_pct: float
    weighted: bool = False
    equation_residuals: np.ndarray | None = None
    whitened_equation_residuals: np.ndarray | None = None
    consistency: Consistency | None = None
    polished: object = None
    linear_values: np.ndarray | None = None
    gate_sigma_pct: np.ndarray | None = None

    family: ClassVar[str] = "direct"

    @property
    def determined(self) -> np.ndarray:
        """Identifiable with σ% at the model's values ≤ `max_sigma_pct` (`gate_sigma_pct`,
        the one rule of the suspension methods: `report.sigma_pct_at_start`), not negative
        (`identified` before the consistency check)."""
        return np.asarray(self.identified, dtype=bool)

    @property
    def judged_at(self) -> str:
        return "the estimate" if self.gate_sigma_pct is None else AT_START

    @property
    def held(self) -> np.ndarray:
        """Unknowns held at the model's value (in the polish, or by `hold`)."""
        return np.array([st.startswith("held") for st in self.status], dtype=bool)

    @property
    def reasons(self) -> tuple[str, ...]:
        """The method's phrase for every unknown it does not call identified."""
        return tuple("" if st.startswith("identified") else st.removeprefix("not determined: ")
                     for st in self.status)

    # The base API (identify.report), in the model's units (N·mm/rad, not N·mm/deg).
    @property
    def _to_model(self) -> np.ndarray:
        return np.array([_DEG_POWER.get(u, 1.0) for u in self.units])

    @property
    def parameters_to_model(self) -> np.ndarray:
        """Per unknown, the factor from its table unit to the model's (N·mm/deg → N·mm/rad:
        180/π; N·mm/deg³ → N·mm/rad³: (180/π)³)."""
        return self._to_model

    @property
    def estimates(self) -> np.ndarray:
        return self.values * self._to_model

    @property
    def sigmas(self) -> np.ndarray:
        return self.sigma * self._to_model

    @property
    def estimate_units(self) -> tuple[str, ...]:
        return tuple(u.replace("/deg", "/rad") if u in _DEG_POWER else u for u in self.units)

    @property
    def residuals(self) -> dict:
        """`{'equations': MeasurementResiduals}`: the residual of every equation (N; rows of
        a case together, (cases, rows)), raw and as weighted in the solve."""
        if self.equation_residuals is None:
            return {}
        return {"equations": MeasurementResiduals(self.equation_residuals,
                                                  self.whitened_equation_residuals)}

    def value(self, name: str) -> float:
        return float(self.values[self._index(name)])

    def _index(self, name: str) -> int:
        return index_of(self.names, name)

    @property
    def combinations(self) -> list[str]:
        """The identifiable combinations of several unknowns, as printed."""
        return [text for text, _, _ in self.relations]

    def rows(self) -> list[dict]:
        """One dict per unknown (and per derived quantity): for CSV/JSON export."""
        out = []
        statuses, reasons = self.statuses, self.status_reasons
        for i, name in enumerate(self.names):
            out.append(dict(parameter=name, value=float(self.values[i]),
                            sigma=_nan_none(self.sigma[i]), sigma_pct=_nan_none(self.sigma_pct[i]),
                            unit=self.units[i], identified=bool(self.is_identified[i]),
                            prior=float(self.prior[i]), status=statuses[i], reason=reasons[i]))
        for name, (v, s, unit) in self.derived.items():
            out.append(dict(parameter=name, value=_nan_none(v), sigma=_nan_none(s),
                            sigma_pct=_nan_none(100 * s / abs(v)) if v else None, unit=unit,
                            identified=bool(np.isfinite(v)) and self.consistent is not False,
                            prior=None, status="derived", reason=""))
        return out

    def csv_rows(self) -> list[dict]:
        """The .csv rows (`write`): `rows()` (the thesis's units)."""
        return self.rows()

    def json_data(self) -> dict:
        """The .json content (`write`): `to_dict()`."""
        return self.to_dict()

    def to_dict(self) -> dict:
        return {
            "method": self.method, "rank": self.rank, "n_equations": self.n_equations,
            "n_unknowns": len(self.names), "parameters": self.rows(),
            "relations": [{"combination": t, "value": float(v), "sigma": _nan_none(s)}
                          for t, v, s in self.relations],
            "cases": [{"case": c, "residual": float(r), "scale": float(s)} for c, r, s in
                      zip(self.cases, self.case_residuals, self.case_scale, strict=True)],
            "notes": list(self.notes),
            "consistency": None if self.consistency is None else self.consistency.summary(),
            "fit_verdict": self.fit_verdict, "judged_at": self.judged_at,
            "polished": self.polished is not None,
        }

    def table(self) -> str:
        """The report as text: one line per unknown (value, σ%, status), the identifiable
        combinations, derived quantities, residual per case and notes."""
        width = max([9] + [len(n) for n in self.names] + [len(n) for n in self.derived])
        lines = [
            f"direct identification ({self.method}): {self.n_equations} equations, "
            f"{len(self.names)} unknowns, rank {self.rank}",
            f"{'parameter':<{width}}  {'value':>12}  {'sigma%':>8}  {'unit':<9} status",
        ]
        for i, name in enumerate(self.names):
            shown = self.identified[i] or self.status[i].startswith(("fixed", "held"))
            value = f"{self.values[i]:12.6g}" if shown else f"{'—':>12}"
            pct = f"{self.sigma_pct[i]:7.3g}%" if np.isfinite(self.sigma_pct[i]) else f"{'—':>8}"
            lines.append(f"{name:<{width}}  {value}  {pct:>8}  {self.units[i]:<9} "
                         f"{self.status[i]}")
        if self.relations:
            lines.append("identifiable combinations:")
            for text, v, s in self.relations:
                pct = f" ({100 * s / abs(v):.3g}%)" if np.isfinite(s) and v else ""
                lines.append(f"  {text} = {v:.6g}{pct}")
        if self.derived:
            lines.append("derived:")
            for name, (v, s, unit) in self.derived.items():
                pct = f" ({100 * s / abs(v):.3g}%)" if np.isfinite(s) and v else ""
                txt = f"{v:.6g}" if np.isfinite(v) else "—"
                lines.append(f"  {name:<{width}} = {txt} {unit}{pct}")
        lines.append("residual per case (N, relative to the case's load terms):")
        lines.append("  " + ", ".join(
            f"{c}: {r:.3g} ({r / s:.2g})" if s > 0 else f"{c}: {r:.3g}"
            for c, r, s in zip(self.cases, self.case_residuals, self.case_scale, strict=True)))
        if self.consistency is not None:
            lines.append(f"model vs data: {self.consistency.verdict}")
        for note in self.notes:
            lines.append(f"note: {note}")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.table()

    def judged(self) -> "DirectReport":
        """This report with every 'identified…' status replaced by `INCONSISTENT_STATUS` when
        the consistency check failed: the per-unknown statuses (`table()`, `rows()`, the CLI)
        then say what `verdicts` and the "model vs data" line say. `direct` returns its
        reports judged."""
        if self.consistent is not False:
            return self
        status = tuple(INCONSISTENT_STATUS + (" (polished through the equilibrium)"
                                               if "polished" in st else "")
                       if st.startswith("identified") else st for st in self.status)
        return dataclasses.replace(self, status=status)

    def plot(self, axes=None):
        """Identified values against the model's (prior) values with ±σ bars, and the residual
        per case. Returns the matplotlib Figure."""
        import matplotlib.pyplot as plt

        if axes is None:
            fig, axes = plt.subplots(1, 2, figsize=(11, 4), width_ratios=(2, 1))
        else:
            fig = axes[0].figure
        idx = np.arange(len(self.names))
        ax = axes[0]
        ax.bar(idx - 0.2, np.abs(self.prior), 0.4, label="model (prior)", color="0.75")
        ok = self.identified
        ax.bar(idx[ok] + 0.2, np.abs(self.values[ok]), 0.4,
               yerr=np.nan_to_num(self.sigma[ok]), label="identified", color="C0", capsize=2)
        ax.set_yscale("log")
        ax.set_xticks(idx, self.names, rotation=90, fontsize=7)
        ax.set_ylabel("|value| (table units)")
        ax.legend(fontsize=8)
        ax.set_title("direct identification (no bar: not identified)", fontsize=9)
        ax = axes[1]
        ax.bar(np.arange(len(self.cases)), self.case_residuals, color="C1")
        ax.set_xticks(np.arange(len(self.cases)), self.cases, fontsize=7)
        ax.set_xlabel("case")
        ax.set_ylabel("equation residual (N)")
        fig.tight_layout()
        return fig


def _nan_none(v):
    v = float(v)
    return v if math.isfinite(v) else None
