"""One resolver of model names: a model file or a built-in model, above `diffsusp.io` (which
reads files and knows no built-in model) and `diffsusp.models` (which builds them).

`load_model(source)` reads any model diffsusp knows: a `.toml` native file, an Adams `.adm`
dataset, a Chrono `.json` template, or the name of a built-in model (`diffsusp.models.ZOO`, or
`diffsusp.models.STOP_VARIANTS` such as 'pseudo_mcpherson_stops'). Every front end (the CLI
verbs, the fleet recipes, `diffsusp.load_model`) goes through it.
"""

import dataclasses
import functools
import os

from .io import ModelFile, library_model_file, read_model_file, read_model_toml
from .models import STOP_VARIANTS, ZOO

__all__ = ["builtin_models", "load_model", "load_model_file"]

_DATA = os.path.join(os.path.dirname(__file__), "models", "data")


def _builtin(name: str) -> ModelFile:
    """A built-in model with the load tables of its shipped file `models/data/<name>.toml`."""
    data = os.path.join(_DATA, f"{name}.toml")
    tables = read_model_toml(data, check=False).load_tables if os.path.exists(data) else {}
    return dataclasses.replace(library_model_file(ZOO[name]()), load_tables=tables)


def _stop_variant(name: str) -> ModelFile:
    """An axle with bump and rebound stops: the load tables of the model it adds them to."""
    base = _builtin(name.removesuffix("_stops"))
    return dataclasses.replace(base, mechanism=STOP_VARIANTS[name]())


def builtin_models() -> dict:
    """Name → zero-argument reader (`ModelFile`) of every built-in model: `diffsusp.models.ZOO`,
    then `STOP_VARIANTS` (the order error messages list them in)."""
    named = {name: functools.partial(_builtin, name) for name in ZOO}
    named.update({name: functools.partial(_stop_variant, name) for name in STOP_VARIANTS})
    return named


def load_model_file(source, *, check: bool = True, side: str | None = None) -> ModelFile:
    """Read a model and whatever comes with it (named load tables for native files), on `side`.

    **Arguments:** `source`: a path (`.toml`, `.adm`, `.json`) or a built-in model name (a key
    of `diffsusp.models.ZOO`, its load tables those of the shipped file
    `diffsusp/models/data/<name>.toml`; or of `diffsusp.models.STOP_VARIANTS`, with the load
    tables of the model it adds stops to); `check`: validate the model at build (native files);
    `side`: 'left', 'right' or None (see `diffsusp.io.read_model_file`).

    **Raises:** `ModelFileError` for a file that cannot be read, or a name that is neither a
    file nor a built-in model; `InputError` for a `side` the model cannot take.
    """
    return read_model_file(source, check=check, side=side, named=builtin_models())


def load_model(source, *, check: bool = True, side: str | None = None):
    """The `Mechanism` of a model file or built-in model name (see `load_model_file`), on
    `side` ('left', 'right'; None: as the model is)."""
    return load_model_file(source, check=check, side=side).mechanism
