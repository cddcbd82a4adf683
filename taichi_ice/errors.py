"""Errors that taichi-ice raises for a user's mistake or a run that cannot go on.

Each is a ``ValueError`` or ``RuntimeError`` subclass so that callers who do not know
taichi-ice can still catch them; the command line turns every one of them into a one-line
message with no traceback.
"""

from __future__ import annotations


class TaichiIceError(Exception):
    """Base of every error taichi-ice raises on purpose."""


class StabilityError(TaichiIceError, ValueError):
    """A time step above the stability limit of the chosen method.

    Raised before anything is integrated; the message names the limit and how to pass it
    deliberately (``check_stability=False`` for a study, ``--force``/``force_dt`` in a run).
    """


class ScenarioError(TaichiIceError, ValueError):
    """A scene file or scene dictionary that is not valid.

    The message names the file, the table and the key, and says how to fix it.
    """


class PolygonError(TaichiIceError, ValueError):
    """A polygon that is not a valid floe: non-convex, clockwise, degenerate or not finite."""


class CapacityError(TaichiIceError, RuntimeError):
    """A fixed-size buffer (contact slots, hash cells) overflowed during a run."""


class DivergenceError(TaichiIceError, RuntimeError):
    """A run produced non-finite or runaway values and was stopped."""
