"""Static equilibrium (KKT Newton), sweeps and derived outputs."""

from .solve import StaticSolution, solve_statics, solve_sweep

__all__ = ["StaticSolution", "solve_statics", "solve_sweep"]
