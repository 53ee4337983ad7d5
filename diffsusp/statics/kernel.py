"""Element kernels and assembly of the equilibrium (KKT) residual and Jacobian, for one load case.

Unknowns: 6 per moving part — the position P (mm) of the part's reference point (the centroid of
its markers at design, so that rotations about nearby joints stay mildly nonlinear for Newton)
and the Gibbs vector b of its rotation from design (spec stiffness §1.3) — and one multiplier per
independent constraint row. The public coordinates q = (p, b) of DESIGN.md (p = displacement of
the point at the global origin) follow as p = P − R(b)·c. Residual:

    r_q = Q_ext(q) + Q_int(q) + Φ_q(q)ᵀ λ        (generalised forces, spec stiffness §1.5, §1.9)
    r_λ = Φ(q) − c                                (joint rows and motion drivers, §1.6)

Every element touches at most two parts, so each one is written as a function of the 12
coordinates z = (q_a, q_b) of its two parts and differentiated there (forward mode, 12
directions), then scattered into the global vector and matrix. The ground is a virtual part whose
coordinates stay at zero (its markers keep their design pose); its rows and columns are dropped.
A wrench (F, T) applied at world point x of a part with coordinates (p, b) has the generalised
force [F; G(b)ᵀ (T + (x − p) × F)], with G(b) = 2/(1 + b·b)(I + b×) (spec §1.4).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ..geometry import gibbs_angular_jacobian, gibbs_to_matrix, projected_angles
from ..geometry.rotations import cross
from ..model.laws import akima_eval
from ..model.mechanism import Loads, Mechanism


def _pose(z6, x0, r0):
    r = gibbs_to_matrix(z6[3:])
    return z6[:3] + r @ x0, r @ r0


def generalised_force(z6, x, force, torque):
    moment = torque + cross(x - z6[:3], force)
    return jnp.concatenate([force, gibbs_angular_jacobian(z6[3:]).T @ moment])


# ----------------------------------------------------------------------------- force elements


def bushing_state(z, x0i, r0i, x0j, r0j, p, spline_mask):
    """Deformation and law of one bushing (Adams convention, spec stiffness §1.8).

    **Returns:** (δ_T in J (mm), projected angles (rad), force f and torque t on I in J axes,
    x_I, x_J, R_J) at the coordinates z of its two parts.
    """
    xi, ri = _pose(z[:6], x0i, r0i)
    xj, rj = _pose(z[6:], x0j, r0j)
    delta_t = rj.T @ (xi - xj)
    delta_r = projected_angles(rj.T @ ri)
    e_t = delta_t - p["offset_trans"]
    e_r = delta_r - p["offset_rot"]
    f = -(p["k_trans"] * e_t + p["cubic_trans"] * e_t**3) + p["preload_force"]
    t = -(p["k_rot"] * e_r + p["cubic_rot"] * e_r**3) + p["preload_torque"]
    if spline_mask is not None:
        e = jnp.concatenate([e_t, e_r])
        spline = jax.vmap(akima_eval)(p["spline_x"], p["spline_y"], e)
        ft = jnp.where(spline_mask, spline, jnp.concatenate([f, t]))
        f, t = ft[:3], ft[3:]
    return delta_t, delta_r, f, t, xi, xj, rj


def bushing_force(z, x0i, r0i, x0j, r0j, p, spline_mask):
    """Generalised forces (12,) of one bushing on its I part then J part."""
    _, _, f, t, xi, xj, rj = bushing_state(z, x0i, r0i, x0j, r0j, p, spline_mask)
    force, torque = rj @ f, rj @ t
    return jnp.concatenate(
        [
            generalised_force(z[:6], xi, force, torque),
            generalised_force(z[6:], xj, -force, -torque - cross(xi - xj, force)),
        ]
    )


def line_force(z, x0i, x0j, tension):
    """Generalised forces of a tension `tension(ℓ)` along the line of two points."""
    eye = jnp.eye(3)
    xi, _ = _pose(z[:6], x0i, eye)
    xj, _ = _pose(z[6:], x0j, eye)
    u = xj - xi
    length = jnp.sqrt(u @ u)
    f = tension(length) * u / length  # pulls I toward J
    zero = jnp.zeros(3)
    return jnp.concatenate(
        [generalised_force(z[:6], xi, f, zero), generalised_force(z[6:], xj, -f, zero)]
    )


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


def load_force(z, x0m, r0f, force, moment, global_frame: bool):
    """Generalised force of a load at marker m, components in frame f (second part of z)."""
    xm, _ = _pose(z[:6], x0m, jnp.eye(3))
    if global_frame:
        rf = jnp.eye(3)
    else:
        _, rf = _pose(z[6:], jnp.zeros(3), r0f)
    return jnp.concatenate([generalised_force(z[:6], xm, rf @ force, rf @ moment), jnp.zeros(6)])


# ----------------------------------------------------------------------------- constraints


def _safe_norm(d):
    """|d| along the last axis, with zero (not NaN) derivatives at d = 0 (a spherical joint's
    design distance)."""
    dd = jnp.sum(d * d, axis=-1)
    positive = dd > 0.0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, dd, 1.0)), 0.0)


def selected_joint_rows(z, x0i, r0i, x0j, r0j, length0, select):
    """Constraint rows Φ of one joint of any kind (Adams definitions, spec stiffness §1.6):
    `select` (r, 12) picks them (one-hot) among the candidate quantities of
    `diffsusp.model.topology.JOINT_CANDIDATES` (d = x_I − x_J, its components on the J axes,
    dot products of the I and J axes, |d| minus its design value `length0`), so that joints of
    every kind are one vmapped group. `x0i`, `x0j` are the markers' offsets from their parts'
    reference points."""
    xi, ri = _pose(z[:6], x0i, r0i)
    xj, rj = _pose(z[6:], x0j, r0j)
    d = xi - xj
    cand = jnp.concatenate([
        d, d @ rj, ri[:, 2] @ rj[:, :2], ri[:, 0:1].T @ rj[:, 1],
        (ri[:, 2] @ rj[:, 2])[None], (_safe_norm(d) - length0)[None], jnp.zeros(1, d.dtype),
    ])
    return select @ cand


def driver_row(z6, offset, x0m, direction):
    xm, _ = _pose(z6, offset, jnp.eye(3))
    return jnp.stack([(xm - x0m) @ direction])


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
    """The force element groups as (group, fn, args): `fn(z, *args)` gives the 12 generalised
    forces of one element (I part, then J part) at the coordinates z of its two parts."""
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
            out.append((topo.bushings, bushing_force,
                        (*geometry, params, jnp.asarray(b.spline_axes, dtype=bool))))
        else:
            params = {k: v for k, v in params.items() if not k.startswith("spline")}
            out.append((topo.bushings, functools.partial(bushing_force, spline_mask=None),
                        (*geometry, params)))
    s = mech.springs
    for g in topo.springs:
        sel = g.members
        i, j = np.asarray(s.i_marker)[sel], np.asarray(s.j_marker)[sel]
        p = dict(k=s.k[sel], free_length=s.free_length[sel], table_x=s.table_x[sel],
                 table_y=s.table_y[sel])
        out.append((g, functools.partial(_spring_force, tabulated=g.kind),
                    (offset[i], offset[j], p)))
    st = mech.stops
    for g in topo.stops:
        sel = g.members
        i, j = np.asarray(st.i_marker)[sel], np.asarray(st.j_marker)[sel]
        p = dict(length=st.length[sel], k=st.k[sel], cubic=st.cubic[sel])
        out.append((g, functools.partial(_stop_force, kind=g.kind), (offset[i], offset[j], p)))
    lp = mech.load_points
    if topo.loads is not None:
        mm, ff = np.asarray(lp.marker), np.asarray(lp.frame)
        axes = jnp.where(jnp.asarray(ff < 0)[:, None, None], jnp.eye(3),
                         mk.orientation[np.where(ff < 0, mm, ff)])
        out.append((topo.loads, functools.partial(load_force, global_frame=False),
                    (offset[mm], axes, loads.force, loads.moment)))
    return out


def _spring_force(z, x0i, x0j, p, tabulated):
    return line_force(z, x0i, x0j, lambda length: spring_tension(length, p, tabulated))


def _stop_force(z, x0i, x0j, p, kind):
    return line_force(z, x0i, x0j, lambda length: stop_tension(length, p, kind))


def constraint_groups(mech: Mechanism, loads: Loads):
    """The constraint groups as (group, fn, args, value offset): `fn(z, *args)` gives the rows Φ
    of one joint (or driver) at the coordinates z of its parts; the offset (driver values) is
    subtracted from the rows."""
    topo = mech.topology
    mk = mech.markers
    offset = marker_offsets(mech)
    out = []
    g = topo.joints
    if g is not None:
        i, j = np.asarray(mech.joints.i_marker), np.asarray(mech.joints.j_marker)
        args = (offset[i], mk.orientation[i], offset[j], mk.orientation[j],
                _safe_norm(mk.position[i] - mk.position[j]), jnp.asarray(g.select))
        out.append((g, selected_joint_rows, args, None))
    if topo.drivers is not None:
        mm = np.asarray(mech.drivers.marker)
        out.append((topo.drivers, driver_row, (offset[mm], mk.position[mm],
                                                mech.drivers.direction),
                    loads.driver[:, None]))
    return out


def _full(mech, y):
    """Solver coordinates with the ground's six zero coordinates appended (its slot)."""
    return jnp.concatenate([y, jnp.zeros(6, y.dtype)])


def _value_and_jacfwd(fn):
    """`fn(z, *args) -> (value, ∂value/∂z)`, the primal computed once (forward mode)."""

    def wrapped(z, *args):
        def f(z_):
            out = fn(z_, *args)
            return out, out

        jac, val = jax.jacfwd(f, has_aux=True)(z)
        return val, jac

    return wrapped


def _rows_and_reaction(fn):
    """`(z, λ, *args) -> (Φ, Φ_zᵀλ)` of one constraint element (reverse mode inside)."""

    def wrapped(z, lam, *args):
        val, vjp = jax.vjp(lambda zz: fn(zz, *args), z)
        return val, vjp(lam)[0]

    return wrapped


def _terms(mech: Mechanism, loads: Loads, q, lam, with_jacobian: bool):
    """Every element contribution, one load case: (vector values, their destinations, matrix
    values, their destinations). Values are traced arrays; destinations are static positions
    in the live residual (n + m + 1, the last one a trash slot) and in the flattened Jacobian
    ((n + m)² + 1)."""
    topo = mech.topology
    size = topo.n + topo.m
    yfull = _full(mech, q)
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
        z = yfull[g.coords]
        if with_jacobian:
            val, jac = jax.vmap(_value_and_jacfwd(fn))(z, *args)
            add_mat(g.coords[:, :, None], g.coords[:, None, :], jac)
        else:
            val = jax.vmap(fn)(z, *args)
        add_vec(g.coords, val)

    for g, fn, args, value_offset in constraint_groups(mech, loads):
        z = yfull[g.coords]
        lam_e = lam_slots[jnp.asarray(g.row_slots - topo.base)]
        pair = _rows_and_reaction(fn)
        if with_jacobian:
            def both(zz, lam_, *a, pair=pair):
                out = pair(zz, lam_, *a)
                return out, out

            (jac, hess), (val, react) = jax.vmap(
                lambda zz, lam_, *a, both=both: jax.jacfwd(both, has_aux=True)(zz, lam_, *a)
            )(z, lam_e, *args)
            add_mat(g.coords[:, :, None], g.coords[:, None, :], hess)
            add_mat(g.coords[:, :, None], g.row_slots[:, None, :], jnp.swapaxes(jac, 1, 2))
            add_mat(g.row_slots[:, :, None], g.coords[:, None, :], jac)
        else:
            val, react = jax.vmap(pair)(z, lam_e, *args)
        if value_offset is not None:
            val = val - value_offset
        add_vec(g.coords, react)
        add_vec(g.row_slots, val)

    vec = (jnp.concatenate(vec_val), np.concatenate(vec_idx))
    if not with_jacobian:
        return (*vec, None, None)
    return (*vec, jnp.concatenate(mat_val), np.concatenate(mat_idx))


def assemble(mech: Mechanism, loads: Loads, q, lam, with_jacobian: bool = True):
    """Residual r (n + m,) and, if asked, its Jacobian (n + m, n + m) at (q, λ), one load case.

    Every element group is evaluated once (vmapped over its elements): force elements with their
    12×12 forward-mode Jacobian, constraints with their rows, Φ_zᵀλ and (one forward-over-
    reverse pass) their Jacobian A and λ-weighted Hessian Σλ∂²Φ. All contributions land in the
    live unknowns through one scatter-add for the vector and one for the matrix (static
    destinations; ground and redundant-row entries go to a trash slot).
    """
    size = mech.topology.n + mech.topology.m
    vec, vec_idx, mat, mat_idx = _terms(mech, loads, q, lam, with_jacobian)
    r = jnp.zeros(size + 1, q.dtype).at[vec_idx].add(vec)[:size]
    if not with_jacobian:
        return r, None
    flat = jnp.zeros(size * size + 1, q.dtype).at[mat_idx].add(mat)
    return r, flat[:-1].reshape(size, size)


def assemble_batch(mech: Mechanism, loads: Loads, q, lam):
    """`assemble` (with the Jacobian) over a leading case axis of `loads`, q and λ.

    The element terms are vmapped over cases; the scatter into the KKT system is done once for
    the whole batch with the case axis minor (each static destination receives a contiguous
    row of cases), which runs an order of magnitude faster on CPU than a vmapped scatter."""
    size = mech.topology.n + mech.topology.m
    dest = {}

    def terms(loads_, q_, lam_):
        vec, dest["vec"], mat, dest["mat"] = _terms(mech, loads_, q_, lam_, True)
        return vec, mat

    vec, mat = jax.vmap(terms)(loads, q, lam)
    cases = q.shape[0]
    r = jnp.zeros((size + 1, cases), q.dtype).at[dest["vec"]].add(vec.T)[:size].T
    flat = jnp.zeros((size * size + 1, cases), q.dtype).at[dest["mat"]].add(mat.T)[:-1]
    return r, flat.T.reshape(cases, size, size)


def constraint_values(mech: Mechanism, loads: Loads, q):
    """All constraint rows (joints then drivers, redundant ones included) at solver coordinates
    q, without touching the force elements."""
    yfull = _full(mech, q)
    out = jnp.zeros(mech.n_rows + 1, q.dtype)  # the last entry takes the padding rows
    for g, fn, args, value_offset in constraint_groups(mech, loads):
        val = jax.vmap(fn)(yfull[g.coords], *args)
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
    """Move solver coordinates y by a Newton increment dy along rigid-body screw motions.

    The increment of each part (dP, db) is read as a twist: ω = G(b)·db (global rotation
    vector) and dP the velocity of its reference point. The part is moved by the exponential of
    that twist, P ← P + V(ω)·dP with V(ω)·ω× = exp(ω×) − I, b ← b(ω) ∘ b. To first order this is
    the additive step; beyond it, a part turning about a joint stays on its arc instead of
    leaving it along the tangent, which keeps Newton's steps long on swinging arms.
    Multipliers move additively.
    """
    q = y[:n].reshape(-1, 6)
    d = dy[:n].reshape(-1, 6)

    def one(q6, d6):
        b = q6[3:]
        w = gibbs_angular_jacobian(b) @ d6[3:]
        c1, c2, c3 = _screw_coefficients(w @ w)
        wx = cross(w, d6[:3])
        step = d6[:3] + c1 * wx + c2 * cross(w, wx)
        g = c3 * w  # Gibbs vector of the rotation ω
        b_new = (g + b + cross(g, b)) / (1.0 - g @ b)
        return jnp.concatenate([q6[:3] + step, b_new])

    moved = jax.vmap(one)(q, d).reshape(-1)
    return jnp.concatenate([moved, y[n:] + dy[n:]])
