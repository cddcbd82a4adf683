"""What a command that writes a folder of runs has finished, so that ``--resume`` goes on.

``taichi-ice ensemble`` (a Simulation per law) and ``taichi-ice paper`` (Figure 3, then a
Simulation per model) are made of parts. The ledger ``DIR/<command>-state.json`` holds the
options the results depend on and, per part, ``started`` or ``done`` (with what the part's
result needs besides its run files: status, failure, steps, dt, wall time). It is written
whole or not at all (write, fsync, rename), so a kill at any instant leaves it readable.

A resume (``resume=True``) reads it, refuses other options with one line naming them, skips
the parts done (their results are read back from their run files) and continues a part that
was started from its Simulation's checkpoint (``checkpoint``), when it wrote one; a part
started without a checkpoint runs again from its start. Without ``resume``, a folder that
holds a ledger or any of the command's outputs is refused unless ``overwrite``. A lock beside
the ledger (``output.RunLock``) keeps two commands out of one folder.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from .._version import __version__
from ..errors import OutputError
from ..scene.table import printable

FORMAT_VERSION = "2"  # 2: a digest of the record (a damaged ledger is refused)


def scene_digest(scene) -> str:
    """SHA-1 of a scene's text and resolved ice (``Scene.identity``): what a resume compares
    (the text itself is long)."""
    return hashlib.sha1(scene.identity.encode()).hexdigest()


def _plain(value: Any) -> Any:
    """``value`` as it reads back from JSON (tuples as lists ...), for comparisons."""
    return json.loads(json.dumps(value))


def _short(value: Any, width: int = 60) -> str:
    text = json.dumps(value)
    return text if len(text) <= width else text[: width - 3] + "..."


def record_digest(record: Mapping[str, Any]) -> str:
    """SHA-256 of a JSON record without its ``digest``: a byte damaged on disk that still
    parses (a status, a step count) changes it, and the record is refused, not believed."""
    rest = {k: v for k, v in record.items() if k != "digest"}
    return hashlib.sha256(json.dumps(rest, sort_keys=True, allow_nan=True).encode()).hexdigest()


class Ledger:
    """The ledger of one command's output folder; use as a context manager (it holds a lock).

    Args:
        folder: the output folder (checked and made already: ``output.check_folder``).
        command: the command's name (``ensemble``, ``paper``): the file is
            ``<command>-state.json``.
        options: what the results depend on (JSON-able); a resume must give the same.
        resume: continue the folder's earlier command (its ledger must exist).
        overwrite: start anew over an earlier command's output.
        outputs: the paths the command writes: any that exists (without ``resume``) is an
            earlier command's output, refused unless ``overwrite``.
        checkpoint_every: wall-clock seconds between checkpoints (None: none); a resume that
            gives None keeps the earlier command's.

    Raises:
        OutputError: another command holds the folder, the folder holds an earlier command's
            output (without ``resume`` or ``overwrite``), a resume finds no ledger, or its
            options differ.
    """

    def __init__(
        self,
        folder: str | Path,
        command: str,
        options: Mapping[str, Any],
        *,
        resume: bool = False,
        overwrite: bool = False,
        outputs: Iterable[str | Path] = (),
        checkpoint_every: float | None = None,
    ):
        from ..run.output import RunLock

        self.folder = Path(folder)
        self.command = command
        self.path = self.folder / f"{command}-state.json"
        self.options = _plain({"taichi_ice": __version__, **options})
        self.resumed = resume
        self._lock = RunLock(self.path)
        self._lock.acquire()
        try:
            if resume:
                old = self._read()
                self._check(old["options"])
                self.parts: dict[str, dict] = dict(old.get("parts", {}))
                self.checkpoint_every = (
                    checkpoint_every if checkpoint_every is not None else old["checkpoint_every"]
                )
            else:
                found = [Path(p) for p in (self.path, *outputs) if Path(p).exists()]
                if found and not overwrite:
                    names = ", ".join(str(p.relative_to(self.folder)) for p in found[:3])
                    more = f" and {len(found) - 3} more" if len(found) > 3 else ""
                    raise OutputError(
                        f"{self.folder}: holds the output of an earlier {command} ({names}{more}); "
                        "pass --resume to continue it, --overwrite to start anew over it, or "
                        "give another --out"
                    )
                self.parts = {}
                self.checkpoint_every = checkpoint_every
            self._save()
        except BaseException:
            self._lock.release()
            raise

    # ----------------------------------------------------------------------------------------

    def __enter__(self) -> Ledger:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Release the folder's lock (the ledger stays)."""
        self._lock.release()

    def _read(self) -> dict:
        if not self.path.is_file():
            raise OutputError(
                f"{self.folder}: no {self.command} to resume here (no {self.path.name}); run "
                "it without --resume first"
            )
        try:
            old = json.loads(self.path.read_text())
            if str(old["format_version"]) != FORMAT_VERSION:
                raise ValueError(f"format {old['format_version']}")
            missing = {"options", "parts", "checkpoint_every"} - set(old)
            if missing:
                raise KeyError(", ".join(sorted(missing)))
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise OutputError(
                f"{self.path}: not a {self.command} ledger this version reads "
                f"({printable(exc)}); start anew with --overwrite"
            ) from None
        if old.get("digest") != record_digest(old):
            raise OutputError(
                f"{self.path}: a damaged ledger (its contents do not match the digest written "
                "with them); start anew with --overwrite"
            )
        return old

    def _check(self, old: Mapping[str, Any]) -> None:
        keys = list(self.options) + [k for k in old if k not in self.options]
        diff = [k for k in keys if old.get(k) != self.options.get(k)]
        if not diff:
            return
        said = "; ".join(
            f"{k}: {_short(old.get(k))} there, {_short(self.options.get(k))} now"
            if k != "scene"
            else "the scene differs"
            for k in diff
        )
        raise OutputError(
            f"{self.folder}: the {self.command} there ran with other options ({said}); resume "
            "with the same options, or start anew with --overwrite"
        )

    def _save(self) -> None:
        record = {
            "format_version": FORMAT_VERSION,
            "command": self.command,
            "options": self.options,
            "checkpoint_every": self.checkpoint_every,
            "parts": self.parts,
        }
        record["digest"] = record_digest(record)
        tmp = self.path.with_name(self.path.name + ".tmp")
        with open(tmp, "w") as fh:
            fh.write(json.dumps(record, indent=1, allow_nan=True) + "\n")
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, self.path)

    # ----------------------------------------------------------------------------------------

    def done(self, part: str) -> dict | None:
        """What ``finish`` recorded of ``part``, or None if it has not finished."""
        entry = self.parts.get(part)
        return entry if entry and entry.get("state") == "done" else None

    def started(self, part: str) -> bool:
        """Whether ``part`` was started (and has not finished)."""
        return (self.parts.get(part) or {}).get("state") == "started"

    def start(self, part: str) -> None:
        self.parts[part] = {"state": "started"}
        self._save()

    def finish(self, part: str, **record: Any) -> None:
        self.parts[part] = {"state": "done", **_plain(record)}
        self._save()


__all__ = ["FORMAT_VERSION", "Ledger", "record_digest", "scene_digest"]
