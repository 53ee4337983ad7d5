"""Validation of a mechanism at its design position on the solver's exact terms: DOF, rank,
redundancy, free modes, joints not assembled (spec stiffness §1.6).

`validate` is `MechanismBuilder.build`'s check (`diffsusp.model.structure`, NumPy: building
compiles nothing) run on the KKT residual and Jacobian that `assemble` gives at q = 0 — the
same analysis, with the elements' preload (geometric) stiffness included. One compiled program
per model structure, shared with the corner's equilibrium load (`design_terms`).
"""

import dataclasses

import jax.numpy as jnp
import numpy as np

from ..compilation import filter_jit
from ..model import Mechanism
from ..model.structure import analyse
from .kernel import assemble, constraint_values, to_internal


@dataclasses.dataclass(frozen=True)
class ValidationReport:
    """Structure of a mechanism at its design position.

    **Fields:** `n_coordinates` (6 per moving part), `n_rows` (joint and driver rows), `rank`
    of Φ_q, `dof` = n_coordinates − rank (kinematic degrees of freedom, bushings ignored),
    `redundant` (names of dropped rows), `free_modes` (descriptions of modes with neither
    constraint nor stiffness), `max_assembly_error` (largest constraint violation at design, mm).
    """

    n_coordinates: int
    n_rows: int
    rank: int
    dof: int
    redundant: tuple[str, ...]
    free_modes: tuple[str, ...]
    max_assembly_error: float

    def __str__(self) -> str:
        lines = [
            f"coordinates: {self.n_coordinates}, constraint rows: {self.n_rows}, "
            f"rank: {self.rank}, kinematic DOF: {self.dof}",
            f"redundant rows: {', '.join(self.redundant) if self.redundant else 'none'}",
            f"free modes: {'; '.join(self.free_modes) if self.free_modes else 'none'}",
        ]
        return "\n".join(lines)


@filter_jit
def _at_design(mech: Mechanism, loads):
    q0 = to_internal(mech, jnp.zeros(mech.n_coordinates))
    phi = constraint_values(mech, loads, q0)
    r, jac = assemble(mech, loads, q0, jnp.zeros(mech.topology.m))
    return phi, r, jac


def design_terms(mech: Mechanism, loads=None):
    """At the design position q = 0 with every constraint row kept and zero multipliers, under
    `loads` (one case; default none): constraint values Φ, the KKT residual r (generalised
    forces, then the rows) and its Jacobian (numpy). One compiled program per model structure,
    whatever the model's name or corners (`validate` and `diffsusp.kc.equilibrium_load` share
    it)."""
    all_rows = dataclasses.replace(mech, independent_rows=tuple(range(mech.n_rows)), name="",
                                   corners=())
    phi, r, jac = _at_design(all_rows, all_rows.loads() if loads is None else loads)
    return np.asarray(phi), np.asarray(r), np.asarray(jac)


def validate(mech: Mechanism, *, tol: float = 1e-9) -> ValidationReport:
    """Check a mechanism at design and report its structure (see the module docstring and
    `diffsusp.model.structure`); `tol`: a mode is free when its stiffness is at most `tol`
    times the largest diagonal stiffness (scaled)."""
    phi, _, jac = design_terms(mech)
    n = mech.n_coordinates
    s = analyse(dataclasses.replace(mech, independent_rows=tuple(range(mech.n_rows))),
                phi, jac[n:, :n], -jac[:n, :n], tol)
    return ValidationReport(
        n_coordinates=n,
        n_rows=mech.n_rows,
        rank=s.rank,
        dof=n - s.rank,
        redundant=s.redundant,
        free_modes=s.free_modes,
        max_assembly_error=float(s.assembly.max()) if s.assembly.size else 0.0,
    )
