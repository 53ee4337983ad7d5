"""The measurement types of identification now live in `diffsusp.measure.data` (one home for
every measurement: `measure.Measurements` and `Landmarks`, `Poses`, `Deformations`,
`Channel`); this module keeps the old import path working."""

from ..measure.data import (
    Channel,
    Deformations,
    Landmarks,
    Measurement,
    Poses,
    data_axes,
    from_measurements,
)

__all__ = ["Channel", "Deformations", "Landmarks", "Measurement", "Poses", "data_axes",
           "from_measurements"]
