"""K&C-rig tables: what an SPMM/MTS rig reports — toe, camber, wheel-centre displacement, ...
against the loads or the wheel travel of each case — as a least-squares `Channel`, so that
`identify.least_squares` (and `diffsusp identify fit MODEL --measurements rig.csv`) correlates
a model to rig curves with the same report and verdict as the landmark fits.

**The table** (CSV or Parquet, `diffsusp.io.tables`: one header row, `#` lines skipped, a unit
in brackets after a column name, no unit = the library's units mm, N, N·mm, rad):

- the **inputs** of each case, named as the K&C metric registry names them
  (`diffsusp.kc.metrics.METRICS`): `wheel_travel` (mm, bump +: a travel rig, the wheel centre
  driven), or any of `vertical_force` (N, up), `lateral_force` (N, inboard),
  `longitudinal_force` (N, rearward = braking, at the contact patch) and `aligning_torque`
  (toe-out; N·mm without a unit, `[N·m]` as rigs print it): a force rig, the wheel free and
  loaded at the ground contact point (`diffsusp.kc.force_rig`), every case its own
  combination. A force table without `vertical_force` holds the corner's design load
  (`Corner.resolve`), with a note; in a force table a `wheel_travel` column is a measured
  channel (the wheel's vertical displacement), not an input. `case` (a label) is ignored.
- the **channels**: any geometric K&C metric of one equilibrium (`CHANNELS`: toe, camber,
  wheel_centre_x/y/z, contact_patch_x/y/z, caster, ..., in the model's frame and the
  metric's sign convention, per side), e.g. `toe [deg]`.
- **σ per channel**, in the channel column's unit: a comment line `# sigma: toe=0.01,
  camber=0.01, wheel_centre_y=0.05` (the option `--rig-sigma` of the CLI, `sigma=` here,
  replaces it), or per case a column `sigma.<channel>` (noise that grows with the signal).
  A channel without σ is an error.

A column that is neither, a missing σ, a non-finite value, two kinds of input (travel and
force) → `ModelFileError` naming the file, the line and the column (exit 2 in the CLI).

spec: kc §1 (metric definitions and signs, `diffsusp.kc.metrics`), stiffness §3 (least squares
through the equilibrium). Units: mm, N, N·mm, rad internally.
"""

import dataclasses
import math
import re

import jax
import jax.numpy as jnp
import numpy as np

from .. import kc
from ..errors import InputError, ModelFileError
from ..io.files import read_input, write_text_atomic
from ..io.tables import read_table, split_header, unit_factor
from ..kc.events import event_loads
from ..kc.metrics import METRICS, corner_geometry
from .data import Channel

FORCE_INPUTS = ("vertical_force", "lateral_force", "longitudinal_force", "aligning_torque")
"""Force-rig inputs (per side: up, inboard, rearward, toe-out), as the metric registry names
them."""

TRAVEL_INPUT = "wheel_travel"
"""The travel-rig input (mm, bump +)."""

CHANNELS = ("toe", "steer", "camber", "caster", "kingpin_inclination", "scrub_radius",
            "mechanical_trail", "wheel_centre_x", "wheel_centre_y", "wheel_centre_z",
            "contact_patch_x", "contact_patch_y", "contact_patch_z", "spin_axis_x",
            "spin_axis_y", "spin_axis_z", "wheel_travel", "half_track_change",
            "wheelbase_change")
"""The metrics a rig table may give as channels: the geometric metrics of one equilibrium
(`diffsusp.kc.metrics`; derivative metrics and the loads are not channels)."""

_DIMENSION = {"rad": "angle", "mm": "length", "N": "force", "N·mm": "moment", "-": None}
_SIGMA_LINE = re.compile(r"^\s*#\s*sigma\s*:(.*)$", re.IGNORECASE)


@dataclasses.dataclass(frozen=True, eq=False)
class RigTable:
    """A K&C-rig table read by `read_rig_table` (library units).

    **Fields:** `path`, `mode` ('force' or 'travel'), `inputs` (name → (cases,) values: the
    force components given, or `wheel_travel`), `channels` (names), `measured` (cases, k),
    `sigma` (cases, k), `units` (the channel columns' units as written, for display),
    `lines` (source line of each case), `notes`.
    """

    path: str
    mode: str
    inputs: dict
    channels: tuple[str, ...]
    measured: np.ndarray
    sigma: np.ndarray
    units: tuple[str | None, ...]
    lines: tuple[int, ...] | None = None
    notes: tuple[str, ...] = ()

    @property
    def n_cases(self) -> int:
        return self.measured.shape[0]


def _metric_unit(name: str) -> str:
    return METRICS[name].unit


def _factor(unit, name, path, line):
    """Factor to the library unit of metric or input `name` from a column's `unit`."""
    dimension = _DIMENSION.get(_metric_unit(name))
    if dimension is None:
        if unit not in (None, "-", "1"):
            raise ModelFileError(f"column '{name}' is dimensionless; got unit '{unit}'.",
                                 path=path, line=line, field=name)
        return 1.0
    try:
        return unit_factor(unit, dimension)
    except ValueError as e:
        raise ModelFileError(f"column '{name}': {e}.", path=path, line=line,
                             field=name) from None


def is_rig_table(path) -> bool:
    """Whether the table at `path` is a K&C-rig table: its header names a rig input
    (`wheel_travel` or a force input) and no landmark, pose or load-point column. Reads the
    header only; False for anything it cannot read (the landmark reader then says why)."""
    try:
        if str(path).lower().endswith((".parquet", ".pq")):
            import pyarrow.parquet as pq

            names = [split_header(n)[0] for n in pq.read_schema(path).names]
        else:
            with open(path, encoding="utf-8-sig", errors="replace") as f:
                names = None
                for _, text in zip(range(1000), f, strict=False):
                    if text.strip() and not text.lstrip().startswith("#"):
                        names = [split_header(c)[0] for c in text.strip().split(",")]
                        break
        if not names:
            return False
    except (OSError, ValueError, ImportError):
        return False
    inputs = set(FORCE_INPUTS) | {TRAVEL_INPUT}
    return any(n in inputs for n in names) and all("." not in n or n.startswith("sigma.")
                                                   for n in names)


def _parse_sigma(text: str, path, line) -> dict[str, float]:
    out = {}
    for item in re.split(r"[,;]", text):
        if not item.strip():
            continue
        name, eq, value = item.partition("=")
        name = name.strip()
        try:
            number = float(value)
        except ValueError:
            number = math.nan
        if not eq or not name or not (math.isfinite(number) and number > 0):
            raise ModelFileError(
                f"sigma: '{item.strip()}' is not name=value with a finite value > 0 (in the "
                "channel column's unit), e.g. 'toe=0.01, wheel_centre_y=0.05'.",
                path=path, line=line, field="sigma")
        out[name] = number
    return out


def _header_sigma(path) -> tuple[dict[str, float], int | None]:
    if str(path).lower().endswith((".parquet", ".pq")):
        return {}, None
    text = read_input(path, "table", "table").decode("utf-8-sig", errors="replace")
    for number, line in enumerate(text.splitlines(), 1):
        match = _SIGMA_LINE.match(line)
        if match:
            return _parse_sigma(match.group(1), path, number), number
    return {}, None


def read_rig_table(path, *, sigma=None) -> RigTable:
    """Read a K&C-rig table (see the module docstring).

    **Arguments:** `path` (.csv or .parquet); `sigma`: σ per channel, a mapping name → value
    or the text 'toe=0.01,camber=0.01' (in each channel column's unit), replacing the file's
    `# sigma:` line.

    **Returns:** a `RigTable` in library units.

    **Raises:** `ModelFileError` (file, line, column): an unknown column, travel and force
    inputs together, no channel, a channel without σ, a non-finite value or σ ≤ 0.
    """
    table = read_table(path)
    path = table.path or str(path)
    header = table.header_line
    if isinstance(sigma, str):
        sigma = _parse_sigma(sigma, "--rig-sigma", None)
    given = dict(sigma) if sigma is not None else None
    file_sigma, sigma_line = _header_sigma(path)
    sigmas = given if given is not None else file_sigma
    inputs, channels, per_case = {}, [], {}
    known = ", ".join((TRAVEL_INPUT, *FORCE_INPUTS))
    for name in table.names:
        unit = table.units.get(name)
        if name == "case":
            continue
        if name.startswith("sigma."):
            per_case[name[len("sigma."):]] = name
        elif name == TRAVEL_INPUT and not any(n in table.names for n in FORCE_INPUTS):
            inputs[name] = table[name] * _factor(unit, name, path, header)
        elif name in FORCE_INPUTS:
            inputs[name] = table[name] * _factor(unit, name, path, header)
        elif name in CHANNELS:
            channels.append(name)
        else:
            raise ModelFileError(
                f"column '{name}' is neither a rig input ({known}), a channel (a geometric "
                f"K&C metric: {', '.join(CHANNELS)}), 'sigma.<channel>' nor 'case'.",
                path=path, line=header, field=name)
    if not inputs:
        raise ModelFileError(f"no rig input column: name the loads or the travel of each case "
                             f"({known}).", path=path, line=header)
    if not channels:
        raise ModelFileError("no channel column: give what the rig measured, e.g. 'toe [deg]',"
                             " 'camber [deg]', 'wheel_centre_y [mm]'.", path=path, line=header)
    for name in per_case:
        if name not in channels:
            raise ModelFileError(f"column 'sigma.{name}' names no channel of the table.",
                                 path=path, line=header, field=f"sigma.{name}")
    for name in sigmas:
        if name not in channels:
            raise ModelFileError(f"sigma is given for '{name}', which is no channel of the "
                                 f"table ({', '.join(channels)}).", path=path,
                                 line=None if given is not None else sigma_line, field="sigma")
    n = table.n_rows
    if n == 0:
        raise ModelFileError("the table has no cases.", path=path, line=header)
    measured = np.empty((n, len(channels)))
    sigma_arr = np.empty((n, len(channels)))
    units = []
    for k, name in enumerate(channels):
        unit = table.units.get(name)
        units.append(unit)
        scale = _factor(unit, name, path, header)
        measured[:, k] = table[name] * scale
        if name in per_case and name not in sigmas:
            sigma_arr[:, k] = table[per_case[name]] * scale
        elif name in sigmas:
            sigma_arr[:, k] = sigmas[name] * scale
        else:
            raise ModelFileError(
                f"channel '{name}' has no sigma: give it on a line '# sigma: {name}=...' (in "
                "the column's unit), a column 'sigma." + name + "', or the CLI option "
                f"--rig-sigma {name}=...", path=path, line=header, field=name)
    columns = [*inputs, *channels, *(per_case[c] for c in per_case)]
    for name in columns:
        values = table[name]
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            phrase, line = table.where(int(bad[0]))
            raise ModelFileError(f"{phrase}: '{values[bad[0]]}' in column '{name}' is not a "
                                 "finite number.", path=path, line=line, field=name)
    bad = np.argwhere(~(sigma_arr > 0))
    if bad.size:
        r, k = (int(v) for v in bad[0])
        phrase, line = table.where(r)
        raise ModelFileError(f"{phrase}: the sigma of channel '{channels[k]}' must be > 0.",
                             path=path, line=line, field=f"sigma.{channels[k]}")
    mode = "travel" if TRAVEL_INPUT in inputs else "force"
    notes = []
    return RigTable(path=str(path), mode=mode, inputs=inputs, channels=tuple(channels),
                    measured=measured, sigma=sigma_arr, units=tuple(units), lines=table.lines,
                    notes=tuple(notes))


@dataclasses.dataclass(frozen=True)
class RigChannels:
    """The channel function of a rig table: `fn(mech, q)` → (cases, k) geometric K&C metrics
    of corner `corner` at the equilibria q (public coordinates), in library units. Hashable
    (its fields are static), so that two fits of one rig share their compiled programs."""

    corner: object  # a kc.ResolvedCorner (a NamedTuple of static values)
    channels: tuple[str, ...]

    def __call__(self, mech, q):
        rc = self.corner
        up, o, r = (jnp.asarray(v) for v in (rc.up, rc.outboard, rc.rearward))
        geo0 = corner_geometry(mech, rc, jnp.zeros(mech.n_coordinates))

        def vec(g, what):
            return jnp.stack([g[f"{what}_{x}"] for x in "xyz"])

        def one(qq):
            geo = corner_geometry(mech, rc, qq)
            w = vec(geo, "wheel_centre") - vec(geo0, "wheel_centre")
            geo["wheel_travel"] = w @ up
            geo["half_track_change"] = (vec(geo, "contact_patch") - vec(geo0, "contact_patch")) @ o
            geo["wheelbase_change"] = w @ r
            return jnp.stack([geo[name] for name in self.channels])

        return jax.vmap(one)(q)


def rig_measurement(mech, table: RigTable, corner=None):
    """The least-squares measurement of a rig table on `mech`: (rig, `Channel`, notes).

    The rig is `kc.travel_rig` (a `wheel_travel` table) or `kc.force_rig` (forces at the
    ground contact point) around `mech` with the model's corner (or `corner`); fit
    `rig.mech` (its parameters are `mech`'s: `Params` built on either apply to both), e.g.
    `identify.least_squares(rig.mech, channel, params)`. The channel's name is 'kc_rig'; its
    residual rows are the table's cases × channels, whitened by their σ."""
    notes = list(table.notes)
    if table.mode == "travel":
        rig = kc.travel_rig(mech, corner)
        loads = event_loads(rig, table.n_cases, travel=table.inputs[TRAVEL_INPUT])
    else:
        rig = kc.force_rig(mech, corner)
        if len(rig.corners) != 1:
            raise InputError(f"a rig table loads one corner; the model has {len(rig.corners)} "
                             "(pass corner= to choose one).")
        given = table.inputs
        vertical = given.get("vertical_force")
        if vertical is None:
            vertical = rig.corners[0].design_load
            c = corner or kc.corners_of(mech)[""]
            origin = ("stated by the model's corner" if c.design_load is not None else
                      "computed: the vertical load that holds the wheel centre at its design "
                      "height")
            notes.append(f"the table gives no vertical_force: every case holds the design load "
                         f"{vertical:.6g} N ({origin}).")
        loads = event_loads(rig, table.n_cases, vertical=vertical,
                       lateral=given.get("lateral_force", 0.0),
                       longitudinal=given.get("longitudinal_force", 0.0),
                       aligning=given.get("aligning_torque", 0.0))
    if len(rig.corners) != 1:
        raise InputError(f"a rig table measures one corner; the model has {len(rig.corners)} "
                         "(pass corner= to choose one).")
    fn = RigChannels(rig.corners[0], table.channels)
    channel = Channel(loads, fn, table.measured, table.sigma, name="kc_rig")
    return rig, channel, notes


def write_rig_table(path, inputs: dict, channels: dict, sigma: dict, units: dict | None = None
                    ) -> None:
    """Write a rig table (CSV): `inputs` and `channels` name → (cases,) values in the column's
    unit (`units`: name → unit, default the library's), `sigma` channel → σ in the same unit:
    a number (the `# sigma:` line) or (cases,) values (a column `sigma.<channel>`). What
    `read_rig_table` reads back."""
    units = dict(units or {})
    scalar = {k: float(v) for k, v in sigma.items() if np.ndim(v) == 0}
    columns = {**inputs, **channels,
               **{f"sigma.{k}": v for k, v in sigma.items() if np.ndim(v) > 0}}
    for k in sigma:
        units.setdefault(f"sigma.{k}", units.get(k))
    names = list(columns)
    if len({np.size(v) for v in columns.values()}) != 1:
        raise InputError("write_rig_table: every column must have one length.")
    head = ",".join(f"{k} [{units[k]}]" if units.get(k) else k for k in names)
    lines = ["# K&C rig table (diffsusp.measure.rig)"]
    if scalar:
        lines.append("# sigma: " + ", ".join(f"{k}={v:.17g}" for k, v in scalar.items()))
    lines.append(head)
    data = np.column_stack([np.atleast_1d(np.asarray(columns[k], dtype=float)) for k in names])
    lines += [",".join(f"{v:.17g}" for v in row) for row in data]
    write_text_atomic(path, "\n".join(lines) + "\n")


__all__ = ["CHANNELS", "FORCE_INPUTS", "TRAVEL_INPUT", "RigChannels", "RigTable",
           "is_rig_table", "read_rig_table", "rig_measurement", "write_rig_table"]
