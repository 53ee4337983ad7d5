"""Files in and out: the native TOML model file, load-case and result tables (CSV, Parquet), and
importers of other tools' models (Adams .adm, Chrono JSON), probed geometry (IGES points,
lines and planes) and tyre property files (.tir, MF 5.2/6.1/6.2).

`load_model(source)` reads any model diffsusp knows: a `.toml` native file, an Adams `.adm`
dataset, a Chrono `.json` template, or the name of a built-in model (`diffsusp.models.ZOO`).
"""

import dataclasses
import os

from .iges import IgesFile, read_iges
from .native import (
    ModelFile,
    model_from_toml,
    model_to_toml,
    read_model_toml,
    write_model_toml,
)
from .tables import (
    Table,
    load_columns,
    loads_from_table,
    parse_unit,
    read_table,
    results_table,
    write_table,
)
from .tir import TirFile, read_tir, tir_from_text, write_tir

__all__ = [
    "IgesFile", "TirFile", "read_iges", "read_tir", "tir_from_text", "write_tir",
    "SIDES", "ModelFile", "Table", "load_columns", "load_model", "load_model_file",
    "loads_from_table", "model_from_toml", "model_to_toml", "parse_unit", "read_model_toml",
    "read_table", "results_table", "save_model", "write_model_toml", "write_table",
]


SIDES = ("left", "right")
"""The sides `load_model(side=...)` gives a half axle."""


def load_model_file(source, *, check: bool = True, side: str | None = None) -> ModelFile:
    """`_load_model_file` on the requested side of the vehicle.

    `side` ('left', 'right', or None: as the model is): a Chrono file is read on that side
    (`read_chrono(side=...)`); any other half axle whose corner (`Mechanism.corners`) is on the
    other side is mirrored (`diffsusp.model.mirror.mirror`, its corner follows). Raises
    `InputError` for a model without a corner, or with more than one (an axle)."""
    from ..errors import InputError

    if side is not None and side not in SIDES:
        raise InputError(f"side must be 'left' or 'right'; got '{side}'.")
    text = os.fspath(source)
    if side is not None and os.path.splitext(text)[1].lower() == ".json":
        from .chrono import read_chrono

        if os.path.isfile(text):
            return ModelFile(mechanism=read_chrono(text, side=side), load_tables={},
                             units=dict(_LIBRARY), path=text)
    out = _load_model_file(source, check=check)
    if side is None:
        return out
    mech = out.mechanism
    if len(mech.corners) != 1 or mech.corners[0].prefix:
        raise InputError(
            f"--side needs a half axle that states its wheel corner; model '{mech.name}' has "
            f"{len(mech.corners) or 'no'} corner(s). Describe the wheel in a [[corner]] table "
            "of a native file, or load the model without a side.")
    if mech.corners[0].side_in(mech) == side:
        return out
    from ..model.mirror import mirror

    return dataclasses.replace(out, mechanism=mirror(mech, name=f"{mech.name} ({side})"))


def _load_model_file(source, *, check: bool = True) -> ModelFile:
    """Read a model and whatever comes with it (named load tables for native files).

    **Arguments:** `source`: a path (`.toml`, `.adm`, `.json`) or a built-in model name (a key
    of `diffsusp.models.ZOO`; its load tables are those of the shipped file
    `diffsusp/models/data/<name>.toml`; or of `diffsusp.models.STOP_VARIANTS`, e.g.
    'pseudo_mcpherson_stops', with the load tables of the model it adds stops to); `check`:
    validate the model at build (native files).

    **Returns:** a `ModelFile`.

    **Raises:** `ModelFileError` for a file that cannot be read, or a name that is neither a
    file nor a built-in model.
    """
    from ..errors import ModelFileError
    from ..models import STOP_VARIANTS, ZOO

    text = os.fspath(source)
    if text in STOP_VARIANTS and not os.path.exists(text):
        # An axle with bump and rebound stops: the load tables of the model it adds them to.
        base = _load_model_file(text.removesuffix("_stops"), check=False)
        return dataclasses.replace(base, mechanism=STOP_VARIANTS[text]())
    if text in ZOO and not os.path.exists(text):
        mech = ZOO[text]()
        data = os.path.join(os.path.dirname(__file__), "..", "models", "data", f"{text}.toml")
        tables = {}
        if os.path.exists(data):
            tables = read_model_toml(data, check=False).load_tables
        return ModelFile(mechanism=mech, load_tables=tables, units=dict(_LIBRARY), path=None)
    suffix = os.path.splitext(text)[1].lower()
    if suffix in (".toml", ".adm", ".json"):
        if not os.path.exists(text):
            raise ModelFileError(
                "no such file; give the path of a model file (.toml, .adm, .json) or a "
                f"built-in model name ({', '.join(ZOO)}).", path=text)
        if os.path.isdir(text):
            raise ModelFileError("is a directory, not a model file.", path=text)
    if suffix == ".toml":
        return read_model_toml(text, check=check)
    if suffix == ".adm":
        from .adams import read_adm

        return ModelFile(mechanism=read_adm(text, check=check), load_tables={},
                         units=dict(_LIBRARY), path=text)
    if suffix == ".json":
        from .chrono import read_chrono

        return ModelFile(mechanism=read_chrono(text), load_tables={}, units=dict(_LIBRARY),
                         path=text)
    raise ModelFileError(
        f"not a model file or a built-in model: expected a .toml, .adm or .json path, or one of "
        f"{', '.join(ZOO)}.", path=text)


_LIBRARY = {"length": "mm", "force": "N", "angle": "rad"}


def load_model(source, *, check: bool = True, side: str | None = None):
    """The `Mechanism` of a model file or built-in model name (see `load_model_file`), on
    `side` ('left', 'right'; None: as the model is)."""
    return load_model_file(source, check=check, side=side).mechanism


def save_model(mech, path, *, load_tables: dict | None = None, units: dict | None = None,
               keep_comments: bool = True) -> None:
    """Write `mech` as a native TOML model file (see `diffsusp.io.native`).

    **Arguments:** `load_tables`: name → `Table` written as `[load_tables.<name>]`; `units`:
    the file's units (default mm, N, rad, which reads back bit for bit); `keep_comments`: when
    `path` is an existing native file, keep its comments (and its load tables if
    `load_tables` is None).
    """
    from ..errors import ModelFileError

    if os.path.splitext(os.fspath(path))[1].lower() != ".toml":
        raise ModelFileError("save_model writes native .toml files; use a .toml path.",
                             path=path)
    write_model_toml(mech, path, load_tables=load_tables, units=units,
                     keep_comments=keep_comments)


def __getattr__(name):
    # The importers load on first use (they pull in their own parsers).
    if name in ("read_adm", "parse_adm", "write_adm", "read_lcf", "write_lcf",
                "read_bushing_property", "write_bushing_property"):
        from . import adams

        return getattr(adams, name)
    if name == "read_chrono":
        from .chrono import read_chrono

        return read_chrono
    raise AttributeError(f"module 'diffsusp.io' has no attribute '{name}'")
