"""The 30-DOF vehicle's input kinematics: wheel poses from K&C look-up tables.

spec: tyre_contact_model §5.2 (Table 30: per corner the half-track l_i, half-wheelbase L_i,
travel z_i, steer β_i, camber γ_i, wind-up ζ_i; §4.2.3: "the camber, wind-up and steer angles
and the track and wheelbase variations come from tables measured on a K&C bench with the
suspension travel and the rack displacement as inputs"), §5.4–5.5 item 3 (what the 30-DOF
model adds over the 12-DOF one: the static toe and camber, the track elastokinematics).

The thesis measured its tables on a bench; here `kc` computes them on a library suspension
(`diffsusp.models.pseudo_mcpherson` by default, for both axles): the wheel centre driven to a
travel z (the travel rig, `kc.travel_rig`) with a lateral force at the contact point, on a
grid (z, F_lat). The tables hold per axle, for its left wheel, the toe, camber,
half-track change and wheelbase change (Adams/Car per-side signs, `kc.METRICS`); a right
wheel is the mirror image. Inputs: the wheel travel (from the body's heave, roll and pitch
over the road and the tyre's deflection under its load, `corner_travel`) and the lateral
force (the compliance); the rack is not an input (the steer is the vehicle's own, added to
the toe). The wind-up ζ_i is left out: a rotation about the spin axis leaves the wheel plane,
so the zero-wobble tyre frame and its inputs, unchanged.

Interpolation: tensor-product cubic Hermite (slopes by centred differences of the knots,
one-sided at the ends, linear beyond the grid), linear in the table values, C¹ in the inputs,
so the poses are continuous and differentiable for the vehicle's dynamics and the on-board
pipeline. Units SI as `diffsusp.tyre.vehicle` (m, N, rad); `kc` works in mm, N.
"""

import pathlib

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .. import kc
from ..errors import ConvergenceError, InputError
from ..models import pseudo_mcpherson
from ..statics import Status

QUANTITIES = ("toe", "camber", "half_track_change", "wheelbase_change")
"""The tabulated K&C metrics (per side, Adams/Car signs): toe (rad, toe-in +), camber (rad,
top outboard +), half-track change (m, outboard +), wheelbase change (m, rearward +)."""

AXLE = np.array([0, 0, 1, 1])
"""The axle (0 front, 1 rear) of each corner in `vehicle.WHEELS` order (FL, FR, RL, RR)."""
SIDE = np.array([1.0, -1.0, 1.0, -1.0])
"""+1 for a left wheel (+y), −1 for a right wheel."""


def kc_cases(mech, travel, lateral) -> dict:
    """Direct K&C evaluations of a half axle (one corner) on the travel rig: per case the wheel
    centre at `travel` (m, bump +) with the lateral force `lateral` (N, inboard +) at the
    contact point (`kc.corner_loads`, `kc.evaluate`: one compiled program for all cases).

    **Returns:** dict of (cases,) arrays of `QUANTITIES` in SI (rad, m).
    **Raises:** `InputError` for a mechanism without exactly one corner, `ConvergenceError`
    when a case does not converge."""
    travel = np.atleast_1d(np.asarray(travel, float))
    lateral = np.broadcast_to(np.asarray(lateral, float), travel.shape)
    if travel.ndim != 1 or not (np.all(np.isfinite(travel)) and np.all(np.isfinite(lateral))):
        raise InputError("travel and lateral must be finite 1-D arrays of one length.")
    rig = kc.travel_rig(mech)
    if len(rig.corners) != 1:
        raise InputError(f"the K&C tables need a half axle with one corner; the model has "
                         f"{len(rig.corners)}.")
    loads = kc.corner_loads(rig.mech, lateral=lateral)
    driver = np.array(loads.driver)
    driver[:, rig.travel_drivers[0]] = 1000.0 * travel
    loads = eqx.tree_at(lambda ld: ld.driver, loads, jnp.asarray(driver))
    sol, metrics, _ = kc.evaluate(rig, loads)
    bad = np.flatnonzero(np.asarray(sol.status) != Status.CONVERGED)
    if bad.size:
        raise ConvergenceError(f"K&C case {int(bad[0])} (travel {travel[bad[0]]:.4g} m, "
                               f"lateral {lateral[bad[0]]:.4g} N) did not converge.")
    scale = {"toe": 1.0, "camber": 1.0, "half_track_change": 1e-3, "wheelbase_change": 1e-3}
    return {k: np.asarray(metrics[k], float) * scale[k] for k in QUANTITIES}


class KCTables(eqx.Module):
    """K&C look-up tables of both axles (spec tyre §5.2, Table 30): `travel` (k_t,) m and
    `lateral` (k_f,) N (inboard +) grids, `values` (2, k_t, k_f, 4) of `QUANTITIES` per axle
    (front, rear) for the left wheel. Build with `kc_tables`; evaluate with `corner` or
    `wheel_poses`."""

    travel: Float[Array, " kt"]
    lateral: Float[Array, " kf"]
    values: Float[Array, "2 kt kf 4"]

    def __check_init__(self):
        t, f = np.asarray(self.travel), np.asarray(self.lateral)
        if t.size < 2 or f.size < 2 or np.any(np.diff(t) <= 0) or np.any(np.diff(f) <= 0):
            raise InputError("K&C tables: travel and lateral grids need ≥ 2 increasing knots.")
        if self.values.shape != (2, t.size, f.size, len(QUANTITIES)):
            raise InputError(f"K&C tables: values of shape {self.values.shape}; expected "
                             f"{(2, t.size, f.size, len(QUANTITIES))}.")

    def lookup(self, axle, travel, lateral) -> Float[Array, "4"]:
        """`QUANTITIES` of the left wheel of `axle` (0, 1) at `travel` (m) and `lateral` (N,
        inboard +), by the C¹ cubic Hermite interpolant."""
        v = self.values[axle]  # (kt, kf, 4)
        kt, kf, q = v.shape
        along_f = hermite(self.lateral, jnp.moveaxis(v, 1, 0).reshape(kf, kt * q), lateral)
        return hermite(self.travel, along_f.reshape(kt, q), travel)

    def corner(self, travel: Float[Array, "4"], fy: Float[Array, "4"]):
        """Per corner (FL, FR, RL, RR) in the body frame (x forward, y left, z up): the steer
        added by the toe (rad, about z), the camber rotation (rad, about the carrier's x), and
        the wheel-centre displacement (4, 3) m from its design position, at the travel (m,
        bump +) and the tyre's lateral force `fy` (N, along the body's y: +y pushes a left
        wheel outboard)."""
        side = jnp.asarray(SIDE)
        vals = jax.vmap(self.lookup)(jnp.asarray(AXLE), travel, -side * fy)
        toe, camber, track, base = vals[:, 0], vals[:, 1], vals[:, 2], vals[:, 3]
        shift = jnp.stack([-base, side * track, travel], axis=1)
        return -side * toe, -side * camber, shift


DEFAULT_TABLES = pathlib.Path(__file__).parent / "data" / "kc_tables_pseudo_mcpherson.npz"
"""The shipped tables of `kc_tables()` (the pseudo-McPherson on both axles, the default grid),
written by `save_tables(kc_tables(), DEFAULT_TABLES)` and checked against `kc` by the tests:
the vehicle and the on-board pipeline use them without compiling a K&C program."""


def save_tables(tables: KCTables, path) -> None:
    """Write `tables` to an .npz archive (`load_tables` reads it)."""
    np.savez(path, travel=np.asarray(tables.travel), lateral=np.asarray(tables.lateral),
             values=np.asarray(tables.values), quantities=np.array(QUANTITIES))


def load_tables(path=None) -> KCTables:
    """`KCTables` from an archive of `save_tables` (default `DEFAULT_TABLES`).

    **Raises:** `InputError` for a missing file or one without the tables' arrays."""
    path = pathlib.Path(DEFAULT_TABLES if path is None else path)
    if not path.is_file():
        raise InputError(f"K&C tables: no file {path}.")
    with np.load(path) as z:
        missing = [k for k in ("travel", "lateral", "values") if k not in z.files]
        if missing:
            raise InputError(f"K&C tables {path}: missing {missing}.")
        if "quantities" in z.files and tuple(z["quantities"]) != QUANTITIES:
            raise InputError(f"K&C tables {path}: quantities {tuple(z['quantities'])}; "
                             f"expected {QUANTITIES}.")
        return KCTables(jnp.asarray(z["travel"], float), jnp.asarray(z["lateral"], float),
                        jnp.asarray(z["values"], float))


def hermite(x: Float[Array, " k"], y: Float[Array, "k m"], t) -> Float[Array, " m"]:
    """The cubic Hermite interpolant through (x, y) (slopes: centred differences of the knots,
    one-sided at the ends) at t, linear beyond the end knots with the end slopes: C¹, and linear
    in y."""
    dx = jnp.diff(x)
    secant = jnp.diff(y, axis=0) / dx[:, None]
    inner = (y[2:] - y[:-2]) / (x[2:] - x[:-2])[:, None]
    s = jnp.concatenate([secant[:1], inner, secant[-1:]], axis=0)
    k = x.shape[0]
    i = jnp.clip(jnp.searchsorted(x, t, side="right") - 1, 0, k - 2)
    h = x[i + 1] - x[i]
    u = jnp.clip((t - x[i]) / h, 0.0, 1.0)
    h00 = (1 + 2 * u) * (1 - u) ** 2
    h10 = u * (1 - u) ** 2
    h01 = u**2 * (3 - 2 * u)
    h11 = u**2 * (u - 1)
    inside = h00 * y[i] + h10 * h * s[i] + h01 * y[i + 1] + h11 * h * s[i + 1]
    below = y[0] + s[0] * (t - x[0])
    above = y[-1] + s[-1] * (t - x[-1])
    return jnp.where(t < x[0], below, jnp.where(t > x[-1], above, inside))


def tables_from_cases(travel, lateral, front: dict, rear: dict | None = None) -> KCTables:
    """`KCTables` from `kc_cases` evaluated on the grid (travel × lateral, travel-major):
    `front` (and `rear`; default the front's) dicts of (k_t·k_f,) arrays."""
    t, f = np.asarray(travel, float), np.asarray(lateral, float)

    def grid(cases):
        return np.stack([np.asarray(cases[k]).reshape(t.size, f.size) for k in QUANTITIES],
                        axis=-1)

    vals = np.stack([grid(front), grid(rear if rear is not None else front)])
    return KCTables(jnp.asarray(t), jnp.asarray(f), jnp.asarray(vals))


def grid_cases(travel, lateral):
    """The (travel, lateral) pairs of a grid, travel-major, as `tables_from_cases` reads them."""
    tt, ff = np.meshgrid(np.asarray(travel, float), np.asarray(lateral, float), indexing="ij")
    return tt.ravel(), ff.ravel()


TRAVEL_GRID = (-0.06, -0.03, 0.0, 0.03, 0.06)
"""The default travel knots of `kc_tables` (m)."""
LATERAL_GRID = (-3000.0, 0.0, 3000.0)
"""The default lateral-force knots of `kc_tables` (N, inboard +)."""


def kc_tables(front=None, rear=None, *, travel=TRAVEL_GRID,
              lateral=LATERAL_GRID) -> KCTables:
    """The K&C tables of the 30-DOF kinematics (spec tyre §5.2), computed by `kc` on half axles
    `front` and `rear` (`Mechanism`s with one corner; default `diffsusp.models.pseudo_mcpherson`
    for both, then computed once) on the grid `travel` (m) × `lateral` (N, inboard +). The
    default grid is coarse (5 × 3 cases: one compiled K&C program); the interpolant is C¹.

    **Returns:** `KCTables`."""
    if front is None:
        front = pseudo_mcpherson()
    tt, ff = grid_cases(travel, lateral)
    cf = kc_cases(front, tt, ff)
    cr = None if rear is None or rear is front else kc_cases(rear, tt, ff)
    return tables_from_cases(travel, lateral, cf, cr)


def corner_travel(corners, heave, roll, pitch, fz=None, fz_static=None,
                  tyre_stiffness=2.2e5) -> Float[Array, "4"]:
    """Wheel travel (m, bump +) of each corner for the body at `heave` (m, up +), `roll` (rad,
    about x: left side up +) and `pitch` (rad, about y: nose down +) from its static position
    over a flat road, with the wheels on the road: the body corner at (L_i, l_i) rises by
    heave + l_i·roll − L_i·pitch (small angles), and a tyre loaded by fz − fz_static (N) more
    than statically deflects by that over `tyre_stiffness` (N/m), lowering the wheel centre.
    `corners` (4, 3) as `Vehicle.corners`."""
    L, l = corners[:, 0], corners[:, 1]
    rise = heave + l * roll - L * pitch
    deflect = 0.0 if fz is None else (fz - fz_static) / tyre_stiffness
    return -rise - deflect


def wheel_poses(tables: KCTables, corners, travel, fy, steer=None):
    """The wheel carriers' poses in the body frame from the K&C tables (Table 30's chain:
    half-track and half-wheelbase moved by the tables, travel, steer = the vehicle's steer +
    the toe's, camber): (R (4, 3, 3) body ← carrier, O (4, 3) m, and the toe steer and camber
    angles (4,) rad of each carrier, signs of the body frame). `travel` (4,) m (bump +), `fy`
    (4,) N along the body's y, `steer` (4,) rad (default 0)."""
    steer = jnp.zeros(4) if steer is None else steer
    toe, camber, shift = tables.corner(travel, fy)
    O = corners + shift
    R = jax.vmap(lambda b, g: _rot_z(b) @ _rot_x(g))(steer + toe, camber)
    return R, O, toe, camber


def _rot_z(a):
    c, s = jnp.cos(a), jnp.sin(a)
    z, o = jnp.zeros_like(c), jnp.ones_like(c)
    return jnp.stack([jnp.stack([c, -s, z]), jnp.stack([s, c, z]), jnp.stack([z, z, o])])


def _rot_x(a):
    c, s = jnp.cos(a), jnp.sin(a)
    z, o = jnp.zeros_like(c), jnp.ones_like(c)
    return jnp.stack([jnp.stack([o, z, z]), jnp.stack([z, c, -s]), jnp.stack([z, s, c])])


__all__ = ["AXLE", "KCTables", "LATERAL_GRID", "QUANTITIES", "SIDE", "TRAVEL_GRID",
           "DEFAULT_TABLES", "corner_travel", "grid_cases", "hermite", "kc_cases", "kc_tables",
           "load_tables", "save_tables", "tables_from_cases", "wheel_poses"]
