"""Identification of model parameters from measurements (spec stiffness ch. 4–5, geometry
ch. 2–3, guaranteed least squares):

- `direct`: linear, from measured equilibria (every part's pose; milliseconds).
- `iterative`: the thesis's correlation loop on the solver (measured bushing deformations).
- `least_squares` / `least_squares_batch`: nonlinear least squares through the differentiable
  equilibrium, from any measurements (`Landmarks`, `Poses`, `Deformations`, `Channel`) of any
  parameters (`Params`: stiffnesses, hardpoints), with σ, identifiability and the directions the
  data cannot see; batched over many data sets.
- `geometric` (`locate_joints`, `correct_geometry`): joint centres and axes from the measured
  relative motion of parts, with σ and an observability verdict per joint, and the
  equilibrium-consistent correction of the bolted-side joint frames (geometry ch. 2–3).
- `rehearse`: before measuring, random truths around the start, the planned experiment
  simulated and the method run: how often each parameter is identified and how often
  "identified" is right (`SuspensionScenario`, `GeometryScenario` for the joint locations;
  the tyre fits provide their own scenarios).
- `sensitivity` and `design_experiment`: exact ∂(K&C metric)/∂(parameter), and the choice of
  load cases that best determine chosen parameters.

`measured_bushings`, `with_start` and `fit_selection` choose what to identify and where to start
(the CLI's defaults); `tables` holds the report tables in the thesis's units and the figures.

Each identification takes a mechanism and measurements and returns the identified mechanism and
a report.
"""

from ..measure.data import (
    Channel,
    Deformations,
    Landmarks,
    Measurement,
    Poses,
    from_measurements,
)
from ._direct import (
    DirectReport,
    DirectSystem,
    direct,
    direct_batch,
    direct_selection,
    direct_system,
)
from ._iterative import IterativeReport, iterative
from ._least_squares import (
    BatchFitReport,
    FitReport,
    least_squares,
    least_squares_batch,
    predict,
    returned_values,
    whitened_residuals,
)
from ._rehearse import (
    GeometryScenario,
    ParameterRehearsal,
    RehearsalReport,
    SuspensionScenario,
    corner_cases,
    rehearse,
)
from ._sensitivity import (
    PARAMETER_SETS,
    DesignReport,
    SensitivityReport,
    design_experiment,
    landmark_model,
    parameter_set,
    sensitivity,
    sensitivity_metrics,
)
from .direct_unknowns import Parameter, with_cubic, with_offsets
from .geometric import (
    CorrectionReport,
    GeometricJoint,
    GeometricReport,
    GeometryDesign,
    JointEstimate,
    apply_locations,
    correct_geometry,
    design_geometry_cases,
    element_table,
    joints_from_model,
    locate_joints,
    offset_equivalent,
    read_joints,
    write_joints,
)
from .params import AXES, Params
from .selection import fit_selection, measured_bushings, with_start

__all__ = [
    "CorrectionReport", "GeometricJoint", "GeometricReport", "GeometryDesign", "JointEstimate",
    "apply_locations", "correct_geometry", "design_geometry_cases", "element_table",
    "joints_from_model", "locate_joints", "offset_equivalent", "read_joints", "write_joints",
    "BatchFitReport", "Channel", "Deformations", "DesignReport", "DirectReport", "DirectSystem",
    "FitReport", "IterativeReport", "Landmarks", "Measurement", "Params", "Poses",
    "SensitivityReport", "design_experiment", "direct", "direct_batch", "direct_selection",
    "direct_system",
    "iterative", "fit_selection", "from_measurements", "measured_bushings", "with_start",
    "least_squares", "least_squares_batch", "predict", "RehearsalReport", "SuspensionScenario",
    "GeometryScenario",
    "rehearse",
    "sensitivity", "sensitivity_metrics", "whitened_residuals",
    "AXES", "PARAMETER_SETS", "Parameter", "ParameterRehearsal", "corner_cases", "landmark_model",
    "parameter_set", "returned_values", "with_cubic", "with_offsets",
]
