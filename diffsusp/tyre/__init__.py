"""Tyre force models (spec: tyre_contact_model §2, §7 C).

- `base`: `AbstractTyre`, what every tyre model answers (`forces`, …): the fits call it;
- `mf89`: the thesis's Bakker–Pacejka 1989/1991 Magic Formula (Annex B) and its twelve
  identified sets (`thesis_sets`, Tables 14–29), in the thesis's units (kN, degrees);
- `mf6`: MF 5.2 / 6.1 / 6.2 steady state from `.tir` files (`diffsusp.io.tir`), library units;
  turn slip (MF 6.1/6.2, `evaluate(..., turn_slip=φ_t)`);
- `vertical`: the vertical model (loaded radius with the MF 6.2 camber, force, speed and
  pressure terms, vertical stiffness, effective rolling radius, wheel spin);
- `examples`: the shipped example `.tir` files (`example_path("mf61")`);
- `spec`: specification quantities (exact derivatives), macro-coefficients, similarity;
- `rig`: the tyre on the K&C rig (the coupled tyre–suspension static equilibrium at a
  commanded slip angle, exact sensitivities to the suspension's parameters);
- `fit`: coefficients from bench data (robust Levenberg–Marquardt, exact Jacobians, σ and
  identifiability through `diffsusp.lsq`), one tyre or many in one batched call;

```python
from diffsusp.io.tir import read_tir
from diffsusp import tyre
m = tyre.MagicFormula6.from_tir(read_tir("car.tir"))
f = tyre.evaluate(m, fz=4000.0, kappa=0.02, alpha=0.05)     # N, N·mm
m89 = tyre.MagicFormula89.from_thesis("dunlop_r16", 2.0)
tyre.mf89.fy0(m89, 2.0, 4.5)                                # N at 2°, 4.5 kN
```
"""

from . import contact, examples, fit, mf6, mf89, rig, spec, thesis_sets, vertical  # noqa: F401
from .base import AbstractTyre
from .examples import example_path
from .mf6 import COEFFICIENTS, FITTYP_VERSION, MagicFormula6, TyreForces, check_limits, evaluate
from .mf89 import MagicFormula89
from .spec import specification

__all__ = ["AbstractTyre", "COEFFICIENTS", "FITTYP_VERSION", "MagicFormula6", "MagicFormula89",
           "TyreForces", "check_limits", "evaluate", "example_path", "examples", "fit", "mf6",
           "mf89", "rig", "spec", "specification", "thesis_sets", "vertical"]
