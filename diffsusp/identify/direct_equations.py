"""The equations of the direct identification (spec stiffness §1.9–1.10, 4.35–4.54): per
measured case the rows Lᵀ D k = −Lᵀ (Q_ext + Q_known) in the solver's coordinates, and the
whitening of each case by the pose noise (generalised least squares, errors in variables).

D = ∂Q_int/∂k is `jax.jacfwd` of the solver's generalised forces (`statics.generalised_forces`)
in the stiffnesses (bushings: the generalised force of a unit −δ per axis; springs: K·ℓ − K·L0,
linear in the unknowns (K, K·L0)); L an orthonormal basis of the null space of Φ_q; rotational
coordinates scaled by the model's length scale so that every row is in N (spec §1.10). The
selection of the unknowns and the analysis of the stacked system are in `identify.direct`.
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..lsq import qr_r
from ..model.mechanism import Mechanism
from ..statics import generalised_forces
from ..statics.kernel import (
    assemble,
    bushing_force,
    bushing_params,
    constraint_jacobian,
    line_force,
    to_internal,
)

__all__: list[str] = []  # the assembly of `direct`; `direct` and `direct_system` are the API

# Unit columns per bushing: 6 stiffnesses, 6 constant forces on I, 6 cubic terms.
BUSHING_COLUMNS = 18


def _scaling(mech: Mechanism) -> np.ndarray:
    """Per coordinate: 1 for translations, 1/ℓ for the Gibbs coordinates (turns N·mm into N)."""
    n_parts = len(mech.parts)
    return np.tile(np.r_[np.ones(3), np.full(3, 1.0 / mech.length_scale)], n_parts)


def _mechanism_at(eval_mech: Mechanism, selection, x):
    """The evaluation model with the unknowns x (table units) put back into their fields: the
    stiffnesses and constants added, each unknown K·L0 = c turned into the free length c/K
    (the evaluation model has L0 = 0 there)."""
    b, s = eval_mech.bushings, eval_mech.springs
    n_b, nc = len(b.names), BUSHING_COLUMNS
    t = selection @ x
    kb = t[: nc * n_b].reshape(n_b, nc)
    ks, cs = t[nc * n_b :: 2], t[nc * n_b + 1 :: 2]
    k_spring = s.k + ks
    free_length = s.free_length + cs / jnp.where(k_spring == 0, 1.0, k_spring)
    return eqx.tree_at(
        lambda mm: (mm.bushings.k_trans, mm.bushings.k_rot, mm.bushings.preload_force,
                    mm.bushings.preload_torque, mm.bushings.cubic_trans, mm.bushings.cubic_rot,
                    mm.springs.k, mm.springs.free_length),
        eval_mech,
        (b.k_trans + kb[:, :3], b.k_rot + kb[:, 3:6], b.preload_force + kb[:, 6:9],
         b.preload_torque + kb[:, 9:12], b.cubic_trans + kb[:, 12:15],
         b.cubic_rot + kb[:, 15:], k_spring, free_length),
    )


def _element_geometry(mech: Mechanism, y):
    """Solver coordinates of every element's two parts, z (E, 12), with the ground as a virtual
    part at zero, and the markers' offsets from their parts' reference points."""
    lay = mech.topology
    yfull = jnp.concatenate([y, jnp.zeros(6, y.dtype)])
    offset = mech.markers.position - jnp.asarray(lay.centre[lay.marker_part])
    return lay, yfull, offset


def _unit_forces(mech: Mechanism, loads, y):
    """D = ∂Q/∂θ (n, 18·nb + 2·ns), `jax.jacfwd` of `statics.generalised_forces` with respect
    to, per bushing, θ = (Ktx, Kty, Ktz, Krx, Kry, Krz) in N/mm and N·mm/rad, then the six
    constant forces on I (preload, or K·δ0 of an offset) (Adams convention, spec stiffness
    §1.8), then the six cubic terms S of F = −(K·δ + S·δ³) in N/mm³ and N·mm/rad³, and per
    spring (K, K·L0): the stiffness at the model's free length L0 (0 where K·L0
    is an unknown) and the free length at unit stiffness, a tension −1 (spec §1.7,
    4.37–4.38). Exact: the forces are linear in θ."""
    b, s = mech.bushings, mech.springs
    n_b, n_s, nc = len(b.names), len(s.names), BUSHING_COLUMNS

    def forces(theta):
        tb = theta[: nc * n_b].reshape(n_b, nc)
        ts = theta[nc * n_b :].reshape(n_s, 2)
        at = eqx.tree_at(
            lambda mm: (mm.bushings.k_trans, mm.bushings.k_rot, mm.bushings.preload_force,
                        mm.bushings.preload_torque, mm.bushings.cubic_trans,
                        mm.bushings.cubic_rot, mm.springs.k, mm.springs.free_length),
            mech, (tb[:, :3], tb[:, 3:6], tb[:, 6:9], tb[:, 9:12], tb[:, 12:15], tb[:, 15:],
                   ts[:, 0], ts[:, 1]))
        return generalised_forces(at, loads, y)

    theta = jnp.concatenate([jnp.zeros(nc * n_b, y.dtype),
                             jnp.stack([jnp.ones(n_s, y.dtype), s.free_length], 1).ravel()])
    return jax.jacfwd(forces)(theta)


def _constraint_jacobian(mech: Mechanism, loads, y):
    """Φ_q (m, n) of the independent constraint rows at y (solver coordinates), from the
    solver's own constraint rows (Adams definitions, spec stiffness §1.6)."""
    return constraint_jacobian(mech, loads, y)


def _null_basis(eval_mech: Mechanism, loads, y, scale):
    """Orthonormal basis L (n, n − m) of the null space of the scaled Φ_q at y (spec §1.9,
    4.43–4.44), and the constraint Jacobian Φ_q (m, n) (unscaled)."""
    lay = eval_mech.topology
    n, m = lay.n, lay.m
    if not m:
        return jnp.eye(n, dtype=y.dtype), jnp.zeros((0, n), y.dtype)
    phi_q = _constraint_jacobian(eval_mech, loads, y)
    row_scale = jnp.asarray(np.where(lay.angular_live, eval_mech.length_scale, 1.0), y.dtype)
    basis, _ = jnp.linalg.qr((phi_q * row_scale[:, None] * scale[None, :]).T, mode="complete")
    return basis[:, m:], phi_q


def _case_rows(eval_mech: Mechanism, selection, q, loads):
    """Rows Lᵀ·D (r, p) and right-hand side −Lᵀ·(Q_ext + Q_known) (r,) of one case (N), and
    the null-space basis L (n, r).

    D = ∂Q_int/∂k (`jax.jacfwd` of `statics.generalised_forces` in the stiffnesses), gathered
    onto the unknowns by `selection`; Q_known is the solver's own assembly (`assemble`) of
    everything else: the loads, the elements, axes and cubic terms not identified."""
    lay = eval_mech.topology
    n, m = lay.n, lay.m
    y = to_internal(eval_mech, q)
    known, _ = assemble(eval_mech, loads, y, jnp.zeros(m, y.dtype), with_jacobian=False)
    known = known[:n]
    columns = _unit_forces(eval_mech, loads, y) @ selection
    scale = jnp.asarray(_scaling(eval_mech), y.dtype)
    null, _ = _null_basis(eval_mech, loads, y, scale)
    return null.T @ (columns * scale[:, None]), -null.T @ (known * scale), null


def _elastic_stiffness(mech: Mechanism, y):
    """Tangent stiffness −∂Q/∂y (n, n) of the bushings and linear springs of `mech` at y."""
    lay, yfull, offset = _element_geometry(mech, y)
    mk = mech.markers
    full = jnp.zeros((yfull.shape[0], yfull.shape[0]), y.dtype)
    b = mech.bushings
    if b.names:
        i, j = np.asarray(b.i_marker, dtype=int), np.asarray(b.j_marker, dtype=int)
        idx = lay.coords(i, j)
        params = {k: v for k, v in bushing_params(mech).items() if not k.startswith("spline")}
        jac = jax.vmap(jax.jacfwd(functools.partial(bushing_force, spline_mask=None)))(
            yfull[idx], offset[i], mk.orientation[i], offset[j], mk.orientation[j], params)
        full = full.at[idx[:, :, None], idx[:, None, :]].add(jac)
    s = mech.springs
    if s.names:
        i, j = np.asarray(s.i_marker, dtype=int), np.asarray(s.j_marker, dtype=int)
        idx = lay.coords(i, j)

        def spring(z, x0i, x0j, k, free_length):
            return line_force(z, x0i, x0j, lambda length: k * (length - free_length))

        jac = jax.vmap(jax.jacfwd(spring))(yfull[idx], offset[i], offset[j], s.k, s.free_length)
        full = full.at[idx[:, :, None], idx[:, None, :]].add(jac)
    return full[: y.shape[0], : y.shape[0]]


def _case_whitener(eval_mech: Mechanism, selection, q, null, x, pose_cov):
    """Whitening matrix C⁻¹ (r, r) of one case: Σ_r = C Cᵀ is the covariance of the case's
    equation residual caused by pose errors of covariance `pose_cov` (n, n, solver
    coordinates), to first order, at the solution x.

    A pose error dy moves the residual Lᵀ(Q + Φ_qᵀλ) by Lᵀ·K·dy with K the tangent stiffness.
    Only the elastic part of K (bushings, springs at x) is kept: the geometric terms of the loads
    and of the joint reactions are smaller by the ratio of a part's rotation error (≈ noise /
    landmark spread) to the bushings' deformations, and the change of L itself multiplies the
    small residual.
    """
    y = to_internal(eval_mech, q)
    mech_x = _mechanism_at(eval_mech, selection, x)
    scale = jnp.asarray(_scaling(eval_mech), y.dtype)
    sens = null.T @ (scale[:, None] * _elastic_stiffness(mech_x, y))  # (r, n)
    cov = sens @ pose_cov @ sens.T
    r = cov.shape[0]
    cov = cov + (1e-12 * jnp.trace(cov) / r + 1e-300) * jnp.eye(r, dtype=cov.dtype)
    chol = jnp.linalg.cholesky(cov)
    return jax.scipy.linalg.solve_triangular(chol, jnp.eye(r, dtype=cov.dtype), lower=True)


_QR_CHUNK = 1024


@jax.jit
def r_factor(W, y):
    """R-factor (positive diagonal) of [W, −y], by a tall-skinny QR: chunks of rows reduced
    separately, then their R's (one tall QR is several times slower for 10⁵ rows)."""
    m = jnp.concatenate([W, -y[:, None]], axis=1)
    n, q = m.shape
    if n > 2 * _QR_CHUNK:
        k = -(-n // _QR_CHUNK)
        m = jnp.concatenate([m, jnp.zeros((k * _QR_CHUNK - n, q), m.dtype)])
        m = jax.vmap(lambda x: jnp.linalg.qr(x, mode="r"))(m.reshape(k, _QR_CHUNK, q))
        m = m.reshape(-1, q)
    return qr_r(m)


@eqx.filter_jit
def system_arrays(eval_mech: Mechanism, selection, q, loads):
    return jax.vmap(lambda q_, l_: _case_rows(eval_mech, selection, q_, l_))(q, loads)


@eqx.filter_jit
def whiteners(eval_mech: Mechanism, selection, q, null, x, pose_cov):
    return jax.vmap(lambda q_, n_, c_: _case_whitener(eval_mech, selection, q_, n_, x, c_))(
        q, null, pose_cov)
