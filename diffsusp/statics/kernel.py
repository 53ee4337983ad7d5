"""Element kernels and assembly of the equilibrium (KKT) residual and Jacobian, for one load case.

Unknowns: 6 per moving part — the position P (mm) of the part's reference point (the centroid of
its markers at design, so that rotations about nearby joints stay mildly nonlinear for Newton)
and the Gibbs vector b of its rotation from design (spec stiffness §1.3) — and one multiplier per
independent constraint row. The public coordinates q = (p, b) of DESIGN.md (p = displacement of
the point at the global origin) follow as p = P − R(b)·c.

Every element touches at most two parts and is written as a function of their poses (P, R): it
returns the wrench it applies to each part — force F (N) and moment M (N·mm) about the part's
reference point P — and, for a joint or a driver, its constraint rows Φ (Adams definitions,
spec stiffness §1.6) with the reaction wrench Φ_δᵀλ written out in closed form (a joint row is a
difference of points or a dot product of axes, so its reaction is a force at a marker or a pure
torque). Summed per part this is the *wrench residual* (spec stiffness §1.5, §1.9)

    w = Σ (F, M)_elements + Σ (F, M)_reactions          (one force and one moment row per part)
    r_λ = Φ(q) − c                                       (joint rows and motion drivers)

differentiated in *twist* coordinates δ = (δP, ω) of each part (P ← P + δP, R ← exp(ω×)·R) by
forward mode over the element's 12 directions: this is the Jacobian Newton uses (`statics.solve`
steps along twists, `retract`). The generalised forces of the Gibbs coordinates are
Q = (F, G(b)ᵀM), G(b) = 2/(1 + b·b)(I + b×) (spec §1.4): `assemble` returns that residual and its
exact Jacobian (the congruence of the twist one plus the derivative of G(b)ᵀ), for
`linearize`, `identify` and `validate`. The ground is a virtual part at rest (P = 0, R = I); its
rows and columns are dropped.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ..geometry import gibbs_angular_jacobian, gibbs_to_matrix, projected_angles
from ..geometry.rotations import NEG_LEVI_CIVITA
from ..model.laws import akima_eval
from ..model.mechanism import Loads, Mechanism

# Small vector algebra as element-wise products and sums: XLA fuses them across the element and
# case axes, where a batched 3×3 `dot_general` runs one tiny matrix product at a time on CPU
# (10–30× slower here).


def _mv(a, x):
    """a @ x for a (3, k), x (k,)."""
    return jnp.sum(a * x, axis=-1)


def _mtv(a, x):
    """aᵀ @ x for a (k, 3), x (k,)."""
    return jnp.sum(a * x[:, None], axis=0)


def _mm(a, b):
    """a @ b for 3×3 matrices."""
    return jnp.sum(a[:, :, None] * b[None, :, :], axis=1)


def _dot(a, b):
    return jnp.sum(a * b, axis=-1)


def skew(v):
    """Cross-product matrix of a 3-vector, `skew(u) @ v = u × v`."""
    return jnp.sum(jnp.asarray(NEG_LEVI_CIVITA, v.dtype) * v, axis=-1)


_I1, _I2 = np.array([1, 2, 0]), np.array([2, 0, 1])


def cross(a, b):
    return a[_I1] * b[_I2] - a[_I2] * b[_I1]


def _rotation(b):
    """Rotation matrix of a Gibbs vector (`geometry.gibbs_to_matrix`, element-wise)."""
    bb = _dot(b, b)
    eye = jnp.eye(3, dtype=b.dtype)
    return ((1.0 - bb) * eye + 2.0 * b[:, None] * b[None, :] + 2.0 * skew(b)) / (1.0 + bb)


def _at(p, r, x0, r0):
    """World position and axes of a marker with offset x0 from its part's reference point and
    design axes r0, on a part at pose (p, r)."""
    return p + _mv(r, x0), _mm(r, r0)


def _z_poses(z):
    """Poses (P, R) of the parts in Gibbs coordinates z (6 or 12)."""
    return [v for k in range(0, z.shape[0], 6) for v in (z[k : k + 3], _rotation(z[k + 3 : k + 6]))]


def to_generalised(z, wrench):
    """Wrenches (F, M about P) of the parts at Gibbs coordinates z → generalised forces
    (F, G(b)ᵀ M) (spec stiffness §1.4)."""
    out = []
    for k in range(0, z.shape[0], 6):
        g = gibbs_angular_jacobian(z[k + 3 : k + 6])
        out += [wrench[k : k + 3], g.T @ wrench[k + 3 : k + 6]]
    return jnp.concatenate(out)


# ----------------------------------------------------------------------------- force elements


def bushing_deformation(xi, ai, xj, aj, p, spline_mask):
    """Deformation and law of one bushing from its markers' world poses (Adams convention,
    spec stiffness §1.8): (δ_T in J (mm), projected angles (rad), force f and torque t on I in J
    axes)."""
    delta_t = _mtv(aj, xi - xj)
    delta_r = projected_angles(_mm(aj.T, ai))
    e_t = delta_t - p["offset_trans"]
    e_r = delta_r - p["offset_rot"]
    f = -(p["k_trans"] * e_t + p["cubic_trans"] * e_t**3) + p["preload_force"]
    t = -(p["k_rot"] * e_r + p["cubic_rot"] * e_r**3) + p["preload_torque"]
    if spline_mask is not None:
        e = jnp.concatenate([e_t, e_r])
        spline = jax.vmap(akima_eval)(p["spline_x"], p["spline_y"], e)
        ft = jnp.where(spline_mask, spline, jnp.concatenate([f, t]))
        f, t = ft[:3], ft[3:]
    return delta_t, delta_r, f, t


def bushing_wrench(pi, ri, pj, rj, x0i, r0i, x0j, r0j, p, spline_mask):
    """Wrenches (12,) of one bushing on its I part then its J part (moments about each part's
    reference point). `x0i`, `x0j` are the markers' offsets from their parts' reference points."""
    xi, ai = _at(pi, ri, x0i, r0i)
    xj, aj = _at(pj, rj, x0j, r0j)
    _, _, f, t = bushing_deformation(xi, ai, xj, aj, p, spline_mask)
    force, torque = _mv(aj, f), _mv(aj, t)
    return jnp.concatenate([force, torque + cross(xi - pi, force),
                            -force, -torque - cross(xi - pj, force)])


def bushing_state(z, x0i, r0i, x0j, r0j, p, spline_mask):
    """`bushing_deformation` at the Gibbs coordinates z of the bushing's two parts."""
    pi, ri, pj, rj = _z_poses(z)
    xi, ai = _at(pi, ri, x0i, r0i)
    xj, aj = _at(pj, rj, x0j, r0j)
    return bushing_deformation(xi, ai, xj, aj, p, spline_mask)


def bushing_force(z, x0i, r0i, x0j, r0j, p, spline_mask):
    """Generalised forces (12,) of one bushing on its I part then J part, Gibbs coordinates z."""
    return to_generalised(z, bushing_wrench(*_z_poses(z), x0i, r0i, x0j, r0j, p, spline_mask))


def line_wrench(pi, ri, pj, rj, x0i, x0j, tension):
    """Wrenches of a tension `tension(ℓ)` along the line of two points (positive pulls I
    toward J)."""
    xi = pi + _mv(ri, x0i)
    xj = pj + _mv(rj, x0j)
    u = xj - xi
    length = jnp.sqrt(_dot(u, u))
    f = tension(length) * u / length
    return jnp.concatenate([f, cross(xi - pi, f), -f, -cross(xj - pj, f)])


def line_force(z, x0i, x0j, tension):
    """Generalised forces of `line_wrench` at the Gibbs coordinates z of its two parts."""
    return to_generalised(z, line_wrench(*_z_poses(z), x0i, x0j, tension))


def spring_tension(length, p, tabulated: bool):
    """Spring tension (N, positive pulls the seats together) at `length` (mm)."""
    if tabulated:
        return akima_eval(p["table_x"], p["table_y"], length - p["free_length"])
    return p["k"] * (length - p["free_length"])


def stop_tension(length, p, kind: str):
    """One-sided stop tension (N): negative (pushing apart) for an engaged bump stop."""
    pen = jnp.maximum(p["length"] - length if kind == "bump" else length - p["length"], 0.0)
    force = p["k"] * pen + p["cubic"] * pen**3
    return -force if kind == "bump" else force


def load_wrench(pi, ri, pf, rf, x0m, r0f, force, moment):
    """Wrench of a load at marker m (offset x0m on part I) whose components are given in the
    axes r0f of a marker on the frame part F (the ground, with identity axes, for global
    components); nothing acts on F."""
    xm = pi + _mv(ri, x0m)
    axes = _mm(rf, r0f)
    f = _mv(axes, force)
    return jnp.concatenate([f, _mv(axes, moment) + cross(xm - pi, f), jnp.zeros(6, f.dtype)])


_E_Z = np.array([0.0, 0.0, 1.0])


def contact_load_wrench(pi, ri, pf, rf, x0m, r0f, spin0, force, moment, radius):
    """`load_wrench` with the force at the ground contact point of a wheel of `radius` about
    marker m (`Loads.contact_radius`): C = x_m − R·u, u = unit(e_z − (e_z·s)s) with s = R_I·s0
    the marker's current z axis (the spin axis). The point moves with the wheel plane, so the
    twist Jacobian carries the load's geometric stiffness; R = 0 is `load_wrench`."""
    s = _mv(ri, spin0)
    v = _E_Z - s[2] * s
    vv = _dot(v, v)
    xm = pi + _mv(ri, x0m) - (radius * jax.lax.rsqrt(jnp.where(vv > 0.0, vv, 1.0))) * v
    axes = _mm(rf, r0f)
    f = _mv(axes, force)
    return jnp.concatenate([f, _mv(axes, moment) + cross(xm - pi, f), jnp.zeros(6, f.dtype)])


# ----------------------------------------------------------------------------- constraints


def _safe_norm(d):
    """|d| along the last axis, with zero (not NaN) derivatives at d = 0 (a spherical joint's
    design distance)."""
    dd = jnp.sum(d * d, axis=-1)
    positive = dd > 0.0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, dd, 1.0)), 0.0)


def joint_rows(pi, ri, pj, rj, lam, x0i, r0i, x0j, r0j, length0, select):
    """Constraint rows Φ (r,) of one joint of any kind and their reaction Φ_δᵀλ (12,).

    `select` (r, 12) picks the rows (one-hot) among the candidate quantities of
    `diffsusp.model.topology.JOINT_CANDIDATES`: d = x_I − x_J (global), its components on the J
    axes, dot products of I and J axes, |d| minus its design value `length0` (spec stiffness
    §1.6). Their reactions, for candidate multipliers μ = selectᵀλ: a force μ_d + μ_ℓ·d/|d|
    at x_I on I and opposite at x_J on J; a force Σμ_k·(J axis k) at x_I, on I and opposite on
    J; a torque μ·(a × b) on I and opposite on J for each dot product a_I·b_J.
    """
    xi, ai = _at(pi, ri, x0i, r0i)
    xj, aj = _at(pj, rj, x0j, r0j)
    d = xi - xj
    dist = _safe_norm(d)
    zi = ai[:, 2]
    cand = jnp.concatenate([
        d, _mtv(aj, d), _mtv(aj[:, :2], zi), _dot(ai[:, 0], aj[:, 1])[None],
        _dot(zi, aj[:, 2])[None], (dist - length0)[None], jnp.zeros(1, d.dtype),
    ])
    mu = _mtv(select, lam)
    u = d / jnp.where(dist > 0.0, dist, 1.0)
    f_point = mu[:3] + mu[10] * u  # at x_I on I, opposite at x_J on J
    f_axes = _mv(aj, mu[3:6])  # at x_I on both
    torque = cross(zi, _mv(aj, mu[np.array([6, 7, 9])])) + mu[8] * cross(ai[:, 0], aj[:, 1])
    f = f_point + f_axes
    react = jnp.concatenate([f, cross(xi - pi, f) + torque,
                             -f, -cross(xj - pj, f_point) - cross(xi - pj, f_axes) - torque])
    return _mv(select, cand), react


def driver_rows(pi, ri, lam, offset, x0m, direction):
    """Row (1,) of a motion driver, (x_m − x_m⁰)·u, and its reaction (6,) on the part."""
    xm = pi + _mv(ri, offset)
    f = lam[0] * direction
    return jnp.stack([_dot(xm - x0m, direction)]), jnp.concatenate([f, cross(xm - pi, f)])


# ----------------------------------------------------------------------------- assembly


def bushing_params(mech):
    b = mech.bushings
    return dict(
        k_trans=b.k_trans, k_rot=b.k_rot, cubic_trans=b.cubic_trans, cubic_rot=b.cubic_rot,
        offset_trans=b.offset_trans, offset_rot=b.offset_rot, preload_force=b.preload_force,
        preload_torque=b.preload_torque, spline_x=b.spline_x, spline_y=b.spline_y,
    )


def marker_offsets(mech: Mechanism):
    """Every marker's position relative to its part's reference point (mm, at design)."""
    topo = mech.topology
    return mech.markers.position - jnp.asarray(topo.centre[topo.marker_part])


def force_groups(mech: Mechanism, loads: Loads):
    """The force element groups as (group, fn, args): `fn(P_I, R_I, P_J, R_J, *args)` gives the
    wrenches (12,) of one element on its two parts."""
    topo = mech.topology
    mk = mech.markers
    offset = marker_offsets(mech)
    out = []
    b = mech.bushings
    if topo.bushings is not None:
        i, j = np.asarray(b.i_marker), np.asarray(b.j_marker)
        params = bushing_params(mech)
        geometry = (offset[i], mk.orientation[i], offset[j], mk.orientation[j])
        if b.has_splines:
            out.append((topo.bushings, bushing_wrench,
                        (*geometry, params, jnp.asarray(b.spline_axes, dtype=bool))))
        else:
            params = {k: v for k, v in params.items() if not k.startswith("spline")}
            out.append((topo.bushings, functools.partial(bushing_wrench, spline_mask=None),
                        (*geometry, params)))
    s = mech.springs
    for g in topo.springs:
        sel = g.members
        i, j = np.asarray(s.i_marker)[sel], np.asarray(s.j_marker)[sel]
        p = dict(k=s.k[sel], free_length=s.free_length[sel], table_x=s.table_x[sel],
                 table_y=s.table_y[sel])
        out.append((g, functools.partial(_spring_wrench, tabulated=g.kind),
                    (offset[i], offset[j], p)))
    st = mech.stops
    for g in topo.stops:
        sel = g.members
        i, j = np.asarray(st.i_marker)[sel], np.asarray(st.j_marker)[sel]
        p = dict(length=st.length[sel], k=st.k[sel], cubic=st.cubic[sel])
        out.append((g, functools.partial(_stop_wrench, kind=g.kind), (offset[i], offset[j], p)))
    lp = mech.load_points
    if topo.loads is not None:
        mm, ff = np.asarray(lp.marker), np.asarray(lp.frame)
        axes = jnp.where(jnp.asarray(ff < 0)[:, None, None], jnp.eye(3),
                         mk.orientation[np.where(ff < 0, mm, ff)])
        if loads.contact_radius is None:
            out.append((topo.loads, load_wrench, (offset[mm], axes, loads.force, loads.moment)))
        else:
            out.append((topo.loads, contact_load_wrench,
                        (offset[mm], axes, mk.orientation[mm][:, :, 2], loads.force,
                         loads.moment, loads.contact_radius)))
    return out


def _spring_wrench(pi, ri, pj, rj, x0i, x0j, p, tabulated):
    return line_wrench(pi, ri, pj, rj, x0i, x0j,
                       lambda length: spring_tension(length, p, tabulated))


def _stop_wrench(pi, ri, pj, rj, x0i, x0j, p, kind):
    return line_wrench(pi, ri, pj, rj, x0i, x0j, lambda length: stop_tension(length, p, kind))


def constraint_groups(mech: Mechanism, loads: Loads):
    """The constraint groups as (group, fn, args, value offset): `fn(*poses, λ_e, *args)` gives
    the rows Φ of one joint (poses of its two parts) or driver (pose of its part) and their
    reaction wrench; the offset (driver values) is subtracted from the rows."""
    topo = mech.topology
    mk = mech.markers
    offset = marker_offsets(mech)
    out = []
    g = topo.joints
    if g is not None:
        i, j = np.asarray(mech.joints.i_marker), np.asarray(mech.joints.j_marker)
        args = (offset[i], mk.orientation[i], offset[j], mk.orientation[j],
                _safe_norm(mk.position[i] - mk.position[j]), jnp.asarray(g.select))
        out.append((g, joint_rows, args, None))
    if topo.drivers is not None:
        mm = np.asarray(mech.drivers.marker)
        out.append((topo.drivers, driver_rows, (offset[mm], mk.position[mm],
                                                mech.drivers.direction),
                    loads.driver[:, None]))
    return out


def part_poses_internal(q):
    """Poses (P (P+1, 3), R (P+1, 3, 3)) of every part at solver coordinates q, the ground last
    (P = 0, R = I)."""
    qb = q.reshape(-1, 6)
    p = jnp.concatenate([qb[:, :3], jnp.zeros((1, 3), q.dtype)])
    r = jnp.concatenate([jax.vmap(_rotation)(qb[:, 3:]), jnp.eye(3, dtype=q.dtype)[None]])
    return p, r


def _element_poses(g, p, r):
    """Poses of the parts of every element of group g: [P_I, R_I(, P_J, R_J)] stacked."""
    parts = np.asarray(g.coords)[:, ::6] // 6
    return [v for k in range(parts.shape[1]) for v in (p[parts[:, k]], r[parts[:, k]])]


def _twist_jacobian(fn, n_parts: int):
    """`fn(*poses, *args) -> out` ↦ `(*poses, *args) -> (out, ∂out/∂δ)` with δ (6·n_parts,) the
    twists (δP, ω) of the parts: P ← P + δP, R ← R + ω×R (first order of exp(ω×)·R). Forward
    mode, the primal computed once."""

    def wrapped(*args):
        poses, rest = args[: 2 * n_parts], args[2 * n_parts :]

        def f(delta):
            moved = []
            for k in range(n_parts):
                d = delta[6 * k : 6 * k + 6]
                p, r = poses[2 * k], poses[2 * k + 1]
                moved += [p + d[:3], r + _mm(skew(d[3:]), r)]
            out = fn(*moved, *rest)
            return out, out

        jac, val = jax.jacfwd(f, has_aux=True)(jnp.zeros(6 * n_parts, poses[0].dtype))
        return val, jac

    return wrapped


def _terms(mech: Mechanism, loads: Loads, q, lam, with_jacobian: bool):
    """Every element contribution to the wrench residual and its twist Jacobian, one load case:
    (vector values, their destinations, matrix values, their destinations). Values are traced
    arrays; destinations are static positions in the live residual (n + m + 1, the last one a
    trash slot) and in the flattened Jacobian ((n + m)² + 1)."""
    topo = mech.topology
    size = topo.n + topo.m
    p, r = part_poses_internal(q)
    lam_slots = jnp.concatenate([lam, jnp.zeros(1, lam.dtype)])
    live = topo.live
    vec_idx, vec_val, mat_idx, mat_val = [], [], [], []

    def add_vec(idx, val):
        vec_idx.append(live[np.asarray(idx)].reshape(-1))
        vec_val.append(val.reshape(-1))

    def add_mat(ri, ci, val):
        ri, ci = np.broadcast_arrays(live[np.asarray(ri)], live[np.asarray(ci)])
        mat_idx.append(np.where((ri == size) | (ci == size), size * size, ri * size + ci)
                       .reshape(-1))
        mat_val.append(val.reshape(-1))

    for g, fn, args in force_groups(mech, loads):
        poses = _element_poses(g, p, r)
        if with_jacobian:
            val, jac = jax.vmap(_twist_jacobian(fn, 2))(*poses, *args)
            add_mat(g.coords[:, :, None], g.coords[:, None, :], jac)
        else:
            val = jax.vmap(fn)(*poses, *args)
        add_vec(g.coords, val)

    for g, fn, args, value_offset in constraint_groups(mech, loads):
        poses = _element_poses(g, p, r)
        lam_e = lam_slots[jnp.asarray(g.row_slots - topo.base)]
        if with_jacobian:
            (val, react), (jac, hess) = jax.vmap(_twist_jacobian(fn, len(poses) // 2))(
                *poses, lam_e, *args)
            add_mat(g.coords[:, :, None], g.coords[:, None, :], hess)
            add_mat(g.coords[:, :, None], g.row_slots[:, None, :], jnp.swapaxes(jac, 1, 2))
            add_mat(g.row_slots[:, :, None], g.coords[:, None, :], jac)
        else:
            val, react = jax.vmap(fn)(*poses, lam_e, *args)
        if value_offset is not None:
            val = val - value_offset
        add_vec(g.coords, react)
        add_vec(g.row_slots, val)

    vec = (jnp.concatenate(vec_val), np.concatenate(vec_idx))
    if not with_jacobian:
        return (*vec, None, None)
    return (*vec, jnp.concatenate(mat_val), np.concatenate(mat_idx))


def assemble_twist(mech: Mechanism, loads: Loads, q, lam, with_jacobian: bool = True):
    """Wrench residual r (n + m,) at solver coordinates q and multipliers λ, one load case, and
    if asked its Jacobian in twist coordinates (n + m, n + m) (see the module docstring).

    Every element group is evaluated once, vmapped over its elements; all contributions land in
    the live unknowns through one scatter-add for the vector and one for the matrix (static
    destinations; ground and redundant-row entries go to a trash slot)."""
    size = mech.topology.n + mech.topology.m
    vec, vec_idx, mat, mat_idx = _terms(mech, loads, q, lam, with_jacobian)
    r = jnp.zeros(size + 1, q.dtype).at[vec_idx].add(vec)[:size]
    if not with_jacobian:
        return r, None
    flat = jnp.zeros(size * size + 1, q.dtype).at[mat_idx].add(mat)
    return r, flat[:-1].reshape(size, size)


def assemble_batch(mech: Mechanism, loads: Loads, q, lam):
    """`assemble_twist` (with the Jacobian) over a leading case axis of `loads`, q and λ.

    The element terms are vmapped over cases; the scatter into the KKT system is done once for
    the whole batch with the case axis minor (each static destination receives a contiguous
    row of cases), which runs an order of magnitude faster on CPU than a vmapped scatter."""
    size = mech.topology.n + mech.topology.m
    dest = {}

    def terms(loads_, q_, lam_):
        vec, dest["vec"], mat, dest["mat"] = _terms(mech, loads_, q_, lam_, True)
        return vec, mat

    # The case axis is handed over last so that the terms come out case-minor, as the scatter
    # wants them. (XLA still runs the element algebra case-major inside: a case-minor layout of
    # the 3-vector algebra, which PERFORMANCE.md suggests, is not reached this way.)
    last = functools.partial(jnp.moveaxis, source=0, destination=-1)
    vec, mat = jax.vmap(terms, in_axes=-1, out_axes=-1)(jax.tree.map(last, loads), q.T, lam.T)
    cases = q.shape[0]
    r = jnp.zeros((size + 1, cases), q.dtype).at[dest["vec"]].add(vec)[:size].T
    flat = jnp.zeros((size * size + 1, cases), q.dtype).at[dest["mat"]].add(mat)[:-1]
    return r, flat.T.reshape(cases, size, size)


def _gibbs_blocks(q):
    """G(b) (P, 3, 3) of every part at solver coordinates q."""
    return jax.vmap(gibbs_angular_jacobian)(q.reshape(-1, 6)[:, 3:])


def generalised_residual(q, w):
    """The wrench residual w (moments M about each part's reference point, then the constraint
    rows) as the residual of the Gibbs coordinates q: moment rows G(b)ᵀM."""
    n = q.shape[0]
    parts = w[:n].reshape(-1, 2, 3)
    moments = jnp.einsum("pji,pj->pi", _gibbs_blocks(q), parts[:, 1])
    return jnp.concatenate([jnp.stack([parts[:, 0], moments], 1).reshape(-1), w[n:]])


def assemble(mech: Mechanism, loads: Loads, q, lam, with_jacobian: bool = True):
    """KKT residual in Gibbs coordinates r = (Q_ext + Q_int + Φ_qᵀλ, Φ − c) (n + m,) at solver
    coordinates q and multipliers λ, one load case, and if asked its exact Jacobian ∂r/∂(q, λ).

    From the wrench form: Q = (F, G(b)ᵀM) per part and, since a Gibbs increment db turns a part
    by ω = G(b)·db, ∂r/∂y = Tᵀ·J_twist·T + ∂(G(b)ᵀ)/∂b·M with T = diag(I, G(b), …, I)."""
    topo = mech.topology
    n = topo.n
    w, jac_t = assemble_twist(mech, loads, q, lam, with_jacobian)
    gb = _gibbs_blocks(q)
    moments = w[:n].reshape(-1, 2, 3)[:, 1]
    r = generalised_residual(q, w)
    if not with_jacobian:
        return r, None
    eye = jnp.eye(3, dtype=q.dtype)
    t_parts = jax.vmap(lambda g: jnp.block([[eye, jnp.zeros_like(eye)],
                                            [jnp.zeros_like(eye), g]]))(gb)
    t = jax.scipy.linalg.block_diag(*t_parts, jnp.eye(topo.m, dtype=q.dtype))
    jac = t.T @ jac_t @ t
    # The derivative of G(b)ᵀ at fixed moments, on each part's moment rows and Gibbs columns.
    dg = jax.vmap(lambda b, m: jax.jacfwd(lambda b_: gibbs_angular_jacobian(b_).T @ m)(b))(
        q.reshape(-1, 6)[:, 3:], moments)
    rows = (6 * np.arange(n // 6))[:, None, None] + 3 + np.arange(3)[None, :, None]
    cols = (6 * np.arange(n // 6))[:, None, None] + 3 + np.arange(3)[None, None, :]
    return r, jac.at[rows, cols].add(dg)


def generalised_forces(mech: Mechanism, loads: Loads, y):
    """Generalised forces Q = Q_ext + Q_int (n,) of the loads and the force elements (bushings,
    springs, stops) at solver coordinates y (one load case; no joint reactions): per part the
    force F (N) and G(b)ᵀM (N·mm) of the moments about its reference point (spec stiffness
    §1.4–1.5). Differentiable in every leaf of `mech`: its `jax.jacfwd` in the stiffnesses is
    the direct method's regressor (spec §1.9)."""
    n = mech.topology.n
    w, _ = assemble_twist(mech, loads, y, jnp.zeros(mech.topology.m, y.dtype),
                          with_jacobian=False)
    return generalised_residual(y, w)[:n]


def constraint_values(mech: Mechanism, loads: Loads, q):
    """All constraint rows (joints then drivers, redundant ones included) at solver coordinates
    q, without touching the force elements."""
    p, r = part_poses_internal(q)
    out = jnp.zeros(mech.n_rows + 1, q.dtype)  # the last entry takes the padding rows
    for g, fn, args, value_offset in constraint_groups(mech, loads):
        lam = jnp.zeros(g.rows.shape, q.dtype)
        val = jax.vmap(fn)(*_element_poses(g, p, r), lam, *args)[0]
        if value_offset is not None:
            val = val - value_offset
        out = out.at[np.asarray(g.rows).reshape(-1)].set(val.reshape(-1))
    return out[:-1]


def constraint_jacobian(mech: Mechanism, loads: Loads, q):
    """Φ_q (m, n) of the independent constraint rows at solver coordinates q (forward mode
    through the constraint rows only)."""
    live = np.asarray(mech.independent_rows, dtype=int)
    return jax.jacfwd(lambda q_: constraint_values(mech, loads, q_)[live])(q)


def to_internal(mech: Mechanism, q):
    """Public coordinates (p, b) → solver coordinates (P = p + R(b)·c, b), one case."""
    c = jnp.asarray(mech.topology.centre[:-1])
    qb = q.reshape(-1, 6)
    rot = jax.vmap(gibbs_to_matrix)(qb[:, 3:])
    return jnp.concatenate([qb[:, :3] + jnp.einsum("pij,pj->pi", rot, c), qb[:, 3:]], 1).ravel()


def to_public(mech: Mechanism, y):
    """Solver coordinates (P, b) → public coordinates (p = P − R(b)·c, b), one case."""
    c = jnp.asarray(mech.topology.centre[:-1])
    yb = y.reshape(-1, 6)
    rot = jax.vmap(gibbs_to_matrix)(yb[:, 3:])
    return jnp.concatenate([yb[:, :3] - jnp.einsum("pij,pj->pi", rot, c), yb[:, 3:]], 1).ravel()


def _screw_coefficients(t2):
    """(1 − cos θ)/θ², (θ − sin θ)/θ³ and tan(θ/2)/θ for θ² = t2, series near 0."""
    small = t2 < 1e-6
    t2s = jnp.where(small, 1.0, t2)
    theta = jnp.sqrt(t2s)
    c1 = jnp.where(small, 0.5 - t2 / 24.0, (1.0 - jnp.cos(theta)) / t2s)
    c2 = jnp.where(small, 1.0 / 6.0 - t2 / 120.0, (theta - jnp.sin(theta)) / (t2s * theta))
    c3 = jnp.where(small, 0.5 + t2 / 24.0, jnp.tan(0.5 * theta) / theta)
    return c1, c2, c3


def retract(y, dy, n: int):
    """Move solver coordinates y by a Newton increment dy in twist coordinates (per part the
    velocity dP of its reference point and a global rotation vector ω) along rigid-body screw
    motions: P ← P + V(ω)·dP with V(ω)·ω× = exp(ω×) − I, b ← b(ω) ∘ b. To first order this is
    the twist step; beyond it, a part turning about a joint stays on its arc instead of leaving
    it along the tangent, which keeps Newton's steps long on swinging arms. Multipliers move
    additively."""
    q = y[:n].reshape(-1, 6)
    d = dy[:n].reshape(-1, 6)

    def one(q6, d6):
        b = q6[3:]
        w = d6[3:]
        c1, c2, c3 = _screw_coefficients(_dot(w, w))
        wx = cross(w, d6[:3])
        step = d6[:3] + c1 * wx + c2 * cross(w, wx)
        g = c3 * w  # Gibbs vector of the rotation ω
        b_new = (g + b + cross(g, b)) / (1.0 - _dot(g, b))
        return jnp.concatenate([q6[:3] + step, b_new])

    moved = jax.vmap(one)(q, d).reshape(-1)
    return jnp.concatenate([moved, y[n:] + dy[n:]])
