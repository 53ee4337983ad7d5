"""Contact-frame kinematics of the tyre's physical model (thesis chapter 2).

spec: tyre_contact_model §1.3–1.6 ((2-8)…(2-104)), §4.1 ((3-1), (3-2)); the robotics
(frames, twists, wrenches) is `diffsusp.mdh`. Frames: wheel carrier R_pf (origin O the wheel
centre, y_pf the spin axis), wobbled wheel R_tw, tyre frame R_p (origin P on the ground, z_p the
ground normal, x_p in the wheel plane), contact patch R_AC. Twists (V | ω), wrenches (F | M).

Units: lengths in any one unit (the thesis's chapter 2 works in m; lengths of the deformation
inputs come out in the unit of the velocities over ω); angles in rad; forces as given.

Signs: the ground plane is given by its unit normal z_r (pointing away from the ground, towards
the wheel) and the signed coordinate d = OP·z_r of the ground along it, seen from O (2-15):
d < 0 for a wheel standing on the ground, and so is the tyre-frame height h = d/cos γ (the
joint 4 of Table 1 is a coordinate along z, not a distance).
"""

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .. import mdh
from ..mdh.tree import inverse_transform, twist_transport

# --------------------------------------------------------------------------------------------
# Tyre frame from the ground plane


def wobble_rotation(theta, phi) -> Float[Array, "3 3"]:
    """^{Rtw}R_{Rpf}: wheel carrier → wobbled wheel (frame 2 of Table 1), wheel angle θ,
    wobble ϕ: (Rot(y, θ)·Rot(z, ϕ))ᵀ, from the chain's rows 1–2.

    The printed (2-8) is not orthonormal (its first row has norm² cos²θ + sin²ϕ); this is the
    matrix the MDH rows of Table 1 give, and it equals (2-8) at ϕ = 0 up to the sign of the
    (1, 3) element, which (2-8) prints as −sin ϕ instead of −cos ϕ·sin θ."""
    ct, st, cp, sp = jnp.cos(theta), jnp.sin(theta), jnp.cos(phi), jnp.sin(phi)
    zero = jnp.zeros_like(ct)
    return jnp.stack([jnp.stack([cp * ct, sp, -cp * st]), jnp.stack([-sp * ct, cp, sp * st]),
                      jnp.stack([st, zero, ct])])


def tyre_frame(normal_pf: Float[Array, "3"], d, theta=0.0, phi=0.0):
    """Tyre frame R_p from the ground plane in R_pf, general case with wobble (2-9…2-22).

    x_p = y_tw ∧ z_r (normalised), z_p = z_r, y_p = z_p ∧ x_p; P on the ground plane, in the
    wheel plane, on the line through O along z_cr: OP·x_p = 0, OP·y_tw = 0, OP·z_p = d (2-15).
    The printed (2-19) inverts the matrix whose *rows* are the frame's coordinates; the system
    (2-15) is solved here as written. The printed (2-20), ξ = atan2(s_z, −s_x), returns ξ + π
    for the frames of Table 1 (x_p = Rot(y, ξ)·x_tw has s = (cos ξ, 0, −sin ξ)); it is
    ξ = atan2(−s_z, s_x) here, which is also what the zero-wobble (2-26) reduces to.

    **Arguments:** `normal_pf` (3,) unit ground normal z_r in R_pf; `d` signed coordinate of the
    ground along z_r from O; `theta`, `phi` wheel angle and wobble (rad).

    **Returns:** dict with `xi`, `gamma`, `h` (the joint values of Table 1 joints 3–5, (2-20…
    2-22)), `R` (3×3) and `P` (3,) of R_p in R_tw, and `T_pf_p` (4×4) ^{Rpf}T_{Rp}.
    """
    Rtw = wobble_rotation(theta, phi)
    z = Rtw @ normal_pf  # (2-9)
    y_tw = jnp.array([0.0, 1.0, 0.0], z.dtype)
    x = jnp.cross(y_tw, z)  # (2-11), (2-14)
    x = x / jnp.linalg.norm(x)
    y = jnp.cross(z, x)  # (2-16)
    R = jnp.stack([x, y, z], axis=1)  # (s n a) (2-18)
    P = jnp.linalg.solve(jnp.stack([x, y_tw, z]), jnp.stack([0.0 * d, 0.0 * d, d]))  # (2-15)
    (sx, nx, ax), (_, _, _), (sz, nz, az) = R[0], R[1], R[2]
    xi = jnp.arctan2(-sz, sx)  # (2-20), sign corrected (see the docstring)
    gamma = jnp.arctan2(nz * jnp.cos(xi) + nx * jnp.sin(xi),
                        az * jnp.cos(xi) + ax * jnp.sin(xi))  # (2-21)
    h = P[2] * jnp.cos(xi) + P[0] * jnp.sin(xi)  # (2-22)
    T_tw_p = _homogeneous(R, P)
    T_pf_tw = _homogeneous(Rtw.T, jnp.zeros(3, z.dtype))
    return {"xi": xi, "gamma": gamma, "h": h, "R": R, "P": P, "T_pf_p": T_pf_tw @ T_tw_p}


def tyre_frame_zero_wobble(normal_pf: Float[Array, "3"], d, theta=0.0):
    """Tyre frame without wobble, θ unknown or irrelevant (2-23…2-29).

    ξ̂ = atan2(a'_x, a'_z) (the wind-up due to the carrier's attitude), ξ = ξ̂ − θ,
    γ = atan2(−a'_y, a'_z cos ξ̂ + a'_x sin ξ̂), h = d / cos γ. (The printed (2-28) writes ξ in
    the cosine and sine; they are those of ξ̂, the angle between x_pf and x_p, as the general
    case (2-21) at θ = 0 shows.)

    **Returns:** dict with `xi_hat`, `xi`, `gamma`, `h`.
    """
    ax, ay, az = normal_pf[0], normal_pf[1], normal_pf[2]
    xi_hat = jnp.arctan2(ax, az)  # (2-26)
    gamma = jnp.arctan2(-ay, az * jnp.cos(xi_hat) + ax * jnp.sin(xi_hat))  # (2-28)
    return {"xi_hat": xi_hat, "xi": xi_hat - theta, "gamma": gamma, "h": d / jnp.cos(gamma)}


def carrier_to_tyre(xi_hat, gamma, h) -> Float[Array, "4 4"]:
    """^{Rpf}T_{Rp} at zero wobble: the contact chain (Table 1) at θ = 0, ξ = ξ̂."""
    chain = mdh.tables.contact_chain()
    q = jnp.stack([0.0 * h, xi_hat, h, gamma, 0.0 * h, 0.0 * h, 0.0 * h])
    return mdh.forward_kinematics(chain, q)[5]


def carrier_to_tyre_closed(xi_hat, gamma, h):
    """(R, P) of ^{Rpf}T_{Rp} at zero wobble in closed form: R = Rot(y, ξ̂)·Rot(x, γ),
    P = h·(sin ξ̂, 0, cos ξ̂) — what `carrier_to_tyre` computes through the chain (tested), for
    the batched on-board pipeline."""
    cx, sx, cg, sg = jnp.cos(xi_hat), jnp.sin(xi_hat), jnp.cos(gamma), jnp.sin(gamma)
    z = jnp.zeros_like(cx)
    R = jnp.stack([jnp.stack([cx, sx * sg, sx * cg]), jnp.stack([z, cg, -sg]),
                   jnp.stack([-sx, cx * sg, cx * cg])])
    return R, h * jnp.stack([sx, z, cx])


def tyre_twist_zero_wobble(twist_pf: Float[Array, "6"], q_p: Float[Array, "3"],
                           qdot_p: Float[Array, "3"]) -> Float[Array, "6"]:
    """`tyre_twist` at zero wobble in closed form (q_p = (ξ̂, h, γ)): relative angular
    velocity ξ̂̇·y + γ̇·Rot(y, ξ̂)x, origin velocity ḣ·(sin ξ̂, 0, cos ξ̂) + h ξ̂̇·(cos ξ̂, 0,
    −sin ξ̂), added to the carrier's twist carried to P, all turned into R_p."""
    xi, h, _ = q_p[0], q_p[1], q_p[2]
    xid, hd, gd = qdot_p[0], qdot_p[1], qdot_p[2]
    R, P = carrier_to_tyre_closed(q_p[0], q_p[2], q_p[1])
    cx, sx = jnp.cos(xi), jnp.sin(xi)
    z = jnp.zeros_like(cx)
    w_rel = jnp.stack([gd * cx, xid, -gd * sx])
    v_rel = hd * jnp.stack([sx, z, cx]) + h * xid * jnp.stack([cx, z, -sx])
    v = twist_pf[:3] + jnp.cross(twist_pf[3:], P) + v_rel
    w = twist_pf[3:] + w_rel
    return jnp.concatenate([R.T @ v, R.T @ w])


def wrench_to_tyre_closed(wrench_pf: Float[Array, "6"], R, P) -> Float[Array, "6"]:
    """`wrench_to_tyre` (massless wheel) from (R, P) of `carrier_to_tyre_closed`."""
    F, M = wrench_pf[:3], wrench_pf[3:]
    return jnp.concatenate([R.T @ F, R.T @ (M - jnp.cross(P, F))])


def ground_plane(T_pf_p: Float[Array, "4 4"]):
    """(z_r, d) in R_pf of the plane through the tyre frame's origin normal to its z axis."""
    n = T_pf_p[:3, 2]
    return n, jnp.dot(n, T_pf_p[:3, 3])


def flat_trac_plane(steer, camber, height):
    """Ground plane of the Flat Trac belt in R_pf (3-1, 3-2): normal (sinβ sinγ, cosβ sinγ,
    cosγ), distance h cos γ (here with the sign convention of this module: d = −h_FT cos γ_FT,
    the belt below the wheel centre for h_FT > 0). spec: tyre §4.1."""
    n = jnp.stack([jnp.sin(steer) * jnp.sin(camber), jnp.cos(steer) * jnp.sin(camber),
                   jnp.cos(camber)])
    return n, -height * jnp.cos(camber)


def flat_trac_transform(steer, camber, height) -> Float[Array, "4 4"]:
    """^{Rpf}T_0 of the bench (3-1). The rotation is (3-1)'s; the translation is (0, 0, −h_FT):
    Table 4's chain puts the bench frame below the wheel centre for h_FT > 0 (the printed
    (3-1) has +h_FT, a length rather than the coordinate along z_pf)."""
    cb, sb, cg, sg = jnp.cos(steer), jnp.sin(steer), jnp.cos(camber), jnp.sin(camber)
    zero, one = jnp.zeros_like(cb), jnp.ones_like(cb)
    return jnp.stack([jnp.stack([cb, sb * cg, sb * sg, zero]),
                      jnp.stack([-sb, cb * cg, cb * sg, zero]),
                      jnp.stack([zero, -sg, cg, -height]), jnp.stack([zero, zero, zero, one])])


# --------------------------------------------------------------------------------------------
# Wrenches and twists


def wrench_to_tyre(wrench_pf: Float[Array, "6"], T_pf_p: Float[Array, "4 4"],
                   inertial: Float[Array, "6"] | None = None) -> Float[Array, "6"]:
    """F_p = ^{Rpf}𝕋_{Rp}ᵀ·[F_pf + D_p·X_p] (2-30): the wheel-carrier wrench (F | M at O, in
    R_pf) carried to the tyre frame (at P, in R_p); `inertial` = D_p·X_p the wheel's inertial
    wrench (`wheel_inertia_regressor`), omitted for a massless wheel."""
    w = wrench_pf if inertial is None else wrench_pf + inertial
    return twist_transport(T_pf_p).T @ w


def wrench_transform_zero_wobble(xi_hat, gamma, h) -> Float[Array, "6 6"]:
    """The 6×6 matrix of (2-31), F_p = 𝕄·F_pf, as printed (zero wobble)."""
    c, s, cg, sg = jnp.cos(xi_hat), jnp.sin(xi_hat), jnp.cos(gamma), jnp.sin(gamma)
    z = jnp.zeros_like(c)
    R = jnp.stack([jnp.stack([c, z, -s]), jnp.stack([s * sg, cg, c * sg]),
                   jnp.stack([s * cg, -sg, c * cg])])
    lower = jnp.stack([jnp.stack([z, h, z]), jnp.stack([-h * c * cg, z, h * s * cg]),
                       jnp.stack([h * c * sg, z, -h * s * sg])])
    return jnp.concatenate([jnp.concatenate([R, jnp.zeros((3, 3), R.dtype)], axis=1),
                            jnp.concatenate([lower, R], axis=1)], axis=0)


def wheel_inertia_regressor(theta, theta_dot, theta_ddot, *, wobble=0.0,
                            omega=None, omega_dot=None, acceleration=None,
                            gravity=(0.0, 0.0, -9.81)):
    """D_p (6, 20) of (2-30): the inertial wrench of the wheel bodies 1 (wheel) and 2 (wobbled
    wheel) of Table 1, at O in R_pf, linear in their 20 inertial parameters (XX…M of each);
    exact by `jax.jacfwd` of the Newton–Euler base wrench. The carrier moves with angular
    velocity `omega`, angular acceleration `omega_dot` and origin acceleration `acceleration`
    (R_pf components); `gravity` in R_pf. With F_pf the wrench the wheel transmits to the
    carrier, the contact wrench at O is F_pf + D_p·X_p."""
    chain = mdh.from_rows(mdh.tables.contact_rows()[:2], values={"phi": wobble})
    dtype = jnp.result_type(theta, float)

    def wrench(x):
        params = jnp.concatenate([x.reshape(2, 10), jnp.zeros((2, 4), dtype)], axis=1)
        return mdh.newton_euler(
            chain, params, jnp.atleast_1d(theta), jnp.atleast_1d(theta_dot),
            jnp.atleast_1d(theta_ddot), gravity=jnp.asarray(gravity, dtype), base_omega=omega,
            base_omega_dot=omega_dot, base_acceleration=acceleration).base_wrench

    return jax.jacfwd(wrench)(jnp.zeros(20, dtype))


def tyre_twist(twist_pf: Float[Array, "6"], q_p: Float[Array, "3"], qdot_p: Float[Array, "3"],
               theta=0.0, theta_dot=0.0, wobble=0.0) -> Float[Array, "6"]:
    """τ_p (2-44, 2-46): the twist of the tyre frame R_p relative to the road, at P, in R_p.

    τ_p = ^{p}𝕋_{pf}·(J_p(q)·q̇ + τ_pf), J_p the Jacobian of body 6 of Table 1 (F-8) over
    q_p = (ξ, h, γ) (and θ, whose rate with ξ̇ makes ξ̂̇); `twist_pf` the carrier's twist at O
    in R_pf.
    """
    chain = mdh.tables.contact_chain(wobble)
    zero = 0.0 * q_p[0]
    q = jnp.stack([theta + zero, q_p[0], q_p[1], q_p[2], zero, zero, zero])
    qd = jnp.stack([theta_dot + zero, qdot_p[0], qdot_p[1], qdot_p[2], zero, zero, zero])
    T = mdh.forward_kinematics(chain, q)[5]
    J = mdh.jacobian(chain, q, 6)  # V of O_p and ω, relative to R_pf, in R_pf
    P, R = T[:3, 3], T[:3, :3]
    total = jnp.concatenate([twist_pf[:3] + jnp.cross(twist_pf[3:], P), twist_pf[3:]]) + J @ qd
    return jnp.concatenate([R.T @ total[:3], R.T @ total[3:]])


def _homogeneous(R, P):
    top = jnp.concatenate([R, P[:, None]], axis=1)
    return jnp.concatenate([top, jnp.array([[0.0, 0.0, 0.0, 1.0]], R.dtype)], axis=0)


def patch_flexibility(wrench_p: Float[Array, "6"], k_x, k_y, k_beta) -> Float[Array, "3"]:
    """q_AC = (y, x, β) = (F_yp/K_y, F_xp/K_x, (M_zp + (1/K_x − 1/K_y)F_xp F_yp)/K_β) (2-41):
    the static deflection of the contact-patch joints 7–9 of Table 1 under the tyre wrench."""
    fx, fy, mz = wrench_p[0], wrench_p[1], wrench_p[5]
    return jnp.stack([fy / k_y, fx / k_x, (mz + (1 / k_x - 1 / k_y) * fx * fy) / k_beta])


# --------------------------------------------------------------------------------------------
# Deformation inputs (2-91…2-104)


def deformation_inputs(twist_p: Float[Array, "6"], omega, gamma, rolling_radius):
    """κ′ = V_x/ω − R_r, δ′ = V_y/ω, φ′ = β̇/ω, φ̄′ = φ′ − γ and the camber products
    π(γ,V_x) = γV_x/ω, π(γ,β̇) = γβ̇/ω, π(γ²,β̇) = γ²β̇/ω (2-91…2-95, 2-112), from the tyre-frame
    twist (V_x V_y V_z | γ̇ ξ̇ β̇) and the spin rate ω (rad/s). Lengths in the unit of V/ω."""
    vx, vy, beta_dot = twist_p[0], twist_p[1], twist_p[5]
    phi = beta_dot / omega
    return {"kappa_p": vx / omega - rolling_radius, "delta_p": vy / omega, "phi_p": phi,
            "phibar_p": phi - gamma, "pi_gamma_vx": gamma * vx / omega,
            "pi_gamma_beta": gamma * phi, "pi_gamma2_beta": gamma**2 * phi}


def psa_inputs(twist_p: Float[Array, "6"], omega, gamma, rolling_radius):
    """The PSA-convention inputs (2-96…2-99): κ = R_r ω/V_x − 1, δ = arctan(−V_y/V_x),
    φ̄ = −β̇/V_x + sin γ/R_r, φ = −β̇/V_x."""
    vx, vy, bd = twist_p[0], twist_p[1], twist_p[5]
    return {"kappa": rolling_radius * omega / vx - 1.0, "delta": jnp.arctan(-vy / vx),
            "phibar": -bd / vx + jnp.sin(gamma) / rolling_radius, "phi": -bd / vx}


def kappa_prime_from_slip(kappa, rolling_radius):
    """κ′ = R_r·(1/(κ+1) − 1) (2-101)."""
    return rolling_radius * (1.0 / (kappa + 1.0) - 1.0)


def slip_from_kappa_prime(kappa_p, rolling_radius):
    """Inverse of (2-101)."""
    return 1.0 / (kappa_p / rolling_radius + 1.0) - 1.0


def delta_prime_from_slip_angle(delta, rolling_radius):
    """δ′ = −R_r·tan δ (2-102), zero longitudinal slip."""
    return -rolling_radius * jnp.tan(delta)


def slip_angle_from_delta_prime(delta_p, rolling_radius):
    """Inverse of (2-102)."""
    return jnp.arctan(-delta_p / rolling_radius)


def phi_prime_from_curvature(phi, rolling_radius):
    """φ′ = −R_r·φ (2-104) (and φ̄′ = −R_r·φ̄ (2-103))."""
    return -rolling_radius * phi


def curvature_from_phi_prime(phi_p, rolling_radius):
    """Inverse of (2-104)."""
    return -phi_p / rolling_radius


def rolling_radius_from_equivalence(delta_p, delta):
    """R_r implied by an equivalence δ′ ↔ δ of (2-102): R_r = |δ′| / tan|δ| (the thesis's
    ±18 mm ↔ ±3.5° gives 0.294 m, spec §0.3)."""
    return jnp.abs(delta_p) / jnp.tan(jnp.abs(delta))


# --------------------------------------------------------------------------------------------
# Analytic contact patch (2-58…2-90)


def patch_geometry(free_radius, height, width=0.0, camber=0.0):
    """The cylinder-on-plane patch with full adhesion (2-59…2-82).

    **Arguments:** `free_radius` R_L, `height` h_0 (> 0, wheel centre above the ground),
    `width` w, `camber` γ (rad).

    **Returns:** dict: `chi0` = arccos(h_0/R_L) (2-60), `length` L = 2R_L sin χ0 (2-61),
    trails `t_x` = −(R_L/χ0²)(sin χ0 − χ0 cos χ0), `t_y` = sin γ·w²/(6χ0 R_L sin χ0),
    `t_z` = R_L(cos χ0 − sin χ0/χ0) (2-77), rolling radius `R_r` = R_L sin χ0/χ0 (2-81),
    crush `e_r` = (R_L/χ0²)(χ0 cos χ0 − sin χ0) (2-82), and `t_y_prime` = t_y/γ's first-order
    slope w²/(6χ0 R_L sin χ0).
    """
    chi = jnp.arccos(height / free_radius)
    s, c = jnp.sin(chi), jnp.cos(chi)
    ty1 = width**2 / (6.0 * chi * free_radius * s)
    return {"chi0": chi, "length": 2.0 * free_radius * s,
            "t_x": -(free_radius / chi**2) * (s - chi * c), "t_y": jnp.sin(camber) * ty1,
            "t_z": free_radius * (c - s / chi), "R_r": free_radius * s / chi,
            "e_r": (free_radius / chi**2) * (chi * c - s), "t_y_prime": ty1}


def pneumatic_matrix(phi_x, phi_y, phi_beta, geometry, f_yc=0.0, m_zon=0.0):
    """The restricted input/output matrix (2-112) (rows F_x, F_y, M_z; columns κ′, δ′, φ,
    π(γ,V_x), π(γ,β̇), π(γ²,β̇), γ, 1), overall factor 2wχ0² left to the Φ's: a structural
    prior of the contact force model from the patch geometry (`patch_geometry`)."""
    tx, ty, er = geometry["t_x"], geometry["t_y_prime"], geometry["e_r"]
    z = 0.0 * tx
    return jnp.stack([
        jnp.stack([phi_x, z, z, z, phi_x * ty, z, z, z]),
        jnp.stack([z, phi_y, -tx * phi_y, z, z, z, phi_y * er, z + f_yc]),
        jnp.stack([z, -tx * phi_y, phi_beta + tx**2 * phi_y, phi_x * ty, z, phi_x * ty**2,
                   -tx * phi_y * er, z + m_zon]),
    ])


def modal(stiffness, damping, inertia):
    """Static gain, natural angular frequency ω0 = √(K/I) and damping ratio h/(2√(KI)) of a
    contact-patch joint (2-40)."""
    return stiffness, jnp.sqrt(stiffness / inertia), damping / (2.0 * jnp.sqrt(stiffness
                                                                                 * inertia))


__all__ = ["carrier_to_tyre", "carrier_to_tyre_closed", "tyre_twist_zero_wobble",
           "wrench_to_tyre_closed", "curvature_from_phi_prime", "deformation_inputs",
           "delta_prime_from_slip_angle", "flat_trac_plane", "flat_trac_transform",
           "ground_plane", "inverse_transform", "kappa_prime_from_slip", "modal",
           "patch_flexibility", "patch_geometry", "phi_prime_from_curvature", "pneumatic_matrix",
           "psa_inputs", "rolling_radius_from_equivalence", "slip_angle_from_delta_prime",
           "slip_from_kappa_prime", "tyre_frame", "tyre_frame_zero_wobble", "tyre_twist",
           "wheel_inertia_regressor", "wobble_rotation", "wrench_to_tyre",
           "wrench_transform_zero_wobble"]
