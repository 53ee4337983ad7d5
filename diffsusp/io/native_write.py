"""Writing the native model file: `model_to_toml` (a tomlkit document) and `write_model_toml`
(which keeps the comments of the file it saves over). Part of `diffsusp.io.native` (the format
is documented there).
"""

import math
import os

import numpy as np

from ..errors import ModelError
from ..model import GROUND, Mechanism, frame_from_axes
from ..model.mechanism import BUSHING_AXES
from .native import (
    BUSHING_FIELDS,
    FORMAT_VERSION,
    LOAD_COMPONENTS,
)
from .native_values import (
    ANG,
    FORCE,
    LEN,
    LIBRARY_UNITS,
    NONE,
    TORQUE,
    UNIT_TABLES,
)
from .tables import Table, split_header


def _write_corners(doc, mech, put, factor):
    import tomlkit

    corners = tomlkit.aot()
    for c in mech.corners:
        t = tomlkit.table()
        if c.prefix:
            t.add("prefix", c.prefix)
        t.add("wheel_centre", c.wheel_centre)
        t.add("contact_point", c.contact_point)
        t.add("wheel_centre_load", False if c.wheel_centre_load is None else c.wheel_centre_load)
        if c.kingpin is not None:
            refs = tomlkit.array()
            for ref in c.kingpin:
                if isinstance(ref, str):
                    refs.append(ref)
                else:
                    it = tomlkit.inline_table()
                    it.add("part", ref[0])
                    it.add("offset", _floats(ref[1], factor(LEN)))
                    refs.append(it)
            t.add("kingpin", refs)
            t["kingpin"].comment("steering axis [upper, lower]: markers or {part, offset = "
                                 "[forward, outboard, up] from the wheel centre}")
        t.add("side", c.side)
        t.add("frame", c.frame)
        put(t, "loaded_radius", c.loaded_radius, LEN, vector=False)
        if c.design_load is not None:
            put(t, "design_load", c.design_load, FORCE, vector=False)
        corners.append(t)
    doc.add("corner", corners)



def _unit_text(dims, units: dict[str, str]) -> str:
    num, den = [], []
    for key, e in zip(("length", "force", "angle"), dims, strict=True):
        if e == 0:
            continue
        sym = units[key] + (f"^{abs(e)}" if abs(e) > 1 else "")
        (num if e > 0 else den).append(sym)
    num.sort(key=lambda s: s[0] not in "NkdlM")  # force first: N·mm
    text = "·".join(num) or "1"
    return text + ("/" + "·".join(den) if den else "")


def _floats(values, factor: float = 1.0) -> list:
    arr = np.asarray(values, dtype=float).ravel()
    if factor != 1.0:
        arr = arr / factor
    return [float(v) for v in arr]


def _is_zero(values) -> bool:
    arr = np.asarray(values, dtype=float)
    return bool(np.all(arr == 0) and not np.any(np.signbit(arr)))


def model_to_toml(mech: Mechanism, *, load_tables: dict | None = None,
                  units: dict | None = None, source: str | None = None):
    """A native model file for `mech`, as a tomlkit document (`tomlkit.dumps` gives the text).

    **Arguments:** `load_tables`: name → `Table` (or mapping column → values, library units)
    written as `[load_tables.<name>]`; `units`: the file's units (default mm, N, rad: exact);
    `source`: a line for the header comment (where the model comes from).
    """
    import tomlkit

    units = dict(LIBRARY_UNITS, **(units or {}))
    for key, value in units.items():
        if key not in UNIT_TABLES or value not in UNIT_TABLES[key]:
            raise ValueError(f"units: unknown {key} unit {value!r}.")
    fac = {k: UNIT_TABLES[k][v] for k, v in units.items()}

    def factor(dims):
        f = 1.0
        for key, e in zip(("length", "force", "angle"), dims, strict=True):
            if e:
                f *= fac[key] ** e
        return f

    def put(table, key, values, dims, *, vector=True, comment=True):
        data = _floats(values, factor(dims))
        table.add(key, data if vector else data[0])
        if comment and dims != NONE:
            table[key].comment(_unit_text(dims, units))

    doc = tomlkit.document()
    doc.add(tomlkit.comment(f"{mech.name}: diffsusp model file (format {FORMAT_VERSION})."))
    if source:
        doc.add(tomlkit.comment(source))
    doc.add(tomlkit.comment("Positions are global at the design position (q = 0), in [units]; "
                            "see diffsusp.io.native for the format."))
    doc.add("diffsusp", FORMAT_VERSION)
    doc.add("name", mech.name)
    doc.add("parts", list(mech.parts))
    doc["parts"].comment("moving parts; 'ground' always exists")
    ut = tomlkit.table()
    for key in ("length", "force", "angle"):
        ut.add(key, units[key])
    doc.add("units", ut)

    names = mech.markers.names
    part_name = ["ground" if p == GROUND else mech.parts[p] for p in mech.markers.part]
    pos = np.asarray(mech.markers.position)
    rot = np.asarray(mech.markers.orientation)
    markers = tomlkit.table(is_super_table=True)
    for k, name in enumerate(names):
        m = tomlkit.table()
        m.add("part", part_name[k])
        put(m, "position", pos[k], LEN)
        _write_orientation(m, rot[k])
        markers.add(name, m)
    doc.add("markers", markers)

    if mech.joints.names:
        joints = tomlkit.table(is_super_table=True)
        for e, name in enumerate(mech.joints.names):
            j = tomlkit.table()
            j.add("kind", mech.joints.kind[e])
            j.add("i", names[mech.joints.i_marker[e]])
            j.add("j", names[mech.joints.j_marker[e]])
            joints.add(name, j)
        doc.add("joints", joints)

    bu = mech.bushings

    def bushing(t, e):
        for field, dims in BUSHING_FIELDS.items():
            value = np.asarray(getattr(bu, field))[e]
            if field in ("k_trans", "k_rot") or not _is_zero(value):
                put(t, field, value, dims)
        if any(bu.spline_axes[e]):
            splines = tomlkit.table(is_super_table=True)
            sx, sy = np.asarray(bu.spline_x)[e], np.asarray(bu.spline_y)[e]
            for a, axis in enumerate(BUSHING_AXES):
                if bu.spline_axes[e][a]:
                    rot_axis = axis.startswith("r")
                    st = tomlkit.table()
                    put(st, "x", sx[a], ANG if rot_axis else LEN)
                    put(st, "y", sy[a], TORQUE if rot_axis else FORCE)
                    splines.add(axis, st)
            t.add("splines", splines)

    _add_elements(doc, "bushings", bu, names, bushing)

    sp = mech.springs
    k, free = np.asarray(sp.k), np.asarray(sp.free_length)

    def spring(t, e):
        if not sp.tabulated[e] or not _is_zero(k[e]):
            put(t, "k", k[e], (-1, 1, 0), vector=False)
        if not sp.tabulated[e] or not _is_zero(free[e]):
            put(t, "free_length", free[e], LEN, vector=False)
        if sp.tabulated[e]:
            tt = tomlkit.table()
            put(tt, "x", np.asarray(sp.table_x)[e], LEN)
            put(tt, "y", np.asarray(sp.table_y)[e], FORCE)
            t.add("table", tt)

    _add_elements(doc, "springs", sp, names, spring)

    st = mech.stops

    def stop(t, e):
        t.add("kind", st.kind[e])
        put(t, "length", np.asarray(st.length)[e], LEN, vector=False)
        put(t, "k", np.asarray(st.k)[e], (-1, 1, 0), vector=False)
        cubic = np.asarray(st.cubic)[e]
        if not _is_zero(cubic):
            put(t, "cubic", cubic, (-3, 1, 0), vector=False)

    _add_elements(doc, "stops", st, names, stop)

    dr = mech.drivers

    def driver(t, e):
        t.add("direction", _floats(np.asarray(dr.direction)[e]))
        t["direction"].comment("global unit vector; the value (travel) is in length units")

    _add_elements(doc, "drivers", dr, names, driver, markers=("marker",))

    lp = mech.load_points

    def load_point(t, e):
        if lp.frame[e] != GROUND:
            t.add("frame", names[lp.frame[e]])

    _add_elements(doc, "load_points", lp, names, load_point, markers=("marker",))

    if mech.corners:
        _write_corners(doc, mech, put, factor)

    if load_tables:
        tables = tomlkit.table(is_super_table=True)
        for name, table in load_tables.items():
            tables.add(name, _write_load_table(table, units))
        doc.add("load_tables", tables)
    return doc


def _add_elements(doc, section: str, elements, names, fill,
                  markers=("i_marker", "j_marker")) -> None:
    """`[<section>.<name>]` for each element of a stack (bushings, springs, stops, drivers,
    load points): its markers by name (field `i_marker` is written as `i`, `marker` as
    `marker`), then what `fill(table, index)` adds; nothing for no element."""
    import tomlkit

    if not elements.names:
        return
    out = tomlkit.table(is_super_table=True)
    for e, name in enumerate(elements.names):
        t = tomlkit.table()
        for field in markers:
            t.add(field.removesuffix("_marker"), names[getattr(elements, field)[e]])
        fill(t, e)
        out.add(name, t)
    doc.add(section, out)


def _write_orientation(m, rot: np.ndarray):
    rot = np.ascontiguousarray(rot, dtype=float)
    if rot.tobytes() == np.eye(3).tobytes():  # bitwise: -0.0 must be written out
        return
    z = rot[:, 2]
    try:
        if np.ascontiguousarray(frame_from_axes(z)).tobytes() == rot.tobytes():
            m.add("z", _floats(z))
            return
    except ModelError:
        pass
    import tomlkit

    axes = tomlkit.array()
    for c in range(3):
        axes.append(_floats(rot[:, c]))
    axes.multiline(True)
    m.add(tomlkit.comment("axes: the x, y, z axes in global components"))
    m.add("axes", axes)


def _write_load_table(table, units: dict[str, str]):
    """Columns keep their own units; a column without one is in library units, which is
    written out unless the file itself is in library units."""
    import tomlkit

    if isinstance(table, Table):
        columns, col_units = table.columns, table.units
    else:
        columns, col_units = dict(table), {}
    names = list(columns)
    arrays = [np.asarray(columns[n], dtype=float).ravel() for n in names]
    if len({a.shape for a in arrays}) > 1:
        raise ValueError("a load table's columns must all have the same length.")
    headers = []
    for n in names:
        unit = col_units.get(n)
        if unit is None and n != "case" and units != LIBRARY_UNITS:
            comp = n.rpartition(".")[2]
            unit = {"f": "N", "m": "N·mm"}.get(comp[:1], "mm") if comp in LOAD_COMPONENTS \
                else "mm"
        headers.append(f"{n} [{unit}]" if unit else n)
    t = tomlkit.table()
    t.add("columns", headers)
    rows = tomlkit.array()
    for r in range(len(arrays[0]) if arrays else 0):
        rows.append([float(a[r]) for a in arrays])
    rows.multiline(True)
    t.add("rows", rows)
    return t


def write_model_toml(mech: Mechanism, path, *, load_tables: dict | None = None,
                     units: dict | None = None, keep_comments: bool = True,
                     source: str | None = None) -> None:
    """Write `mech` as a native model file (see `model_to_toml`).

    With `keep_comments` and an existing native file at `path`, the new content is merged into
    it: comments on keys and sections that still exist are kept, and its `[load_tables]` are
    kept when `load_tables` is None.
    """
    import tomlkit

    doc = model_to_toml(mech, load_tables=load_tables, units=units, source=source)
    if keep_comments and os.path.exists(path):
        try:
            with open(path, encoding="utf-8") as f:
                old = tomlkit.parse(f.read())
        except Exception:  # not a readable TOML file: overwrite it
            old = None
        if old is not None and isinstance(old.get("units"), dict):
            if load_tables is None and isinstance(old.get("load_tables"), dict):
                doc.add("load_tables", _with_units(old["load_tables"], old["units"]))
            doc = _merge_document(old, doc)
    text = tomlkit.dumps(doc)
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)


def _with_units(tables, old_units):
    """Load tables kept from a file being overwritten: columns without a unit were in that
    file's units, which the new file may not share, so write them out."""
    length, force = old_units.get("length", "mm"), old_units.get("force", "N")
    for table in tables.values():
        columns = table.get("columns") if isinstance(table, dict) else None
        if not isinstance(columns, list):
            continue
        for c, header in enumerate(list(columns)):
            if not isinstance(header, str):
                continue
            name, unit = split_header(header)
            if unit is not None or name == "case":
                continue
            comp = name.rpartition(".")[2]
            unit = (force if comp.startswith("f") else f"{force}·{length}") \
                if comp in LOAD_COMPONENTS else length
            columns[c] = f"{name} [{unit}]"
    return tables


def _same(a, b) -> bool:
    """Equal values, telling -0.0 from 0.0 (an int and the equal float are the same)."""
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    numbers = (int, float)
    if isinstance(a, numbers) and isinstance(b, numbers) and not isinstance(a, bool) \
            and not isinstance(b, bool):
        try:
            x, y = float(a), float(b)
        except OverflowError:
            return False
        return x == y and math.copysign(1.0, x) == math.copysign(1.0, y)
    return type(a) is type(b) and a == b


def _merge_document(old, new):
    """`new`'s content in `old`'s layout: keys and tables that exist in both keep `old`'s
    comments; order follows `new` (marker order matters)."""
    import tomlkit
    from tomlkit.items import AoT, Table

    def merge(old_t, new_t):
        for key in list(old_t.keys()):
            if key not in new_t:
                del old_t[key]
        order = list(new_t.keys())
        for key in order:
            new_item = new_t.item(key) if hasattr(new_t, "item") else new_t[key]
            if key in old_t:
                old_item = old_t.item(key)
                if isinstance(old_item, Table) and isinstance(new_item, Table):
                    merge(old_item, new_item)
                    continue
                if not isinstance(old_item, Table | AoT) and not isinstance(new_item, Table):
                    if _same(old_item.unwrap(), new_item.unwrap()):
                        continue  # unchanged: keep its layout and the comments inside it
                    if old_item.trivia.comment:  # a human's comment beats the generated one
                        new_item.trivia.comment = old_item.trivia.comment
                        new_item.trivia.comment_ws = old_item.trivia.comment_ws
                old_t[key] = new_item
            else:
                old_t[key] = new_item
        if list(old_t.keys()) != order:
            # Reinsert in the new order (sections are tables of named elements).
            items = [(k, old_t.item(k)) for k in order]
            for k in order:
                del old_t[k]
            for k, item in items:
                old_t[k] = item
        return old_t

    merged = merge(old, new)
    # Sanity: the merged text must read back to the same content.
    if tomlkit.parse(tomlkit.dumps(merged)).unwrap() != new.unwrap():
        return new
    return merged
