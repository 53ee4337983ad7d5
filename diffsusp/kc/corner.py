"""Which markers are the wheel: the corners a model carries (`Mechanism.corners`, see
`diffsusp.model.corner`), looked up for K&C events, sensitivity and identification.

Every built-in model and every imported model states its corner when it is built (the Chrono
importer from the file's spindle, contact point and ball joints; a native model file in its
`[[corner]]` tables); nothing is guessed from the model's name. A model without one (an Adams
dataset, a version-1 native file) needs a `Corner` passed as `corner=` (or the CLI's corner
options).
"""

import numpy as np

from ..errors import InputError
from ..model import Mechanism
from ..model.corner import (  # noqa: F401  (re-exported: diffsusp.kc.Corner)
    FRAMES,
    Corner,
    PointRef,
    ResolvedCorner,
)


def default_corner(mech: Mechanism, prefix: str = "") -> Corner:
    """The corner `mech` carries under `prefix` ('' for a half axle), or an `InputError` that
    says how to describe the wheel."""
    for corner in mech.corners:
        if corner.prefix == prefix:
            return corner
    stated = ", ".join(repr(c.prefix) for c in mech.corners)
    raise InputError(
        f"no default K&C corner for model '{mech.name}'"
        + (f" under prefix '{prefix}' (it has {stated})" if stated else
           " (the model states none: an Adams dataset or a version-1 native file)")
        + ". Describe the wheel with diffsusp.kc.Corner(wheel_centre=..., contact_point=..., "
        "kingpin=(upper, lower), frame='adams'|'iso', loaded_radius=...) and pass it as "
        "corner=, or store it with the model (MechanismBuilder.corner, a [[corner]] table of "
        "the native file)."
    )


def corners_of(mech: Mechanism) -> dict[str, Corner]:
    """The corners of a model by prefix: one for a half axle (key ''), or one per side for an
    axle made by `diffsusp.model.combine.combine` (keys are its prefixes, e.g. 'left/')."""
    if not mech.corners:
        return {"": default_corner(mech)}
    return {c.prefix: c for c in mech.corners}


_LOADS = {}  # id(mechanism) → (mechanism, contact point, up, load): a computed design load


def equilibrium_load(mech: Mechanism, contact_point: str, up=(0.0, 0.0, 1.0)) -> float:
    """The vertical contact load (N, along `up`) at load point `contact_point` for which the
    design position q = 0 is an equilibrium of `mech` without its motion drivers: the
    least-squares (F, λ) of the generalised-force rows of the design KKT residual,
    Q0 + F·Q1 + Φ_qᵀλ = 0 (exact for a one-DOF corner; spec: stiffness §1.4, virtual work).
    The program of `diffsusp.model.validate.design_terms` (the one validation compiled); the
    value is remembered per mechanism object."""
    hit = _LOADS.get(id(mech))
    if hit is not None and hit[0] is mech and hit[1:3] == (contact_point, tuple(up)):
        return hit[3]
    from ..model import Loads
    from ..model.validate import design_terms
    from .rig import remove_drivers

    base = remove_drivers(mech, mech.drivers.names)
    k = base.load_points.index(contact_point)
    n, n_l = base.n_coordinates, len(base.load_points.names)
    zero = np.zeros((n_l, 3))
    unit = zero.copy()
    unit[k] = np.asarray(up, dtype=float)
    r0 = design_terms(base, Loads(force=zero, moment=zero, driver=np.zeros(0)))[1][:n]
    _, r1, jac = design_terms(base, Loads(force=unit, moment=zero, driver=np.zeros(0)))
    a = jac[:n, n:]  # Φ_qᵀ: the residual is linear in the multipliers
    sol = np.linalg.lstsq(np.column_stack([r1[:n] - r0, a]), -r0, rcond=None)[0]
    value = float(sol[0])
    if len(_LOADS) > 64:
        _LOADS.clear()
    _LOADS[id(mech)] = (mech, contact_point, tuple(up), value)
    return value


__all__ = ["FRAMES", "Corner", "PointRef", "ResolvedCorner", "corners_of", "default_corner",
           "equilibrium_load"]
