"""Modified Denavit–Hartenberg trees: geometry, kinematics and Newton–Euler dynamics.

spec: tyre_contact_model §6 (Annex F), §1.4 and §5.2 (the thesis's tables). A small, general
robotics module: the tyre's physical model (`diffsusp.tyre.contact`) and the synthetic vehicle
(`diffsusp.tyre.vehicle`) are built on it.

```python
from diffsusp import mdh
tree = mdh.tables.contact_chain()                   # Table 1: 10 frames, 7 DOF
T = mdh.forward_kinematics(tree, q)                 # ^0T_j of every body
tau = mdh.inverse_dynamics(tree, params, q, qd, qdd)
W, tau0 = mdh.regressor(tree, q, qd, qdd)           # tau = W @ params.ravel() + tau0
fit, names = mdh.base_parameters(tree, jax.random.key(0))   # lsq.Fit: rank, relations
```
"""

from . import tables
from .dynamics import (
    INERTIAL,
    JOINT,
    PER_JOINT,
    Dynamics,
    Motion,
    base_parameters,
    forward_dynamics,
    inverse_dynamics,
    mass_matrix,
    newton_euler,
    parameter_names,
    regressor,
    regressor_batch,
)
from .tree import (
    LOCKED,
    PRISMATIC,
    REVOLUTE,
    Row,
    Tree,
    attach,
    change_of_point,
    forward_kinematics,
    from_rows,
    inverse_transform,
    jacobian,
    joint_transforms,
    path,
    skew,
    transform,
    twist_transport,
)

__all__ = [
    "INERTIAL", "JOINT", "LOCKED", "PER_JOINT", "PRISMATIC", "REVOLUTE", "Dynamics", "Motion",
    "Row", "Tree", "attach", "base_parameters", "change_of_point", "forward_dynamics",
    "forward_kinematics", "from_rows", "inverse_dynamics", "inverse_transform", "jacobian",
    "joint_transforms", "mass_matrix", "newton_euler", "parameter_names", "path", "regressor",
    "regressor_batch", "skew", "tables", "transform", "twist_transport",
]
