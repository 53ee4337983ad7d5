"""Files in and out: the native TOML model file, load-case and result tables (CSV, Parquet), and
importers of other tools' models (Adams .adm, Chrono JSON), probed geometry (IGES points,
lines and planes) and tyre property files (.tir, MF 5.2/6.1/6.2).

`read_model_file(source)` reads a model file: a `.toml` native file, an Adams `.adm` dataset or
a Chrono `.json` template. io depends on `diffsusp.model` only: the resolver that also knows
the built-in models by name is `diffsusp.load_model` (and `diffsusp.resolve.load_model_file`).
"""

import dataclasses
import os
from collections.abc import Callable, Mapping

from ..errors import InputError, ModelFileError
from ..model.mirror import mirror
from .adams import read_adm
from .chrono import read_chrono
from .iges import IgesFile, read_iges
from .native import ModelFile, model_from_toml, read_model_toml
from .native_write import model_to_toml, write_model_toml
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
    "MODEL_SUFFIXES", "SIDES", "ModelFile", "NamedModels", "Table", "library_model_file",
    "load_columns",
    "loads_from_table", "model_from_toml", "model_to_toml", "parse_unit", "read_model_toml",
    "read_model_file", "read_table", "results_table", "save_model", "write_model_toml",
    "write_table",
]


MODEL_SUFFIXES = (".toml", ".adm", ".json")
"""The model file formats `read_model_file` reads (and every verb that takes a MODEL)."""

SIDES = ("left", "right")
"""The sides `read_model_file(side=...)` gives a half axle."""

NamedModels = Mapping[str, Callable[[], ModelFile]]
"""Name → zero-argument reader of a model that is not a file (`read_model_file(named=...)`)."""


def read_model_file(source, *, check: bool = True, side: str | None = None,
                    named: NamedModels | None = None) -> ModelFile:
    """Read a model file, or a named model of `named`, on the requested side of the vehicle.

    **Arguments:** `source`: a path (`.toml`, `.adm`, `.json`) or a key of `named`; `check`:
    validate the model at build (native files); `side` ('left', 'right', or None: as the model
    is): a Chrono file is read on that side (`read_chrono(side=...)`); any other half axle whose
    corner (`Mechanism.corners`) is on the other side is mirrored (`diffsusp.model.mirror.mirror`,
    its corner follows); `named`: the models known by name (an existing path wins over a name).
    `diffsusp.resolve.load_model_file` passes the built-in models: this module depends on
    `diffsusp.model` only.

    **Returns:** a `ModelFile`.

    **Raises:** `ModelFileError` for a file that cannot be read, or a source that is neither a
    file nor a name of `named`; `InputError` for a `side` on a model without a corner, or with
    more than one (an axle).
    """
    if side is not None and side not in SIDES:
        raise InputError(f"side must be 'left' or 'right'; got '{side}'.")
    text = os.fspath(source)
    if side is not None and os.path.splitext(text)[1].lower() == ".json":
        if os.path.isfile(text):
            return ModelFile(mechanism=read_chrono(text, side=side), load_tables={},
                             units=dict(_LIBRARY), path=text)
    out = _read_model_file(source, check=check, named=named or {})
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
    return dataclasses.replace(out, mechanism=mirror(mech, name=f"{mech.name} ({side})"))


def _read_model_file(source, *, check: bool, named: NamedModels) -> ModelFile:
    """A model file by its suffix, or a named model (see `read_model_file`)."""
    text = os.fspath(source)
    if text in named and not os.path.exists(text):
        return named[text]()
    suffix = os.path.splitext(text)[1].lower()
    if suffix not in MODEL_SUFFIXES or not os.path.exists(text):
        raise ModelFileError(_not_a_model(text, named), path=text)
    if os.path.isdir(text):
        raise ModelFileError("is a directory, not a model file.", path=text)
    if suffix == ".toml":
        return read_model_toml(text, check=check)
    if suffix == ".adm":
        return ModelFile(mechanism=read_adm(text, check=check), load_tables={},
                         units=dict(_LIBRARY), path=text)
    return ModelFile(mechanism=read_chrono(text), load_tables={}, units=dict(_LIBRARY),
                     path=text)


def _not_a_model(text: str, named: NamedModels) -> str:
    """The one message for a source that is neither a model file nor a name of `named`."""
    expected = "expected a .toml, .adm or .json path."
    missing = os.path.splitext(text)[1].lower() in MODEL_SUFFIXES
    if not named:
        return f"model '{text}' is not a model file: {'no such file.' if missing else expected}"
    why = "no such file." if missing else f"not a model file or a built-in model; {expected}"
    return (f"model '{text}' is neither a built-in model ({', '.join(named)}) nor a model file: "
            f"{why} Give a built-in model name or the path of a model file "
            f"({', '.join(MODEL_SUFFIXES)}).")


def library_model_file(mech) -> ModelFile:
    """A `ModelFile` for a mechanism built in Python: no load tables, library units."""
    return ModelFile(mechanism=mech, load_tables={}, units=dict(_LIBRARY), path=None)


_LIBRARY = {"length": "mm", "force": "N", "angle": "rad"}


def save_model(mech, path, *, load_tables: dict | None = None, units: dict | None = None,
               keep_comments: bool = True) -> None:
    """Write `mech` as a native TOML model file (see `diffsusp.io.native`).

    **Arguments:** `load_tables`: name → `Table` written as `[load_tables.<name>]`; `units`:
    the file's units (default mm, N, rad, which reads back bit for bit); `keep_comments`: when
    `path` is an existing native file, keep its comments (and its load tables if
    `load_tables` is None).
    """
    if os.path.splitext(os.fspath(path))[1].lower() != ".toml":
        raise ModelFileError("save_model writes native .toml files; use a .toml path.",
                             path=path)
    write_model_toml(mech, path, load_tables=load_tables, units=units,
                     keep_comments=keep_comments)

