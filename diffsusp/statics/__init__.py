"""Static equilibrium (KKT Newton), sweeps and derived outputs."""

from ._linearize import Linearization, linearize, linearize_internal, residual, scaled_solve
from .kernel import generalised_forces, to_internal, to_public
from .outputs import (
    bushing_states,
    flagged_cases,
    joint_reactions,
    marker_poses,
    part_poses,
    spring_states,
)
from .solve import StaticSolution, solve_statics, solve_statics_chunks, solve_sweep
from .status import STATUS_TEXT, Status
from .validation import ValidationReport, validate

__all__ = [
    "STATUS_TEXT", "Linearization", "StaticSolution", "Status", "ValidationReport",
    "bushing_states", "flagged_cases", "generalised_forces", "joint_reactions", "linearize",
    "linearize_internal", "marker_poses", "part_poses", "residual", "scaled_solve",
    "solve_statics", "solve_statics_chunks", "solve_sweep", "spring_states", "to_internal",
    "to_public", "validate",
]
