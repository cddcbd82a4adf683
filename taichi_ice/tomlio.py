"""TOML text in and out: ``tomllib`` (``tomli`` before Python 3.11) to read, ``tomli-w`` to write.

The one place that knows which TOML library this Python has. Scene files are read here, and a
scene built in code (or changed by ``scene.reseeded`` / ``Scene.with_friction``) gets its
``text`` from :func:`dump_toml`, which parses back to the same tables.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from typing import Any

import numpy as np
import tomli_w

if sys.version_info >= (3, 11):
    import tomllib  # novm: this branch runs on Python 3.11 and later only
else:  # the tomli backport has the same API
    import tomli as tomllib

__all__ = ["TOMLDecodeError", "dump_toml", "loads"]

TOMLDecodeError = tomllib.TOMLDecodeError


def loads(text: str) -> dict[str, Any]:
    """``tomllib.loads``; arrays or tables nested deeper than Python's recursion limit are a
    TOMLDecodeError too (tomllib recurses once a level and raised RecursionError)."""
    try:
        return tomllib.loads(text)
    except RecursionError:
        raise TOMLDecodeError(
            "arrays or tables nested too deeply to read (more than about a thousand levels)"
        ) from None


def dump_toml(data: Mapping[str, Any]) -> str:
    """Write scene data as TOML text (``tomli_w.dumps``).

    Args:
        data: tables (mappings) of numbers, booleans, strings and arrays, nested as in a
            scene file; NumPy arrays and scalars are accepted wherever a number or an array
            is, and written as plain TOML numbers and arrays.

    Raises:
        TypeError: a value TOML cannot hold (``None``, an object).
    """
    return tomli_w.dumps(_plain(data))


def _plain(v: Any) -> Any:
    """``v`` with NumPy arrays and scalars turned into the Python values tomli-w writes."""
    if isinstance(v, Mapping):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    return v
