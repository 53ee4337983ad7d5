"""Geometric identification: joint locations from the measured relative motion of parts
(spec geometry §4, the thesis's chapter 3).

Every part frame coincides with the global frame at design (DESIGN.md), so a measured part pose
(R, T) is the part's displacement from design. For a pair of parts (S1, S2) and a case c, the
**relative operator** of S2 with respect to S1 (3.6, 3.9) is

    R^c = R1ᵀ R2,   T^c = R1ᵀ (T2 − T1):

a point of S2 at design position C sits at R^c C + T^c in S1's design frame. A joint forbids
some of these motions; the solvers below read its location (design coordinates, mm) and, where
needed, its axis from the c_max operators:

- `'ball'` (a ball joint, or a stiff bushing taken as one): (R^c − I) C = −T^c stacked over
  the cases, linear least squares (3.11–3.12).
- `'revolute'` (a revolute joint, or a pair of bushings on one arm): the axis u is the right
  singular vector of the smallest singular value of M = [R^c − I] (3.14–3.16); the point is
  solved in the plane orthogonal to u (truncated pseudo-inverse) and its position along u comes
  from a prior (the thesis fixes x: CORRECTIONS 17).
- `'ball_known_slide'` (a ball joint on a part sliding along a known u: the tie rod on the
  rack): [vᵀ; wᵀ]((R^c − I) C + T^c) = 0 with v, w ⟂ u, linear least squares (3.17–3.21).
- `'ball_unknown_slide'` (a ball joint on a part sliding along an unknown line of S1: the
  McPherson strut top): the images C^c = R^c C + T^c (and C itself) are collinear; minimise
  the normalised smallest principal moment (λ₂ + λ₃)/λ₁ of their scatter (3.22–3.25; the
  normalisation removes the criterion's preference for short trajectories, a digest note) by
  Levenberg–Marquardt from a 3×3×3 grid of starts around the prior (the thesis's single
  Nelder–Mead run had local minima); the line's direction is the slide (strut) axis.
- `'compliant_bushing'` (a bushing at one end of a link whose other end is a ball joint): the
  bushing centre's displacement δ^c = T^c + (R^c − I) C is along the link's axis at case c,
  R^c u with u = (C − C_ball)/‖C − C_ball‖: minimise Σ‖δ^c × R^c u‖² by Levenberg–Marquardt
  from the ball-joint solution (3.26–3.35; the thesis keeps u, the issue asks for R^c u).

**σ and observability.** Every solver minimises Σ_c ‖r_c(x)‖² with r_c the equations of
case c, which depend on that case's registered poses only. The first-order covariance of a
registered pose under independent landmark noise σ_L is closed-form (`pose_covariance`), and
the implicit-function theorem gives the estimate's influence matrix case by case, so the
covariance is a sum over cases of small products (`_uncertainty`: no differentiation through
the solvers or the registration). A joint is reported **observable** when (1) the weakest
singular value of its equations stands above the value landmark noise alone gives it
(`min_snr` times that noise level: the data tell the direction from noise), and (2) the
largest σ of its centre, inflated by the equations' lack of fit when they fit worse than
the noise explains (a bushing taken as a joint), is within the hardpoint tolerance
`max_sigma`; otherwise the report says "not observable from these cases" and gives no centre
(the thesis's strut top without steering input was 175 mm off: spec geometry §4.8, §4.10).

Units: mm, rad. Every solver is written for one joint and the whole stack of cases; all joints
of a list are located by one compiled program.

**Modules.** This module holds the joint list a model implies (`joints_from_model`), the
located joints written back into a model (`apply_locations`) and the experiment design
(`design_geometry_cases`); the data types and files are in `geometric_joints`, the solvers in
`geometric_locate`, the correction in `geometric_correct`. Every public name is importable
from here.
"""

import dataclasses
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import InputError
from ..statics import part_poses
from ._sensitivity import design_experiment
from .geometric_correct import CorrectionReport, correct_geometry, offset_equivalent
from .geometric_joints import (
    FREE_AXIS_RATIO,
    GROUND,
    JOINT_KINDS,
    Coordinate,
    GeometricJoint,
    GeometricReport,
    JointEstimate,
    element_table,
    free_axis,
    model_geometry,
    read_joints,
    write_joints,
)
from .geometric_locate import (
    START_OFFSETS,
    case_residual,
    joint_specs,
    joint_values,
    locate_joints,
    pose_covariance,
    registration_check,
    relative_operators,
    skew,
)
from .params import Params

__all__ = [
    "JOINT_KINDS",
    "START_OFFSETS",
    "GeometryDesign",
    "design_geometry_cases",
    "apply_locations",
    "displace_joints",
    "element_table",
    "joints_from_model",
    "model_geometry",
    "CorrectionReport",
    "correct_geometry",
    "GeometricJoint",
    "GeometricReport",
    "JointEstimate",
    "Coordinate",
    "joint_values",
    "locate_joints",
    "registration_check",
    "offset_equivalent",
    "read_joints",
    "relative_operators",
    "write_joints",
]


def joints_from_model(mech, parts: Sequence[str], *, compliant: Sequence[str] = ()
                      ) -> tuple[tuple[GeometricJoint, ...], tuple[str, ...]]:
    """The joint list a model implies for the measured `parts` (spec geometry §4.6): which
    solver locates which element, with the model's hardpoints as priors.

    - spherical and universal joints, and bushings, between two measured parts (or one and the
      ground): `'ball'`; a bushing free about one axis (`FREE_AXIS_RATIO`): `'revolute'`
      with the model's point kept along the axis (not observable there), like a revolute (a
      bushing named in `compliant`, on a link whose other end is a ball joint:
      `'compliant_bushing'`);
    - revolute and cylindrical joints: `'revolute'` (the prior keeps the model's point along
      the axis);
    - a ball joint (spherical/universal) between a measured part and an unmeasured part that
      slides on the ground (translational joint: a steering rack): `'ball_known_slide'` along
      the slide axis;
    - a bushing or ball joint between the ground and an unmeasured part that slides on a
      measured part (translational or cylindrical joint: the McPherson strut):
      `'ball_unknown_slide'` from the model's position.

    **Returns:** `(joints, notes)`: the list, and one sentence per element left out (and per
    cylindrical joint located as a revolute).
    """
    table = element_table(mech)
    measured = {mech.part_index(p) for p in parts if p != GROUND}
    name_of = {i: p for i, p in enumerate(mech.parts)}
    name_of[-1] = GROUND
    pos = np.asarray(mech.markers.position)
    ori = np.asarray(mech.markers.orientation)

    def known(p):
        return p < 0 or p in measured

    def slides_of(p):
        return [(n, e) for n, e in table.items() if e[1] in ("translational", "cylindrical")
                and p in (e[2], e[3])]

    joints, notes, balls = [], [], {}
    for name, (_, kind, pi, pj, mi, _) in table.items():
        at = tuple(float(v) for v in pos[mi])
        if kind in ("spherical", "universal", "bushing") and known(pi) and known(pj):
            if pi < 0 and pj < 0:
                continue
            free = free_axis(mech, name) if kind == "bushing" else None
            if name in compliant:
                joints.append(("compliant", name, pi, pj, at))
            elif free is not None:
                joints.append(GeometricJoint(name, "revolute", (name_of[pi], name_of[pj]),
                                             prior=at, elements=(name,)))
                notes.append(f"'{name}' (bushing) is free about its {'xyz'[free]} axis "
                             f"(torsional stiffness ≤ {FREE_AXIS_RATIO:g} × the other two): "
                             "located as a revolute, its position along the axis is not "
                             "observable")
            else:
                joints.append(GeometricJoint(name, "ball", (name_of[pi], name_of[pj]),
                                             elements=(name,)))
                if kind != "bushing":
                    balls[name] = (pi, pj)
        elif kind in ("revolute", "cylindrical") and known(pi) and known(pj):
            joints.append(GeometricJoint(name, "revolute", (name_of[pi], name_of[pj]),
                                         prior=at, elements=(name,)))
            if kind == "cylindrical":
                notes.append(f"'{name}' (cylindrical) is located as a revolute, whose equations "
                             "assume the parts do not slide: if they do, its report says it "
                             "is not observable (lack of fit)")
        elif kind in ("spherical", "universal", "bushing") and (known(pi) != known(pj)):
            inner, outer = (pj, pi) if known(pi) else (pi, pj)  # inner: the unmeasured one
            moved = False
            for _, (_, _, si, sj, smi, smj) in slides_of(inner):
                other = sj if si == inner else si
                if other < 0 and kind != "bushing":
                    axis = ori[smj if sj == other else smi][:, 2]
                    joints.append(GeometricJoint(
                        name, "ball_known_slide", (GROUND, name_of[outer]),
                        slide=tuple(float(v) for v in axis), elements=(name,)))
                    moved = True
                elif other >= 0 and known(other) and outer < 0:
                    joints.append(GeometricJoint(
                        name, "ball_unknown_slide", (name_of[other], GROUND), prior=at,
                        elements=(name,)))
                    moved = True
                if moved:
                    break
            if not moved:
                notes.append(f"'{name}' joins unmeasured part '{name_of[inner]}': not located")
        elif kind not in ("translational", "cylindrical") or (known(pi) and known(pj)):
            if not (known(pi) and known(pj)):
                notes.append(f"'{name}' ({kind}) joins an unmeasured part: not located")
            elif kind != "bushing":
                notes.append(f"'{name}' ({kind}): no localisation method for this kind")
    out = []
    for j in joints:
        if isinstance(j, tuple):
            _, name, pi, pj, at = j
            link = pj if pi < 0 else pi
            ball = next((b for b, (a, c) in balls.items() if link in (a, c)), None)
            if ball is None:
                raise InputError(f"bushing '{name}' is marked compliant but its link "
                                 f"'{name_of[link]}' has no ball joint to another measured "
                                 "part.")
            out.append(GeometricJoint(name, "compliant_bushing",
                                      (name_of[pj if pi == link else pi], name_of[link]),
                                      link_ball=ball, elements=(name,)))
        else:
            out.append(j)
    unknown = [c for c in compliant if c not in table]
    if unknown:
        raise InputError(f"compliant: {', '.join(unknown)} not bushings of '{mech.name}'.")
    return tuple(out), tuple(notes)


def displace_joints(mech, joints: Sequence[GeometricJoint], offsets):
    """`mech` with the I and J markers of each joint's elements moved by `offsets` (joints,
    3) mm (design positions; the joints stay assembled: both markers move together). A
    bushing's or joint's markers shared by two listed joints move once, by the first."""
    import equinox as eqx

    table = element_table(mech)
    pos = np.array(mech.markers.position)
    done = set()
    for joint, offset in zip(joints, np.asarray(offsets, float), strict=True):
        for element in joint.elements:
            if element not in table:
                raise InputError(f"joint '{joint.name}' stands for '{element}', which is not "
                                 f"a joint or bushing of model '{mech.name}'.")
            for m in table[element][4:]:
                if m not in done:
                    pos[m] = pos[m] + offset
                    done.add(m)
    return eqx.tree_at(lambda m: m.markers.position, mech, jnp.asarray(pos))


def apply_locations(mech, report: GeometricReport, joints: Sequence[GeometricJoint]):
    """The model with the located joints: the I and J markers of every element a located
    joint the report calls identified (every coordinate but a revolute's position along its
    axis) stands for are moved to its centre (design coordinates); a revolute
    joint's markers are also turned so that their z is the located axis.

    **Returns:** `(mechanism, moved)`: the new model and element name → displacement (mm).
    """
    import equinox as eqx

    table = element_table(mech)
    x0 = np.array(mech.markers.position)
    o0 = np.array(mech.markers.orientation)
    moved = {}
    for joint in joints:
        est = report[joint.name]
        if not est.observable or (est.coordinates and not report.joint_identified(joint.name)):
            continue  # only what the report calls identified is written
        for element in joint.elements:
            if element not in table:
                raise InputError(f"joint '{joint.name}' stands for '{element}', which is not "
                                 f"a joint or bushing of model '{mech.name}'.")
            _, kind, _, _, mi, mj = table[element]
            moved[element] = float(np.linalg.norm(est.centre - x0[mi]))
            for m in (mi, mj):
                x0[m] = est.centre
                if joint.kind == "revolute" and est.axis is not None:
                    z = est.axis if est.axis @ o0[m][:, 2] >= 0 else -est.axis
                    x = o0[m][:, 0] - (o0[m][:, 0] @ z) * z
                    x /= np.linalg.norm(x)
                    o0[m] = np.column_stack([x, np.cross(z, x), z])
    new = eqx.tree_at(lambda m: (m.markers.position, m.markers.orientation), mech,
                      (jnp.asarray(x0), jnp.asarray(o0)))
    return new, moved


# ------------------------------------------------------------- experiment design (geometry)


@dataclasses.dataclass(frozen=True)
class GeometryDesign:
    """Result of `design_geometry_cases`.

    **Fields:** `cases`: the chosen candidate indices, in the order they were added, up to
    the first step at which every joint is observable (all of them if none is); `sigma`:
    joint name → largest coordinate σ (mm) of its centre with those cases (at the landmark
    noise σ_L; inf when not determined); `observable`: joint name → σ finite and ≤
    `max_sigma`; `history`: the worst joint σ after each added case; `complete`: every joint
    observable; `report`: the stiffness design's `DesignReport` of the whole greedy run
    (`budget` steps; targets named `'<marker>.x'`…).
    """

    cases: tuple[int, ...]
    sigma: dict
    observable: dict
    history: tuple[float, ...]
    complete: bool
    report: object = None


def _design_parameters(mech, joints, table):
    """The model numbers that stand for each joint's unknowns: its centre (the position of
    the I marker of its first element; a revolute's coordinate along the axis is fixed by
    its prior and left out) and, for the unknown slide, the slide's line on S1 (the position
    and z axis of the translational/cylindrical joint's marker on S1, one coordinate of each
    left out for the gauge). Returns (Params, per joint (centre marker, line marker or None),
    target names)."""
    n_markers = len(mech.markers.names)
    pos_mask = np.zeros((n_markers, 3), bool)
    ori_mask = np.zeros((n_markers, 3, 3), bool)
    ori = np.asarray(mech.markers.orientation)
    markers, targets = [], []
    for j in joints:
        if not j.elements or j.elements[0] not in table:
            raise InputError(f"joint '{j.name}': the design needs elements=(name of a joint or "
                             f"bushing of model '{mech.name}'), whose marker is its centre "
                             "(joints_from_model fills it).")
        centre = table[j.elements[0]][4]
        keep = [True, True, True]
        if j.kind == "revolute":
            axis = ori[centre][:, 2]
            drop = "xyz".index(j.prior_coordinate) if j.prior_coordinate else \
                int(np.argmax(np.abs(axis)))
            keep[drop] = False
        pos_mask[centre] |= keep
        targets += [f"{mech.markers.names[centre]}.{c}" for c, k in zip("xyz", keep,
                                                                         strict=True) if k]
        line = None
        if j.kind == "ball_unknown_slide":
            s1 = mech.part_index(j.parts[0])
            for _, kind, pi, pj, mi, mj in table.values():
                if kind in ("translational", "cylindrical") and s1 in (pi, pj):
                    line = mi if pi == s1 else mj
                    break
            if line is None:
                raise InputError(f"joint '{j.name}': model '{mech.name}' has no translational "
                                 f"or cylindrical joint on '{j.parts[0]}' for the slide.")
            axis = ori[line][:, 2]
            fixed = int(np.argmax(np.abs(axis)))
            pos_mask[line] = [c != fixed for c in range(3)]
            ori_mask[line, :, 2] = [c != fixed for c in range(3)]
        markers.append((centre, line))
    params = Params.leaves(mech, lambda m: (m.markers.position, m.markers.orientation),
                           (pos_mask, ori_mask))
    return params, markers, targets


def design_geometry_cases(
    mech,
    candidates,
    joints: Sequence[GeometricJoint],
    layout,
    *,
    landmark_sigma: float = 0.05,
    max_sigma: float = 10.0,
    budget: int | None = None,
    start: Sequence[int] = (),
) -> GeometryDesign:
    """Which load cases make every joint observable (spec geometry §4.10: steering inputs,
    varied rotations), chosen by the stiffness design's greedy search
    (`diffsusp.identify.design_experiment`, criterion "sigma").

    The joint localisation is a least-squares problem in the joint centres whose equations
    r_c (`case_residual`) hold case by case; so is a stiffness identification in the
    stiffnesses, and `design_experiment` chooses cases from any per-case measurement model.
    Here the measurement model of a case is the whitened geometric equations of every joint at
    the model's equilibrium, W_c r_c(x) with x the model's joint hardpoints (the parameters),
    the poses held at the equilibrium (its derivative with respect to the hardpoints is not
    the localisation's: the equations use the measured poses) and W_c = (D_c Σ_c D_cᵀ)^(−1/2)
    from the poses' landmark noise (`pose_covariance`, D_c = ∂r_c/∂poses), joint by joint
    (each solver uses its own equations only): each case adds A_cᵀ (D_c Σ_c D_cᵀ)⁻¹ A_c / σ_L²
    to the information of the centres (the generalised least-squares bound of the estimators'
    covariance, a little below the σ `locate_joints` reports for its ordinary least squares).
    The strut top's line (a point and the direction of the slide on
    S1) are nuisance parameters (without the localisation's design-position equation: the
    design is pessimistic there); a compliant bushing and its link's
    ball share the ball centre; a revolute's coordinate along the axis is fixed by its prior.

    **Arguments:**

    - `mech`: the model (the truth or the nominal design); `candidates`: candidate `Loads`
      (e.g. wheel heights × rack positions × forces: `mech.loads(...)`).
    - `joints`: the joint list, each with `elements` (as `joints_from_model` gives it).
    - `layout`: the `LandmarkLayout` of the measured parts (their noise whitens the equations).
    - `landmark_sigma` (mm), `max_sigma` (mm: a joint is observable when its centre's largest
      coordinate σ is within it), `budget`: greedy steps (default: the number of candidates,
      at most 12), `start`: cases already in the plan.

    **Returns:** a `GeometryDesign`.

    **Raises:** `InputError` for a joint without `elements`, a part without landmarks, or an
    unknown slide whose model has no slide joint on S1.
    """
    table = element_table(mech)
    parts = tuple(layout.parts)
    joint_specs(joints, parts)  # unknown parts, links
    params, markers, targets = _design_parameters(mech, joints, table)
    measured = [mech.part_index(p) for p in parts]
    reference = jnp.asarray(layout.position)
    present = jnp.asarray(layout.present, dtype=reference.dtype)
    part_index = {p: (-1 if p == GROUND else mech.part_index(p)) for j in joints
                  for p in j.parts}
    slot = {i: k for k, i in enumerate(measured)}
    kinds = [(j.kind, j.parts, None if j.kind != "compliant_bushing" else
              [g.name for g in joints].index(j.link_ball), j.slide) for j in joints]

    def observe(m, q):
        q = jax.lax.stop_gradient(q)
        rot, trans = part_poses(m, q)
        rot_m, trans_m = rot[jnp.asarray(measured)], trans[jnp.asarray(measured)]
        pose_cov = pose_covariance(reference, rot_m[None], present[None])[0]
        eye = jnp.eye(3, dtype=rot.dtype)
        pos, ori = m.markers.position, m.markers.orientation

        def residuals(eps):
            def pose(p):
                i = part_index[p]
                if i < 0:
                    return eye, jnp.zeros(3, rot.dtype)
                k = slot[i]
                return (eye + skew(eps[k, :3])) @ rot_m[k], trans_m[k] + eps[k, 3:]

            out = []
            for (kind, (p1, p2), link, slide), (centre, line) in zip(kinds, markers,
                                                                     strict=True):
                (r1, t1), (r2, t2) = pose(p1), pose(p2)
                r, t = r1.T @ r2, r1.T @ (t2 - t1)
                x = pos[centre]
                extra = jnp.zeros(3, rot.dtype)
                if kind == "ball_unknown_slide":
                    x = jnp.concatenate([x, pos[line], ori[line][:, 2]])
                elif kind == "ball_known_slide":
                    extra = jnp.asarray(slide, rot.dtype)
                elif kind == "compliant_bushing":
                    extra = pos[markers[link][0]]
                out.append(case_residual(kind, x, r, t, extra))
            return out

        eps0 = jnp.zeros((len(measured), 6), rot.dtype)
        cov_pose = jax.scipy.linalg.block_diag(*pose_cov)
        out = []
        for res, d in zip(residuals(eps0), jax.jacfwd(residuals)(eps0), strict=True):
            # each joint whitened on its own: its solver does not use the other joints'
            # equations (nor their correlated noise)
            # (pseudo-inverse square root: a combination of the equations that no noise
            # reaches is an identity — the compliant link's r·R u = 0 — not information)
            d = jax.lax.stop_gradient(d.reshape(-1, 6 * len(measured)))
            w, v = jnp.linalg.eigh(d @ cov_pose @ d.T)
            scale = jnp.where(w > 1e-6 * w[-1], 1.0 / jnp.sqrt(jnp.maximum(w, 1e-300)), 0.0)
            out.append((v * scale) @ v.T @ res)
        return jnp.concatenate(out)

    n_cand = int(candidates.n_cases)
    steps = min(n_cand, 12) if budget is None else min(int(budget), n_cand)
    report = design_experiment(mech, candidates, params, steps, sigma=landmark_sigma,
                               observe=observe, targets=targets, criterion="sigma",
                               start=tuple(start))
    per_joint = []
    for centre, _ in markers:
        prefix = f"{mech.markers.names[centre]}."
        per_joint.append([t for t, name in enumerate(report.targets)
                          if name.startswith(prefix)])
    history, observable, sigma = [], {}, {}
    stop = len(report.chosen)
    best = {j.name: np.inf for j in joints}
    for step in range(len(report.chosen)):
        # A case added never removes information: a σ that rises again after a step is the
        # rank test of the pseudo-inverse flipping (a weak direction under a threshold relative
        # to the strongest), not a joint lost; each joint keeps the best bound so far.
        sig = {j.name: min(best[j.name], float(np.max(report.sigma[step][cols])))
               for j, cols in zip(joints, per_joint, strict=True)}
        best = sig
        history.append(max(sig.values()))
        sigma, observable = sig, {k: bool(v <= max_sigma) for k, v in sig.items()}
        if all(observable.values()):
            stop = step + 1
            break
    return GeometryDesign(tuple(report.chosen[:stop]), sigma, observable, tuple(history),
                          all(observable.values()), report)
