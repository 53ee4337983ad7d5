"""Mechanism pytree, builder and validation."""

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
from .validate import ValidationReport, validate

__all__ = [
    "GROUND", "JOINT_ROWS", "Bushings", "Drivers", "Joints", "LoadPoints", "Loads", "Markers",
    "Mechanism", "MechanismBuilder", "Springs", "Stops", "ValidationReport", "describe",
    "frame_from_axes", "parameter_leaves", "validate",
]
