"""The tyre on the K&C rig: contact-patch forces from a tyre model whose slip angle and
inclination follow the suspension's compliance (spec: tyre §7 C).

A force rig (`diffsusp.kc.force_rig`: the wheel free, loaded at its contact point) with the
contact-patch force no longer prescribed but produced by a Magic Formula tyre (`MagicFormula6`,
spec: tyre §7 C) running at a commanded slip angle α_cmd, slip ratio κ and vertical load F_z on
a flat road. The force deflects the suspension (compliance steer and camber), which changes the
tyre's slip angle and inclination, which changes the force: a coupled static equilibrium.

**The equilibrium.** Unknown: the wrench w the road applies to the wheel, global components at
the load point the rig loads (horizontal force along the vehicle's forward and outboard axes,
and the moment: 5 numbers per case; the vertical force is the commanded F_z). For a given w,
q(w) is the suspension's equilibrium under w (as `diffsusp.solve_statics` would find it), and
the tyre closes the loop:

    g(w) = w − T(q(w)) = 0,     T(q) = the tyre's wrench at the slip and inclination of pose q.

Solved as one system: the suspension's KKT residual r(y; w) = 0 (y = solver coordinates and
multipliers, `diffsusp.statics.residual`) together with g, by Newton's method
(`optimistix.root_find` with `optx.Newton`), vmapped over cases, from the design pose and the
rigid-suspension guess w₀ = T(design). This is the same root as the nested form (Newton on g
with q(w) from `solve_statics` and ∂q/∂w from its implicit derivative) but one loop: the nested
form nests two Newton loops in one program (XLA compile 42 s against 29 s for a one-part
wheel on the project's loaded 2-core machine) for the same answers. Newton's Jacobian is exact:
∂r/∂y is the statics' own assembled KKT Jacobian (`linearize_internal`, through a custom JVP
rule), ∂r/∂w and the tyre rows by forward-mode autodiff. The root is differentiated
implicitly (`optx.ImplicitAdjoint`, the default): `jax.jvp`/`jax.jacfwd`/`jax.grad` of any
output with respect to any float leaf of the mechanism (bushing stiffnesses, hardpoints), of
the tyre (coefficients) or of the inputs are exact, neither unrolled nor finite differences.
No line search: from the rigid guess the coupled system converges in 3–7 steps on the
pseudo-McPherson; a case that does not converge in `max_steps` is reported
(`diffsusp.statics.Status.MAX_STEPS`).

**Axes and signs** (stated once here; every field of `TyreRigSolution` follows them):

- The tyre works in ISO-W (TYDEX W, as the `.tir` files and `diffsusp.tyre.mf6`): origin at
  the contact point, x = heading h (the intersection of the wheel plane with the road plane,
  forward), z = up (the road normal; the road is the model's horizontal ground plane), y = ℓ =
  z × x (to the left of the heading). Forces and moments are those the road exerts on the tyre.
  With these axes the `.tir` files' cornering stiffness K_yα = ∂F_y/∂α is *negative*: a
  positive slip angle pushes the tyre to its right.
- Slip angle (ISO-W): the angle from the heading to the wheel's velocity over the road, about
  +z. The road's direction is fixed by the command: α = α_cmd at the design pose, so with the
  steer angle ψ(q) (the K&C `steer`: yaw of the heading about up, left turn positive)
  α = α_cmd − (ψ(q) − ψ(design)). Static toe is therefore not part of α (add −ψ(design),
  returned as `design_steer`, to α_cmd to measure the command from the vehicle's x axis).
- Inclination (ISO-W): the right-hand rotation of the wheel plane about the heading, i.e. top
  of the wheel to the right of the heading positive: γ = σ·(camber(q) + camber_offset), with
  the K&C camber (top outboard positive) and σ = +1 for a right wheel, −1 for a left one. The
  static camber is part of γ (the road is fixed); `camber_offset` (rad, K&C sense) adds e.g. a
  road camber or a rig tilt.
- Slip ratio κ and F_z are commanded (κ is a wheel-speed quantity the statics does not change;
  F_z is the force rig's vertical load, N, up).
- K&C toe, camber and steer: `diffsusp.kc.metrics` (Adams/Car, per side).

**Where the wrench acts** (`longitudinal_at`): 'contact_patch' (default, as `kc.braking`): the
whole tyre wrench acts on the wheel carrier at the corner's contact-patch load point (the
wheel is locked to the carrier: the moment about the spin axis — brake torque — is reacted by
the carrier). 'wheel_centre' (as `kc.traction`): the torque about the spin axis is reacted by
the body through a drive shaft, so the carrier receives, at the wheel-centre load point, the
tyre force and the tyre moment transported there, minus its component along the spin axis.

Units at this interface: F_z, forces N; moments N·mm; angles rad; lengths mm (the statics);
the tyre's own units are those of `diffsusp.tyre.mf6` (N, N·mm, rad, mm/s, Pa).

```python
import jax.numpy as jnp
from diffsusp import tyre
from diffsusp.io.tir import read_tir
from diffsusp.models import pseudo_mcpherson
model = tyre.MagicFormula6.from_tir(read_tir(tyre.example_path("mf61")))
rig = tyre.rig.tyre_rig(pseudo_mcpherson(), model)
sol = tyre.rig.solve(rig, slip_angle=jnp.radians(jnp.array([-2.0, 1.0, 4.0])), fz=4500.0)
sol.forces.fy, sol.forces.mz, sol.slip_angle, sol.toe
```
"""

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, ArrayLike, Float, Int

from ..errors import ConvergenceError, InputError
from ..kc import ResolvedCorner, corner_geometry, force_rig
from ..model import Loads, Mechanism
from ..statics import (
    STATUS_TEXT,
    Status,
    linearize,
    linearize_internal,
    marker_poses,
    residual,
    to_public,
)
from .mf6 import MagicFormula6, TyreForces, evaluate

__all__ = ["TyreRig", "TyreRigSolution", "tyre_rig", "solve"]


class TyreRig(eqx.Module):
    """A suspension corner on a force rig with a tyre at its contact patch (`tyre_rig`).

    **Fields:** `mech` (the rig's mechanism: wheel drivers removed, as `kc.force_rig`), `tyre`
    (`MagicFormula6`), static `corner` (`ResolvedCorner`), `driven` (1.0: the wrench acts at
    the wheel centre, `longitudinal_at='wheel_centre'`; 0.0: at the contact patch; a float leaf,
    not a static switch, so that both modes of one mechanism share one compiled program),
    `combined` and `limits` (as `mf6.evaluate`). `longitudinal_at` (property) names the mode of
    a concrete rig. Every float leaf of `mech` and `tyre` can be differentiated.
    """

    mech: Mechanism
    tyre: MagicFormula6
    corner: ResolvedCorner = eqx.field(static=True)
    driven: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(0.0))
    combined: bool = eqx.field(static=True, default=True)
    limits: bool = eqx.field(static=True, default=True)

    @property
    def longitudinal_at(self) -> str:
        return "wheel_centre" if float(self.driven) else "contact_patch"


class TyreRigSolution(eqx.Module):
    """The coupled equilibria of `solve`, per case (leading axis), axes and signs of the module
    docstring.

    **Fields:**

    - `forces`: `TyreForces` of the tyre at equilibrium, ISO-W: fx, fy [N]; mx, my, mz [N·mm];
    - `slip_angle`, `inclination` [rad]: the tyre's α and γ (ISO-W) at equilibrium;
    - `toe`, `camber`, `steer` [rad]: K&C metrics of the corner at equilibrium;
      `design_steer` [rad]: the steer angle at design (ψ(design));
    - `force`, `moment`: the wrench on the wheel carrier, global components, at the load point
      named by `longitudinal_at` (N, N·mm; F_z included);
    - `q`: the suspension's public coordinates; `status` (`diffsusp.statics.Status` codes),
      `iterations` (Newton steps).
    """

    forces: TyreForces
    slip_angle: Float[Array, " cases"]
    inclination: Float[Array, " cases"]
    toe: Float[Array, " cases"]
    camber: Float[Array, " cases"]
    steer: Float[Array, " cases"]
    design_steer: Float[Array, ""]
    force: Float[Array, "cases 3"]
    moment: Float[Array, "cases 3"]
    q: Float[Array, "cases n"]
    status: Int[Array, " cases"]
    iterations: Int[Array, " cases"]


def tyre_rig(mech: Mechanism, tyre: MagicFormula6, *, corner=None,
             longitudinal_at: str = "contact_patch", combined: bool = True,
             limits: bool = True) -> TyreRig:
    """Put `mech`'s wheel on a force rig with `tyre` at its contact patch.

    **Arguments:** `mech` (a half axle: one corner), `tyre` (`MagicFormula6`), `corner` (a
    `diffsusp.kc.Corner`; default the model's registered one), `longitudinal_at`
    ('contact_patch' or 'wheel_centre': who reacts the torque about the spin axis, module
    docstring), `combined`, `limits` (passed to `mf6.evaluate`).

    **Returns:** a `TyreRig` for `solve`.
    """
    if not isinstance(tyre, MagicFormula6):
        raise InputError(f"tyre_rig needs a MagicFormula6 tyre (diffsusp.tyre.MagicFormula6."
                         f"from_tir); got {type(tyre).__name__}.")
    if longitudinal_at not in ("contact_patch", "wheel_centre"):
        raise InputError(f"longitudinal_at must be 'contact_patch' or 'wheel_centre'; got "
                         f"'{longitudinal_at}'.")
    rig = force_rig(mech, corner)
    if len(rig.corners) != 1:
        raise InputError(f"tyre_rig works on one corner; the model has {len(rig.corners)} "
                         "(pass corner= to choose one).")
    rc = rig.corners[0]
    if longitudinal_at == "wheel_centre" and rc.wheel_centre_load < 0:
        raise InputError("longitudinal_at='wheel_centre' needs a wheel-centre load point; the "
                         "corner has none (Corner.wheel_centre_load).")
    return TyreRig(mech=rig.mech, tyre=tyre, corner=rc,
                   driven=jnp.asarray(1.0 if longitudinal_at == "wheel_centre" else 0.0),
                   combined=combined, limits=limits)


# ----------------------------------------------------------------------------- the kernel


def _axes(rc: ResolvedCorner):
    """Rows: the vehicle's forward, outboard and up unit vectors (the unknowns' basis)."""
    return jnp.asarray([rc.forward, rc.outboard, rc.up])


def _load_point(rig: TyreRig):
    """Index of the load point the wrench acts at (traced: `driven` is a leaf)."""
    rc = rig.corner
    if rc.wheel_centre_load < 0:
        return rc.contact_point
    return jnp.where(rig.driven > 0.0, rc.wheel_centre_load, rc.contact_point)


def _loads(rig: TyreRig, w, fz) -> Loads:
    """Loads of one case: the wrench w (5: force along forward, outboard; moment along forward,
    outboard, up) plus F_z·up at the rig's load point."""
    mech = rig.mech
    e = _axes(rig.corner)
    n_l, n_d = len(mech.load_points.names), len(mech.drivers.names)
    p = _load_point(rig)
    force = jnp.zeros((n_l, 3)).at[p].set(w[0] * e[0] + w[1] * e[1] + fz * e[2])
    moment = jnp.zeros((n_l, 3)).at[p].set(w[2] * e[0] + w[3] * e[1] + w[4] * e[2])
    return Loads(force=force, moment=moment, driver=jnp.zeros(n_d))


def _tyre_state(rig: TyreRig, q, case, design_steer):
    """The tyre at pose q (one case): slip, inclination, forces, K&C angles and the wrench it
    applies (5, as `_loads`) — the map T of the module docstring."""
    rc = rig.corner
    mech = rig.mech
    fz, alpha_cmd, kappa, camber_offset = case
    geo = corner_geometry(mech, rc, q)
    up = jnp.asarray(rc.up)
    s = jnp.stack([geo["spin_axis_x"], geo["spin_axis_y"], geo["spin_axis_z"]])  # outboard
    left = -rc.sigma * s  # spin axis toward the vehicle's left
    h = jnp.cross(left, up)
    h = h / jnp.linalg.norm(h)  # heading (ISO-W x)
    y_axis = jnp.cross(up, h)  # ISO-W y (left of the heading)
    alpha = alpha_cmd - (geo["steer"] - design_steer)
    gamma = rc.sigma * (geo["camber"] + camber_offset)
    f = evaluate(rig.tyre, fz, kappa, alpha, gamma, combined=rig.combined, limits=rig.limits)
    force = f.fx * h + f.fy * y_axis  # horizontal part (F_z is commanded)
    moment = f.mx * h + f.my * y_axis + f.mz * up
    if rc.wheel_centre_load >= 0:  # transported to the wheel centre when driven = 1
        d = rig.driven
        c, w = _load_point_positions(mech, rc, q, geo)
        moment = moment + d * jnp.cross(c - w, force + fz * up)
        moment = moment - d * (moment @ s) * s  # the spin-axis torque goes to the body
    e = _axes(rc)
    wrench = jnp.stack([force @ e[0], force @ e[1], moment @ e[0], moment @ e[1], moment @ e[2]])
    return wrench, f, alpha, gamma, geo


def _load_point_positions(mech: Mechanism, rc: ResolvedCorner, q, geo):
    """Positions of the contact-patch and wheel-centre load points at pose q. When both are on
    the wheel-centre marker's part (a wheel carrier), from the wheel-centre pose that
    `corner_geometry` has already computed (a rigid transport of their design offsets, no
    second pass over every marker); otherwise from `marker_poses`."""
    markers = mech.markers
    lp = (mech.load_points.marker[rc.contact_point], mech.load_points.marker[rc.wheel_centre_load])
    if all(markers.part[m] == markers.part[rc.wheel_centre] for m in lp):
        centre = jnp.stack([geo["wheel_centre_x"], geo["wheel_centre_y"], geo["wheel_centre_z"]])
        to_now = geo["_orientation"] @ markers.orientation[rc.wheel_centre].T
        return tuple(centre + to_now @ (markers.position[m] - markers.position[rc.wheel_centre])
                     for m in lp)
    pos, _ = marker_poses(mech, q)
    return pos[lp[0]], pos[lp[1]]


def _scale(rig: TyreRig, fz):
    r = rig.corner.loaded_radius
    return jnp.stack([fz, fz, fz * r, fz * r, fz * r])


def _split(mech: Mechanism, y):
    return y[: mech.n_coordinates], y[mech.n_coordinates:]


def _tyre_residual(rig: TyreRig, case, design_steer, y, u):
    """u − T(q(y))/scale: the tyre rows of the coupled residual (dimensionless)."""
    q = to_public(rig.mech, _split(rig.mech, y)[0])
    return u - _tyre_state(rig, q, case, design_steer)[0] / _scale(rig, case[0])


def _statics_residual(rig: TyreRig, case, row_scale, y, u):
    """The suspension's KKT residual under the wrench u·scale, rows scaled by `row_scale`."""
    w = u * _scale(rig, case[0])
    return row_scale * residual(rig.mech, _loads(rig, w, case[0]), y)


@eqx.filter_custom_jvp
def _coupled(rig, case, design_steer, row_scale, y, u):
    """The coupled residual (statics rows, tyre rows) at solver coordinates and multipliers y
    and the scaled wrench u. A custom JVP so that Newton's Jacobian uses the statics' own
    assembled KKT Jacobian (`linearize_internal`) for ∂r/∂y instead of forward-mode autodiff
    through the assembly in every direction."""
    return (_statics_residual(rig, case, row_scale, y, u),
            _tyre_residual(rig, case, design_steer, y, u))


@_coupled.def_jvp
def _coupled_jvp(primals, tangents):
    rig, case, design_steer, row_scale, y, u = primals
    t_rig, t_case, t_steer, _, t_y, t_u = tangents
    r, dr = eqx.filter_jvp(lambda rg, c, u_: _statics_residual(rg, c, row_scale, y, u_),
                           (rig, case, u), (t_rig, t_case, t_u))
    if t_y is not None:  # (only then: the implicit adjoint's ∂/∂(rig) needs no assembly)
        w = u * _scale(rig, case[0])
        lin = linearize_internal(rig.mech, _loads(rig, w, case[0]), y)
        dr = (0.0 if dr is None else dr) + row_scale * (lin.jacobian @ t_y)
    g, dg = eqx.filter_jvp(_tyre_residual, (rig, case, design_steer, y, u),
                           (t_rig, t_case, t_steer, t_y, t_u))
    zero = jnp.zeros_like
    return (r, g), (zero(r) if dr is None else dr, zero(g) if dg is None else dg)


def _solve_traced(rig: TyreRig, cases, q0, rtol, atol, max_steps):
    mech = rig.mech
    design = jnp.zeros(mech.n_coordinates)
    design_steer = corner_geometry(mech, rig.corner, design)["steer"]
    m = len(mech.independent_rows)

    def fn(z, args):
        rig_, case, steer0, row_scale, col_scale = args
        y_scaled, u = z
        return _coupled(rig_, case, steer0, row_scale, col_scale * y_scaled, u)

    # The starting point from inputs without tangents: the root's derivative comes from the
    # implicit function theorem (`optx.ImplicitAdjoint`), never from the start, and a
    # forward-mode trace through the start's KKT linearisation only made every
    # differentiated program bigger (to trace and to compile).
    dynamic, static = eqx.partition((rig, design_steer), eqx.is_inexact_array)
    rig_start, steer_start = eqx.combine(jax.lax.stop_gradient(dynamic), static)

    def one(case, q_start):
        scale = _scale(rig, case[0])
        case0 = jax.lax.stop_gradient(case)
        scale0 = _scale(rig_start, case0[0])
        u0 = _tyre_state(rig_start, q_start, case0, steer_start)[0] / scale0  # rigid suspension
        # Multipliers start at 0: the KKT residual is linear in them, so Newton's first step
        # gives them (no line search here, unlike solve_statics, hence no merit to start well).
        lin0 = linearize(rig_start.mech, _loads(rig_start, u0 * scale0, case0[0]), q_start,
                         jnp.zeros(m))
        y0 = lin0.y
        # Rows in displacement units (mm or rad): each row / its largest Jacobian entry, so
        # that atol means the same for force, moment and constraint rows; then the columns
        # equilibrated too (a stiff model's columns span many decades: without it Newton's
        # LU steps stall at round-off above the tolerance).
        jac = jax.lax.stop_gradient(lin0.jacobian)
        row_scale = 1.0 / jnp.maximum(jnp.max(jnp.abs(jac), axis=1), 1e-300)
        col_scale = 1.0 / jnp.maximum(jnp.max(jnp.abs(row_scale[:, None] * jac), axis=0),
                                      1e-300)
        res = optx.root_find(fn, optx.Newton(rtol=rtol, atol=atol), (y0 / col_scale, u0),
                             args=(rig, case, design_steer, row_scale, col_scale),
                             max_steps=max_steps, throw=False)
        y, u = res.value
        y = col_scale * y
        q = to_public(mech, _split(mech, y)[0])
        w = u * scale
        _, f, alpha, gamma, geo = _tyre_state(rig, q, case, design_steer)
        loads = _loads(rig, w, case[0])
        p = _load_point(rig)
        # optimistix's outcome in the statics' one status vocabulary
        status = jnp.where(res.result == optx.RESULTS.successful, Status.CONVERGED,
                           jnp.where(res.result == optx.RESULTS.max_steps_reached,
                                     Status.MAX_STEPS, Status.STALLED))
        return dict(forces=f, slip_angle=alpha, inclination=gamma, toe=geo["toe"],
                    camber=geo["camber"], steer=geo["steer"], force=loads.force[p],
                    moment=loads.moment[p], q=q, status=status,
                    iterations=res.stats["num_steps"])

    out = jax.vmap(one)(cases, q0)
    return TyreRigSolution(design_steer=design_steer, **out)


_solve = eqx.filter_jit(_solve_traced)


def solve(rig: TyreRig, slip_angle: ArrayLike, *, fz: ArrayLike | None = None,
          slip_ratio: ArrayLike = 0.0, camber_offset: ArrayLike = 0.0,
          q0: Float[Array, "*cases n"] | None = None, rtol: float = 1e-9,
          atol: float = 1e-9, max_steps: int = 30, throw: bool = True) -> TyreRigSolution:
    """The coupled tyre–suspension equilibria, one per case (module docstring).

    **Arguments** (broadcast to a common case axis):

    - `slip_angle`: commanded slip angle α_cmd [rad, ISO-W], the tyre's slip angle at the
      design pose;
    - `fz`: vertical load [N, up, > 0] (default: the corner's design load);
    - `slip_ratio`: κ [-] (ISO-W: positive driving);
    - `camber_offset`: added to the K&C camber [rad, top outboard positive];
    - `q0`: start of the suspension's equilibria (default design);
    - `rtol`, `atol`: Newton's Cauchy termination (`optx.Newton`): the last step below
      atol + rtol·|z| componentwise and the residual below atol, with the wrench scaled
      (forces / F_z, moments / (F_z·R_l)) and the suspension's rows in displacement units
      (each row divided by its largest Jacobian entry at the start: mm or rad). Newton
      converges quadratically, so the solution is far more accurate than the last step;
    - `max_steps`: Newton steps; `throw`: raise `ConvergenceError` naming the first failed
      case (otherwise see `status`; a warning is issued).

    **Returns:** `TyreRigSolution` (case axis first). Pure and differentiable: under `jax.jit`,
    `jax.jvp` or `jax.grad` the checks on concrete values and `throw` are skipped.
    """
    arrays = [jnp.asarray(v, dtype=float) for v in
              (rig.corner.design_load if fz is None else fz, slip_angle, slip_ratio,
               camber_offset)]
    shape = jnp.broadcast_shapes(*(a.shape for a in arrays))
    if len(shape) > 1:
        raise InputError(f"solve: the inputs must be scalars or 1-D case arrays; got shape "
                         f"{shape}.")
    cases = tuple(jnp.broadcast_to(a, shape).reshape(-1) for a in arrays)
    n = cases[0].shape[0]
    concrete = not any(isinstance(a, jax.core.Tracer) for a in cases)
    if concrete:
        values = np.stack([np.asarray(a) for a in cases])
        if not np.all(np.isfinite(values)):
            raise InputError("solve: fz, slip_angle, slip_ratio and camber_offset must be "
                             "finite.")
        if np.any(values[0] <= 0.0):
            raise InputError(f"solve: fz must be a positive vertical load in N; got "
                             f"{float(values[0].min()):g}.")
    nq = rig.mech.n_coordinates
    q0 = jnp.zeros((n, nq)) if q0 is None else jnp.broadcast_to(jnp.asarray(q0, float), (n, nq))
    case_array = jnp.stack(cases, axis=1)
    # Inside a caller's trace (its jit compiles this too) the solve is traced inline: a
    # nested jit is traced twice under autodiff (the function, then the derivative of its
    # jaxpr), which cost a differentiated program a quarter of its tracing.
    inside = any(isinstance(leaf, jax.core.Tracer)
                 for leaf in jax.tree.leaves((eqx.filter(rig, eqx.is_array), case_array, q0)))
    sol = (_solve_traced if inside else _solve)(rig, case_array, q0, rtol, atol, max_steps)
    if concrete and not isinstance(sol.status, jax.core.Tracer):
        status = np.asarray(sol.status)
        bad = np.flatnonzero(status != Status.CONVERGED)
        if bad.size:
            c = int(bad[0])
            message = (
                f"tyre rig: case {c} (F_z = {float(cases[0][c]):g} N, slip angle "
                f"{float(cases[1][c]):g} rad, slip ratio {float(cases[2][c]):g}) did not "
                f"converge: {STATUS_TEXT[int(status[c])]} ({bad.size} of {n} cases failed). The "
                "tyre force may be beyond what the suspension carries: reduce the slip or "
                "load, or pass throw=False to get per-case statuses.")
            if throw:
                raise ConvergenceError(message)
            warnings.warn(message, stacklevel=2)
    return sol

