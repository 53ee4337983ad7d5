"""Static equilibrium (KKT Newton), sweeps and derived outputs."""

from .outputs import (
    bushing_states,
    joint_reactions,
    marker_poses,
    part_poses,
    spring_states,
)
from .solve import StaticSolution, solve_statics, solve_sweep

__all__ = [
    "StaticSolution", "bushing_states", "joint_reactions", "marker_poses", "part_poses",
    "solve_statics", "solve_sweep", "spring_states",
]
