"""diffsusp: differentiable elastokinematic (K&C) suspension solver and identification, in JAX.

Units: mm, N, N·mm, rad. Enable float64 (`jax.config.update("jax_enable_x64", True)`) before use.
"""

from . import geometry, io, lsq
from .errors import ConvergenceError, InputError, ModelError, ModelFileError, ModelWarning
from .io import load_model, save_model
from .model import Loads, Mechanism, MechanismBuilder, ValidationReport, validate
from .statics import (
    StaticSolution,
    bushing_states,
    joint_reactions,
    marker_poses,
    part_poses,
    solve_statics,
    solve_sweep,
    spring_states,
)

__all__ = [
    "ConvergenceError", "InputError", "Loads", "Mechanism", "MechanismBuilder", "ModelError",
    "ModelFileError", "ModelWarning",
    "StaticSolution", "ValidationReport", "bushing_states", "geometry", "io", "joint_reactions",
    "load_model", "lsq", "marker_poses", "part_poses", "solve_statics", "save_model", "solve_sweep",
    "spring_states", "validate",
]
