"""Equilibrium-consistent geometric correction (spec geometry §3.8, the thesis's chapter 2):
the bolted-side joint frames moved so that the model's equilibrium reproduces measured poses,
and the offset-equivalent model of bushing preloads. Units: mm.
"""

import dataclasses
import math
from collections.abc import Sequence
from typing import ClassVar

import jax.numpy as jnp
import numpy as np

from ..errors import InputError
from ..statics import bushing_states, marker_poses, part_poses, solve_statics
from .geometric_joints import Coordinate, CoordinateRows
from .geometric_locate import pose_covariance, skew
from .report import IdentificationReport

TOL_FLOOR = 1e-4
"""mm: `correct_geometry`'s default stop on noise-free data (the pose error below it)."""
STALL_RATIO = 0.5
STALL_SIGMA = 0.1
NOISE_FLOOR = 10.0
"""`correct_geometry`'s default stop on noisy data: a correction that lowers the pose error by
less than `STALL_SIGMA`·σ and by less than a factor 1/`STALL_RATIO` has reached what the data
allow (σ: the measurements' noise, mm); converged when the error is then within `NOISE_FLOOR`·σ
(the largest distance over many noisy points is a few σ)."""


@dataclasses.dataclass(frozen=True)
class CorrectionReport(CoordinateRows, IdentificationReport):
    """Result of `correct_geometry`.

    **Fields:** `pose_errors`: per equilibrium solved, the largest distance (mm) between a
    marker or landmark of a measured part at the model's equilibrium and at the measured pose
    (the first is the uncorrected model's, the last the final one's); `converged` (the last is
    below `tol`, or, by default, below 1e-4 mm or at the noise floor: see `correct_geometry`);
    `moves`: marker name → total displacement of its design position (mm);
    `elements`: the joints and bushings whose I (or J) marker was moved; `case_errors`: the
    final model's pose error at every measured case (mm: how it does away from the reference
    case); `notes`; `coordinates`: one `Coordinate` per moved marker coordinate (its new design
    position, mm, and its σ from the landmark noise of the reference case's measured poses).

    On the report base: one row per moved marker coordinate (`'<marker>.x'`…) with
    value, σ and one status: *identified* when the correction converged and σ is known (the
    marker's parts measured with landmarks, or the ground), *not determined* otherwise (with
    the reason). The correction reproduces one case by construction, so its consistency with
    the data is not checked (`consistency` None); the stop reason says how it ended.
    """

    pose_errors: tuple[float, ...]
    converged: bool
    moves: dict
    elements: tuple[str, ...]
    case_errors: tuple[float, ...] = ()
    notes: tuple[str, ...] = ()
    coordinates: tuple[tuple[str, Coordinate], ...] = ()

    family: ClassVar[str] = "geometric_correction"
    judged_at: ClassVar[str] = "the corrected model (no σ % bar)"
    combinations: ClassVar[tuple] = ()
    consistency: ClassVar[None] = None

    @property
    def iterations(self) -> int:
        return len(self.pose_errors) - 1

    def _labelled(self) -> list[tuple[str, Coordinate]]:
        return list(self.coordinates)

    @property
    def stop_reason(self) -> str:
        head = (f"{self.iterations} correction(s), pose error at the reference case "
                + " → ".join(f"{e:.3g}" for e in self.pose_errors) + " mm")
        return head + ("" if self.converged else " (NOT converged)") + "".join(
            f"; {n}" for n in self.notes)

    def summary(self) -> dict:
        return IdentificationReport.summary(self) | dict(
            pose_errors=list(self.pose_errors), converged=self.converged,
            iterations=self.iterations, moves=self.moves, elements=list(self.elements),
            case_errors=list(self.case_errors), notes=list(self.notes))

    def __str__(self) -> str:
        lines = [f"Geometric correction: {self.iterations} correction(s), pose error "
                 + " → ".join(f"{e:.2e}" for e in self.pose_errors) + " mm"
                 + ("" if self.converged else " (NOT converged)")]
        for name, move in self.moves.items():
            lines.append(f"  {name:<28} moved {move:8.4f} mm")
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


def _marker_sigma(x_i, part_i, part_j, measured_index, rot_m, trans_m, pose_cov, sigma):
    """σ (3,) of a moved I marker's design position from the landmark noise of the measured
    poses of its two parts at the reference case (spec geometry §3.8: x_I = R1ᵀ(g − T1) with g
    the point of S2 where I must sit; a pose perturbed by (θ, δT) moves it by
    R1ᵀ([g − T1]× θ1 − δT1) + R1ᵀ(−[g − T2]× θ2 + δT2)); None when a part is neither measured
    nor the ground (its pose is the equilibrium's, whose noise is not modelled here)."""
    for p in (part_i, part_j):
        if p >= 0 and p not in measured_index:
            return None
    if part_i >= 0:
        m1 = measured_index[part_i]
        r1, t1 = rot_m[m1], trans_m[m1]
    else:
        m1, r1, t1 = None, np.eye(3), np.zeros(3)
    g = r1 @ x_i + t1
    cov = np.zeros((3, 3))
    if m1 is not None:
        g1 = r1.T @ np.hstack([np.asarray(skew(jnp.asarray(g - t1))), -np.eye(3)])
        cov += g1 @ pose_cov[m1] @ g1.T
    if part_j >= 0:
        m2 = measured_index[part_j]
        g2 = r1.T @ np.hstack([-np.asarray(skew(jnp.asarray(g - trans_m[m2]))), np.eye(3)])
        cov += g2 @ pose_cov[m2] @ g2.T
    return sigma * np.sqrt(np.clip(np.diag(cov), 0.0, None))


def _element_markers(mech, elements, side):
    pairs = []
    groups = [("joint", mech.joints), ("bushing", mech.bushings)]
    known = {n: (kind, group) for kind, group in groups for n in group.names}
    names = list(known) if elements is None else list(elements)
    for name in names:
        if name not in known:
            raise InputError(f"element '{name}' is not a joint or bushing of model "
                             f"'{mech.name}' (known: {', '.join(known)}).")
        _, group = known[name]
        k = group.names.index(name)
        i, j = group.i_marker[k], group.j_marker[k]
        which = side.get(name, "i") if isinstance(side, dict) else side
        if which not in ("i", "j"):
            raise InputError(f"side of '{name}' must be 'i' or 'j'; got {which!r}.")
        pairs.append((name, (i, j) if which == "i" else (j, i)))
    moved = [m for _, (m, _) in pairs]
    dup = sorted({mech.markers.names[m] for m in moved if moved.count(m) > 1})
    if dup:
        raise InputError(f"marker(s) {', '.join(dup)} would be moved by several elements; "
                         "correct one element per marker (name them in params).")
    return tuple(pairs)


def _followers(mech, measured_index):
    """For each unmeasured part, the measured part whose displacement it follows at the
    measured state (joined to it by an ideal joint), or None (joined to the ground by an ideal
    joint, or to no measured part: it keeps its equilibrium pose)."""
    part_of = mech.markers.part
    links = [(part_of[i], part_of[j]) for i, j in zip(mech.joints.i_marker,
                                                       mech.joints.j_marker, strict=True)]
    out = {}
    for p in range(len(mech.parts)):
        if p in measured_index:
            continue
        others = [b if a == p else a for a, b in links if p in (a, b)]
        out[p] = None if -1 in others else next((o for o in others if o in measured_index),
                                                None)
    return out


def _part_pose_table(rot_eq, trans_eq, rot_m, trans_m, measured_index, followers):
    """Poses (P, 3, 3)/(P, 3) of every part at the measured state: measured where the part is
    measured; an unmeasured part jointed to a measured one moves with it from the equilibrium
    (its joint keeps its equilibrium state), else keeps its equilibrium pose."""
    rot, trans = np.array(rot_eq), np.array(trans_eq)
    for p, m in measured_index.items():
        rot[p], trans[p] = rot_m[m], trans_m[m]
    for p, leader in followers.items():
        if leader is not None:
            m = measured_index[leader]
            r_move = rot_m[m] @ rot_eq[leader].T
            rot[p] = r_move @ rot_eq[p]
            trans[p] = r_move @ (trans_eq[p] - trans_eq[leader]) + trans_m[m]
    return rot, trans


def _global(rot, trans, part, x, o):
    if part < 0:
        return x, o
    return rot[part] @ x + trans[part], rot[part] @ o


def correct_geometry(
    mech,
    measurements,
    params: Sequence[str] | None = None,
    *,
    case: int = 0,
    loads=None,
    side: str | dict = "i",
    tol: float | None = None,
    max_iterations: int = 20,
    **solve_options,
):
    """Equilibrium-consistent geometric correction (spec geometry §3.7–3.8, chapter 2;
    CORRECTIONS 13): move the joint and bushing frames on the bolted side so that the model's
    static equilibrium under the measured case's loads reproduces the measured part poses.

    One correction (2.33)–(2.35): solve the equilibrium; for each element (markers I on part
    S1, J on S2), take the relative pose D_eq of I in J at that equilibrium (the bushing's
    equilibrium deformation; for an ideal joint a pose its constraint allows) and place I where
    it must be on S1 for I to sit at D_eq from J when S1 and S2 are at their measured poses:
    [A*_I/S1] = [A_S1]⁻¹[A_S2][A_J/S2] D_eq. The bushing is drawn pre-deformed, not given an
    offset (§3.9). The new geometry changes lever arms and wrench directions, so the new
    equilibrium is not yet the measured one: re-solve and re-correct until the largest
    marker/landmark distance between equilibrium and measurement is below `tol` (one pass cannot
    be exact: CORRECTIONS 13). A part without a measured pose (e.g. the strut) is taken to move
    with the measured part it is jointed to (from the equilibrium to the measured state), or to
    stay at its equilibrium pose when it is jointed to the ground (e.g. the rack).

    **Arguments:**

    - `mech`: the model; `measurements`: `Measurements` (poses of some parts);
      `case`: which measured case is the reference equilibrium (0-based). Every measured case
      is solved at each pass (one batched solve); the others are reported, not corrected for.
    - `loads`: the loads of every measured case (default: the measurements' own).
    - `params`: the joints and bushings to correct, by name (default: all); `side`: which
      marker moves, `'i'` (the Adams I marker: the inner sleeve, bolted, in the thesis's
      convention) or `'j'`, or a dict name → side.
    - `tol` (mm): stop when the pose error is below it. Default None: relative to the noise —
      stop when the error is below `TOL_FLOOR` (1e-4 mm: noise-free data, as before) or when a
      correction no longer lowers it (by less than `STALL_SIGMA`·σ and less than a factor
      2, σ = `measurements.sigma`): the remaining error is the measured poses' own noise, which
      no geometry removes (an absolute 1e-4 mm is out of reach of noisy data and said "NOT
      converged" for a correction that was done). It is then converged if within
      `NOISE_FLOOR`·σ; a note gives the error against σ.
    - `max_iterations`; `**solve_options` for `solve_statics`.

    **Returns:** `(corrected mechanism, CorrectionReport)`.
    """
    import equinox as eqx


    n_cases = measurements.n_cases
    if not 0 <= case < n_cases:
        raise InputError(f"case {case} is out of range: the measurements have {n_cases} "
                         f"case(s) (0-based).")
    measured_index = {}
    for m, part in enumerate(measurements.parts):
        if part not in mech.parts:
            raise InputError(f"measured part '{part}' is not a part of model '{mech.name}' "
                             f"(its parts: {', '.join(mech.parts)}).")
        measured_index[mech.parts.index(part)] = m
    if not measured_index:
        raise InputError("the measurements have no pose of any part of the model.")
    table_loads = measurements.loads if loads is None else loads
    if table_loads.n_cases != n_cases:
        raise InputError(f"loads must have one case per measured case ({n_cases}); got "
                         f"{table_loads.n_cases}.")
    pairs = _element_markers(mech, params, side)
    rot_all = np.asarray(measurements.rotation)
    trans_all = np.asarray(measurements.translation)
    rot_m, trans_m = rot_all[case], trans_all[case]
    # points that show the pose error: every marker of a measured part, and its landmarks
    part_of = np.asarray(mech.markers.part)
    check = [(p, np.asarray(mech.markers.position)[part_of == p]) for p in measured_index]
    if measurements.layout is not None:
        lay = np.asarray(measurements.layout.position)
        check += [(mech.parts.index(part), lay[k][measurements.layout.present[k]])
                  for k, part in enumerate(measurements.layout.parts) if part in mech.parts]

    def pose_errors(rot_eq, trans_eq):
        """Largest point distance (mm) per case between equilibrium and measurement."""
        err = np.zeros(n_cases)
        for p, pts in check:
            if len(pts):
                m = measured_index[p]
                diff = (np.einsum("kj,cij->cki", pts, rot_eq[:, p] - rot_all[:, m])
                        + (trans_eq[:, p] - trans_all[:, m])[:, None])
                err = np.maximum(err, np.max(np.linalg.norm(diff, axis=-1), axis=-1))
        return err

    original = np.asarray(mech.markers.position)
    followers = _followers(mech, measured_index)
    sigma = float(measurements.sigma)

    def stalled():
        if tol is not None or len(errors) < 2:
            return False
        gain = errors[-2] - errors[-1]
        return gain < STALL_SIGMA * sigma and errors[-1] > STALL_RATIO * errors[-2]

    def done():
        return errors[-1] < (TOL_FLOOR if tol is None else tol) or stalled()

    errors, q0, current = [], None, mech
    for _ in range(max_iterations + 1):
        # every measured case at once (one batched solve); the reference case drives the
        # correction, the others show how the corrected model does elsewhere
        sol = solve_statics(current, table_loads, q0=q0, **solve_options)
        q_all = np.asarray(sol.q)
        rot_eq_all, trans_eq_all = (np.asarray(a) for a in part_poses(current, q_all))
        case_errors = pose_errors(rot_eq_all, trans_eq_all)
        errors.append(float(case_errors[case]))
        if done() or len(errors) > max_iterations:
            break
        q = q_all[case]
        rot, trans = _part_pose_table(rot_eq_all[case], trans_eq_all[case], rot_m, trans_m,
                                      measured_index, followers)
        pos_eq, ori_eq = (np.asarray(a) for a in marker_poses(current, q))
        x0 = np.array(current.markers.position)
        o0 = np.array(current.markers.orientation)
        for _, (mi, mj) in pairs:
            r_d = ori_eq[mj].T @ ori_eq[mi]
            t_d = ori_eq[mj].T @ (pos_eq[mi] - pos_eq[mj])
            pj, oj = _global(rot, trans, part_of[mj], x0[mj], o0[mj])
            pi_star, oi_star = pj + oj @ t_d, oj @ r_d
            pi = part_of[mi]
            if pi < 0:
                x0[mi], o0[mi] = pi_star, oi_star
            else:
                x0[mi] = rot[pi].T @ (pi_star - trans[pi])
                o0[mi] = rot[pi].T @ oi_star
        current = eqx.tree_at(lambda m: (m.markers.position, m.markers.orientation), current,
                              (jnp.asarray(x0), jnp.asarray(o0)))
        q0 = jnp.asarray(q_all)
    final = np.asarray(current.markers.position)
    moves = {current.markers.names[mi]: float(np.linalg.norm(final[mi] - original[mi]))
             for _, (mi, _) in pairs}
    limit = TOL_FLOOR if tol is None else tol
    converged = errors[-1] < limit or (stalled() and errors[-1] <= NOISE_FLOOR * sigma)
    notes = ()
    if errors[-1] >= limit and converged:
        notes = (f"stopped at the noise floor: pose error {errors[-1]:.3g} mm "
                 f"({errors[-1] / sigma:.2g} σ of the measurements, σ = {sigma:g} mm) no longer "
                 "falls: the rest is the measured poses' noise",)
    elif not converged:
        why = (f"tol {tol:g} mm" if tol is not None else
               f"still falling, or above {NOISE_FLOOR:g} σ = {NOISE_FLOOR * sigma:g} mm")
        notes = (f"not converged: pose error {errors[-1]:.3g} mm after {len(errors) - 1} "
                 f"corrections ({why})",)
    coords = _correction_rows(current, pairs, measurements, measured_index, case, sigma,
                              bool(converged))
    return current, CorrectionReport(tuple(errors), bool(converged), moves,
                                     tuple(n for n, _ in pairs), tuple(case_errors), notes,
                                     coords)


def _correction_rows(mech, pairs, measurements, measured_index, case, sigma, converged):
    """One (marker, `Coordinate`) per coordinate of every moved marker (its new design
    position and σ, `_marker_sigma`), with its status."""
    part_of = np.asarray(mech.markers.part)
    final = np.asarray(mech.markers.position)
    rot_m = np.asarray(measurements.rotation)[case]
    trans_m = np.asarray(measurements.translation)[case]
    landmarks = measurements.layout is not None and measurements.weights is not None
    pose_cov = None
    if landmarks:
        pose_cov = np.asarray(pose_covariance(
            jnp.asarray(measurements.layout.position),
            jnp.asarray(measurements.rotation)[case:case + 1],
            jnp.asarray(measurements.weights)[case:case + 1]))[0]
    out = []
    for _, (mi, mj) in pairs:
        name = mech.markers.names[mi]
        sig = None if pose_cov is None else _marker_sigma(
            final[mi], int(part_of[mi]), int(part_of[mj]), measured_index, rot_m, trans_m,
            pose_cov, sigma)
        if not converged:
            reason = "the correction did not converge"
        elif pose_cov is None:
            reason = "σ unknown: poses without landmarks"
        elif sig is None:
            reason = ("σ unknown: a part of this element has no measured pose (it moves with "
                      "the equilibrium)")
        else:
            reason = ""
        for k in range(3):
            s = math.nan if sig is None else float(sig[k])
            out.append((name, Coordinate(name="xyz"[k], value=float(final[mi, k]), sigma=s,
                                         unit="mm", determined=not reason, reason=reason)))
    return tuple(out)


def offset_equivalent(mech, q, bushings: Sequence[str] | None = None):
    """The offset model of a pre-deformed bushing (spec geometry §3.9, eqs. 2.36–2.43): at the
    configuration `q` (the reference equilibrium) each bushing's I marker is moved onto its J
    marker and the deformation it had there becomes the offset: δ0 = −δ_eq, angles0 =
    −angles_eq (2.36: T₀ = −T_eq; in the Adams law F = −K(δ − δ0) as the thesis's
    F = f(T − T₀)), so both models exert the same force and torque on I at the reference.

    They are **not** equivalent elsewhere: with R^c the relative rotation of I in J at another
    configuration, the offset model's translational deformation is T^c − R^c R_eqᵀ T_eq (2.41)
    and its force −K(T^c − R^c R_eqᵀ T_eq + T_eq) differs from the pre-deformed −K T^c unless
    R^c R_eqᵀ T_eq = T_eq (2.42–2.43). (Even at the reference the J part's moment differs by
    the second-order δ_eq × F, since I and J then coincide.) The thesis draws bushings
    pre-deformed (`correct_geometry` does): this converter exists to compare the two.

    **Arguments:** `mech`; `q` (n,) the public coordinates of the reference equilibrium;
    `bushings`: names (default all).

    **Returns:** the offset-model `Mechanism`.
    """
    import equinox as eqx


    b = mech.bushings
    names = list(b.names) if bushings is None else list(bushings)
    for n in names:
        if n not in b.names:
            raise InputError(f"'{n}' is not a bushing of model '{mech.name}' (bushings: "
                             f"{', '.join(b.names) or 'none'}).")
    q = jnp.asarray(q)
    delta_t, delta_r, _, _ = (np.asarray(a) for a in bushing_states(mech, q))
    pos, ori = (np.asarray(a) for a in marker_poses(mech, q))
    rot, trans = (np.asarray(a) for a in part_poses(mech, q))
    x0 = np.array(mech.markers.position)
    o0 = np.array(mech.markers.orientation)
    off_t, off_r = np.array(b.offset_trans), np.array(b.offset_rot)
    for n in names:
        k = b.names.index(n)
        i, j = b.i_marker[k], b.j_marker[k]
        part = mech.markers.part[i]
        if part < 0:
            x0[i], o0[i] = pos[j], ori[j]
        else:
            x0[i] = rot[part].T @ (pos[j] - trans[part])
            o0[i] = rot[part].T @ ori[j]
        off_t[k], off_r[k] = -delta_t[k], -delta_r[k]
    return eqx.tree_at(
        lambda m: (m.markers.position, m.markers.orientation, m.bushings.offset_trans,
                   m.bushings.offset_rot),
        mech, (jnp.asarray(x0), jnp.asarray(o0), jnp.asarray(off_t), jnp.asarray(off_r)))
