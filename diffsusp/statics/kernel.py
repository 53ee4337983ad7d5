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
from ..model.laws import akima_eval
from ..model.mechanism import GROUND, JOINT_ROWS, Loads, Mechanism, row_blocks

# Rows of each joint kind that measure an angle (dimensionless) rather than a length (mm).
_ANGULAR_ROWS = {
    "spherical": (),
    "revolute": (3, 4),
    "cylindrical": (2, 3),
    "translational": (2, 3, 4),
    "universal": (3,),
    "fixed": (3, 4, 5),
    "inline": (),
    "inplane": (),
    "perpendicular": (0,),
    "distance": (),
}


def _pose(z6, x0, r0):
    r = gibbs_to_matrix(z6[3:])
    return z6[:3] + r @ x0, r @ r0


def _generalised_force(z6, x, force, torque):
    moment = torque + jnp.cross(x - z6[:3], force)
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


def _bushing_force(z, x0i, r0i, x0j, r0j, p, spline_mask):
    """Generalised forces (12,) of one bushing on its I part then J part."""
    _, _, f, t, xi, xj, rj = bushing_state(z, x0i, r0i, x0j, r0j, p, spline_mask)
    force, torque = rj @ f, rj @ t
    return jnp.concatenate(
        [
            _generalised_force(z[:6], xi, force, torque),
            _generalised_force(z[6:], xj, -force, -torque - jnp.cross(xi - xj, force)),
        ]
    )


def _line_force(z, x0i, x0j, tension):
    """Generalised forces of a tension `tension(ℓ)` along the line of two points."""
    eye = jnp.eye(3)
    xi, _ = _pose(z[:6], x0i, eye)
    xj, _ = _pose(z[6:], x0j, eye)
    u = xj - xi
    length = jnp.sqrt(u @ u)
    f = tension(length) * u / length  # pulls I toward J
    zero = jnp.zeros(3)
    return jnp.concatenate(
        [_generalised_force(z[:6], xi, f, zero), _generalised_force(z[6:], xj, -f, zero)]
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


def _load_force(z, x0m, r0f, force, moment, global_frame: bool):
    """Generalised force of a load at marker m, components in frame f (second part of z)."""
    xm, _ = _pose(z[:6], x0m, jnp.eye(3))
    if global_frame:
        rf = jnp.eye(3)
    else:
        _, rf = _pose(z[6:], jnp.zeros(3), r0f)
    return jnp.concatenate([_generalised_force(z[:6], xm, rf @ force, rf @ moment), jnp.zeros(6)])


# ----------------------------------------------------------------------------- constraints


def joint_rows(kind: str, z, x0i, r0i, x0j, r0j, length0):
    """Constraint rows Φ of one joint of `kind` (Adams definitions, spec stiffness §1.6).

    `x0i`, `x0j` are the markers' offsets from their parts' reference points; `length0` the
    design distance of the two markers (for 'distance')."""
    xi, ri = _pose(z[:6], x0i, r0i)
    xj, rj = _pose(z[6:], x0j, r0j)
    d = xi - xj
    (xi_, _, zi_), (xj_, yj_, zj_) = ri.T, rj.T
    if kind == "spherical":
        return d
    if kind == "revolute":
        return jnp.concatenate([d, jnp.stack([zi_ @ xj_, zi_ @ yj_])])
    if kind == "cylindrical":
        return jnp.stack([d @ xj_, d @ yj_, zi_ @ xj_, zi_ @ yj_])
    if kind == "translational":
        return jnp.stack([d @ xj_, d @ yj_, zi_ @ xj_, zi_ @ yj_, xi_ @ yj_])
    if kind == "universal":
        return jnp.concatenate([d, jnp.stack([zi_ @ zj_])])
    if kind == "fixed":
        return jnp.concatenate([d, jnp.stack([zi_ @ xj_, zi_ @ yj_, xi_ @ yj_])])
    if kind == "inline":
        return jnp.stack([d @ xj_, d @ yj_])
    if kind == "inplane":
        return jnp.stack([d @ zj_])
    if kind == "perpendicular":
        return jnp.stack([zi_ @ zj_])
    if kind == "distance":
        return jnp.stack([jnp.sqrt(d @ d) - length0])
    raise ValueError(f"unknown joint kind '{kind}'")


def _driver_row(z6, offset, x0m, direction):
    xm, _ = _pose(z6, offset, jnp.eye(3))
    return jnp.stack([(xm - x0m) @ direction])


# ----------------------------------------------------------------------------- layout


class Layout:
    """Static index bookkeeping of one mechanism: where every element lands in the KKT system.

    Coordinates of part a occupy 6a..6a+5; the ground is a virtual part P at 6P..6P+5.
    Multiplier k (of `independent_rows`) sits at 6(P+1) + k; redundant rows go to one dummy slot
    at the end. `keep` extracts the live unknowns in the order (q, λ).
    """

    def __init__(self, mech: Mechanism):
        n_parts = len(mech.parts)
        self.n = 6 * n_parts
        self.m = len(mech.independent_rows)
        self.base = base = 6 * (n_parts + 1)
        self.size = base + self.m + 1
        dummy = base + self.m
        position = {r: base + k for k, r in enumerate(mech.independent_rows)}
        self.row_slot = np.array([position.get(r, dummy) for r in range(mech.n_rows)], dtype=int)
        self.keep = np.concatenate([np.arange(self.n), base + np.arange(self.m)])
        marker_part = np.array(mech.markers.part, dtype=int)
        self.marker_part = np.where(marker_part == GROUND, n_parts, marker_part)
        self.centre = np.zeros((n_parts + 1, 3))
        self.centre[:n_parts] = np.asarray(mech.reference_points, dtype=float).reshape(-1, 3)
        self.angular = np.zeros(mech.n_rows, dtype=bool)
        for kind, _, offsets in row_blocks(mech.joints):
            for row in _ANGULAR_ROWS[kind]:
                self.angular[offsets + row] = True
        self.angular_live = self.angular[list(mech.independent_rows)]

    def coords(self, markers_i, markers_j) -> np.ndarray:
        """(E, 12) global coordinate indices of the two parts of each element."""
        a = self.marker_part[np.asarray(markers_i, dtype=int)]
        b = self.marker_part[np.asarray(markers_j, dtype=int)]
        six = np.arange(6)
        return np.concatenate([6 * a[:, None] + six, 6 * b[:, None] + six], axis=1)


@functools.lru_cache(maxsize=64)
def layout(mech_static_key) -> Layout:
    return Layout(mech_static_key.mech)


class _Key:
    """Hashable wrapper keyed on the mechanism's static structure (values do not matter)."""

    def __init__(self, mech):
        self.mech = mech
        self.key = jax.tree_util.tree_structure(mech)

    def __hash__(self):
        return hash(self.key)

    def __eq__(self, other):
        return self.key == other.key


def get_layout(mech: Mechanism) -> Layout:
    return layout(_Key(mech))


# ----------------------------------------------------------------------------- assembly


def bushing_params(mech):
    b = mech.bushings
    return dict(
        k_trans=b.k_trans, k_rot=b.k_rot, cubic_trans=b.cubic_trans, cubic_rot=b.cubic_rot,
        offset_trans=b.offset_trans, offset_rot=b.offset_rot, preload_force=b.preload_force,
        preload_torque=b.preload_torque, spline_x=b.spline_x, spline_y=b.spline_y,
    )


def _element_terms(mech: Mechanism, loads: Loads, q, lam, lay: Layout, with_jacobian: bool):
    """All element contributions as a list of (row indices, col indices, values) for the matrix
    and (indices, values) for the residual vector."""
    qfull = jnp.concatenate([q, jnp.zeros(6, q.dtype)])
    mk = mech.markers
    offset = mk.position - jnp.asarray(lay.centre[lay.marker_part])
    vec_terms, mat_terms = [], []

    def add_force(fn, idx, *args):
        for sel, side, sub in _ground_split(idx, lay):
            f = _restrict(fn, side, slice_output=True)
            a = jax.tree.map(lambda x, sel=sel: x[sel], args)
            z = qfull[sub]
            if with_jacobian:
                val, jac = jax.vmap(_value_and_jacfwd(f))(z, *a)
                mat_terms.append((sub[:, :, None], sub[:, None, :], jac))
            else:
                val = jax.vmap(f)(z, *a)
            vec_terms.append((sub, val))

    if mech.bushings.names:
        b = mech.bushings
        i, j = np.asarray(b.i_marker), np.asarray(b.j_marker)
        params = bushing_params(mech)
        geometry = (offset[i], mk.orientation[i], offset[j], mk.orientation[j])
        if b.has_splines:
            add_force(_bushing_force, lay.coords(i, j), *geometry, params,
                      jnp.asarray(b.spline_axes, dtype=bool))
        else:
            params = {k: v for k, v in params.items() if not k.startswith("spline")}
            add_force(functools.partial(_bushing_force, spline_mask=None), lay.coords(i, j),
                      *geometry, params)

    for elements, tension_of in (
        (mech.springs, lambda e, k: functools.partial(spring_tension, tabulated=k)),
        (mech.stops, lambda e, k: functools.partial(stop_tension, kind=k)),
    ):
        if not elements.names:
            continue
        flags = elements.tabulated if elements is mech.springs else elements.kind
        params = (
            dict(k=elements.k, free_length=elements.free_length, table_x=elements.table_x,
                 table_y=elements.table_y)
            if elements is mech.springs
            else dict(length=elements.length, k=elements.k, cubic=elements.cubic)
        )
        for flag in sorted(set(flags)):
            sel = np.array([f == flag for f in flags])
            i = np.asarray(elements.i_marker)[sel]
            j = np.asarray(elements.j_marker)[sel]
            tension = tension_of(elements, flag)
            p_sel = {k: v[sel] for k, v in params.items()}
            add_force(
                lambda z, a, c, p, tension=tension: _line_force(
                    z, a, c, lambda length: tension(length, p)
                ),
                lay.coords(i, j), offset[i], offset[j], p_sel,
            )

    if mech.load_points.names:
        lp = mech.load_points
        m_idx = np.asarray(lp.marker)
        f_idx = np.asarray(lp.frame)
        for is_global in (True, False):
            sel = (f_idx == GROUND) == is_global
            if not sel.any():
                continue
            mm, ff = m_idx[sel], np.where(f_idx[sel] < 0, m_idx[sel], f_idx[sel])
            idx = lay.coords(mm, ff)
            if is_global:  # the frame is fixed: only the loaded part's coordinates matter
                idx[:, 6:] = lay.base - 6 + np.arange(6)
            add_force(
                functools.partial(_load_force, global_frame=is_global),
                idx, offset[mm], mk.orientation[ff], loads.force[sel], loads.moment[sel],
            )

    # Constraint rows: value, (r, 12) Jacobian and λ-weighted Hessian per joint.
    row_vals = []
    lam_rows = jnp.concatenate([lam, jnp.zeros(1, lam.dtype)])[jnp.asarray(lay.row_slot - lay.base)]
    for kind, idx, offsets in row_blocks(mech.joints):
        i = np.asarray(mech.joints.i_marker)[idx]
        j = np.asarray(mech.joints.j_marker)[idx]
        rows = offsets[:, None] + np.arange(JOINT_ROWS[kind])
        fn = functools.partial(joint_rows, kind)
        d0 = mk.position[i] - mk.position[j]
        args = (offset[i], mk.orientation[i], offset[j], mk.orientation[j],
                jnp.sqrt(jnp.sum(d0**2, axis=-1)))
        _constraint_terms(fn, lay.coords(i, j), rows, args, qfull, lam_rows, lay,
                          vec_terms, mat_terms, row_vals, with_jacobian)
    if mech.drivers.names:
        mm = np.asarray(mech.drivers.marker)
        rows = mech.joints.n_rows + np.arange(len(mm))[:, None]
        idx = lay.coords(mm, mm)[:, :6]
        _constraint_terms(_driver_row, idx, rows,
                          (offset[mm], mk.position[mm], mech.drivers.direction),
                          qfull, lam_rows, lay, vec_terms, mat_terms, row_vals, with_jacobian,
                          offset=loads.driver[:, None])
    return vec_terms, mat_terms, row_vals


def _ground_split(idx, lay):
    """Split a group of two-part elements (E, 12 coordinate indices) by which parts move:
    yields (selection, side, indices) with side 'both' (12 coordinates), 'a' or 'b' (the 6 of
    the moving part; the other is the ground). Differentiating only what moves halves the work
    for the many elements attached to the ground (the body of a K&C rig)."""
    ground = lay.base - 6
    a_ground = idx[:, 0] == ground
    b_ground = idx[:, 6] == ground
    for sel, side, cols in (
        (~a_ground & ~b_ground, "both", slice(0, 12)),
        (~a_ground & b_ground, "a", slice(0, 6)),
        (a_ground & ~b_ground, "b", slice(6, 12)),
    ):
        if sel.any():
            yield sel, side, idx[sel][:, cols]


def _restrict(fn, side: str, slice_output: bool):
    """`fn(z12, ...)` as a function of the moving part's 6 coordinates (ground ones are zero).
    With `slice_output`, keep only the moving part's 6 generalised forces."""
    if side == "both":
        return fn

    def restricted(z6, *args):
        zero = jnp.zeros(6, z6.dtype)
        z = jnp.concatenate([z6, zero] if side == "a" else [zero, z6])
        out = fn(z, *args)
        if slice_output:
            return out[:6] if side == "a" else out[6:]
        return out

    return restricted


def _value_and_jacfwd(fn):
    """`fn(z, *args) -> (value, ∂value/∂z)`, the primal computed once (forward mode)."""

    def wrapped(z, *args):
        def f(z_):
            out = fn(z_, *args)
            return out, out

        jac, val = jax.jacfwd(f, has_aux=True)(z)
        return val, jac

    return wrapped


def _constraint_terms(fn, idx, rows, args, qfull, lam_rows, lay, vec_terms, mat_terms,
                      row_vals, with_jacobian, offset=None, split=True):
    if split and idx.shape[1] == 12:
        for sel, side, sub in _ground_split(idx, lay):
            _constraint_terms(_restrict(fn, side, slice_output=False), sub, rows[sel],
                              jax.tree.map(lambda x, sel=sel: x[sel], args), qfull, lam_rows, lay,
                              vec_terms, mat_terms, row_vals, with_jacobian,
                              None if offset is None else offset[sel], split=False)
        return
    z = qfull[idx]
    lam_e = lam_rows[jnp.asarray(rows)]  # (E, r)
    slots = lay.row_slot[rows]  # (E, r)
    if with_jacobian:
        val, jac, g, hess = _vmapped_constraint(fn, z, lam_e, args)
        mat_terms.append((idx[:, :, None], idx[:, None, :], hess))
        mat_terms.append((idx[:, :, None], slots[:, None, :], jnp.swapaxes(jac, 1, 2)))
        mat_terms.append((slots[:, :, None], idx[:, None, :], jac))
    else:
        def value_and_reaction(z_, lam_, *a):
            val, vjp = jax.vjp(lambda zz: fn(zz, *a), z_)
            return val, vjp(lam_)[0]

        val, g = jax.vmap(value_and_reaction)(z, lam_e, *args)
    if offset is not None:
        val = val - offset
    vec_terms.append((idx, g))
    vec_terms.append((slots, val))
    row_vals.append((rows, val))


def _vmapped_constraint(fn, z, lam_e, args):
    """Per joint: rows Φ, Jacobian A (r×k), Aᵀλ and the Hessian Σ λ ∂²Φ (k×k)."""

    def per_element(z_, lam_, *a):
        def reaction(zz):
            val, vjp = jax.vjp(lambda z3: fn(z3, *a), zz)
            return vjp(lam_)[0], val

        hess, _ = jax.jacfwd(reaction, has_aux=True)(z_)
        val, jac = _value_and_jacfwd(fn)(z_, *a)
        return val, jac, jac.T @ lam_, hess

    return jax.vmap(per_element)(z, lam_e, *args)


def assemble(mech: Mechanism, loads: Loads, q, lam, with_jacobian: bool = True):
    """Residual r (n + m,) and, if asked, its Jacobian (n + m, n + m) at (q, λ), one load case.

    All element contributions land in the live unknowns through one scatter-add each for the
    vector and the matrix (static destinations; ground and redundant-row entries go to a trash
    slot), which XLA runs far faster than one scatter per element group.
    """
    lay = get_layout(mech)
    vec_terms, mat_terms, _ = _element_terms(mech, loads, q, lam, lay, with_jacobian)
    size = lay.n + lay.m
    pos = np.full(lay.size, size)  # global index → live position; everything else → trash
    pos[lay.keep] = np.arange(size)
    dest = np.concatenate([pos[np.asarray(idx)].reshape(-1) for idx, _ in vec_terms])
    vals = jnp.concatenate([val.reshape(-1) for _, val in vec_terms])
    r = jnp.zeros(size + 1, q.dtype).at[dest].add(vals)[:size]
    if not with_jacobian:
        return r, None
    dests, vals = [], []
    for ri, ci, val in mat_terms:
        ri, ci = np.broadcast_arrays(pos[np.asarray(ri)], pos[np.asarray(ci)])
        trash = (ri == size) | (ci == size)
        dests.append(np.where(trash, size * size, ri * size + ci).reshape(-1))
        vals.append(val.reshape(-1))
    flat = jnp.zeros(size * size + 1, q.dtype).at[np.concatenate(dests)].add(jnp.concatenate(vals))
    return r, flat[:-1].reshape(size, size)


def constraint_values(mech: Mechanism, loads: Loads, q):
    """All constraint rows (joints then drivers, redundant ones included) at q."""
    lay = get_layout(mech)
    _, _, row_vals = _element_terms(mech, loads, q, jnp.zeros(lay.m, q.dtype), lay, False)
    out = jnp.zeros(mech.n_rows, q.dtype)
    for rows, val in row_vals:
        out = out.at[np.asarray(rows).reshape(-1)].set(val.reshape(-1))
    return out


def to_internal(mech: Mechanism, q):
    """Public coordinates (p, b) → solver coordinates (P = p + R(b)·c, b), one case."""
    c = jnp.asarray(get_layout(mech).centre[:-1])
    qb = q.reshape(-1, 6)
    rot = jax.vmap(gibbs_to_matrix)(qb[:, 3:])
    return jnp.concatenate([qb[:, :3] + jnp.einsum("pij,pj->pi", rot, c), qb[:, 3:]], 1).ravel()


def to_public(mech: Mechanism, y):
    """Solver coordinates (P, b) → public coordinates (p = P − R(b)·c, b), one case."""
    c = jnp.asarray(get_layout(mech).centre[:-1])
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
        wx = jnp.cross(w, d6[:3])
        step = d6[:3] + c1 * wx + c2 * jnp.cross(w, wx)
        g = c3 * w  # Gibbs vector of the rotation ω
        b_new = (g + b + jnp.cross(g, b)) / (1.0 - g @ b)
        return jnp.concatenate([q6[:3] + step, b_new])

    moved = jax.vmap(one)(q, d).reshape(-1)
    return jnp.concatenate([moved, y[n:] + dy[n:]])
