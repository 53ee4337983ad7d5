"""Static index data of a mechanism, resolved once when it is built (the MuJoCo MJX way).

Every element touches at most two parts. Its 12 solver coordinates z = (q_a, q_b) are gathered
from the full coordinate vector by a static index array; the ground is a virtual part whose six
coordinates sit in a fixed slot of zeros, so ground-attached elements need no special case.
Element groups (one per element kind and law) carry their stacked index arrays; the statics
kernel vmaps one element function over each group and scatters into the KKT system through the
destinations computed here.

Slots of the full unknown vector: coordinates of part a at 6a…6a+5 (a < P), the ground at
6P…6P+5, multiplier k of `independent_rows` at 6(P+1)+k, one dummy slot for redundant rows.
`live` maps a slot to its place in the solved vector (q, λ) or to the trash position `size`.
"""

import numpy as np

from .kinds import GROUND, JOINT_ROWS, row_blocks

# Rows of each joint kind that measure an angle (dimensionless) rather than a length (mm).
ANGULAR_ROWS = {
    "spherical": (),
    "revolute": (3, 4),
    "cylindrical": (2, 3),
    "translational": (2, 3, 4),
    "universal": (3,),
    "fixed": (3, 4, 5),
    "inline": (),
    "inplane": (),
    "perpendicular": (0,),
    "distance": (),
}


# Every joint row is one of these candidate quantities (d = x_I − x_J, axes of I and J):
#   0–2 d (global), 3 d·x_J, 4 d·y_J, 5 d·z_J, 6 z_I·x_J, 7 z_I·y_J, 8 x_I·y_J, 9 z_I·z_J,
#   10 |d| − its design value, 11 zero (padding)
JOINT_CANDIDATES = {
    "spherical": (0, 1, 2),
    "revolute": (0, 1, 2, 6, 7),
    "cylindrical": (3, 4, 6, 7),
    "translational": (3, 4, 6, 7, 8),
    "universal": (0, 1, 2, 9),
    "fixed": (0, 1, 2, 6, 7, 8),
    "inline": (3, 4),
    "inplane": (5,),
    "perpendicular": (9,),
    "distance": (10,),
}
N_CANDIDATES = 12


class Group:
    """One element group: `members` (indices into the element table), `coords` (E, 12) slots of
    the two parts' coordinates (I part first), and for constraint groups `rows` (E, r) row
    numbers and `row_slots` (E, r) multiplier slots."""

    def __init__(self, kind, members, coords, rows=None, row_slots=None):
        self.kind = kind
        self.members = np.asarray(members, dtype=int)
        self.coords = coords
        self.rows = rows
        self.row_slots = row_slots


class Topology:
    """Index bookkeeping of one mechanism, computed from its static fields only (hashable by
    them, so it is static data of the `Mechanism` pytree)."""

    def __init__(self, mech):
        self.key = (
            len(mech.parts), mech.markers.part, mech.joints.kind, mech.joints.i_marker,
            mech.joints.j_marker, mech.bushings.i_marker, mech.bushings.j_marker,
            mech.springs.i_marker, mech.springs.j_marker, mech.springs.tabulated,
            mech.stops.i_marker, mech.stops.j_marker, mech.stops.kind, mech.drivers.marker,
            mech.load_points.marker, mech.load_points.frame, mech.independent_rows,
            mech.reference_points,
        )
        n_parts = len(mech.parts)
        self.n = 6 * n_parts
        self.m = len(mech.independent_rows)
        self.ground = self.n  # first slot of the ground's (zero) coordinates
        self.base = base = self.n + 6
        self.size = base + self.m + 1
        n_rows = mech.joints.n_rows + len(mech.drivers.names)
        dummy = base + self.m
        position = {r: base + k for k, r in enumerate(mech.independent_rows)}
        self.row_slot = np.array([position.get(r, dummy) for r in range(n_rows)], dtype=int)
        live = np.full(self.size, self.n + self.m)  # trash position
        live[: self.n] = np.arange(self.n)
        live[base : base + self.m] = self.n + np.arange(self.m)
        self.live = live
        marker_part = np.array(mech.markers.part, dtype=int)
        self.marker_part = np.where(marker_part == GROUND, n_parts, marker_part)
        centre = np.zeros((n_parts + 1, 3))
        given = np.asarray(mech.reference_points, dtype=float).reshape(-1, 3)[:n_parts]
        centre[: len(given)] = given  # a mechanism still being assembled may have none yet
        self.centre = centre
        self.angular = np.zeros(n_rows, dtype=bool)
        for kind, _, offsets in row_blocks(mech.joints):
            for row in ANGULAR_ROWS[kind]:
                self.angular[offsets + row] = True
        self.angular_live = self.angular[list(mech.independent_rows)]

        def coords(i, j):
            return self.coords(i, j)

        b = mech.bushings
        self.bushings = (
            Group("bushing", np.arange(len(b.names)), coords(b.i_marker, b.j_marker))
            if b.names else None
        )
        self.springs = self._split(mech.springs, mech.springs.tabulated)
        self.stops = self._split(mech.stops, mech.stops.kind)
        lp = mech.load_points
        frame = np.asarray(lp.frame, dtype=int)
        marker = np.asarray(lp.marker, dtype=int)
        # One group: a load in global components uses the ground (its zero coordinates, identity
        # axes) as its frame.
        if marker.size:
            load_coords = coords(marker, np.where(frame < 0, marker, frame))
            load_coords[frame < 0, 6:] = self.ground + np.arange(6)
            self.loads = Group("load", np.arange(marker.size), load_coords)
        else:
            self.loads = None
        # All joints in one group: rows padded to the longest kind present, each row a
        # selection (one-hot) of the candidate quantities; padding rows select zero and land in
        # the trash (row n_rows, the dummy multiplier slot).
        jt = mech.joints
        if jt.names:
            width = max(JOINT_ROWS[k] for k in jt.kind)
            offsets = np.cumsum([0] + [JOINT_ROWS[k] for k in jt.kind])[:-1]
            rows = np.full((len(jt.names), width), n_rows)
            select = np.zeros((len(jt.names), width, N_CANDIDATES))
            for e, kind in enumerate(jt.kind):
                cand = JOINT_CANDIDATES[kind]
                rows[e, : len(cand)] = offsets[e] + np.arange(len(cand))
                select[e, np.arange(width), (*cand, *[N_CANDIDATES - 1] * (width - len(cand)))] = 1
            row_slot = np.r_[self.row_slot, dummy]
            self.joints = Group("joint", np.arange(len(jt.names)),
                                coords(jt.i_marker, jt.j_marker), rows, row_slot[rows])
            self.joints.select = select
        else:
            self.joints = None
        dm = np.asarray(mech.drivers.marker, dtype=int)
        if dm.size:
            rows = mech.joints.n_rows + np.arange(dm.size)[:, None]
            self.drivers = Group("driver", np.arange(dm.size), coords(dm, dm)[:, :6], rows,
                                 self.row_slot[rows])
        else:
            self.drivers = None

    def _split(self, elements, flags):
        groups = []
        for flag in sorted(set(flags)):
            sel = np.flatnonzero([f == flag for f in flags])
            i = np.asarray(elements.i_marker)[sel]
            j = np.asarray(elements.j_marker)[sel]
            groups.append(Group(flag, sel, self.coords(i, j)))
        return groups

    def coords(self, markers_i, markers_j) -> np.ndarray:
        """(E, 12) coordinate slots of the two parts of each element (ground: its zero slot)."""
        a = self.marker_part[np.asarray(markers_i, dtype=int)]
        b = self.marker_part[np.asarray(markers_j, dtype=int)]
        six = np.arange(6)
        return np.concatenate([6 * a[:, None] + six, 6 * b[:, None] + six], axis=1)

    def __hash__(self):
        return hash(self.key)

    def __repr__(self):
        # Derived from the mechanism's static fields: its sizes say enough (and print the same
        # in every process, unlike the default's address).
        return f"Topology(n={self.n}, m={self.m})"

    def __eq__(self, other):
        return isinstance(other, Topology) and self.key == other.key
