"""Tree structures in modified Denavit–Hartenberg (Khalil–Kleinfinger) parameters.

spec: tyre_contact_model §6.1–6.3 (Annex F: F-1…F-8). A tree of n joints links bodies C_1…C_n
to the base C_0; joint j joins C_j to its antecedent C_{a(j)} (a(j) < j). Each joint has six
geometric parameters (γ_j, b_j, α_j, d_j, θ_j, r_j) and a type σ_j: 0 revolute (the joint
variable adds to θ_j), 1 prismatic (adds to r_j), 2 locked (no variable: the frame is fixed on
the antecedent body; θ_j and r_j are constants, e.g. the wheel wobble of Table 1).

Units: any consistent set (the thesis's tables are SI: m, rad). The joint vector `q` holds one
entry per *mobile* joint (σ ∈ {0, 1}), in joint order; `Tree.mobile` gives their indices.
"""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..errors import ModelError

REVOLUTE, PRISMATIC, LOCKED = 0, 1, 2


@dataclasses.dataclass(frozen=True)
class Row:
    """One printed row of an MDH table: joint j with antecedent a, type σ and the six geometric
    parameters; `variable` is the joint variable's name ("" for a locked joint), `label` says
    what the joint is."""

    j: int
    a: int
    sigma: int
    gamma: float
    b: float
    alpha: float
    d: float
    theta: float
    r: float
    variable: str = ""
    label: str = ""


class Tree(eqx.Module):
    """An MDH tree: geometric parameters as arrays (differentiable), topology static.

    **Fields:** `gamma`, `b`, `alpha`, `d`, `theta`, `r` (n,): the constant parts of the six
    parameters (for a revolute joint the variable adds to θ_j, for a prismatic one to r_j);
    `antecedent` (n,) a(j) with 0 the base and bodies numbered 1…n; `sigma` (n,) joint types;
    `variables` joint-variable names ("" for locked joints); `labels` meanings.
    """

    gamma: Float[Array, " n"]
    b: Float[Array, " n"]
    alpha: Float[Array, " n"]
    d: Float[Array, " n"]
    theta: Float[Array, " n"]
    r: Float[Array, " n"]
    antecedent: tuple[int, ...] = eqx.field(static=True)
    sigma: tuple[int, ...] = eqx.field(static=True)
    variables: tuple[str, ...] = eqx.field(static=True)
    labels: tuple[str, ...] = eqx.field(static=True)

    def __check_init__(self):
        n = len(self.antecedent)
        for name in ("gamma", "b", "alpha", "d", "theta", "r"):
            if jnp.shape(getattr(self, name)) != (n,):
                raise ModelError(f"MDH tree: '{name}' must have shape ({n},) (one value per "
                                 f"joint); got {jnp.shape(getattr(self, name))}.")
        if len(self.sigma) != n or len(self.variables) != n or len(self.labels) != n:
            raise ModelError("MDH tree: 'sigma', 'variables' and 'labels' need one entry per "
                             "joint.")
        for j, (a, s) in enumerate(zip(self.antecedent, self.sigma, strict=True), start=1):
            if not 0 <= a < j:
                raise ModelError(f"MDH tree: joint {j} has antecedent a({j}) = {a}; bodies are "
                                 f"numbered from the base, so 0 <= a(j) < j is required.")
            if s not in (REVOLUTE, PRISMATIC, LOCKED):
                raise ModelError(f"MDH tree: joint {j} has sigma = {s}; use 0 (revolute), 1 "
                                 "(prismatic) or 2 (locked).")

    @property
    def n(self) -> int:
        return len(self.antecedent)

    @property
    def mobile(self) -> tuple[int, ...]:
        """0-based indices of the mobile joints (σ ∈ {0, 1}): the order of `q`."""
        return tuple(j for j, s in enumerate(self.sigma) if s != LOCKED)

    @property
    def dof(self) -> int:
        return len(self.mobile)

    def successors(self, j: int) -> tuple[int, ...]:
        """1-based successors s(j) of body j (j = 0: the base)."""
        return tuple(k + 1 for k, a in enumerate(self.antecedent) if a == j)

    def index(self, variable: str) -> int:
        """Position in `q` of the joint variable `variable`."""
        names = [self.variables[j] for j in self.mobile]
        if variable not in names:
            raise ModelError(f"MDH tree has no mobile joint variable {variable!r}; it has "
                             f"{names}.")
        return names.index(variable)

    def with_locked(self, variables, values=None) -> "Tree":
        """The same tree with the named mobile joints locked at `values` (default 0): their
        value moves into θ_j (revolute) or r_j (prismatic). E.g. the 12-DOF vehicle from the
        30-DOF one (spec §5.2)."""
        values = [0.0] * len(variables) if values is None else list(values)
        sigma, theta, r = list(self.sigma), _np(self.theta), _np(self.r)
        for name, v in zip(variables, values, strict=True):
            hits = [j for j in self.mobile if self.variables[j] == name]
            if not hits:
                raise ModelError(f"cannot lock {name!r}: no mobile joint has that variable.")
            for j in hits:
                if sigma[j] == REVOLUTE:
                    theta = theta.at[j].add(v) if isinstance(theta, jax.Array) else _set(
                        theta, j, v)
                else:
                    r = r.at[j].add(v) if isinstance(r, jax.Array) else _set(r, j, v)
                sigma[j] = LOCKED
        return Tree(self.gamma, self.b, self.alpha, self.d, theta, r, self.antecedent,
                    tuple(sigma), self.variables, self.labels)


def from_rows(rows, *, values: dict | None = None) -> Tree:
    """A tree from MDH table rows (`Row`), numbered 1…n in order; `values` gives numbers for
    symbolic constants the rows name in `variable` of locked joints (e.g. the wobble ϕ)."""
    rows = list(rows)
    for k, row in enumerate(rows, start=1):
        if row.j != k:
            raise ModelError(f"MDH rows must be numbered 1…n in order; row {k} says j = {row.j}.")
    values = values or {}
    theta = [row.theta for row in rows]
    r = [row.r for row in rows]
    for k, row in enumerate(rows):
        if row.sigma == LOCKED and row.variable in values:
            theta[k] += values[row.variable]
    f = np.asarray
    return Tree(f([x.gamma for x in rows], float), f([x.b for x in rows], float),
                f([x.alpha for x in rows], float), f([x.d for x in rows], float),
                f(theta, float), f(r, float), tuple(x.a for x in rows),
                tuple(x.sigma for x in rows), tuple(x.variable for x in rows),
                tuple(x.label for x in rows))


def attach(parent: Tree, child: Tree, at: int, *, prefix: str = "") -> Tree:
    """`child`'s base C_0 identified with body `at` of `parent` (a locked joint with identity
    transform, spec §4.1/§5.2: "attached by a locked joint"): child body k becomes body
    parent.n + k. `prefix` is put in front of the child's variable names."""
    if not 0 <= at <= parent.n:
        raise ModelError(f"attach: body {at} does not exist (the parent has bodies 0…{parent.n}).")
    off = parent.n
    ante = tuple(at if a == 0 else a + off for a in child.antecedent)
    def cat(a, b):
        a, b = _np(a), _np(b)
        if isinstance(a, np.ndarray) and isinstance(b, np.ndarray):
            return np.concatenate([a, b])
        return jnp.concatenate([a, b])

    return Tree(cat(parent.gamma, child.gamma), cat(parent.b, child.b),
                cat(parent.alpha, child.alpha), cat(parent.d, child.d),
                cat(parent.theta, child.theta), cat(parent.r, child.r),
                parent.antecedent + ante, parent.sigma + child.sigma,
                parent.variables + tuple(prefix + v if v else v for v in child.variables),
                parent.labels + child.labels)


def _np(x):
    """Concrete values as NumPy (building trees issues no XLA programs); tracers unchanged."""
    try:
        return np.asarray(x, float)
    except (TypeError, jax.errors.TracerArrayConversionError, jax.errors.ConcretizationTypeError):
        return x


def _set(a, j, v):
    a = np.array(a, float)
    a[j] += v
    return a


# --------------------------------------------------------------------------------------------
# Geometry


def skew(p: Float[Array, "3"]) -> Float[Array, "3 3"]:
    """(p∧), the cross-product matrix (spec (2-35))."""
    x, y, z = p[0], p[1], p[2]
    zero = jnp.zeros_like(x)
    return jnp.stack([jnp.stack([zero, -z, y]), jnp.stack([z, zero, -x]),
                      jnp.stack([-y, x, zero])])


def transform(gamma, b, alpha, d, theta, r) -> Float[Array, "4 4"]:
    """^iT_j = Rot(z,γ)·Trans(z,b)·Rot(x,α)·Trans(x,d)·Rot(z,θ)·Trans(z,r) (F-1), in the closed
    form (F-2) with the corrected sign of row 2, column 1: SγCθ + CγCαSθ (CORRECTIONS 9)."""
    cg, sg, ca, sa = jnp.cos(gamma), jnp.sin(gamma), jnp.cos(alpha), jnp.sin(alpha)
    ct, st = jnp.cos(theta), jnp.sin(theta)
    zero, one = jnp.zeros_like(ct), jnp.ones_like(ct)
    return jnp.stack([
        jnp.stack([cg * ct - sg * ca * st, -cg * st - sg * ca * ct, sg * sa,
                   d * cg + r * sg * sa]),
        jnp.stack([sg * ct + cg * ca * st, -sg * st + cg * ca * ct, -cg * sa,
                   d * sg - r * cg * sa]),
        jnp.stack([sa * st, sa * ct, ca, r * ca + b]),
        jnp.stack([zero, zero, zero, one]),
    ])


def joint_values(tree: Tree, q: Float[Array, " dof"]):
    """(θ, r) of every joint at the joint vector q (F-4: q_j = σ̄_j θ_j + σ_j r_j)."""
    q = jnp.asarray(q)
    if q.shape != (tree.dof,):
        raise ModelError(f"joint vector q must have shape ({tree.dof},) (one entry per mobile "
                         f"joint of the tree); got {q.shape}.")
    full = jnp.zeros(tree.n, q.dtype if jnp.issubdtype(q.dtype, jnp.floating) else float)
    full = full.at[np.asarray(tree.mobile, int)].set(q) if tree.dof else full
    rev = np.asarray([s == REVOLUTE for s in tree.sigma])
    pri = np.asarray([s == PRISMATIC for s in tree.sigma])
    theta = tree.theta + jnp.where(rev, full, 0.0)
    r = tree.r + jnp.where(pri, full, 0.0)
    return theta, r


def joint_transforms(tree: Tree, q) -> Float[Array, "n 4 4"]:
    """^{a(j)}T_j of every joint at q."""
    theta, r = joint_values(tree, q)
    return jax.vmap(transform)(tree.gamma, tree.b, tree.alpha, tree.d, theta, r)


def forward_kinematics(tree: Tree, q) -> Float[Array, "n 4 4"]:
    """^0T_j of every body (F-5, F-6): products along the path from the base, one `lax.scan`
    over the joints in order (a(j) < j), so the program's size does not grow with the tree."""
    local = joint_transforms(tree, q)
    ante = jnp.asarray(tree.antecedent, jnp.int32)
    init = jnp.zeros((tree.n + 1, 4, 4), local.dtype).at[0].set(jnp.eye(4, dtype=local.dtype))

    def step(frames, x):
        j, a, T = x
        frames = frames.at[j + 1].set(frames[a] @ T)
        return frames, None

    frames, _ = jax.lax.scan(step, init, (jnp.arange(tree.n), ante, local))
    return frames[1:]


def path(tree: Tree, body: int) -> tuple[int, ...]:
    """0-based joints on the path from the base to `body` (1-based)."""
    out, k = [], body
    while k != 0:
        out.append(k - 1)
        k = tree.antecedent[k - 1]
    return tuple(reversed(out))


def jacobian(tree: Tree, q, body: int) -> Float[Array, "6 dof"]:
    """J_body (F-7, F-8): [V; ω] of the origin of frame `body` relative to the base, in frame 0,
    = J·q̇. Column i: [a_i; 0] (prismatic), [a_i × L_{i,body}; a_i] (revolute), 0 off the path
    or for a locked joint."""
    T = forward_kinematics(tree, q)
    if not tree.dof:
        return jnp.zeros((6, 0), T.dtype)
    mob = np.asarray(tree.mobile, int)
    on_path = np.isin(mob, path(tree, body)).astype(float)
    prismatic = np.asarray([tree.sigma[j] == PRISMATIC for j in tree.mobile], float)
    a, o = T[mob, :3, 2], T[mob, :3, 3]
    lever = jnp.cross(a, T[body - 1, :3, 3][None, :] - o)
    top = prismatic[:, None] * a + (1.0 - prismatic[:, None]) * lever
    bottom = (1.0 - prismatic[:, None]) * a
    return (jnp.concatenate([top, bottom], axis=1) * on_path[:, None]).T


# --------------------------------------------------------------------------------------------
# Twists and wrenches (spec (2-32)…(2-36), (2-71))


def twist_transport(T: Float[Array, "4 4"]) -> Float[Array, "6 6"]:
    """^i𝕋_j = [[R, (P∧)R], [0, R]] for ^iT_j = [R, P; 0, 1] (2-34): a twist (V | ω) of a body
    at O_j in frame j → at O_i in frame i, 𝒱_i = ^i𝕋_j 𝒱_j. Wrenches (F | M) go the other way,
    𝔽_j = ^i𝕋_jᵀ 𝔽_i (2-36)."""
    R, P = T[:3, :3], T[:3, 3]
    top = jnp.concatenate([R, skew(P) @ R], axis=1)
    bottom = jnp.concatenate([jnp.zeros((3, 3), T.dtype), R], axis=1)
    return jnp.concatenate([top, bottom], axis=0)


def inverse_transform(T: Float[Array, "4 4"]) -> Float[Array, "4 4"]:
    """(^iT_j)⁻¹ = ^jT_i."""
    R, P = T[:3, :3], T[:3, 3]
    top = jnp.concatenate([R.T, (-R.T @ P)[:, None]], axis=1)
    return jnp.concatenate([top, T[3:]], axis=0)


def change_of_point(BA: Float[Array, "3"]) -> Float[Array, "6 6"]:
    """M_{B,A} = [[I, (BA∧)], [0, I]] (2-71): the twist at A → the twist at B (same frame),
    V_B = V_A + BA × ω."""
    eye = jnp.eye(3, dtype=jnp.result_type(BA, float))
    top = jnp.concatenate([eye, skew(jnp.asarray(BA))], axis=1)
    bottom = jnp.concatenate([jnp.zeros_like(eye), eye], axis=1)
    return jnp.concatenate([top, bottom], axis=0)


def as_array(x: ArrayLike) -> Array:
    return jnp.asarray(x, jnp.result_type(x, float))
