"""Landmarks ("amers") on parts: layouts, synthetic placement, distance tables and re-ordering.

The thesis puts four landmarks on every part (machined cones probed with a ball, spec geometry
§3.3): three define a pose, the fourth gives robustness. They must be spread out and have
pairwise distances all different, so that landmarks probed in any order on the assembled axle
can be matched back to the part model by comparing distance tables (§3.5): every permutation of
the measured points is tried and accepted when all distances agree within ε = 0.5 mm (2.16).
No match means a wrong landmark (an outlier, which is then searched for and excluded); several
matches mean a symmetric layout (ambiguous, reported).

Units: mm. Part frames coincide with the global frame at design (DESIGN.md), so a landmark's
position "in the part frame" is its global position at design.
"""

import itertools
from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..errors import InputError
from ..model.mechanism import GROUND, Mechanism

REORDER_TOLERANCE = 0.5
"""ε of the distance-table test (mm), spec geometry §3.5 (2.16): hard under-vehicle conditions."""
COLLINEAR_RATIO = 1e-3
"""Landmarks whose second principal spread is below this fraction of the first are collinear
(they do not fix the rotation about their line)."""
MIN_LANDMARKS = 3


class LandmarkLayout(eqx.Module):
    """Landmarks of every part, in the part frame (= global position at design), mm.

    Parts may carry different numbers of landmarks: `position` is padded to the largest count
    and `names[p]` lists the landmarks part p really has (`present` marks them).

    **Fields:** `position` (parts, k, 3) mm; static `parts` (part names) and `names` (landmark
    names per part).
    """

    position: Float[Array, "parts k 3"]
    parts: tuple[str, ...] = eqx.field(static=True)
    names: tuple[tuple[str, ...], ...] = eqx.field(static=True)

    def __check_init__(self):
        n_parts = len(self.parts)
        k = max((len(n) for n in self.names), default=0)
        if len(self.names) != n_parts or self.position.shape != (n_parts, k, 3):
            raise ValueError(
                f"LandmarkLayout: position must have shape ({n_parts}, {k}, 3) for {n_parts} "
                f"parts with up to {k} landmarks; got {self.position.shape}."
            )

    @property
    def present(self) -> np.ndarray:
        """(parts, k) bool: which padded slots are real landmarks."""
        k = self.position.shape[1]
        return np.array([[a < len(n) for a in range(k)] for n in self.names], dtype=bool)

    def part_index(self, part: str) -> int:
        try:
            return self.parts.index(part)
        except ValueError:
            raise InputError(
                f"no landmarks for part '{part}'; parts with landmarks: {', '.join(self.parts)}."
            ) from None


def make_layout(landmarks: dict[str, dict[str, tuple[float, float, float]]]) -> LandmarkLayout:
    """A `LandmarkLayout` from `{part: {landmark: (x, y, z)}}` (mm, part frame = global at
    design), checked: finite, at least three non-collinear landmarks per part."""
    parts = tuple(landmarks)
    names = tuple(tuple(landmarks[p]) for p in parts)
    k = max((len(n) for n in names), default=0)
    pos = np.zeros((len(parts), k, 3))
    for i, p in enumerate(parts):
        for a, name in enumerate(names[i]):
            value = np.asarray(landmarks[p][name], dtype=float)
            if value.shape != (3,) or not np.all(np.isfinite(value)):
                raise InputError(
                    f"landmark '{name}' of part '{p}' must be 3 finite coordinates (mm); got "
                    f"{value.tolist()}."
                )
            pos[i, a] = value
    layout = LandmarkLayout(position=jnp.asarray(pos), parts=parts, names=names)
    check_layout(layout)
    return layout


def _spread(points: np.ndarray) -> np.ndarray:
    centred = points - points.mean(axis=0)
    return np.linalg.svd(centred, compute_uv=False) if len(points) else np.zeros(3)


def is_collinear(points: np.ndarray) -> bool:
    """Fewer than three points, or all of them (nearly) on one line (see `COLLINEAR_RATIO`)."""
    points = np.asarray(points, dtype=float)
    if len(points) < MIN_LANDMARKS:
        return True
    s = _spread(points)
    return bool(s[0] == 0.0 or s[1] < COLLINEAR_RATIO * s[0])


def check_layout(layout: LandmarkLayout) -> list[str]:
    """Check a layout: raises `InputError` for a part with fewer than three non-collinear
    landmarks; returns warnings (as text) for layouts whose probing order cannot be recovered
    by distances (a symmetric layout: spec geometry §3.3 rule 3)."""
    notes = []
    pos = np.asarray(layout.position)
    for i, part in enumerate(layout.parts):
        pts = pos[i, : len(layout.names[i])]
        if len(pts) < MIN_LANDMARKS or is_collinear(pts):
            raise InputError(
                f"part '{part}' has {len(pts)} landmark(s)"
                f"{' on one line' if len(pts) >= MIN_LANDMARKS else ''}; a pose needs at least "
                "three non-collinear landmarks (the thesis uses four, spread apart: spec geometry "
                "§3.3). Add landmarks off the line of the others."
            )
        matches, _ = _matching_permutations(pts, pts, 2 * REORDER_TOLERANCE)
        if len(matches) > 1:
            notes.append(
                f"part '{part}': its landmarks are symmetric ({len(matches)} orderings have the "
                f"same distance table within {2 * REORDER_TOLERANCE} mm), so landmarks probed "
                "in an unknown order cannot be matched; make all pairwise distances different."
            )
    return notes


def place_landmarks(
    mech: Mechanism,
    per_part: int = 4,
    *,
    seed: int = 0,
    offset: float | None = None,
    parts: tuple[str, ...] | None = None,
) -> LandmarkLayout:
    """Place `per_part` landmarks on every moving part, as the thesis did on the real axle.

    Each landmark is a random point of the segment hull of the part's markers (its hardpoints)
    plus a random offset (the landmarks sit on the part's surface, not on its joint centres),
    drawn until the set satisfies the thesis's rules (spec geometry §3.3): spread out (second
    principal spread ≥ 20 % of the first), all pairwise distances different by more than
    4ε = 2 mm (so re-ordering is never ambiguous) and at least 5 mm apart.

    **Arguments:**

    - `mech`: the mechanism (landmarks go on its moving parts).
    - `per_part`: landmarks per part (≥ 3; default 4).
    - `seed`: seed of the placement (deterministic).
    - `offset`: size of the random offset (mm); default 15 % of the part's marker extent, at
      least 20 mm.
    - `parts`: parts to equip (default: all moving parts).

    **Returns:** a `LandmarkLayout`; landmark names `'<part>.a1'`, `'<part>.a2'`, ...
    """
    if per_part < MIN_LANDMARKS:
        raise InputError(f"per_part must be at least {MIN_LANDMARKS}; got {per_part}.")
    rng = np.random.default_rng(seed)
    parts = tuple(mech.parts) if parts is None else tuple(parts)
    marker_part = np.asarray(mech.markers.part)
    marker_pos = np.asarray(mech.markers.position)
    positions = []
    for part in parts:
        index = mech.part_index(part)
        if index == GROUND:
            raise InputError("landmarks go on moving parts; 'ground' has no pose to measure.")
        pts = np.unique(np.round(marker_pos[marker_part == index], 9), axis=0)
        if len(pts) == 0:
            pts = np.asarray(mech.reference_points[index], dtype=float)[None]
        extent = float(np.max(np.linalg.norm(pts - pts.mean(0), axis=1))) if len(pts) > 1 else 0
        size = offset if offset is not None else max(20.0, 0.15 * 2 * extent)
        for _ in range(10_000):
            weights = rng.dirichlet(np.ones(len(pts)), size=per_part)
            cand = weights @ pts + rng.normal(size=(per_part, 3)) * size
            if _good_layout(cand):
                break
        else:  # pragma: no cover - the random search succeeds in a few draws
            raise InputError(f"could not place {per_part} landmarks on part '{part}'.")
        positions.append(cand)
    names = tuple(tuple(f"{p}.a{a + 1}" for a in range(per_part)) for p in parts)
    return LandmarkLayout(position=jnp.asarray(np.array(positions)), parts=parts, names=names)


def _good_layout(points: np.ndarray) -> bool:
    s = _spread(points)
    if s[1] < 0.2 * s[0]:
        return False
    d = distance_table(points)[np.triu_indices(len(points), 1)]
    if d.min() < 5.0:
        return False
    gaps = np.abs(d[:, None] - d[None, :])[np.triu_indices(len(d), 1)]
    return bool(gaps.min() > 4 * REORDER_TOLERANCE)


def distance_table(points: Float[np.ndarray, "k 3"]) -> Float[np.ndarray, "k k"]:
    """Pairwise distances ‖P_a − P_b‖ (mm) of a landmark set (spec geometry §3.3, 2.11; the
    thesis keeps the upper triangle)."""
    points = np.asarray(points, dtype=float)
    return np.linalg.norm(points[:, None, :] - points[None, :, :], axis=-1)


def _matching_permutations(reference, measured, tolerance):
    """Injective maps a → π(a) from reference landmarks to measured points whose distance tables
    agree within `tolerance`; returns (list of π as tuples, their largest |ΔD|)."""
    d_ref = distance_table(reference)
    d_mea = distance_table(measured)
    k, m = len(reference), len(measured)
    perms = np.array(list(itertools.permutations(range(m), k)), dtype=int).reshape(-1, k)
    sub = d_mea[perms[:, :, None], perms[:, None, :]]  # (P, k, k)
    err = np.max(np.abs(sub - d_ref[None]), axis=(1, 2)) if k else np.zeros(len(perms))
    ok = np.flatnonzero(err <= tolerance)
    order = ok[np.argsort(err[ok], kind="stable")]
    return [tuple(int(v) for v in perms[i]) for i in order], err[order]


class Reordering(NamedTuple):
    """Result of `reorder_landmarks`.

    **Fields:**

    - `order` (k,) int: `measured[order[a]]` is reference landmark a; −1 for a reference landmark
      with no measured point (an excluded outlier). None when nothing matches.
    - `ambiguous`: more than one ordering fits (symmetric layout); `order` is the best fit.
    - `outlier`: index of the measured point that fitted no ordering and was left out, or None.
    - `max_error`: largest distance disagreement (mm) of the chosen ordering.
    - `candidates`: every ordering that fits, best first.
    - `message`: a sentence for the report ('' when the match is clean).
    """

    order: np.ndarray | None
    ambiguous: bool
    outlier: int | None
    max_error: float
    candidates: tuple[tuple[int, ...], ...]
    message: str


def reorder_landmarks(
    reference: Float[np.ndarray, "k 3"],
    measured: Float[np.ndarray, "k 3"],
    *,
    tolerance: float = REORDER_TOLERANCE,
) -> Reordering:
    """Match landmarks probed in an unknown order to the part model by their distance tables.

    Tries every permutation (k! of them: 24 for the thesis's four landmarks) and accepts those
    with |D_P(a, b) − D_Q(π(a), π(b))| ≤ `tolerance` for all pairs (spec geometry §3.5, 2.16).
    If none fits, one measured point is wrong: every way of leaving one measured point out and
    matching the rest to k − 1 reference landmarks is tried (the digest's suggestion), and a
    unique fit names the outlier. At least three landmarks must remain.

    **Arguments:** `reference` (k, 3) the part's landmarks (mm); `measured` (k, 3) the probed
    points in any order (mm); `tolerance` ε (mm), default 0.5.

    **Returns:** a `Reordering`.
    """
    reference = np.asarray(reference, dtype=float)
    measured = np.asarray(measured, dtype=float)
    k = len(reference)
    if measured.shape != reference.shape:
        raise InputError(
            f"reorder_landmarks: {len(measured)} measured points for {k} reference landmarks; "
            "give one measured point per landmark."
        )
    matches, errors = _matching_permutations(reference, measured, tolerance)
    if matches:
        ambiguous = len(matches) > 1
        message = (
            f"{len(matches)} orderings of the landmarks fit the distance table within "
            f"{tolerance} mm (symmetric layout): the pose is ambiguous"
            if ambiguous else ""
        )
        return Reordering(np.array(matches[0]), ambiguous, None, float(errors[0]),
                          tuple(matches), message)
    if k - 1 < MIN_LANDMARKS:
        return Reordering(None, False, None, float("nan"), (),
                          f"no ordering of the {k} landmarks fits the distance table within "
                          f"{tolerance} mm, and fewer than {MIN_LANDMARKS} would remain without "
                          "the wrong one")
    fits = []
    for drop_ref in range(k):
        keep_ref = [a for a in range(k) if a != drop_ref]
        sub, err = _matching_permutations(reference[keep_ref], measured, tolerance)
        for perm, e in zip(sub, err, strict=True):
            order = np.full(k, -1)
            order[keep_ref] = perm
            outlier = int(next(j for j in range(k) if j not in perm))
            fits.append((float(e), order, outlier))
    if not fits:
        return Reordering(None, False, None, float("nan"), (),
                          f"no ordering of the landmarks fits the distance table within "
                          f"{tolerance} mm, even leaving one out: more than one landmark is "
                          "wrong, or they belong to another part")
    fits.sort(key=lambda f: f[0])
    e, order, outlier = fits[0]
    ambiguous = len(fits) > 1
    message = (
        f"measured point {outlier + 1} fits no ordering (an outlier beyond {tolerance} mm) and "
        f"was excluded; reference landmark {int(np.flatnonzero(order < 0)[0]) + 1} is unmeasured"
    )
    if ambiguous:
        message += f"; {len(fits)} ways of leaving one point out fit (ambiguous)"
    return Reordering(order, ambiguous, outlier, e,
                      tuple(tuple(int(v) for v in f[1]) for f in fits), message)


def landmark_positions(
    layout: LandmarkLayout,
    rotation: Float[Array, "*batch parts 3 3"],
    translation: Float[Array, "*batch parts 3"],
) -> Float[Array, "*batch parts k 3"]:
    """Global positions of every landmark for part poses (R, T): Q_a = R P_a + T (mm)."""
    return jnp.einsum("...pij,pkj->...pki", rotation, layout.position) + translation[..., None, :]
