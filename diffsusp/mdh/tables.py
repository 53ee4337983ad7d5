"""The thesis's MDH tables and the trees they assemble into.

spec: tyre_contact_model §1.4 (Table 1, contact chain), §4.1 (Table 4, Flat Trac), §5.2
(Tables 30, 31, vehicle), §0.5 items 1, 2, 11 and §9.4 (the source's typos). SI units (m, rad).

Decisions on the source's typos (documented here and tested):

- **Table 1, rows 7/8** print r_7 = x labelled "ballant" (lateral) and r_8 = y "avance"
  (longitudinal). The text defines q_AC = (y, x, β), y lateral and x longitudinal: joint 7 is the
  lateral displacement y, joint 8 the longitudinal x (variables named so; the axes they move
  along are checked in the tests: joint 7 slides along y_p, joint 8 along x_p).
- **Table 1 caption**: R_10 is attached like R_9 (locked on the contact-patch body).
- **Table 4**: the belt translations y_T, x_T are prismatic (σ = 1, printed 0), the belt
  orientation α_T is a revolute variable in θ_5 (printed in r_5), joint 8 is locked (σ = 2,
  printed 0). The belt orientation and lateral joints can be locked (`bench_locked=True`) as
  the thesis does (they are not measured).
- **Table 30** is headed "Modèle DHM du banc Flat Trac" in the source (copy-paste): it is the
  axle chain. Its rows are j = 2…8 with a(2) = 1 the body.
- **Table 31** is the body's single locked joint. The body's 6 DOF relative to the ground (§5.2,
  "free body = 3 prismatic + 3 revolute", §6.1) are not in any table: `free_body()` adds them
  (x, y, z translations, then yaw ψ, pitch, roll ϕ about the body axes) and a locked joint that
  turns the last frame onto the body frame R_c (x forward, y left, z up), so at q = 0 the body
  frame is the ground frame.
"""

import math

import jax.numpy as jnp

from .tree import LOCKED, PRISMATIC, REVOLUTE, Row, Tree, attach, from_rows

PI = math.pi
H = PI / 2


def contact_rows() -> list[Row]:
    """Table 1 (wheel carrier R_pf = R_0 → contact patch R_10), typo of rows 7/8 resolved."""
    return [
        Row(1, 0, REVOLUTE, 0, 0, -H, 0, 0, 0, "theta", "wheel rotation"),
        Row(2, 1, LOCKED, 0, 0, H, 0, 0, 0, "phi", "wheel wobble (locked at a known value)"),
        Row(3, 2, REVOLUTE, 0, 0, -H, 0, 0, 0, "xi", "tyre wind-up (virtual)"),
        Row(4, 3, PRISMATIC, 0, 0, H, 0, H, 0, "h", "tyre height (loaded radius)"),
        Row(5, 4, REVOLUTE, 0, 0, H, 0, 0, 0, "gamma", "camber"),
        Row(6, 5, LOCKED, 0, 0, -H, 0, -H, 0, "", "locked: R_6 = R_p (tyre frame)"),
        Row(7, 6, PRISMATIC, 0, 0, -H, 0, -H, 0, "y", "lateral patch displacement (ballant)"),
        Row(8, 7, PRISMATIC, 0, 0, -H, 0, H, 0, "x", "longitudinal patch displacement (avance)"),
        Row(9, 8, REVOLUTE, 0, 0, H, 0, 0, 0, "beta", "contact-patch torsion"),
        Row(10, 9, LOCKED, 0, 0, 0, 0, H, 0, "", "locked: R_10 = R_AC (contact patch)"),
    ]


def contact_chain(wobble: float = 0.0) -> Tree:
    """Table 1: the 7-DOF chain wheel carrier → contact patch; q = (θ, ξ, h, γ, y, x, β);
    `wobble` ϕ (rad) is the locked joint 2's value. Body 6 is the tyre frame R_p, body 10 the
    contact patch R_AC."""
    return from_rows(contact_rows(), values={"phi": wobble})


def flat_trac(*, bench_locked: bool = False) -> Tree:
    """Table 4 (Flat Trac, σ typos resolved): base R_0; bodies 1–4 the arm (R_4 = R_pf), bodies
    5–8 the belt (R_8 = road R_r). q = (γ_FT, h_FT, β_FT, α_T, y_T, x_T), or (γ_FT, h_FT, β_FT,
    x_T) with `bench_locked` (α_T and y_T locked at 0, as in the thesis)."""
    rows = [
        Row(1, 0, LOCKED, 0, 0, 0, 0, H, 0, "", "locked"),
        Row(2, 1, REVOLUTE, 0, 0, H, 0, 0, 0, "gamma_FT", "Flat Trac camber"),
        Row(3, 2, PRISMATIC, 0, 0, -H, 0, -H, 0, "h_FT", "Flat Trac height"),
        Row(4, 3, REVOLUTE, 0, 0, 0, 0, 0, 0, "beta_FT", "Flat Trac steer (R_4 = R_pf)"),
        Row(5, 0, REVOLUTE, 0, 0, 0, 0, 0, 0, "alpha_T", "belt orientation"),
        Row(6, 5, PRISMATIC, 0, 0, -H, 0, -H, 0, "y_T", "belt lateral displacement"),
        Row(7, 6, PRISMATIC, 0, 0, -H, 0, H, 0, "x_T", "belt advance"),
        Row(8, 7, LOCKED, 0, 0, H, 0, H, 0, "", "locked (R_8 = road R_r)"),
    ]
    tree = from_rows(rows)
    return tree.with_locked(("alpha_T", "y_T")) if bench_locked else tree


def flat_trac_with_wheel(*, bench_locked: bool = True, wobble: float = 0.0) -> Tree:
    """Table 4 with the wheel chain of Table 1 attached at bench body 4 (R_pf)."""
    return attach(flat_trac(bench_locked=bench_locked), contact_chain(wobble), 4)


def free_body() -> Tree:
    """The body's 6 DOF relative to the ground (ground frame: z up): translations x, y, z along
    the ground axes, then yaw ψ, pitch, roll ϕ (ZYX), and a locked joint onto the body frame.
    Bodies 1–7; body 7 is the body frame (at q = 0 the ground frame)."""
    rows = [
        Row(1, 0, PRISMATIC, 0, 0, 0, 0, 0, 0, "Z", "body heave (ground z)"),
        Row(2, 1, PRISMATIC, H, 0, H, 0, 0, 0, "X", "body advance (ground x)"),
        Row(3, 2, PRISMATIC, H, 0, H, 0, 0, 0, "Y", "body sway (ground y)"),
        Row(4, 3, REVOLUTE, H, 0, H, 0, 0, 0, "yaw", "body yaw"),
        Row(5, 4, REVOLUTE, 0, 0, -H, 0, 0, 0, "pitch", "body pitch"),
        Row(6, 5, REVOLUTE, H, 0, H, 0, 0, 0, "roll", "body roll"),
        Row(7, 6, LOCKED, -H, 0, H, 0, H, 0, "", "locked: body frame R_c (Table 31)"),
    ]
    return from_rows(rows)


def body_rows() -> list[Row]:
    """Table 31: the body's single locked joint (identity)."""
    return [Row(1, 0, LOCKED, 0, 0, 0, 0, 0, 0, "", "body (Table 31)")]


def axle_rows(half_track: float, half_wheelbase: float, height: float = 0.0) -> list[Row]:
    """Table 30 renumbered 1…7 (printed j = 2…8; its a(2) = 1 is the body, here the base):
    half-track l (prismatic), half-wheelbase L, suspension travel z (constant part `height`),
    steer β, camber γ, wind-up ζ, locked R_8 = R_pf. Constants (m) are the design values the
    variables add to."""
    return [
        Row(1, 0, PRISMATIC, 0, 0, -H, 0, -H, half_track, "l", "half-track"),
        Row(2, 1, PRISMATIC, 0, 0, -H, 0, -H, half_wheelbase, "L", "half-wheelbase"),
        Row(3, 2, PRISMATIC, 0, 0, -H, 0, 0, height, "z", "suspension travel"),
        Row(4, 3, REVOLUTE, 0, 0, 0, 0, 0, 0, "steer", "steer"),
        Row(5, 4, REVOLUTE, 0, 0, H, 0, H, 0, "camber", "camber"),
        Row(6, 5, REVOLUTE, 0, 0, H, 0, H, 0, "windup", "wind-up"),
        Row(7, 6, LOCKED, 0, 0, H, 0, 0, 0, "", "locked: R_8 = R_pf"),
    ]


WHEELS = ("FL", "FR", "RL", "RR")


def default_geometry() -> dict:
    """Half-track, half-wheelbase (signed: + left, + forward) and wheel-centre height below the
    body frame (m), for a mid-size saloon (Peugeot 406-like; the thesis gives none)."""
    return {"FL": (0.75, 1.20, -0.25), "FR": (-0.75, 1.20, -0.25),
            "RL": (0.74, -1.50, -0.25), "RR": (-0.74, -1.50, -0.25)}


def vehicle(dof: int = 58, geometry: dict | None = None) -> Tree:
    """The vehicle tree of §5.2: free body (6 DOF) + Table 31 + four Table-30 axle chains
    (6 DOF each) + four Table-1 contact chains (7 DOF each, for dof = 58).

    - 58 DOF: all of it (6 + 4×6 + 4×7);
    - 30 DOF: no contact chains (6 + 4×6), the wheel carriers are the leaves;
    - 12 DOF: the 30-DOF tree with half-track and half-wheelbase variations, camber, wind-up and
      the rear steer locked at 0 (§5.2: 6 + 4 travels + 2 front steers).

    Variables are prefixed by the wheel ("FL_z", "FR_steer", …). `geometry`: as
    `default_geometry()`.
    """
    if dof not in (58, 30, 12):
        raise ValueError(f"vehicle trees have 58, 30 or 12 DOF; got dof={dof}.")
    geometry = geometry or default_geometry()
    tree = attach(free_body(), from_rows(body_rows()), 7)
    body = tree.n
    for wheel in WHEELS:
        l, L, z = geometry[wheel]
        axle = from_rows(axle_rows(l, L, z))
        tree = attach(tree, axle, body, prefix=f"{wheel}_")
        carrier = tree.n
        if dof == 58:
            tree = attach(tree, contact_chain(), carrier, prefix=f"{wheel}_")
    if dof == 12:
        lock = [f"{w}_{v}" for w in WHEELS for v in ("l", "L", "camber", "windup")]
        lock += ["RL_steer", "RR_steer"]
        tree = tree.with_locked(lock)
    return tree


def carrier_bodies(tree: Tree) -> dict:
    """1-based body index of each wheel carrier R_pf (the locked frame 8 of each axle chain)."""
    out = {}
    for j, label in enumerate(tree.labels):
        if label == "locked: R_8 = R_pf":
            out[WHEELS[len(out)]] = j + 1
    return out


def body_index(tree: Tree) -> int:
    """1-based index of the vehicle body frame (Table 31)."""
    return tree.labels.index("body (Table 31)") + 1


__all__ = ["WHEELS", "axle_rows", "body_index", "body_rows", "carrier_bodies", "contact_chain",
           "contact_rows", "default_geometry", "flat_trac", "flat_trac_with_wheel",
           "free_body", "vehicle"]
_ = jnp
