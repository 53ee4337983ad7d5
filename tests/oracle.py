"""An independent NumPy/SciPy static-equilibrium solver for diffsusp mechanisms (test oracle and
benchmark baseline).

It solves the same physics as `diffsusp.solve_statics` (spec stiffness §1.5–1.9, Adams
conventions of DESIGN.md) with a deliberately different formulation, so that agreement between
the two is evidence that both are right:

- **State**: per moving part, the position p (mm) of its frame origin and its rotation matrix R
  (not a Gibbs vector). Newton increments are (δp, δθ) with δθ a *global* rotation vector:
  R ← expm(skew(δθ)) R (Rodrigues), p ← p + δp. The ground is a virtual part fixed at (0, I).
- **Equations**: per part, force balance ΣF = 0 and moment balance about the part's current
  origin p, ΣM = 0, over bushings, springs, stops, external loads and the joint reactions
  Σ_k λ_k ∇Φ_k; plus the constraint rows Φ(q) = c. The constraint gradients ∇Φ_k (d/dδp, d/dδθ of
  each part) are central finite differences (6th-order stencil) of Φ on rotation matrices, so
  they do not share anything with JAX's autodiff or Gibbs Jacobians. Element forces and moments
  are the closed-form element laws read straight from the Mechanism's arrays.
- **Solver**: damped Newton on (δp, δθ, λ) whose Jacobian is a central finite difference of the
  residual (step 1e-6, times the length scale for translations). Every residual term depends on
  the poses of at most two parts, so the differencing is done element by element on those 12
  coordinates and scattered (the same numbers as differencing the assembled residual, P times
  cheaper); the λ columns are exact (the residual is linear in λ). Rows and columns are scaled
  physically (N, N·mm, mm, rad) and then equilibrated (max-norm rows, then columns). The step
  (rotations capped at 0.5 rad) is backtracked on the merit ½‖r‖² with force rows / F_s,
  moment rows / (F_s·L), constraint rows / L; each trial point is first brought back onto
  the constraints by minimum-norm Gauss–Newton corrections (a second-order correction: it
  stops the constraints' curvature from rejecting good steps far from the solution, and is
  switched off once converged). Converged when every force row < 1e-9·F_s (moment rows
  1e-9·F_s·L) and every constraint row < 1e-11 mm (angular rows 1e-11/L), then 2 polishing
  (full Newton) steps. Multipliers start from least squares at the start pose.
  `method="root"` uses `scipy.optimize.root` (hybr) instead, then the same Newton polish.

Laws (all in the conventions of `diffsusp.model.mechanism`):
- marker x = p + R x0, R_m = R R0 (x0, R0 = global design pose);
- bushing (Adams): δ_T = R_Jᵀ(x_I − x_J), projected angles of R_Jᵀ R_I, e = δ − offset,
  f = −(k e + cubic e³) + preload per axis (or the Akima spline value of e on flagged axes), on I
  at x_I: F_I = R_J f, T_I = R_J t; on J at x_J: −F_I and −T_I − (x_I − x_J) × F_I;
- spring: tension k(ℓ − L0) (or Akima of ℓ − L0) pulling the two seats together;
- stop: penetration (length − ℓ) for a bump stop, (ℓ − length) for rebound, force k p + c p³
  pushing apart (bump) or pulling together (rebound) when p > 0;
- load: force/moment at the load point's marker, components global or in the frame marker's
  current axes;
- joints: Adams rows as in `diffsusp.model.mechanism.Joints`; drivers (x_m − x_m0)·dir − value.
"""

import dataclasses
import os

import numpy as np
import scipy.optimize

# Constraint rows per joint kind and which of them are angular (dimensionless dot products of
# unit axes) rather than lengths (mm). Written from the Adams definitions, not imported.
_ROWS = {
    "spherical": 3, "revolute": 5, "cylindrical": 4, "translational": 5, "universal": 4,
    "fixed": 6, "inline": 2, "inplane": 1, "perpendicular": 1, "distance": 1,
}
_ANGULAR = {
    "spherical": (), "revolute": (3, 4), "cylindrical": (2, 3), "translational": (2, 3, 4),
    "universal": (3,), "fixed": (3, 4, 5), "inline": (), "inplane": (), "perpendicular": (0,),
    "distance": (),
}

_DEBUG = bool(os.environ.get("ORACLE_DEBUG"))

# 6th-order central stencil for a first derivative: f' ≈ Σ w_s f(s h) / h.
_STENCIL = np.array([-3.0, -2.0, -1.0, 1.0, 2.0, 3.0])
_WEIGHTS = np.array([-1.0, 9.0, -45.0, 45.0, -9.0, 1.0]) / 60.0


# ----------------------------------------------------------------------------- rotations


def skew(v):
    """(..., 3) -> (..., 3, 3) with skew(u) @ w = u × w."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape + (3,))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def expm_so3(v):
    """Rodrigues: expm(skew(v)) for rotation vectors v (..., 3) (rad)."""
    v = np.asarray(v, dtype=float)
    theta2 = np.sum(v * v, axis=-1)
    theta = np.sqrt(theta2)
    small = theta < 1e-4
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta2 / 6.0 + theta2**2 / 120.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta2 / 24.0 + theta2**2 / 720.0,
                 (1.0 - np.cos(safe)) / safe**2)
    k = skew(v)
    return np.eye(3) + a[..., None, None] * k + b[..., None, None] * (k @ k)


def rotation_angle(r):
    """Angle (rad) of rotation matrices (..., 3, 3), accurate for small angles."""
    r = np.asarray(r, dtype=float)
    s = 0.5 * np.linalg.norm(
        np.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0],
                  r[..., 1, 0] - r[..., 0, 1]], axis=-1), axis=-1)
    c = 0.5 * (np.trace(r, axis1=-2, axis2=-1) - 1.0)
    return np.arctan2(s, c)


def matrix_to_gibbs(r):
    """Gibbs vector b = vee(R − Rᵀ)/(1 + tr R) = u tan(θ/2) of rotation matrices (..., 3, 3)."""
    r = np.asarray(r, dtype=float)
    num = np.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0],
                    r[..., 1, 0] - r[..., 0, 1]], axis=-1)
    return num / (1.0 + np.trace(r, axis1=-2, axis2=-1))[..., None]


def gibbs_to_matrix(b):
    """Rotation matrices of Gibbs vectors (..., 3) (spec stiffness eq. 4.6), for warm starts."""
    b = np.asarray(b, dtype=float)
    bb = np.sum(b * b, axis=-1)[..., None, None]
    outer = b[..., :, None] * b[..., None, :]
    return ((1.0 - bb) * np.eye(3) + 2.0 * outer + 2.0 * skew(b)) / (1.0 + bb)


def projected_angles(r):
    """Adams projected angles (AX, AY, AZ) of R = R_{I/J} (..., 3, 3) -> (..., 3)."""
    return np.stack([np.arctan2(-r[..., 1, 2], r[..., 2, 2]),
                     np.arctan2(r[..., 0, 2], r[..., 2, 2]),
                     np.arctan2(r[..., 1, 0], r[..., 0, 0])], axis=-1)


# ----------------------------------------------------------------------------- Akima law


def _akima_slopes(x, y):
    """Akima knot slopes (ghost secants 2m0 − m1, 3m0 − 2m1 at each end; the weights
    |m_{i+1} − m_i| carry the same tiny smoothing as diffsusp's documented law)."""
    m = np.diff(y) / np.diff(x)
    if m.size == 1:
        return np.array([m[0], m[0]])
    me = np.concatenate([[3 * m[0] - 2 * m[1], 2 * m[0] - m[1]], m,
                         [2 * m[-1] - m[-2], 3 * m[-1] - 2 * m[-2]]])
    eps = 1e-9 * (np.max(np.abs(m)) + 1.0)
    dm = np.sqrt(np.diff(me) ** 2 + eps**2)
    w1, w2 = dm[2:], dm[:-2]
    return (w1 * me[1:-2] + w2 * me[2:-1]) / (w1 + w2)


def akima(x, y, t):
    """Akima interpolant of the table (x, y) at t (any shape), linear beyond the end knots."""
    x, y, t = np.asarray(x, float), np.asarray(y, float), np.asarray(t, float)
    s = _akima_slopes(x, y)
    i = np.clip(np.searchsorted(x, t, side="right") - 1, 0, x.size - 2)
    h = x[i + 1] - x[i]
    u = np.clip((t - x[i]) / h, 0.0, 1.0)
    inside = ((1 + 2 * u) * (1 - u) ** 2 * y[i] + u * (1 - u) ** 2 * h * s[i]
              + u**2 * (3 - 2 * u) * y[i + 1] + u**2 * (u - 1) * h * s[i + 1])
    return np.where(t < x[0], y[0] + s[0] * (t - x[0]),
                    np.where(t > x[-1], y[-1] + s[-1] * (t - x[-1]), inside))


# ----------------------------------------------------------------------------- model arrays


def _a(x):
    return np.asarray(x, dtype=float)


@dataclasses.dataclass
class _Group:
    """Elements of one kind: marker indices on part a (i) and part b (j), parts, parameters."""

    kind: str
    i: np.ndarray
    j: np.ndarray
    part_a: np.ndarray
    part_b: np.ndarray
    params: dict


class _Model:
    """The Mechanism's arrays as NumPy, grouped per element kind."""

    def __init__(self, mech):
        mk = mech.markers
        self.n_parts = n_parts = len(mech.parts)
        self.x0 = _a(mk.position)
        self.r0 = _a(mk.orientation)
        part = np.asarray(mk.part, dtype=int)
        self.mpart = np.where(part < 0, n_parts, part)  # ground = virtual part n_parts
        self.length = float(mech.length_scale)
        self.n_rows = mech.n_rows
        self.independent = np.asarray(mech.independent_rows, dtype=int)

        def group(kind, i, j, params):
            i, j = np.asarray(i, dtype=int), np.asarray(j, dtype=int)
            return _Group(kind, i, j, self.mpart[i], self.mpart[j], params)

        b = mech.bushings
        self.forces: list[_Group] = []
        if b.names:
            params = {f: _a(getattr(b, f)) for f in (
                "k_trans", "k_rot", "cubic_trans", "cubic_rot", "offset_trans", "offset_rot",
                "preload_force", "preload_torque", "spline_x", "spline_y")}
            params["spline_axes"] = np.asarray(b.spline_axes, dtype=bool).reshape(-1, 6)
            self.forces.append(group("bushing", b.i_marker, b.j_marker, params))
        s = mech.springs
        if s.names:
            self.forces.append(group("spring", s.i_marker, s.j_marker, dict(
                k=_a(s.k), free_length=_a(s.free_length), table_x=_a(s.table_x),
                table_y=_a(s.table_y), tabulated=np.asarray(s.tabulated, dtype=bool))))
        st = mech.stops
        if st.names:
            self.forces.append(group("stop", st.i_marker, st.j_marker, dict(
                length=_a(st.length), k=_a(st.k), cubic=_a(st.cubic),
                bump=np.array([k == "bump" for k in st.kind]))))
        lp = mech.load_points
        self.n_loads = len(lp.names)
        if lp.names:
            frame = np.asarray(lp.frame, dtype=int)
            is_global = frame < 0
            # The frame marker's part is "part b" of a load (the load acts on part a only).
            self.loads = group("load", lp.marker, np.where(is_global, lp.marker, frame),
                               dict(is_global=is_global))
        else:
            self.loads = None

        # Joint rows, grouped by kind; `rows` are the global row numbers (joints then drivers).
        jt = mech.joints
        offsets = np.cumsum([0] + [_ROWS[k] for k in jt.kind])[:-1].astype(int)
        self.constraints: list[_Group] = []
        self.angular = np.zeros(self.n_rows, dtype=bool)
        for kind in _ROWS:
            sel = np.array([k == kind for k in jt.kind], dtype=bool)
            if not sel.any():
                continue
            rows = offsets[sel][:, None] + np.arange(_ROWS[kind])
            for r in _ANGULAR[kind]:
                self.angular[rows[:, r]] = True
            i = np.asarray(jt.i_marker, dtype=int)[sel]
            j = np.asarray(jt.j_marker, dtype=int)[sel]
            self.constraints.append(group(kind, i, j, dict(rows=rows)))
        dv = mech.drivers
        self.n_drivers = len(dv.names)
        if dv.names:
            rows = jt.n_rows + np.arange(len(dv.names))[:, None]
            m = np.asarray(dv.marker, dtype=int)
            self.constraints.append(group("driver", m, m, dict(rows=rows,
                                                               direction=_a(dv.direction))))
        self.live = np.zeros(self.n_rows, dtype=bool)
        self.live[self.independent] = True
        self.slot = -np.ones(self.n_rows, dtype=int)  # row -> multiplier index (or -1)
        self.slot[self.independent] = np.arange(self.independent.size)
        self.angular_live = self.angular[self.independent]


# ----------------------------------------------------------------------------- element laws
#
# Every law takes the poses of its two parts, pa (..., E, 3), ra (..., E, 3, 3), pb, rb, and
# returns per element either a wrench (..., E, 12) = [F_a, M_a about pa, F_b, M_b about pb] or
# constraint rows (..., E, r). Leading axes (perturbations) broadcast.


def _marker(p, r, x0, r0):
    return p + np.einsum("...ij,...j->...i", r, x0), r @ r0


def _wrench(pa, pb, xa, fa, ta, xb, fb, tb):
    return np.concatenate([fa, ta + np.cross(xa - pa, fa), fb, tb + np.cross(xb - pb, fb)],
                          axis=-1)


def _bushing(model, g, pa, ra, pb, rb, ctx):
    prm = g.params
    xi, ri = _marker(pa, ra, model.x0[g.i], model.r0[g.i])
    xj, rj = _marker(pb, rb, model.x0[g.j], model.r0[g.j])
    d = xi - xj
    e_t = np.einsum("...ji,...j->...i", rj, d) - prm["offset_trans"]
    e_r = projected_angles(np.swapaxes(rj, -1, -2) @ ri) - prm["offset_rot"]
    f = -(prm["k_trans"] * e_t + prm["cubic_trans"] * e_t**3) + prm["preload_force"]
    t = -(prm["k_rot"] * e_r + prm["cubic_rot"] * e_r**3) + prm["preload_torque"]
    ft = np.concatenate([np.broadcast_to(f, e_t.shape), np.broadcast_to(t, e_r.shape)], -1)
    if prm["spline_axes"].any():
        ft = ft.copy()
        e = np.concatenate([e_t, e_r], axis=-1)
        for el, axis in zip(*np.nonzero(prm["spline_axes"]), strict=True):
            ft[..., el, axis] = akima(prm["spline_x"][el, axis], prm["spline_y"][el, axis],
                                      e[..., el, axis])
    force = np.einsum("...ij,...j->...i", rj, ft[..., :3])
    torque = np.einsum("...ij,...j->...i", rj, ft[..., 3:])
    return _wrench(pa, pb, xi, force, torque, xj, -force, -torque - np.cross(d, force))


def _line(model, g, pa, ra, pb, rb, tension_of_length):
    xi = pa + np.einsum("...ij,...j->...i", ra, model.x0[g.i])
    xj = pb + np.einsum("...ij,...j->...i", rb, model.x0[g.j])
    u = xj - xi
    length = np.linalg.norm(u, axis=-1)
    f = (tension_of_length(length) / length)[..., None] * u  # on I, toward J
    zero = np.zeros_like(f)
    return _wrench(pa, pb, xi, f, zero, xj, -f, zero)


def _spring(model, g, pa, ra, pb, rb, ctx):
    prm = g.params

    def tension(length):
        stretch = length - prm["free_length"]
        out = prm["k"] * stretch
        if prm["tabulated"].any():
            out = out.copy()
            for el in np.flatnonzero(prm["tabulated"]):
                out[..., el] = akima(prm["table_x"][el], prm["table_y"][el], stretch[..., el])
        return out

    return _line(model, g, pa, ra, pb, rb, tension)


def _stop(model, g, pa, ra, pb, rb, ctx):
    prm = g.params

    def tension(length):
        pen = np.where(prm["bump"], prm["length"] - length, length - prm["length"])
        pen = np.maximum(pen, 0.0)
        force = prm["k"] * pen + prm["cubic"] * pen**3
        return np.where(prm["bump"], -force, force)

    return _line(model, g, pa, ra, pb, rb, tension)


def _load(model, g, pa, ra, pb, rb, ctx):
    force, moment = ctx["force"], ctx["moment"]  # (E, 3) in the load point's frame
    xm = pa + np.einsum("...ij,...j->...i", ra, model.x0[g.i])
    radius = g.params.get("contact_radius")
    if radius is not None:  # the ground contact point of a wheel about the marker (spin = z)
        s = np.einsum("...ij,...j->...i", ra, model.r0[g.i][:, :, 2])
        v = np.array([0.0, 0.0, 1.0]) - s[..., 2:3] * s
        n = np.linalg.norm(v, axis=-1, keepdims=True)
        xm = xm - radius[:, None] * v / np.where(n > 0, n, 1.0)
    frame = rb @ model.r0[g.j]
    is_global = g.params["is_global"][:, None]
    f = np.where(is_global, force, np.einsum("...ij,...j->...i", frame, force))
    t = np.where(is_global, moment, np.einsum("...ij,...j->...i", frame, moment))
    zero = np.zeros_like(f)
    return _wrench(pa, pb, xm, f, t, xm, zero, zero)


def _joint_rows(kind, model, g, pa, ra, pb, rb, ctx):
    """Adams joint rows; d = x_I − x_J, axes are the columns of R_m."""
    xi, ri = _marker(pa, ra, model.x0[g.i], model.r0[g.i])
    xj, rj = _marker(pb, rb, model.x0[g.j], model.r0[g.j])
    d = xi - xj

    def dot(u, v):
        return np.sum(u * v, axis=-1)

    xi_, zi_ = ri[..., :, 0], ri[..., :, 2]
    xj_, yj_, zj_ = rj[..., :, 0], rj[..., :, 1], rj[..., :, 2]
    if kind == "spherical":
        rows = [d[..., 0], d[..., 1], d[..., 2]]
    elif kind == "revolute":
        rows = [d[..., 0], d[..., 1], d[..., 2], dot(zi_, xj_), dot(zi_, yj_)]
    elif kind == "cylindrical":
        rows = [dot(d, xj_), dot(d, yj_), dot(zi_, xj_), dot(zi_, yj_)]
    elif kind == "translational":
        rows = [dot(d, xj_), dot(d, yj_), dot(zi_, xj_), dot(zi_, yj_), dot(xi_, yj_)]
    elif kind == "universal":
        rows = [d[..., 0], d[..., 1], d[..., 2], dot(zi_, zj_)]
    elif kind == "fixed":
        rows = [d[..., 0], d[..., 1], d[..., 2], dot(zi_, xj_), dot(zi_, yj_), dot(xi_, yj_)]
    elif kind == "inline":
        rows = [dot(d, xj_), dot(d, yj_)]
    elif kind == "inplane":
        rows = [dot(d, zj_)]
    elif kind == "perpendicular":
        rows = [dot(zi_, zj_)]
    elif kind == "distance":
        d0 = model.x0[g.i] - model.x0[g.j]
        rows = [np.linalg.norm(d, axis=-1) - np.linalg.norm(d0, axis=-1)]
    else:
        raise ValueError(f"oracle: unknown joint kind '{kind}'")
    return np.stack(rows, axis=-1)


def _driver_rows(model, g, pa, ra, pb, rb, ctx):
    xm = pa + np.einsum("...ij,...j->...i", ra, model.x0[g.i])
    travel = np.sum((xm - model.x0[g.i]) * g.params["direction"], axis=-1)
    return (travel - ctx["driver"])[..., None]


_FORCE_LAWS = {"bushing": _bushing, "spring": _spring, "stop": _stop, "load": _load}


def _rows_fn(g):
    if g.kind == "driver":
        return _driver_rows
    return lambda *args: _joint_rows(g.kind, *args)


# ----------------------------------------------------------------------------- perturbations


class _Directions:
    """Local increments (K, 12) = (δp_a, δθ_a, δp_b, δθ_b) and their rotations expm(skew(δθ))."""

    def __init__(self, dirs):
        self.dirs = dirs
        self.rot_a = expm_so3(dirs[:, 3:6])
        self.rot_b = expm_so3(dirs[:, 9:12])


def _perturb(pa, ra, pb, rb, d: _Directions):
    """Poses moved by the local increments of `d`: arrays with a new leading axis K
    (rotations R ← expm(skew(δθ)) R with global δθ)."""
    extra = (slice(None),) + (None,) * (pa.ndim - 1)
    return (pa[None] + d.dirs[:, 0:3][extra], d.rot_a[extra] @ ra[None],
            pb[None] + d.dirs[:, 6:9][extra], d.rot_b[extra] @ rb[None])


def _stencil_dirs(steps, points):
    """Directions (12·len(points), 12): each local coordinate c moved by points·steps[c]."""
    eye = np.eye(12) * steps[:, None]
    return (points[None, :, None] * eye[:, None, :]).reshape(-1, 12)


class _Oracle:
    """Residual and Jacobian of the equilibrium in (δp, δθ, λ) for one mechanism."""

    def __init__(self, mech, *, h_constraint=1e-2, h_jacobian=1e-6):
        self.mech = mech
        self.model = m = _Model(mech)
        L = m.length
        # Inner FD (constraint gradients, 6th-order stencil): rotations 1e-2 rad, translations
        # 1e-3·L mm. Truncation ~h⁶/140 relative (1e-14), round-off ~eps·|x|/h (~1e-12).
        self.h_in = np.tile(np.r_[np.full(3, 0.1 * h_constraint * L), np.full(3, h_constraint)],
                            2)
        # Outer FD (Newton Jacobian): 1e-6 scaled.
        self.h_out = np.tile(np.r_[np.full(3, h_jacobian * L), np.full(3, h_jacobian)], 2)
        self.inner = _Directions(_stencil_dirs(self.h_in, _STENCIL))  # (12·6, 12)
        self.outer = _Directions(_stencil_dirs(self.h_out, np.array([-1.0, 1.0])))  # (24, 12)
        self.n = 6 * m.n_parts
        self.n_mult = m.independent.size

    # -- local views ----------------------------------------------------------------------

    def _local(self, p, r, g):
        return p[g.part_a], r[g.part_a], p[g.part_b], r[g.part_b]

    @staticmethod
    def _full(p, r):
        """Append the ground (p = 0, R = I) as the virtual last part."""
        return np.vstack([p, np.zeros((1, 3))]), np.concatenate([r, np.eye(3)[None]], axis=0)

    def _row_gradients(self, g, local, ctx):
        """Rows Φ (..., E, r) and their gradients (..., E, r, 12) in (δp, δθ) of the two parts,
        by the 6th-order central stencil."""
        fn = _rows_fn(g)
        k = _STENCIL.size
        pert = _perturb(*local, self.inner)  # 12 k perturbations
        vals = fn(self.model, g, *pert, ctx)  # (12 k, ..., E, r)
        vals = vals.reshape((12, k) + vals.shape[1:])
        grad = np.tensordot(_WEIGHTS, vals, axes=([0], [1]))  # (12, ..., E, r)
        grad = grad / self.h_in.reshape((12,) + (1,) * (grad.ndim - 1))
        return fn(self.model, g, *local, ctx), np.moveaxis(grad, 0, -1)

    # -- element contributions --------------------------------------------------------------

    def _terms(self, p, r, lam_rows, ctx, local_dirs=None):
        """Per element group: (coordinate indices (E, 12), generalised forces (..., E, 12),
        constraint row indices (E, r) or None, rows (..., E, r) or None, row gradients or
        None). With `local_dirs` (K, 12), every value has a leading axis K: the element's two
        parts moved by those increments (for the Jacobian)."""
        m = self.model
        p, r = self._full(p, r)
        six = np.arange(6)
        out = []
        groups = [(g, True) for g in m.forces]
        if m.loads is not None:
            groups.append((m.loads, True))
        groups += [(g, False) for g in m.constraints]
        for g, is_force in groups:
            idx = np.concatenate([6 * g.part_a[:, None] + six, 6 * g.part_b[:, None] + six], 1)
            local = self._local(p, r, g)
            if local_dirs is not None:
                local = _perturb(*local, local_dirs)
            if is_force:
                out.append((idx, _FORCE_LAWS[g.kind](m, g, *local, ctx), None, None, None))
            else:
                rows_idx = g.params["rows"]
                vals, grads = self._row_gradients(g, local, ctx)
                lam = lam_rows[rows_idx]  # (E, r)
                gen = np.einsum("...erc,er->...ec", grads, lam)
                out.append((idx, gen, rows_idx, vals, grads))
        return out

    def constraints(self, p, r, driver):
        """Live constraint rows Φ − c (m,) and their gradients (m, 6P) in (δp, δθ)."""
        m = self.model
        pf, rf = self._full(p, r)
        values = np.zeros(self.n_mult)
        jac = np.zeros((self.n_mult, self.n + 6))
        six = np.arange(6)
        for g in m.constraints:
            idx = np.concatenate([6 * g.part_a[:, None] + six, 6 * g.part_b[:, None] + six], 1)
            vals, grads = self._row_gradients(g, self._local(pf, rf, g), dict(driver=driver))
            slots = m.slot[g.params["rows"]]
            live = slots >= 0
            values[slots[live]] = vals[live]
            _scatter(jac, slots[:, :, None], idx[:, None, :], grads, live[:, :, None])
        return values, jac[:, :self.n]

    def residual(self, p, r, lam, force, moment, driver, *, with_jacobian=False):
        """Residual (6P + m,): [ΣF, ΣM about p per part; live constraint rows − c], optionally
        its Jacobian in (δp, δθ, λ), and per coordinate the sum of |element generalised forces|
        (for the load scale)."""
        m = self.model
        n, base = self.n, self.n + 6  # the ground's 6 slots n..n+5 are dropped at the end
        size = base + self.n_mult
        keep = np.r_[np.arange(n), base + np.arange(self.n_mult)]
        lam_rows = np.zeros(m.n_rows)
        lam_rows[m.independent] = lam
        ctx = dict(force=force, moment=moment, driver=driver)
        res = np.zeros(size)
        elastic = np.zeros(size)
        terms = self._terms(p, r, lam_rows, ctx)
        for idx, gen, rows_idx, vals, _ in terms:
            np.add.at(res, idx, gen)
            if rows_idx is None:
                np.add.at(elastic, idx, np.abs(gen))
            else:
                slots = m.slot[rows_idx]
                res[base + slots[slots >= 0]] = vals[slots >= 0]
        if not with_jacobian:
            return res[keep], None, elastic[:n]
        jac = np.zeros((size, size))
        pert = self._terms(p, r, lam_rows, ctx, local_dirs=self.outer)  # −h, +h per coordinate
        two_h = 2 * self.h_out[:, None, None]
        for (idx, _, rows_idx, _, grads), (_, gen_p, _, vals_p, _) in zip(terms, pert,
                                                                           strict=True):
            d_gen = (gen_p[1::2] - gen_p[0::2]) / two_h  # (12 directions, E, 12)
            _scatter(jac, idx[:, :, None], idx[:, None, :], np.moveaxis(d_gen, 0, -1))
            if rows_idx is None:
                continue
            d_rows = (vals_p[1::2] - vals_p[0::2]) / two_h  # (12, E, r)
            slots = m.slot[rows_idx]  # (E, r), −1 for dropped rows
            live = slots >= 0
            _scatter(jac, base + slots[:, :, None], idx[:, None, :],
                     np.moveaxis(d_rows, 0, -1), live[:, :, None])
            # λ columns are exact: the residual is linear in λ (∂r/∂λ_k = ∇Φ_k).
            _scatter(jac, idx[:, :, None], base + slots[:, None, :],
                     np.swapaxes(grads, 1, 2), live[:, None, :])
        return res[keep], jac[np.ix_(keep, keep)], elastic[:n]


def _scatter(jac, rows, cols, vals, live=None):
    rows, cols, vals = np.broadcast_arrays(rows, cols, vals)
    if live is not None:
        live = np.broadcast_to(live, rows.shape)
        rows, cols, vals = rows[live], cols[live], vals[live]
    np.add.at(jac, (rows.ravel(), cols.ravel()), vals.ravel())


# ----------------------------------------------------------------------------- solver


@dataclasses.dataclass
class OracleSolution:
    """An equilibrium found by the oracle.

    **Fields:** `p` (P, 3) part origins (mm, global); `R` (P, 3, 3) part rotations from design;
    `lam` (m,) multipliers of `mech.independent_rows` (N for length rows, N·mm for angular
    rows; same row functions as diffsusp, so the same multipliers); `iterations` (Newton steps,
    polish included); `residual` (largest force row / F_s, moment rows / (F_s·L));
    `constraint_error` (largest constraint row, mm; angular rows × L); `load_scale` F_s (N);
    `converged`.
    """

    p: np.ndarray
    R: np.ndarray
    lam: np.ndarray
    iterations: int
    residual: float
    constraint_error: float
    load_scale: float
    converged: bool

    def q(self) -> np.ndarray:
        """diffsusp's coordinates: per part (p, Gibbs vector b of R), flattened (6P,)."""
        return to_q(self.p, self.R)


def to_q(p, R) -> np.ndarray:
    """(p, R) -> diffsusp q (6P,): p and b = vee(R − Rᵀ)/(1 + tr R) per part."""
    p, R = np.asarray(p, float), np.asarray(R, float)
    return np.concatenate([p, matrix_to_gibbs(R)], axis=1).reshape(-1)


def from_q(q) -> tuple[np.ndarray, np.ndarray]:
    """diffsusp q (6P,) -> (p (P, 3), R (P, 3, 3))."""
    q = np.asarray(q, float).reshape(-1, 6)
    return q[:, :3].copy(), gibbs_to_matrix(q[:, 3:])


def marker_poses(mech, p, R) -> tuple[np.ndarray, np.ndarray]:
    """Global positions (M, 3) (mm) and orientations (M, 3, 3) of every marker."""
    m = _oracle(mech).model
    pf, rf = _Oracle._full(np.asarray(p, float), np.asarray(R, float))
    return _marker(pf[m.mpart], rf[m.mpart], m.x0, m.r0)


_ORACLES: dict[int, _Oracle] = {}


def _oracle(mech) -> _Oracle:
    key = id(mech)
    if key not in _ORACLES or _ORACLES[key].mech is not mech:
        _ORACLES[key] = _Oracle(mech)
    return _ORACLES[key]


def _scales(orc: _Oracle, res, elastic, force, moment, lam):
    """Load scale F_s (N: the largest external load, element force or reaction, moments / L)
    and the row scales that make every row of the residual comparable: force rows 1/F_s,
    moment rows 1/(F_s·L), length constraint rows 1 (mm), angular constraint rows L."""
    m = orc.model
    L = m.length
    rot = np.tile(np.r_[np.zeros(3), np.ones(3)], m.n_parts).astype(bool)
    lam_len = np.abs(lam[~m.angular_live]) if lam.size else np.zeros(0)
    lam_ang = np.abs(lam[m.angular_live]) / L if lam.size else np.zeros(0)
    f_scale = 1.0 + max(
        np.max(np.abs(force), initial=0.0), np.max(np.abs(moment), initial=0.0) / L,
        np.max(elastic[~rot], initial=0.0), np.max(elastic[rot], initial=0.0) / L,
        np.max(lam_len, initial=0.0), np.max(lam_ang, initial=0.0))
    row_force = np.where(rot, 1.0 / (f_scale * L), 1.0 / f_scale)
    row_con = np.where(m.angular_live, L, 1.0)
    return f_scale, np.r_[row_force, row_con]


def _measures(orc, res, row):
    n = orc.n
    force = np.max(np.abs(res[:n] * row[:n]), initial=0.0)
    con = np.max(np.abs(res[n:] * row[n:]), initial=0.0)
    return force, con


def _apply(orc, p, r, lam, dx):
    n_parts = orc.model.n_parts
    d = dx[:orc.n].reshape(n_parts, 6)
    return p + d[:, :3], expm_so3(d[:, 3:]) @ r, lam + dx[orc.n:]


def _col_scale(orc, f_scale):
    m = orc.model
    L = m.length
    return np.r_[np.tile(np.r_[np.full(3, L), np.ones(3)], m.n_parts),
                 np.where(m.angular_live, f_scale * L, f_scale)]


def _newton_step(orc, jac, res, row, col):
    """Solve the scaled KKT system: physical scaling, then row/column max-norm equilibration."""
    a = jac * row[:, None] * col[None, :]
    d_r = 1.0 / np.maximum(np.max(np.abs(a), axis=1), 1e-300)
    a = a * d_r[:, None]
    d_c = 1.0 / np.maximum(np.max(np.abs(a), axis=0), 1e-300)
    a = a * d_c[None, :]
    return col * d_c * np.linalg.solve(a, -(d_r * row * res))


def _project(orc, p, r, driver, atol, iterations=4):
    """Restore the constraints after a trial step: minimum-norm Gauss–Newton corrections
    (translations measured in units of L) until every row is below `atol`. Used by the line
    search only (a second-order correction): it leaves the equations and the Newton step as
    they are. Returns None if the rows do not decrease."""
    if not orc.n_mult:
        return p, r
    L = orc.model.length
    weight = np.where(orc.model.angular_live, L, 1.0)
    col = np.tile(np.r_[np.full(3, L), np.ones(3)], orc.model.n_parts)
    error = np.inf
    for _ in range(iterations):
        values, jac = orc.constraints(p, r, driver)
        new_error = np.max(np.abs(values * weight))
        if new_error <= atol:
            return p, r
        if not new_error < 0.5 * error:
            return None
        error = new_error
        a = jac * col[None, :]
        dx = -col * (a.T @ np.linalg.solve(a @ a.T, values))
        p, r, _ = _apply(orc, p, r, np.zeros(0), dx)
    values, _ = orc.constraints(p, r, driver)
    return (p, r) if np.max(np.abs(values * weight)) <= max(atol, 1e-3 * error) else None


def _initial_multipliers(orc, p, r, force, moment, driver):
    """λ minimising the scaled force residual at the start pose (least squares)."""
    if not orc.n_mult:
        return np.zeros(0)
    lam = np.zeros(orc.n_mult)
    res, _, elastic = orc.residual(p, r, lam, force, moment, driver)
    f_scale, row = _scales(orc, res, elastic, force, moment, lam)
    col = _col_scale(orc, f_scale)[orc.n:]
    grad = orc.constraints(p, r, driver)[1]  # ∂r_q/∂λ = ∇Φᵀ
    a = grad.T * row[:orc.n, None] * col[None, :]
    sol, *_ = np.linalg.lstsq(a, -(row[:orc.n] * res[:orc.n]), rcond=None)
    return sol * col


def solve(mech, force, moment, driver, q0=None, *, lam0=None, method: str = "newton",
          rtol: float = 1e-9, atol: float = 1e-11, max_steps: int = 60, polish: int = 2,
          throw: bool = True, contact_radius=None) -> OracleSolution:
    """Static equilibrium of `mech` under one load case, by the independent NumPy formulation.

    **Arguments:**
    - `mech`: a diffsusp `Mechanism` (its arrays are read with `np.asarray`).
    - `force`, `moment`: (l, 3) per load point (N, N·mm), in the load point's frame.
    - `driver`: (d,) driver values (mm).
    - `q0`: warm start: an `OracleSolution`, a (p, R) tuple, or diffsusp coordinates q (6P,).
      Default: the design position. If Newton stagnates from a warm start, it starts again
      from the design position (the iterations of both attempts are counted).
    - `lam0`: start multipliers (default: least squares at the start pose; an `OracleSolution`
      warm start brings its own).
    - `method`: "newton" (default) or "root" (`scipy.optimize.root`, hybr, then the Newton
      polish).
    - `rtol`: force rows below rtol·F_s (moments rtol·F_s·L); `atol`: constraint rows (mm).
    - `polish`: Newton steps taken after convergence.
    - `contact_radius`: (l,) per load point (mm) or None: where > 0 the load point's force acts
      at the lowest point (along +z) of the circle of that radius about its marker in the plane
      normal to the marker's z axis (`diffsusp.model.Loads.contact_radius`).

    **Returns:** an `OracleSolution`.
    """
    orc = _oracle(mech)
    m = orc.model
    if m.loads is not None:
        m.loads.params.pop("contact_radius", None)
        if contact_radius is not None and np.any(np.asarray(contact_radius) != 0):
            m.loads.params["contact_radius"] = np.asarray(contact_radius, float).reshape(-1)
    force = np.asarray(force, float).reshape(m.n_loads, 3)
    moment = np.asarray(moment, float).reshape(m.n_loads, 3)
    driver = np.asarray(driver, float).reshape(m.n_drivers)
    if q0 is None:
        p, r = np.zeros((m.n_parts, 3)), np.tile(np.eye(3), (m.n_parts, 1, 1))
    elif isinstance(q0, OracleSolution):
        p, r = q0.p.copy(), q0.R.copy()
        lam0 = q0.lam.copy() if lam0 is None else lam0
    elif isinstance(q0, tuple):
        p, r = np.asarray(q0[0], float).copy(), np.asarray(q0[1], float).copy()
    else:
        p, r = from_q(q0)
    lam = (_initial_multipliers(orc, p, r, force, moment, driver) if lam0 is None
           else np.asarray(lam0, float).copy())
    args = (force, moment, driver)
    evaluations = 0
    if method == "root":
        p, r, lam, evaluations = _root(orc, p, r, lam, args)
    elif method != "newton":
        raise ValueError(f"method must be 'newton' or 'root'; got '{method}'.")
    out = _newton(orc, p, r, lam, args, rtol, atol, max_steps, polish)
    if not out.converged and q0 is not None:
        # A warm start far from this case's equilibrium can lead Newton towards a singular
        # configuration: start again from the design position.
        p0, r0 = np.zeros((m.n_parts, 3)), np.tile(np.eye(3), (m.n_parts, 1, 1))
        lam0 = _initial_multipliers(orc, p0, r0, *args)
        retry = _newton(orc, p0, r0, lam0, args, rtol, atol, max_steps, polish)
        retry.iterations += out.iterations
        out = retry
    out.iterations += evaluations
    if throw and not out.converged:
        raise RuntimeError(
            f"oracle: no convergence in {max_steps} steps (force residual "
            f"{out.residual:.3g}·F_s, constraint {out.constraint_error:.3g} mm).")
    return out


def _newton(orc, p, r, lam, args, rtol, atol, max_steps, polish) -> OracleSolution:
    force, moment, driver = args
    res, jac, elastic = orc.residual(p, r, lam, *args, with_jacobian=True)
    # Merit weights fixed for the whole solve (so the merit is one function that every step
    # decreases): forces / F_s at the start, moments / (F_s·L), constraints / L.
    _, row0 = _scales(orc, res, elastic, force, moment, lam)
    weight = np.r_[row0[:orc.n], row0[orc.n:] / orc.model.length]
    steps, converged_at, merits = 0, None, []
    while True:
        f_scale, row = _scales(orc, res, elastic, force, moment, lam)
        f_err, c_err = _measures(orc, res, row)
        if converged_at is None and f_err <= rtol and c_err <= atol:
            converged_at = steps
        if converged_at is not None and steps - converged_at >= polish:
            break
        if steps >= max_steps + polish:
            break
        col = _col_scale(orc, f_scale)
        dx = _newton_step(orc, jac, res, row, col)
        rot = np.abs(dx[:orc.n].reshape(-1, 6)[:, 3:])
        cap = max(np.max(rot, initial=0.0) / 0.5, 1.0)  # no rotation step above 0.5 rad
        dx = dx / cap
        merit0 = 0.5 * np.sum((res * weight) ** 2)
        merits.append(merit0)
        if converged_at is None and len(merits) > 8 and merit0 > 0.9 * merits[-9]:
            break  # stagnating (heading for a singular configuration): give up
        alpha = 1.0
        for _ in range(30):
            trial = _apply(orc, p, r, lam, alpha * dx)
            if converged_at is None:
                projected = _project(orc, trial[0], trial[1], driver, atol)
                if projected is not None:
                    trial = (*projected, trial[2])
            res_t, _, _ = orc.residual(*trial, *args)
            merit = 0.5 * np.sum((res_t * weight) ** 2)
            # Past convergence (polish) the merit is at round-off: take the full step.
            if converged_at is not None or (np.isfinite(merit)
                                            and merit <= (1 - 1e-4 * alpha) * merit0):
                break
            alpha *= 0.5
        p, r, lam = trial
        if _DEBUG:
            print(f"step {steps}: force {f_err:.2e} constraint {c_err:.2e} cap {cap:.2f} "
                  f"alpha {alpha:.2e} merit {merit0:.2e} -> {merit:.2e}")
        # Re-orthonormalise R (products of rotations drift by ~1e-16 per step).
        u, _, vt = np.linalg.svd(r)
        r = u @ vt
        steps += 1
        res, jac, elastic = orc.residual(p, r, lam, *args, with_jacobian=True)

    f_scale, row = _scales(orc, res, elastic, force, moment, lam)
    f_err, c_err = _measures(orc, res, row)
    return OracleSolution(p=p, R=r, lam=lam, iterations=steps, residual=f_err,
                          constraint_error=c_err, load_scale=f_scale,
                          converged=converged_at is not None)


def _root(orc, p0, r0, lam0, args):
    """scipy.optimize.root (hybr) in scaled coordinates: x = (p − p0)/L, rotation vector θ with
    R = expm(skew(θ)) R0, λ / scale."""
    res, _, elastic = orc.residual(p0, r0, lam0, *args)
    f_scale, row = _scales(orc, res, elastic, args[0], args[1], lam0)
    col = _col_scale(orc, f_scale)

    def unpack(x):
        return _apply(orc, p0, r0, lam0, x * col)

    def fun(x):
        return orc.residual(*unpack(x), *args)[0] * row

    sol = scipy.optimize.root(fun, np.zeros(col.size), method="hybr",
                              options=dict(xtol=1e-13, maxfev=200 * (col.size + 1)))
    p, r, lam = unpack(sol.x)
    return p, r, lam, int(sol.nfev)


def constraint_jacobian(mech, p, R) -> np.ndarray:
    """∇Φ of the live rows (m, 6P) in (δp, δθ) per part (finite differences, as in the solve)."""
    orc = _oracle(mech)
    driver = np.zeros(orc.model.n_drivers)
    return orc.constraints(np.asarray(p, float), np.asarray(R, float), driver)[1]


def reactions(mech, p, R, lam) -> np.ndarray:
    """Joint and driver reactions Σ λ_k ∇Φ_k per part (P, 6): force (N) and moment about the
    part origin (N·mm), global components."""
    return (constraint_jacobian(mech, p, R).T @ np.asarray(lam, float)).reshape(-1, 6)


def bushing_deformations(mech, p, R) -> tuple[np.ndarray, np.ndarray]:
    """Bushing deformations of I relative to J in J: δ_T (n, 3) mm, projected angles (n, 3)
    rad."""
    b = mech.bushings
    x, rm = marker_poses(mech, p, R)
    i, j = np.asarray(b.i_marker, dtype=int), np.asarray(b.j_marker, dtype=int)
    rj_t = np.swapaxes(rm[j], -1, -2)
    return (np.einsum("nij,nj->ni", rj_t, x[i] - x[j]), projected_angles(rj_t @ rm[i]))


def solve_loads(mech, loads, *, chain: bool = False, **kwargs) -> list[OracleSolution]:
    """Every case of a diffsusp `Loads` table (leading case axis), one after the other; with
    `chain`, each case starts from the previous solution (a sweep). Keyword arguments go to
    `solve`."""
    force, moment = np.asarray(loads.force, float), np.asarray(loads.moment, float)
    driver = np.asarray(loads.driver, float)
    sols: list[OracleSolution] = []
    for c in range(force.shape[0]):
        warm = sols[-1] if (chain and sols) else None
        sols.append(solve(mech, force[c], moment[c], driver[c], q0=warm, **kwargs))
    return sols
