"""The example tyre property files shipped with diffsusp (`diffsusp/tyre/data/`, licences and
provenance in its README.md: MFeval 4.0 examples and Project Chrono's FED tyre, BSD-3)."""

import pathlib

__all__ = ["DATA", "EXAMPLES", "example_path"]

DATA = pathlib.Path(__file__).parent / "data"
EXAMPLES = {
    "mf61": "MagicFormula61_Paramerters.tir",
    "mf62": "MagicFormula62_Paramerters.tir",
    "mf52": "MagicFormula52_Paramerters.tir",
    "book": "PacejkaBook_Defaults.tir",
    "truck_60psi": "335_65R22_5_G275MSA_60psi.tir",
    "truck_70psi": "335_65R22_5_G275MSA_70psi.tir",
}
"""Short name → file name (the MFeval names keep their original spelling)."""


def example_path(name: str) -> pathlib.Path:
    """Path of a shipped example `.tir` file by short name (`EXAMPLES`) or file name."""
    file = EXAMPLES.get(name, name)
    path = DATA / file
    if not path.is_file() or path.suffix != ".tir":
        raise ValueError(f"no example tyre {name!r}; known: {', '.join(EXAMPLES)}")
    return path
