"""K&C events: batched statics runs on a rig around the model, with every metric and its exact
derivatives.

An event builds a `Rig` (the model plus motion drivers: wheel travel, rack), a table of load
cases (one per point of the event), and calls `evaluate`: `solve_statics` solves every case at
once (vmapped over cases, from the design position or `q0`), then one compiled call computes the
geometric metrics and differentiates them in forward mode through the equilibrium with respect
to a few rig inputs u (travel, vertical load, lateral and longitudinal force, aligning torque,
wheel-centre loads, rack). The derivative is the implicit one, dy/du = −J⁻¹ ∂r/∂u at the
solution, with the KKT Jacobian J and ∂r/∂u by autodiff of the solver's own residual
(`statics.linearize`) — the same formula as `solve_statics`'s custom JVP rule, evaluated
without re-running Newton inside the derivative
(jax.jacfwd through `solve_statics` traces the Newton loop again under the JVP: 82–125 s of
tracing against 27 + 14 s for this split on the project's loaded 2-core machine, and a Newton
program that is not shared with plain solves of the same model). No finite differences.
Metrics and signs: `diffsusp.kc.metrics`. Per-side load components (vertical up, lateral
inboard, longitudinal rearward = braking, aligning torque toe-out):
`ResolvedCorner.load_vectors`.

Two compiled programs per rig structure and number of cases (the batched solve, shared with any
other `solve_statics` of that model and shape, and the metrics): events of one kind reuse them
for new values, and `evaluate` can be `jax.vmap`ped over designs.
"""

import dataclasses
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..compilation import filter_jit
from ..errors import ConvergenceError, InputError
from ..model import GROUND, Loads, Mechanism
from ..statics import (
    STATUS_TEXT,
    StaticSolution,
    Status,
    bushing_states,
    linearize,
    solve_statics,
    to_public,
)
from ..statics.checks import STABILITY_TOLERANCE, law_validity, stability_margins, warn_law_validity
from .corner import Corner, ResolvedCorner, corners_of, design_load
from .loadcases import TABLE_4_4, TABLE_5_1
from .metrics import DERIVATIVE_METRICS, METRICS, Derivatives, corner_geometry
from .rig import ROAD_CONTACT, add_driver, add_road_contact, remove_drivers

__all__ = [
    "TABLES",
    "KCEvent",
    "Rig",
    "aligning_torque",
    "anti_pitch",
    "braking",
    "compliance_matrix",
    "corner_loads",
    "derivative_metrics",
    "evaluate",
    "force_rig",
    "lateral_force",
    "load_table",
    "longitudinal_force",
    "opposite_travel",
    "parallel_travel",
    "steering",
    "traction",
    "travel_rig",
    "vertical_force",
]

TABLES = {"table_5_1": TABLE_5_1, "table_4_4": TABLE_4_4}
"""The thesis load tables (F_vert, F_lat, F_long) in N: Table 5-1 (13 cases, spec stiffness
§2.7) and Table 4.4 (17 K&C bench cases, §1.13). `load_table` applies them per side."""


class Rig(eqx.Module):
    """A model on a K&C rig: the mechanism with its rig drivers and the corners to measure.

    **Fields:** `mech` (with drivers), `pattern` (per corner, the sign of the primary input:
    +1 parallel, ±1 opposite travel; an array so that parallel and opposite travel share one
    compiled program), static `corners` (resolved), `mode` ('travel': wheel heights driven;
    'force': wheels free, loaded by forces), `travel_drivers` (per corner, index of its
    wheel-travel driver or −1), `rack_driver` (index of the steering rack's driver, or −1;
    a rack is an input of every event on the rig, steering or not: steer gain), `road` (per
    corner, the load point where its contact-patch loads act at the ground contact point — the
    wheel plane's lowest point on the road, `add_road_contact` — or empty: at the corner's
    `contact_point`, fixed on the wheel carrier).
    """

    mech: Mechanism
    pattern: Float[Array, " corners"]
    corners: tuple[ResolvedCorner, ...] = eqx.field(static=True)
    mode: str = eqx.field(static=True)
    travel_drivers: tuple[int, ...] = eqx.field(static=True)
    rack_driver: int = eqx.field(static=True, default=-1)
    road: tuple[int, ...] = eqx.field(static=True, default=())

    def contact(self, c: int) -> int:
        """The load point where corner `c`'s contact-patch loads act."""
        return self.road[c] if self.road else self.corners[c].contact_point

    def contact_radius(self, n: int | None = None):
        """`Loads.contact_radius` of the rig: each corner's loaded radius at its road contact
        load point (None without road contacts); with a leading axis of `n` cases."""
        if not self.road:
            return None
        radius = np.zeros(len(self.mech.load_points.names))
        for c, rc in enumerate(self.corners):
            radius[self.road[c]] = rc.loaded_radius
        return jnp.asarray(radius if n is None else np.broadcast_to(radius, (n, radius.size)))

    def multiplier_index(self, driver: int) -> int:
        """Position of driver `driver`'s row among the solution's multipliers."""
        return self.mech.independent_rows.index(self.mech.joints.n_rows + driver)

    @property
    def n_inputs(self) -> int:
        n = 4
        if self.mode == "force":
            n += 6 * sum(c.wheel_centre_load >= 0 for c in self.corners)
        return n + (self.rack_driver >= 0)

    @property
    def is_axle(self) -> bool:
        """Two corners, a left and a right one, in a travel rig (roll metrics apply)."""
        return (self.mode == "travel" and len(self.corners) == 2
                and sorted(c.side for c in self.corners) == ["left", "right"])


def _resolve(mech: Mechanism, corner) -> tuple[ResolvedCorner, ...]:
    if corner is None:
        corners = corners_of(mech)
    elif isinstance(corner, Corner):
        corners = {corner.prefix: corner}
    elif isinstance(corner, dict):
        corners = {}
        for key, c in corner.items():
            prefix = key if key == "" or key.endswith("/") else key + "/"
            corners[prefix] = c if c.prefix == prefix else dataclasses.replace(c, prefix=prefix)
    else:
        raise InputError(f"corner must be a Corner, a dict of them, or None; got {type(corner)}.")
    out = []
    for c in corners.values():
        rc = c.resolve(mech, design_load(mech, c))
        for lp in (rc.contact_point, rc.wheel_centre_load):
            if lp >= 0 and mech.load_points.frame[lp] != GROUND:
                raise InputError(
                    f"load point '{mech.load_points.names[lp]}' has components in a marker "
                    "frame; K&C events need global components (load_point(..., frame=None))."
                )
        out.append(rc)
    return tuple(out)


def _wheel_markers(mech: Mechanism, rc: ResolvedCorner) -> set[int]:
    return {rc.wheel_centre, mech.load_points.marker[rc.contact_point]}


def _strip_wheel_drivers(mech: Mechanism, corners) -> Mechanism:
    wheel = set().union(*(_wheel_markers(mech, rc) for rc in corners))
    names = [n for n, m in zip(mech.drivers.names, mech.drivers.marker, strict=True)
             if m in wheel]
    return remove_drivers(mech, names)


def _rack(mech: Mechanism, rack: str, required: bool) -> int:
    if rack in mech.drivers.names:
        return mech.drivers.names.index(rack)
    if required:
        raise InputError(
            f"steering needs a rack driver '{rack}'; the model has "
            f"{', '.join(mech.drivers.names) or 'no drivers'}. Add one with "
            "diffsusp.kc.with_rack(mech) (a tie rod whose inner end is on the ground)."
        )
    return -1


def travel_rig(mech: Mechanism, corner=None, *, drive: str = "wheel_centre",
               pattern=None, rack: str = "rack_travel", require_rack: bool = False) -> Rig:
    """The model with each wheel's height driven (a vertical driver on the wheel centre, or on
    the contact point with `drive='contact_patch'`), named `<prefix>wheel_travel`. Drivers the
    model already had on those markers are replaced. `pattern`: per corner sign of the travel
    (default all +1, parallel travel). A driver named `rack` (see `with_rack`) is the rig's
    steering input (held at the load case's value, and differentiated: steer gain)."""
    if drive not in ("wheel_centre", "contact_patch"):
        raise InputError(f"drive must be 'wheel_centre' or 'contact_patch'; got '{drive}'.")
    corners = _resolve(mech, corner)
    mech = _strip_wheel_drivers(mech, corners)
    drivers = []
    for rc in corners:
        marker = (mech.markers.names[rc.wheel_centre] if drive == "wheel_centre"
                  else mech.markers.names[mech.load_points.marker[rc.contact_point]])
        mech = add_driver(mech, rc.prefix + "wheel_travel", marker, rc.up)
        drivers.append(len(mech.drivers.names) - 1)
    pattern = np.ones(len(corners)) if pattern is None else np.asarray(pattern, dtype=float)
    return Rig(mech=mech, pattern=jnp.asarray(pattern), corners=corners, mode="travel",
               travel_drivers=tuple(drivers), rack_driver=_rack(mech, rack, require_rack))


def force_rig(mech: Mechanism, corner=None, *, rack: str = "rack_travel",
              contact: str = "road") -> Rig:
    """The model with its wheels free and loaded by forces (drivers on the wheel markers are
    removed; others, e.g. a rack, stay at the load case's value).

    `contact`: where the contact-patch forces act. 'road' (default, as a K&C rig and Adams
    apply the tyre force): at the ground contact point, the wheel plane's lowest point on the
    road, C = W − R_l·u (W the wheel centre, u the unit vector in the wheel plane pointing up
    from the road, R_l the corner's `loaded_radius`), which moves with the wheel — a wind-up
    of the wheel carrier does not carry it along the road. A load point `<prefix>road_contact`
    on the wheel-centre marker is added for it (`add_road_contact`) and the loads carry
    `contact_radius`. 'fixed': at the corner's `contact_point` load point, fixed on the
    wheel carrier (the load does not follow a wind-up of the carrier along the road)."""
    if contact not in ("road", "fixed"):
        raise InputError(f"contact must be 'road' or 'fixed'; got '{contact}'.")
    corners = _resolve(mech, corner)
    mech = _strip_wheel_drivers(mech, corners)
    road = []
    if contact == "road":
        for rc in corners:
            mech, k = add_road_contact(mech, rc.wheel_centre, rc.prefix)
            road.append(k)
    return Rig(mech=mech, pattern=jnp.ones(len(corners)), corners=corners, mode="force",
               travel_drivers=tuple(-1 for _ in corners), rack_driver=_rack(mech, rack, False),
               road=tuple(road))


# ----------------------------------------------------------------------------- the kernel


def _basis(rig: Rig) -> Loads:
    """Tangent directions of the rig inputs: `Loads` with a leading axis of n_u inputs.

    0: primary input (travel drivers × pattern, or vertical forces × pattern);
    1, 2, 3: per-side lateral (inboard) force, longitudinal (rearward) force and aligning
    torque (toe-out) at every contact point; force mode: then 6 per corner at its wheel-centre
    load point (global Fx, Fy, Fz, Mx, My, Mz); last, if the rig has a rack: its driver."""
    mech = rig.mech
    n_l, n_d = len(mech.load_points.names), len(mech.drivers.names)
    n_u = rig.n_inputs
    force = jnp.zeros((n_u, n_l, 3))
    moment = jnp.zeros((n_u, n_l, 3))
    driver = jnp.zeros((n_u, n_d))
    k = 4
    for c, rc in enumerate(rig.corners):
        cp = rig.contact(c)
        if rig.mode == "travel":
            driver = driver.at[0, rig.travel_drivers[c]].set(rig.pattern[c])
        elif rig.mode == "force":
            force = force.at[0, cp].add(rig.pattern[c] * jnp.asarray(rc.up))
        force = force.at[1, cp].add(-jnp.asarray(rc.outboard))
        force = force.at[2, cp].add(jnp.asarray(rc.rearward))
        moment = moment.at[3, cp].add(jnp.asarray(rc.toe_out))
        if rig.mode == "force" and rc.wheel_centre_load >= 0:
            for a in range(3):
                force = force.at[k + a, rc.wheel_centre_load, a].set(1.0)
                moment = moment.at[k + 3 + a, rc.wheel_centre_load, a].set(1.0)
            k += 6
    if rig.rack_driver >= 0:
        driver = driver.at[n_u - 1, rig.rack_driver].set(1.0)
    radius = None if not rig.road else jnp.zeros((n_u, n_l))
    return Loads(force=force, moment=moment, driver=driver, contact_radius=radius)


def raw_metrics(rig: Rig, loads: Loads, q, multipliers) -> dict:
    """Geometric metrics and per-side loads of every corner, one case (scalars)."""
    mech = rig.mech
    out = {}
    design = jnp.zeros(mech.n_coordinates)
    for c, rc in enumerate(rig.corners):
        geo = corner_geometry(mech, rc, q)
        geo0 = corner_geometry(mech, rc, design)
        up, o, r, a = (jnp.asarray(v) for v in (rc.up, rc.outboard, rc.rearward, rc.toe_out))

        def vec(g, what):
            return jnp.stack([g[f"{what}_{x}"] for x in "xyz"])

        w, cpt = vec(geo, "wheel_centre"), vec(geo, "contact_patch")
        geo["wheel_travel"] = (w - vec(geo0, "wheel_centre")) @ up
        geo["half_track_change"] = (cpt - vec(geo0, "contact_patch")) @ o
        geo["wheelbase_change"] = (w - vec(geo0, "wheel_centre")) @ r
        force = loads.force[rig.contact(c)]
        moment = loads.moment[rig.contact(c)]
        if rc.wheel_centre_load >= 0:
            force = force + loads.force[rc.wheel_centre_load]
        vertical = force @ up
        if rig.travel_drivers[c] >= 0:
            d = rig.travel_drivers[c]
            vertical = vertical + multipliers[rig.multiplier_index(d)] * (
                mech.drivers.direction[d] @ up)
        geo["vertical_force"] = vertical
        geo["lateral_force"] = 0.0 - force @ o  # (0.0 − x: no negative zeros)
        geo["longitudinal_force"] = force @ r
        geo["aligning_torque"] = moment @ a
        geo["_lateral_position"] = cpt @ o  # distance of C from the centreline (y = 0)
        for key, value in geo.items():
            out[rc.prefix + key] = value
    if rig.is_axle:
        left, right = sorted(rig.corners, key=lambda rc: rc.side)
        mk = mech.markers
        lateral = jnp.asarray(right.outboard)  # the vehicle's right
        track = jnp.abs((mk.position[right.wheel_centre] - mk.position[left.wheel_centre])
                        @ lateral)
        zl, zr = out[left.prefix + "wheel_travel"], out[right.prefix + "wheel_travel"]
        out["roll_angle"] = jnp.arctan2(zr - zl, track)
        out["_track"] = track
    return out


def _derived(rig: Rig, m: dict, jac: dict) -> tuple[dict, dict]:
    """Derivative metrics of one case from the derivatives (n_u,) of the raw metrics."""
    out, compliance = {}, {}
    k = 4
    for rc in rig.corners:
        p = rc.prefix
        at = Derivatives(jac, m, rc, rig)
        for name, metric in METRICS.items():  # the registry's per-corner derivative metrics
            value = None if metric.derive is None else metric.derive(at)
            if value is not None:
                out[p + name] = value
        if rig.mode == "force" and rc.wheel_centre_load >= 0:
            cols = slice(k, k + 6)
            dw = jnp.stack([jac[p + f"wheel_centre_{a}"][cols] for a in "xyz"])  # (3, 6)
            rot = m[p + "_orientation"]
            omega = jnp.einsum("nik,jk->nij", jac[p + "_orientation"][cols], rot)  # dR Rᵀ
            w = jnp.stack([omega[:, 2, 1], omega[:, 0, 2], omega[:, 1, 0]])  # (3, 6)
            compliance[p] = jnp.concatenate([dw, w])
            k += 6
    if "roll_angle" in m:
        left, right = sorted(rig.corners, key=lambda rc: rc.side)
        dfl = jac[left.prefix + "vertical_force"][0]
        dfr = jac[right.prefix + "vertical_force"][0]
        out["roll_stiffness"] = -0.5 * m["_track"] * (dfl - dfr) / jac["roll_angle"][0]
    return out, compliance


def metrics_at(rig: Rig, loads: Loads, sol: StaticSolution):
    """Metrics and their derivatives at the equilibria `sol` (the implicit function theorem:
    dy/du = −J⁻¹ ∂r/∂u with J and ∂r/∂u by autodiff of the KKT residual, the same linear
    solve as `solve_statics`'s custom JVP rule), and the checks `solve_statics` would do
    (stability margin from the same linearisation, the bushings' projected angles).

    The second half of `evaluate`, for callers that solve the cases themselves (the design
    batch) or differentiate the metrics through pinned equilibria (`kc.hessian_vector_product`).

    **Returns:** (metrics: name → (cases,), compliance: corner prefix → (cases, 6, 6),
    (stable, law_valid) flags (cases,), bushing angles (cases, bushings, 3)); NaN metrics where
    `sol.status` is not converged."""
    mech = rig.mech
    n = mech.n_coordinates
    basis = _basis(rig)

    def one(loads_c, q, lam):
        lin = linearize(mech, loads_c, q, lam)
        y = lin.y[:n]
        # (n_u, n + m): solver coordinates and multipliers
        dy = jax.vmap(lambda b: lin.tangent(d_loads=b))(basis)

        def metrics(y_, lam_, l_):
            return raw_metrics(rig, l_, to_public(mech, y_), lam_)

        m = metrics(y, lam, loads_c)
        jac_m = jax.vmap(lambda dy_u, b_u: jax.jvp(metrics, (y, lam, loads_c),
                                                   (dy_u[:n], dy_u[n:], b_u))[1])(dy, basis)
        angles = bushing_states(mech, q)[1]
        return m, jac_m, (lin.stiffness, lin.constraint_jacobian), angles

    m, jac, lin, angles = jax.vmap(one)(loads, sol.q, sol.multipliers)
    margin = stability_margins(mech, *lin)
    derived, compliance = jax.vmap(lambda m_, j_: _derived(rig, m_, j_))(m, jac)
    metrics = {k: v for k, v in m.items() if not k.rsplit("/", 1)[-1].startswith("_")}
    metrics.update(derived)
    ok = sol.status == Status.CONVERGED
    metrics = {k: jnp.where(ok, v, jnp.nan) for k, v in metrics.items()}
    compliance = {k: jnp.where(ok[:, None, None], v, jnp.nan) for k, v in compliance.items()}
    angles = jax.lax.stop_gradient(angles)  # for the flags and the warning only
    law = jax.vmap(lambda a: law_validity(mech, None, angles=a))(angles)
    flags = (ok & (margin > STABILITY_TOLERANCE), ok & (law <= 1.0))
    return metrics, compliance, flags, jnp.where(ok[:, None, None], angles, 0.0)


_metrics_kernel = filter_jit(metrics_at)


def evaluate(rig: Rig, loads: Loads, *, q0: Float[Array, "cases n"] | None = None,
             rtol: float = 1e-12, atol: float = 1e-10, max_steps: int = 50):
    """Solve every load case of `loads` on `rig` and compute all metrics and derivative metrics.

    Two compiled programs: `solve_statics` on the rig's mechanism (the same program any batched
    solve of that structure and number of cases uses) and the metrics with their forward-mode
    derivatives through the equilibrium. Pure: differentiate it, or `eqx.filter_vmap` it over
    designs (e.g. stiffness values in `rig.mech`). Non-converged cases get NaN metrics and a
    non-zero status.

    **Arguments:** `rig` (`travel_rig`, `force_rig`), `loads` with a leading case axis (for
    `rig.mech`), `q0` start coordinates (default: design), solver tolerances as
    `solve_statics`.

    **Returns:** (`StaticSolution`, metrics: name → (cases,) arrays, compliance: corner prefix →
    (cases, 6, 6)). `solve_statics` warns (`ModelWarning`) when a bushing rotates beyond its
    law's validity.
    """
    if loads.n_cases is None:
        raise InputError("evaluate needs loads with a leading case axis.")
    with warnings.catch_warnings():
        # Failed cases are reported by status (and by the events).
        warnings.filterwarnings("ignore", message=r"solve_statics: \d+ of \d+ cases did not")
        sol = solve_statics(rig.mech, loads, q0=q0, rtol=rtol, atol=atol, max_steps=max_steps,
                            throw=False, checks=False)
    metrics, compliance, (stable, law_valid), angles = _metrics_kernel(rig, loads, sol)
    if not isinstance(sol.q, jax.core.Tracer):  # as `solve_statics` does for concrete calls
        sol = dataclasses.replace(sol, stable=stable, law_valid=law_valid)
        warn_law_validity(rig.mech, angles)
    return sol, metrics, compliance


# ----------------------------------------------------------------------------- events


@dataclasses.dataclass
class KCEvent:
    """The result of a K&C event.

    **Fields:** `name` (event), `x` (the event's input per case), `x_name`, `x_unit`, `metrics`
    (name → (cases,) array in internal units; for axles each corner's names carry its prefix,
    e.g. 'left/toe'), `compliance` (corner prefix → (cases, 6, 6), force events),
    `solution` (`StaticSolution`), `loads` (the load table, for `rig.mech`), `rig`, `label`
    (for legends), `held` (what the derivative metrics hold fixed).
    """

    name: str
    x: np.ndarray
    x_name: str
    x_unit: str
    metrics: dict
    compliance: dict
    solution: StaticSolution
    loads: Loads
    rig: Rig
    label: str
    held: str

    @property
    def converged(self) -> np.ndarray:
        return np.asarray(self.solution.status) == Status.CONVERGED

    @property
    def prefixes(self) -> tuple[str, ...]:
        return tuple(rc.prefix for rc in self.rig.corners)

    def corner_metrics(self, prefix: str) -> dict:
        """The metrics of one corner of an axle, without its prefix."""
        prefix = prefix if prefix.endswith("/") or prefix == "" else prefix + "/"
        return {k[len(prefix):]: v for k, v in self.metrics.items()
                if k.startswith(prefix) and "/" not in k[len(prefix):]}


def _cases(values, what: str) -> np.ndarray:
    arr = np.atleast_1d(np.asarray(values, dtype=float))
    if arr.ndim != 1 or arr.size == 0:
        raise InputError(f"{what} must be a 1-D sequence of values; got shape {arr.shape}.")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{what} contains non-finite values.")
    return arr


def event_loads(rig: Rig, n: int, *, vertical=0.0, lateral=0.0, longitudinal=0.0, aligning=0.0,
           at: str = "contact_patch", travel=0.0, rack=0.0) -> Loads:
    """The event's load table: per-side components applied at every corner (× pattern for the
    primary input)."""
    mech = rig.mech
    n_l, n_d = len(mech.load_points.names), len(mech.drivers.names)
    force = np.zeros((n, n_l, 3))
    moment = np.zeros((n, n_l, 3))
    driver = np.zeros((n, n_d))
    b = [np.broadcast_to(np.asarray(v, dtype=float), (n,)) for v in
         (vertical, lateral, longitudinal, aligning, travel, rack)]
    vertical, lateral, longitudinal, aligning, travel, rack = b
    pattern = np.asarray(rig.pattern)
    for c, rc in enumerate(rig.corners):
        sign = pattern[c]
        f_v, _ = rc.load_vectors(vertical * (sign if rig.mode == "force" else 1.0), 0, 0, 0)
        f_h, m = rc.load_vectors(0, lateral, longitudinal, aligning)
        cp = rig.contact(c)
        force[:, cp] += f_v
        if at == "wheel_centre":
            if rc.wheel_centre_load < 0:
                raise InputError("this event loads the wheel centre, but the corner has no "
                                 "wheel_centre_load load point.")
            force[:, rc.wheel_centre_load] += f_h
        else:
            force[:, cp] += f_h
        moment[:, cp] += m
        if rig.travel_drivers[c] >= 0:
            driver[:, rig.travel_drivers[c]] = sign * travel
    if rig.rack_driver >= 0:
        driver[:, rig.rack_driver] = rack
    return Loads(force=jnp.asarray(force), moment=jnp.asarray(moment), driver=jnp.asarray(driver),
                 contact_radius=rig.contact_radius(n))


def corner_loads(mech: Mechanism, table=None, *, vertical=0.0, lateral=0.0,
                 longitudinal=0.0, aligning=0.0, corner=None,
                 at: str = "contact_patch") -> Loads:
    """Per-side wheel loads as the `Loads` of `mech`, without running an event: what
    `load_table` and the force events apply, for a user's own solves, measurements or fleets.

    The components are given per side, as a K&C bench states them, and turned into global
    vectors at every corner by its own axes (`ResolvedCorner.load_vectors`, spec kc §1:
    vertical up, lateral inboard, longitudinal rearward = braking, aligning torque toe-out),
    so the same table loads a left or a right wheel, in the Adams/Car frame (x rearward) or
    the ISO frame (x forward) alike — no sign to work out by hand.

    **Arguments:**
    - `table`: `(cases, 3)` rows (F_vert, F_lat, F_long) in N, e.g. `kc.TABLES['table_5_1']`;
      or give the components one by one: `vertical`, `lateral`, `longitudinal` (N) and
      `aligning` (N·mm), scalars or `(cases,)` arrays (broadcast together).
    - `corner`: a `Corner`, a dict of them, or None (every corner of the model, each loaded
      with the same per-side components).
    - `at`: where the lateral and longitudinal forces act: 'contact_patch' (default) or
      'wheel_centre' (the corner's `wheel_centre_load` point); vertical force and aligning
      torque act at the contact point.

    **Returns:** `Loads` of `mech` with a leading case axis (drivers at 0). A driver on a
    loaded wheel would carry the vertical load: apply them to a model whose wheels are free
    (`kc.force_rig(mech).mech` removes those drivers, as the force events do). On a model with
    road contact load points (`kc.force_rig(mech).mech`) the contact-patch loads act at the
    ground contact point, moving with the wheel, as in the force events (the loads carry
    `contact_radius`); on the model itself at its `contact_point`, fixed on the wheel
    carrier."""
    if table is not None:
        arr = np.asarray(table, dtype=float)
        if arr.ndim != 2 or arr.shape[1] != 3 or not np.all(np.isfinite(arr)):
            raise InputError(f"table must be a finite (cases, 3) array of (F_vert, F_lat, "
                             f"F_long) in N; got shape {arr.shape}.")
        vertical, lateral, longitudinal = arr.T
    if at not in ("contact_patch", "wheel_centre"):
        raise InputError(f"at must be 'contact_patch' or 'wheel_centre'; got '{at}'.")
    values = [np.asarray(v, dtype=float) for v in (vertical, lateral, longitudinal, aligning)]
    try:
        shape = np.broadcast_shapes(*(v.shape for v in values))
    except ValueError:
        raise InputError("vertical, lateral, longitudinal and aligning must be scalars or "
                         "(cases,) arrays of one length; got shapes "
                         f"{[v.shape for v in values]}.") from None
    if len(shape) > 1 or not all(np.all(np.isfinite(v)) for v in values):
        raise InputError(f"the load components must be finite scalars or (cases,) arrays; "
                         f"got shape {shape}.")
    corners = _resolve(mech, corner)
    names = mech.load_points.names
    road = tuple(names.index(rc.prefix + ROAD_CONTACT) for rc in corners
                 if rc.prefix + ROAD_CONTACT in names)
    rig = Rig(mech=mech, pattern=jnp.ones(len(corners)), corners=corners, mode="force",
              travel_drivers=tuple(-1 for _ in corners),
              road=road if len(road) == len(corners) else ())
    n = shape[0] if shape else 1
    return event_loads(rig, n, vertical=values[0], lateral=values[1], longitudinal=values[2],
                  aligning=values[3], at=at)


def _run(name, rig, loads, x, x_name, x_unit, held, q0=None, throw=True, label=None,
         **solver) -> KCEvent:
    sol, metrics, compliance = evaluate(rig, loads, q0=q0, **solver)
    status = np.asarray(sol.status)
    bad = np.flatnonzero(status != Status.CONVERGED)
    if bad.size and throw:
        c = int(bad[0])
        raise ConvergenceError(
            f"{name}: case {c} ({x_name} = {x[c]:g} {x_unit}) did not converge "
            f"({STATUS_TEXT.get(int(status[c]), 'failed')}, relative force residual "
            f"{float(np.asarray(sol.residual)[c]):.3g}; {bad.size} of {status.size} cases "
            "failed). The load or travel is probably beyond what the model can carry (no bump "
            "stops): reduce the range, or pass throw=False to get NaN metrics for those cases."
        )
    if bad.size:
        warnings.warn(f"{name}: {bad.size} of {status.size} cases did not converge (NaN "
                      "metrics).", stacklevel=3)
    return KCEvent(name=name, x=x, x_name=x_name, x_unit=x_unit, metrics=metrics,
                   compliance=compliance, solution=sol, loads=loads, rig=rig,
                   label=label or rig.mech.name, held=held)


def _fz(rig: Rig, fz) -> float:
    return float(rig.corners[0].design_load if fz is None else fz)


def parallel_travel(mech: Mechanism, travel, *, corner=None, drive: str = "wheel_centre",
                    q0=None, throw: bool = True, label: str | None = None,
                    **solver) -> KCEvent:
    """Parallel wheel travel: every wheel's height driven by `travel` (mm, bump positive).

    The wheel-centre (or, with `drive='contact_patch'`, the contact point's) vertical position
    is prescribed by a driver; nothing else is loaded. Derivative metrics hold the wheel height
    fixed (compliances) and differentiate along the travel (bump steer, wheel rate, ...).

    **Arguments:** `mech` (a half axle or a `combine`d axle), `travel` (mm, e.g.
    `jnp.linspace(-80, 80, 161)`), `corner` (default: the model's registered corner(s)),
    `drive`, `q0`, `throw` (raise `ConvergenceError` on a failed case; else NaN metrics),
    `label` (legend), solver options (`rtol`, `atol`, `max_steps`).

    **Returns:** a `KCEvent` (x = travel).
    """
    x = _cases(travel, "travel")
    rig = travel_rig(mech, corner, drive=drive)
    loads = event_loads(rig, x.size, travel=x)
    ev = _run("parallel_travel", rig, loads, x, "wheel_travel", "mm", "wheel height", q0,
              throw, label, **solver)
    for key in [k for k in ev.metrics if METRICS.get(k.rsplit("/", 1)[-1], ()) and
                METRICS[k.rsplit("/", 1)[-1]].per_roll]:
        ev.metrics.pop(key)  # no roll in parallel travel (0/0)
    return ev


def opposite_travel(axle: Mechanism, travel, *, corner=None, drive: str = "wheel_centre",
                    q0=None, throw: bool = True, label: str | None = None,
                    **solver) -> KCEvent:
    """Opposite wheel travel (roll) on an axle with a left and a right corner (`combine`): the
    left wheel travels +`travel`, the right −`travel` (mm). Adds `roll_angle` and
    `roll_stiffness` to the per-corner metrics."""
    x = _cases(travel, "travel")
    corners = _resolve(axle, corner)
    sides = sorted(rc.side for rc in corners)
    if sides != ["left", "right"]:
        raise InputError(
            f"opposite_travel needs an axle with one left and one right corner (combine "
            f"{{'left': m, 'right': mirror(m)}}); got sides {sides}."
        )
    pattern = [1.0 if rc.side == "left" else -1.0 for rc in corners]
    rig = travel_rig(axle, corner, drive=drive, pattern=pattern)
    loads = event_loads(rig, x.size, travel=x)
    return _run("opposite_travel", rig, loads, x, "wheel_travel", "mm", "wheel heights", q0,
                throw, label, **solver)


def vertical_force(mech: Mechanism, fz, *, corner=None, q0=None, throw: bool = True,
                   label: str | None = None, **solver) -> KCEvent:
    """Vertical force sweep: `fz` (N, up) at every contact point, wheels free. Derivative
    metrics hold the vertical load and differentiate along it (wheel rate = 1/(dz/dF_z))."""
    x = _cases(fz, "fz")
    rig = force_rig(mech, corner)
    loads = event_loads(rig, x.size, vertical=x)
    return _run("vertical_force", rig, loads, x, "vertical_force", "N", "vertical load", q0,
                throw, label, **solver)


def lateral_force(mech: Mechanism, fy, *, fz=None, corner=None, q0=None, throw: bool = True,
                  label: str | None = None, **solver) -> KCEvent:
    """Lateral force sweep `fy` (N, inboard positive) at the contact point under the vertical
    load `fz` (N; default the corner's design load)."""
    x = _cases(fy, "fy")
    rig = force_rig(mech, corner)
    loads = event_loads(rig, x.size, vertical=_fz(rig, fz), lateral=x)
    return _run("lateral_force", rig, loads, x, "lateral_force", "N", "vertical load", q0,
                throw, label, **solver)


def longitudinal_force(mech: Mechanism, fx, *, fz=None, at: str = "contact_patch",
                       corner=None, q0=None, throw: bool = True, label: str | None = None,
                       **solver) -> KCEvent:
    """Longitudinal force sweep `fx` (N, rearward positive: braking) at the contact point
    (outboard brakes) or the wheel centre (`at='wheel_centre'`: traction reacted by the body
    through the drive shaft), under the vertical load `fz`."""
    if at not in ("contact_patch", "wheel_centre"):
        raise InputError(f"at must be 'contact_patch' or 'wheel_centre'; got '{at}'.")
    x = _cases(fx, "fx")
    rig = force_rig(mech, corner)
    loads = event_loads(rig, x.size, vertical=_fz(rig, fz), longitudinal=x, at=at)
    return _run("longitudinal_force", rig, loads, x, "longitudinal_force", "N",
                "vertical load", q0, throw, label, **solver)


def braking(mech: Mechanism, force, *, fz=None, **kwargs) -> KCEvent:
    """Braking force `force` (N, positive = braking, i.e. rearward on the tyre) at the contact
    patch (outboard brakes), under the vertical load `fz`."""
    ev = longitudinal_force(mech, force, fz=fz, at="contact_patch", **kwargs)
    ev.name, ev.x_name = "braking", "braking_force"
    return ev


def traction(mech: Mechanism, force, *, fz=None, **kwargs) -> KCEvent:
    """Traction force `force` (N, positive = driving forward) at the wheel centre (drive torque
    reacted by the body), under the vertical load `fz`."""
    x = _cases(force, "force")
    ev = longitudinal_force(mech, -x, fz=fz, at="wheel_centre", **kwargs)
    ev.name, ev.x, ev.x_name = "traction", x, "traction_force"
    return ev


def aligning_torque(mech: Mechanism, mz, *, fz=None, corner=None, q0=None, throw: bool = True,
                    label: str | None = None, **solver) -> KCEvent:
    """Aligning torque sweep `mz` (N·mm, toe-out sense) at the contact point under the vertical
    load `fz`."""
    x = _cases(mz, "mz")
    rig = force_rig(mech, corner)
    loads = event_loads(rig, x.size, vertical=_fz(rig, fz), aligning=x)
    return _run("aligning_torque", rig, loads, x, "aligning_torque", "N·mm", "vertical load",
                q0, throw, label, **solver)


def steering(mech: Mechanism, rack_travel, *, travel: float = 0.0, rack: str = "rack_travel",
             corner=None, q0=None, throw: bool = True, label: str | None = None,
             **solver) -> KCEvent:
    """Steering: rack travel `rack_travel` (mm, see `with_rack`: positive toward the vehicle's
    left) with the wheel height held at `travel` (mm). The model needs a rack driver `rack`
    (`diffsusp.kc.with_rack`)."""
    x = _cases(rack_travel, "rack_travel")
    rig = travel_rig(mech, corner, rack=rack, require_rack=True)
    loads = event_loads(rig, x.size, travel=travel, rack=x)
    return _run("steering", rig, loads, x, "rack_travel", "mm", "wheel height", q0, throw,
                label, **solver)


def load_table(mech: Mechanism, table=TABLE_5_1, *, corner=None, q0=None, throw: bool = True,
               label: str | None = None, contact: str = "road", **solver) -> KCEvent:
    """A table of (F_vert, F_lat, F_long) load cases (N) at the contact point, per side
    (vertical up, lateral inboard, longitudinal rearward = braking), e.g. `TABLES['table_5_1']`
    (13 cases) or `TABLES['table_4_4']` (17). `contact` as `force_rig`: 'road' (default) at
    the ground contact point moving with the wheel; 'fixed' at the corner's contact-patch load
    point, where the thesis applies them: on the pseudo-McPherson (Adams/Car frame, left wheel)
    `contact='fixed'` is exactly `diffsusp.models.thesis_load_cases` (the 4 500 N case then
    holds the design position; at the road contact point the wheel sits 0.3 mm lower).
    x = case number (1-based). The loads alone, without the event: `corner_loads(mech, table)`."""
    table = np.asarray(table, dtype=float)
    if table.ndim != 2 or table.shape[1] != 3 or not np.all(np.isfinite(table)):
        raise InputError(
            f"table must be a finite (cases, 3) array of (F_vert, F_lat, F_long) in N; got "
            f"shape {table.shape}."
        )
    rig = force_rig(mech, corner, contact=contact)
    loads = corner_loads(rig.mech, table, corner=corner)
    x = np.arange(1.0, table.shape[0] + 1)
    return _run("load_table", rig, loads, x, "case", "", "vertical load", q0, throw, label,
                **solver)


def derivative_metrics(ev: KCEvent) -> dict:
    """The derivative metrics of an event (bump steer, wheel rate, compliances, ...)."""
    return {k: v for k, v in ev.metrics.items() if k.rsplit("/", 1)[-1] in DERIVATIVE_METRICS}


def compliance_matrix(ev: KCEvent, prefix: str = "") -> np.ndarray:
    """The 6×6 wheel-centre compliance matrix per case of a force event (see
    `diffsusp.kc.metrics`)."""
    if prefix not in ev.compliance:
        raise InputError(
            f"event '{ev.name}' has no compliance matrix for corner '{prefix}' (force events "
            "with a wheel-centre load point have one)."
        )
    return ev.compliance[prefix]


def anti_pitch(ev: KCEvent, *, cg_height: float, wheelbase: float, axle: str = "front",
               brake_front_fraction: float = 0.6, drive_front_fraction: float = 0.0,
               prefix: str = "") -> dict:
    """Anti-dive, anti-lift and anti-squat percentages from the side-view path slopes.

    With tan θ the slope of the side-view instant centre seen from the contact point (outboard
    brakes) or wheel centre (drive torque reacted by the body): front axle, tan θ = −(contact or
    wheel-centre recession rate); rear axle, tan θ = +rate. Then (classic single-axle formulas):
    anti-dive (front, braking) = tan θ_c · (L/h) · β_f; anti-lift (rear, braking) = tan θ_c ·
    (L/h) · (1 − β_f); anti-squat (rear, traction) = tan θ_w · (L/h) · (1 − δ_f); anti-lift
    (front, traction) = tan θ_w · (L/h) · δ_f; all × 100 %.

    **Arguments:** `ev` (a travel or force event), `cg_height` h and `wheelbase` L (mm),
    `axle` ('front' or 'rear'), brake and drive fractions on the front axle.

    **Returns:** {'anti_dive' or 'anti_lift_braking', 'anti_squat' or 'anti_lift_traction'}
    → (cases,) percentages.
    """
    m = ev.corner_metrics(prefix) if prefix else ev.metrics
    if "contact_recession_rate" not in m:
        raise InputError("anti_pitch needs a travel or force event (recession rates).")
    if axle not in ("front", "rear"):
        raise InputError(f"axle must be 'front' or 'rear'; got '{axle}'.")
    sign = -1.0 if axle == "front" else 1.0
    ratio = wheelbase / cg_height * 100.0
    tan_c = sign * np.asarray(m["contact_recession_rate"])
    tan_w = sign * np.asarray(m["wheel_centre_recession_rate"])
    if axle == "front":
        return {"anti_dive": tan_c * ratio * brake_front_fraction,
                "anti_lift_traction": tan_w * ratio * drive_front_fraction}
    return {"anti_lift_braking": tan_c * ratio * (1.0 - brake_front_fraction),
            "anti_squat": tan_w * ratio * (1.0 - drive_front_fraction)}
