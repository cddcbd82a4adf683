"""Checkpoints: the whole state of a run, so that a killed run continues bit for bit.

A checkpoint is an HDF5 file beside the run file (``RUN.h5.ckpt``), written whole to
``RUN.h5.ckpt.tmp`` and then renamed over the last one (``os.replace``, atomic on POSIX): a
kill at any instant leaves the previous checkpoint or the new one, never a part of one.

What it holds is read from the engine, not listed here, so that it follows the state's
declaration (``taichi_ice.engine.schema``) as fields come and go:

- ``/data/<name>``: every field of the batch's mutable state (``World.data``: positions,
  velocities, contact memory with theta and spring stretch, energy accumulators, probe
  impulses, status word ...), as ``to_numpy`` gives it;
- ``/nbr/<name>``: the neighbour lists (``World.neighbours``), so that they are rebuilt at the
  same steps as in a run that was never stopped;
- ``/host/initial_energy``: the energy table at t = 0 (the budget's starting capital);
- attributes: ``steps``, ``time``, ``dt``, ``precision``, ``n_samples`` and ``n_frames``
  (rows of each run file written when it was taken, JSON lists), ``scenarios`` (each
  scene's text and the ``[ice]`` values it resolved to: ``Scene.identity``),
  ``frictions`` and ``grids`` (the digests of the scenes' current and wind grid files) (JSON
  lists: a resume must be the same run), ``run_ids`` (the ``run_id`` of
  each run file, JSON list: a resume must continue the same files), ``format_version`` and
  ``written`` (UTC);
- ``digest``: SHA-256 of every array and attribute above (``written`` aside). HDF5 keeps no
  checksum of its data, so a flipped bit in a field would otherwise be restored into the
  run and carried on silently; a checkpoint whose digest differs is refused.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
from pathlib import Path

import h5py
import numpy as np

from .. import provenance
from ..engine import schema
from ..errors import OutputError, RunFileError
from ..scene.table import printable
from .runfile_read import DAMAGE

FORMAT_VERSION = "13"  # 2: contact memory single-buffered (no buffer axis, no contact_area);
#                       3: a status word per world;
#                       4: each contact's stick-spring energy, a severed energy column;
#                       5: a body's rotation (body_rot) instead of its turned outline;
#                       6: the neighbour lists' gaps and paths (nbr_gap, nbr_path);
#                       7: a digest of everything in it (damage is refused, not restored)
#                       8: the integrator (euler, analytic; coupled, midstep since),
#                          whose state differs
#                       9: fields at the layout's capacities (assemble.capacity)
#                       10: the forcing's energy columns and clock (body_time)
#                       11: the analytic steps' contact booking (contact_booking)
#                       12: each scene with the [ice] it resolved to (Scene.identity),
#                           since a default changed (slide_resolution, 2026-11-27)
#                       13: the scenes' bodies' and probes' rows only, not the
#                           capacities' (which grew: assemble.CAPACITY_FLOORS)
SUFFIX = ".ckpt"


def path_for(run_path: str | Path) -> Path:
    """The checkpoint of a run file: ``RUN.h5`` -> ``RUN.h5.ckpt``."""
    return Path(f"{run_path}{SUFFIX}")


def identity(sim) -> dict:
    """What a resumed run must share with the run it continues (JSON-able)."""
    return {
        # the text and the [ice] it resolved to: a default that changed is another run
        "scenarios": [s.identity for s in sim.scenes],
        "frictions": [json.dumps(s.friction.to_dict(), sort_keys=True) for s in sim.scenes],
        "dt": float(sim.dt),
        "precision": sim.precision,
        "integrator": sim.options.integrator,
        # A scene's text names its grid files, not what they held: their digests.
        "grids": [_grid_digests(s) for s in sim.scenes],
    }


def _grid_digests(scene) -> list[str]:
    """SHA-256 of the current's and the wind's grid of ``scene`` (those it has)."""
    fields = (
        scene.water.current if scene.water is not None else None,
        scene.wind.velocity if scene.wind is not None else None,
    )
    return [f.digest for f in fields if hasattr(f, "digest")]


def state(world) -> dict:
    """``{group: {name: array}}``: every field a run's state is, read back (what a checkpoint
    holds and ``put_state`` puts back), in one launch (``World.transfer``): the rows of the
    scenes' bodies and probes, not the capacity's (``_rows``), which no kernel touches, so
    that a small scene's checkpoint is its own size."""
    arrays = world.transfer.read()
    return {
        group: {name: arrays[name][_rows(world, name)] for name in container.names}
        for group, container in (("data", world.data), ("nbr", world.neighbours))
    }


# The axes cut to the scenes' counts in a checkpoint. Not the worlds': a world past the
# scenes' has no bodies, but a GPU's kernel per stage still writes its rows of the per-world
# fields (its lists' staleness: found on Vulkan), and a resumed run must hold them too.
SCENE_AXES = ("n_bodies", "n_probes")


def _rows(world, name: str) -> tuple[slice, ...]:
    """The part of field ``name`` a checkpoint holds: the scenes' rows (``Batch.real``'s
    counts) along ``SCENE_AXES``, the whole of every other axis."""
    v = schema.var(name)
    real = schema.allocated_shape(world.batch.real, v)
    return tuple(
        slice(0, n) if axis in SCENE_AXES else slice(None) for axis, n in zip(v.shape, real)
    )


def put_state(sim, arrays: dict, steps: int, initial_energy, where: str | Path) -> None:
    """Put ``state``'s ``arrays`` into ``sim``'s World, ``steps`` steps of its dt done.

    Raises:
        RunFileError: the arrays are not this World's fields (``where`` names their source).
    """
    world = sim.world
    # The fields a checkpoint does not hold, and the rows past the scenes', stay as they are.
    current = world.transfer.read()
    for group, container in (("data", world.data), ("nbr", world.neighbours)):
        names = set(container.names)
        saved = arrays[group]
        if set(saved) != names:
            raise RunFileError(
                f"{where}: the checkpoint's state ({sorted(set(saved) ^ names)} differ) "
                "is of another version of taichi-ice; start anew with --overwrite"
            )
        for name in container.names:
            array = np.asarray(saved[name])
            rows = _rows(world, name)
            want = current[name][rows].shape
            if tuple(array.shape) != want:
                raise RunFileError(
                    f"{where}: field {name} has shape {array.shape} in the checkpoint; this "
                    f"run's is {want}: start anew with --overwrite"
                )
            current[name][rows] = array
    world.transfer.write(current)
    sim.initial_energy = np.asarray(initial_energy).copy()
    world.steps = int(steps)
    world.time = world.steps * world.dt


def write(sim, path: str | Path, n_samples, n_frames, run_ids=None) -> Path:
    """Write ``sim``'s whole state to ``path`` atomically (write, fsync, rename);
    ``run_ids``: the run files' ``run_id`` attributes, checked on resume."""
    from .runfile import check_room

    path = Path(path)
    world = sim.world
    tmp = path.with_name(path.name + ".tmp")
    arrays = state(world)
    size = sum(a.nbytes for g in arrays.values() for a in g.values())
    # The last checkpoint stays until the new one is whole; a disk without room for both
    # stops the run here, before the new one is begun.
    check_room(path, 2 * size, "the checkpoint")
    try:
        _write(sim, tmp, arrays, run_ids, n_samples, n_frames)
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
    except OSError as exc:
        remove(tmp)
        raise OutputError(
            f"{path}: the checkpoint could not be written ({exc}); the last one is kept"
        ) from None
    os.replace(tmp, path)
    return path


def _write(sim, tmp: Path, arrays: dict, run_ids, n_samples, n_frames) -> None:
    world = sim.world
    with h5py.File(tmp, "w") as f:
        for group, named in arrays.items():
            g = f.create_group(group)
            for name, array in named.items():
                g.create_dataset(name, data=array)
        f.create_group("host").create_dataset("initial_energy", data=sim.initial_energy)
        ident = identity(sim)
        f.attrs["format_version"] = FORMAT_VERSION
        f.attrs["written"] = provenance.now()
        f.attrs["steps"] = int(world.steps)
        f.attrs["time"] = float(world.time)
        f.attrs["dt"] = ident["dt"]
        f.attrs["precision"] = ident["precision"]
        f.attrs["integrator"] = ident["integrator"]
        f.attrs["scenarios"] = json.dumps(ident["scenarios"])
        f.attrs["frictions"] = json.dumps(ident["frictions"])
        f.attrs["grids"] = json.dumps(ident["grids"])
        f.attrs["n_samples"] = json.dumps([int(n) for n in n_samples])
        f.attrs["n_frames"] = json.dumps([int(n) for n in n_frames])
        if run_ids is not None:
            f.attrs["run_ids"] = json.dumps([str(r) for r in run_ids])
        groups = {**arrays, "host": {"initial_energy": np.asarray(sim.initial_energy)}}
        f.attrs["digest"] = digest(groups, dict(f.attrs))


def digest(groups: dict, attrs: dict) -> str:
    """SHA-256 of a checkpoint's arrays (``{group: {name: array}}``: names, dtypes, shapes
    and bytes) and attributes (but ``written`` and ``digest``), in a fixed order."""
    h = hashlib.sha256()
    for group in sorted(groups):
        # A damaged name may not be UTF-8 (h5py gives it as bytes): it stays in the digest.
        for name in sorted(groups[group], key=_text):
            a = np.ascontiguousarray(groups[group][name])
            h.update(f"{group}/{_text(name)}:{a.dtype.str}:{a.shape}".encode(*_SURROGATES))
            h.update(a.tobytes())
    for key in sorted(attrs, key=_text):
        if key not in ("written", "digest"):
            # A damaged attribute may hold bytes that are not UTF-8: they stay in the digest.
            h.update(f"{_text(key)}={_text(attrs[key])}".encode(*_SURROGATES))
    return h.hexdigest()


_SURROGATES = ("utf-8", "surrogateescape")


def _text(value):
    """``value``, or the text of bytes (kept whole: undecodable bytes as surrogates)."""
    return value.decode(*_SURROGATES) if isinstance(value, bytes) else value


def read(path: str | Path) -> dict:
    """A checkpoint as ``{"attrs": {...}, "data": {...}, "nbr": {...}, "host": {...}}``.

    Raises:
        RunFileError: no checkpoint, or not a checkpoint file.
    """
    path = Path(path)
    if not path.is_file():
        raise RunFileError(
            f"{path}: no checkpoint to resume from; the run wrote none (run with "
            "--checkpoint-every, e.g. 10min), or it was never started"
        )
    try:
        with h5py.File(path, "r") as f:
            out = {
                "attrs": {
                    k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()
                }
            }
            for group in ("data", "nbr", "host"):
                out[group] = {name: ds[()] for name, ds in f[group].items()}
    except DAMAGE as exc:
        reason = printable(str(exc).strip().splitlines()[0] if str(exc).strip() else exc)
        raise RunFileError(
            f"{path}: not a taichi-ice checkpoint, or a damaged one ({reason}); start anew "
            "with --overwrite"
        ) from None
    if str(out["attrs"].get("format_version")) == FORMAT_VERSION:
        groups = {g: out[g] for g in ("data", "nbr", "host")}
        if out["attrs"].get("digest") != digest(groups, out["attrs"]):
            raise RunFileError(
                f"{path}: a damaged checkpoint (its contents do not match the digest written "
                "with them); start anew with --overwrite"
            )
    # (Another format is refused by ``restore``, naming the versions.)
    for key in ("scenarios", "frictions", "grids", "n_samples", "n_frames", "run_ids"):
        if key == "run_ids" and key not in out["attrs"]:
            continue  # written before run ids: the rows are still checked
        try:
            out["attrs"][key] = json.loads(out["attrs"][key])
        except (KeyError, TypeError, ValueError):
            raise RunFileError(
                f"{path}: a damaged checkpoint (attribute {key} missing or unreadable); "
                "start anew with --overwrite"
            ) from None
    return out


def restore(sim, ckpt: dict, where: str | Path) -> None:
    """Put a checkpoint's state into ``sim`` (same scenes, dt, precision: checked).

    Raises:
        RunFileError: the checkpoint is of another run, or its fields do not fit.
    """
    a = ckpt["attrs"]
    if str(a.get("format_version")) != FORMAT_VERSION:
        raise RunFileError(
            f"{where}: the checkpoint is of format {a.get('format_version')}, written by another "
            f"version of taichi-ice (this one reads format {FORMAT_VERSION}); resume it with "
            "that version, or start anew with --overwrite"
        )
    ident = identity(sim)
    # The law first: a scene's text holds its [friction] table, so another law (--friction)
    # would otherwise be reported as another scene. The integrator next: a scene's dt =
    # "auto" follows it (Coulomb's default changed from euler to midstep on 2026-12-02).
    if a["frictions"] == ident["frictions"] and a["integrator"] != ident["integrator"]:
        raise RunFileError(
            f"{where}: the checkpoint is of another run (its integrator differs from this "
            f"one's: it stepped with {a['integrator']}, this run with {ident['integrator']}); "
            f'resume with --integrator {a["integrator"]} (integrator="{a["integrator"]}"), '
            "or start anew with --overwrite"
        )
    for key, now, then in (
        ("friction law", ident["frictions"], a["frictions"]),
        ("scene", ident["scenarios"], a["scenarios"]),
        ("forcing grid files' contents", ident["grids"], a["grids"]),
        ("dt", ident["dt"], float(a["dt"])),
        ("precision", ident["precision"], a["precision"]),
        ("integrator", ident["integrator"], a["integrator"]),
    ):
        if now != then:
            raise RunFileError(
                f"{where}: the checkpoint is of another run (its {key} differs from this "
                "one's); resume with the same scene and options, or start anew with --overwrite"
            )
    put_state(sim, ckpt, int(a["steps"]), ckpt["host"]["initial_energy"], where)


def remove(path: str | Path) -> None:
    """Delete a checkpoint (a run that completed needs none)."""
    for p in (Path(path), Path(path).with_name(Path(path).name + ".tmp")):
        with contextlib.suppress(FileNotFoundError):
            p.unlink()


__all__ = [
    "FORMAT_VERSION",
    "SUFFIX",
    "identity",
    "path_for",
    "put_state",
    "read",
    "remove",
    "restore",
    "state",
    "write",
]
