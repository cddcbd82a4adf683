"""A friction law from its written forms: a scene's ``[friction]`` table or the command line's
``--friction rate-state:t_c=2``.

``law_from_table`` and ``parse_law`` are the one parser of both forms; the laws they build,
and what each key means, are declared in ``friction`` (``friction.LAWS``, ``Law.keys``), which
this module only reads. NumPy only, like ``friction``.
"""

import difflib
from collections.abc import Mapping
from typing import Any

import numpy as np

from .friction import LAWS, Law, LawError

__all__ = ["law_from_table", "parse_law"]

# Other spellings the command line accepts.
_ALIASES = {
    "ratestate": "rate-state",
    "rate_state": "rate-state",
    "rs": "rate-state",
    "steady_state": "steady-state",
    "steady": "steady-state",
    "memory_only": "memory-only",
    "memory": "memory-only",
}


def _law_class(name: str, lenient: bool = False) -> type:
    """The law class named ``name``; ``lenient`` (the command line) also takes other cases
    and the spellings in ``_ALIASES``, while scene files must spell the name exactly."""
    key = name
    if lenient:
        key = name.strip().lower()
        key = _ALIASES.get(key, key)
    if key in LAWS:
        return LAWS[key]
    close = difflib.get_close_matches(key.replace("_", "-"), list(LAWS), n=1)
    hint = f'did you mean "{close[0]}"? ' if close else ""
    allowed = " | ".join(f'"{k}"' for k in LAWS)
    raise LawError(f'unknown law "{name}"; {hint}allowed: {allowed}', key="law")


def law_from_table(table: Mapping[str, Any]) -> Law:
    """The law of a ``[friction]`` table: ``{"law": "rate-state", "t_c": 2.0, ...}``.

    ``law`` defaults to ``"coulomb"``; every other key must be one of that law's parameters
    or choices, and parameters must be numbers (not strings).

    Raises:
        LawError: an unknown law or key, a key of another law, a wrong type or an invalid
            value; ``key`` names the key, the message says how to fix it.
    """
    name = table.get("law", "coulomb")
    if not isinstance(name, str):
        raise LawError(f"expected a string, got {name!r}", key="law")
    cls = _law_class(name)
    every = {k: law for law in LAWS.values() for k in law.keys()}
    for key in table:
        if key == "law" or key in cls.keys():
            continue
        if key in every:
            raise LawError(
                f'belongs to law = "{every[key].name}", not law = "{cls.name}"; remove it or '
                "change law",
                key=key,
            )
        known = ("law", *cls.keys())
        close = difflib.get_close_matches(key, known, n=1, cutoff=0.6) or [
            k for k in known if k.lower() == key.lower()
        ]
        hint = f"did you mean '{close[0]}'? " if close else ""
        raise LawError(f"unknown key '{key}'; {hint}known keys: {', '.join(known)}", key=key)
    kwargs: dict[str, Any] = {}
    for p in cls.parameters():
        if p.name in table:
            value = table[p.name]
            if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
                fix = "; remove the quotes" if isinstance(value, str) else ""
                raise LawError(f"expected a number, got {value!r}{fix}", key=p.name)
            kwargs[p.name] = value
    for key in cls.choices:
        if key in table:
            kwargs[key] = table[key]
    try:
        return cls(**kwargs)
    except ValueError as exc:
        bad = next((k for k in cls.keys() if str(exc).startswith(k + " ")), None)
        raise LawError(str(exc), key=bad) from None


def parse_law(text: str) -> Law:
    """A law from its command-line form: ``coulomb``, ``coulomb:0.5``, ``coulomb:mu=0.5``,
    ``rate-state`` or ``rate-state:A=0.05,t_c=2,method=rk4``.

    A bare number after the colon is the law's first parameter.

    Raises:
        LawError: an unknown law or key, or a value that is not valid.
    """
    name, _, args = text.partition(":")
    cls = _law_class(name, lenient=True)
    table: dict[str, Any] = {"law": cls.name}
    for item in filter(None, (a.strip() for a in args.split(","))):
        key, eq, value = item.partition("=")
        if not eq:
            key, value = cls.parameters()[0].name, item
        key = key.strip()
        if key in cls.choices:
            table[key] = value.strip()
            continue
        try:
            table[key] = float(value)
        except ValueError:
            raise LawError(f"{key} must be a number, got {value.strip()!r}", key=key) from None
    return law_from_table(table)
