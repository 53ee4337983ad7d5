"""Measurement types of identification: what was measured, under which loads, with which
uncertainty; and the conversions that let every identification method take any of them.

spec: stiffness §2.2 (deformations from poses), §2.8 (landmarks with σ = 0.05 mm), §6 item 8
(marker or deformation residuals, K&C responses); DESIGN.md "Identification".

Each measurement carries its load table (`Loads`, leading case axis), its measured values, their
standard deviations σ and an optional mask (False = missing or excluded). The residual of an entry
is (model − measured), whitened by σ: r = mask·(model − measured)/σ. Measured values may carry
one extra leading axis (several data sets under the same loads, σ and mask): that is what
`least_squares_batch` identifies in one compiled call.

One measurement object for every method (DESIGN.md "Identification"): `direct`, `iterative`
and `least_squares` all accept a `measure.Measurements` (measured equilibria: part poses, with
the landmarks they were registered from) or the types here, and take from it what their
equations need: the part poses (`as_equilibria`), the bushing deformations
(`as_deformations`) or whitened residuals (`as_fit_data`).
"""

from collections.abc import Callable, Sequence
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..errors import InputError
from ..model.mechanism import GROUND, Loads, Mechanism
from ..statics import bushing_states, part_poses
from .measurements import Measurements, bushing_deformations, from_poses


def _as_measured(value, core_shape: tuple[int | None, ...], what: str, n_cases: int | None):
    """Float array of shape core_shape (None = any) or with one leading data-set axis."""
    arr = np.asarray(value, dtype=float)
    rank = len(core_shape)
    if arr.ndim not in (rank, rank + 1):
        raise InputError(f"{what}: measured values must have shape {_shape_text(core_shape)} "
                         f"(or with a leading data-set axis); got {arr.shape}.")
    core = arr.shape[arr.ndim - rank:]
    for got, want in zip(core, core_shape, strict=True):
        if want is not None and got != want:
            raise InputError(f"{what}: measured values must have shape "
                             f"{_shape_text(core_shape)}; got {arr.shape}.")
    if n_cases is not None and core[0] != n_cases:
        raise InputError(f"{what}: {core[0]} measured cases for a load table of {n_cases} "
                         "cases; give one row per load case.")
    return arr


def _shape_text(shape):
    return "(" + ", ".join("·" if s is None else str(s) for s in shape) + ")"


def _weights(measured: np.ndarray, core: tuple[int, ...], sigma, mask, what: str,
             sigma_names: str) -> tuple[np.ndarray, np.ndarray]:
    """(measured with masked entries set to 0, mask/σ of shape `core`)."""
    sigma = np.asarray(sigma, dtype=float)
    try:
        sigma = np.broadcast_to(sigma, core)
    except ValueError:
        raise InputError(f"{what}: sigma of shape {sigma.shape} does not broadcast to the "
                         f"measured shape {core} ({sigma_names}).") from None
    if not np.all(np.isfinite(sigma) & (sigma > 0)):
        raise InputError(f"{what}: every sigma must be finite and > 0 ({sigma_names}); mask "
                         "entries out instead of giving them an infinite sigma.")
    if mask is None:
        keep = np.ones(core, bool)
    else:
        keep = np.asarray(mask, dtype=bool)
        while keep.ndim < len(core):  # e.g. a (cases, k) mask for (cases, k, 3) points
            keep = keep[..., None]
        try:
            keep = np.broadcast_to(keep, core)
        except ValueError:
            raise InputError(f"{what}: mask of shape {np.shape(mask)} does not fit the measured "
                             f"shape {core}.") from None
    bad = ~np.isfinite(measured) & keep
    if bad.any():
        at = tuple(int(i) for i in np.argwhere(bad)[0])
        raise InputError(f"{what}: measured value at index {at} is not finite; mark missing "
                         "values False in `mask`.")
    measured = np.where(keep, measured, 0.0)
    return measured, keep / sigma


def _check_loads(loads: Loads, what: str) -> int:
    if not isinstance(loads, Loads) or loads.n_cases is None:
        raise InputError(f"{what}: `loads` must be a Loads table with a leading case axis (see "
                         "Mechanism.loads or models.thesis_load_cases).")
    return loads.n_cases


class Measurement(eqx.Module):
    """Base of the measurement types: `loads`, `weight` (mask/σ, the shape of one data set's
    measured values) and `name`; `residual(mech, q)` gives model − measured (physical units)
    at the equilibria q `(cases, n)` of `loads`. `value_fields` names the fields that hold the
    measured values (those a batch of data sets stacks on a leading axis)."""

    value_fields: ClassVar[tuple[str, ...]] = ("measured",)

    def predict(self, mech: Mechanism, q):
        """The model's values of this measurement at the equilibria q `(cases, n)`."""
        raise NotImplementedError

    def check(self, mech: Mechanism):
        """Raise `InputError` if the measurement does not fit `mech` (names, load table)."""
        force = self.loads.force
        if force.shape[-2] != len(mech.load_points.names) or (
                self.loads.driver.shape[-1] != len(mech.drivers.names)):
            raise InputError(f"{self.name}: the load table has {force.shape[-2]} load points "
                             f"and {self.loads.driver.shape[-1]} drivers, the model "
                             f"'{mech.name}' {len(mech.load_points.names)} and "
                             f"{len(mech.drivers.names)}; build it with that model's "
                             "Mechanism.loads.")
        known = ("ground",) + mech.parts
        for part in getattr(self, "parts", ()):
            if part not in known:
                raise InputError(f"{self.name}: unknown part '{part}'; the model's parts are: "
                                 f"{', '.join(known)}.")
        for bushing in getattr(self, "bushings", ()):
            if bushing not in mech.bushings.names:
                raise InputError(f"{self.name}: unknown bushing '{bushing}'; the model's "
                                 f"bushings are: {', '.join(mech.bushings.names)}.")

    def residual(self, mech: Mechanism, q) -> Array:
        """Model − measured (physical units), the shape of `weight`."""
        return self.predict(mech, q) - getattr(self, self.value_fields[0])

    @property
    def n_sets(self) -> int | None:
        """Number of data sets (leading axis of the measured values), None for one."""
        first = getattr(self, self.value_fields[-1])
        return first.shape[0] if first.ndim > self.weight.ndim else None

    def select(self, k: int) -> "Measurement":
        """The `k`-th data set of a batched measurement."""
        return eqx.tree_at(lambda m: tuple(getattr(m, f) for f in self.value_fields), self,
                           tuple(getattr(self, f)[k] for f in self.value_fields))


class Landmarks(Measurement):
    """Positions of points fixed on parts (a measuring arm's targets), per load case.

    **Fields:** `points` `(k, 3)` the points' global positions at design (q = 0), mm;
    `parts` the part carrying each point (`'ground'` allowed); `measured` `(cases, k, 3)`
    measured global positions (mm); `weight` = mask/σ.
    """

    loads: Loads
    points: Float[Array, "k 3"]
    measured: Float[Array, "*sets cases k 3"]
    weight: Float[Array, "cases k 3"]
    parts: tuple[str, ...] = eqx.field(static=True)
    name: str = eqx.field(static=True, default="landmarks")

    def __init__(self, loads: Loads, parts: Sequence[str], points, measured, sigma,
                 mask=None, name: str = "landmarks"):
        """**Arguments:** `loads`; `parts` (k names); `points` `(k, 3)` design positions
        (mm, global); `measured` `(cases, k, 3)` or `(sets, cases, k, 3)` (mm); `sigma` (mm,
        broadcast to `(cases, k, 3)`); `mask` `(cases, k)` or `(cases, k, 3)`, False = missing.
        """
        n = _check_loads(loads, name)
        parts = tuple(parts)
        points = np.asarray(points, dtype=float)
        if points.shape != (len(parts), 3):
            raise InputError(f"{name}: points must have shape ({len(parts)}, 3), one per part "
                             f"name; got {points.shape}.")
        measured = _as_measured(measured, (n, len(parts), 3), name, n)
        measured, weight = _weights(measured, (n, len(parts), 3), sigma, mask, name, "mm")
        self.loads, self.parts, self.name = loads, parts, name
        self.points, self.measured, self.weight = (jnp.asarray(points), jnp.asarray(measured),
                                                   jnp.asarray(weight))

    @classmethod
    def on_markers(cls, mech: Mechanism, markers: Sequence[str], loads: Loads, measured, sigma,
                   mask=None, name: str = "landmarks") -> "Landmarks":
        """Landmarks at the design positions of the named markers (on those markers' parts).
        The points are copied: identifying marker positions later does not move them."""
        idx = [mech.markers.index(m) for m in markers]
        parts = tuple("ground" if mech.markers.part[i] == GROUND else
                      mech.parts[mech.markers.part[i]] for i in idx)
        points = np.asarray(mech.markers.position)[idx]
        return cls(loads, parts, points, measured, sigma, mask, name)

    def predict(self, mech: Mechanism, q) -> Float[Array, "cases k 3"]:
        """Model positions of the points at the equilibria q `(cases, n)` (mm, global)."""
        index = np.array([mech.part_index(p) for p in self.parts])
        moving = index != GROUND
        rot, trans = part_poses(mech, q)  # (cases, P, 3, 3), (cases, P, 3)
        if not len(mech.parts):
            return jnp.broadcast_to(self.points, (q.shape[0], *self.points.shape))
        safe = np.where(moving, index, 0)
        moved = trans[:, safe] + jnp.einsum("cpij,pj->cpi", rot[:, safe], self.points)
        return jnp.where(moving[None, :, None], moved, self.points)


def _rotation_error(r_model, r_meas):
    """Small-angle rotation error (rad, global axes) of r_model relative to r_meas:
    vee(E − Eᵀ)/2 with E = R_model R_measᵀ (= sin θ · axis)."""
    e = r_model @ jnp.swapaxes(r_meas, -1, -2)
    return 0.5 * jnp.stack([e[..., 2, 1] - e[..., 1, 2], e[..., 0, 2] - e[..., 2, 0],
                            e[..., 1, 0] - e[..., 0, 1]], axis=-1)


class Poses(Measurement):
    """Measured part poses (e.g. registered from landmarks), per load case.

    Residual per part: translation error (mm) and rotation error (rad, global axes, the
    small-angle vector of R_model R_measᵀ), whitened by `sigma_translation`, `sigma_rotation`.
    """

    value_fields: ClassVar[tuple[str, ...]] = ("rotation", "translation")

    loads: Loads
    rotation: Float[Array, "*sets cases p 3 3"]
    translation: Float[Array, "*sets cases p 3"]
    weight: Float[Array, "cases p 6"]
    parts: tuple[str, ...] = eqx.field(static=True)
    name: str = eqx.field(static=True, default="poses")

    def __init__(self, loads: Loads, parts: Sequence[str], rotation, translation,
                 sigma_translation, sigma_rotation, mask=None, name: str = "poses"):
        """**Arguments:** `rotation` `(cases, p, 3, 3)` and `translation` `(cases, p, 3)`
        (mm) of each part frame (identity and 0 at design), with an optional leading data-set
        axis; σ in mm and rad; `mask` `(cases, p)`."""
        n = _check_loads(loads, name)
        parts = tuple(parts)
        rotation = _as_measured(rotation, (n, len(parts), 3, 3), name, n)
        translation = _as_measured(translation, (n, len(parts), 3), name, n)
        core = (n, len(parts), 6)
        sigma = np.concatenate([np.broadcast_to(sigma_translation, 3),
                                np.broadcast_to(sigma_rotation, 3)])
        keep = None if mask is None else np.asarray(mask, bool)
        _, weight = _weights(np.zeros(core), core, sigma, keep, name, "mm and rad")
        keep_t = weight[..., :3] > 0
        keep_r = (weight[..., 3:] > 0).any(axis=-1)
        for what, value, kept in (("translation", translation, keep_t),
                                  ("rotation", rotation, keep_r[..., None, None])):
            bad = ~np.isfinite(value) & kept
            if bad.any():
                at = tuple(int(i) for i in np.argwhere(bad)[0])
                raise InputError(f"{name}: measured {what} at index {at} is not finite; mark "
                                 "missing poses False in `mask`.")
        rotation = np.where(keep_r[..., None, None], rotation, np.eye(3))
        translation = np.where(keep_t, translation, 0.0)
        self.loads, self.parts, self.name = loads, parts, name
        self.rotation, self.translation = jnp.asarray(rotation), jnp.asarray(translation)
        self.weight = jnp.asarray(weight)

    def predict(self, mech, q):
        """(rotation `(cases, p, 3, 3)`, translation `(cases, p, 3)`) of the parts."""
        index = np.array([mech.part_index(p) for p in self.parts])
        rot, trans = part_poses(mech, q)
        return rot[:, index], trans[:, index]

    def residual(self, mech, q):
        rot, trans = self.predict(mech, q)
        return jnp.concatenate([trans - self.translation,
                                _rotation_error(rot, self.rotation)], axis=-1)


class Deformations(Measurement):
    """Measured bushing deformations (Tx, Ty, Tz in mm; projected angles AX, AY, AZ in rad;
    I relative to J, in J: spec stiffness §2.2), per load case."""

    loads: Loads
    measured: Float[Array, "*sets cases n 6"]
    weight: Float[Array, "cases n 6"]
    bushings: tuple[str, ...] = eqx.field(static=True)
    name: str = eqx.field(static=True, default="deformations")

    def __init__(self, loads: Loads, bushings: Sequence[str], measured, sigma, mask=None,
                 name: str = "deformations"):
        """**Arguments:** `measured` `(cases, n, 6)`; `sigma` broadcast to it, e.g.
        `(0.01, 0.01, 0.01, 1e-4, 1e-4, 1e-4)` (mm, rad); `mask` `(cases, n)` or full."""
        n = _check_loads(loads, name)
        bushings = tuple(bushings)
        measured = _as_measured(measured, (n, len(bushings), 6), name, n)
        measured, weight = _weights(measured, (n, len(bushings), 6), sigma, mask, name,
                                    "mm, rad")
        self.loads, self.bushings, self.name = loads, bushings, name
        self.measured, self.weight = jnp.asarray(measured), jnp.asarray(weight)

    def predict(self, mech, q):
        index = np.array([mech.bushings.index(b) for b in self.bushings])
        d_t, ang, _, _ = bushing_states(mech, q)
        return jnp.concatenate([d_t, ang], axis=-1)[:, index]


class Channel(Measurement):
    """Any response computed from the equilibria: `fn(mech, q) -> (cases, k)` (e.g. a K&C
    channel: toe, camber, wheel-centre position vs load), with its measured values."""

    loads: Loads
    measured: Float[Array, "*sets cases k"]
    weight: Float[Array, "cases k"]
    fn: Callable = eqx.field(static=True)
    name: str = eqx.field(static=True, default="channel")

    def __init__(self, loads: Loads, fn: Callable, measured, sigma, mask=None,
                 name: str = "channel"):
        """**Arguments:** `fn(mech, q)` with q `(cases, n)`, returning `(cases, k)` in the
        units of `measured` and `sigma`; `measured` `(cases, k)`; `mask` `(cases, k)`."""
        n = _check_loads(loads, name)
        measured = np.asarray(measured, dtype=float)
        if measured.ndim == 1:
            measured = measured[:, None]
        measured = _as_measured(measured, (n, None), name, n)
        core = measured.shape[-2:]
        measured, weight = _weights(measured, core, sigma, mask, name, "the channel's units")
        self.loads, self.fn, self.name = loads, fn, name
        self.measured, self.weight = jnp.asarray(measured), jnp.asarray(weight)

    def predict(self, mech, q):
        out = jnp.asarray(self.fn(mech, q))
        return out[:, None] if out.ndim == 1 else out


def from_measurements(meas, sigma: float, sigma_rotation: float) -> Measurement:
    """The least-squares measurement of a `diffsusp.measure.Measurements` (e.g. a landmark or
    pose table read by `measure.read_measurements`): its landmarks themselves when it has them
    (any subset of the parts; a part with fewer than three landmarks still counts; missing or
    excluded landmarks masked), else its part poses.

    **Arguments:** `sigma` (mm) per landmark coordinate or pose translation; `sigma_rotation`
    (rad) per pose rotation axis (poses only).
    """
    if meas.landmarks is None:
        return Poses(meas.loads, meas.parts, np.asarray(meas.rotation),
                     np.asarray(meas.translation), sigma, sigma_rotation)
    layout = meas.layout
    part_index, slot = np.nonzero(layout.present)
    measured = np.asarray(meas.landmarks)[:, part_index, slot]
    mask = (np.asarray(meas.weights)[:, part_index, slot] > 0) & np.all(np.isfinite(measured),
                                                                        axis=-1)
    return Landmarks(meas.loads, [layout.parts[p] for p in part_index],
                     np.asarray(layout.position)[part_index, slot],
                     np.where(mask[..., None], measured, 0.0), sigma, mask=mask)


def as_fit_data(data) -> tuple[Measurement, ...]:
    """The measurements of a least-squares fit: `data` as a tuple of `Measurement`s, a
    `measure.Measurements` replaced by its landmarks or poses (`from_measurements`, with its
    own σ: `Measurements.sigma`, `sigma_rotation`).

    **Raises:** `InputError` for anything else, or repeated measurement names."""
    items = (data,) if isinstance(data, Measurement | Measurements) else tuple(data)
    items = tuple(
        from_measurements(m, m.sigma, _pose_sigma_rotation(m))
        if isinstance(m, Measurements) else m for m in items)
    if not items or not all(isinstance(m, Measurement) for m in items):
        raise InputError("data must be a measurement (measure.Measurements, Landmarks, Poses, "
                         "Deformations, Channel) or a sequence of them.")
    names = [m.name for m in items]
    if len(set(names)) != len(names):
        raise InputError(f"measurement names {names} repeat; give each a distinct name=.")
    return items


def _pose_sigma_rotation(meas) -> float:
    if meas.landmarks is not None:
        return 1.0  # unused: the landmarks themselves are the residuals
    if meas.sigma_rotation is None:
        raise InputError("these measurements are part poses without landmarks: give their "
                         "rotation σ (rad), e.g. dataclasses.replace(meas, sigma_rotation=1e-3),"
                         " or pass a Poses measurement.")
    return meas.sigma_rotation


def _single(data, kinds: tuple[type, ...], what: str):
    """The one measurement of `kinds` in `data` (one measurement or a sequence)."""
    items = (data,) if not isinstance(data, list | tuple) else tuple(data)
    found = [m for m in items if isinstance(m, kinds)]
    if len(found) != 1:
        raise InputError(f"{what}; got {', '.join(type(m).__name__ for m in items) or 'nothing'}"
                         ".")
    if getattr(found[0], "n_sets", None):
        raise InputError("the measured values have a data-set axis; identify one data set at a "
                         "time (m.select(k)) or use least_squares_batch.")
    return found[0]


def as_equilibria(data):
    """The measured equilibria (part poses and loads) of `data`, as a `measure.Measurements`:
    a `Measurements` itself, or a `Poses` measurement (one data set).

    **Raises:** `InputError` when `data` carries no part poses (the direct method needs the pose
    of every moving part at every equilibrium: spec stiffness §1.1)."""
    found = _single(data, (Measurements, Poses),
                    "the direct method needs measured part poses: a measure.Measurements "
                    "(from_landmarks, from_poses, synthesize, read_measurements) or a Poses")
    if isinstance(found, Measurements):
        return found
    if not bool(np.all(np.asarray(found.weight) > 0)):
        raise InputError(f"{found.name}: the direct method needs every pose of every case; "
                         "drop the cases with masked poses.")
    return from_poses(found.parts, np.asarray(found.rotation), np.asarray(found.translation),
                      found.loads)


def as_deformations(mech: Mechanism, data, bushings: Sequence[str]) -> Deformations:
    """The measured deformations of `bushings` (in that order) from `data`: a `Deformations`
    measurement, or the deformations at measured poses (`Measurements`, `Poses`; spec
    stiffness §2.2, `measure.bushing_deformations`), with σ 1 where the data give none.

    **Raises:** `InputError` when `data` has neither, a bushing is missing, or an entry is
    masked (the correlation method regresses over every case)."""
    found = _single(data, (Deformations, Measurements, Poses),
                    "the iterative method needs measured bushing deformations: a Deformations, "
                    "or measured part poses (measure.Measurements, Poses)")
    bushings = tuple(bushings)
    if isinstance(found, Deformations):
        missing = [b for b in bushings if b not in found.bushings]
        if missing:
            raise InputError(f"{found.name}: no measured deformation of bushing(s) {missing}; "
                             f"measured: {', '.join(found.bushings)}.")
        idx = np.array([found.bushings.index(b) for b in bushings], dtype=int)
        weight = np.asarray(found.weight)[:, idx]
        if not np.all(weight > 0):
            raise InputError(f"{found.name}: the iterative method regresses over every case; "
                             "drop the cases with masked deformations.")
        return Deformations(found.loads, bushings, np.asarray(found.measured)[:, idx],
                            1.0 / weight, name=found.name)
    meas = found if isinstance(found, Measurements) else as_equilibria(found)
    d_t, d_r = bushing_deformations(mech, meas, bushings)
    return Deformations(meas.loads, bushings, np.concatenate([d_t, d_r], axis=-1), 1.0)


def data_axes(data: Sequence[Measurement]):
    """`in_axes` for vmapping over data sets: 0 on the measured values, None elsewhere."""
    batched = set()
    for m in data:
        for f in m.value_fields:
            batched.add(id(getattr(m, f)))
    return jax.tree.map(lambda x: 0 if id(x) in batched else None, tuple(data))


__all__ = ["Channel", "Deformations", "Landmarks", "Measurement", "Poses", "as_deformations",
           "as_equilibria", "as_fit_data", "data_axes", "from_measurements"]
