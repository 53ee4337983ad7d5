"""Measured equilibria: part poses (from landmarks or given) and the loads of each case.

The direct identification needs, at every static equilibrium, the pose of every moving part and
the applied loads (spec stiffness §1.1). Poses come from landmarks by rigid registration (spec
geometry §3.6) or are given directly (e.g. a simulation's part results). Everything here works on
a whole table at once: arrays carry a leading case axis, then a part axis.

Conventions: mm, N, N·mm, rad; a part pose (R, T) is that of the part frame, which coincides
with the global frame at design (q = 0), so T is where the point that was at the global origin
has gone and R the rotation from design (DESIGN.md "Reference configuration").
"""

import dataclasses
import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from ..errors import InputError
from ..geometry.registration import register_landmarks
from ..geometry.rotations import GIBBS_SINGULARITY_TOL, matrix_to_quaternion
from ..model.mechanism import GROUND, Loads, Mechanism
from ..statics import bushing_states, part_poses, solve_statics
from .landmarks import (
    MIN_LANDMARKS,
    REORDER_TOLERANCE,
    LandmarkLayout,
    check_layout,
    is_collinear,
    landmark_positions,
    place_landmarks,
    reorder_landmarks,
)
from .noise import ARM_SIGMA, GaussianNoise


class Measurements(eqx.Module):
    """Measured static equilibria of a mechanism: per case, part poses and loads.

    **Fields:**

    - `rotation` (cases, parts, 3, 3) and `translation` (cases, parts, 3) (mm): pose of each
      part frame in the global frame.
    - `loads`: the applied `Loads`, with the same leading case axis (N, N·mm; drivers mm).
    - `landmarks` (cases, parts, k, 3) (mm) the measured landmarks in layout order, `weights`
      (cases, parts, k) (1 used, 0 missing or excluded), `layout` the `LandmarkLayout`, and `rms`
      (cases, parts) the registration residual (mm): present when the poses come from
      landmarks, else None.
    - static `parts` (part names, in the order of the part axis), `cases` (case labels) and
      `notes` (exclusions and warnings, one sentence each, shown in identification reports).
    - static `sigma` (mm): the standard deviation of a landmark coordinate (default the
      measuring arm's `ARM_SIGMA`), and `sigma_rotation` (rad, or None): of a pose's rotation
      when there are no landmarks. They whiten the residuals when a least-squares fit takes
      these measurements (`identify.least_squares`); the direct method derives its weights
      from the registration geometry.
    """

    rotation: Float[Array, "cases parts 3 3"]
    translation: Float[Array, "cases parts 3"]
    loads: Loads
    landmarks: Float[Array, "cases parts k 3"] | None = None
    weights: Float[Array, "cases parts k"] | None = None
    rms: Float[Array, "cases parts"] | None = None
    layout: LandmarkLayout | None = None
    parts: tuple[str, ...] = eqx.field(static=True, default=())
    cases: tuple[str, ...] = eqx.field(static=True, default=())
    notes: tuple[str, ...] = eqx.field(static=True, default=())
    sigma: float = eqx.field(static=True, default=ARM_SIGMA)
    sigma_rotation: float | None = eqx.field(static=True, default=None)

    @property
    def n_cases(self) -> int:
        return self.rotation.shape[-4]

    def coordinates(self, mech: Mechanism, *, unmeasured: str = "error"
                    ) -> Float[Array, "cases n"]:
        """Public generalised coordinates q (cases, 6·parts) of `mech` at the measured poses:
        per part the translation T (mm) and the Gibbs vector of R (spec stiffness §1.3).

        `unmeasured='design'` puts parts without a measured pose at their design pose (q = 0),
        for quantities that depend on the measured parts only (e.g. the deformation of a bushing
        between two measured parts); the default raises.

        **Raises:** `InputError` if a moving part of `mech` has no measured pose (the direct
        method needs every part: spec stiffness §1.1, §1.14).
        """
        if unmeasured not in ("error", "design"):
            raise InputError(f"unmeasured must be 'error' or 'design'; got '{unmeasured}'.")
        meas = self
        if unmeasured == "design":
            missing = [p for p in mech.parts if p not in self.parts]
            if missing:
                n = self.n_cases
                eye = jnp.broadcast_to(jnp.eye(3), (n, len(missing), 3, 3))
                meas = Measurements(
                    rotation=jnp.concatenate([self.rotation, eye], axis=1),
                    translation=jnp.concatenate(
                        [self.translation, jnp.zeros((n, len(missing), 3))], axis=1),
                    loads=self.loads, parts=self.parts + tuple(missing), cases=self.cases)
        return meas._coordinates_of(mech)

    def _coordinates_of(self, mech: Mechanism):
        index = []
        for part in mech.parts:
            if part not in self.parts:
                raise InputError(
                    f"the measurements have no pose for part '{part}' of model '{mech.name}'; "
                    "the direct method needs the pose of every moving part at every "
                    f"equilibrium (measured parts: {', '.join(self.parts) or 'none'}). Measure "
                    "its landmarks, or simplify the model (the thesis replaced the unmeasurable "
                    "strut by a point-on-line joint: spec stiffness §1.13)."
                )
            index.append(self.parts.index(part))
        unknown = [p for p in self.parts if p not in mech.parts]
        if unknown:
            raise InputError(
                f"the measurements have poses for part(s) {', '.join(map(repr, unknown))} that "
                f"model '{mech.name}' does not have (its parts: {', '.join(mech.parts)}); check "
                "the part names."
            )
        if not isinstance(self.rotation, jax.core.Tracer):
            trace = np.trace(np.asarray(self.rotation), axis1=-2, axis2=-1)
            if np.any(1.0 + trace < GIBBS_SINGULARITY_TOL):
                c, p = np.argwhere(1.0 + trace < GIBBS_SINGULARITY_TOL)[0][-2:]
                raise InputError(
                    f"part '{self.parts[p]}' is rotated by 180° from design in case "
                    f"{self.cases[c] if self.cases else c + 1}, where Gibbs vectors are "
                    "singular; check the measured pose (parts of a suspension turn little).")
        return _coordinates(self.rotation, self.translation, tuple(index))


@functools.partial(jax.jit, static_argnames="index")
def _coordinates(rotation, translation, index):
    # Gibbs vectors from the quaternion (Shepperd), without `matrix_to_gibbs`'s runtime check:
    # the 180° singularity is checked on the host above (a runtime check over 10⁴ cases hung
    # repeated calls with jax 0.10 / equinox 0.13).
    idx = np.asarray(index, dtype=int)
    rot = rotation[..., idx, :, :]
    quat = jax.vmap(matrix_to_quaternion)(rot.reshape(-1, 3, 3))
    gibbs = (quat[:, 1:] / quat[:, :1]).reshape(*rot.shape[:-2], 3)
    q = jnp.concatenate([translation[..., idx, :], gibbs], axis=-1)
    return q.reshape(*q.shape[:-2], -1)


def _case_labels(n: int, cases) -> tuple[str, ...]:
    if cases is None:
        return tuple(str(c + 1) for c in range(n))
    cases = tuple(str(c) for c in cases)
    if len(cases) != n:
        raise InputError(f"{len(cases)} case labels for {n} cases; give one label per case.")
    return cases


def _check_loads(loads: Loads, n_cases: int, what: str):
    if loads.n_cases is None:
        raise InputError("loads must have a leading case axis (one row per measured case).")
    if loads.n_cases != n_cases:
        raise InputError(
            f"{what} has {n_cases} cases but the loads have {loads.n_cases}; give one load "
            "case per measured equilibrium, in the same order."
        )
    for field in ("force", "moment", "driver"):
        value = np.asarray(getattr(loads, field))
        if not np.all(np.isfinite(value)):
            c = int(np.argwhere(~np.isfinite(value))[0][0])
            raise InputError(f"loads.{field} of case {c + 1} is not finite (NaN or inf).")


def from_poses(
    parts: tuple[str, ...],
    rotation: Float[Array, "cases parts 3 3"],
    translation: Float[Array, "cases parts 3"],
    loads: Loads,
    *,
    cases=None,
) -> Measurements:
    """`Measurements` from given part poses (e.g. a simulation's part results).

    **Arguments:** `parts` names of the part axis; `rotation` (cases, parts, 3, 3) rotation
    matrices (columns: part axes in the global frame); `translation` (cases, parts, 3) (mm);
    `loads` with a leading case axis; `cases` optional labels.

    **Raises:** `InputError` for wrong shapes, non-finite values, a matrix that is not a
    rotation, or a number of load cases different from the number of pose cases.
    """
    rotation = np.asarray(rotation, dtype=float)
    translation = np.asarray(translation, dtype=float)
    parts = tuple(parts)
    n_parts = len(parts)
    if rotation.ndim != 4 or rotation.shape[1:] != (n_parts, 3, 3):
        raise InputError(
            f"rotation must have shape (cases, {n_parts}, 3, 3); got {rotation.shape}."
        )
    if translation.shape != rotation.shape[:2] + (3,):
        raise InputError(
            f"translation must have shape {rotation.shape[:2] + (3,)}; got {translation.shape}."
        )
    for name, value in (("rotation", rotation), ("translation", translation)):
        bad = np.argwhere(~np.isfinite(value))
        if bad.size:
            c, p = bad[0][:2]
            raise InputError(
                f"{name} of part '{parts[p]}' in case {c + 1} is not finite (NaN or inf)."
            )
    err = np.abs(np.einsum("cpji,cpjk->cpik", rotation, rotation) - np.eye(3)).max(axis=(2, 3))
    if np.any(err > 1e-6) or np.any(np.linalg.det(rotation) < 0):
        c, p = np.argwhere((err > 1e-6) | (np.linalg.det(rotation) < 0))[0]
        raise InputError(
            f"the rotation of part '{parts[p]}' in case {c + 1} is not a rotation matrix "
            f"(|RᵀR − I| = {err[c, p]:.2g}); give orthonormal matrices with det +1."
        )
    _check_loads(loads, rotation.shape[0], "the pose table")
    return Measurements(
        rotation=jnp.asarray(rotation), translation=jnp.asarray(translation), loads=loads,
        parts=parts, cases=_case_labels(rotation.shape[0], cases),
    )


def from_landmarks(
    layout: LandmarkLayout,
    measured: Float[Array, "cases parts k 3"],
    loads: Loads,
    *,
    weights: Float[Array, "cases parts k"] | None = None,
    reorder: bool = False,
    tolerance: float = REORDER_TOLERANCE,
    cases=None,
    method: str = "quaternion",
) -> Measurements:
    """`Measurements` from landmarks measured at each equilibrium: poses by registration.

    Per case and part: NaN coordinates mark a landmark as missing (excluded, noted); with
    `reorder`, points probed in an unknown order are matched to the layout by their distance
    tables, a wrong point is excluded and an ambiguous match is noted (spec geometry §3.5); the
    pose is then the least-squares rigid fit of the remaining landmarks (spec geometry §3.6).

    **Arguments:**

    - `layout`: the landmarks of each part in the part frame (mm).
    - `measured` (cases, parts, k, 3): the same landmarks measured in the global frame (mm), in
      layout order (or any order per part if `reorder`), parts in `layout.parts` order.
    - `loads`: the applied loads, one case per measured case.
    - `weights`: optional (cases, parts, k) landmark weights (0 excludes).
    - `reorder`, `tolerance`: re-ordering by distance tables and its ε (mm).
    - `cases`: optional case labels; `method`: registration method.

    **Raises:** `InputError` for shape mismatches, a number of load cases different from the
    number of landmark cases, or a part left with fewer than three non-collinear landmarks in
    some case (naming the case and the part).
    """
    check_layout(layout)
    measured = np.array(measured, dtype=float)
    n_parts, k = len(layout.parts), layout.position.shape[1]
    if measured.ndim != 4 or measured.shape[1:] != (n_parts, k, 3):
        raise InputError(
            f"measured landmarks must have shape (cases, {n_parts}, {k}, 3) for the layout's "
            f"{n_parts} parts and up to {k} landmarks; got {measured.shape}."
        )
    n_cases = measured.shape[0]
    labels = _case_labels(n_cases, cases)
    _check_loads(loads, n_cases, "the landmark table")
    present = np.broadcast_to(layout.present, measured.shape[:3])
    w = present.astype(float) if weights is None else np.asarray(weights, float) * present
    if w.shape != measured.shape[:3]:
        raise InputError(f"weights must have shape {measured.shape[:3]}; got {w.shape}.")
    reference = np.asarray(layout.position)
    notes = []
    for c in range(n_cases):
        for p, part in enumerate(layout.parts):
            names = layout.names[p]
            nan = ~np.all(np.isfinite(measured[c, p]), axis=-1) & (w[c, p] > 0)
            for a in np.flatnonzero(nan):
                notes.append(f"case {labels[c]}: landmark '{names[a]}' of part '{part}' has no "
                             "finite coordinates and was excluded")
            w[c, p, nan] = 0.0
            measured[c, p, ~np.isfinite(measured[c, p]).all(-1)] = 0.0
            used = np.flatnonzero(w[c, p] > 0)
            if reorder and len(used) >= MIN_LANDMARKS:
                result = reorder_landmarks(reference[p, used], measured[c, p, used],
                                           tolerance=tolerance)
                if result.order is None:
                    raise InputError(
                        f"case {labels[c]}, part '{part}': {result.message}. Check the "
                        "landmarks measured on this part (spec geometry §3.5)."
                    )
                source = measured[c, p, used].copy()
                for slot, j in zip(used, result.order, strict=True):
                    if j < 0:
                        w[c, p, slot] = 0.0
                    else:
                        measured[c, p, slot] = source[j]
                if result.message:
                    notes.append(f"case {labels[c]}, part '{part}': {result.message}")
                used = np.flatnonzero(w[c, p] > 0)
            if len(used) < MIN_LANDMARKS or is_collinear(reference[p, used]):
                raise InputError(
                    f"case {labels[c]}, part '{part}': {len(used)} usable landmark(s)"
                    f"{' on one line' if len(used) >= MIN_LANDMARKS else ''}; a pose needs at "
                    "least three non-collinear landmarks. Re-measure the part or give it more "
                    "landmarks."
                )
    reg = _register(jnp.asarray(reference), jnp.asarray(measured), jnp.asarray(w), method)
    return Measurements(
        rotation=reg.rotation, translation=reg.translation, loads=loads,
        landmarks=jnp.asarray(measured), weights=jnp.asarray(w), rms=reg.rms, layout=layout,
        parts=layout.parts, cases=labels, notes=tuple(notes),
    )


@eqx.filter_jit
def _register(reference, measured, weights, method):
    return register_landmarks(reference, measured, weights, method=method)


def reregister(meas: Measurements, *, method: str = "quaternion") -> Measurements:
    """Poses recomputed from `meas.landmarks` (after changing them, e.g. adding noise).
    Pure array code (jit/vmap friendly); no input checks."""
    reg = register_landmarks(meas.layout.position, meas.landmarks, meas.weights, method=method)
    return dataclasses.replace(meas, rotation=reg.rotation, translation=reg.translation,
                               rms=reg.rms)


def add_noise(meas: Measurements, noise: GaussianNoise, key: PRNGKeyArray) -> Measurements:
    """Measurements with Gaussian noise on the landmarks (then registered again) and on the
    loads. Pure array code: `jax.vmap` it over keys for Monte-Carlo batches.

    **Raises:** `InputError` if `meas` has no landmarks and the noise has a landmark σ.
    """
    if meas.landmarks is None:
        if noise.landmarks > 0:
            raise InputError("these measurements have no landmarks to add noise to; build them "
                             "with from_landmarks or synthesize.")
        return dataclasses.replace(meas, loads=noise.perturb_loads(key, meas.loads))
    k1, k2 = jax.random.split(key)
    meas = dataclasses.replace(meas, landmarks=noise.perturb_landmarks(k1, meas.landmarks),
                               loads=noise.perturb_loads(k2, meas.loads))
    return reregister(meas)


def synthesize(
    mech: Mechanism,
    loads: Loads,
    *,
    layout: LandmarkLayout | None = None,
    noise: GaussianNoise | None = None,
    key: PRNGKeyArray | None = None,
    per_part: int = 4,
    seed: int = 0,
    **solve_options,
) -> Measurements:
    """Synthetic measurements of `mech` under `loads`: solve the equilibria, put the landmarks
    on the parts, measure them (with noise) and register the poses back.

    This is the thesis's numerical-validation protocol (spec stiffness §1.12, §2.8: Adams
    equilibria, four landmarks per part, σ = 0.05 mm on every coordinate).

    **Arguments:**

    - `mech`, `loads`: the model and a load table (leading case axis).
    - `layout`: landmarks to use (default `place_landmarks(mech, per_part, seed=seed)`).
    - `noise`: a `GaussianNoise` (default: none); `key`: its PRNG key (default `PRNGKey(seed)`).
    - `**solve_options`: passed to `solve_statics` (e.g. `rtol`, `max_steps`).

    **Returns:** `Measurements` with landmarks (their `sigma` the noise's landmark σ, or
    `ARM_SIGMA` without noise); noise-free poses are exact to rounding.
    """
    if loads.n_cases is None:
        loads = jax.tree.map(lambda a: a[None], loads)
    layout = place_landmarks(mech, per_part, seed=seed) if layout is None else layout
    sol = solve_statics(mech, loads, **solve_options)
    rot, trans = part_poses(mech, sol.q)
    index = np.asarray([mech.part_index(p) for p in layout.parts], dtype=int)
    true = landmark_positions(layout, rot[:, index], trans[:, index])
    weights = jnp.broadcast_to(jnp.asarray(layout.present, float), true.shape[:3])
    meas = Measurements(
        rotation=rot[:, index], translation=trans[:, index], loads=loads, landmarks=true,
        weights=weights, rms=jnp.zeros(true.shape[:2]), layout=layout, parts=layout.parts,
        cases=_case_labels(true.shape[0], None),
        sigma=noise.landmarks if noise is not None and noise.landmarks > 0 else ARM_SIGMA,
    )
    if noise is not None:
        meas = add_noise(meas, noise, jax.random.PRNGKey(seed) if key is None else key)
    return meas


def bushing_deformations(mech: Mechanism, meas: Measurements, bushings=None):
    """Bushing deformations at the measured poses (spec stiffness §1.8, geometry §2.6):
    δ_T (cases, bushings, 3) in mm and the projected angles (cases, bushings, 3) in rad, of
    each bushing's I marker relative to its J marker, in J axes (Adams convention).

    `bushings`: names (default: all, and every moving part must be measured); with names, only
    the parts those bushings connect need a measured pose, and the result follows their order.

    **Raises:** `InputError` if a part of a requested bushing has no measured pose.
    """
    if bushings is None:
        delta_t, delta_r, _, _ = bushing_states(mech, meas.coordinates(mech))
        return delta_t, delta_r
    index = [mech.bushings.index(n) for n in bushings]
    for name, b in zip(bushings, index, strict=True):
        for marker in (mech.bushings.i_marker[b], mech.bushings.j_marker[b]):
            part = mech.markers.part[marker]
            if part != GROUND and mech.parts[part] not in meas.parts:
                raise InputError(
                    f"bushing '{name}' connects part '{mech.parts[part]}', which has no "
                    f"measured pose (measured parts: {', '.join(meas.parts) or 'none'}).")
    q = meas.coordinates(mech, unmeasured="design")
    delta_t, delta_r, _, _ = bushing_states(mech, q)
    return delta_t[:, np.asarray(index)], delta_r[:, np.asarray(index)]


def case_subset(meas: Measurements, cases) -> Measurements:
    """The measurements of some cases only (`cases`: indices, in the order wanted)."""
    idx = np.asarray(cases, dtype=int)

    def take(a):
        return None if a is None else a[idx]

    return dataclasses.replace(
        meas, rotation=take(meas.rotation), translation=take(meas.translation),
        loads=jax.tree.map(take, meas.loads), landmarks=take(meas.landmarks),
        weights=take(meas.weights), rms=take(meas.rms),
        cases=tuple(meas.cases[i] for i in idx),
    )
