"""Output paths, claimed before any work starts: an existing run file is refused unless
overwritten on purpose, a folder or an unwritable place is refused with the reason, and a
lock file (``RUN.h5.lock``) names the process that writes the run, so that a second writer
is refused with a message naming the first.

``claim`` / ``release`` a run file (what ``Simulation.run`` and the command line do),
``check_folder`` an output folder (``ensemble --out``, ``paper --out``), ``RunLock`` the lock
itself (ledgers and sweeps take one too). Writing and reading the run file is
``taichi_ice.run.runfile`` and ``taichi_ice.run.runfile_read``.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
from collections.abc import Mapping
from pathlib import Path

from .. import provenance
from ..errors import OutputError

__all__ = ["RunLock", "check_folder", "check_output", "claim", "release"]


def check_folder(path: str | Path, make: bool = True) -> Path:
    """Check that ``path`` can be an output folder (``ensemble --out``, ``paper --out``), and
    make it (``make=False``: only check that it could be made, and leave nothing behind).

    Raises:
        OutputError: the path is a file, lies below a file, or cannot be made or written.
    """
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise OutputError(f"{p}: is a file; --out names a folder of results: give a folder")
    ancestor = p
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if ancestor.exists() and not ancestor.is_dir():
        raise OutputError(f"{p}: cannot be made: {ancestor} is a file, not a folder")
    if not make:
        if not os.access(ancestor, os.W_OK | os.X_OK):  # novermin (flags, not a union type)
            raise OutputError(f"{p}: {ancestor} is not writable; give another --out")
        return p
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{p}: cannot make the folder ({exc.strerror or exc})") from None
    if not os.access(p, os.W_OK | os.X_OK):  # novermin (flags, not a union type)
        raise OutputError(f"{p}: the folder is not writable; give another --out")
    return p


def check_output(path: str | Path, overwrite: bool = False, inputs=()) -> Path:
    """Check that ``path`` can be written as a run file, and make its folder.

    Args:
        path: the output file.
        overwrite: allow replacing an existing file.
        inputs: files the run reads (the scene): never an output.

    Raises:
        OutputError: the path is a folder, an input, an existing file (without
            ``overwrite``), below a file, or in a folder that cannot be made or written.
    """
    p = Path(path)
    if p.is_dir():
        raise OutputError(f"{p}: is a folder; give a file name for the output, e.g. {p / 'run.h5'}")
    for src in inputs:
        with contextlib.suppress(OSError):
            if Path(src).exists() and p.exists() and p.resolve() == Path(src).resolve():
                raise OutputError(
                    f"{p}: is the scene file the run reads; give another --out (e.g. "
                    f"{p.with_suffix('.h5')})"
                )
    if p.exists() and not overwrite:
        raise OutputError(
            f"{p}: exists; pass --overwrite (overwrite=True) to replace it, --resume to "
            "continue it, or give another --out"
        )
    parent = p.parent
    ancestor = parent
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if ancestor.exists() and not ancestor.is_dir():
        raise OutputError(f"{p}: cannot be made: {ancestor} is a file, not a folder")
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{p}: cannot make its folder {parent} ({exc.strerror or exc})") from None
    if not os.access(parent, os.W_OK | os.X_OK):  # novermin (flags, not a union type)
        raise OutputError(f"{p}: the folder {parent} is not writable; give another --out")
    if p.exists() and not os.access(p, os.W_OK):
        raise OutputError(f"{p}: exists and is not writable; give another --out")
    return p


class RunLock:
    """``RUN.h5.lock``: who writes a run file (pid, host, command, since when).

    Made with O_EXCL, so of two processes that claim one path only one succeeds; a lock
    left by a process of this host that no longer exists is taken over.
    """

    def __init__(self, target: str | Path):
        self.target = Path(target)
        self.path = Path(f"{self.target}.lock")
        self.held = False

    def acquire(self) -> None:
        info = {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "command": provenance.command(),
            "since": provenance.now(),
        }
        for _ in range(3):
            try:
                flags = os.O_CREAT | os.O_EXCL | os.O_WRONLY  # novermin (flags, not a union)
                fd = os.open(self.path, flags, 0o644)
            except FileExistsError:
                other = self.owner()
                if self._stale(other):
                    with contextlib.suppress(FileNotFoundError):
                        self.path.unlink()
                    continue
                raise OutputError(
                    f"{self.target}: another run is writing it: pid {other.get('pid', '?')} on "
                    f"{other.get('host', '?')} since {other.get('since', '?')} "
                    f"({other.get('command', '?')}); wait for it, or give another --out (if that "
                    f"run is gone, delete {self.path})"
                ) from None
            except OSError as exc:
                raise OutputError(
                    f"{self.target}: cannot write in {self.path.parent} ({exc.strerror or exc})"
                ) from None
            with os.fdopen(fd, "w") as fh:
                json.dump(info, fh)
            self.held = True
            return
        raise OutputError(f"{self.target}: cannot take its lock {self.path}; delete it and retry")

    def owner(self) -> dict:
        """The lock's record (``{}`` if it cannot be read)."""
        try:
            return dict(json.loads(self.path.read_text()))
        except (OSError, ValueError, TypeError):
            return {}

    @staticmethod
    def _stale(other: Mapping) -> bool:
        """True for a lock of this host whose process is gone."""
        if other.get("host") != socket.gethostname() or not isinstance(other.get("pid"), int):
            return False
        if other["pid"] == os.getpid():
            return False  # this process writes it already (another Simulation)
        try:
            os.kill(other["pid"], 0)
        except ProcessLookupError:
            return True
        except PermissionError:
            return False
        return False

    def release(self) -> None:
        if self.held:
            with contextlib.suppress(FileNotFoundError):
                self.path.unlink()
            self.held = False


# Claims this process holds, by resolved path: the command line claims its output before
# the scene is built, and the run that then writes it finds the claim here.
_CLAIMS: dict[Path, list] = {}


def _key(path: Path) -> Path:
    return path.parent.resolve() / path.name


def claim(path: str | Path, overwrite: bool = False, resume: bool = False, inputs=()) -> Path:
    """Check ``path`` (``check_output``) and lock it for this process; ``release`` frees it.

    A second claim of a path this process holds already passes (it counts). With ``resume``
    the file must exist (it is continued, not replaced).
    """
    p = Path(path)
    key = _key(p) if p.parent.exists() else None
    if key is not None and key in _CLAIMS:
        _CLAIMS[key][1] += 1
        return p
    if resume:
        if not p.is_file():
            raise OutputError(f"{p}: no such run file to resume; run without --resume first")
        check_output(p, overwrite=True, inputs=inputs)
    else:
        check_output(p, overwrite=overwrite, inputs=inputs)
    lock = RunLock(p)
    lock.acquire()
    _CLAIMS[_key(p)] = [lock, 1]
    return p


def release(path: str | Path) -> None:
    """Undo one ``claim`` of ``path``; the last one removes the lock."""
    key = _key(Path(path))
    entry = _CLAIMS.get(key)
    if entry is None:
        return
    entry[1] -= 1
    if entry[1] <= 0:
        entry[0].release()
        del _CLAIMS[key]
