"""The report API every identification method shares (DESIGN.md "Identification": the same
base API for `direct`, `iterative` and `least_squares`, so a user who learnt one knows the
others).

Each report keeps its own fields (e.g. `DirectReport.values` in the thesis's table units, the
`FitReport` history) and also answers, in the model's units (N/mm, N·mm/rad, N, N·mm, mm):

- `names`: the parameters, e.g. `'bushing_A.Ktx'`;
- `estimates`, `sigmas` (1σ; NaN when the method gives none, inf when the data carry no
  information), `sigma_pct` (100·σ/|estimate|), `estimate_units`;
- `identifiable`: the data determine the parameter on its own;
- `combinations`: texts of the combinations of several parameters the method names (direct:
  the combinations the data determine; least squares: the directions the data cannot see);
- `residuals`: measurement name → `MeasurementResiduals` (raw, whitened);

and, from those, `rows()`, `to_frame()`, `to_json()` and `plot()`.
"""

import dataclasses
import json
import math
from typing import ClassVar

import numpy as np


@dataclasses.dataclass(frozen=True)
class MeasurementResiduals:
    """Residuals of one measurement at the estimate: `raw` model − measured (physical units,
    the measured shape; 0 where masked) and `whitened` (mask·raw/σ)."""

    raw: np.ndarray
    whitened: np.ndarray


def _number(v):
    v = float(v)
    return v if math.isfinite(v) else None


class IdentificationReport:
    """Base of the identification reports (see the module docstring for what a subclass
    provides). Not a dataclass itself, so that its subclasses keep their own fields."""

    family: ClassVar[str] = "identification"
    """The method's name: 'direct', 'iterative', 'least_squares'."""

    def rows(self) -> list[dict]:
        """One dict per parameter: parameter, estimate, sigma, sigma_pct, unit, identifiable
        (model units; None where there is no number)."""
        return [dict(parameter=name, estimate=_number(self.estimates[i]),
                     sigma=_number(self.sigmas[i]), sigma_pct=_number(self.sigma_pct[i]),
                     unit=self.estimate_units[i], identifiable=bool(self.identifiable[i]))
                for i, name in enumerate(self.names)]

    def summary(self) -> dict:
        """The common part of every report as plain data: method, parameters (`rows()`),
        combinations, and per measurement the RMS of its whitened residuals."""
        rms = {}
        for name, res in self.residuals.items():
            white = np.asarray(res.whitened, dtype=float)
            rms[name] = _number(np.sqrt(np.mean(white ** 2))) if white.size else None
        return {"method": self.family, "parameters": self.rows(),
                "combinations": list(self.combinations), "residual_rms": rms}

    def to_json(self, **kwargs) -> str:
        """`summary()` as JSON (NaN and inf written as null); `kwargs` go to `json.dumps`."""
        return json.dumps(self.summary(), **kwargs)

    def to_frame(self):
        """`rows()` as a pandas DataFrame indexed by parameter (pandas is imported here only:
        it is not a dependency of the library)."""
        try:
            import pandas as pd
        except ImportError:  # pragma: no cover - depends on the environment
            raise ImportError("to_frame needs pandas (pip install pandas); rows() gives the "
                              "same table as dicts.") from None
        return pd.DataFrame(self.rows()).set_index("parameter")

    def plot(self, axes=None):
        """Estimates with ±σ bars on a log scale (grey: not identifiable). Returns the
        matplotlib Figure."""
        import matplotlib.pyplot as plt

        if axes is None:
            fig, axes = plt.subplots(figsize=(max(4.0, 0.35 * len(self.names) + 2), 3.5))
        else:
            fig = axes.figure
        idx = np.arange(len(self.names))
        ok = np.asarray(self.identifiable, dtype=bool)
        value = np.abs(np.asarray(self.estimates, dtype=float))
        sigma = np.nan_to_num(np.asarray(self.sigmas, dtype=float), nan=0.0, posinf=0.0)
        axes.bar(idx[ok], value[ok], yerr=sigma[ok], color="C0", capsize=2,
                 label="identifiable")
        axes.bar(idx[~ok], value[~ok], color="0.75", label="not identifiable")
        axes.set_yscale("log")
        axes.set_xticks(idx, self.names, rotation=90, fontsize=7)
        axes.set_ylabel("|estimate| (model units)")
        axes.set_title(f"{self.family.replace('_', ' ')} identification", fontsize=9)
        axes.legend(fontsize=8)
        fig.tight_layout()
        return fig


__all__ = ["IdentificationReport", "MeasurementResiduals"]
