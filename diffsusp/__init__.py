"""diffsusp: differentiable elastokinematic (K&C) suspension solver and identification, in JAX.

Units: mm, N, N·mm, rad. Enable float64 (`jax.config.update("jax_enable_x64", True)`) before use.
"""

from . import fleet, geometry, identify, io, kc, lsq, mdh, measure, model, models, statics, tyre  # noqa: F401  (every stage loaded)
from .errors import ConvergenceError, InputError, ModelError, ModelFileError, ModelWarning
from .io import save_model
from .model import Loads, Mechanism, MechanismBuilder
from .resolve import load_model
from .statics import (
    Linearization,
    StaticSolution,
    ValidationReport,
    bushing_states,
    joint_reactions,
    linearize,
    marker_poses,
    part_poses,
    solve_statics,
    solve_sweep,
    spring_states,
    validate,
)

__all__ = [
    "ConvergenceError", "InputError", "Linearization", "Loads", "Mechanism", "MechanismBuilder",
    "ModelError", "ModelFileError", "ModelWarning", "StaticSolution", "ValidationReport",
    "bushing_states", "geometry", "io", "joint_reactions", "linearize", "load_model", "lsq",
    "marker_poses", "part_poses", "save_model", "solve_statics", "solve_sweep", "spring_states",
    "statics", "tyre", "validate",
]
