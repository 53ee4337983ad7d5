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
registered pose under independent landmark noise σ_L is closed-form (`_pose_covariance`), and
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

**Size.** About 1 200 lines: the five joint solvers of chapter 3, their σ and observability
verdicts, the experiment design and the equilibrium-consistent correction share the relative
operators and the joint description; they are read together with the thesis's chapter.
"""

import dataclasses
import functools
import json
import math
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import InputError

__all__ = [
    "JOINT_KINDS",
    "GeometryDesign",
    "design_geometry_cases",
    "apply_locations",
    "joints_from_model",
    "CorrectionReport",
    "correct_geometry",
    "GeometricJoint",
    "GeometricReport",
    "JointEstimate",
    "locate_joints",
    "offset_equivalent",
    "relative_operators",
]

JOINT_KINDS = ("ball", "revolute", "ball_known_slide", "ball_unknown_slide",
               "compliant_bushing")
"""Joint kinds the localisation knows (spec geometry §4.6's joint list)."""

GROUND = "ground"
START_OFFSETS = 150.0
"""Half-width (mm) of the 3×3×3 grid of starts around the initial estimate of a
`'ball_unknown_slide'` joint (the thesis's Nelder–Mead had local minima: §4.4b, §4.10)."""
LM_STEPS = 60


@dataclasses.dataclass(frozen=True)
class GeometricJoint:
    """One entry of the joint list: which parts, which kind, and the kind's extra data.

    **Fields:**

    - `name`; `kind`: one of `JOINT_KINDS`; `parts`: (S1, S2), the part names as in the
      measurements, `'ground'` for the fixed chassis/frame. S2 moves relative to S1; for
      `'ball_unknown_slide'` S2 is the part carrying the ball (the chassis for the strut top)
      and S1 the part carrying the slide (the hub carrier); for `'compliant_bushing'` S2 is
      the link.
    - `slide`: `'ball_known_slide'`: the slide direction in S1 (e.g. the rack axis (0, 1, 0)).
    - `prior`: `'revolute'`: a point (mm) whose position along the axis is kept (the thesis
      fixes x of each bushing of a pair); with `prior_coordinate` ('x', 'y' or 'z') only that
      coordinate of it is kept, else the point of the axis nearest to `prior` is reported.
      `'ball_unknown_slide'`: the initial estimate (required).
    - `link_ball`: `'compliant_bushing'`: name of the ball joint at the link's other end (a
      `'ball'` joint of the same list, between the link and another part).
    - `elements`: names of the model's joints or bushings this located joint stands for (their
      markers are moved by `apply_locations`).
    """

    name: str
    kind: str
    parts: tuple[str, str]
    slide: tuple[float, float, float] | None = None
    prior: tuple[float, float, float] | None = None
    prior_coordinate: str | None = None
    link_ball: str | None = None
    elements: tuple[str, ...] = ()

    def __post_init__(self):
        if self.kind not in JOINT_KINDS:
            raise InputError(f"joint '{self.name}': unknown kind '{self.kind}'; use one of "
                             f"{', '.join(JOINT_KINDS)}.")
        if len(self.parts) != 2 or self.parts[0] == self.parts[1]:
            raise InputError(f"joint '{self.name}': parts must be two different part names; "
                             f"got {self.parts!r}.")
        if self.kind == "ball_known_slide" and self.slide is None:
            raise InputError(f"joint '{self.name}' (ball_known_slide) needs the slide direction"
                             " slide=(x, y, z), e.g. the rack axis.")
        if self.kind == "ball_unknown_slide" and self.prior is None:
            raise InputError(f"joint '{self.name}' (ball_unknown_slide) needs an initial "
                             "estimate prior=(x, y, z) of the ball centre (mm).")
        if self.kind == "revolute" and self.prior is None:
            raise InputError(
                f"joint '{self.name}' (revolute) needs prior=(x, y, z): motion does not fix "
                "the point along the axis (spec geometry §4.3, CORRECTIONS 17).")
        if self.prior_coordinate not in (None, "x", "y", "z"):
            raise InputError(f"joint '{self.name}': prior_coordinate must be 'x', 'y' or 'z'.")
        if self.kind == "compliant_bushing" and self.link_ball is None:
            raise InputError(f"joint '{self.name}' (compliant_bushing) needs link_ball, the "
                             "name of the ball joint at the link's other end.")


@dataclasses.dataclass(frozen=True)
class JointEstimate:
    """Located joint. Coordinates are design (reference) coordinates in the global frame (mm).

    **Fields:** `name`, `kind`, `parts`; `centre` (3,) mm (None when not observable); `axis`
    (3,) unit (revolute: the axis; slides: the slide direction; None otherwise); `sigma` (3,)
    σ of the centre's coordinates (mm) and `sigma_axis` (3,) of the axis' components, at the
    nominal landmark noise; `residual`: root-mean-square of the solver's equations (mm; the
    unknown slide: the trajectory points' distance to their line); `singular_values` of the
    solver's equations (largest first; with σ: of the per-case equations in the unknowns the
    solver determines, for the unknown slide the centre and its line); `observable`; `note`.
    `estimate` keeps the raw centre even when not observable (for diagnostics). `snr`: the
    weakest singular value over its noise level (see `locate_joints`); `chi2`: the residual
    energy over the energy landmark noise alone would leave (≈ 1 for a joint the data fit,
    larger for a bushing taken as a joint). NaN without σ.
    """

    name: str
    kind: str
    parts: tuple[str, str]
    centre: np.ndarray | None
    axis: np.ndarray | None
    sigma: np.ndarray
    sigma_axis: np.ndarray | None
    residual: float
    singular_values: np.ndarray
    observable: bool
    note: str
    estimate: np.ndarray
    snr: float = math.nan
    chi2: float = math.nan

    def to_dict(self) -> dict:
        def arr(v):
            return None if v is None else [float(x) for x in np.asarray(v)]

        return dict(name=self.name, kind=self.kind, parts=list(self.parts),
                    centre=arr(self.centre), axis=arr(self.axis), sigma=arr(self.sigma),
                    sigma_axis=arr(self.sigma_axis), residual=float(self.residual),
                    singular_values=arr(self.singular_values), observable=self.observable,
                    note=self.note, snr=float(self.snr), chi2=float(self.chi2))


@dataclasses.dataclass(frozen=True)
class GeometricReport:
    """Result of `locate_joints`: one `JointEstimate` per joint of the list, in order, the
    landmark noise σ_L used for the σ (mm), and the number of cases."""

    joints: tuple[JointEstimate, ...]
    landmark_sigma: float
    n_cases: int
    notes: tuple[str, ...] = ()

    def __getitem__(self, name: str) -> JointEstimate:
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(f"no joint named '{name}' (joints: "
                       f"{', '.join(j.name for j in self.joints)}).")

    def to_json(self) -> str:
        return json.dumps(dict(landmark_sigma=self.landmark_sigma, n_cases=self.n_cases,
                               notes=list(self.notes),
                               joints=[j.to_dict() for j in self.joints]), indent=2)

    def rows(self) -> list[dict]:
        """One flat row per joint (for tables and CSV): x, y, z, σx, σy, σz, axis, verdict."""
        out = []
        for j in self.joints:
            c = j.centre if j.centre is not None else np.full(3, np.nan)
            a = j.axis if j.axis is not None else np.full(3, np.nan)
            out.append(dict(joint=j.name, kind=j.kind, part_1=j.parts[0], part_2=j.parts[1],
                            x=c[0], y=c[1], z=c[2], sigma_x=j.sigma[0], sigma_y=j.sigma[1],
                            sigma_z=j.sigma[2], axis_x=a[0], axis_y=a[1], axis_z=a[2],
                            residual=j.residual, snr=j.snr, chi2=j.chi2,
                            observable=j.observable, note=j.note))
        return out

    def __str__(self) -> str:
        lines = [f"Joint locations from {self.n_cases} cases (σ at landmark noise "
                 f"{self.landmark_sigma:g} mm):"]
        for j in self.joints:
            head = f"  {j.name:<24} {j.kind:<19}"
            if j.centre is None:
                lines.append(f"{head} not observable from these cases ({j.note})")
                continue
            c, s = j.centre, j.sigma
            text = (f"{head} ({c[0]:9.3f}, {c[1]:9.3f}, {c[2]:9.3f}) mm "
                    f"± ({s[0]:.3f}, {s[1]:.3f}, {s[2]:.3f})")
            if j.axis is not None:
                text += f"  axis ({j.axis[0]:.5f}, {j.axis[1]:.5f}, {j.axis[2]:.5f})"
            lines.append(text + f"  rms {j.residual:.2e}" + (f"  [{j.note}]" if j.note else ""))
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


# ----------------------------------------------------------------------------- solvers


def relative_operators(r1, t1, r2, t2):
    """Relative operators of S2 with respect to S1 over the cases (3.6, 3.9):
    R^c = R1ᵀ R2, T^c = R1ᵀ (T2 − T1). Shapes (c, 3, 3), (c, 3)."""
    r = jnp.einsum("cji,cjk->cik", r1, r2)
    t = jnp.einsum("cji,cj->ci", r1, t2 - t1)
    return r, t


def _ball(r, t):
    m = (r - jnp.eye(3)).reshape(-1, 3)
    return jnp.linalg.lstsq(m, -t.reshape(-1))[0], m


def _revolute(r, t, prior, coordinate):
    m = (r - jnp.eye(3)).reshape(-1, 3)
    u_, s, vt = jnp.linalg.svd(m, full_matrices=False)
    axis = vt[2]
    axis = axis * jnp.where(axis[jnp.argmax(jnp.abs(axis))] < 0, -1.0, 1.0)
    b = -t.reshape(-1)
    # point in the plane orthogonal to the axis: the two largest singular directions only
    point = vt[:2].T @ ((u_[:, :2].T @ b) / s[:2])
    if coordinate is None:
        point = point + axis * (axis @ (prior - point))
    else:
        point = point + axis * (prior[coordinate] - point[coordinate]) / axis[coordinate]
    return point, axis, m, s


def _known_slide(r, t, slide):
    u = slide / jnp.linalg.norm(slide)
    v = jnp.cross(u, jnp.eye(3)[jnp.argmin(jnp.abs(u))])
    v = v / jnp.linalg.norm(v)
    w = jnp.cross(u, v)
    vw = jnp.stack([v, w])
    m = jnp.einsum("ij,cjk->cik", vw, r - jnp.eye(3)).reshape(-1, 3)
    b = -jnp.einsum("ij,cj->ci", vw, t).reshape(-1)
    return jnp.linalg.lstsq(m, b)[0], m


def _trajectory(c, r, t, mask):
    """Images of a point of S2 over the cases, with the design position itself (3.22), and
    their weights (0 for padding cases)."""
    pts = jnp.concatenate([c[None], jnp.einsum("cij,j->ci", r, c) + t])
    return pts, jnp.concatenate([jnp.ones(1, mask.dtype), mask])


def _line_residual(c, r, t, mask):
    pts, w = _trajectory(c, r, t, mask)
    d = pts - (w @ pts) / jnp.sum(w)
    scatter = (d * w[:, None]).T @ d
    lam, v = jnp.linalg.eigh(scatter)
    u = v[:, 2]
    perp = (d - (d @ u)[:, None] * u) * jnp.sqrt(w)[:, None]
    return perp.ravel() / jnp.sqrt(lam[2] / jnp.sum(w)), u


def _link_residual(c, r, t, ball):
    u = (c - ball) / jnp.linalg.norm(c - ball)
    delta = t + jnp.einsum("cij,j->ci", r, c) - c
    return jnp.cross(delta, jnp.einsum("cij,j->ci", r, u)).ravel()


def _lm(residual, x0, steps=LM_STEPS):
    """Levenberg–Marquardt on a 3-parameter residual, fixed number of steps (vmappable)."""
    def cost(x):
        r = residual(x)
        return r @ r

    def step(_, state):
        x, lam, f = state
        r = residual(x)
        jac = jax.jacfwd(residual)(x)
        h = jac.T @ jac
        g = jac.T @ r
        dx = -jnp.linalg.solve(h + lam * (jnp.diag(jnp.diag(h)) + 1e-12 * jnp.trace(h)
                                          * jnp.eye(3) + 1e-300), g)
        trial = x + dx
        ft = cost(trial)
        better = jnp.isfinite(ft) & (ft < f)
        return (jnp.where(better, trial, x), jnp.where(better, lam / 3.0, lam * 4.0),
                jnp.where(better, ft, f))

    x, _, f = jax.lax.fori_loop(0, steps, step, (x0, jnp.asarray(1e-3, x0.dtype), cost(x0)))
    return x, f


def _gn_singular_values(residual, x):
    return jnp.linalg.svd(jax.jacfwd(residual)(x), compute_uv=False)


def _locate(specs, rot, trans, mask, index, slides, priors, starts):
    """All joints from the poses (cases, parts, 3, 3)/(cases, parts, 3); `mask` (cases,) is 0
    for padding cases (their relative operators are replaced by the identity, which adds zero
    rows to every solver). Returns per joint: centre, axis (zeros if none), residual rms,
    singular values, amount of relative motion."""
    n_cases = rot.shape[0]
    n_real = jnp.sum(mask)
    eye = jnp.broadcast_to(jnp.eye(3, dtype=rot.dtype), (n_cases, 3, 3))
    zero = jnp.zeros((n_cases, 3), rot.dtype)

    def pose(p):
        return (eye, zero) if p < 0 else (rot[:, p], trans[:, p])

    out, centres = {}, {}
    order = sorted(range(len(specs)), key=lambda k: specs[k][1] == "compliant_bushing")
    for k in order:
        name, kind, (p1, p2), coordinate, link = specs[k]
        r, t = relative_operators(*pose(index[p1]), *pose(index[p2]))
        r = jnp.where(mask[:, None, None] > 0, r, jnp.eye(3, dtype=r.dtype))
        t = jnp.where(mask[:, None] > 0, t, 0.0)
        motion = jnp.max(jnp.abs(r - jnp.eye(3)), axis=(0, 1, 2)) + \
            jnp.max(jnp.abs(t)) / 1000.0
        axis = jnp.zeros(3, rot.dtype)
        if kind == "ball":
            c, m = _ball(r, t)
            res = (m @ c + t.reshape(-1))
            sv = jnp.linalg.svd(m, compute_uv=False)
        elif kind == "revolute":
            c, axis, m, sv = _revolute(r, t, priors[k], coordinate)
            res = m @ c + t.reshape(-1)
        elif kind == "ball_known_slide":
            c, m = _known_slide(r, t, slides[k])
            u = slides[k] / jnp.linalg.norm(slides[k])
            delta = t + jnp.einsum("cij,j->ci", r, c) - c
            res = (delta - (delta @ u)[:, None] * u).ravel()
            axis = u
            sv = jnp.linalg.svd(m, compute_uv=False)
        elif kind == "ball_unknown_slide":
            data = (r, t, mask)

            def fn(x, d):
                return _line_residual(x, *d)[0]

            grid = jnp.asarray([-1.0, 0.0, 1.0], rot.dtype) * START_OFFSETS
            offsets = jnp.stack(jnp.meshgrid(grid, grid, grid, indexing="ij"), -1).reshape(-1, 3)
            frozen = functools.partial(fn, d=jax.lax.stop_gradient(data))
            xs, fs = jax.vmap(lambda x0, f=frozen: _lm(f, x0))(starts[k] + offsets)
            c = xs[jnp.argmin(jnp.where(jnp.isfinite(fs), fs, jnp.inf))]
            _, axis = _line_residual(c, r, t, mask)
            axis = axis * jnp.where(axis[jnp.argmax(jnp.abs(axis))] < 0, -1.0, 1.0)
            pts, w = _trajectory(c, r, t, mask)
            d = pts - (w @ pts) / jnp.sum(w)
            res = ((d - (d @ axis)[:, None] * axis) * jnp.sqrt(w)[:, None]).ravel()
            sv = _gn_singular_values(frozen, jax.lax.stop_gradient(c))
        else:  # compliant_bushing
            ball = centres[link]
            data = (r, t, ball)

            def fn(x, d):
                return _link_residual(x, *d)

            frozen = functools.partial(fn, d=jax.lax.stop_gradient(data))
            start, _ = _ball(*jax.lax.stop_gradient((r, t)))
            c, _ = _lm(frozen, start)
            res = fn(c, data)
            sv = _gn_singular_values(frozen, jax.lax.stop_gradient(c))
        centres[k] = c
        rows = res.shape[0] // (n_cases + (kind == "ball_unknown_slide"))
        count = rows * (n_real + (kind == "ball_unknown_slide"))
        out[k] = dict(centre=c, axis=axis, rms=jnp.sqrt(jnp.sum(res**2) / count), sv=sv,
                      motion=motion)
    return [out[k] for k in range(len(specs))]


def _skew(v):
    z = jnp.zeros_like(v[..., 0])
    return jnp.stack([jnp.stack([z, -v[..., 2], v[..., 1]], -1),
                      jnp.stack([v[..., 2], z, -v[..., 0]], -1),
                      jnp.stack([-v[..., 1], v[..., 0], z], -1)], -2)


def _pose_covariance(reference, rotation, weights):
    """First-order covariance, per unit landmark σ, of every registered pose (cases, parts,
    6, 6), in the perturbation R → (I + [θ]×) R, T → T + δT (θ first).

    The registration minimises Σ_a w_a ‖R P_a + T − Q_a‖² (spec geometry §3.6); a landmark moves
    by G_a (θ, δT) with G_a = [−[R P_a]×, I], so to first order (θ, δT) = N⁻¹ Σ_a w_a G_aᵀ δQ_a
    with N = Σ_a w_a G_aᵀ G_a, whose covariance under independent noise of σ per coordinate
    is σ² N⁻¹ (Σ_a w_a² G_aᵀ G_a) N⁻¹ (σ² N⁻¹ for 0/1 weights)."""
    w = weights
    ref = jnp.where(w[..., None] > 0, reference[None], 0.0)
    a = jnp.einsum("cpij,cpkj->cpki", rotation, ref)
    eye = jnp.broadcast_to(jnp.eye(3, dtype=a.dtype), a.shape + (3,))
    g = jnp.concatenate([-_skew(a), eye], -1)  # (c, p, k, 3, 6)
    info = jnp.einsum("cpk,cpkai,cpkaj->cpij", w, g, g)
    info2 = jnp.einsum("cpk,cpkai,cpkaj->cpij", w**2, g, g)
    inv = jnp.linalg.inv(info)
    return inv @ info2 @ inv


def _case_residual(kind, x, r, t, extra):
    """The equations of one case for one joint (zero at the joint's true location):
    `'ball'`/`'revolute'`: δ = T + (R − I) C (3.11); `'ball_known_slide'`: δ minus its
    component along the slide (3.19); `'compliant_bushing'`: δ × R u with u from the link's
    ball centre `extra` (3.34 with R^c u); `'ball_unknown_slide'`: x = (C, G, u), the distance
    of the image of C to the line through G along u of S1 (3.22–3.25 as a least-squares
    problem in the centre and the line)."""
    if kind == "ball_unknown_slide":
        u = x[6:] / jnp.linalg.norm(x[6:])
        d = r @ x[:3] + t - x[3:6]
        return d - (d @ u) * u
    delta = t + r @ x - x
    if kind in ("ball", "revolute"):
        return delta
    if kind == "ball_known_slide":
        u = extra / jnp.linalg.norm(extra)
        return delta - (delta @ u) * u
    u = (x - extra) / jnp.linalg.norm(x - extra)
    return jnp.cross(delta, r @ u)


def _sigma_parameters(kind, centre, axis, r, t, mask):
    """The unknowns of the per-case equations at the estimate: the centre, and for
    `'ball_unknown_slide'` the line (G, u) through the centre's trajectory."""
    if kind != "ball_unknown_slide":
        return centre
    pts, w = _trajectory(centre, r, t, mask)
    return jnp.concatenate([centre, (w @ pts) / jnp.sum(w), axis])


def _free_basis(kind, coordinate, axis, dtype):
    """Columns spanning the unknowns the estimator determines: the revolute's point moves in
    the plane its prior leaves free (⟂ the prior coordinate's axis, or ⟂ the joint axis);
    every other kind: all its unknowns."""
    if kind == "revolute":
        if coordinate is not None:
            return jnp.eye(3, dtype=dtype)[:, [i for i in range(3) if i != coordinate]]
        return jnp.linalg.svd(jnp.eye(3, dtype=dtype) - jnp.outer(axis, axis))[0][:, :2]
    if kind == "ball_unknown_slide":
        # gauge: G slides along u, and u's length: the seven other directions
        u = axis
        gauge = jnp.zeros((9, 2), dtype).at[3:6, 0].set(u).at[6:, 1].set(u)
        return jnp.linalg.svd(jnp.eye(9, dtype=dtype) - gauge @ gauge.T)[0][:, :7]
    return jnp.eye(3, dtype=dtype)


def _uncertainty(specs, rot, trans, mask, index, pose_cov, slides, outputs):
    """σ (per unit landmark σ) of every located centre and axis, and the noise level of every
    joint's singular values, in closed form (no differentiation through the solvers).

    Each solver minimises Σ_c ‖r_c(x)‖² over its unknowns x, with r_c the equations of case c
    (`_case_residual`), which depend on the noisy poses of that case only. The implicit-function
    theorem gives δx = −H⁻¹ Σ_c B_c ε_c with H = Σ_c ∂²(½‖r_c‖²)/∂x², B_c = ∂²(½‖r_c‖²)/∂x∂ε_c
    and ε_c the pose perturbations of case c, whose covariance is `_pose_covariance`; a compliant
    bushing adds the influence of its link's ball centre. So Cov(x) = Σ_c Φ_c Σ_c Φ_cᵀ with
    Φ_c = ∂x/∂ε_c: a sum over cases of small products. A revolute axis (the null vector of
    M = [R^c − I]) moves by δu = −(MᵀM)⁺ Σ_c (R^c − I)ᵀ δR^c u (first-order perturbation of a
    singular vector); the unknown slide's axis is part of its unknowns.

    The singular values' noise: a direction v of the unknowns is determined by the data when
    the equations' Jacobian A = [∂r_c/∂x] has ‖A v‖ (its singular value) well above the norm
    that noise alone gives A v, ‖δA v‖ with δA from the pose noise — its root-mean-square is
    returned per right singular vector (per unit landmark σ)."""
    n_parts = rot.shape[1]
    eye = jnp.eye(3, dtype=rot.dtype)
    order = sorted(range(len(specs)), key=lambda k: specs[k][1] == "compliant_bushing")
    relative = {}
    params, extras = {}, {}
    for k in order:
        _, kind, (p1, p2), _, link = specs[k]
        poses = []
        for p in (p1, p2):
            i = index[p]
            poses.append((jnp.broadcast_to(eye, rot[:, 0].shape), jnp.zeros_like(trans[:, 0]))
                         if i < 0 else (rot[:, i], trans[:, i]))
        r, t = relative_operators(*poses[0], *poses[1])
        relative[k] = (r, t)
        params[k] = _sigma_parameters(kind, outputs[k]["centre"], outputs[k]["axis"], r, t,
                                      mask)
        extras[k] = slides[k] if kind == "ball_known_slide" else (
            outputs[link]["centre"] if kind == "compliant_bushing" else jnp.zeros(3, rot.dtype))

    def one_case(rot_c, trans_c):
        def poses(eps, p):
            i = index[p]
            if i < 0:
                return eye, jnp.zeros(3, rot.dtype)
            return (eye + _skew(eps[i, :3])) @ rot_c[i], trans_c[i] + eps[i, 3:]

        eps0 = jnp.zeros((n_parts, 6), rot.dtype)
        out = {}
        for k in order:
            _, kind, (p1, p2), _, _ = specs[k]

            def residual(x, eps, extra, kind=kind, p1=p1, p2=p2):
                (r1, t1), (r2, t2) = poses(eps, p1), poses(eps, p2)
                return _case_residual(kind, x, r1.T @ r2, r1.T @ (t2 - t1), extra)

            x, extra = params[k], extras[k]
            n_x, n_e = x.shape[0], 6 * n_parts

            def flat(z, residual=residual, n_x=n_x, n_e=n_e):
                return residual(z[:n_x], z[n_x:n_x + n_e].reshape(n_parts, 6), z[n_x + n_e:])

            rest = jnp.concatenate([eps0.ravel(), extra])

            def first(x, flat=flat, rest=rest):
                jac = jax.jacfwd(flat)(jnp.concatenate([x, rest]))
                return jac, (jac, flat(jnp.concatenate([x, rest])))

            # one forward-over-forward program gives every first and second derivative:
            # second[r, i, j] = ∂²r/∂z_i∂x_j with z = (x, pose perturbations, extra)
            second, (jac, res) = jax.jacfwd(first, has_aux=True)(x)
            a, dx = jac[:, :n_x], jac[:, n_x:]
            curvature = jnp.einsum("r,rij->ji", res, second)  # (x, z)
            out[k] = dict(
                a=a, r=res, d=dx[:, :n_e],
                h=a.T @ a + curvature[:, :n_x],
                b=a.T @ dx[:, :n_e] + curvature[:, n_x:n_x + n_e],
                c=a.T @ dx[:, n_e:] + curvature[:, n_x + n_e:],
                dj=jnp.swapaxes(second[:, n_x:n_x + n_e], 1, 2))
        return out

    per = jax.vmap(one_case)(rot, trans)
    cov_pose = jax.vmap(lambda c: jax.scipy.linalg.block_diag(*c))(pose_cov)  # (c, 6P, 6P)
    cov_pose = cov_pose * mask[:, None, None]
    influence, noise = {}, {}
    for k in order:
        _, kind, _, coordinate, link = specs[k]
        d = {key: v * mask.reshape((-1,) + (1,) * (v.ndim - 1)) for key, v in per[k].items()}
        h = jnp.sum(d["h"], 0)
        axis = outputs[k]["axis"]
        x = params[k]
        basis = _free_basis(kind, coordinate, axis, rot.dtype)
        a_f = jnp.einsum("crp,pq->crq", d["a"], basis)
        gauss = jnp.einsum("crp,crq->pq", a_f, a_f)
        rss = jnp.sum(d["r"] ** 2)
        if kind == "ball_unknown_slide":
            # the design position is on the line too (C itself, no pose noise)
            def design(z):
                u = z[6:] / jnp.linalg.norm(z[6:])
                g = z[:3] - z[3:6]
                return g - (g @ u) * u

            a0 = jax.jacfwd(design)(x)
            h = h + a0.T @ a0 + jnp.einsum("i,ijk->jk", design(x),
                                           jax.hessian(design)(x))
            gauss = gauss + basis.T @ a0.T @ a0 @ basis
            rss = rss + jnp.sum(design(x) ** 2)
        # lack of fit: the residual energy noise alone would leave, E‖r‖² = tr((I − P_A) Σ_r)
        cov_r = jnp.einsum("cre,cef,csf->crs", d["d"], cov_pose, d["d"])
        expected = jnp.einsum("crr->", cov_r) - jnp.trace(jnp.linalg.solve(
            gauss, jnp.einsum("crp,crs,csq->pq", a_f, cov_r, a_f)))
        hinv = basis @ jnp.linalg.inv(basis.T @ h @ basis) @ basis.T
        phi = -jnp.einsum("ij,cjk->cik", hinv, d["b"])  # (c, p, 6P)
        if kind == "compliant_bushing":
            coupling = jnp.sum(d["c"], 0)
            phi = phi - jnp.einsum("ij,jk,ckl->cil", hinv, coupling, influence[link][:, :3])
        if kind == "revolute":
            m = d["a"].reshape(-1, 3)
            w_, v_ = jnp.linalg.eigh(m.T @ m)
            plane = v_[:, 1:] @ jnp.diag(1.0 / w_[1:]) @ v_[:, 1:].T
            du = jnp.einsum("crpe,p->cre", d["dj"], axis)
            phi_axis = -jnp.einsum("ij,crj,cre->cie", plane, d["a"], du)
        elif kind == "ball_unknown_slide":
            phi_axis = phi[:, 6:] - jnp.einsum("i,j,cje->cie", axis, axis, phi[:, 6:])
            phi_axis = phi_axis / jnp.linalg.norm(x[6:])
        else:
            phi_axis = jnp.zeros_like(phi[:, :3])
        influence[k] = jnp.concatenate([phi[:, :3], phi_axis], 1)
        # noise of A v for every right singular vector v of the (free) equations
        a_free = a_f.reshape(-1, basis.shape[1])
        _, _, vt = jnp.linalg.svd(a_free, full_matrices=False)
        dv = jnp.einsum("crpe,pq,iq->crie", d["dj"], basis, vt)
        noise[k] = (jnp.linalg.svd(a_free, compute_uv=False),
                    jnp.sqrt(jnp.einsum("crie,cef,crif->i", dv, cov_pose, dv)), rss, expected)
    phi_all = jnp.concatenate([influence[k] for k in range(len(specs))], 1)
    cov = jnp.einsum("cie,cef,cjf->ij", phi_all, cov_pose, phi_all)
    return cov, [noise[k] for k in range(len(specs))]


def _flat(outputs):
    return jnp.concatenate([jnp.concatenate([o["centre"], o["axis"]]) for o in outputs])


@functools.partial(jax.jit, static_argnames=("specs", "index", "with_sigma"))
def _run(specs, rot, trans, mask, index, slides, priors, starts, reference, weights,
         with_sigma):
    outputs = _locate(specs, rot, trans, mask, index, slides, priors, starts)
    if not with_sigma:
        return outputs, None, None
    pose_cov = _pose_covariance(reference, rot, weights)
    cov, noise = _uncertainty(specs, rot, trans, mask, index, pose_cov, slides,
                              jax.lax.stop_gradient(outputs))
    return outputs, cov, noise


CASE_BUCKET = 16
"""Case counts are padded up to a multiple of this (padding cases are masked out), so tables
of 17 and 25 cases share one compiled program."""


def _pad(a, n):
    a = jnp.asarray(a)
    extra = n - a.shape[0]
    return a if extra == 0 else jnp.concatenate([a, jnp.repeat(a[:1], extra, axis=0)])


def _specs(joints: Sequence[GeometricJoint], parts: tuple[str, ...]):
    names = [j.name for j in joints]
    if len(set(names)) != len(names):
        raise InputError("joint names must be unique in the joint list.")
    known = set(parts) | {GROUND}
    used = []
    for j in joints:
        for p in j.parts:
            if p not in known:
                raise InputError(
                    f"joint '{j.name}' names part '{p}', which has no measured pose (measured "
                    f"parts: {', '.join(parts) or 'none'}; the fixed frame is '{GROUND}').")
            if p != GROUND and p not in used:
                used.append(p)
        if j.kind == "compliant_bushing":
            if j.link_ball not in names:
                raise InputError(f"joint '{j.name}': link_ball '{j.link_ball}' is not in the "
                                 "joint list.")
            ball = joints[names.index(j.link_ball)]
            if ball.kind != "ball" or j.parts[1] not in ball.parts:
                raise InputError(
                    f"joint '{j.name}': link_ball '{j.link_ball}' must be a 'ball' joint of "
                    f"the link '{j.parts[1]}' (S2 of the bushing).")
    part_index = {p: i for i, p in enumerate(parts)}
    specs = tuple(
        (j.name, j.kind, j.parts,
         None if j.prior_coordinate is None else "xyz".index(j.prior_coordinate),
         names.index(j.link_ball) if j.kind == "compliant_bushing" else None)
        for j in joints)
    index = {GROUND: -1, **part_index}
    return specs, tuple(sorted(index.items(), key=lambda kv: kv[0]))


def locate_joints(
    measurements,
    joints: Sequence[GeometricJoint],
    *,
    landmark_sigma: float = 0.05,
    max_sigma: float = 10.0,
    min_snr: float = 3.0,
    rcond: float = 1e-6,
    with_sigma: bool = True,
) -> GeometricReport:
    """Locate joints from the measured motion of the parts (spec geometry §4, chapter 3).

    **Arguments:**

    - `measurements`: `diffsusp.measure.Measurements` over the cases (from landmarks: the σ
      are then those of the landmark noise; from poses only: no σ). Part poses are
      displacements from design, so the located centres are design coordinates (mm).
    - `joints`: the joint list (`GeometricJoint`s).
    - `landmark_sigma`: σ_L of every landmark coordinate (mm) for the reported σ (the
      measuring arm's ±0.05 mm: spec geometry §1.6).
    - `min_snr`: a joint is not observable when the weakest singular value of its equations
      (after the revolute's axis, which is their null direction) is below `min_snr` times the
      root-mean-square value landmark noise alone gives it (‖δA v‖ for its singular vector v):
      the data do not tell that direction from noise.
    - `max_sigma`: the hardpoint tolerance (mm): a joint whose largest centre σ, inflated by
      its lack of fit (× √(χ²/E) when the equations' residual energy χ² exceeds the energy E
      landmark noise alone would leave: a bushing taken as a joint), exceeds it is not
      observable. Default 10 mm: the thesis accepts its bushing locations within 7 mm
      (Table 3.1) and calls the strut top's 50 mm and 175 mm failures (spec geometry §4.8–4.9).
    - `rcond`: without landmarks (poses only, no σ): a joint whose equations' smallest
      singular value is below `rcond` × the largest (after the revolute's axis) is not
      observable.
    - `with_sigma`: compute σ and the noise-relative verdict (closed form: `_uncertainty`).

    The number of cases is padded up to a multiple of `CASE_BUCKET` with masked cases, so that
    tables of similar size share one compiled program.

    **Returns:** a `GeometricReport`.

    **Raises:** `InputError` for a joint list naming an unknown part or a wrong link.
    """
    parts = tuple(measurements.parts)
    specs, index = _specs(joints, parts)
    slides = tuple(jnp.asarray(j.slide if j.slide is not None else (0.0, 0.0, 0.0), float)
                   for j in joints)
    priors = tuple(jnp.asarray(j.prior if j.prior is not None else (0.0, 0.0, 0.0), float)
                   for j in joints)
    starts = priors
    lookup = tuple((name, i) for name, i in index)
    n_cases = int(measurements.n_cases)
    n_pad = -(-n_cases // CASE_BUCKET) * CASE_BUCKET
    mask = jnp.concatenate([jnp.ones(n_cases), jnp.zeros(n_pad - n_cases)])
    landmarks = measurements.landmarks is not None and measurements.layout is not None
    with_sigma = bool(with_sigma) and landmarks
    if landmarks:
        reference = jnp.asarray(measurements.layout.position)
        weights = _pad(measurements.weights, n_pad)
    else:
        reference = jnp.zeros((len(parts), 1, 3))
        weights = jnp.ones((n_pad, len(parts), 1))
    outputs, cov, noise = _run(specs, _pad(measurements.rotation, n_pad),
                               _pad(measurements.translation, n_pad), mask, _IndexMap(lookup),
                               slides, priors, starts, reference, weights, with_sigma)
    cov = None if cov is None else np.asarray(cov) * landmark_sigma**2
    results = []
    for k, (j, o) in enumerate(zip(joints, outputs, strict=True)):
        centre = np.asarray(o["centre"])
        axis = np.asarray(o["axis"]) if j.kind != "ball" and j.kind != "compliant_bushing" \
            else None
        sv = np.asarray(o["sv"])
        snr, chi2 = math.nan, math.nan
        if cov is not None:
            block = cov[6 * k: 6 * k + 6, 6 * k: 6 * k + 6]
            sigma = np.sqrt(np.clip(np.diag(block)[:3], 0, None))
            sigma_axis = None if axis is None else np.sqrt(np.clip(np.diag(block)[3:], 0, None))
            worst = float(np.sqrt(max(np.linalg.eigvalsh(block[:3, :3]).max(), 0.0))) \
                if np.all(np.isfinite(block[:3, :3])) else math.inf
            free, level, rss, expected = (np.asarray(v) for v in noise[k])
            # the weakest direction the solver determines (a revolute: in the plane its prior
            # leaves free; its axis is the null direction of M, kept in `singular_values`)
            snr = float(free[-1] / max(landmark_sigma * level[-1], 1e-300))
            sv = sv if j.kind == "revolute" else free
            chi2 = float(rss / max(landmark_sigma**2 * expected, 1e-300))
            worst_fit = worst * math.sqrt(max(1.0, chi2)) if math.isfinite(chi2) else math.inf
        else:
            sigma, sigma_axis, worst = np.full(3, np.nan), None, float("nan")
            worst_fit = math.nan
        if j.kind == "revolute":
            relative = sv[1] / sv[0] if sv[0] > 0 else 0.0
        else:
            relative = sv[-1] / sv[0] if sv[0] > 0 else 0.0
        moving = float(o["motion"]) > 1e-9
        note = ""
        if not moving:
            observable, note = False, (f"parts '{j.parts[0]}' and '{j.parts[1]}' never move "
                                       "relative to each other")
        elif not np.all(np.isfinite(centre)):
            observable, note = False, "the solver found no finite centre"
        elif cov is None and not relative > rcond:
            observable, note = False, (f"singular equations (relative singular value "
                                       f"{relative:.1e})")
        elif cov is not None and not snr >= min_snr:
            observable, note = False, (
                f"the weakest singular value of the equations is {snr:.2g} × its noise level "
                f"(at landmark noise {landmark_sigma:g} mm; needs ≥ {min_snr:g})")
        elif cov is not None and not worst_fit <= max_sigma:
            observable, note = False, (
                f"σ up to {worst_fit:.3g} mm at landmark noise {landmark_sigma:g} mm"
                + (f" and lack of fit χ²/E = {chi2:.2g}" if chi2 > 1 else "")
                + f" (limit {max_sigma:g} mm)")
        else:
            observable = True
        results.append(JointEstimate(
            name=j.name, kind=j.kind, parts=tuple(j.parts),
            centre=centre if observable else None, axis=axis if observable else None,
            sigma=sigma, sigma_axis=sigma_axis, residual=float(o["rms"]), singular_values=sv,
            observable=observable, note=note, estimate=centre, snr=snr, chi2=chi2))
    return GeometricReport(tuple(results), float(landmark_sigma), int(measurements.n_cases),
                           tuple(measurements.notes))


class _IndexMap(tuple):
    """Part name → pose index (−1 for ground), hashable for jit's static arguments."""

    def __getitem__(self, key):
        if isinstance(key, str):
            return dict(tuple.__iter__(self))[key]
        return tuple.__getitem__(self, key)



# ------------------------------------------------------------------- chapter 2: correction


@dataclasses.dataclass(frozen=True)
class CorrectionReport:
    """Result of `correct_geometry`.

    **Fields:** `pose_errors`: per equilibrium solved, the largest distance (mm) between a
    marker or landmark of a measured part at the model's equilibrium and at the measured pose
    (the first is the uncorrected model's, the last the final one's); `converged` (the last is
    below `tol`); `moves`: marker name → total displacement of its design position (mm);
    `elements`: the joints and bushings whose I (or J) marker was moved; `case_errors`: the
    final model's pose error at every measured case (mm: how it does away from the reference
    case); `notes`.
    """

    pose_errors: tuple[float, ...]
    converged: bool
    moves: dict
    elements: tuple[str, ...]
    case_errors: tuple[float, ...] = ()
    notes: tuple[str, ...] = ()

    @property
    def iterations(self) -> int:
        return len(self.pose_errors) - 1

    def __str__(self) -> str:
        lines = [f"Geometric correction: {self.iterations} correction(s), pose error "
                 + " → ".join(f"{e:.2e}" for e in self.pose_errors) + " mm"
                 + ("" if self.converged else " (NOT converged)")]
        for name, move in self.moves.items():
            lines.append(f"  {name:<28} moved {move:8.4f} mm")
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


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
                         "correct one element per marker (pass elements=...).")
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
    *,
    case: int = 0,
    loads=None,
    elements: Sequence[str] | None = None,
    side: str | dict = "i",
    tol: float = 1e-4,
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
    - `elements`: joints and bushings to correct (default: all); `side`: which marker moves,
      `'i'` (the Adams I marker: the inner sleeve, bolted, in the thesis's convention) or
      `'j'`, or a dict name → side.
    - `tol` (mm), `max_iterations`; `**solve_options` for `solve_statics`.

    **Returns:** `(corrected mechanism, CorrectionReport)`.
    """
    import equinox as eqx

    from ..statics import marker_poses, part_poses, solve_statics

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
    pairs = _element_markers(mech, elements, side)
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
    errors, q0, current = [], None, mech
    for _ in range(max_iterations + 1):
        # every measured case at once (one batched solve); the reference case drives the
        # correction, the others show how the corrected model does elsewhere
        sol = solve_statics(current, table_loads, q0=q0, **solve_options)
        q_all = np.asarray(sol.q)
        rot_eq_all, trans_eq_all = (np.asarray(a) for a in part_poses(current, q_all))
        case_errors = pose_errors(rot_eq_all, trans_eq_all)
        errors.append(float(case_errors[case]))
        if errors[-1] < tol or len(errors) > max_iterations:
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
    notes = ()
    if errors[-1] >= tol:
        notes = (f"not converged: pose error {errors[-1]:.3g} mm after {len(errors) - 1} "
                 f"corrections (tol {tol:g} mm)",)
    return current, CorrectionReport(tuple(errors), errors[-1] < tol, moves,
                                     tuple(n for n, _ in pairs), tuple(case_errors), notes)


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

    from ..statics import bushing_states, marker_poses, part_poses

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


def element_table(mech):
    """name → (group, kind, I part, J part, I marker, J marker) of every joint and bushing."""
    part_of = mech.markers.part
    out = {}
    for name, kind, i, j in zip(mech.joints.names, mech.joints.kind, mech.joints.i_marker,
                                mech.joints.j_marker, strict=True):
        out[name] = ("joint", kind, part_of[i], part_of[j], i, j)
    for name, i, j in zip(mech.bushings.names, mech.bushings.i_marker, mech.bushings.j_marker,
                          strict=True):
        out[name] = ("bushing", "bushing", part_of[i], part_of[j], i, j)
    return out


def joints_from_model(mech, parts: Sequence[str], *, compliant: Sequence[str] = ()
                      ) -> tuple[tuple[GeometricJoint, ...], tuple[str, ...]]:
    """The joint list a model implies for the measured `parts` (spec geometry §4.6): which
    solver locates which element, with the model's hardpoints as priors.

    - spherical and universal joints, and bushings, between two measured parts (or one and the
      ground): `'ball'` (a bushing named in `compliant`, on a link whose other end is a ball
      joint: `'compliant_bushing'`);
    - revolute and cylindrical joints: `'revolute'` (the prior keeps the model's point along
      the axis);
    - a ball joint (spherical/universal) between a measured part and an unmeasured part that
      slides on the ground (translational joint: a steering rack): `'ball_known_slide'` along
      the slide axis;
    - a bushing or ball joint between the ground and an unmeasured part that slides on a
      measured part (translational or cylindrical joint: the McPherson strut):
      `'ball_unknown_slide'` from the model's position.

    **Returns:** `(joints, notes)`: the list, and one sentence per element left out.
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
            if name in compliant:
                joints.append(("compliant", name, pi, pj, at))
            else:
                joints.append(GeometricJoint(name, "ball", (name_of[pi], name_of[pj]),
                                             elements=(name,)))
                if kind != "bushing":
                    balls[name] = (pi, pj)
        elif kind in ("revolute", "cylindrical") and known(pi) and known(pj):
            joints.append(GeometricJoint(name, "revolute", (name_of[pi], name_of[pj]),
                                         prior=at, elements=(name,)))
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


def apply_locations(mech, report: GeometricReport, joints: Sequence[GeometricJoint]):
    """The model with the located joints: the I and J markers of every element a located,
    observable joint stands for are moved to its centre (design coordinates); a revolute
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
        if not est.observable:
            continue
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
    from .params import Params

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
    r_c (`_case_residual`) hold case by case; so is a stiffness identification in the
    stiffnesses, and `design_experiment` chooses cases from any per-case measurement model.
    Here the measurement model of a case is the whitened geometric equations of every joint at
    the model's equilibrium, W_c r_c(x) with x the model's joint hardpoints (the parameters),
    the poses held at the equilibrium (its derivative with respect to the hardpoints is not
    the localisation's: the equations use the measured poses) and W_c = (D_c Σ_c D_cᵀ)^(−1/2)
    from the poses' landmark noise (`_pose_covariance`, D_c = ∂r_c/∂poses), joint by joint
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
    from ..statics import part_poses
    from .sensitivity import design_experiment

    table = element_table(mech)
    parts = tuple(layout.parts)
    _specs(joints, parts)  # unknown parts, links
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
        pose_cov = _pose_covariance(reference, rot_m[None], present[None])[0]
        eye = jnp.eye(3, dtype=rot.dtype)
        pos, ori = m.markers.position, m.markers.orientation

        def residuals(eps):
            def pose(p):
                i = part_index[p]
                if i < 0:
                    return eye, jnp.zeros(3, rot.dtype)
                k = slot[i]
                return (eye + _skew(eps[k, :3])) @ rot_m[k], trans_m[k] + eps[k, 3:]

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
                out.append(_case_residual(kind, x, r, t, extra))
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
    for step in range(len(report.chosen)):
        sig = {j.name: float(np.max(report.sigma[step][cols]))
               for j, cols in zip(joints, per_joint, strict=True)}
        history.append(max(sig.values()))
        sigma, observable = sig, {k: bool(v <= max_sigma) for k, v in sig.items()}
        if all(observable.values()):
            stop = step + 1
            break
    return GeometryDesign(tuple(report.chosen[:stop]), sigma, observable, tuple(history),
                          all(observable.values()), report)
