"""Measurements: landmarks → part poses, landmark re-ordering, noise models, bushing
deformations, synthetic measurements, measurement tables (CSV/Parquet; the format is
`diffsusp.io.measurements`), and the measurement types every identification method takes
(`data`: `Landmarks`, `Poses`, `Deformations`, `Channel`, and the conversions from
`Measurements`).

spec: geometry §3.3–3.7 (landmarks, distance tables, Arun/Kabsch, deformations); stiffness §1.1,
§1.12, §2.8 (what the direct method needs; the thesis's numerical protocol). Units: mm, N, N·mm,
rad.
"""

from .data import (
    Channel,
    Deformations,
    Landmarks,
    Measurement,
    Poses,
    as_deformations,
    as_equilibria,
    as_fit_data,
    from_measurements,
)
from .landmarks import (
    COLLINEAR_RATIO,
    REORDER_TOLERANCE,
    LandmarkLayout,
    Reordering,
    check_layout,
    distance_table,
    landmark_positions,
    make_layout,
    place_landmarks,
    reorder_landmarks,
)
from .measurements import (
    Measurements,
    add_noise,
    bushing_deformations,
    case_subset,
    from_landmarks,
    from_poses,
    reregister,
    synthesize,
)
from .noise import ARM_SIGMA, GaussianNoise
from .table import read_measurements, write_measurements

__all__ = [
    "Channel", "Deformations", "Landmarks", "Measurement", "Poses", "as_deformations",
    "as_equilibria", "as_fit_data", "from_measurements",
    "ARM_SIGMA", "COLLINEAR_RATIO", "REORDER_TOLERANCE", "GaussianNoise", "LandmarkLayout",
    "Measurements", "Reordering", "add_noise", "bushing_deformations", "case_subset",
    "check_layout", "distance_table", "from_landmarks", "from_poses", "landmark_positions",
    "make_layout", "place_landmarks", "read_measurements", "reorder_landmarks", "reregister",
    "synthesize", "write_measurements",
]
