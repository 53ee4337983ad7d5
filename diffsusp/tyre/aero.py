"""The aerodynamic force of a wheel spinning in the air (thesis §3.2.2.1.3.3, fig. 33; spec
tyre §4.2): lifted off the belt and left to spin down, a wheel develops a lateral force (and an
aligning moment) "strongly linear in the spin speed", identified under a laminar (∝ ω), a
turbulent (∝ ω²) or a mixed flow law. On the bench the same force adds to the contact force at
the wheel's spin speed: `remove` takes it out of bench data before the identification (the
thesis kept an F_z-independent offset b_{·,1,1,0} partly for it).

The law, per channel: Y(ω) = Y0 + k_l·ω + k_t·ω·|ω| — Y0 the channel's offset with the wheel
stopped, k_l the laminar and k_t the turbulent coefficient (ω·|ω| so that the force follows the
spin direction). `identify` fits it by linear least squares (`lsq`) and, with `law="auto"`,
keeps the flow terms the data support: the elimination loop removes a term whose σ % exceeds
100/√F (the F-test at `significance`: 30.4 % at 10⁻³, the bench identification's rule)."""

import dataclasses
import math
from collections.abc import Mapping

import numpy as np
from scipy import stats

from .. import lsq
from ..errors import InputError

__all__ = ["AeroLaw", "LAWS", "identify", "remove"]

LAWS = ("laminar", "turbulent", "both", "auto")
_TERMS = ("offset", "laminar", "turbulent")


@dataclasses.dataclass(frozen=True)
class AeroLaw:
    """An identified aerodynamic law of one channel (see the module docstring).

    **Fields:** `channel`; `law` (the flow terms kept: "laminar", "turbulent", "both" or
    "none"); `offset`, `laminar`, `turbulent` (Y0 in the channel's unit, k_l per rad/s, k_t per
    (rad/s)²; 0 where not kept) and their 1σ `sigma` (same order; NaN where not kept);
    `residual_sigma` (the fit's residual RMS, the noise estimate); `n` samples;
    `omega_range` (rad/s) of the run."""

    channel: str
    law: str
    offset: float
    laminar: float
    turbulent: float
    sigma: tuple[float, float, float]
    residual_sigma: float
    n: int
    omega_range: tuple[float, float]

    def __call__(self, omega) -> np.ndarray:
        """The aerodynamic part of the channel at spin speed `omega` [rad/s] (the offset is
        the stopped wheel's, not aerodynamic: not included)."""
        w = np.asarray(omega, float)
        return self.laminar * w + self.turbulent * w * np.abs(w)

    def to_dict(self) -> dict:
        return {"channel": self.channel, "law": self.law, "offset": self.offset,
                "laminar": self.laminar, "turbulent": self.turbulent,
                "sigma": dict(zip(_TERMS, self.sigma, strict=True)),
                "residual_sigma": self.residual_sigma, "n": self.n,
                "omega_range": list(self.omega_range)}


def identify(omega, channels: Mapping[str, object], *, law: str = "auto",
             significance: float = 1e-3) -> dict[str, AeroLaw]:
    """The aerodynamic law of each channel (e.g. {"FY": fy, "MZ": mz}) from a wheel-in-the-air
    run: spin speed `omega` [rad/s] and the channels, sample by sample (a spin-down: ω from
    its top speed to rest). `law`: "laminar", "turbulent", "both", or "auto" (the terms the
    data support, see the module docstring).

    **Raises:** `InputError` for a run that does not spin (ω constant: the law is not
    determined), mismatched lengths or an unknown `law`."""
    if law not in LAWS:
        raise InputError(f"law must be one of {', '.join(LAWS)}; got {law!r}.")
    w = np.asarray(omega, float).ravel()
    if not np.isfinite(w).all():
        raise InputError("omega has non-finite samples.")
    if w.size < 4 or np.ptp(w) <= 1e-9 * max(np.abs(w).max(), 1.0):
        raise InputError("a wheel-in-the-air run must spin down (ω varying): the law is not "
                         "determined by a constant spin speed.")
    W = np.stack([np.ones_like(w), w, w * np.abs(w)], axis=1)
    held = {"laminar": ("turbulent",), "turbulent": ("laminar",)}.get(law, ())
    threshold = 100.0 / math.sqrt(stats.f.ppf(1.0 - significance, 1, max(w.size - 3, 1)))
    out = {}
    for name, y in channels.items():
        y = np.asarray(y, float).ravel()
        if y.shape != w.shape or not np.isfinite(y).all():
            raise InputError(f"channel {name}: {y.size} finite samples expected to match "
                             f"omega's {w.size}.")
        if law == "auto":
            fit, _ = lsq.eliminate(W, y, names=_TERMS, keep=("offset",),
                                   sigma_pct_threshold=threshold)
        else:
            fit = lsq.solve(W, y, names=_TERMS, fixed=held)
        kept = np.asarray(fit.kept, bool) & ~np.asarray(fit.fixed, bool)
        x = np.where(kept, np.asarray(fit.x, float), 0.0)
        sigma = np.where(kept, np.asarray(fit.sigma, float), np.nan)
        flows = [t for t, k in zip(_TERMS[1:], kept[1:], strict=True) if k]
        out[name] = AeroLaw(name, "both" if len(flows) == 2 else flows[0] if flows else "none",
                            float(x[0]), float(x[1]), float(x[2]),
                            tuple(float(s) for s in sigma), float(fit.residual_sigma),
                            int(w.size), (float(w.min()), float(w.max())))
    return out


def remove(columns: Mapping[str, np.ndarray], laws: Mapping[str, AeroLaw]) -> dict:
    """Bench columns (library units, with "omega" [rad/s]) with each law's aerodynamic part
    subtracted from its channel at the bench's spin speed; the other columns unchanged."""
    if "omega" not in columns:
        raise InputError("removing the aerodynamic force needs the bench's 'omega' column "
                         "(the wheel's spin speed).")
    out = dict(columns)
    for name, law in laws.items():
        if name not in out:
            raise InputError(f"the bench data have no {name} channel to correct.")
        out[name] = np.asarray(out[name], float) - law(out["omega"])
    return out
