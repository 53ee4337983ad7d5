"""The unknowns of the direct method: which stiffnesses and constants a selection (`params`,
`axisymmetric=`) makes unknown, their values in the model (the prior),
and the quantities derived from them (free lengths, offsets). spec: stiffness §1.10 (the
internal forces are linear in these parameters), §7 R3."""

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np

from ..errors import InputError, ModelError
from ..geometry import DEG
from ..model.mechanism import Mechanism
from .params import Params, selected_entries

# re-exported by `identify.direct`; the rest serves direct, direct_polish
__all__ = ["Parameter", "direct_selection", "with_cubic", "with_offsets"]

AXES = ("tx", "ty", "tz", "rx", "ry", "rz")


STIFFNESS_NAMES = ("Ktx", "Kty", "Ktz", "Krx", "Kry", "Krz")


OFFSET_NAMES = ("Fx0", "Fy0", "Fz0", "Mx0", "My0", "Mz0")


CUBIC_NAMES = ("Stx", "Sty", "Stz", "Srx", "Sry", "Srz")


@dataclasses.dataclass(frozen=True)
class Parameter:
    """One unknown of the linear system (static description).

    `kind`: 'stiffness' (bushing axis, column ∂Q/∂k), 'cubic' (bushing axis: S of the law
    F = −(K·δ + S·δ³), column ∂Q/∂S), 'constant' (bushing axis: K·δ0 + preload), 'spring_k'
    (spring K, with the model's L0 if `spring_c` is not also unknown), 'spring_c' (K·L0);
    `element` the bushing/spring index; `axes` the bushing axes it covers (two for an
    axisymmetric pair); `unit` of the table value; `to_internal` factor from the table unit to
    the model's (N·mm/deg → N·mm/rad, N·mm/deg³ → N·mm/rad³).
    """

    name: str
    kind: str
    element: int
    axes: tuple[int, ...]
    unit: str
    to_internal: float


_FIELDS = {
    "bushings.k_trans": ("bushing", "k", (0, 1, 2)),
    "bushings.k_rot": ("bushing", "k", (3, 4, 5)),
    "bushings.cubic_trans": ("bushing", "cubic", (0, 1, 2)),
    "bushings.cubic_rot": ("bushing", "cubic", (3, 4, 5)),
    "bushings.offset_trans": ("bushing", "offset", (0, 1, 2)),
    "bushings.offset_rot": ("bushing", "offset", (3, 4, 5)),
    "springs.k": ("spring", "k", ()),
    "springs.free_length": ("spring", "free_length", ()),
}


def default_where(m: Mechanism):
    return (m.bushings.k_trans, m.bushings.k_rot, m.springs.k, m.springs.free_length)


def selected_fields(mech: Mechanism, where) -> dict[str, np.ndarray]:
    """{field: flat indices of the selected entries} of a `Params` or a `where` function."""
    selected = {}
    for path, idx in selected_entries(mech, where).items():
        key = ".".join(path)
        if key not in _FIELDS:
            raise InputError(
                "where= selected something the direct method cannot identify: it identifies "
                "the parameters the internal forces are linear in, entries of "
                f"{', '.join('m.' + p for p in _FIELDS)}. Choose elements by their names "
                "or entries with a Params; for other parameters (hardpoints, nonlinear laws) "
                "use a least-squares fit through the equilibrium."
            )
        if idx.size:
            selected[key] = idx
    return selected


def free_axes(mech: Mechanism) -> list[tuple[int, int]]:
    """(bushing, axis) pairs whose stiffness is 0 in the model: free directions (e.g. a Chrono
    bushing's torsion about its pivot axis), which the default selection leaves out."""
    k = np.concatenate([np.asarray(mech.bushings.k_trans), np.asarray(mech.bushings.k_rot)],
                       axis=1).reshape(-1, 6)
    return [(int(e), int(a)) for e, a in np.argwhere(k == 0)]


def parameters(mech: Mechanism, fields: Mapping[str, np.ndarray], elements, axisymmetric,
                offsets_alone_ok=True, free=()) -> tuple[Parameter, ...]:
    b, s = mech.bushings, mech.springs
    names = set(b.names) | set(s.names)
    if elements is None:
        elements = tuple(b.names) + tuple(s.names)
    elements = tuple(elements)
    unknown = [e for e in elements if e not in names]
    if unknown:
        raise InputError(
            f"params names {', '.join(map(repr, unknown))}, which model '{mech.name}' does "
            f"not have; its bushings: {', '.join(b.names) or 'none'}; springs: "
            f"{', '.join(s.names) or 'none'}."
        )
    axisym = tuple(axisymmetric)
    bad = [e for e in axisym if e not in b.names]
    if bad:
        raise InputError(f"axisymmetric= names {', '.join(map(repr, bad))}, which are not "
                         f"bushings of the model ({', '.join(b.names) or 'none'}).")
    # Selected axes per bushing: k (stiffness), s (cubic term), c (offset), (bushings, 6).
    k_sel = np.zeros((len(b.names), 6), bool)
    s_sel = np.zeros((len(b.names), 6), bool)
    c_sel = np.zeros((len(b.names), 6), bool)
    sel_of = {"k": k_sel, "cubic": s_sel, "offset": c_sel}
    spring_sel = {"k": np.zeros(len(s.names), bool), "free_length": np.zeros(len(s.names), bool)}
    for path, idx in fields.items():
        group, kind, axes = _FIELDS[path]
        if group == "bushing":
            sel_of[kind][idx // 3, np.asarray(axes)[idx % 3]] = True
        else:
            spring_sel[kind][idx] = True
    spline = np.asarray(b.spline_axes, dtype=bool).reshape(len(b.names), 6)
    cubic = np.concatenate([np.asarray(b.cubic_trans), np.asarray(b.cubic_rot)], axis=1) \
        if b.names else np.zeros((0, 6))
    params = []
    for e, name in enumerate(b.names):
        if name not in elements:
            continue
        sym = name in axisym
        if sym:  # an axisymmetric pair is one unknown: selected if either axis is
            for sel in (k_sel, s_sel, c_sel):
                for x in (0, 3):
                    sel[e, x:x + 2] = sel[e, x:x + 2].any()
        k_axes, c_axes = set(np.flatnonzero(k_sel[e])), set(np.flatnonzero(c_sel[e]))
        s_axes = set(np.flatnonzero(s_sel[e]))
        k_axes -= {a for f, a in free if f == e and not (sym and a in (0, 1, 3, 4))}
        for a in sorted(k_axes | s_axes | c_axes):
            if spline[e, a]:
                raise ModelError(
                    f"bushing '{name}' uses a spline law on axis {AXES[a]}; the direct method "
                    "identifies linear stiffness. Leave it out (params: the other elements) or "
                    "replace the spline by its slope."
                )
        for a in sorted(c_axes):
            if cubic[e, a] != 0 or a in s_axes:
                raise ModelError(
                    f"bushing '{name}' has a cubic term on axis {AXES[a]}, which makes its "
                    "offset enter nonlinearly; identify its offsets with a linear law only."
                )
        for kind, axes_of_kind, names_of_kind in (("stiffness", k_axes, STIFFNESS_NAMES),
                                                  ("cubic", s_axes, CUBIC_NAMES)):
            power = 1 if kind == "stiffness" else 3
            for a in sorted(axes_of_kind):
                if sym and a in (1, 4):
                    continue
                rot = a >= 3
                if sym and a in (0, 3):
                    label = names_of_kind[a][:2] + "r"  # Ktr, Krr, Str, Srr: the radial pair
                    axes = (a, a + 1)
                else:
                    label, axes = names_of_kind[a], (a,)
                unit = ("N·mm/deg" if rot else "N/mm") + ("³" if power == 3 else "")
                params.append(Parameter(f"{name}.{label}", kind, e, axes, unit,
                                        DEG ** -power if rot else 1.0))
        for a in sorted(c_axes):
            params.append(Parameter(f"{name}.{OFFSET_NAMES[a]}", "constant", e, (a,),
                                    "N·mm" if a >= 3 else "N", 1.0))
    for e, name in enumerate(s.names):
        spring_k, spring_c = spring_sel["k"][e], spring_sel["free_length"][e]
        if name not in elements or not (spring_k or spring_c):
            continue
        if s.tabulated[e]:
            raise ModelError(f"spring '{name}' has a tabulated law; the direct method "
                             "identifies linear springs (K, L0). Leave it out (params: the "
                             "other elements).")
        if spring_k:
            params.append(Parameter(f"{name}.K", "spring_k", e, (), "N/mm", 1.0))
        if spring_c:
            params.append(Parameter(f"{name}.KL0", "spring_c", e, (), "N", 1.0))
    if not params:
        raise InputError("nothing to identify: the selection (params) picks no "
                         "stiffness of this model.")
    return tuple(params)


def bushing_arrays(mech: Mechanism, cubic: bool = False) -> tuple[np.ndarray, ...]:
    """The bushings' stiffnesses, offsets and preloads (and with `cubic`, their cubic terms)
    as (bushings, 6) arrays, translations then rotations (model units)."""
    b = mech.bushings
    pairs = [(b.k_trans, b.k_rot), (b.offset_trans, b.offset_rot),
             (b.preload_force, b.preload_torque)] + ([(b.cubic_trans, b.cubic_rot)] if cubic
                                                     else [])
    if not b.names:
        return tuple(np.zeros((0, 6)) for _ in pairs)
    return tuple(np.concatenate([np.asarray(t), np.asarray(r)], axis=1) for t, r in pairs)


def prior(mech: Mechanism, params: tuple[Parameter, ...]) -> np.ndarray:
    s = mech.springs
    k, off, pre, cubic = bushing_arrays(mech, cubic=True)
    out = []
    for p in params:
        if p.kind in ("stiffness", "cubic"):
            value = (k if p.kind == "stiffness" else cubic)[p.element, list(p.axes)]
            out.append(np.mean(value) / p.to_internal)
        elif p.kind == "constant":
            a = p.axes[0]
            out.append(k[p.element, a] * off[p.element, a] + pre[p.element, a])
        elif p.kind == "spring_k":
            out.append(float(s.k[p.element]))
        else:
            out.append(float(s.k[p.element] * s.free_length[p.element]))
    return np.asarray(out, dtype=float)


def selection_of(params) -> tuple[object, tuple[str, ...] | None]:
    """(entries, elements) of the one selector `params`: a `Params` or a `where` function
    selects entries (of every element), a sequence of names selects elements (bushings and
    springs, their default entries: `default_where`); None: the default entries of every
    element."""
    if params is None or isinstance(params, Params) or callable(params):
        return params, None
    names = (params,) if isinstance(params, str) else tuple(params)
    if not all(isinstance(n, str) for n in names):
        raise InputError("params must be a Params, a `where` function (lambda m: "
                         "m.bushings.k_trans, ...) or a sequence of element names.")
    return None, names


def with_offsets(m: Mechanism):
    """The default entries and the bushings' offsets (identified as the constant force
    K·δ0): stiffnesses, offsets, the springs' K and free length."""
    return (m.bushings.k_trans, m.bushings.k_rot, m.bushings.offset_trans,
            m.bushings.offset_rot, m.springs.k, m.springs.free_length)


def with_cubic(m: Mechanism):
    """The default entries and the bushings' cubic terms S of F = −(K·δ + S·δ³):
    stiffnesses, cubic terms, the springs' K and free length."""
    return (m.bushings.k_trans, m.bushings.k_rot, m.bushings.cubic_trans, m.bushings.cubic_rot,
            m.springs.k, m.springs.free_length)


def direct_selection(mech: Mechanism, elements: Sequence[str] | None = None,
                     offsets: bool = False, cubic: bool = False):
    """The one selector of `direct` for "these elements", "with their offsets" and "with
    their cubic terms": None (the default), the element names, `with_offsets` or
    `with_cubic`, or, for both, a `Params` of those entries that belong to the named bushings
    and springs."""
    if offsets and cubic:
        raise ModelError("offsets and cubic terms cannot both be unknowns of the direct "
                         "method: an offset under a cubic law enters the forces nonlinearly.")
    where = with_offsets if offsets else with_cubic if cubic else None
    if where is None:
        return tuple(elements) if elements else None
    if not elements:
        return where
    known = set(mech.bushings.names) | set(mech.springs.names)
    unknown = [e for e in elements if e not in known]
    if unknown:
        raise InputError(f"params names {', '.join(map(repr, unknown))}, which model "
                         f"'{mech.name}' does not have; its bushings: "
                         f"{', '.join(mech.bushings.names) or 'none'}; springs: "
                         f"{', '.join(mech.springs.names) or 'none'}.")
    masks = []
    for path in selected_entries(mech, where):
        group = getattr(mech, path[0])
        shape = np.shape(getattr(group, path[1]))
        rows = np.isin(np.asarray(group.names, dtype=object), list(elements))
        masks.append(np.broadcast_to(rows.reshape((-1,) + (1,) * (len(shape) - 1)), shape))
    return Params.leaves(mech, where, tuple(masks), positive=False)


def derived(params, values, cov, mech, identified_mask):
    """Spring free lengths and bushing offsets from (K, K·L0) and (K, K·δ0 + P), with σ by
    first-order propagation of the covariance."""
    out = {}
    index = {p.name: i for i, p in enumerate(params)}
    b, s = mech.bushings, mech.springs
    for i, p in enumerate(params):
        if p.kind == "spring_c":
            name = s.names[p.element]
            j = index.get(f"{name}.K")
            c = values[i]
            if j is None:
                k, var = float(s.k[p.element]), cov[i, i] / float(s.k[p.element]) ** 2
                value = c / k
            else:
                k = values[j]
                value = c / k if k else np.nan
                grad = np.zeros(len(values))
                grad[i], grad[j] = 1.0 / k, -c / k**2
                var = grad @ cov @ grad if k else np.nan
            ok = identified_mask[i] and (j is None or identified_mask[j])
            out[f"{name}.L0"] = (value if ok else np.nan, float(np.sqrt(max(var, 0.0)))
                                 if ok else np.nan, "mm")
        elif p.kind == "constant":
            name = b.names[p.element]
            a = p.axes[0]
            k_name = f"{name}.{STIFFNESS_NAMES[a]}"
            j = index.get(k_name)
            pre = np.concatenate([np.asarray(b.preload_force), np.asarray(b.preload_torque)],
                                 axis=1)[p.element, a]
            unit_k = 1.0 / DEG if a >= 3 else 1.0  # table K → model K
            k_model = np.concatenate([np.asarray(b.k_trans), np.asarray(b.k_rot)],
                                     axis=1)[p.element, a] / unit_k
            k = values[j] if j is not None else k_model
            c = values[i] - pre
            value = c / k if k else np.nan
            grad = np.zeros(len(values))
            grad[i] = 1.0 / k if k else np.nan
            if j is not None:
                grad[j] = -c / k**2 if k else np.nan
            var = grad @ cov @ grad
            ok = identified_mask[i] and (j is None or identified_mask[j])
            unit = "deg" if a >= 3 else "mm"
            out[f"{name}.d{AXES[a][1]}0" if a < 3 else f"{name}.a{AXES[a][1]}0"] = (
                value if ok else np.nan, float(np.sqrt(max(var, 0.0))) if ok else np.nan, unit)
    return out
