"""Typed, checked access to the tables of a scene file.

Every value read through a :class:`Table` is checked (type, finiteness, sign, allowed
words), and every error is a ``ScenarioError`` that names the file, the table
(``[[body]] #3 'pillar'``) and the key, and says how to fix it; an unknown key gets the
closest known one as a suggestion. ``taichi_ice.scene.parse`` reads every table with it.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..errors import PolygonError, ScenarioError
from ..physics import polygon
from ..readonly import frozen

__all__ = ["REQUIRED", "Table", "array_of_tables", "check_keys", "is_number", "type_name"]

# Default of a key that must be given: reading it when absent is an error.
REQUIRED = object()

# What TOML numbers, booleans and arrays arrive as (NumPy too, for scenes built in code);
# tuples for isinstance, which takes `X | Y` only from Python 3.10.
_NUMBERS = (int, float, np.integer, np.floating)
_BOOLEANS = (bool, np.bool_)
_ARRAYS = (list, tuple, np.ndarray)


def is_number(v: Any) -> bool:
    """True for an int or float (NumPy too), False for a boolean, which Python counts as one."""
    return isinstance(v, _NUMBERS) and not isinstance(v, _BOOLEANS)


def type_name(v: Any) -> str:
    """What ``v`` is, in the scene file's words, for messages: ``a string ("2.0")``."""
    if isinstance(v, _BOOLEANS):
        return f"a boolean ({str(bool(v)).lower()})"
    if isinstance(v, str):
        return f'a string ("{v}")'
    if is_number(v):
        return f"a number ({v})"
    if isinstance(v, Mapping):
        return "a table"
    if isinstance(v, _ARRAYS):
        return "an array"
    return f"a {type(v).__name__}"


def _suggest(key: str, known: Sequence[str]) -> str:
    lower = {k.lower(): k for k in known}
    close = difflib.get_close_matches(key.lower(), list(lower), n=1, cutoff=0.6)
    hint = f"did you mean '{lower[close[0]]}'? " if close else ""
    return f"{hint}known keys: {', '.join(known)}"


def printable(text: Any) -> str:
    """``text`` with each character that does not print (a newline, a NUL, a control
    character) written as its escape, so that a message that quotes it stays one line."""
    text = str(text)
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def check_keys(source: str, label: str, data: Mapping, known: Sequence[str], what="key") -> None:
    """Refuse the first key of ``data`` not in ``known``, suggesting the closest known one."""
    for key in data:
        if key not in known:
            raise ScenarioError(
                f"{source}: {label}: unknown {what} '{printable(key)}'; {_suggest(key, known)}"
            )


class Table:
    """Typed, checked access to one table; every error names the file, table and key."""

    def __init__(self, source: str, label: str, data: Any, known: Sequence[str]):
        self.source, self.label = source, label
        if not isinstance(data, Mapping):
            raise ScenarioError(f"{source}: {label} must be a table, got {type_name(data)}")
        self.data = data
        check_keys(source, label, data, known)

    def error(self, key: str, message: str) -> ScenarioError:
        """The error for ``key``, its message prefixed with the file, the table and the key."""
        return ScenarioError(f"{self.source}: {self.label}, key '{printable(key)}': {message}")

    def __contains__(self, key: str) -> bool:
        return key in self.data

    def get(self, key: str, default: Any) -> Any:
        """The value as given, unchecked; ``default`` when absent (an error if REQUIRED)."""
        if key in self.data:
            return self.data[key]
        if default is REQUIRED:
            raise self.error(key, "missing; this key is required")
        return default

    def as_number(self, key: str, v: Any, what: str = "a number") -> float:
        """``v`` (read from ``key``) as a finite float; ``what`` says what was expected."""
        if not is_number(v):
            fix = ""
            if isinstance(v, str):
                try:
                    float(v)
                    fix = "; remove the quotes"
                except ValueError:
                    pass
            raise self.error(key, f"expected {what}, got {type_name(v)}{fix}")
        x = float(v)
        if not math.isfinite(x):
            raise self.error(key, f"must be a finite number, got {x}")
        return x

    def number(
        self,
        key: str,
        default: Any = REQUIRED,
        *,
        positive: bool = False,
        nonnegative: bool = False,
        unit: str = "",
    ) -> float:
        v = self.get(key, default)
        if v is default and key not in self.data:
            return v
        x = self.as_number(key, v)
        if positive and x <= 0.0:
            raise self.error(key, f"must be positive, got {x:g}{unit}")
        if nonnegative and x < 0.0:
            raise self.error(key, f"must not be negative, got {x:g}{unit}")
        return x

    def angle(self, key: str, default: Any = REQUIRED) -> float:
        """A number of radians; more than a full turn is refused, since it is almost always
        degrees written where radians are meant (``angle = 10`` for 10 degrees)."""
        x = self.number(key, default)
        if x is not default and abs(x) > 2.0 * math.pi:
            raise self.error(
                key,
                f"{x:g} rad is more than a full turn; angles are in radians: for {x:g} "
                f"degrees write {math.radians(x):.6g}, and a turn past 2 pi as the angle less "
                "whole turns",
            )
        return x

    def integer(self, key: str, default: Any = REQUIRED, *, minimum: int | None = None) -> int:
        v = self.get(key, default)
        if v is default and key not in self.data:
            return v
        if not isinstance(v, (int, np.integer)) or isinstance(v, _BOOLEANS):
            raise self.error(
                key, f"expected a whole number (like 3, no decimal point), got {type_name(v)}"
            )
        if minimum is not None and v < minimum:
            raise self.error(key, f"must be at least {minimum}, got {v}")
        return int(v)

    def boolean(self, key: str, default: bool) -> bool:
        v = self.get(key, default)
        if not isinstance(v, _BOOLEANS):
            raise self.error(key, f"expected true or false, got {type_name(v)}")
        return bool(v)

    def string(
        self, key: str, default: Any = REQUIRED, choices: Sequence[str] | None = None
    ) -> str:
        v = self.get(key, default)
        if not isinstance(v, str):
            raise self.error(key, f"expected a string, got {type_name(v)}")
        if choices is not None and v not in choices:
            allowed = " | ".join(f'"{c}"' for c in choices)
            raise self.error(key, f'unknown value "{v}"; allowed: {allowed}')
        return v

    def vector(self, key: str, default: Any = REQUIRED, *, positive: bool = False) -> np.ndarray:
        v = self.get(key, default)
        if not isinstance(v, _ARRAYS) or len(v) != 2:
            raise self.error(key, f"expected an array of two numbers [x, y], got {type_name(v)}")
        xy = np.array([self.as_number(key, c, "two numbers [x, y]") for c in v])
        if positive and np.any(xy <= 0.0):
            raise self.error(key, f"both components must be positive, got {xy.tolist()}")
        return frozen(xy)

    def polygon(self, key: str) -> np.ndarray:
        v = self.get(key, REQUIRED)
        if not isinstance(v, _ARRAYS) or not all(
            isinstance(p, _ARRAYS) and len(p) == 2 and all(map(is_number, p)) for p in v
        ):
            raise self.error(
                key, "expected an array of [x, y] number pairs, like [[0, 0], [1, 0], [0, 1]]"
            )
        try:
            return polygon.check_polygon(v, what=f"{self.source}: {self.label}, key '{key}'")
        except PolygonError as exc:
            raise ScenarioError(str(exc)) from None


def array_of_tables(source: str, data: Mapping, key: str) -> list:
    """The array of tables ``[[key]]`` of ``data`` (empty when absent), unchecked inside."""
    v = data.get(key, [])
    if isinstance(v, Mapping):
        raise ScenarioError(
            f"{source}: '{key}' must be an array of tables: write [[{key}]] (double brackets), "
            f"not [{key}]"
        )
    if not isinstance(v, (list, tuple)):
        raise ScenarioError(
            f"{source}: '{key}' must be an array of tables [[{key}]], got {type_name(v)}"
        )
    return list(v)
