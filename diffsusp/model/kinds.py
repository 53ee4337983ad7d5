"""Element-kind vocabulary of a mechanism, shared by the pytree (`mechanism`) and the solver's
index data (`topology`): the ground's part index and the constraint rows of each joint kind."""

import numpy as np

__all__ = ["GROUND", "JOINT_ROWS"]

GROUND = -1
"""Part index of the ground (it has no coordinates)."""

JOINT_ROWS = {
    "spherical": 3,
    "revolute": 5,
    "cylindrical": 4,
    "translational": 5,
    "universal": 4,
    "fixed": 6,
    "inline": 2,
    "inplane": 1,
    "perpendicular": 1,
    "distance": 1,
}
"""Constraint rows per joint kind (Adams definitions, spec stiffness §1.6)."""


def row_blocks(joints) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """Group joints by kind: (kind, joint indices, row offsets of each joint), in row order."""
    offsets = np.cumsum([0] + [JOINT_ROWS[k] for k in joints.kind])[:-1]
    blocks = []
    for kind in JOINT_ROWS:
        idx = np.array([i for i, k in enumerate(joints.kind) if k == kind], dtype=int)
        if idx.size:
            blocks.append((kind, idx, offsets[idx]))
    return blocks
