"""Geometric identification's data: the joint description (`GeometricJoint`), the located
joints (`JointEstimate`, `GeometricReport` with its table, JSON and figure), the model's element
table, and the joint-list and joint-table files (spec geometry §4.6, §4.9).

The solvers are in `diffsusp.identify.geometric_locate`, the correction in
`diffsusp.identify.geometric_correct`; `diffsusp.identify.geometric` re-exports every public
name. Units: mm.
"""

import csv
import dataclasses
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import ClassVar

import numpy as np

from ..errors import InputError, ModelFileError
from .report import Consistency, IdentificationReport, sigma_pct

JOINT_KINDS = ("ball", "revolute", "ball_known_slide", "ball_unknown_slide",
               "compliant_bushing")
"""Joint kinds the localisation knows (spec geometry §4.6's joint list)."""

GROUND = "ground"


@dataclasses.dataclass(frozen=True)
class GeometricJoint:
    """One entry of the joint list: which parts, which kind, and the kind's extra data.

    **Fields:**

    - `name`; `kind`: one of `JOINT_KINDS`; `parts`: (S1, S2), the part names as in the
      measurements, `'ground'` for the fixed chassis/frame. S2 moves relative to S1; for
      `'ball_unknown_slide'` S2 is the part carrying the ball (the chassis for the strut top)
      and S1 the part carrying the slide (the hub carrier); for `'compliant_bushing'` S2 is
      the link.
    - `slide`: `'ball_known_slide'`: the slide direction in S1 (e.g. the rack axis (0, 1, 0)).
    - `prior`: `'revolute'`: a point (mm) whose position along the axis is kept (the thesis
      fixes x of each bushing of a pair); with `prior_coordinate` ('x', 'y' or 'z') only that
      coordinate of it is kept, else the point of the axis nearest to `prior` is reported.
      `'ball_unknown_slide'`: the initial estimate (required).
    - `link_ball`: `'compliant_bushing'`: name of the ball joint at the link's other end (a
      `'ball'` joint of the same list, between the link and another part).
    - `elements`: names of the model's joints or bushings this located joint stands for (their
      markers are moved by `apply_locations`).
    """

    name: str
    kind: str
    parts: tuple[str, str]
    slide: tuple[float, float, float] | None = None
    prior: tuple[float, float, float] | None = None
    prior_coordinate: str | None = None
    link_ball: str | None = None
    elements: tuple[str, ...] = ()

    def __post_init__(self):
        if self.kind not in JOINT_KINDS:
            raise InputError(f"joint '{self.name}': unknown kind '{self.kind}'; use one of "
                             f"{', '.join(JOINT_KINDS)}.")
        if len(self.parts) != 2 or self.parts[0] == self.parts[1]:
            raise InputError(f"joint '{self.name}': parts must be two different part names; "
                             f"got {self.parts!r}.")
        if self.kind == "ball_known_slide" and self.slide is None:
            raise InputError(f"joint '{self.name}' (ball_known_slide) needs the slide direction"
                             " slide=(x, y, z), e.g. the rack axis.")
        if self.kind == "ball_unknown_slide" and self.prior is None:
            raise InputError(f"joint '{self.name}' (ball_unknown_slide) needs an initial "
                             "estimate prior=(x, y, z) of the ball centre (mm).")
        if self.kind == "revolute" and self.prior is None:
            raise InputError(
                f"joint '{self.name}' (revolute) needs prior=(x, y, z): motion does not fix "
                "the point along the axis (spec geometry §4.3, CORRECTIONS 17).")
        if self.prior_coordinate not in (None, "x", "y", "z"):
            raise InputError(f"joint '{self.name}': prior_coordinate must be 'x', 'y' or 'z'.")
        if self.kind == "compliant_bushing" and self.link_ball is None:
            raise InputError(f"joint '{self.name}' (compliant_bushing) needs link_ball, the "
                             "name of the ball joint at the link's other end.")


@dataclasses.dataclass(frozen=True)
class Coordinate:
    """One located coordinate of a joint: a row of the report (one verdict).

    **Fields:** `name` ('x', 'y', 'z' of the centre; 'axis_y'… a component of a revolute's or
    slide's unit axis, the largest component left out: the norm fixes it); `value`; `sigma`
    the reported 1σ (landmark noise, × √(χ²/E) when the joint's equations fit worse than the
    noise explains — × √(3χ²/E) for a revolute beyond `LACK_OF_FIT` —, with the model's
    compliance bias `bias` added in quadrature; NaN: none); `unit` ('mm' or '-');
    `determined` (the data fix it: its joint observable and nothing flags it); `seen` (False:
    the parts never move relative to each other); `reason` why it is not determined;
    `along_axis`: a revolute's coordinate along its axis (kept at the prior's: never
    observable, spec geometry §4.3).
    """

    name: str
    value: float
    sigma: float
    unit: str
    determined: bool
    seen: bool = True
    reason: str = ""
    bias: float = 0.0
    along_axis: bool = False

    def to_dict(self) -> dict:
        def num(v):
            return float(v) if math.isfinite(v) else None

        return dict(name=self.name, value=num(self.value), sigma=num(self.sigma),
                    unit=self.unit, determined=self.determined, seen=self.seen,
                    reason=self.reason, bias=num(self.bias), along_axis=self.along_axis)


@dataclasses.dataclass(frozen=True)
class JointEstimate:
    """Located joint. Coordinates are design (reference) coordinates in the global frame (mm).

    **Fields:** `name`, `kind`, `parts`; `centre` (3,) mm (None when not observable); `axis`
    (3,) unit (revolute: the axis; slides: the slide direction; None otherwise); `sigma` (3,)
    σ of the centre's coordinates (mm) and `sigma_axis` (3,) of the axis' components, at the
    nominal landmark noise; `residual`: root-mean-square of the solver's equations (mm; the
    unknown slide: the trajectory points' distance to their line); `singular_values` of the
    solver's equations (largest first; with σ: of the per-case equations in the unknowns the
    solver determines, for the unknown slide the centre and its line); `observable`; `note`.
    `estimate` keeps the raw centre even when not observable (for diagnostics). `snr`: the
    weakest singular value over its noise level (see `locate_joints`); `chi2`: the residual
    energy over the energy landmark noise alone would leave (≈ 1 for a joint the data fit,
    larger for a bushing taken as a joint). NaN without σ.
    """

    name: str
    kind: str
    parts: tuple[str, str]
    centre: np.ndarray | None
    axis: np.ndarray | None
    sigma: np.ndarray
    sigma_axis: np.ndarray | None
    residual: float
    singular_values: np.ndarray
    observable: bool
    note: str
    estimate: np.ndarray
    snr: float = math.nan
    chi2: float = math.nan
    coordinates: tuple["Coordinate", ...] = ()
    peak: float = math.nan
    covariance: np.ndarray | None = None

    @property
    def determined(self) -> bool:
        """Every coordinate the joint's solver estimates is determined (the revolute's position
        along its axis excepted: never observable)."""
        rows = [c for c in self.coordinates if not c.along_axis]
        return bool(rows) and all(c.determined for c in rows)

    def to_dict(self) -> dict:
        def arr(v):
            return None if v is None else [float(x) for x in np.asarray(v)]

        return dict(name=self.name, kind=self.kind, parts=list(self.parts),
                    centre=arr(self.centre), axis=arr(self.axis), sigma=arr(self.sigma),
                    sigma_axis=arr(self.sigma_axis), residual=float(self.residual),
                    singular_values=arr(self.singular_values), observable=self.observable,
                    note=self.note, snr=float(self.snr), chi2=float(self.chi2),
                    coordinates=[c.to_dict() for c in self.coordinates])


class CoordinateRows:
    """The report base's per-parameter properties of a report whose rows are `Coordinate`s,
    each labelled by its owner (a joint, a marker): `names` '<owner>.<coordinate>', estimates,
    σ, σ %, units, determined (`identifiable`), `seen`, `reasons`; no residual table. The
    report provides `_labelled()` → [(owner, Coordinate)]."""

    def _labelled(self) -> list[tuple[str, Coordinate]]:
        raise NotImplementedError

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(f"{owner}.{c.name}" for owner, c in self._labelled())

    @property
    def estimates(self) -> np.ndarray:
        return np.array([c.value for _, c in self._labelled()], dtype=float)

    @property
    def sigmas(self) -> np.ndarray:
        return np.array([c.sigma for _, c in self._labelled()], dtype=float)

    @property
    def sigma_pct(self) -> np.ndarray:
        return sigma_pct(self.sigmas, self.estimates)

    @property
    def estimate_units(self) -> tuple[str, ...]:
        return tuple(c.unit for _, c in self._labelled())

    @property
    def identifiable(self) -> np.ndarray:
        return np.array([c.determined for _, c in self._labelled()], dtype=bool)

    @property
    def seen(self) -> np.ndarray:
        return np.array([c.seen for _, c in self._labelled()], dtype=bool)

    @property
    def reasons(self) -> tuple[str, ...]:
        return tuple(c.reason for _, c in self._labelled())

    @property
    def residuals(self) -> dict:
        return {}


@dataclasses.dataclass(frozen=True)
class GeometricReport(CoordinateRows, IdentificationReport):
    """Result of `locate_joints`: one `JointEstimate` per joint of the list, in order, the
    landmark noise σ_L used for the σ (mm), and the number of cases.

    On the report base of every identification (`identify.report`): one parameter
    per located coordinate (`'<joint>.x'`, `'<joint>.axis_y'`…, see `Coordinate`) with its
    value, σ and one status — *identified* (determined and the data consistent), *not
    determined* with the reason (a revolute's position along its axis; not observable; a
    compliant joint taken as a ball without the model), *not seen* (the parts never move
    relative to each other). `consistency`: the registration residuals of every part and case
    against σ_L (χ² with 3n − 6 dof per part and case); `warnings`: the parts and cases whose
    own registration residual is beyond noise (swapped or moved landmarks), which make the
    verdict inconsistent. Each joint's own lack of fit is judged joint by joint (σ inflated, or
    the joint flagged). Every writer (`format_table`, `csv_text`, `html_text`, `write`)
    renders these rows; `joint_rows()` keeps the former one row per joint.
    """

    joints: tuple[JointEstimate, ...]
    landmark_sigma: float
    n_cases: int
    notes: tuple[str, ...] = ()
    consistency: Consistency | None = None
    warnings: tuple[str, ...] = ()

    family: ClassVar[str] = "geometry"
    judged_at: ClassVar[str] = ("the estimate (no σ % bar: a coordinate is determined when its "
                                "joint is observable and its σ within the hardpoint tolerance)")
    combinations: ClassVar[tuple] = ()

    def __getitem__(self, name: str) -> JointEstimate:
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(f"no joint named '{name}' (joints: "
                       f"{', '.join(j.name for j in self.joints)}).")

    def _coordinates(self) -> list[tuple[JointEstimate, Coordinate]]:
        return [(j, c) for j in self.joints for c in j.coordinates]

    def _labelled(self) -> list[tuple[str, Coordinate]]:
        return [(j.name, c) for j, c in self._coordinates()]

    @property
    def fit_verdict(self) -> str:
        """The registration's consistency verdict, and the flagged parts and cases."""
        text = ("consistency not checked (poses without landmarks)" if self.consistency is None
                else self.consistency.verdict)
        return "; ".join((text, *self.warnings))

    def joint_identified(self, name: str) -> bool:
        """Every coordinate of joint `name` its solver estimates is identified."""
        ident = dict(zip(self.names, self.is_identified, strict=True))
        joint = self[name]
        rows = [c for c in joint.coordinates if not c.along_axis]
        return bool(rows) and all(ident[f"{name}.{c.name}"] for c in rows)

    def summary(self) -> dict:
        """The report base's summary (one row per coordinate) with the landmark σ, the number
        of cases, the notes and warnings, and the joints in detail."""
        return IdentificationReport.summary(self) | dict(
            landmark_sigma=self.landmark_sigma, n_cases=self.n_cases, notes=list(self.notes),
            warnings=list(self.warnings), joints=[j.to_dict() for j in self.joints])

    def to_json(self, **kwargs) -> str:
        return json.dumps(self.summary(), **({"indent": 2} | kwargs))

    def joint_rows(self) -> list[dict]:
        """One flat row per joint (the joint table, `write_joints`): x, y, z, σx, σy, σz,
        axis, residual, snr, χ²/E, observable, note."""
        out = []
        for j in self.joints:
            c = j.centre if j.centre is not None else np.full(3, np.nan)
            a = j.axis if j.axis is not None else np.full(3, np.nan)
            out.append(dict(joint=j.name, kind=j.kind, part_1=j.parts[0], part_2=j.parts[1],
                            x=c[0], y=c[1], z=c[2], sigma_x=j.sigma[0], sigma_y=j.sigma[1],
                            sigma_z=j.sigma[2], axis_x=a[0], axis_y=a[1], axis_z=a[2],
                            residual=j.residual, snr=j.snr, chi2=j.chi2,
                            observable=j.observable, note=j.note))
        return out

    def plot(self, mech=None, joints: Sequence[GeometricJoint] = (), axes=None):
        """Top (x–y) and side (x–z) views of the located centres (crosses with 2σ bars) and,
        given the model `mech` and the joint list, the model's hardpoints of each joint's
        elements (circles). `axes`: two matplotlib Axes (default: a new figure). Returns the
        matplotlib Figure (made without pyplot: nothing is kept open)."""
        from matplotlib.figure import Figure

        if axes is None:
            fig = Figure(figsize=(11, 5))
            axes = fig.subplots(1, 2)
        else:
            fig = axes[0].figure
        table = {} if mech is None else element_table(mech)
        pos = None if mech is None else np.asarray(mech.markers.position)
        elements = {j.name: j.elements for j in joints}
        views = ((0, 1, "top view (x, y)"), (0, 2, "side view (x, z)"))
        for ax, (a, b, label) in zip(axes, views, strict=True):
            for est in self.joints:
                for element in elements.get(est.name, ()):
                    if element in table:
                        p = pos[table[element][4]]
                        ax.plot(p[a], p[b], "o", mfc="none", color="0.4")
                if est.centre is not None:
                    ax.errorbar(est.centre[a], est.centre[b], xerr=2 * est.sigma[a],
                                yerr=2 * est.sigma[b], fmt="x", color="C3")
                    ax.annotate(est.name, (est.centre[a], est.centre[b]), fontsize=7,
                                xytext=(3, 3), textcoords="offset points")
            ax.set_title(label)
            ax.set_xlabel("xyz"[a] + " (mm)")
            ax.set_ylabel("xyz"[b] + " (mm)")
            ax.set_aspect("equal", adjustable="datalim")
        if table:
            axes[0].plot([], [], "o", mfc="none", color="0.4", label="model")
        axes[0].plot([], [], "x", color="C3", label="located (±2σ)")
        axes[0].legend(fontsize=8)
        fig.tight_layout()
        return fig

    def __str__(self) -> str:
        lines = [f"Joint locations from {self.n_cases} cases (σ at landmark noise "
                 f"{self.landmark_sigma:g} mm):"]
        for j in self.joints:
            head = f"  {j.name:<24} {j.kind:<19}"
            if j.centre is None:
                lines.append(f"{head} not observable from these cases ({j.note})")
                continue
            c, s = j.centre, j.sigma
            text = (f"{head} ({c[0]:9.3f}, {c[1]:9.3f}, {c[2]:9.3f}) mm "
                    f"± ({s[0]:.3f}, {s[1]:.3f}, {s[2]:.3f})")
            if j.axis is not None:
                text += f"  axis ({j.axis[0]:.5f}, {j.axis[1]:.5f}, {j.axis[2]:.5f})"
            lines.append(text + f"  rms {j.residual:.2e}" + (f"  [{j.note}]" if j.note else ""))
        lines += [f"  note: {n}" for n in self.notes]
        lines.append(f"  verdict: {self.fit_verdict}")
        return "\n".join(lines)


# ----------------------------------------------------------------------------- solvers


def element_table(mech):
    """name → (group, kind, I part, J part, I marker, J marker) of every joint and bushing."""
    part_of = mech.markers.part
    out = {}
    for name, kind, i, j in zip(mech.joints.names, mech.joints.kind, mech.joints.i_marker,
                                mech.joints.j_marker, strict=True):
        out[name] = ("joint", kind, part_of[i], part_of[j], i, j)
    for name, i, j in zip(mech.bushings.names, mech.bushings.i_marker, mech.bushings.j_marker,
                          strict=True):
        out[name] = ("bushing", "bushing", part_of[i], part_of[j], i, j)
    return out


FREE_AXIS_RATIO = 1e-3
"""A bushing is free about one of its marker axes when its rotational stiffness there (linear
plus cubic at 0.1 rad) is at most this fraction of the smaller of the other two: the arm then
turns about that axis (a revolute) and the bushing's position along it leaves no trace in the
relative motion (spec geometry §4.3)."""


def free_axis(mech, name: str) -> int | None:
    """The one axis (0, 1, 2 of the bushing's I marker) a bushing is free about, or None (no
    free axis, or two or three: a ball). spec: geometry §4.3, stiffness §1.8."""
    b = mech.bushings
    k = list(b.names).index(name)
    rot = np.abs(np.asarray(b.k_rot)[k]) + np.abs(np.asarray(b.cubic_rot)[k]) * 0.01
    for a in range(3):
        others = np.delete(rot, a)
        if others.min() > 0 and rot[a] <= FREE_AXIS_RATIO * others.min():
            return a
    return None


def model_geometry(mech, joint: GeometricJoint):
    """The model's own location of `joint` as `locate_joints` reports it: `(centre, axis)`, the
    centre the design position of the I marker of its first element, the axis (a revolute: the
    joint's marker z, or a bushing's free axis; an unknown slide: the z of the slide joint's
    marker on S1; else None) — or None when the joint names no element of `mech`. The truth a
    located joint is compared with (the rehearsal), and the reference of the compliance bias."""
    table = element_table(mech)
    if not joint.elements or joint.elements[0] not in table:
        return None
    name = joint.elements[0]
    group, _, _, _, mi, _ = table[name]
    pos = np.asarray(mech.markers.position)
    ori = np.asarray(mech.markers.orientation)
    axis = None
    if joint.kind == "revolute":
        free = free_axis(mech, name) if group == "bushing" else None
        axis = ori[mi][:, 2 if free is None else free]
    elif joint.kind == "ball_unknown_slide":
        s1 = mech.part_index(joint.parts[0]) if joint.parts[0] != GROUND else -1
        for _, kind, pi, pj, ma, mb in table.values():
            if kind in ("translational", "cylindrical") and s1 in (pi, pj):
                axis = ori[ma if pi == s1 else mb][:, 2]
                break
        if axis is None:
            return None
    return pos[mi].copy(), (np.zeros(3) if axis is None else np.asarray(axis, float))


def read_joints(path) -> tuple[GeometricJoint, ...]:
    """The joint list of a JSON file: a list of objects with the `GeometricJoint` fields (name,
    kind, parts, and optionally slide, prior, prior_coordinate, link_ball, elements; spec
    geometry §4.6). Raises `ModelFileError` naming the file (and the line, or the joint) on an
    unreadable file, non-JSON text or an invalid joint."""
    path = Path(path)
    try:
        items = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as e:
        raise ModelFileError(f"cannot read the joint list ({e}).", path=path) from None
    except json.JSONDecodeError as e:
        raise ModelFileError(f"not JSON: {e.msg}.", path=path, line=e.lineno) from None
    if not isinstance(items, list):
        raise ModelFileError("the joint list must be a JSON list of objects with name, kind, "
                             "parts (and slide, prior, prior_coordinate, link_ball, elements).",
                             path=path)
    return tuple(_joint_of(item, k, path) for k, item in enumerate(items))


def _joint_of(item, k: int, path: Path) -> GeometricJoint:
    try:
        item = dict(item)
        for key in ("parts", "slide", "prior", "elements"):
            if item.get(key) is not None:
                item[key] = tuple(item[key])
        return GeometricJoint(**item)
    except (TypeError, ValueError) as e:
        raise ModelFileError(f"joint {k + 1}: {e}", path=path, field="joints") from None


def write_joints(report: GeometricReport, path) -> None:
    """Write the joint table: `.json` → `report.to_json()`; otherwise CSV, one row per joint
    with the columns of `GeometricReport.joint_rows` (an unobservable joint's coordinates empty)."""
    path = Path(path)
    if path.suffix.lower() == ".json":
        path.write_text(report.to_json() + "\n", encoding="utf-8")
        return
    rows = report.joint_rows()
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]) if rows else ["joint"])
        writer.writeheader()
        for row in rows:
            writer.writerow({k: "" if v != v else v for k, v in row.items()})
