"""What to identify and where to start: the bushing selection of the `iterative` method, the
parameter selection of the `least_squares` fit with start values, and the display units of
the thesis's tables (spec stiffness §1.8, §2.2, §3; the CLI's `identify iterative|fit` call
these, a script may too).

Stiffnesses are N/mm (translational) and N·mm/rad (rotational) in the model; the thesis quotes
rotational stiffnesses per degree, so a start value `start` means `start` N/mm and `start`
N·mm/deg (the thesis's start: 10⁴ for both, spec stiffness §2.2).
"""

from collections.abc import Sequence

import equinox as eqx
import numpy as np

from ..errors import InputError
from ..geometry import DEG
from ..model import Mechanism
from .params import AXES, Params

ROTATIONAL = ("Krx", "Kry", "Krz")


def measured_bushings(mech: Mechanism, meas, names: Sequence[str] | None = None
                      ) -> tuple[str, ...]:
    """The bushings to identify: `names` (checked against the model), or every bushing whose
    parts are all measured (`meas.parts`; ground counts as measured). Raises `InputError` when
    a name is unknown or no bushing qualifies."""
    if names:
        for n in names:
            if n not in mech.bushings.names:
                raise InputError(f"model '{mech.name}' has no bushing '{n}'; its bushings: "
                                 f"{', '.join(mech.bushings.names) or 'none'}.")
        return tuple(names)
    measured = set(meas.parts)
    out = tuple(name for b, name in enumerate(mech.bushings.names)
                if all(p < 0 or mech.parts[p] in measured
                       for p in (mech.markers.part[mech.bushings.i_marker[b]],
                                 mech.markers.part[mech.bushings.j_marker[b]])))
    if not out:
        raise InputError("no bushing of the model connects measured parts only; measure the "
                         "parts of the bushings to identify, or name them with --bushing.")
    return out


def with_start(mech: Mechanism, names: Sequence[str], start: float | None) -> Mechanism:
    """`mech` with every stiffness of the bushings `names` set to `start` (N/mm and N·mm/deg);
    `start=None` returns `mech` unchanged. Raises `InputError` for a non-positive start."""
    if start is None:
        return mech
    if not start > 0:
        raise InputError(f"--start must be a positive stiffness; got {start}.")
    idx = [mech.bushings.index(n) for n in names]
    kt, kr = np.array(mech.bushings.k_trans), np.array(mech.bushings.k_rot)
    kt[idx], kr[idx] = start, start / DEG
    return eqx.tree_at(lambda m: (m.bushings.k_trans, m.bushings.k_rot), mech, (kt, kr))


def without_zeros(mech: Mechanism) -> Mechanism:
    """`mech` with every non-positive stiffness and spring rate set to 1 (a placeholder for a
    selection whose start values are all given)."""
    def positive(a):
        a = np.asarray(a, dtype=float)
        return np.where(a > 0, a, 1.0)

    return eqx.tree_at(lambda m: (m.bushings.k_trans, m.bushings.k_rot, m.springs.k), mech,
                       tuple(positive(a) for a in (mech.bushings.k_trans, mech.bushings.k_rot,
                                                  mech.springs.k)))


def named_stiffnesses(mech: Mechanism, names: Sequence[str] | None = None) -> Params:
    """The stiffnesses named 'bushing.Ktx', … among the default fit selection (`fit_selection`:
    every stiffness that is not 0 in the model), in that order by bushing; None or empty: the
    whole default. Raises `InputError` for a name outside it."""
    default = fit_selection(mech)[0]
    wanted = [n.strip() for n in names or () if n.strip()]
    if not wanted:
        return default
    unknown = [n for n in wanted if n not in default.names]
    if unknown:
        raise InputError(f"unknown parameter(s) {', '.join(unknown)}; the model's: "
                         f"{', '.join(default.names)}.")
    params = None
    for bushing in dict.fromkeys(n.rsplit(".", 1)[0] for n in wanted):
        axes = tuple(n.rsplit(".", 1)[1] for n in wanted if n.rsplit(".", 1)[0] == bushing)
        p = Params.bushing_stiffness(mech, (bushing,), axes=axes)
        params = p if params is None else params + p
    return params


def fit_selection(mech: Mechanism, bushings: Sequence[str] | None = None,
                  axes: str | Sequence[str] | None = None, *, centres: bool = False,
                  springs: bool = False, start: float | None = None
                  ) -> tuple[Params, list[str]]:
    """The parameters of a least-squares fit (spec stiffness §3, §6 item 8) and notes on what
    was left out.

    `bushings` (default: all) × `axes` (a sequence or 'Ktx,Ktz'; default all six) stiffnesses,
    plus the bushings' centres (`centres`) and the spring rates (`springs`). Without `start`, a
    stiffness or spring rate that is 0 in the model (a free direction: no log-scaled start
    exists) is left out, with a note; with `start` every selected stiffness starts there (N/mm,
    N·mm/deg). Raises `InputError` when nothing is selected."""
    if isinstance(axes, str):
        axes = tuple(a.strip() for a in axes.split(","))
    axes = tuple(axes) if axes else AXES
    names = tuple(bushings or mech.bushings.names)
    notes: list[str] = []
    params = None

    def add(p):
        nonlocal params
        params = p if params is None else params + p

    if names and axes and start is None:
        if any(n not in mech.bushings.names for n in names):
            add(Params.bushing_stiffness(mech, names, axes=axes))  # names the unknown bushing
        k = np.concatenate([np.asarray(mech.bushings.k_trans),
                            np.asarray(mech.bushings.k_rot)], axis=1)
        zero = [f"{n}.{a}" for n in names for a in axes
                if a in AXES and not k[mech.bushings.index(n), AXES.index(a)] > 0]
        if zero:
            notes.append(
                f"left out {len(zero)} stiffness(es) that are 0 in the model (free "
                f"directions; a zero cannot be fitted on a log scale): {', '.join(zero)}. "
                "Give --start to fit every selected stiffness from one positive value.")
        pairs = [(n, a) for n in names for a in axes if f"{n}.{a}" not in zero]
        for n in dict.fromkeys(n for n, _ in pairs):
            add(Params.bushing_stiffness(mech, (n,), axes=tuple(a for m, a in pairs if m == n)))
    elif names and axes:
        # Every value is replaced by `start`: select from a copy without zero stiffnesses.
        add(Params.bushing_stiffness(without_zeros(mech), names, axes=axes))
    if centres:
        add(Params.bushing_centres(mech, names))
    if springs and mech.springs.names:
        rate = np.asarray(mech.springs.k) > 0
        if start is None and not rate.all():
            notes.append("left out the spring rate(s) that are 0 in the model: " + ", ".join(
                n for n, ok in zip(mech.springs.names, rate, strict=True) if not ok) + ".")
        if rate.any() or start is not None:
            add(Params.leaves(without_zeros(mech), lambda m: m.springs.k,
                              None if start is not None else rate))
    if params is None:
        raise InputError("nothing to identify: the model has no bushings (or --axes is empty, "
                         "or every selected stiffness is 0: give --start) and neither "
                         "--centres nor --springs was asked.")
    if start is not None:
        axis = [name.rsplit(".", 1)[-1] for name in params.names]
        values = np.where([a in ROTATIONAL for a in axis], start / DEG, start)
        params = params.with_start(np.where([a in AXES for a in axis], values,
                                            np.asarray(params.start, dtype=float)))
    return params, notes


def display_value(name: str, value: float) -> tuple[float, str]:
    """`value` of parameter `name` in the thesis's units: (value, unit), rotational stiffness
    per degree (N*mm/deg), translational stiffness and spring rate N/mm, positions mm."""
    axis = name.rsplit(".", 1)[-1]
    if axis in ROTATIONAL:
        return value * DEG, "N*mm/deg"
    if axis in ("Ktx", "Kty", "Ktz") or name.endswith(".k"):
        return value, "N/mm"
    return value, "mm"


__all__ = ["ROTATIONAL", "display_value", "fit_selection", "measured_bushings",
           "named_stiffnesses", "with_start", "without_zeros"]
