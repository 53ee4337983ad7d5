"""The thesis's pseudo-McPherson test half axle (spec stiffness §0, §2.7; geometry §2.2, §2.5,
§3.10)."""


from ..geometry import DEG
from ..model import Mechanism, MechanismBuilder
from ..model.corner import Corner, common_perpendicular_midpoint, design_offset

__all__ = ["PSEUDO_MCPHERSON_JOINTS", "PSEUDO_MCPHERSON_REULER_DEG", "pseudo_mcpherson"]

# Table 2.2: joint poses of the loaded half axle (4500 N vertical), Adams/Car frame, mm and
# REULER (ψ, θ, φ) in degrees. Ball joints have no orientation.
PSEUDO_MCPHERSON_JOINTS = {
    "L1": (-294.7, -365.1, 246.1),
    "L2": (61.1, -383.5, 186.2),
    "L3": (-73.7, -353.4, 228.3),
    "L4": (73.7, -594.7, 762.6),
    "L5": (63.1, -617.8, 635.1),
    "L6": (-135.3, -694.6, 207.4),
    "L7": (5.87, -679.9, 164.8),
    "L8": (-25.5, -691.2, 233.0),
    "L9": (0.0, -787.0, 305.0),
}
"""Table 2.2 joint positions (mm, Adams/Car frame: x rearward, y right, z up; left side)."""

PSEUDO_MCPHERSON_REULER_DEG = {
    "L1": (129.5, 90.22, 181.79),
    "L2": (79.58, 90.24, 4.11),
    "L4": (321.5, 166.7, 53.68),
    "L5": (-28.84, 168.1, 0.0),
    "L9": (-0.26, 90.69, 0.0),
}
"""Table 2.2 joint orientations, REULER z-x-z (ψ, θ, φ) in degrees."""

BUSHING_STIFFNESS = {
    "bushing_A": ((13875.0, 13875.0, 1370.0), (11000.0, 11000.0, 4000.0)),
    "bushing_B": ((310.0, 2400.0, 180.0), (4500.0, 1100.0, 1600.0)),
    "bushing_F": ((1285.0, 1285.0, 647.0), (5500.0, 5500.0, 0.0)),
}
"""Table 2.1 nominal stiffnesses: (Ktx, Kty, Ktz) in N/mm, (Krx, Kry, Krz) in N·mm/deg."""

SPRING_RATE = 22.0
"""Suspension spring rate (N/mm), Table 2.1."""

LOADED_RADIUS = 305.0
"""Wheel centre height above the contact patch at the 4500 N design load (mm): L9's z."""

DESIGN_LOAD = 4500.0
"""Vertical wheel load (N) at which Table 2.2 was measured."""

SPRING_FREE_LENGTH = 357.32158331
"""Spring free length (mm) that makes Table 2.2 the equilibrium under `DESIGN_LOAD` (see the
builder's docstring for the derivation)."""

BUMP_STOP = dict(length=70.0, k=50.0, cubic=1.0)
"""Bump stop of `pseudo_mcpherson(stops=True)` on the strut length |L4 − L5| (mm, N/mm, N/mm³):
engaged below 70 mm, i.e. 60.0 mm of strut compression from the design length 130.0 mm (about
+73 mm of wheel travel above the 4500 N ride height), force 50·p + 1.0·p³ N at p mm of
penetration (1.5 kN at 10 mm, 9 kN at 20 mm, 28.5 kN at 30 mm: a progressive elastomer bump stop
like the force–deflection curve of an Adams/Car `.bum` property file). Chosen: the thesis
tabulates no stop."""

REBOUND_STOP = dict(length=225.0, k=100.0, cubic=2.0)
"""Rebound stop of `pseudo_mcpherson(stops=True)` on the strut length (mm, N/mm, N/mm³): engaged
above 225 mm, i.e. 95.0 mm of strut extension from design (about −100 mm of wheel travel, reached
near 2 050 N of vertical load), force 100·p + 2.0·p³ N (3 kN at 10 mm, 18 kN at 20 mm), stiffer
than the bump stop like the hydraulic/elastomer rebound stop inside a damper (Adams/Car `.reb`).
Chosen: the thesis tabulates no stop."""


def virtual_lower_pivot() -> tuple[float, float, float]:
    """The design virtual lower steering pivot as a (forward, outboard, up) offset (mm) from the
    wheel centre L9: the midpoint of the common perpendicular of the two lower links' lines
    (front arm L1–L8, rear arm L2–L7, Table 2.2), at (−1.62, −716.49, 197.11) mm in the
    Adams/Car frame. The two lines pass 70 mm apart vertically; in plan view they cross 8–12 %
    beyond the ball joints."""
    p = PSEUDO_MCPHERSON_JOINTS
    pivot = common_perpendicular_midpoint(p["L1"], p["L8"], p["L2"], p["L7"])
    return design_offset(pivot, p["L9"], "adams", "left")


def corner(*, strut: bool = True):
    """The wheel of the half axle (`diffsusp.model.corner.Corner`): Adams/Car frame, side from
    the wheel centre (left as built), wheel centre L9 (its z axis is the spin axis, outboard),
    contact patch `LOADED_RADIUS` below it, steering axis from the strut top L4 (None without
    the strut) to the design virtual lower pivot of the two lower links (`virtual_lower_pivot`,
    fixed on the hub carrier), design load `DESIGN_LOAD`."""
    kingpin = ("L4_strut_top", ("hub_carrier", virtual_lower_pivot())) if strut else None
    return Corner(kingpin=kingpin, frame="adams", loaded_radius=LOADED_RADIUS,
                  design_load=DESIGN_LOAD)


def pseudo_mcpherson(wheel_travel: bool = False, *,
                     spring_free_length: float = SPRING_FREE_LENGTH,
                     stops: bool = False) -> Mechanism:
    """The pseudo-McPherson front half axle of the thesis's K&C tests, nominal stiffnesses.

    **Source:** spec "suspension_stiffness_identification" §0 (Tables 2.1, 2.2 and the parts
    S1–S7), §2.7 (the Chapter 5 reference model: Table 2.2 geometry + Table 2.1 stiffnesses);
    spec "suspension_geometry_identification" §2.2 (REULER = Rz(ψ)Rx(θ)Rz(φ), columns = joint
    axes in global), §2.5 (the tables are in the Adams/Car frame), §3.10 (inferred joint map).

    **Frame:** Adams/Car: x rearward, y to the right, z up, origin on the ground midway between
    the contact patches; this is the left wheel (y < 0); mm. Table 2.2 is the loaded state
    (4500 N vertical) and is taken as the design position q = 0.

    **Parts:** `'front_arm'` (S2), `'rear_arm'` (S3), `'strut'` (S5), `'hub_carrier'` (S6).
    The frame S1 is the ground. The rigid dummy wheel S7 is merged into the hub carrier (on the
    rig it is rigidly bolted to it; statically nothing moves between them). The tie rod S4 is
    not a part (see below). n = 24 coordinates.

    **Joint map** (the L-numbers of Table 2.2; L3, L5–L9 inferred in geometry §3.10):

    | L | element | kind | markers (I on ↔ J on) |
    |---|---|---|---|
    | L1 | `'bushing_B'` front arm–frame | bushing, REULER L1 | ground ↔ front_arm |
    | L2 | `'bushing_A'` rear arm–frame | bushing, REULER L2 | ground ↔ rear_arm |
    | L3–L6 | `'tie_rod'` | distance (massless link) | ground (L3) ↔ hub_carrier (L6) |
    | L4 | `'bushing_F'` strut top | bushing, REULER L4 | strut ↔ ground |
    | L5 | `'strut_slide'` strut–hub carrier | translational, z of REULER L5 | strut ↔ hub_carrier |
    | L7 | `'rear_ball_joint'` | spherical | rear_arm ↔ hub_carrier |
    | L8 | `'front_ball_joint'` | spherical | front_arm ↔ hub_carrier |
    | L4–L5 | `'spring'` | linear spring | strut (L4) ↔ hub_carrier (L5) |
    | L9 | `'wheel_centre'` marker | REULER L9 (z = spin axis ≈ −y) | hub_carrier |

    Bushing sleeves: the inner sleeve (I) is bolted to the frame and the outer sleeve (J) pressed
    into the arm, so A and B have I on the ground; the strut-top bushing F has I on the strut and
    J on the ground. Stiffnesses are Table 2.1, rotational values converted from N·mm/deg to
    N·mm/rad (×180/π). With the Adams convention (law on I, deformation of I in J) instead of the
    thesis's mirrored one, the difference is the second-order δ × K·δ moment.

    **Removed free modes** (two motions have no stiffness in the physical axle; each is removed
    by a joint that carries no load in that direction, so the statics is unchanged):

    - the tie rod spins freely about its own axis between its two ball joints: it is modelled
      as a `distance` joint (a massless link of the design length 347.35 mm) between L3 on the
      ground and L6 on the hub carrier. The steering is fixed (the rack end L3 is on the frame).
    - bushing F has Krz = 0, so in a cylindrical strut–hub-carrier joint the strut rod would spin
      freely about its axis: the joint at L5 is `translational` (slides along z of L5, and locks
      the strut's spin to the hub carrier's rotation, which the arms and tie rod hold).
      The torque it carries about the strut axis is only what the strut's own elements exert
      about that axis (bushing F has no Krz), nearly nothing. (With the Table 2.2 poses as given the
      spin in a cylindrical joint is in fact *nearly* free, not exactly: L4 lies 2.5 mm off
      the L5 axis and bushing F's z is 3.6° from it, so the preloaded spring and bushing F give
      it about 10 N·mm/deg, ~2e-6 of the model's largest stiffness; `validate` names it only
      with `tol=1e-5`. The tie rod's spin is exactly free.)

    **Spring:** linear, 22 N/mm, between the upper seat at L4 (strut top, on the strut) and the
    lower seat at L5 (on the hub carrier, on the slide axis). Its design length is |L4 − L5| =
    130.009 mm; its line is 1.1° from the slide axis (the Table 2.2 values as given).
    **Reconstructed free length** L0 = 357.32158331 mm (`SPRING_FREE_LENGTH`; compression
    227.313 mm, 5000.9 N at design): chosen so that under the 4500 N vertical design load at the
    contact patch the equilibrium keeps the wheel centre at its design height. Derived with the
    solver: the wheel-centre height error Δz(L0) of the 4500 N equilibrium was zeroed by secant
    steps from L0 = 300 mm (Δz = +44.68 mm) and 350 mm (+5.85 mm): 357.5377, 357.3208,
    357.32158323, 357.32158331 (|Δz| < 1e-10 mm). The equilibrium is not exactly Table 2.2
    because the bushings are undeformed at q = 0 while the loaded axle deflects them: under
    4500 N the wheel centre settles by (−1.54, +0.28, 0.00) mm, mostly bushing B's soft radial
    direction (310 N/mm, 1.3 mm). No bump or rebound stops are modelled (none are tabulated),
    so large loads give large travels: −137.8 mm at 1500 N and +102.3 mm at 7500 N (wheel
    rate ≈ 24 N/mm about design).

    **Loads:** load point `'contact_patch'` on the hub carrier at (0, −787, 0) (loaded radius
    305 mm below L9), components in the global frame. Sign mapping used by
    `thesis_load_cases`: F_vert → +z (the ground pushing the wheel up), F_lat → +y (to the right,
    i.e. inboard on this left wheel), F_long → +x (rearward, i.e. a braking force).
    Load point `'wheel_centre'` (at the L9 marker, global components) takes wheel-centre
    forces and moments.

    **Markers:** `'wheel_centre'` (L9) and one marker per hardpoint on the moving part that
    carries it: `'L1_front_arm_bushing'`, `'L8_front_arm_ball'` (front_arm);
    `'L2_rear_arm_bushing'`, `'L7_rear_arm_ball'` (rear_arm); `'L4_strut_top'` (strut);
    `'L5_strut_base'`, `'L6_tie_rod_outer'`, `'L7_hub_rear_ball'`, `'L8_hub_front_ball'`
    (hub_carrier); `'L3_tie_rod_inner'` (ground). Joint and bushing markers are named
    `'<element>.i'` and `'<element>.j'`.

    **Structure:** 12 joint rows (distance 1, translational 5, two spherical 3 + 3), rank 12,
    12 kinematic DOF, all held by bushings and the spring (no redundant row, no free mode).
    With `wheel_travel=True`, driver `'wheel_travel'` prescribes the wheel centre's global z
    travel (mm): 13 rows, rank 13, 11 DOF; at zero travel and no load its multiplier (the
    vertical wheel-centre force the driver supplies) is 4501 N, consistent with the free length.
    One DOF per wheel travel: condensed onto the hub carrier at the 4500 N equilibrium
    (wheel-centre translation and rotation × 305 mm), the softest mode is the vertical travel
    (24.2 N/mm, direction 0.99 vertical); the next is the longitudinal compliance with wind-up
    (174 N/mm, bushing B's soft radial axis), a ratio of 7.2; the tie rod makes one direction
    rigid. (In the full 12-DOF reduced stiffness, scaled like `validate`, the arms' spins about
    their own axes, held only by the bushings' Krx, are as soft as the wheel travel but move no
    joint.)

    **Stops** (`stops=True`; the thesis's model has none, so the identification tests and the
    reference numbers use the stop-free model): a bump stop `'bump_stop'` and a rebound stop
    `'rebound_stop'` on the strut length, between the spring seats L4 (strut) and L5 (hub
    carrier), where an Adams/Car MacPherson template puts them (between the damper rod and the
    damper tube, with a clearance from the design length and a force–penetration law). Bump
    stop engaged below 70 mm (60 mm of strut compression from the 130.0 mm design length, about
    +73 mm of wheel travel), 50·p + 1.0·p³ N; rebound stop engaged above 225 mm (95 mm of
    extension, about −100 mm of wheel travel), 100·p + 2.0·p³ N (`BUMP_STOP`, `REBOUND_STOP`).
    Why they are needed: inside the thesis envelope (vertical 1 500–7 500 N, lateral and
    longitudinal ±4 000 N at the contact patch) the stop-free model has no equilibrium for
    about 8–10 % of the load combinations. Large vertical load with a forward (traction)
    longitudinal force pushes the wheel up until the spring is ~20 mm long and the tangent
    stiffness vanishes (a limit point), and a large inboard lateral force at low vertical load
    pulls the wheel down by 170–200 mm where the arms' and the spring's geometric softening
    again end the equilibrium branch (the stability margin of `diffsusp.statics.checks` falls to
    zero along a load ramp, so it is the model, not the solver). With the stops the strut stays
    between 58 and 236 mm over the envelope, the wheel centre between −121 and +92 mm, and every
    case has a stable equilibrium. Under pure vertical load the stops change nothing between
    2 050 and 6 500 N.

    **Arguments:**

    - `wheel_travel`: add the wheel-travel driver.
    - `spring_free_length`: spring free length (mm); the default is the reconstructed value.
    - `stops`: add the bump and rebound stops.

    **Returns:** the `Mechanism`.
    """
    return _builder(wheel_travel, spring_free_length, stops=stops).build()


BUSHING_JOINTS = {"bushing_B": (("ground", "front_arm"), "L1"),
                  "bushing_A": (("ground", "rear_arm"), "L2"),
                  "bushing_F": (("strut", "ground"), "L4")}
"""Each bushing's (I part, J part) and the hardpoint it sits at (Tables 2.1, 2.2)."""


def add_arm_markers(b: MechanismBuilder) -> None:
    """The lower arms' hardpoint markers (L1, L8 on the front arm; L2, L7 on the rear arm)."""
    p, e = PSEUDO_MCPHERSON_JOINTS, PSEUDO_MCPHERSON_REULER_DEG
    b.marker("L1_front_arm_bushing", "front_arm", p["L1"], reuler_deg=e["L1"])
    b.marker("L8_front_arm_ball", "front_arm", p["L8"])
    b.marker("L2_rear_arm_bushing", "rear_arm", p["L2"], reuler_deg=e["L2"])
    b.marker("L7_rear_arm_ball", "rear_arm", p["L7"])


def add_hub_markers(b: MechanismBuilder) -> None:
    """The hub carrier's hardpoint markers (L5, L6, L7, L8) and the wheel centre (L9)."""
    p, e = PSEUDO_MCPHERSON_JOINTS, PSEUDO_MCPHERSON_REULER_DEG
    b.marker("L5_strut_base", "hub_carrier", p["L5"], reuler_deg=e["L5"])
    b.marker("L6_tie_rod_outer", "hub_carrier", p["L6"])
    b.marker("L7_hub_rear_ball", "hub_carrier", p["L7"])
    b.marker("L8_hub_front_ball", "hub_carrier", p["L8"])
    b.marker("wheel_centre", "hub_carrier", p["L9"], reuler_deg=e["L9"])


def add_bushings(b: MechanismBuilder, names) -> None:
    """The named bushings at their hardpoints (`BUSHING_JOINTS`) with the Table 2.1 nominal
    stiffnesses (`BUSHING_STIFFNESS`, the rotational rates converted to N·mm/rad)."""
    p, e = PSEUDO_MCPHERSON_JOINTS, PSEUDO_MCPHERSON_REULER_DEG
    for name in names:
        parts, joint = BUSHING_JOINTS[name]
        k_trans, k_rot_deg = BUSHING_STIFFNESS[name]
        b.bushing(name, parts=parts, at=p[joint], reuler_deg=e[joint], k_trans=k_trans,
                  k_rot=tuple(k / DEG for k in k_rot_deg))


def _builder(wheel_travel: bool, spring_free_length: float, *, tie_rod_part: bool = False,
             strut_joint: str = "translational", stops: bool = False) -> MechanismBuilder:
    """The builder of `pseudo_mcpherson`. `tie_rod_part=True` models the tie rod as a part
    between two ball joints and `strut_joint='cylindrical'` uses the physical strut joint: the
    two free modes the public model removes (kept for tests of `validate`)."""
    p, e = PSEUDO_MCPHERSON_JOINTS, PSEUDO_MCPHERSON_REULER_DEG
    b = MechanismBuilder("pseudo-McPherson half axle" + (" (wheel travel)" if wheel_travel else "")
                         + (" (stops)" if stops else ""))
    for part in ("front_arm", "rear_arm", "strut", "hub_carrier"):
        b.part(part)

    # Readable hardpoint markers (measurement landmarks, K&C outputs).
    add_arm_markers(b)
    b.marker("L4_strut_top", "strut", p["L4"], reuler_deg=e["L4"])
    b.marker("L3_tie_rod_inner", "ground", p["L3"])
    add_hub_markers(b)
    add_bushings(b, ("bushing_B", "bushing_A", "bushing_F"))

    if tie_rod_part:
        b.part("tie_rod")
        b.joint("tie_rod_inner_ball_joint", "spherical", parts=("tie_rod", "ground"), at=p["L3"])
        b.joint("tie_rod_outer_ball_joint", "spherical", parts=("tie_rod", "hub_carrier"),
                at=p["L6"])
    else:
        b.joint("tie_rod", "distance", parts=("ground", "hub_carrier"), at=(p["L3"], p["L6"]))
    b.joint("strut_slide", strut_joint, parts=("strut", "hub_carrier"), at=p["L5"],
            reuler_deg=e["L5"])
    b.joint("rear_ball_joint", "spherical", parts=("rear_arm", "hub_carrier"), at=p["L7"])
    b.joint("front_ball_joint", "spherical", parts=("front_arm", "hub_carrier"), at=p["L8"])
    b.spring("spring", parts=("strut", "hub_carrier"), at=(p["L4"], p["L5"]), k=SPRING_RATE,
             free_length=spring_free_length)
    if stops:
        b.stop("bump_stop", parts=("strut", "hub_carrier"), at=(p["L4"], p["L5"]), kind="bump",
               **BUMP_STOP)
        b.stop("rebound_stop", parts=("strut", "hub_carrier"), at=(p["L4"], p["L5"]),
               kind="rebound", **REBOUND_STOP)

    x9, y9, z9 = p["L9"]
    b.load_point("contact_patch", part="hub_carrier", at=(x9, y9, z9 - LOADED_RADIUS))
    b.load_point("wheel_centre", marker="wheel_centre")
    if wheel_travel:
        b.driver("wheel_travel", marker="wheel_centre", direction=(0.0, 0.0, 1.0))
    b.corner(corner())
    return b
