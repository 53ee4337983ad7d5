"""Recursive Newton–Euler inverse dynamics of an MDH tree, its regressor and base parameters.

spec: tyre_contact_model §6.4 (Annex F: F-9…F-44, projected Khalil–Dombre form with the Coriolis
factor 2 of (F-31)). Standard parameters per body and joint j (F-9, plus the offset of Table 2):

    X_j = (XX, XY, XZ, YY, YZ, ZZ, MX, MY, MZ, M | k, h, fs, off)

inertia about O_j in frame j, first moments MS_j = M_j·O_jG_j, mass; joint stiffness k,
viscous damping h (f_v), Coulomb friction fs, effort offset off. The joint effort is

    Γ_j = (σ_j f_j + σ̄_j m_j)ᵀ a_j + k_j q_j + h_j q̇_j + fs_j sign(q̇_j) + off_j      (F-39, F-44)

linear in X, so the regressor W = ∂Γ/∂X is exact by `jax.jacfwd` (the design's "one way":
autodiff of the model, not hand-written column-wise products).

Gravity enters as the base acceleration V̇_0 = −g (F-32). External loads are wrenches applied
*on* body j by the environment, (f | m) in frame j about O_j; the thesis's 𝔽_ej (F-21) is the
wrench the body exerts on the environment, i.e. minus this.
"""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .. import lsq
from ..errors import ModelError
from .tree import LOCKED, PRISMATIC, REVOLUTE, Tree, joint_transforms

INERTIAL = ("XX", "XY", "XZ", "YY", "YZ", "ZZ", "MX", "MY", "MZ", "M")
JOINT = ("k", "h", "fs", "off")
PER_JOINT = INERTIAL + JOINT
N_PER_JOINT = len(PER_JOINT)


def parameter_names(tree: Tree) -> tuple[str, ...]:
    """Names of the standard parameters, row-major as `params` (n, 14): "XX1", …, "off7"."""
    return tuple(f"{p}{j + 1}" for j in range(tree.n) for p in PER_JOINT)


class Motion(NamedTuple):
    """Per-body kinematics of one Newton–Euler pass, each in its own frame: ω, ω̇, V (origin
    velocity), V̇ (origin acceleration, gravity folded in: V̇ − g)."""

    omega: Float[Array, "n 3"]
    omega_dot: Float[Array, "n 3"]
    velocity: Float[Array, "n 3"]
    acceleration: Float[Array, "n 3"]


class Dynamics(NamedTuple):
    """Result of `newton_euler`: `tau` (dof,) joint efforts; `base_wrench` (6,) the wrench
    (f | m) the base exerts on its successors, in frame 0 about O_0; `wrenches` (n, 6) the
    wrench a(j) exerts on body j, in frame j about O_j; `motion` (`Motion`)."""

    tau: Float[Array, " dof"]
    base_wrench: Float[Array, "6"]
    wrenches: Float[Array, "n 6"]
    motion: Motion


def _full(tree: Tree, v):
    out = jnp.zeros(tree.n, jnp.result_type(v, float))
    return out.at[np.asarray(tree.mobile, int)].set(v) if tree.dof else out


def newton_euler(
    tree: Tree,
    params: Float[Array, "n 14"],
    q: Float[Array, " dof"],
    qd: Float[Array, " dof"],
    qdd: Float[Array, " dof"],
    *,
    gravity: Float[Array, "3"] = (0.0, 0.0, -9.81),
    loads: Float[Array, "n 6"] | None = None,
    base_omega: Float[Array, "3"] | None = None,
    base_velocity: Float[Array, "3"] | None = None,
    base_omega_dot: Float[Array, "3"] | None = None,
    base_acceleration: Float[Array, "3"] | None = None,
) -> Dynamics:
    """Inverse dynamics by the recursive Newton–Euler algorithm (F-26…F-44, projected form).

    **Arguments:**
    - `tree`: the MDH tree; `params` (n, 14): standard parameters (`PER_JOINT` order) per body
      and joint (the joint part of locked joints is ignored).
    - `q`, `qd`, `qdd` (dof,): joint positions, velocities, accelerations of the mobile joints.
    - `gravity` (3,): in frame 0 (V̇_0 = base_acceleration − g).
    - `loads` (n, 6): wrenches applied on body j by the environment, frame j, about O_j.
    - `base_omega`, `base_velocity`, `base_omega_dot`, `base_acceleration` (3,): motion of the
      base frame (default at rest), in frame 0.

    **Returns:** `Dynamics`.
    """
    params = jnp.asarray(params)
    if params.shape != (tree.n, N_PER_JOINT):
        raise ModelError(f"params must have shape ({tree.n}, {N_PER_JOINT}) (XX…M, k, h, fs, off "
                         f"per body); got {params.shape}.")
    dtype = jnp.result_type(params, q, qd, qdd, float)
    z3 = jnp.zeros(3, dtype)
    g = jnp.asarray(gravity, dtype)
    w0 = z3 if base_omega is None else jnp.asarray(base_omega, dtype)
    v0 = z3 if base_velocity is None else jnp.asarray(base_velocity, dtype)
    wd0 = z3 if base_omega_dot is None else jnp.asarray(base_omega_dot, dtype)
    a0 = (z3 if base_acceleration is None else jnp.asarray(base_acceleration, dtype)) - g
    qf, qdf, qddf = _full(tree, q), _full(tree, qd), _full(tree, qdd)
    local = joint_transforms(tree, q)
    ez = jnp.array([0.0, 0.0, 1.0], dtype)
    n = tree.n
    ante = jnp.asarray(tree.antecedent, jnp.int32)
    rev = jnp.asarray([s == REVOLUTE for s in tree.sigma], dtype)
    pri = jnp.asarray([s == PRISMATIC for s in tree.sigma], dtype)
    # One scan over the joints in order (a(j) < j) for the forward recursion and one in reverse
    # order for the backward one: the program's size does not grow with the tree. Index 0 of
    # the carried arrays is the base, body j is index j.
    init = tuple(jnp.zeros((n + 1, 3), dtype).at[0].set(v) for v in (w0, wd0, v0, a0))

    def forward(carry, x):
        W, WD, V, AC = carry
        j, i, T, rj, pj, qdj, qddj = x
        A, P = T[:3, :3].T, T[:3, 3]
        wi, wdi, vi, ai = W[i], WD[i], V[i], AC[i]
        jwi = A @ wi
        vj = A @ (vi + jnp.cross(wi, P)) + pj * qdj * ez
        aj = (A @ (ai + jnp.cross(wdi, P) + jnp.cross(wi, jnp.cross(wi, P)))
              + pj * (qddj * ez + 2.0 * jnp.cross(jwi, qdj * ez)))
        wj = jwi + rj * qdj * ez
        wdj = A @ wdi + rj * (qddj * ez + jnp.cross(jwi, qdj * ez))
        out = (W.at[j + 1].set(wj), WD.at[j + 1].set(wdj), V.at[j + 1].set(vj),
               AC.at[j + 1].set(aj))
        return out, (wj, wdj, vj, aj)

    _, (omega, omega_dot, vel, acc) = jax.lax.scan(
        forward, init, (jnp.arange(n), ante, local, rev, pri, qdf, qddf))
    ext = jnp.zeros((n, 6), dtype) if loads is None else jnp.asarray(loads, dtype)

    def backward(F, x):
        j, i, T, p, w, wd, a, load = x
        XX, XY, XZ, YY, YZ, ZZ, MX, MY, MZ, M = (p[k] for k in range(10))
        J = jnp.stack([jnp.stack([XX, XY, XZ]), jnp.stack([XY, YY, YZ]),
                       jnp.stack([XZ, YZ, ZZ])])
        MS = jnp.stack([MX, MY, MZ])
        f = M * a + jnp.cross(wd, MS) + jnp.cross(w, jnp.cross(w, MS)) - load[:3] + F[j + 1, :3]
        m = J @ wd + jnp.cross(w, J @ w) + jnp.cross(MS, a) - load[3:] + F[j + 1, 3:]
        A, P = T[:3, :3], T[:3, 3]
        fa = A @ f
        F = F.at[i].add(jnp.concatenate([fa, A @ m + jnp.cross(P, fa)]))
        return F, jnp.concatenate([f, m])

    F, wrench = jax.lax.scan(
        backward, jnp.zeros((n + 1, 6), dtype),
        (jnp.arange(n), ante, local, params, omega, omega_dot, acc, ext), reverse=True)
    base = F[0]

    mob = np.asarray(tree.mobile, int)
    if not tree.dof:
        tau = jnp.zeros(0, dtype)
    else:
        prismatic = np.asarray([tree.sigma[j] == PRISMATIC for j in tree.mobile])
        body = jnp.where(prismatic, wrench[mob, 2], wrench[mob, 5])
        k, h, fs, off = (params[mob, 10 + c] for c in range(4))
        tau = body + k * qf[mob] + h * qdf[mob] + fs * jnp.sign(qdf[mob]) + off
    return Dynamics(tau, base, wrench, Motion(omega, omega_dot, vel, acc))


def inverse_dynamics(tree, params, q, qd, qdd, **kwargs) -> Float[Array, " dof"]:
    """Γ (dof,) of `newton_euler` (same arguments)."""
    return newton_euler(tree, params, q, qd, qdd, **kwargs).tau


def regressor(tree: Tree, q, qd, qdd, **kwargs) -> tuple[Float[Array, "dof p"], Array]:
    """(W, Γ_0): Γ = W·X + Γ_0 with X = params.ravel() (F-11), W = ∂Γ/∂X exactly by
    `jax.jacfwd` (Γ is linear in X); Γ_0 = Γ(X = 0) is the part of the external loads that does
    not depend on the parameters (zero without `loads`). Same keywords as `newton_euler`."""
    dtype = jnp.result_type(q, qd, qdd, float)
    x0 = jnp.zeros(tree.n * N_PER_JOINT, dtype)

    def gamma(x):
        return inverse_dynamics(tree, x.reshape(tree.n, N_PER_JOINT), q, qd, qdd, **kwargs)

    return jax.jacfwd(gamma)(x0), gamma(x0)


@eqx.filter_jit
def regressor_batch(tree: Tree, Q, QD, QDD, gravity=(0.0, 0.0, -9.81)):
    """`regressor` (W only) over a batch of states (leading axis), compiled once per tree
    structure and batch shape (the tree's numbers are arguments, not constants)."""
    gravity = jnp.asarray(gravity, float)
    return jax.vmap(lambda q, qd, qdd: regressor(tree, q, qd, qdd, gravity=gravity)[0])(
        Q, QD, QDD)


def mass_matrix(tree: Tree, params, q) -> Float[Array, "dof dof"]:
    """A(q) = ∂Γ/∂q̈ (F-20), exact by `jax.jacfwd` (Γ is affine in q̈)."""
    z = jnp.zeros(tree.dof, jnp.result_type(params, q, float))
    return jax.jacfwd(lambda a: inverse_dynamics(tree, params, q, z, a, gravity=jnp.zeros(3)))(z)


def forward_dynamics(tree: Tree, params, q, qd, tau, *, free=None, qdd_given=None,
                     **kwargs) -> Float[Array, " dof"]:
    """q̈ from A(q)·q̈ = Γ − b(q, q̇) (the inverse model at q̈ = 0 gives b: Coriolis,
    centrifugal, gravity, joint laws and loads). `free` (static tuple of positions in q) selects
    the joints whose acceleration is unknown; the others follow `qdd_given` (driven joints,
    e.g. a prescribed steer). Same keywords as `newton_euler`."""
    dof = tree.dof
    free = tuple(range(dof)) if free is None else tuple(free)
    fixed = tuple(k for k in range(dof) if k not in free)
    dtype = jnp.result_type(params, q, qd, float)
    a0 = jnp.zeros(dof, dtype) if qdd_given is None else jnp.asarray(qdd_given, dtype)
    a0 = a0.at[np.asarray(free, int)].set(0.0)
    b = inverse_dynamics(tree, params, q, qd, a0, **kwargs)
    A = mass_matrix(tree, params, q)
    fi = np.asarray(free, int)
    sol = jnp.linalg.solve(A[fi][:, fi], jnp.asarray(tau, dtype)[fi] - b[fi])
    del fixed
    return a0.at[fi].set(sol)


def base_parameters(tree: Tree, seed: int = 0, *, samples: int | None = None,
                    gravity=(0.0, 0.0, -9.81), joint_parameters: bool = True, threshold=None):
    """The base (identifiable) parameters of a tree: the regressor stacked over random
    excitation (q, q̇, q̈ uniform in [−1, 1], NumPy generator `seed`), through `diffsusp.lsq`
    (QR identifiability, kept columns, regrouping relations). Columns that never act (the joint
    laws of locked joints, and k, h, fs, off when `joint_parameters` is False) are left out.

    **Returns:** (`lsq.Fit` whose `rank` is the number of base parameters and `relations` the
    regrouped combinations, the names of the columns used).
    """
    samples = samples or max(4 * tree.n * N_PER_JOINT // max(tree.dof, 1), 8)
    rng = np.random.default_rng(seed)
    Q, QD, QDD = rng.uniform(-1.0, 1.0, (3, samples, tree.dof))

    W = regressor_batch(tree, Q, QD, QDD, jnp.asarray(gravity, float))
    W = W.reshape(samples * tree.dof, -1)
    names = parameter_names(tree)
    use = []
    for j in range(tree.n):
        for c, p in enumerate(PER_JOINT):
            if p in JOINT and (tree.sigma[j] == LOCKED or not joint_parameters):
                continue
            use.append(j * N_PER_JOINT + c)
    W = np.asarray(W)[:, use]
    # cos(±π/2) = 6e-17 in the tables' constant angles leaves rounding in entries that are 0
    # (a column of 1e-17's would be a spurious dependent column): round them to 0.
    W = np.where(np.abs(W) < 1e-12 * np.abs(W).max(), 0.0, W)
    x = rng.uniform(0.5, 1.5, len(use))
    used = tuple(names[u] for u in use)
    return lsq.solve(W, W @ x, names=used, threshold=threshold, pivot=False), used
