"""Two links on bushings joined by a coupler (spec stiffness §1.12c, §7 R3)."""


from ..geometry import DEG
from ..model import Mechanism, MechanismBuilder

LINK_LENGTH = 450.0
"""Length of links S1 and S2 along global y (mm)."""
LINK_SPACING = 250.0
"""Distance between S1 and S2 along global x (mm)."""


def two_bushing_coupler(k_trans: float = 10000.0, k_rot_deg: float = 10000.0) -> Mechanism:
    """Two links each held on the ground by a bushing and joined by a coupler through two
    revolutes (the thesis's "two bushings / 4-bar" case).

    **Source:** spec "suspension_stiffness_identification" §1.12c (fig. 4.8, lost) and §7 R3.
    The lengths (450 mm links, 250 mm apart) and topology are the thesis's; the rest of the
    geometry is lost and chosen here.

    **Frame:** global, mm; everything lies in the plane z = 0 at design.

    **Chosen geometry:**

    - S1 `'link_1'` from (0, 0, 0) to (0, 450, 0) and S2 `'link_2'` from (250, 0, 0) to
      (250, 450, 0), i.e. both along global y, 250 mm apart along x;
    - bushings `'bushing_1'` and `'bushing_2'` at the ground ends (0, 0, 0) and (250, 0, 0):
      I on the ground, J on the link, axes = global axes; `k_trans` N/mm and `k_rot_deg`
      N·mm/deg (converted to N·mm/rad) on all axes (thesis: 10 000 and 10 000);
    - S3 `'coupler'` from (0, 450, 0) to (250, 450, 0), joined to S1 and S2 by revolutes
      `'revolute_1'` and `'revolute_2'` at those points, axes along global z;
    - load point `'coupler_middle'` on S3 at (125, 450, 0), global components.

    **Structure:** n = 18, m = 10 joint rows, rank 10, 8 kinematic DOF all held by the bushings
    (no free mode). Because the revolute axes are parallel (global z), the revolutes force S1,
    S2 and S3 to share their rotations about x and y: Krx of the two bushings act in parallel,
    and so do Kry; only the sums Krx1 + Krx2 and Kry1 + Kry2 are identifiable, Krz (and the
    translations) individually.

    **Returns:** the `Mechanism`.
    """
    k_rot = k_rot_deg / DEG
    z_axis = (0.0, 0.0, 1.0)
    b = MechanismBuilder("two-bushing coupler")
    for part in ("link_1", "link_2", "coupler"):
        b.part(part)
    for k, x in ((1, 0.0), (2, LINK_SPACING)):
        b.bushing(f"bushing_{k}", parts=("ground", f"link_{k}"), at=(x, 0.0, 0.0),
                  k_trans=k_trans, k_rot=k_rot)
        b.joint(f"revolute_{k}", "revolute", parts=(f"link_{k}", "coupler"),
                at=(x, LINK_LENGTH, 0.0), z=z_axis)
    b.load_point("coupler_middle", part="coupler", at=(LINK_SPACING / 2, LINK_LENGTH, 0.0))
    return b.build()
