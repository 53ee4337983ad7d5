"""Reading the native model file's values where they are written: units and dimensions, the
line of a key in the TOML text (`Source`, for located errors) and typed values converted to
library units (`Reader`). Part of `diffsusp.io.native` (its format is documented there).
"""

import math
import re

import numpy as np

from ..errors import ModelFileError
from ..geometry import DEG

MAX_MAGNITUDE = 1e15
"""Largest magnitude of any number in a model file, in mm, N and rad (beyond it a value is a
typo or a unit mistake, and products in the checks would overflow)."""

LENGTH_UNITS = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
FORCE_UNITS = {"N": 1.0, "daN": 10.0, "kN": 1000.0, "lbf": 4.4482216152605}
ANGLE_UNITS = {"rad": 1.0, "deg": DEG}
UNIT_TABLES = {"length": LENGTH_UNITS, "force": FORCE_UNITS, "angle": ANGLE_UNITS}
LIBRARY_UNITS = {"length": "mm", "force": "N", "angle": "rad"}

# Dimensions as exponents of (length, force, angle).
NONE, LEN, ANG, FORCE = (0, 0, 0), (1, 0, 0), (0, 0, 1), (0, 1, 0)
TORQUE = (1, 1, 0)


# --------------------------------------------------------------------------------- locating


_BARE = r"[A-Za-z0-9_-]+"
_BASIC = r'"(?:[^"\\]|\\.)*"'
_LITERAL = r"'[^']*'"
_KEY = rf"(?:{_BARE}|{_BASIC}|{_LITERAL})"
_KEY_RE = re.compile(rf"\s*({_KEY})\s*")


def _split_keys(text: str) -> tuple[str, ...] | None:
    """Dotted TOML key → its parts (quotes removed), or None if it cannot be read."""
    keys, pos = [], 0
    while True:
        match = _KEY_RE.match(text, pos)
        if not match:
            return None
        raw = match.group(1)
        if raw[0] == '"':
            try:
                import json

                keys.append(json.loads(raw))
            except ValueError:
                return None
        elif raw[0] == "'":
            keys.append(raw[1:-1])
        else:
            keys.append(raw)
        pos = match.end()
        if pos == len(text):
            return tuple(keys)
        if text[pos] != ".":
            return None
        pos += 1


class Source:
    """The text of a file, to find the line of a key path for error messages."""

    _HEADER_RE = re.compile(r"^\s*\[\[?\s*(.*?)\s*\]\]?\s*(?:#.*)?$")

    def __init__(self, text: str, path):
        self.path = path
        self.lines = text.splitlines()
        self.headers: list[tuple[int, tuple[str, ...]]] = [(0, ())]
        for n, raw in enumerate(self.lines):
            if raw.lstrip().startswith("["):
                match = self._HEADER_RE.match(raw)
                keys = _split_keys(match.group(1)) if match else None
                if keys is not None:
                    self.headers.append((n, keys))

    def line(self, keys: tuple[str, ...]) -> int:
        """1-based line of the deepest part of `keys` found in the text (1 if none)."""
        for depth in range(len(keys), -1, -1):
            prefix = keys[:depth]
            for h, (start, header) in enumerate(self.headers):
                if header != prefix:
                    continue
                end = self.headers[h + 1][0] if h + 1 < len(self.headers) else len(self.lines)
                rest = keys[depth:]
                if rest:
                    found = self._key_line(start + (h > 0), end, rest)
                    if found is not None:
                        return found
                if depth > 0:
                    return start + 1
            # A table defined only through deeper headers ([a.b] defines a).
            for start, header in self.headers[1:]:
                if depth > 0 and header[:depth] == prefix:
                    return start + 1
        return 1

    def _key_line(self, start, end, rest) -> int | None:
        for n in range(start, end):
            raw = self.lines[n]
            match = re.match(rf"\s*({_KEY}(?:\s*\.\s*{_KEY})*)\s*=", raw)
            if not match:
                continue
            keys = _split_keys(match.group(1))
            if keys and tuple(keys[: len(rest)]) == tuple(rest[: len(keys)]):
                return n + 1
        return None

    def error(self, message: str, keys: tuple[str, ...], *, line: int | None = None):
        return ModelFileError(message, path=self.path, line=line or self.line(keys),
                              field=".".join(keys) if keys else None)


# --------------------------------------------------------------------------------- values


class Reader:
    """Typed access to the parsed document, with unit conversion and located errors."""

    def __init__(self, source: Source, units: dict[str, float]):
        self.src = source
        self.units = units

    def factor(self, dims) -> float:
        f = 1.0
        for name, e in zip(("length", "force", "angle"), dims, strict=True):
            if e:
                f *= self.units[name] ** e
        return f

    def table(self, value, keys, what: str) -> dict:
        if not isinstance(value, dict):
            raise self.src.error(f"expected a table ({what}); got {shown(value)}.", keys)
        return value

    def keys(self, table: dict, keys, allowed, required=()):
        unknown = [k for k in table if k not in allowed]
        if unknown:
            raise self.src.error(
                f"unknown key '{unknown[0]}'; allowed keys here: {', '.join(allowed)}.",
                (*keys, unknown[0]),
            )
        for k in required:
            if k not in table:
                raise self.src.error(f"missing required key '{k}'.", keys)

    def string(self, value, keys, what="a name") -> str:
        if not isinstance(value, str):
            raise self.src.error(f"expected a string ({what}); got {shown(value)}.", keys)
        return value

    def number(self, value, keys, dims=NONE, *, convert=True) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.src.error(f"expected a number; got {shown(value)}.", keys)
        try:
            x = float(value)
        except OverflowError:
            x = math.inf
        if not math.isfinite(x):
            raise self.src.error(f"expected a finite number; got {value}.", keys)
        f = self.factor(dims) if convert else 1.0
        x = x * f if f != 1.0 else x
        if abs(x) > MAX_MAGNITUDE:
            raise self.src.error(
                f"{value} is out of range (|value| ≤ {MAX_MAGNITUDE:g} in mm, N, rad); check "
                "the number and the [units].", keys)
        return x

    def vector(self, value, keys, dims=NONE, *, scalar=False, convert=True) -> np.ndarray:
        if scalar and not isinstance(value, list):
            return np.full(3, self.number(value, keys, dims, convert=convert))
        if not isinstance(value, list) or len(value) != 3:
            what = "a number or a list of 3 numbers" if scalar else "a list of 3 numbers"
            raise self.src.error(f"expected {what}; got {shown(value)}.", keys)
        return np.array([self.number(v, keys, dims, convert=convert) for v in value])

    def numbers(self, value, keys, dims=NONE) -> np.ndarray:
        if not isinstance(value, list) or len(value) < 2:
            raise self.src.error(f"expected a list of at least 2 numbers; got {shown(value)}.",
                                 keys)
        return np.array([self.number(v, keys, dims) for v in value])

    def xy(self, value, keys, dims_x, dims_y):
        table = self.table(value, keys, "with x and y lists")
        self.keys(table, keys, ("x", "y"), ("x", "y"))
        return (self.numbers(table["x"], (*keys, "x"), dims_x),
                self.numbers(table["y"], (*keys, "y"), dims_y))


def shown(value) -> str:
    """How a value read from a file is named in an error message ("the number 3", ...)."""
    if isinstance(value, bool):
        return f"a boolean ({str(value).lower()})"
    if isinstance(value, int | float):
        return f"the number {value}"
    if isinstance(value, str):
        text = value if len(value) <= 40 else value[:37] + "..."
        return f"the string {text!r}"
    if isinstance(value, list):
        return f"a list of {len(value)} items"
    if isinstance(value, dict):
        return "a table"
    return type(value).__name__
