"""Quantities derived from an equilibrium: poses, bushing deformations and forces, spring
lengths and forces, joint reactions. Each function takes public coordinates q (one case, or a
leading case axis) and is differentiable, so it composes with the implicit solve.

spec: stiffness §0 (poses, projected angles), §1.8 (bushing law), §1.7 (springs), §1.9
(multipliers are the joint reactions).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ..compilation import filter_jit
from ..geometry import gibbs_to_matrix
from ..model.mechanism import GROUND, Mechanism
from .kernel import (
    bushing_params,
    bushing_state,
    constraint_groups,
    marker_offsets,
    part_poses_internal,
    spring_tension,
    to_internal,
)
from .status import Status


def _batched(fn):
    """Apply a one-case function of (mech, q, ...) over a leading case axis of q if present,
    compiled (`eqx.filter_jit`: called op by op, bushing_states took ~100 ms for 13 cases)."""

    @filter_jit
    @functools.wraps(fn)
    def wrapper(mech, q, *args):
        q = jnp.asarray(q)
        if q.ndim == 2:
            return jax.vmap(lambda q_, *a: fn(mech, q_, *a))(q, *args)
        return fn(mech, q, *args)

    return wrapper


@_batched
def part_poses(mech: Mechanism, q):
    """Rotation R (P, 3, 3) and translation T (P, 3) (mm) of every part frame in the global
    frame (at design R = I and T = 0)."""
    qb = q.reshape(-1, 6)
    return jax.vmap(gibbs_to_matrix)(qb[:, 3:]), qb[:, :3]


@_batched
def marker_poses(mech: Mechanism, q):
    """Global positions (M, 3) (mm) and orientations (M, 3, 3) of every marker."""
    rot, trans = part_poses(mech, q)
    part = np.asarray(mech.markers.part)
    moving = part != GROUND
    idx = np.where(moving, part, 0)
    r = jnp.where(moving[:, None, None], rot[idx], jnp.eye(3)) if len(mech.parts) else jnp.eye(3)
    t = jnp.where(moving[:, None], trans[idx], 0.0) if len(mech.parts) else jnp.zeros(3)
    pos = t + jnp.einsum("mij,mj->mi", r, mech.markers.position)
    return pos, jnp.einsum("mij,mjk->mik", r, mech.markers.orientation)


def _element_z(mech, q, i_markers, j_markers):
    y = jnp.concatenate([to_internal(mech, q), jnp.zeros(6)])
    return y[mech.topology.coords(i_markers, j_markers)], marker_offsets(mech)


@_batched
def bushing_states(mech: Mechanism, q):
    """Per bushing: translational deformation δ_T (n, 3) (mm, in J), projected angles (n, 3)
    (rad), force (n, 3) (N) and torque (n, 3) (N·mm) on the I part in J axes."""
    b = mech.bushings
    i, j = np.asarray(b.i_marker, dtype=int), np.asarray(b.j_marker, dtype=int)
    z, offset = _element_z(mech, q, i, j)
    mk = mech.markers
    params = bushing_params(mech)
    if b.has_splines:
        mask = jnp.asarray(b.spline_axes, dtype=bool)
        state = jax.vmap(bushing_state)(z, offset[i], mk.orientation[i], offset[j],
                                        mk.orientation[j], params, mask)
    else:
        params = {k: v for k, v in params.items() if not k.startswith("spline")}
        state = jax.vmap(functools.partial(bushing_state, spline_mask=None))(
            z, offset[i], mk.orientation[i], offset[j], mk.orientation[j], params
        )
    return state[:4]


@_batched
def spring_states(mech: Mechanism, q):
    """Per spring: length (n,) (mm) and tension (n,) (N, positive pulls the seats together)."""
    s = mech.springs
    pos, _ = marker_poses(mech, q)
    length = jnp.linalg.norm(pos[np.asarray(s.i_marker)] - pos[np.asarray(s.j_marker)], axis=-1)
    params = dict(k=s.k, free_length=s.free_length, table_x=s.table_x, table_y=s.table_y)
    tension = jnp.stack(
        [
            spring_tension(length[e], {k: v[e] for k, v in params.items()}, s.tabulated[e])
            for e in range(len(s.names))
        ]
    ) if s.names else jnp.zeros(0)
    return length, tension


@filter_jit
def joint_reactions(mech: Mechanism, sol):
    """Reaction wrench of every joint on its I part, at the I marker, global components, from
    `sol` (a `diffsusp.statics.StaticSolution`: its `q` and `multipliers`).

    **Returns:** force (n_joints, 3) (N) and moment (n_joints, 3) (N·mm), with a leading case
    axis if `sol` has one. Rows dropped as redundant carry no reaction (Adams does the same).
    """
    if sol.q.ndim == 2:
        return jax.vmap(lambda q, lam: _joint_reactions(mech, q, lam))(sol.q, sol.multipliers)
    return _joint_reactions(mech, sol.q, sol.multipliers)


def _joint_reactions(mech: Mechanism, q, lam):
    topo = mech.topology
    lam_slots = jnp.concatenate([lam, jnp.zeros(1)])
    p, r = part_poses_internal(to_internal(mech, q))
    pos, _ = marker_poses(mech, q)
    n_joints = len(mech.joints.names)
    force = jnp.zeros((n_joints, 3))
    moment = jnp.zeros((n_joints, 3))
    for g, fn, args, _ in constraint_groups(mech, mech.loads()):
        if g.kind == "driver":
            continue
        parts = np.asarray(g.coords)[:, ::6] // 6
        lam_e = lam_slots[jnp.asarray(g.row_slots - topo.base)]
        react = jax.vmap(fn)(p[parts[:, 0]], r[parts[:, 0]], p[parts[:, 1]], r[parts[:, 1]],
                             lam_e, *args)[1]
        f_i = react[:, :3]
        # The moment about the I part's reference point, moved to the I marker.
        i = np.asarray(mech.joints.i_marker)[g.members]
        arm = pos[i] - p[parts[:, 0]]
        force = force.at[g.members].set(f_i)
        moment = moment.at[g.members].set(react[:, 3:6] - jnp.cross(arm, f_i))
    return force, moment


def flagged_cases(sol) -> dict[str, np.ndarray]:
    """The cases of a solution that a check fails, as arrays of case indices.

    spec: stiffness §0 (bushing law validity), §1.9 (KKT system); DESIGN.md "Static
    equilibrium" (failures are reported per case). `sol` is a `StaticSolution` with a leading
    case axis, or anything with its `status`, `stable` and `law_valid` arrays:

    - 'failed': the cases that did not converge (a case that was not solved,
      `Status.NOT_SOLVED`, is in no list);
    - 'unstable': converged cases whose `stable` flag is False;
    - 'law_invalid': converged cases whose `law_valid` flag is False.

    A flag that is None (a solution computed under a transformation) flags no case.
    """
    status = np.atleast_1d(np.asarray(sol.status))
    converged = status == Status.CONVERGED

    def failing(flag):
        if flag is None:
            return np.zeros(0, dtype=int)
        return np.flatnonzero(converged & ~np.atleast_1d(np.asarray(flag, dtype=bool)))

    failed = (status != Status.CONVERGED) & (status != Status.NOT_SOLVED)
    return {"failed": np.flatnonzero(failed), "unstable": failing(sol.stable),
            "law_invalid": failing(sol.law_valid)}
