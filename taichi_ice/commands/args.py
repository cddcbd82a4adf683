"""Command-line value types: what ``type=`` of an argparse option calls.

Each turns one option's text into its value or raises ``argparse.ArgumentTypeError`` with
the message argparse prints. Shared by the subcommands' options (``cli``, ``commands.sweep``);
the options themselves, and the commands, are not here.
"""

from __future__ import annotations

import argparse
import math
import re


def parse_friction(text: str):
    """``--friction``: a law in its command-line form (``friction.parse_law``)."""
    from ..physics.friction import LAWS, LawError
    from ..physics.friction_parse import parse_law

    try:
        return parse_law(text)
    except LawError as exc:
        forms = "; ".join(
            f"{name}[:{','.join(f'{k}=..' for k in law.keys())}]" for name, law in LAWS.items()
        )
        raise argparse.ArgumentTypeError(f"--friction {text!r}: {exc} (use {forms})") from None


def parse_dt(text: str):
    """``--dt``: seconds, or None for 'auto' (the scene's time step)."""
    if text == "auto":
        return None
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--dt {text!r}: use 'auto' or seconds") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"--dt {text!r}: must be positive")
    return value


_DURATION_UNITS = {"": 1.0, "s": 1.0, "min": 60.0, "m": 60.0, "h": 3600.0}


def parse_duration(text: str) -> float:
    """``--checkpoint-every``: wall-clock seconds from ``30s``, ``10min``, ``1h`` or ``90``."""
    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*(s|min|m|h|)\s*", text)
    if not m or not math.isfinite(float(m.group(1))):
        raise argparse.ArgumentTypeError(
            f"{text!r}: use a wall-clock duration such as 30s, 10min or 1h"
        )
    return float(m.group(1)) * _DURATION_UNITS[m.group(2)]


def nonnegative_int(text: str) -> int:
    """A whole number, 0 or more (``--every``, ``--workers``)."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: use a whole number, 0 or more")
    return value


def slots_per_body(text: str) -> int:
    """``--slots``: contact slots per body, 1 to ``options.MAX_SLOTS``."""
    from ..engine.options import MAX_SLOTS

    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 1 <= value <= MAX_SLOTS:
        raise argparse.ArgumentTypeError(f"{text!r}: use 1 to {MAX_SLOTS} contact slots per body")
    return value


def positive_float(text: str) -> float:
    """A time in seconds, above 0 and finite (``--until``)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not value > 0 or not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r}: use a time in seconds, above 0")
    return value


def positive_int(text: str) -> int:
    """A whole number, 1 or more (``--seeds``, ``--batch-size``)."""
    value = nonnegative_int(text)
    if value == 0:
        raise argparse.ArgumentTypeError(f"{text!r}: use a whole number, 1 or more")
    return value
