"""Where a result came from: versions, git revision, command, host, and times, as attributes.

Every run file carries these (``runfile.RunWriter``), so that a result found years later says
which code, libraries and command made it, on which machine and when. The one place that
asks git: the run files' ``git_revision`` and the benchmark's short ``git_describe``.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import platform
import shlex
import socket
import subprocess
import sys
from functools import lru_cache
from importlib import metadata
from pathlib import Path

from ._version import __version__


def now() -> str:
    """The time now, ISO 8601 in UTC to the second (``2025-01-31T12:00:00Z``)."""
    return _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def versions(extra: tuple[str, ...] = ()) -> dict[str, str]:
    """``{"taichi_ice_version", "taichi_version", "numpy_version", "h5py_version",
    "python_version"}`` and ``"<dist>_version"`` of each distribution in ``extra``; a library
    that is not installed reads "not installed"."""
    out = {"taichi_ice_version": __version__, "python_version": platform.python_version()}
    for dist in ("taichi", "numpy", "h5py", *extra):
        try:
            out[f"{dist}_version"] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[f"{dist}_version"] = "not installed"
    return out


def _git(*args: str) -> str | None:
    """What ``git -C <the package's folder> ARGS`` prints, stripped; None when it fails, the
    package is not a git checkout (an installed wheel) or git is missing."""
    here = Path(__file__).resolve().parent
    with contextlib.suppress(OSError, subprocess.SubprocessError):
        return subprocess.run(
            ["git", "-C", str(here), *args],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
    return None


@lru_cache(maxsize=1)
def git_revision() -> str:
    """The commit the package runs from (``+dirty`` if its tree has changes), or "" when it is
    not a git checkout (an installed wheel) or git is missing."""
    rev = _git("rev-parse", "HEAD")
    dirty = _git("status", "--porcelain", "--untracked-files=no", ".")
    if rev is None or dirty is None:
        return ""
    return f"{rev}+dirty" if dirty else rev


def git_describe() -> str | None:
    """``git describe --always --dirty`` of the package's checkout (``c48739b-dirty``: what
    ``taichi-ice bench`` records), or None when it is not one or git is missing."""
    return _git("describe", "--always", "--dirty")


def command() -> str:
    """The command line of this process, quoted as a shell would need it."""
    return " ".join(shlex.quote(a) for a in [Path(sys.argv[0]).name, *sys.argv[1:]])


def run_attributes() -> dict[str, str]:
    """Everything above as root attributes of an output file (``started`` is now)."""
    return {
        **versions(),
        "git_revision": git_revision(),
        "command": command(),
        "host": socket.gethostname(),
        "started": now(),
    }


__all__ = ["command", "git_describe", "git_revision", "now", "run_attributes", "versions"]
