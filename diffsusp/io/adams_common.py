"""Text helpers and unit tables shared by the Adams readers and writers (`adams`: datasets,
`adams_property`: TeimOrbit property files, .lcf load-case files, .bus bushing files).

Units: every reader converts to mm, N, N·mm, rad.
"""

import re
from pathlib import Path

from ..errors import ModelFileError
from .files import read_input

LENGTH_TO_MM = {
    "MILLIMETER": 1.0, "MM": 1.0, "CENTIMETER": 10.0, "CM": 10.0, "METER": 1000.0, "M": 1000.0,
    "KILOMETER": 1.0e6, "KM": 1.0e6, "INCH": 25.4, "IN": 25.4, "FOOT": 304.8, "FT": 304.8,
    "MILE": 1609344.0,
}
FORCE_TO_N = {
    "NEWTON": 1.0, "N": 1.0, "KILONEWTON": 1000.0, "KN": 1000.0, "MILLINEWTON": 1.0e-3,
    "DYNE": 1.0e-5, "POUND_FORCE": 4.4482216152605, "LBF": 4.4482216152605,
    "KPOUND_FORCE": 4448.2216152605, "KILOGRAM_FORCE": 9.80665, "KGF": 9.80665,
    "OUNCE_FORCE": 0.27801385095378125,
}
SYSTEMS = {
    "MKS": ("METER", "NEWTON"), "MMKS": ("MILLIMETER", "NEWTON"), "CGS": ("CENTIMETER", "DYNE"),
    "IPS": ("INCH", "POUND_FORCE"), "FPS": ("FOOT", "POUND_FORCE"),
}


def read_source(source, what: str) -> tuple[str, Path | None]:
    """Text of `source`: a `Path`, a path string (one line), text (with a newline) or bytes."""
    if isinstance(source, bytes | bytearray):
        return _decode(bytes(source)), None
    if isinstance(source, Path) or (isinstance(source, str) and "\n" not in source):
        path = Path(source)
        try:
            data = read_input(path, f"{what} file")
        except FileNotFoundError:
            raise ModelFileError(f"cannot read the {what} file: no such file.", path=path,
                                 line=None) from None
        return _decode(data), path
    if isinstance(source, str):
        return source, None
    raise TypeError(f"expected a path, text or bytes; got {type(source).__name__}.")


def _decode(data: bytes) -> str:
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def error(message, path, line, field=None):
    """A located error; the field is named in the prefix only if the message does not already
    name it (`file:43: BUSHING/1: K needs 3 values`, not `file:43: K: BUSHING/1: K needs ...`)."""
    if field and re.search(rf"(?<![\w.]){re.escape(str(field))}(?![\w])", message):
        err = ModelFileError(message, path=path, line=line)
        err.field = field
        return err
    return ModelFileError(message, path=path, line=line, field=field)


def fmt(x: float) -> str:
    return repr(float(x)).upper()
