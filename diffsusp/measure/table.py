"""Measurement tables ↔ `Measurements`: `read_measurements` turns a landmark or pose table into
poses (registered from the landmarks, spec geometry §3.3–3.6) and loads; `write_measurements`
writes them back. The file format (columns, units, checks) is `diffsusp.io.measurements`.
"""

import jax.numpy as jnp
import numpy as np

from ..errors import InputError, ModelFileError
from ..geometry import matrix_to_reuler, reuler_to_matrix
from ..io.measurements import (
    ANGLE_COLUMNS,
    ANGLE_LIMIT,
    LANDMARK_COLUMNS,
    LENGTH_LIMIT,
    POSE_COLUMNS,
    MeasurementRows,
    read_measurement_rows,
    write_measurement_rows,
)
from ..model.mechanism import Mechanism
from .landmarks import LandmarkLayout, check_layout
from .measurements import Measurements, from_landmarks, from_poses


def read_measurements(path, mech: Mechanism, *, reorder: bool = False,
                      tolerance: float = 0.5) -> Measurements:
    """Read a landmark or pose table (format: `diffsusp.io.measurements`) for model `mech`.

    **Arguments:** `path` (.csv or .parquet); `mech` (load points and drivers of the load
    columns); `reorder`, `tolerance`: match landmarks probed in an unknown order by their
    distance tables (spec geometry §3.5).

    **Returns:** `Measurements` (poses registered from the landmarks, or as given).

    **Raises:** `ModelFileError` (bad file, naming line and column), `InputError` (e.g. a part
    with fewer than three usable landmarks in a case), `FileNotFoundError`.
    """
    raw = read_measurement_rows(path)
    if not raw.rows:
        raise ModelFileError("the table has no rows; give one row per case and landmark.",
                             path=raw.path, line=1 if raw.lines else None)
    if "landmark" in raw.names:
        return _landmark_table(raw, mech, reorder, tolerance)
    raw.require(POSE_COLUMNS)
    return _pose_table(raw, mech)


def _landmark_table(raw: MeasurementRows, mech, reorder, tolerance) -> Measurements:
    raw.require(LANDMARK_COLUMNS)
    labels, order = raw.cases()
    parts = raw.text("part")
    names = raw.text("landmark")
    xyz = np.stack([raw.numbers(c, raw.factor(c, "length"), allow_empty=True,
                                limit=LENGTH_LIMIT, unit="mm") for c in ("x", "y", "z")], axis=1)
    ref = np.stack([raw.numbers(c, raw.factor(c, "length"), limit=LENGTH_LIMIT, unit="mm")
                    for c in ("x0", "y0", "z0")], axis=1)
    weight = raw.numbers("weight", allow_empty=True) if "weight" in raw.names else None
    part_names = list(dict.fromkeys(parts))
    per_part = {p: list(dict.fromkeys(n for q, n in zip(parts, names, strict=True) if q == p))
                for p in part_names}
    k = max(len(v) for v in per_part.values())
    position = np.full((len(part_names), k, 3), np.nan)
    measured = np.full((len(order), len(part_names), k, 3), np.nan)
    weights = np.zeros((len(order), len(part_names), k))
    for p, part in enumerate(part_names):  # a landmark without a row in a case: not measured
        weights[:, p, : len(per_part[part])] = 1.0
    raw.check_parts(mech, parts)
    seen = {}
    part_index = {p: k for k, p in enumerate(part_names)}
    case_index = {c: k for k, c in enumerate(order)}
    landmark_index = {p: {n: k for k, n in enumerate(v)} for p, v in per_part.items()}
    for r in range(len(raw.rows)):
        if not np.all(np.isfinite(ref[r])):
            raise ModelFileError("the design position (x0, y0, z0) of a landmark must be "
                                 "finite.", path=raw.path, line=raw.where(r), field="x0")
        p = part_index[parts[r]]
        a = landmark_index[parts[r]][names[r]]
        c = case_index[labels[r]]
        key = (c, p, a)
        if key in seen:
            raise ModelFileError(
                f"landmark '{names[r]}' of part '{parts[r]}' appears twice in case "
                f"'{labels[r]}' (also on line {raw.where(seen[key])}).", path=raw.path,
                line=raw.where(r), field="landmark")
        seen[key] = r
        if np.all(np.isfinite(position[p, a])):
            if np.max(np.abs(position[p, a] - ref[r])) > 1e-9 * (1 + np.abs(ref[r]).max()):
                raise ModelFileError(
                    f"landmark '{names[r]}' of part '{parts[r]}' has design position "
                    f"{ref[r].tolist()} here and {position[p, a].tolist()} on an earlier row; "
                    "it must be the same on every row.", path=raw.path, line=raw.where(r),
                    field="x0")
        position[p, a] = ref[r]
        measured[c, p, a] = xyz[r]
        weights[c, p, a] = 1.0 if weight is None or not np.isfinite(weight[r]) else weight[r]
    position = np.nan_to_num(position)
    layout = LandmarkLayout(position=jnp.asarray(position), parts=tuple(part_names),
                            names=tuple(tuple(per_part[p]) for p in part_names))
    check_layout(layout)
    loads = raw.case_loads(mech, labels, order, set(LANDMARK_COLUMNS) | {"weight"})
    return from_landmarks(layout, measured, loads, weights=weights, reorder=reorder,
                          tolerance=tolerance, cases=order)


def _pose_table(raw: MeasurementRows, mech) -> Measurements:
    labels, order = raw.cases()
    parts = raw.text("part")
    xyz = np.stack([raw.numbers(c, raw.factor(c, "length"), limit=LENGTH_LIMIT, unit="mm")
                    for c in ("x", "y", "z")], axis=1)
    angles = np.stack([raw.numbers(c, raw.factor(c, "angle"), limit=ANGLE_LIMIT, unit="rad")
                       for c in ANGLE_COLUMNS], axis=1)
    part_names = list(dict.fromkeys(parts))
    part_index = {p: k for k, p in enumerate(part_names)}
    case_index = {c: k for k, c in enumerate(order)}
    rotation = np.full((len(order), len(part_names), 3, 3), np.nan)
    translation = np.full((len(order), len(part_names), 3), np.nan)
    for r in range(len(raw.rows)):
        for name, v in (("x", xyz[r]), ("psi", angles[r])):
            if not np.all(np.isfinite(v)):
                raise ModelFileError("a pose must be finite.", path=raw.path,
                                     line=raw.where(r), field=name)
        c, p = case_index[labels[r]], part_index[parts[r]]
        if np.isfinite(translation[c, p, 0]):
            raise ModelFileError(f"part '{parts[r]}' appears twice in case '{labels[r]}'.",
                                 path=raw.path, line=raw.where(r), field="part")
        translation[c, p] = xyz[r]
        rotation[c, p] = np.asarray(reuler_to_matrix(jnp.asarray(angles[r])))
    missing = np.argwhere(~np.isfinite(translation[..., 0]))
    if missing.size:
        c, p = missing[0]
        raise InputError(f"{raw.path}: no pose of part '{part_names[p]}' in case "
                         f"'{order[c]}'; every case needs the pose of every part.")
    raw.check_parts(mech, parts)
    loads = raw.case_loads(mech, labels, order, set(POSE_COLUMNS))
    return from_poses(tuple(part_names), rotation, translation, loads, cases=order)


def _load_columns(mech: Mechanism, meas: Measurements) -> dict[str, np.ndarray]:
    out = {}
    force, moment = np.asarray(meas.loads.force), np.asarray(meas.loads.moment)
    for i, name in enumerate(mech.load_points.names):
        for a, comp in enumerate("xyz"):
            if np.any(force[:, i, a] != 0):
                out[f"{name}.f{comp}"] = force[:, i, a]
            if np.any(moment[:, i, a] != 0):
                out[f"{name}.m{comp}"] = moment[:, i, a]
    for d, name in enumerate(mech.drivers.names):
        out[name] = np.asarray(meas.loads.driver)[:, d]
    if not out and mech.load_points.names:  # all loads zero: still say so
        out[f"{mech.load_points.names[0]}.fz"] = force[:, 0, 2]
    return out


def write_measurements(meas: Measurements, path, mech: Mechanism) -> None:
    """Write `meas` as a landmark table (if it has landmarks) or a pose table, CSV or Parquet
    (from the suffix), with the loads as `<load point>.fx` … columns of `mech` (N, N·mm)."""
    cases = meas.cases or tuple(str(c + 1) for c in range(meas.n_cases))
    loads = _load_columns(mech, meas)
    rows = []
    if meas.landmarks is not None:
        layout = meas.layout
        ref = np.asarray(layout.position)
        pts = np.asarray(meas.landmarks)
        w = np.asarray(meas.weights)
        header = [*LANDMARK_COLUMNS, "weight"]
        units = ["", "", "", "mm", "mm", "mm", "mm", "mm", "mm", ""]
        for c, case in enumerate(cases):
            for p, part in enumerate(layout.parts):
                for a, name in enumerate(layout.names[p]):
                    rows.append([case, part, name, *pts[c, p, a], *ref[p, a], w[c, p, a]]
                                + [v[c] for v in loads.values()])
    else:
        header = list(POSE_COLUMNS)
        units = ["", "", "mm", "mm", "mm", "deg", "deg", "deg"]
        rot, trans = np.asarray(meas.rotation), np.asarray(meas.translation)
        for c, case in enumerate(cases):
            for p, part in enumerate(meas.parts):
                angles = np.degrees(np.asarray(matrix_to_reuler(jnp.asarray(rot[c, p]))))
                rows.append([case, part, *trans[c, p], *angles]
                            + [v[c] for v in loads.values()])
    for name in loads:
        header.append(name)
        units.append("N·mm" if ".m" in name else ("mm" if name in mech.drivers.names else "N"))
    write_measurement_rows(path, header, units, rows)
