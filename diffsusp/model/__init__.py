"""Mechanism pytree, builder, corners and the build-time checks."""

from .builder import MechanismBuilder, frame_from_axes
from .kinds import GROUND, JOINT_ROWS
from .mechanism import (
    Bushings,
    Drivers,
    Joints,
    LoadPoints,
    Loads,
    Markers,
    Mechanism,
    Springs,
    Stops,
    describe,
    parameter_leaves,
)

__all__ = [
    "GROUND", "JOINT_ROWS", "Bushings", "Drivers", "Joints", "LoadPoints", "Loads", "Markers",
    "Mechanism", "MechanismBuilder", "Springs", "Stops", "describe", "frame_from_axes",
    "parameter_leaves",
]
