"""The isolated bushing of the thesis's Adams example (spec stiffness §1.12a, §4.1, §7 R1)."""


from ..geometry import DEG
from ..model import Mechanism, MechanismBuilder

ISOLATED_BUSHING_REULER_DEG = (28.18678543, 33.2259422, 350.8538915)
"""REULER (ψ, θ, φ) of the bushing's I and J markers in `model_exemple11` (deg)."""


def isolated_bushing(k_trans: float = 100.0, k_rot_deg: float = 10000.0) -> Mechanism:
    """One arm held on the ground by one six-axis bushing: the Adams dataset `model_exemple11`.

    **Source:** spec "suspension_stiffness_identification" §4.1 (thesis Annex F) and §1.12a
    (Table 4.1), reference result §7 R1.

    **Frame:** the Adams model's global frame (mm); the arm's part frame coincides with it at
    design (q = 0), as for every diffsusp model.

    **Model:**

    - part `'arm'` (Adams PART/2), on the ground through bushing `'bush'` (BUSHING/1);
    - bushing markers: I = MARKER/7 on the arm and J = MARKER/8 on the ground, both at the
      origin with REULER = (28.18678543, 33.2259422, 350.8538915) deg, so the bushing starts
      undeformed and its axes are rotated with respect to the global frame. Law on I, deformation
      of I relative to J expressed in J (Adams convention). Markers: `'bush.i'`, `'bush.j'`;
    - stiffness K = `k_trans` N/mm on the three translations (the annex has 100; Table 4.1 says
      10 000: both are meant to be identified exactly) and KT = `k_rot_deg`·180/π N·mm/rad on
      the three projected angles (the annex's 5.729577951e5 N·mm/rad = 10 000 N·mm/deg);
    - load point `'tip'` on the arm at QP = (−300, 0, 0) (MARKER/12), components global (the
      GFORCE's RM = MARKER/13 is a ground marker with no rotation);
    - load point `'centre'` on the arm at the origin (not in the annex), for the closed form:
      a force F and moment M there give, exactly (no small-angle approximation, because
      the load and the bushing's I marker are the same point), a global translation F/K of the
      arm, a translational deformation δ_T = R_Jᵀ F / K in J, and projected angles of R_{I/J}
      equal to R_Jᵀ M / K_T, with R_J the bushing frame (columns = J axes in global).

    Not modelled (statics only): mass, damping CT, the floating reaction marker, the commented
    out cylindrical joint.

    **Arguments:**

    - `k_trans`: translational stiffness on each bushing axis (N/mm).
    - `k_rot_deg`: rotational stiffness on each bushing axis (N·mm/deg; converted to N·mm/rad).

    **Returns:** the `Mechanism` (1 part, n = 6, no joint, 6 DOF all held by the bushing).
    """
    b = MechanismBuilder("isolated bushing (model_exemple11)")
    b.part("arm")
    b.bushing(
        "bush",
        parts=("arm", "ground"),
        at=(0.0, 0.0, 0.0),
        reuler_deg=ISOLATED_BUSHING_REULER_DEG,
        k_trans=k_trans,
        k_rot=k_rot_deg / DEG,
    )
    b.load_point("tip", part="arm", at=(-300.0, 0.0, 0.0))
    b.load_point("centre", part="arm", at=(0.0, 0.0, 0.0))
    return b.build()
