"""The abstract tyre: what every steady-state tyre model of `diffsusp.tyre` answers, so that the
fits, the bench programmes and the specification quantities call methods instead of asking
which model they hold (spec: tyre §7 C, §7 E item 22).

A tyre is an `equinox.Module` with a `coefficients` dict (name → float64 scalar array) and the
steady-state `forces(fz, kappa, alpha, gamma, vx, pressure)` in library units (inputs N, -, rad,
rad, mm/s, Pa; forces N, moments N·mm, ISO-W axes), as a dict channel → array over the
channels it evaluates (`channels`). The rest has defaults for a model without validity ranges,
nominal load or physical constraints (the 1989 set): a new tyre model subclasses `AbstractTyre`,
implements `forces`, `channels`, `nominal_load` and `default_groups`, and overrides the others
where it has them (MF 6.x: `mf6.MagicFormula6`).

```python
from diffsusp import tyre
m = tyre.MagicFormula89.from_thesis("dunlop_r16", 2.0)
m.forces(4000.0, 0.0, 0.05)["FY"]                    # N
```
"""

import abc
import dataclasses
from typing import Self

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

__all__ = ["AbstractTyre"]


class AbstractTyre(eqx.Module):
    """A steady-state tyre model (module docstring).

    **Abstract:** `coefficients` (field: name → float64 scalar array), `channels` (class
    variable: the outputs `forces` returns, of "FX", "FY", "MX", "MY", "MZ"), `forces`,
    `nominal_load`, `default_groups`.
    """

    coefficients: eqx.AbstractVar[dict[str, Float[Array, ""]]]
    channels: eqx.AbstractClassVar[tuple[str, ...]]

    @abc.abstractmethod
    def forces(self, fz: ArrayLike, kappa: ArrayLike, alpha: ArrayLike, gamma: ArrayLike = 0.0,
               vx: ArrayLike | None = None, pressure: ArrayLike | None = None, *,
               combined: bool = True, channels: tuple[str, ...] | None = None
               ) -> dict[str, Array]:
        """Steady-state forces [N] and moments [N·mm] (ISO-W) at `fz` [N], `kappa` [-],
        `alpha`, `gamma` [rad], `vx` [mm/s] and `pressure` [Pa] (None or NaN entries: the
        model's own speed and pressure), elementwise; `combined=False`: the pure-slip
        functions. Returns channel → array for `channels` (default every one of the model's
        `channels`; a model may return more)."""

    @property
    @abc.abstractmethod
    def nominal_load(self) -> float:
        """The load [N] a bench programme is centred on when the model gives no range."""

    @abc.abstractmethod
    def default_groups(self, channels) -> list[str]:
        """The coefficient groups (`diffsusp.tyre.fit.GROUPS`) a fit estimates when none are
        named, for bench data measuring `channels`."""

    def __getitem__(self, name: str) -> Array:
        return self.coefficients[name]

    @property
    def limit(self) -> dict[str, float]:
        """Validity ranges by name (FZMIN … CAMMAX, SI and rad); none by default."""
        return {}

    def with_limits(self, limits: dict[str, float]) -> Self:
        """A copy with the validity ranges `limits`; a model without ranges is returned as
        is."""
        del limits
        return self

    def with_coefficients(self, coefficients: dict) -> Self:
        """A copy with the coefficient dict `coefficients` (values as given: traced values
        stay traced; the model's other fields kept)."""
        return dataclasses.replace(self, coefficients=dict(coefficients))

    def replace(self, **values) -> Self:
        """A copy with some coefficients changed (library units)."""
        c = dict(self.coefficients)
        for k, v in values.items():
            if k not in c:
                raise ValueError(f"unknown coefficient {k!r}")
            c[k] = jnp.asarray(v, dtype=float)
        return self.with_coefficients(c)

    def constraint_violations(self, fz: ArrayLike, gamma: ArrayLike) -> list[str]:
        """The physical constraints the coefficients break over the range of load `fz` [N] and
        camber `gamma` [rad] (texts); none checked by default."""
        del fz, gamma
        return []

    def data_start(self, data, names, predict) -> dict[str, float]:
        """Starting values of coefficients among `names` from bench `data` (`predict(model)`:
        the model's (c, n) outputs at the data's inputs); none by default."""
        del data, names, predict
        return {}
