"""Which numbers of a mechanism an identification estimates, and in which coordinates.

spec: stiffness §6 item 8 (gradient-based identification: log-scaled stiffnesses, priors,
equivalent solutions), §3 perspective 2 (joint geometric + stiffness identification);
DESIGN.md "Identification"; STYLE.md "Identification: select, partition, solve, combine".

A `Params` is a list of named scalar parameters θ (physical units: N/mm, N·mm/rad, mm...), each
written into one or more entries of the mechanism's array leaves by `apply(mech, θ)`. The
optimiser works in internal coordinates u, one per parameter, chosen from its bounds:

| bounds | θ(u) | typical use |
|---|---|---|
| none | θ = u | positions (mm), offsets, preloads |
| lower only | θ = lower + exp(u) | stiffnesses (lower = 0: log scale) |
| upper only | θ = upper − exp(u) | |
| both | θ = lower + (upper − lower)·sigmoid(u) | a hardpoint kept in a box |

so every u is unconstrained, bounds hold by construction, and for a positive stiffness a step
in u is a relative change (σ of u is the relative standard deviation of θ).
"""

import dataclasses
from collections.abc import Callable, Mapping, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..errors import InputError, index_of
from ..model.mechanism import Mechanism, field_unit

AXES = ("Ktx", "Kty", "Ktz", "Krx", "Kry", "Krz")
"""A bushing's six stiffnesses (translations N/mm, then rotations N·mm/rad), in the J frame."""

_POSITIVE_FIELDS = {("bushings", "k_trans"), ("bushings", "k_rot"), ("springs", "k"),
                    ("stops", "k")}
"""Leaves that are stiffnesses: log-scaled (lower bound 0) unless told otherwise."""


class _Tag:
    """Stands in for an array leaf while a `where` selector runs, to find which leaf it picked."""

    def __init__(self, path: tuple[str, ...], shape: tuple[int, ...]):
        self.path, self.shape = path, shape


def _field_path(keypath) -> tuple[str, ...]:
    names = []
    for key in keypath:
        if not isinstance(key, jax.tree_util.GetAttrKey):
            raise InputError(f"cannot name the leaf at {jax.tree_util.keystr(keypath)}; select "
                             "fields of the Mechanism (e.g. m.bushings.k_trans).")
        names.append(key.name)
    return tuple(names)


def _get(tree, path: tuple[str, ...]):
    for name in path:
        tree = getattr(tree, name)
    return tree


def _entry_names(mech: Mechanism, path: tuple[str, ...], shape: tuple[int, ...]) -> list[str]:
    """One readable name per entry of the leaf at `path` (row-major order)."""
    group, field = (path[0], path[-1]) if len(path) == 2 else (None, ".".join(path))
    size = int(np.prod(shape)) if shape else 1
    if group == "bushings" and field in ("k_trans", "k_rot"):
        axes = AXES[:3] if field == "k_trans" else AXES[3:]
        return [f"{b}.{a}" for b in mech.bushings.names for a in axes]
    owners = {"bushings": mech.bushings.names, "springs": mech.springs.names,
              "stops": mech.stops.names, "markers": mech.markers.names,
              "drivers": mech.drivers.names}.get(group)
    if owners is None or not shape or shape[0] != len(owners):
        return [f"{'.'.join(path)}[{i}]" for i in range(size)]
    rest = shape[1:]
    names = []
    for owner in owners:
        if not rest:
            names.append(f"{owner}.{field}")
        elif field == "position" or rest == (3,):
            label = field if field != "position" else ""
            names += [f"{owner}.{label}{'_' if label else ''}{c}" for c in "xyz"]
        else:
            names += [f"{owner}.{field}[{','.join(map(str, ix))}]" for ix in np.ndindex(*rest)]
    return names


class _Target(eqx.Module):
    """Entries `leaf_index` (flat) of the leaf at `path` take θ[param_index] + offset."""

    offset: Float[Array, " k"]
    path: tuple[str, ...] = eqx.field(static=True)
    leaf_index: tuple[int, ...] = eqx.field(static=True)
    param_index: tuple[int, ...] = eqx.field(static=True)


class Params(eqx.Module):
    """Named parameters of a mechanism to identify, with their start values and bounds.

    Build one with `Params.leaves` (the equinox `where=` idiom), `Params.bushing_stiffness`,
    `Params.bushing_centres`, and combine with `+`.

    **Fields:** `names` (one per parameter, e.g. `'bushing_A.Ktx'`, `'spring.k'`,
    `'bushing_A.x'`), `start` (physical values θ0), `lower`, `upper` (bounds, ±inf when none),
    `given` (per parameter: its start was set by `with_start`; empty: none was).

    **Start values.** A `Params` is a *selection*: built from a mechanism it copies that
    mechanism's values as `start`, but a fit (`least_squares(mech, data, params)`) starts from
    the values of the `mech` it is given (`starting_from`), as its docstring says — building
    the selection on the model and fitting a modified copy (`start = eqx.tree_at(...)`) starts
    from the copy, not silently from the model the selection was built on. Only values set
    explicitly with `with_start` (the CLI's `--start`, the polish's linear estimates) override
    the mechanism's.
    """

    start: Float[Array, " p"]
    lower: Float[Array, " p"]
    upper: Float[Array, " p"]
    targets: tuple[_Target, ...]
    names: tuple[str, ...] = eqx.field(static=True)
    given: tuple[bool, ...] = eqx.field(static=True, default=())

    def __check_init__(self):
        p = len(self.names)
        if len(set(self.names)) != p:
            dup = sorted({n for n in self.names if self.names.count(n) > 1})
            raise InputError(f"parameters {dup} are selected twice; select each number once.")
        for field in ("start", "lower", "upper"):
            if getattr(self, field).shape != (p,):
                raise InputError(f"Params.{field} must have shape ({p},).")

    def __len__(self) -> int:
        return len(self.names)

    # ------------------------------------------------------------------ constructors

    @classmethod
    def leaves(
        cls,
        mech: Mechanism,
        where: Callable[[Mechanism], object],
        mask=None,
        *,
        positive: bool | None = None,
    ) -> "Params":
        """Every entry of the array leaves that `where(mech)` returns (one leaf or a tuple).

        **Arguments:**
        - `where`: e.g. `lambda m: (m.bushings.k_trans, m.bushings.k_rot, m.springs.k)`.
        - `mask`: optional boolean array (one leaf) or tuple of arrays/None (one per leaf), of
          the leaf's shape: only the True entries are parameters.
        - `positive`: log-scale the parameters (lower bound 0). Default: stiffnesses
          (`k_trans`, `k_rot`, springs and stops `k`) yes, everything else no.

        Names: `'<bushing>.Ktx'`… for stiffnesses, `'<element>.<field>'` for one number per
        element, `'<marker>.x'` for marker positions, `'<element>.<field>_x'` for 3-vectors.
        """
        tagged = jax.tree_util.tree_map_with_path(
            lambda kp, x: _Tag(_field_path(kp), tuple(np.shape(x))), mech)
        picked = where(tagged)
        single = isinstance(picked, _Tag)
        picked = (picked,) if single else tuple(picked)
        if not picked or not all(isinstance(t, _Tag) for t in picked):
            raise InputError("`where` must return array leaves of the mechanism (one or a tuple), "
                             "e.g. lambda m: (m.bushings.k_trans, m.springs.k).")
        if mask is None:
            masks = (None,) * len(picked)
        elif single or not isinstance(mask, (tuple, list)):
            masks = (mask,) if single else None
            if masks is None:
                raise InputError("`mask` must be a tuple with one entry per selected leaf.")
        else:
            masks = tuple(mask)
        if len(masks) != len(picked):
            raise InputError(f"`mask` has {len(masks)} entries for {len(picked)} selected leaves.")
        names, start, lower, targets = [], [], [], []
        for tag, m in zip(picked, masks, strict=True):
            value = np.asarray(_get(mech, tag.path), dtype=float).reshape(-1)
            entry = _entry_names(mech, tag.path, tag.shape)
            sel = np.ones(value.size, bool)
            if m is not None:
                m = np.asarray(m, dtype=bool)
                if m.shape != tag.shape:
                    raise InputError(f"mask for {'.'.join(tag.path)} must have shape {tag.shape};"
                                     f" got {m.shape}.")
                sel = m.reshape(-1)
            idx = np.flatnonzero(sel)
            pos = positive if positive is not None else tag.path in _POSITIVE_FIELDS
            first = len(names)
            names += [entry[i] for i in idx]
            start += list(value[idx])
            lower += [0.0 if pos else -np.inf] * idx.size
            targets.append(_Target(offset=jnp.zeros(idx.size), path=tag.path,
                                   leaf_index=tuple(int(i) for i in idx),
                                   param_index=tuple(range(first, first + idx.size))))
        return cls._make(names, start, lower, [np.inf] * len(names), targets)

    @classmethod
    def bushing_stiffness(
        cls,
        mech: Mechanism,
        names: Sequence[str] | None = None,
        axes: Sequence[str] = AXES,
    ) -> "Params":
        """The stiffnesses `axes` (of `'Ktx'`, `'Kty'`, `'Ktz'`, `'Krx'`, `'Kry'`, `'Krz'`) of
        the bushings `names` (default: all), log-scaled. N/mm and N·mm/rad."""
        names = tuple(mech.bushings.names if names is None else names)
        bad = [a for a in axes if a not in AXES]
        if bad:
            raise InputError(f"unknown bushing axes {bad}; use some of {list(AXES)}.")
        rows = [_bushing_index(mech, n) for n in names]
        trans = np.zeros((len(mech.bushings.names), 3), bool)
        rot = np.zeros_like(trans)
        for r in rows:
            for a in axes:
                (trans if a.startswith("Kt") else rot)[r, "xyz".index(a[-1])] = True
        picks, masks = [], []
        if trans.any():
            picks.append("k_trans")
            masks.append(trans)
        if rot.any():
            picks.append("k_rot")
            masks.append(rot)
        params = cls.leaves(mech, lambda m: tuple(getattr(m.bushings, f) for f in picks),
                            tuple(masks))
        # Order as asked: bushing by bushing, axis by axis.
        order = [params.names.index(f"{n}.{a}") for n in names for a in axes]
        return params._reorder(order)

    @classmethod
    def bushing_centres(cls, mech: Mechanism, names: Sequence[str]) -> "Params":
        """The centres of bushings `names`: 3 coordinates each (`'<bushing>.x'`, `.y`, `.z`,
        mm, global, at design), the I marker's position. Moving a centre moves the I and J
        markers together (the bushing stays undeformed at design), so the hardpoint moves on
        both parts; other markers of the parts (landmarks, joints) do not move."""
        pos = np.asarray(mech.markers.position, dtype=float)
        params_names, start, targets = [], [], []
        for k, name in enumerate(names):
            b = _bushing_index(mech, name)
            i, j = mech.bushings.i_marker[b], mech.bushings.j_marker[b]
            centre = pos[i]
            params_names += [f"{name}.{c}" for c in "xyz"]
            start += list(centre)
            p_idx = tuple(range(3 * k, 3 * k + 3))
            for marker in (i, j):
                targets.append(_Target(offset=jnp.asarray(pos[marker] - centre),
                                       path=("markers", "position"),
                                       leaf_index=tuple(3 * marker + c for c in range(3)),
                                       param_index=p_idx))
        p = len(params_names)
        return cls._make(params_names, start, [-np.inf] * p, [np.inf] * p, targets)

    @classmethod
    def _make(cls, names, start, lower, upper, targets) -> "Params":
        start = np.asarray(start, dtype=float)
        lower = np.asarray(lower, dtype=float)
        upper = np.asarray(upper, dtype=float)
        params = cls(start=jnp.asarray(start), lower=jnp.asarray(lower),
                     upper=jnp.asarray(upper), targets=tuple(targets), names=tuple(names))
        params._check_start()
        return params

    # ------------------------------------------------------------------ combination

    def __add__(self, other: "Params") -> "Params":
        if not isinstance(other, Params):
            return NotImplemented
        shift = len(self)
        moved = tuple(_Target(offset=t.offset, path=t.path, leaf_index=t.leaf_index,
                              param_index=tuple(i + shift for i in t.param_index))
                      for t in other.targets)
        given = self._given + other._given
        return Params(start=jnp.concatenate([self.start, other.start]),
                      lower=jnp.concatenate([self.lower, other.lower]),
                      upper=jnp.concatenate([self.upper, other.upper]),
                      targets=self.targets + moved, names=self.names + other.names,
                      given=given if any(given) else ())

    @property
    def _given(self) -> tuple[bool, ...]:
        return self.given or (False,) * len(self)

    def _reorder(self, order: Sequence[int]) -> "Params":
        order = np.asarray(order, dtype=int)
        inverse = np.empty_like(order)
        inverse[order] = np.arange(order.size)
        targets = tuple(_Target(offset=t.offset, path=t.path, leaf_index=t.leaf_index,
                                param_index=tuple(int(inverse[i]) for i in t.param_index))
                        for t in self.targets)
        given = tuple(self._given[i] for i in order) if self.given else ()
        return Params(start=self.start[order], lower=self.lower[order], upper=self.upper[order],
                      targets=targets, names=tuple(self.names[i] for i in order), given=given)

    def with_bounds(self, bounds: Mapping[str, tuple[float | None, float | None]]) -> "Params":
        """A copy with `bounds` {name: (lower, upper)} (None = unbounded on that side), e.g.
        `{'bushing_A.x': (60.0, 62.0), 'spring.k': (0.0, None)}`. The start values must lie
        strictly inside."""
        lower, upper = np.array(self.lower), np.array(self.upper)
        for name, (lo, hi) in bounds.items():
            k = self.index(name)
            lower[k] = -np.inf if lo is None else float(lo)
            upper[k] = np.inf if hi is None else float(hi)
        params = dataclasses.replace(self, lower=jnp.asarray(lower), upper=jnp.asarray(upper))
        params._check_start()
        return params

    def with_start(self, values) -> "Params":
        """A copy starting from `values`: a `(p,)` array, a mapping name → value (others kept),
        or a Mechanism to read them from. These start values are *given*: a fit starts from
        them whatever the values of the mechanism it is handed (see `starting_from`)."""
        start = np.array(self.start)
        given = list(self._given)
        if isinstance(values, Mechanism):
            start = np.asarray(self.values(values))
            given = [True] * len(self)
        elif isinstance(values, Mapping):
            for name, v in values.items():
                start[self.index(name)] = float(v)
                given[self.index(name)] = True
        else:
            start = np.asarray(values, dtype=float)
            if start.shape != (len(self),):
                raise InputError(f"start values must have shape ({len(self)},); got "
                                 f"{start.shape}.")
            given = [True] * len(self)
        params = dataclasses.replace(self, start=jnp.asarray(start), given=tuple(given))
        params._check_start()
        return params

    def starting_from(self, mech: Mechanism) -> "Params":
        """The selection with the start values a fit of `mech` uses: `mech`'s values
        (`values(mech)`), except those set with `with_start`. `least_squares` and
        `least_squares_batch` call it, so `least_squares(start, data, params)` starts from
        `start` even when `params` was built from another mechanism (see the class
        docstring). Raises `InputError` when a value of `mech` is not a valid start (a
        stiffness ≤ 0, outside the bounds): give one with `with_start`."""
        theta = np.asarray(self.values(mech), dtype=float)
        start = np.where(np.asarray(self._given, bool), np.asarray(self.start), theta)
        if np.array_equal(start, np.asarray(self.start)):
            return self
        params = dataclasses.replace(self, start=jnp.asarray(start))
        params._check_start()
        return params

    def index(self, name: str) -> int:
        return index_of(self.names, name)

    def _check_start(self):
        if isinstance(self.start, jax.core.Tracer):
            return
        start, lower, upper = (np.asarray(a) for a in (self.start, self.lower, self.upper))
        bad = ~np.isfinite(start) | (start <= lower) | (start >= upper)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            what = ("a log-scaled stiffness must start above 0; give a positive start value "
                    "or select it with positive=False" if lower[k] == 0 and np.isinf(upper[k])
                    else "the start value must be finite and strictly inside the bounds")
            raise InputError(f"parameter '{self.names[k]}' starts at {start[k]:g} with bounds "
                             f"({lower[k]:g}, {upper[k]:g}): {what}.")

    def units(self, mech: Mechanism) -> tuple[str, ...]:
        """The unit of each parameter: the `unit` metadata of the field it is written into
        (`model.mechanism.field_unit`), e.g. N/mm, N·mm/rad, mm."""
        units = ["-"] * len(self)
        for t in self.targets:
            for i in t.param_index:
                units[i] = field_unit(mech, t.path)
        return tuple(units)

    # ------------------------------------------------------------------ values

    def values(self, mech: Mechanism) -> Float[Array, " p"]:
        """The current values θ of the parameters in `mech` (physical units)."""
        theta = jnp.zeros(len(self))
        for t in self.targets:
            leaf = jnp.reshape(_get(mech, t.path), -1)
            theta = theta.at[np.asarray(t.param_index, dtype=int)].set(
                leaf[np.asarray(t.leaf_index, dtype=int)] - t.offset)
        return theta

    def apply(self, mech: Mechanism, theta: Float[Array, " p"]) -> Mechanism:
        """`mech` with the parameters set to θ (physical units); differentiable in θ."""
        for t in self.targets:
            leaf = _get(mech, t.path)
            flat = jnp.reshape(leaf, -1).at[np.asarray(t.leaf_index, dtype=int)].set(
                theta[np.asarray(t.param_index, dtype=int)] + t.offset)
            mech = eqx.tree_at(lambda m, path=t.path: _get(m, path), mech,
                               flat.reshape(jnp.shape(leaf)))
        return mech

    # ------------------------------------------------------------------ coordinates

    def _branches(self):
        lo, hi = self.lower, self.upper
        has_lo, has_hi = jnp.isfinite(lo), jnp.isfinite(hi)
        lo_s = jnp.where(has_lo, lo, 0.0)
        hi_s = jnp.where(has_hi, hi, 1.0)
        return has_lo, has_hi, lo_s, hi_s

    def to_physical(self, u: Float[Array, " p"]) -> Float[Array, " p"]:
        """θ(u) (see the module docstring)."""
        has_lo, has_hi, lo, hi = self._branches()
        return jnp.where(
            has_lo & has_hi, lo + (hi - lo) * jax.nn.sigmoid(u),
            jnp.where(has_lo, lo + jnp.exp(u), jnp.where(has_hi, hi - jnp.exp(u), u)))

    def to_internal(self, theta: Float[Array, " p"]) -> Float[Array, " p"]:
        """u(θ), the inverse of `to_physical`."""
        has_lo, has_hi, lo, hi = self._branches()
        both = has_lo & has_hi
        x = jnp.clip(jnp.where(both, (theta - lo) / (hi - lo), 0.5), 1e-300, 1 - 1e-16)
        d_lo = jnp.where(has_lo & ~has_hi, theta - lo, 1.0)
        d_hi = jnp.where(has_hi & ~has_lo, hi - theta, 1.0)
        return jnp.where(both, jnp.log(x) - jnp.log1p(-x),
                         jnp.where(has_lo, jnp.log(d_lo), jnp.where(has_hi, jnp.log(d_hi),
                                                                    theta)))

    def derivative(self, u: Float[Array, " p"]) -> Float[Array, " p"]:
        """dθ/du (diagonal), for propagating covariances from u to θ."""
        return jax.jvp(self.to_physical, (u,), (jnp.ones_like(u),))[1]

    @property
    def log_scaled(self) -> np.ndarray:
        """Which parameters are log-scaled (lower bound only): their σ in u is relative."""
        return np.isfinite(np.asarray(self.lower)) & ~np.isfinite(np.asarray(self.upper))


def selected_entries(mech: Mechanism, selection) -> dict[tuple[str, ...], np.ndarray]:
    """Which entries of which leaves a selection picks: `{field path: flat indices}`.

    `selection` is a `Params` (its targets) or a `where` function (every entry of the leaves it
    returns). This is how every identification method reads the one selector: `least_squares`
    identifies exactly these entries; `direct` and `iterative` identify the ones their
    equations can (and say which they cannot). No start values are checked here.
    """
    if isinstance(selection, Params):
        out: dict[tuple[str, ...], set[int]] = {}
        for t in selection.targets:
            out.setdefault(t.path, set()).update(t.leaf_index)
        return {path: np.array(sorted(idx), dtype=int) for path, idx in out.items()}
    if not callable(selection):
        raise InputError("the selection must be a Params or a `where` function selecting leaves "
                         "of the mechanism, e.g. lambda m: (m.bushings.k_trans, m.bushings.k_rot).")
    tagged = jax.tree_util.tree_map_with_path(
        lambda kp, x: _Tag(_field_path(kp), tuple(np.shape(x))), mech)
    try:
        picked = selection(tagged)
    except InputError:
        raise
    except Exception as e:  # a selector that does not apply to this model
        raise InputError(f"where= could not be applied to the model: {e}") from None
    picked = (picked,) if isinstance(picked, _Tag) else tuple(picked)
    if not all(isinstance(t, _Tag) for t in picked):
        raise InputError("`where` must return array leaves of the mechanism (one or a tuple), "
                         "e.g. lambda m: (m.bushings.k_trans, m.springs.k).")
    return {t.path: np.arange(int(np.prod(t.shape)) if t.shape else 1) for t in picked}


def _bushing_index(mech: Mechanism, name: str) -> int:
    try:
        return mech.bushings.index(name)
    except ValueError as err:
        raise InputError(str(err)) from None
