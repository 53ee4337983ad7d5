"""Joint location from the measured relative motion of parts: the five solvers of the thesis's
chapter 3, their σ and observability verdicts, and `locate_joints` (spec geometry §4; the method
is described in `diffsusp.identify.geometric`'s docstring).

**Size.** About 600 lines: the solvers, the closed-form pose covariance and the case-by-case
influence matrices are one computation compiled as one program; they are read together with
the thesis's chapter 3.
"""

import functools
import math
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import InputError
from ..statics import Status, part_poses, solve_statics
from .geometric_joints import (
    GROUND,
    Coordinate,
    GeometricJoint,
    GeometricReport,
    JointEstimate,
    model_geometry,
)
from .report import CONSISTENCY_ALPHA, Consistency, chi2_quantile

__all__ = ["START_OFFSETS", "joint_values", "locate_joints", "registration_check",
           "relative_operators"]  # re-exported by `identify.geometric`

START_OFFSETS = 150.0
"""Half-width (mm) of the 3×3×3 grid of starts around the initial estimate of a
`'ball_unknown_slide'` joint (the thesis's Nelder–Mead had local minima: §4.4b, §4.10)."""
LM_STEPS = 60


# ----------------------------------------------------------------------------- solvers


def relative_operators(r1, t1, r2, t2):
    """Relative operators of S2 with respect to S1 over the cases (3.6, 3.9):
    R^c = R1ᵀ R2, T^c = R1ᵀ (T2 − T1). Shapes (c, 3, 3), (c, 3)."""
    r = jnp.einsum("cji,cjk->cik", r1, r2)
    t = jnp.einsum("cji,cj->ci", r1, t2 - t1)
    return r, t


LACK_OF_FIT = 2.0
"""χ²/E above which a located ball's or revolute's equations do not fit the landmark noise (a
model error: a bushing soft about its axis, a joint of another kind). Its σ is then not
inflated by √(χ²/E) as for noise, but by √(3χ²/E): a systematic misfit does not average out
over the equations, and its share in the three directions of the centre can lie along the
weakest one — the direction the relative motion hardly sees (on the Chrono strut's arm
bushing taken as a ball, ≈ 21 mm off along the pivot axis with σ·√(χ²/E) ≈ 8 mm: reported
observable before). The reported σ of the centre and of a revolute's axis carry the same
factor (the compliance bias: the Chrono double wishbone's torsion-free arm bushing located as
a revolute is 9 mrad and 0.8 mm off its axis line under ±2000 N lateral cases, about 12 × the
noise σ). A ball's reported σ stays the noise σ: there the factor does not cover the bias (the
pseudo-McPherson's stiff bushing A, χ²/E = 2.4, is 3.9 mm off with σ·√(3χ²/E) = 0.59 mm)."""


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
                      motion=motion, peak=jnp.max(jnp.linalg.norm(res.reshape(-1, 3), axis=1)))
    return [out[k] for k in range(len(specs))]


def skew(v):
    z = jnp.zeros_like(v[..., 0])
    return jnp.stack([jnp.stack([z, -v[..., 2], v[..., 1]], -1),
                      jnp.stack([v[..., 2], z, -v[..., 0]], -1),
                      jnp.stack([-v[..., 1], v[..., 0], z], -1)], -2)


def pose_covariance(reference, rotation, weights):
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
    g = jnp.concatenate([-skew(a), eye], -1)  # (c, p, k, 3, 6)
    info = jnp.einsum("cpk,cpkai,cpkaj->cpij", w, g, g)
    info2 = jnp.einsum("cpk,cpkai,cpkaj->cpij", w**2, g, g)
    inv = jnp.linalg.inv(info)
    return inv @ info2 @ inv


def case_residual(kind, x, r, t, extra):
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
    (`case_residual`), which depend on the noisy poses of that case only. The implicit-function
    theorem gives δx = −H⁻¹ Σ_c B_c ε_c with H = Σ_c ∂²(½‖r_c‖²)/∂x², B_c = ∂²(½‖r_c‖²)/∂x∂ε_c
    and ε_c the pose perturbations of case c, whose covariance is `pose_covariance`; a compliant
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
            return (eye + skew(eps[i, :3])) @ rot_c[i], trans_c[i] + eps[i, 3:]

        eps0 = jnp.zeros((n_parts, 6), rot.dtype)
        out = {}
        for k in order:
            _, kind, (p1, p2), _, _ = specs[k]

            def residual(x, eps, extra, kind=kind, p1=p1, p2=p2):
                (r1, t1), (r2, t2) = poses(eps, p1), poses(eps, p2)
                return case_residual(kind, x, r1.T @ r2, r1.T @ (t2 - t1), extra)

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
    pose_cov = pose_covariance(reference, rot, weights)
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


def joint_specs(joints: Sequence[GeometricJoint], parts: tuple[str, ...]):
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
    model=None,
    loads=None,
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
      landmark noise alone would leave: a bushing taken as a joint; × √(3χ²/E) for a `ball`
      whose χ²/E exceeds `LACK_OF_FIT`: a model error, which does not average out), exceeds
      it is not observable. Default 10 mm: the thesis accepts its bushing locations within 7 mm
      (Table 3.1) and calls the strut top's 50 mm and 175 mm failures (spec geometry §4.8–4.9).
    - `rcond`: without landmarks (poses only, no σ): a joint whose equations' smallest
      singular value is below `rcond` × the largest (after the revolute's axis) is not
      observable.
    - `with_sigma`: compute σ and the noise-relative verdict (closed form: `_uncertainty`).
    - `model` (optional, with `loads`, default the measurements' loads): the model whose
      joints are located. Its own equilibria at the measured cases, located the same way,
      give each coordinate's **compliance bias** (located − the model's hardpoint: a bushing
      taken as a ball or a revolute deflects, and the located point is biased by it — the
      pseudo-McPherson's bushing A by 3.9 mm with a noise σ of 0.06 mm); it is added to σ in
      quadrature. Without the model, a ball whose equations do not fit (χ²/E >
      `LACK_OF_FIT`) is reported not determined ("compliant: …").

    The number of cases is padded up to a multiple of `CASE_BUCKET` with masked cases, so that
    tables of similar size share one compiled program.

    **Report:** one row per located coordinate (`Coordinate`: the centre's x, y, z;
    a revolute's two coordinates across its axis where the line crosses the plane of the
    prior's coordinate along it, that coordinate itself "not determined: position along the
    axis not observable", and its axis' two smaller components; an unknown slide's axis
    likewise), with σ and one status; the consistency verdict is the registration's (every
    part and case against σ_L: `registration_check`): a part whose landmarks were swapped or
    moved in some case is named in a warning and the verdict is inconsistent, so that no
    coordinate is then "identified".

    **Returns:** a `GeometricReport`.

    **Raises:** `InputError` for a joint list naming an unknown part or a wrong link, or a
    `model` without a measured part.
    """
    parts = tuple(measurements.parts)
    specs, index = joint_specs(joints, parts)
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

    def run(rotation, translation):
        return _run(specs, _pad(rotation, n_pad), _pad(translation, n_pad), mask,
                    _IndexMap(lookup), slides, priors, starts, reference, weights, with_sigma)

    outputs, cov, noise = run(measurements.rotation, measurements.translation)
    cov = None if cov is None else np.asarray(cov) * landmark_sigma**2
    notes = list(measurements.notes)
    nominal = None
    if model is not None:
        nominal, note = _model_located(model, measurements, joints, loads, run)
        notes += [note] if note else []
    results = []
    for k, (j, o) in enumerate(zip(joints, outputs, strict=True)):
        centre = np.asarray(o["centre"])
        axis = np.asarray(o["axis"]) if j.kind != "ball" and j.kind != "compliant_bushing" \
            else None
        sv = np.asarray(o["sv"])
        snr, chi2 = math.nan, math.nan
        block = None
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
            if j.kind in ("ball", "revolute") and chi2 > LACK_OF_FIT:
                # the misfit is a model error (a compliant bushing taken as a ball or a
                # revolute), not noise: it does not average out over the equations as noise
                # does; counted in full (the in-range share of a misfit of χ²·E: √(3χ²) times
                # the noise σ); a revolute's reported σ of centre and axis carry it too
                inflate = math.sqrt(3.0 * chi2)
                worst_fit = worst * inflate
                if j.kind == "revolute":
                    sigma = sigma * inflate
                    sigma_axis = None if sigma_axis is None else sigma_axis * inflate
                    block = block * inflate**2
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
                + f" (limit {max_sigma:g} mm)"
                + ("; a ball whose equations do not fit: a joint of another kind (a bushing "
                   "soft about its axis is a revolute)" if j.kind == "ball"
                   and chi2 > LACK_OF_FIT else ""))
        else:
            observable = True
        if observable and j.kind == "revolute":
            # motion fixes the axis line only: the point along it is the prior's (spec geometry
            # §4.3); its σ are those of the line's point at that position
            note = ("position along the axis not observable (kept at the prior's "
                    + (f"{j.prior_coordinate}" if j.prior_coordinate else "nearest point")
                    + ")")
        raw_axis = np.asarray(o["axis"])
        coords = _coordinates(
            j, centre, raw_axis, block, observable=observable, moving=moving, note=note,
            chi2=chi2, peak=float(o["peak"]), max_sigma=max_sigma,
            nominal=None if nominal is None else nominal[k])
        results.append(JointEstimate(
            name=j.name, kind=j.kind, parts=tuple(j.parts),
            centre=centre if observable else None, axis=axis if observable else None,
            sigma=sigma, sigma_axis=sigma_axis, residual=float(o["rms"]), singular_values=sv,
            observable=observable, note=note, estimate=centre, snr=snr, chi2=chi2,
            coordinates=coords, peak=float(o["peak"]), covariance=block))
    consistency, warnings = (registration_check(measurements, landmark_sigma) if landmarks
                             else (None, ()))
    return GeometricReport(tuple(results), float(landmark_sigma), int(measurements.n_cases),
                           tuple(notes), consistency, tuple(warnings))


def _dominant(kind: str, axis, prior_coordinate: str | None) -> int:
    """The coordinate a revolute's line is cut at (its prior's coordinate, else the axis'
    largest component), and the axis component left out (the norm fixes it)."""
    if kind == "revolute" and prior_coordinate is not None:
        return "xyz".index(prior_coordinate)
    return int(np.argmax(np.abs(np.asarray(axis, float))))


def joint_values(kind: str, centre, axis, prior, d: int):
    """The reported coordinates of a located joint (names, values, Jacobian (k, 6) with respect
    to (centre, axis), units, along-the-axis flags):

    - a point: x, y, z of the centre;
    - `'revolute'`: where its line (through `centre` along `axis`) crosses the plane of the
      prior's coordinate `d`, the two other coordinates; coordinate `d` itself (the prior's:
      along the axis); then the axis components but the `d`-th (the axis signed so that
      component `d` is positive);
    - `'ball_unknown_slide'`: x, y, z and the slide axis' components but the `d`-th.
    """
    c = np.asarray(centre, float)
    names, values, jac, units, along = [], [], [], [], []
    eye = np.eye(3)
    if kind in ("revolute", "ball_unknown_slide"):
        a = np.asarray(axis, float)
        a = a / np.linalg.norm(a) * (1.0 if a[d] >= 0 else -1.0)
    if kind == "revolute":
        s = float(np.asarray(prior, float)[d])
        t = (s - c[d]) / a[d]
        point = c + a * t
        d_c = eye - np.outer(a, eye[d]) / a[d]
        d_a = t * (eye - np.outer(a, eye[d]) / a[d])
        for i in range(3):
            names.append("xyz"[i])
            values.append(float(point[i]))
            jac.append(np.concatenate([d_c[i], d_a[i]]) if i != d else np.zeros(6))
            units.append("mm")
            along.append(i == d)
    else:
        for i in range(3):
            names.append("xyz"[i])
            values.append(float(c[i]))
            jac.append(np.concatenate([eye[i], np.zeros(3)]))
            units.append("mm")
            along.append(False)
    if kind in ("revolute", "ball_unknown_slide"):
        for i in range(3):
            if i != d:
                names.append(f"axis_{'xyz'[i]}")
                values.append(float(a[i]))
                jac.append(np.concatenate([np.zeros(3), eye[i]]))
                units.append("-")
                along.append(False)
    return names, np.array(values), np.array(jac), units, along


def _coordinates(j: GeometricJoint, centre, axis, block, *, observable, moving, note, chi2,
                 peak, max_sigma, nominal):
    """The `Coordinate` rows of one located joint (see `locate_joints`)."""
    axis = np.asarray(axis, float)
    if not (np.all(np.isfinite(axis)) and np.linalg.norm(axis) > 0):
        axis = np.array([1.0, 0.0, 0.0])  # no axis found (parts that do not move)
    d = _dominant(j.kind, axis, j.prior_coordinate)
    prior = j.prior if j.prior is not None else centre
    names, values, jac, units, along = joint_values(j.kind, centre, axis, prior, d)
    if block is not None and np.all(np.isfinite(block)):
        sigma = np.sqrt(np.clip(np.einsum("ri,ij,rj->r", jac, block, jac), 0.0, None))
        if j.kind != "revolute" or not chi2 > LACK_OF_FIT:
            # equations that fit worse than the noise explains (χ²/E > 1, the Birge ratio):
            # the reported σ scaled by √(χ²/E), never below the noise σ (a revolute's misfit
            # beyond LACK_OF_FIT is already in its block); the rehearsal of the pseudo-McPherson
            # found the noise σ alone 5-9 % short on a ball joint (4 of 199 truths at 3.1-3.7σ)
            sigma = sigma * math.sqrt(max(1.0, chi2)) if math.isfinite(chi2) else sigma
    else:
        sigma = np.full(len(names), np.nan)
    bias = np.zeros(len(names))
    if nominal is not None and moving:
        located, truth = nominal
        if located is not None and truth is not None:
            bias = (joint_values(j.kind, *located, prior, d)[1]
                    - joint_values(j.kind, *truth, prior, d)[1])
            bias = np.where(np.isfinite(bias), bias, np.inf)
    carried = nominal is not None and moving and nominal[0] is not None \
        and nominal[1] is not None
    misfit = (j.kind == "ball" and not carried and math.isfinite(chi2) and chi2 > LACK_OF_FIT)
    out = []
    for k, name in enumerate(names):
        sig = float(np.hypot(sigma[k], bias[k])) if not along[k] else math.nan
        reason, ok = "", True
        if not moving:
            ok, reason = False, note
        elif not observable:
            ok, reason = False, f"not observable: {note}"
        elif along[k]:
            ok, reason = False, (f"position along the axis not observable (the prior's "
                                 f"{'xyz'[d]} kept)")
        elif misfit:
            ok, reason = False, (
                f"compliant: its centre moves up to {peak:.2g} mm across the cases (lack of "
                f"fit χ²/E = {chi2:.2g}), a bias the noise σ does not cover; give the model "
                "to carry its compliance in σ")
        elif units[k] == "mm" and not sig <= max_sigma:
            ok, reason = False, (f"σ {sig:.3g} mm with the model's compliance bias is beyond "
                                 f"the hardpoint tolerance {max_sigma:g} mm")
        out.append(Coordinate(name=name, value=float(values[k]),
                              sigma=float(sig) if not along[k] else math.nan,
                              unit=units[k], determined=ok, seen=moving, reason=reason,
                              bias=float(bias[k]), along_axis=along[k]))
    return tuple(out)


def _model_located(model, measurements, joints, loads, run):
    """Per joint (located, truth): the model's own equilibria at the measured cases located as
    the measurements are (same compiled program), and the model's hardpoint and axis
    (`model_geometry`); None where the model has no element for it. Returns the
    list and a note (or "")."""
    loads = measurements.loads if loads is None else loads
    missing = [p for p in measurements.parts if p not in model.parts]
    if missing:
        raise InputError(f"measured part(s) {', '.join(missing)} are not parts of model "
                         f"'{model.name}': its compliance bias cannot be computed.")
    sol = solve_statics(model, loads, throw=False)
    bad = np.asarray(sol.status) != Status.CONVERGED
    if bad.any():
        return None, (f"the model has no equilibrium in {int(bad.sum())} measured case(s): "
                      "its compliance bias is not carried in σ")
    rot, trans = part_poses(model, sol.q)
    index = np.asarray([model.part_index(p) for p in measurements.parts], dtype=int)
    outputs, _, _ = run(np.asarray(rot)[:, index], np.asarray(trans)[:, index])
    out = []
    for j, o in zip(joints, outputs, strict=True):
        truth = model_geometry(model, j)
        located = (np.asarray(o["centre"]), np.asarray(o["axis"]))
        moving = float(o["motion"]) > 1e-9  # the model's parts move: a bias to speak of
        out.append((located if moving and np.all(np.isfinite(located[0])) else None, truth))
    return out, ("σ carry the compliance bias of the model's own equilibria at the measured "
                 "cases (located − hardpoint)")


def registration_check(measurements, landmark_sigma: float):
    """The registration residuals of every part and case against the landmark σ:
    χ² = Σ ‖R P + T − Q‖² / σ_L² over the landmarks used, 3n − 6 dof per
    part and case. A part and case beyond the upper `CONSISTENCY_ALPHA`/(parts × cases)
    quantile (swapped or moved landmarks) is named in a warning and makes the verdict
    inconsistent; so does the total χ² beyond its quantile. Returns `(Consistency, warnings)`.
    """
    ref = np.asarray(measurements.layout.position, float)
    lm = np.asarray(measurements.landmarks, float)
    w = np.asarray(measurements.weights, float) > 0
    rot = np.asarray(measurements.rotation, float)
    trans = np.asarray(measurements.translation, float)
    res = np.einsum("cpij,pkj->cpki", rot, ref) + trans[:, :, None] - lm
    sq = np.where(w, np.sum(res**2, axis=-1), 0.0) / landmark_sigma**2  # (c, p, k)
    chi2_pc = sq.sum(-1)
    used = w.sum(-1)
    dof_pc = np.maximum(3 * used - 6, 1)
    n_pc = int(np.count_nonzero(used))
    cases = tuple(measurements.cases) or tuple(str(c + 1) for c in range(lm.shape[0]))
    warnings = []
    flagged = np.zeros(chi2_pc.shape, bool)
    for p, part in enumerate(measurements.parts):
        bad = [c for c in range(lm.shape[0]) if used[c, p] and chi2_pc[c, p] > chi2_quantile(
            int(dof_pc[c, p]), CONSISTENCY_ALPHA / max(n_pc, 1))]
        if not bad:
            continue
        flagged[bad, p] = True
        rms = np.sqrt(chi2_pc[bad, p] / (3 * used[bad, p])) * landmark_sigma
        warnings.append(
            f"part '{part}': registration residual RMS up to {rms.max():.3g} mm "
            f"({rms.max() / landmark_sigma:.3g} σ) in case(s) "
            f"{', '.join(cases[c] for c in bad)}: landmarks swapped or moved on this part? "
            "Check its landmarks in those cases (or read the table with --reorder, which "
            "matches them by their distances)")
    n_res = int(3 * used.sum())
    n_par = 6 * n_pc
    dof = max(n_res - n_par, 1)
    chi2 = float(chi2_pc.sum())
    critical = chi2_quantile(dof)
    with np.errstate(invalid="ignore", divide="ignore"):
        case_rms = np.sqrt(chi2_pc.sum(-1) / np.maximum(3 * used.sum(-1), 1))
    consistency = Consistency(
        chi2=chi2, n_residuals=n_res, n_parameters=n_par, dof=dof, critical=critical,
        case_rms=case_rms, cases=cases, failed_cases=(),
        consistent=bool(chi2 <= critical and not flagged.any()), measurements=("landmarks",),
        note="registration residuals of every part and case against the landmark σ; each "
             "joint's own lack of fit is judged joint by joint")
    return consistency, tuple(warnings)


class _IndexMap(tuple):
    """Part name → pose index (−1 for ground), hashable for jit's static arguments."""

    def __getitem__(self, key):
        if isinstance(key, str):
            return dict(tuple.__iter__(self))[key]
        return tuple.__getitem__(self, key)
