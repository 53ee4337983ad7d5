"""Geometric primitives fitted to probed points, each with its covariance from the probe noise.

The thesis measures the joints of a disassembled part with a measuring arm (spec geometry §3.2):

- a **ball joint** centre: part 2 is moved about the joint through ≥ 4 positions while the same
  point of part 2 is probed; the probed points lie on a sphere whose centre is the joint (2.8).
  Fitted by the algebraic linear least squares ‖p‖² = 2 c·p + k, k = r² − ‖c‖² (the digest's
  choice; the thesis does not name its method);
- **lines** (cylinder axes as the arm's software exports them, or probed points along an edge):
  orthogonal (total) least squares: centroid and principal direction;
- **planes** (sleeve ends, clamp faces): orthogonal least squares: centroid and the direction
  of least spread;
- a **bushing frame** from its sleeve: the axis line intersected with the two end planes gives
  Points 1 and 2; their midpoint (Point 3) is the centre, the axis is z_b (§3.2, fig. 2.5).

**Covariances.** Every estimate here is a smooth function of the probed coordinates, so its
covariance under independent Gaussian probe noise of σ (mm, per coordinate) is, to first order,
σ² J Jᵀ with J the exact Jacobian of the estimator with respect to the probed coordinates
(`jax.jacfwd`). Without a given σ, it is estimated from the fit's own residuals with the
degrees of freedom of the fit. Directions are unit vectors; their covariance is singular along
the direction itself (rank 2).

Every function acts on one set of points (no batch axis); batch with `jax.vmap`. Units: mm.
"""

import functools
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

__all__ = [
    "BushingFrame",
    "LineFit",
    "PlaneFit",
    "SphereFit",
    "bushing_frame",
    "fit_line",
    "fit_plane",
    "fit_sphere",
    "intersect_line_plane",
]


def _points(points, minimum: int, what: str):
    points = jnp.asarray(points)
    points = points.astype(jnp.result_type(points, float))
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"{what}: points must have shape (n, 3); got {points.shape}.")
    if points.shape[0] < minimum:
        raise ValueError(
            f"{what} needs at least {minimum} points; got {points.shape[0]}. Probe more "
            "positions (spec geometry §3.2).")
    return points


def _sign_fixed(v):
    """A unit vector with its largest-magnitude component positive (a fixed orientation, so a
    fitted direction is a smooth function of the data)."""
    k = jnp.argmax(jnp.abs(v))
    return v * jnp.where(v[k] < 0, -1.0, 1.0)


def _covariance(estimator, points, sigma, sigma_hat):
    jac = jax.jacfwd(estimator)(points).reshape(-1, points.size)
    s = jnp.where(jnp.isnan(sigma), sigma_hat, sigma)
    return s**2 * jac @ jac.T, s


def _sigma(sigma, dtype):
    """A given probe noise as an array, NaN for "estimate it" (one compiled program)."""
    return jnp.asarray(jnp.nan if sigma is None else sigma, dtype)


class SphereFit(NamedTuple):
    """Result of `fit_sphere`.

    **Fields:** `centre` (3,) and `radius` () in mm; `covariance` (4, 4) of (centre, radius)
    in mm²; `rms` () the root-mean-square radial residual (mm); `sigma` () the probe noise
    used for the covariance (mm, given or estimated).
    """

    centre: Float[Array, "3"]
    radius: Float[Array, ""]
    covariance: Float[Array, "4 4"]
    rms: Float[Array, ""]
    sigma: Float[Array, ""]


def _sphere(points):
    # ‖p‖² = 2 c·p + k, solved in coordinates centred on the centroid (conditioning).
    mean = jnp.mean(points, axis=0)
    p = points - mean
    a = jnp.concatenate([2.0 * p, jnp.ones((p.shape[0], 1), p.dtype)], axis=1)
    sol = jnp.linalg.lstsq(a, jnp.sum(p * p, axis=1))[0]
    c = sol[:3]
    radius = jnp.sqrt(sol[3] + c @ c)
    return jnp.concatenate([c + mean, radius[None]])


def fit_sphere(points: Float[ArrayLike, "n 3"], sigma: float | None = None) -> SphereFit:
    """Centre and radius of the sphere through probed points: a ball-joint centre (spec geometry
    §3.2, 2.8).

    Algebraic linear least squares ‖p‖² = 2 c·p + k (k = r² − ‖c‖²); exact for points exactly on
    a sphere. The points must not be coplanar (a circle does not fix its sphere): spread the
    probed positions over the joint's range of motion.

    **Arguments:**

    - `points`: (n, 3) probed positions (mm), n ≥ 4.
    - `sigma`: probe noise per coordinate (mm); default: estimated from the radial residuals
      with n − 4 degrees of freedom (0 when n = 4).

    **Returns:** a `SphereFit` (centre, radius, covariance of both, rms, sigma).
    """
    points = _points(points, 4, "a sphere fit")
    return _fit_sphere(points, _sigma(sigma, points.dtype))


@jax.jit
def _fit_sphere(points, sigma):
    est = _sphere(points)
    resid = jnp.linalg.norm(points - est[:3], axis=1) - est[3]
    n = points.shape[0]
    sigma_hat = jnp.sqrt(jnp.sum(resid**2) / max(n - 4, 1)) if n > 4 else jnp.zeros(())
    cov, s = _covariance(_sphere, points, sigma, sigma_hat)
    return SphereFit(est[:3], est[3], cov, jnp.sqrt(jnp.mean(resid**2)), s)


class LineFit(NamedTuple):
    """Result of `fit_line`: the line through `point` along the unit `direction`.

    **Fields:** `point` (3,) the centroid of the points (mm), `direction` (3,) unit, sign fixed
    so that its largest component is positive; `covariance` (6, 6) of (point, direction) (mm²,
    mm, 1); `rms` () root-mean-square orthogonal distance (mm); `sigma` () noise used (mm).
    """

    point: Float[Array, "3"]
    direction: Float[Array, "3"]
    covariance: Float[Array, "6 6"]
    rms: Float[Array, ""]
    sigma: Float[Array, ""]


def _centroid_axis(points, k: int):
    """(centroid, unit principal direction k of the centred points): k = 0 the direction of
    most spread (a line), k = 2 of least spread (a plane's normal)."""
    mean = jnp.mean(points, axis=0)
    _, _, vt = jnp.linalg.svd(points - mean, full_matrices=False)
    return jnp.concatenate([mean, _sign_fixed(vt[k])])


_line = functools.partial(_centroid_axis, k=0)
_plane = functools.partial(_centroid_axis, k=2)


def fit_line(points: Float[ArrayLike, "n 3"], sigma: float | None = None) -> LineFit:
    """Orthogonal least-squares line through points (spec geometry §3.2: cylinder axes, edges).

    **Arguments:** `points` (n, 3) mm, n ≥ 2 (n ≥ 3 to estimate the noise); `sigma` probe noise
    (mm), default estimated from the orthogonal residuals with 2(n − 2) degrees of freedom.

    **Returns:** a `LineFit`.
    """
    points = _points(points, 2, "a line fit")
    return _fit_line(points, _sigma(sigma, points.dtype))


@jax.jit
def _fit_line(points, sigma):
    est = _line(points)
    d = points - est[:3]
    perp = d - (d @ est[3:])[:, None] * est[3:]
    ss = jnp.sum(perp**2)
    n = points.shape[0]
    sigma_hat = jnp.sqrt(ss / (2 * (n - 2))) if n > 2 else jnp.zeros(())
    cov, s = _covariance(_line, points, sigma, sigma_hat)
    return LineFit(est[:3], est[3:], cov, jnp.sqrt(ss / n), s)


class PlaneFit(NamedTuple):
    """Result of `fit_plane`: the plane through `point` with unit `normal`.

    **Fields:** `point` (3,) centroid (mm), `normal` (3,) unit (largest component positive),
    `covariance` (6, 6) of (point, normal); `rms` () root-mean-square distance (mm); `sigma`.
    """

    point: Float[Array, "3"]
    normal: Float[Array, "3"]
    covariance: Float[Array, "6 6"]
    rms: Float[Array, ""]
    sigma: Float[Array, ""]


def fit_plane(points: Float[ArrayLike, "n 3"], sigma: float | None = None) -> PlaneFit:
    """Orthogonal least-squares plane through points (spec geometry §3.2: sleeve ends, clamp
    faces). The points must not be collinear.

    **Arguments:** `points` (n, 3) mm, n ≥ 3; `sigma` probe noise (mm), default estimated from
    the distances with n − 3 degrees of freedom.

    **Returns:** a `PlaneFit`.
    """
    points = _points(points, 3, "a plane fit")
    return _fit_plane(points, _sigma(sigma, points.dtype))


@jax.jit
def _fit_plane(points, sigma):
    est = _plane(points)
    dist = (points - est[:3]) @ est[3:]
    n = points.shape[0]
    sigma_hat = jnp.sqrt(jnp.sum(dist**2) / (n - 3)) if n > 3 else jnp.zeros(())
    cov, s = _covariance(_plane, points, sigma, sigma_hat)
    return PlaneFit(est[:3], est[3:], cov, jnp.sqrt(jnp.mean(dist**2)), s)


def intersect_line_plane(
    line_point: Float[ArrayLike, "3"],
    line_direction: Float[ArrayLike, "3"],
    plane_point: Float[ArrayLike, "3"],
    plane_normal: Float[ArrayLike, "3"],
    covariance: Float[ArrayLike, "12 12"] | None = None,
) -> tuple[Float[Array, "3"], Float[Array, "3 3"] | None]:
    """Point where a line meets a plane (spec geometry §3.2, fig. 2.5: Points 1 and 2).

    x = a + t u with t = n·(b − a) / n·u.

    **Arguments:** the line (point a, direction u), the plane (point b, normal n), all mm or
    unit; `covariance`: optional (12, 12) covariance of (a, u, b, n) (e.g. the two fits'
    covariances as diagonal blocks).

    **Returns:** `(point, covariance)`: the intersection (mm) and its (3, 3) covariance
    (None without an input covariance). A line parallel to the plane has no intersection:
    `eqx.error_if` raises at run time.
    """
    args = jnp.concatenate([jnp.ravel(jnp.asarray(v, float)) for v in
                            (line_point, line_direction, plane_point, plane_normal)])
    if args.shape != (12,):
        raise ValueError("intersect_line_plane: give four 3-vectors (line point and direction, "
                         "plane point and normal).")
    if covariance is None:
        return _intersection(args), None
    return _intersection_cov(args, jnp.asarray(covariance, args.dtype))


def _intersection_point(x):
    a, u, b, n = x[:3], x[3:6], x[6:9], x[9:]
    return a + u * (n @ (b - a)) / (n @ u)


def _checked(args):
    u, n = args[3:6], args[9:]
    denom = jnp.abs(n @ u) / (jnp.linalg.norm(n) * jnp.linalg.norm(u))
    return eqx.error_if(args, denom < 1e-9,
                        "the line is parallel to the plane: they have no intersection point.")


@eqx.filter_jit
def _intersection(args):
    return _intersection_point(_checked(args))


@eqx.filter_jit
def _intersection_cov(args, covariance):
    args = _checked(args)
    jac = jax.jacfwd(_intersection_point)(args)
    return _intersection_point(args), jac @ covariance @ jac.T


class BushingFrame(NamedTuple):
    """Result of `bushing_frame`.

    **Fields:** `centre` (3,) Point 3 (mm), `axis` (3,) unit sleeve axis z_b, `ends` (2, 3)
    Points 1 and 2 (mm), `covariance` (6, 6) of (centre, axis), `length` () the sleeve length
    |P2 − P1| (mm).
    """

    centre: Float[Array, "3"]
    axis: Float[Array, "3"]
    ends: Float[Array, "2 3"]
    covariance: Float[Array, "6 6"]
    length: Float[Array, ""]


def bushing_frame(
    axis_points: Float[ArrayLike, "n 3"],
    end_1: Float[ArrayLike, "m 3"],
    end_2: Float[ArrayLike, "l 3"],
    sigma: float,
) -> BushingFrame:
    """Bushing frame from its sleeve (spec geometry §3.2, fig. 2.5b): the axis line (fitted to
    `axis_points`, e.g. the measuring arm's cylinder axis sampled along it) meets the two end
    planes (fitted to `end_1`, `end_2`) at Points 1 and 2; the centre is their midpoint
    (Point 3) and z_b the axis. A revolute joint's frame is built the same way.

    **Arguments:** the probed point sets (mm): ≥ 2 on the axis, ≥ 3 on each end face; `sigma`
    the probe noise (mm) for the covariance.

    **Returns:** a `BushingFrame` (centre, axis, the two end points, covariance of centre and
    axis, sleeve length).
    """
    axis_points = _points(axis_points, 2, "the bushing axis")
    end_1 = _points(end_1, 3, "the first sleeve end plane")
    end_2 = _points(end_2, 3, "the second sleeve end plane")
    flat = jnp.concatenate([axis_points.ravel(), end_1.ravel(), end_2.ravel()])
    return _bushing_frame(flat, jnp.asarray(sigma, flat.dtype), axis_points.shape[0],
                          end_1.shape[0])


@functools.partial(jax.jit, static_argnums=(2, 3))
def _bushing_frame(flat, sigma, n_a, n_1):
    def frame(flat):
        a = flat[: 3 * n_a].reshape(n_a, 3)
        e1 = flat[3 * n_a: 3 * (n_a + n_1)].reshape(n_1, 3)
        e2 = flat[3 * (n_a + n_1):].reshape(-1, 3)
        line = _line(a)
        p1 = _intersection_point(jnp.concatenate([line, _plane(e1)]))
        p2 = _intersection_point(jnp.concatenate([line, _plane(e2)]))
        return jnp.concatenate([0.5 * (p1 + p2), line[3:], p1, p2])

    out = frame(flat)
    jac = jax.jacfwd(lambda x: frame(x)[:6])(flat)
    cov = sigma**2 * jac @ jac.T
    ends = out[6:].reshape(2, 3)
    return BushingFrame(out[:3], out[3:6], ends, cov, jnp.linalg.norm(ends[1] - ends[0]))
