"""The measurements of the direct identification (spec stiffness §1.8, §1.10): the checks that
every moving part's pose is measured, and the covariance of each case's measured poses (from
the landmark noise, propagated through the pose fit), which whitens the equations of
`identify.direct_equations` (generalised least squares, errors in variables).
"""


import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from ..errors import InputError
from ..geometry import gibbs_angular_jacobian, skew
from ..measure.measurements import Measurements
from ..model.mechanism import JOINT_ROWS, Mechanism

__all__: list[str] = []  # used by `identify.direct`


def check_measurements(mech: Mechanism, meas: Measurements):
    if not isinstance(meas, Measurements):
        raise InputError(f"measurements must be a diffsusp.measure.Measurements; got "
                         f"{type(meas).__name__}.")
    if meas.rotation.ndim != 4:
        raise InputError("measurements must have one leading case axis (a batch of measurement "
                         "sets: identify each with its own call).")
    loads = meas.loads
    n_cases = meas.n_cases
    if loads.force.shape[:1] != (n_cases,):
        raise InputError(f"the measurements have {n_cases} cases but their loads have "
                         f"{loads.force.shape[0] if loads.force.ndim == 3 else 'no'} cases.")
    n_l, n_d = len(mech.load_points.names), len(mech.drivers.names)
    if loads.force.shape[1:] != (n_l, 3) or loads.driver.shape[1:] != (n_d,):
        raise InputError(
            f"the loads are for {loads.force.shape[1]} load points and {loads.driver.shape[1]} "
            f"drivers, but model '{mech.name}' has {n_l} load points "
            f"({', '.join(mech.load_points.names) or 'none'}) and {n_d} drivers; build them with "
            "mech.loads(...)."
        )
    _check_every_part_measured(mech, meas)
    q = np.asarray(meas.coordinates(mech))
    if not np.all(np.isfinite(q)):
        c = int(np.argwhere(~np.isfinite(q))[0][0])
        raise InputError(f"the pose of case {meas.cases[c] if meas.cases else c + 1} is not "
                         "finite (NaN or inf).")
    for field in ("force", "moment"):
        value = np.asarray(getattr(loads, field))
        if not np.all(np.isfinite(value)):
            c = int(np.argwhere(~np.isfinite(value))[0][0])
            raise InputError(f"the {field} of case {c + 1} is not finite (NaN or inf).")
    return q


def _check_every_part_measured(mech: Mechanism, meas: Measurements):
    """Raise, saying why and what to do instead, when a moving part has no measured pose.

    The equations are formed at the measured pose of every part (spec stiffness §1.1, §1.14):
    the generalised forces D(q)·k need q whole. For an unmeasured part, the joints to the
    measured parts fix some of its coordinates; the others (e.g. the pseudo-McPherson strut's
    slide in the hub carrier) are set at each equilibrium by the balance of its elastic
    elements, i.e. by the stiffnesses being identified: unknown × unknown, not a linear
    system. The message counts them: 6 per part less the rows of the joints that hold it
    (exact for independent rows, as in the thesis's models)."""
    missing = [p for p in mech.parts if p not in meas.parts]
    if not missing:
        return

    lay = mech.topology
    part_of = [mech.parts[int(k)] if int(k) < len(mech.parts) else "ground"
               for k in np.asarray(lay.marker_part)]
    joints = [(n, kind) for n, kind, i, j in zip(mech.joints.names, mech.joints.kind,
                                                 mech.joints.i_marker, mech.joints.j_marker,
                                                 strict=True)
              if part_of[i] in missing or part_of[j] in missing]
    joints, free = [n for n, _ in joints], max(
        6 * len(missing) - sum(JOINT_ROWS[k] for _, k in joints), 0)
    names = ", ".join(map(repr, missing))
    why = (f"its joints ({', '.join(joints) or 'none'}) leave it {free} free coordinate(s) "
           "relative to the measured parts, set at every equilibrium by its elastic elements, "
           "i.e. by the stiffnesses being identified: the equations would not be linear in "
           "them" if free else
           f"its joints ({', '.join(joints)}) fix its pose from the measured parts, but the "
           "direct method does not complete poses from the joints")
    raise InputError(
        f"the measurements have no pose for part(s) {names} of model '{mech.name}' "
        f"(measured: {', '.join(meas.parts) or 'none'}). The direct method writes the "
        "equilibrium at the measured pose of every moving part (spec stiffness §1.1, §1.14); "
        f"{why}. Instead: identify.least_squares(mech, measurements, params) fits the "
        "landmarks of the measured parts through the model's own equilibrium (which places "
        f"{names}), or identify.iterative; or measure its landmarks; or simplify the model "
        "(the thesis replaced the unmeasurable strut by a point-on-line joint: spec stiffness "
        "§1.13).")


def _pose_covariance(mech: Mechanism, meas: Measurements) -> Array:
    """Covariance (cases, n, n) of the measured poses in the solver's coordinates (reference
    point, Gibbs vector), for landmark noise of unit σ (mm) per coordinate: the first-order
    covariance of a least-squares rigid registration (centroid translation σ²/k, rotation
    σ²·(Σ_a |r_a|²I − r_a r_aᵀ)⁻¹ about the landmark centroid, uncorrelated). For poses given
    without landmarks: unit σ on the reference point (mm) and on ℓ·rotation (mm).
    Only the structure matters: `lsq` estimates the noise level from the residual."""
    lay = mech.topology
    index = np.asarray([meas.parts.index(p) for p in mech.parts], dtype=int)
    centre = jnp.asarray(lay.centre[:-1])
    rot = meas.rotation[:, index]
    eye = jnp.eye(3, dtype=rot.dtype)

    if meas.landmarks is not None:
        ref = meas.layout.position[index]  # (P, k, 3)
        w = meas.weights[:, index]  # (C, P, k)

        def part_cov(r, ref_p, w_p, c):
            total = jnp.sum(w_p)
            c0 = (w_p @ ref_p) / total
            arm_l = (ref_p - c0) @ r.T  # landmarks about their centroid, current axes
            inertia = jnp.einsum("k,kij->ij", w_p,
                                 jnp.einsum("ki,ki->k", arm_l, arm_l)[:, None, None] * eye
                                 - arm_l[:, :, None] * arm_l[:, None, :])
            cov_t, cov_w = eye / total, jnp.linalg.inv(inertia)
            arm = r @ (c - c0)
            return cov_t, cov_w, arm

        cov_t, cov_w, arm = jax.vmap(jax.vmap(part_cov, in_axes=(0, 0, 0, 0)),
                                     in_axes=(0, None, 0, None))(rot, ref, w, centre)
    else:
        n_c, n_p = rot.shape[:2]
        cov_t = jnp.broadcast_to(eye, (n_c, n_p, 3, 3))
        cov_w = cov_t / mech.length_scale**2
        arm = jnp.zeros((n_c, n_p, 3), rot.dtype)

    def block(r, ct, cw, a):
        # Gibbs vector b = vee(R − Rᵀ)/(1 + tr R) (the poses were checked by `coordinates`).
        b = jnp.stack([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / (
            1.0 + jnp.trace(r))
        g_inv = jnp.linalg.inv(gibbs_angular_jacobian(b))
        top = jnp.concatenate([eye, -skew(a)], axis=1)
        bottom = jnp.concatenate([jnp.zeros((3, 3), r.dtype), g_inv], axis=1)
        t = jnp.concatenate([top, bottom], axis=0)
        cov = jnp.zeros((6, 6), r.dtype).at[:3, :3].set(ct).at[3:, 3:].set(cw)
        return t @ cov @ t.T

    blocks = jax.vmap(jax.vmap(block))(rot, cov_t, cov_w, arm)  # (C, P, 6, 6)
    n_c, n_p = blocks.shape[:2]
    full = jnp.zeros((n_c, n_p, 6, n_p, 6), blocks.dtype)
    full = full.at[:, np.arange(n_p), :, np.arange(n_p), :].set(jnp.moveaxis(blocks, 1, 0))
    return full.reshape(n_c, 6 * n_p, 6 * n_p)


pose_covariance_jit = eqx.filter_jit(_pose_covariance)
