"""Per-case checks of an equilibrium: is it stable, and are the bushing laws used within their
validity there.

spec: stiffness §0 (projected angles and their validity), §1.9 (KKT system); DESIGN.md
"Static equilibrium". Both checks run on every solution `solve_statics` and `solve_sweep`
return (`StaticSolution.stable`, `StaticSolution.law_valid`); the functions below give the
numbers behind the flags.

**Stability.** A static equilibrium (q*, λ*) is stable when every small displacement the joints
allow costs positive work: the reduced tangent stiffness K_r = Nᵀ K N is positive definite, with
K = −∂Q/∂q the tangent stiffness (constraint Hessian Σλ∂²Φ included: `Linearization.stiffness`)
and N a basis of the null space of Φ_q (`Linearization.constraint_jacobian`). Three choices:

- Adams bushings are not exactly conservative (the law acts on I and J receives the moment
  transfer δ × F), so K_r is not exactly symmetric. What is checked is its symmetric part
  S = (K_r + K_rᵀ)/2: S positive definite means xᵀ K_r x > 0 for every admissible x (no
  admissible direction along which the structure gives way), which also excludes divergence
  (every real eigenvalue of K_r is then positive).
- Coordinates: the solver's (reference point in mm, Gibbs vector) are used. At a KKT point the
  projected Hessian of the Lagrangian transforms by congruence under a change of coordinates
  (the terms with the second derivatives of the change multiply the residual, which is zero), so
  its signature, hence the flag, does not depend on them (Sylvester's law of inertia).
- Scale: rotation coordinates are multiplied by the model's length scale L (so every entry is
  in N/mm) and N is orthonormal in those units; the stability margin is the smallest eigenvalue
  of S divided by the largest in magnitude, and the equilibrium is flagged stable when the
  margin exceeds `STABILITY_TOLERANCE` (1e-9). A margin between −1e-9 and 1e-9 is a mode with
  no stiffness within round-off (neutral, a free mode): not positive definite, so not stable.
  Under the Table 5-1 loads (no load for the models without a contact patch) the built-in
  models' margins are above 1e-5 (two_bushing_coupler
  9.6e-5, pseudo_mcpherson 1.2e-4 to 4.2e-4, double_wishbone_bushings 2.6e-3); along a load
  ramp that ends in a limit point the margin falls through 1e-6 before the solver stalls.

**Law validity.** The bushing laws are functions of the projected angles AX, AY, AZ, which
describe a rotation only while it is small about two of the axes: the thesis states
|AX|, |AY| < 15° and |AZ| < 90° (spec stiffness §0; Adams warns above about 10°). A case's law is
valid when no bushing axis that carries a law (nonzero linear or cubic rotational stiffness, or
a spline) exceeds its limit (`ANGLE_LIMITS_DEG`). Under large loads a bushing can end up turned
by 170°: a true equilibrium of the linear law, meaningless for the part it stands for.

Cases that did not converge have both flags False.
"""

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ..compilation import filter_jit
from ..errors import ModelWarning
from ..model.mechanism import Loads, Mechanism
from ._linearize import linearize
from .outputs import bushing_states
from .status import Status

STABILITY_TOLERANCE = 1e-9
"""Smallest margin λ_min(S)/max|λ(S)| of a stable equilibrium (see the module docstring)."""

ANGLE_LIMITS_DEG = (15.0, 15.0, 90.0)
"""Validity of the projected angles (|AX|, |AY|, |AZ|) of a bushing law, in degrees (thesis,
spec stiffness §0)."""


def _coordinate_scale(mech: Mechanism):
    """1 for the translation coordinates, 1/L for the Gibbs vectors (L the length scale, mm)."""
    n_parts = mech.topology.n // 6
    block = np.r_[np.ones(3), np.full(3, 1.0 / mech.length_scale)]
    return jnp.asarray(np.tile(block, n_parts))


def reduced_stiffness(mech: Mechanism, loads: Loads, q: Float[Array, " n"],
                      multipliers: Float[Array, " m"]) -> Float[Array, "d d"]:
    """The reduced tangent stiffness K_r = Nᵀ K N (N/mm) of one equilibrium, in scaled
    solver coordinates (rotations × L), N an orthonormal basis of the null space of Φ_q
    (d = n − m columns, the kinematic degrees of freedom). Not symmetric in general.

    **Arguments:** `mech`, one load case `loads`, its public coordinates `q` and `multipliers`
    (e.g. `sol.q[c]`, `sol.multipliers[c]`); `jax.vmap` it over cases.
    """
    lin = linearize(mech, loads, q, multipliers)
    return _reduced(mech, lin.stiffness, lin.constraint_jacobian)


def _reduced(mech: Mechanism, stiffness, constraint_jacobian):
    d = _coordinate_scale(mech)
    k = d[:, None] * stiffness * d[None, :]
    a = constraint_jacobian * d[None, :]
    m = a.shape[0]
    if m == 0:
        return k
    # Full SVD of the (m, n) constraint Jacobian; the last n − m right singular vectors span
    # its null space (the independent rows have full rank at a regular configuration). A
    # non-finite one (a case that did not converge) is replaced, so no NaN reaches LAPACK.
    a = jnp.where(jnp.all(jnp.isfinite(a)), a, jnp.eye(*a.shape, dtype=a.dtype))
    _, _, vt = jnp.linalg.svd(a, full_matrices=True)
    basis = vt[m:].T
    return basis.T @ k @ basis


def stability_margin(mech: Mechanism, loads: Loads, q: Float[Array, " n"],
                     multipliers: Float[Array, " m"]) -> Float[Array, ""]:
    """λ_min(S) / max|λ(S)| of the symmetric part S of `reduced_stiffness`, one case: positive
    for a stable equilibrium, negative for an unstable one (1 when there is no degree of
    freedom; NaN when the stiffness is not finite)."""
    lin = linearize(mech, loads, q, multipliers)
    return stability_margins(mech, lin.stiffness[None], lin.constraint_jacobian[None])[0]


def stability_margins(mech: Mechanism, stiffness: Float[Array, "cases n n"],
                      constraint_jacobian: Float[Array, "cases m n"]) -> Float[Array, " cases"]:
    """`stability_margin` of a batch of linearised equilibria (their `Linearization.stiffness`
    and `constraint_jacobian`), for a caller that has them. Case after case (`lax.map`): each
    SVD and eigen-decomposition is then one small LAPACK call that runs inline. jaxlib splits a
    batched call over the CPU thread pool and waits for it from a pool thread, so two batched
    calls that run at once (e.g. beside a batched LU of the same program) can deadlock a
    2-thread pool."""

    # Not differentiated: the margin feeds a boolean flag, and the SVD of a full basis has no
    # JVP (a program that differentiates the K&C metrics computes the flags too).
    stiffness, constraint_jacobian = jax.lax.stop_gradient((stiffness, constraint_jacobian))

    def one(k_a):
        kr = _reduced(mech, *k_a)
        if kr.shape[0] == 0:
            return jnp.ones((), kr.dtype)
        finite = jnp.all(jnp.isfinite(kr))
        sym = jnp.where(finite, 0.5 * (kr + kr.T), jnp.eye(kr.shape[0], dtype=kr.dtype))
        eig = jnp.linalg.eigvalsh(sym)
        margin = eig[0] / jnp.maximum(jnp.max(jnp.abs(eig)), jnp.finfo(kr.dtype).tiny)
        return jnp.where(finite, margin, jnp.nan)

    return jax.lax.map(one, (stiffness, constraint_jacobian))


def kkt_stability_margin(mech: Mechanism, jacobian: Float[Array, "k k"]) -> Float[Array, ""]:
    """`stability_margin` of one equilibrium from a KKT Jacobian in twist coordinates (per part
    the displacement of its reference point and a rotation vector; `kernel.assemble_twist`),
    e.g. the one the Newton factorised at the solution: K = −J[:n, :n], Φ_δ = J[n:, :n].

    At a KKT point the reduced stiffness in twist and in Gibbs coordinates are congruent (the
    moments vanish, so the Gibbs Jacobian is Tᵀ·J·T with T = diag(I, G(b))), hence the same
    sign of the margin (module docstring); its value differs by the conditioning of G(b),
    which is 1 at design. The null-space basis comes from a complete QR of Φ_δᵀ (any
    orthonormal basis gives the same eigenvalues), the smallest LAPACK call that gives one.
    Not differentiated; NaN when the Jacobian is not finite."""
    jacobian = jax.lax.stop_gradient(jacobian)
    n = mech.topology.n
    d = _coordinate_scale(mech)
    k = -d[:, None] * jacobian[:n, :n] * d[None, :]
    a = jacobian[n:, :n] * d[None, :]
    finite = jnp.all(jnp.isfinite(jacobian))
    m = a.shape[0]
    if m:
        a = jnp.where(finite, a, jnp.eye(*a.shape, dtype=a.dtype))
        basis = jnp.linalg.qr(a.T, mode="complete")[0][:, m:]
        k = basis.T @ jnp.where(finite, k, 0.0) @ basis
    if k.shape[0] == 0:
        return jnp.ones((), k.dtype)
    sym = jnp.where(finite, 0.5 * (k + k.T), jnp.eye(k.shape[0], dtype=k.dtype))
    eig = jnp.linalg.eigvalsh(sym)
    margin = eig[0] / jnp.maximum(jnp.max(jnp.abs(eig)), jnp.finfo(k.dtype).tiny)
    return jnp.where(finite, margin, jnp.nan)


def _carried_rotations(mech: Mechanism):
    """(bushings, 3) mask of the rotation axes that carry a law (an axis with no law has no
    validity to leave)."""
    b = mech.bushings
    spline = jnp.asarray(b.spline_axes, dtype=bool).reshape(-1, 6)[:, 3:]
    return (b.k_rot != 0) | (b.cubic_rot != 0) | spline


def law_validity(mech: Mechanism, q: Float[Array, " n"], *, angles=None) -> Float[Array, ""]:
    """The largest ratio |angle| / limit over every bushing rotation axis that carries a law,
    one case (public coordinates q, or the bushings' projected `angles` (bushings, 3) when the
    caller has them): ≤ 1 where the laws are valid (`ANGLE_LIMITS_DEG`); 0 for a model without
    bushings."""
    if not mech.bushings.names:
        return jnp.zeros((), jnp.result_type(q if angles is None else angles))
    if angles is None:
        angles = bushing_states(mech, q)[1]
    ratio = jnp.abs(angles) / jnp.radians(jnp.asarray(ANGLE_LIMITS_DEG))
    return jnp.max(jnp.where(_carried_rotations(mech), ratio, 0.0))


def warn_law_validity(mech: Mechanism, angles, stacklevel: int = 2) -> None:
    """Warn (`ModelWarning`) about the largest projected angle of a bushing axis that carries
    a law beyond its validity, if any; `angles` (cases, bushings, 3) rad, concrete."""
    if not mech.bushings.names:
        return
    b = mech.bushings
    carried = ((np.asarray(b.k_rot) != 0) | (np.asarray(b.cubic_rot) != 0)
               | np.asarray(b.spline_axes, dtype=bool).reshape(-1, 6)[:, 3:])
    angles = np.abs(np.asarray(angles)).reshape(-1, len(b.names), 3)
    angles = np.where(carried, angles, 0.0)
    ratio = angles / np.radians(ANGLE_LIMITS_DEG)
    if np.any(ratio > 1.0):
        c, e, a = np.unravel_index(np.argmax(ratio), ratio.shape)
        warnings.warn(
            f"bushing '{mech.bushings.names[e]}' is rotated by {np.degrees(angles[c, e, a]):.1f}° "
            f"about its {'xyz'[a]} axis (case {c}), beyond the projected angles' validity "
            f"(|AX|, |AY| < 15°, |AZ| < 90°): its law is not meaningful there. Check the loads "
            "or model a joint instead of the bushing.",
            ModelWarning,
            stacklevel=stacklevel + 1,
        )


def equilibrium_flags(mech: Mechanism, loads: Loads, q: Float[Array, "cases n"],
                      multipliers: Float[Array, "cases m"], converged: Bool[Array, " cases"]
                      ) -> tuple[Bool[Array, " cases"], Bool[Array, " cases"]]:
    """(stable, law_valid) of a batch of equilibria (leading case axis of `loads`, q,
    multipliers, converged); both False where a case did not converge. Not differentiated
    (`stop_gradient`: the flags are booleans, and eigen-decompositions stay out of
    derivatives)."""
    mech, loads, q, multipliers = jax.lax.stop_gradient((mech, loads, q, multipliers))
    # A case that did not converge may hold NaNs or a wild pose: check the design pose instead
    # (its flags are False anyway), so that no NaN reaches an eigen-decomposition.
    q = jnp.where(converged[:, None], q, 0.0)
    multipliers = jnp.where(converged[:, None], multipliers, 0.0)
    # Case after case (lax.map): the linearisation vmapped over cases compiles ~1.7x slower
    # (its scatter), and this program is compiled next to every concrete solve.
    margin = jax.lax.map(lambda a: stability_margin(mech, *a), (loads, q, multipliers))
    ratio = jax.vmap(lambda q_: law_validity(mech, q_))(q)
    return (converged & (margin > STABILITY_TOLERANCE),
            converged & (ratio <= 1.0))


@filter_jit
def _flags(mech, loads, q, multipliers, converged):
    return equilibrium_flags(mech, loads, q, multipliers, converged)


def _is_traced(tree) -> bool:
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(tree))


_FLAG_CHUNK = 64
"""Cases per call of the compiled flags program: every table size (one case, 13, 4096) reuses
one program per model structure (the last chunk is padded), so a test suite or an
identification that solves tables of many sizes compiles it once; a chunk costs ~10–30 ms."""


def with_flags(mech: Mechanism, loads: Loads, sol):
    """`sol` (a `StaticSolution`, one case or a leading case axis) with `stable` and
    `law_valid` filled in; unchanged (None flags) when any input is traced, so that programs
    that solve inside jit / vmap / grad (identification, K&C derivatives) do not grow."""
    if _is_traced((mech, loads, sol)):
        return sol
    single = loads.n_cases is None
    if single:
        loads, batch = jax.tree.map(lambda a: a[None], (loads, sol))
    else:
        batch = sol
    n = batch.status.shape[0]
    # Sliced on the host: a device gather per array and chunk costs more than the chunk's work.
    loads_h, q, lam, status = jax.tree.map(np.asarray, (loads, batch.q, batch.multipliers,
                                                        batch.status))
    stable, law_valid = [np.zeros(0, bool)], [np.zeros(0, bool)]
    for start in range(0, n, _FLAG_CHUNK):
        index = np.minimum(np.arange(start, start + _FLAG_CHUNK), n - 1)
        real = np.arange(start, start + _FLAG_CHUNK) < n
        out = _flags(mech, jax.tree.map(lambda a, index=index: a[index], loads_h), q[index],
                     lam[index], (status[index] == Status.CONVERGED) & real)
        stable.append(np.asarray(out[0])[real])
        law_valid.append(np.asarray(out[1])[real])
    stable, law_valid = jnp.asarray(np.concatenate(stable)), jnp.asarray(np.concatenate(law_valid))
    if single:
        stable, law_valid = stable[0], law_valid[0]
    return eqx.tree_at(lambda s: (s.stable, s.law_valid), sol, (stable, law_valid),
                       is_leaf=lambda x: x is None)
