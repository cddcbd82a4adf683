"""Reading run files: ``read_run`` (NumPy), ``open_run`` (one ``xarray.Dataset``), and the
checks that a file is a whole taichi-ice run file and the one a checkpoint recorded.

A file may be read while its run writes it (each read retries if it meets a write), after
the run failed and after it was killed; a file whose bytes were damaged is refused in one
line (``damaged``). The layout and the writer are ``taichi_ice.run.runfile``; this module
writes nothing.
"""

from __future__ import annotations

import contextlib
import time as _time
from pathlib import Path

import h5py
import numpy as np

from ..errors import RunFileError

__all__ = [
    "DAMAGE",
    "check_checkpoint_match",
    "check_resumable",
    "check_run_file",
    "damaged",
    "frame_contacts",
    "open_file",
    "open_run",
    "read_run",
]

# A reader that opens a file at the instant the writer extends it may be refused: retry.
_READ_TRIES = 20
_READ_PAUSE = 0.05  # s


def check_resumable(
    path, run_id: str | None, samples: int, frames: int, contacts: bool | None = None
) -> None:
    """Raise RunFileError unless the run file at ``path`` is the one a checkpoint recorded
    (``run_id``, None: not checked) and holds the ``samples`` and ``frames`` it counts (and
    ``/contacts`` exactly if ``contacts``; None: not checked); the file is only read (a
    batch checks every file before changing any)."""
    with open_file(path) as f:
        check_checkpoint_match(f, path, run_id, samples, frames, contacts=contacts)


def check_checkpoint_match(
    f: h5py.File, path, run_id: str | None, samples: int, frames: int, contacts=None
) -> None:
    """Refuse to resume ``f`` from a checkpoint of another run, or from one that counts more
    rows than the file holds (the file was replaced after the checkpoint was taken); and,
    ``contacts`` not None, a run that writes ``/contacts`` (or not) into a file that does not
    have it (or does)."""
    fix = "start anew with --overwrite (resume=False), which removes the checkpoint"
    if run_id is not None and str(f.attrs.get("run_id", "")) != run_id:
        raise RunFileError(
            f"{path}: its checkpoint belongs to another run (run ids differ: the file was "
            f"replaced or the checkpoint copied from elsewhere); {fix}"
        )
    if contacts is not None and contacts != ("contacts" in f):
        raise RunFileError(
            f"{path}: the run was started {'without' if contacts else 'with'} --contacts "
            f"(contacts={not contacts}); resume it the same way"
        )
    held = (len(f["series"]["time"]), len(f["frames"]["time"]))
    if contacts and len(f["contacts"]["time"]) < frames:
        held = (held[0], len(f["contacts"]["time"]))
    if held[0] < samples or held[1] < frames:
        raise RunFileError(
            f"{path}: holds {held[0]} samples and {held[1]} frames, fewer than the "
            f"{samples} and {frames} its checkpoint counts: the checkpoint is not of this "
            f"file; {fix}"
        )


# What HDF5 raises on a file whose bytes were damaged (a bit flipped, a block cut): a
# checksum or an address that does not add up, a name or a type that no longer decodes.
DAMAGE = (OSError, RuntimeError, KeyError, ValueError, TypeError, UnicodeDecodeError)


def damaged(path, exc: BaseException) -> RunFileError:
    """The one-line error for a run file HDF5 cannot read whole."""
    from ..scene.table import printable

    reason = printable(str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__)
    return RunFileError(
        f"{path}: damaged, HDF5 cannot read it ({reason}); run it again, or use a copy"
    )


def check_run_file(f: h5py.File, path) -> None:
    """Refuse ``f`` unless it has the groups and the status of a taichi-ice run file."""
    missing = [g for g in ("series", "frames", "bodies") if g not in f]
    if missing or "status" not in f.attrs:
        raise RunFileError(
            f"{path}: an HDF5 file, but not a taichi-ice run file (no "
            f"{'/' + missing[0] if missing else 'status attribute'}); give a file that "
            "taichi-ice run wrote"
        )


@contextlib.contextmanager
def open_file(path: str | Path):
    """``h5py.File(path, "r")`` of a run file, retried while a writer extends it.

    Raises:
        RunFileError: no such file, not HDF5, or not a run file.
    """
    p = Path(path)
    if not p.is_file():
        raise RunFileError(
            f"{p}: {'is a folder' if p.is_dir() else 'no such file'}; give a run file (.h5)"
        )
    for attempt in range(_READ_TRIES):
        try:
            f = h5py.File(p, "r", locking=False)
            break
        except OSError as exc:
            if not h5py.is_hdf5(p):
                raise RunFileError(f"{p}: not an HDF5 file; give a run file (.h5)") from None
            if attempt == _READ_TRIES - 1:
                raise RunFileError(f"{p}: cannot be read ({exc})") from None
            _time.sleep(_READ_PAUSE)
    try:
        try:
            check_run_file(f, p)
        except DAMAGE as exc:
            raise damaged(p, exc) from None
        yield f
    finally:
        f.close()


def read_run(path: str | Path) -> dict:
    """Everything in a run file as NumPy arrays: ``{"attrs", "series", "frames", "bodies"}``,
    and ``"contacts"`` if the run wrote them (``runfile_contacts``; ``frame_contacts``
    picks one frame's rows).

    Works on a file that is still being written, whose run failed, or was killed.
    """
    out: dict = {}
    with open_file(path) as f:
        try:
            out["attrs"] = {
                k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()
            }
            for group in ("series", "frames", "bodies", "contacts"):
                if group == "contacts" and group not in f:
                    continue
                out[group] = {}
                for name, ds in f[group].items():
                    data = ds[()]
                    if ds.dtype.kind == "O":
                        data = np.array([x.decode() if isinstance(x, bytes) else x for x in data])
                    out[group][name] = data
        except DAMAGE as exc:
            raise damaged(path, exc) from None
    return out


def frame_contacts(run: dict, frame: int) -> dict[str, np.ndarray]:
    """The contact rows of frame ``frame`` of ``run`` (``read_run``'s), ``{name: array}``
    (every ``/contacts`` variable on ``contact``; none if the run wrote no contacts)."""
    c = run.get("contacts")
    if c is None:
        return {}
    ends = np.cumsum(c["row_size"])
    rows = slice(int(ends[frame] - c["row_size"][frame]), int(ends[frame]))
    return {k: v[rows] for k, v in c.items() if k not in ("time", "row_size")}


def open_run(path: str | Path):
    """A run file as one ``xarray.Dataset`` (loaded into memory; the file is closed).

    Series keep the dimension ``time``; frames are on ``frame_time`` (their ``time``);
    bodies on ``body``, ``vertex``, ``body_edge`` and ``probe``; contacts, if the run wrote
    them, on ``contact`` (their ``row_size`` on ``frame_time``); the root attributes (the
    run's provenance) are the Dataset's. Needs xarray with a netCDF-4 engine
    (``pip install 'taichi-ice[xarray]'``).
    """
    try:
        import xarray as xr
    except ImportError:
        raise RunFileError(
            "open_run needs xarray: pip install 'taichi-ice[xarray]' (or read_run for NumPy)"
        ) from None
    with open_file(path) as f:
        groups = [g for g in ("series", "frames", "bodies", "contacts") if g in f]
    parts = []
    for attempt in range(_READ_TRIES):
        try:
            root = xr.open_dataset(path).load()
            for group in groups:
                with xr.open_dataset(path, group=group) as ds:
                    part = ds.load()
                if group in ("frames", "contacts"):
                    part = part.rename({"time": "frame_time"})
                parts.append(part)
            break
        except (OSError, ValueError):
            parts = []
            if attempt == _READ_TRIES - 1:
                raise
            _time.sleep(_READ_PAUSE)
    merged = xr.merge([root, *parts], combine_attrs="override")
    merged.attrs = dict(root.attrs)
    return merged
