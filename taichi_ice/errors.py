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


class OutputError(TaichiIceError, ValueError):
    """An output path that cannot be written, or is taken: it exists (and ``--overwrite`` was
    not given), it is a folder, its folder cannot be made or written, or another run holds its
    lock. Raised before any work starts."""


class RunFileError(TaichiIceError, ValueError):
    """A file that is not a taichi-ice run (or checkpoint) file, or one that cannot resume."""


class BackendError(TaichiIceError, RuntimeError):
    """The arch asked for cannot run here (no GPU, no driver); probed in a child process."""


class SizeError(TaichiIceError, ValueError):
    """A scene whose state would not fit in memory, estimated before anything is allocated."""


class Interrupted(TaichiIceError, KeyboardInterrupt):
    """The run was stopped by SIGINT (Ctrl-C) or SIGTERM (``timeout``, batch schedulers).

    A ``KeyboardInterrupt`` too, so that code which catches Ctrl-C catches it; the run stops
    at the end of a stride of steps, with its file closed and (if checkpointing) a checkpoint.
    """


class UsageError(TaichiIceError, ValueError):
    """An argument of the API or the command line that cannot be used: an end time that is
    not a positive finite number of seconds, a dt of 0, an empty batch, and the like."""
