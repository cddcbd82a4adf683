"""Running sweeps: a sweep's batches on Dask (or in this process), resumable, into one dataset.

    from taichi_ice.experiments.sweep.spec import load_sweep
    from taichi_ice.experiments.sweep.run import run_sweep
    sweep = load_sweep("sweeps/pillar.toml")
    result = run_sweep(sweep, "out/sweep", workers=2)     # an embedded Dask LocalCluster
    ds = result.dataset()                                  # xarray.Dataset, one row per world

Each batch (``sweep_plan``) is one ``Simulation`` (``ensemble.run_worlds``) and one task on
``dask.distributed``: an embedded ``LocalCluster`` of ``workers`` processes (one Taichi
runtime each, started once per process) or an existing cluster (``scheduler``). Every world
is bit-identical alone and in any batch (the engine sums forces in fixed point), so the
results do not depend on the number of workers or the batch size; a batch that fails (a
world diverged) is run again world by world, so that one world's failure never cuts another
short.

Everything lands in the output folder as it completes: ``batches/batch-<id>.json`` (written
whole or not at all), so a sweep that is interrupted and started again runs only the worlds
no batch file holds. At the end ``sweep.nc`` (netCDF-4,
``taichi_ice.experiments.sweep.dataset``) holds one row per world: the metrics, with units and
long names, the coordinates seed, law and every swept parameter, and which batch ran which
world.

What a sweep is and how its file is checked is ``sweep_spec``'s; the command line is
``cli_sweep``'s.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import sys
import time
from collections.abc import Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..._version import __version__
from ...errors import Interrupted, OutputError, TaichiIceError
from ..ledger import record_digest
from .plan import (
    BODY_STEPS_PER_SECOND,
    batch_seconds,
    batch_spec,
    contact_slots,
    plan_batches,
)
from .spec import Sweep, SweepError, world_scene

__all__ = ["SweepResult", "load_done", "run_batch", "run_sweep"]

# Most workers of the embedded local cluster (one process and one Taichi runtime each).
MAX_WORKERS = 1024

BATCH_DIR = "batches"
DATASET = "sweep.nc"
STATE = "sweep-state.json"
LOG = "sweep-log.json"


def run_batch(spec: dict) -> dict:
    """Run one batch (a Dask task, or in this process): its worlds as one Simulation.

    Taichi starts on the first batch a process runs and stays up for the next ones, and
    so do the Worlds (``pool.POOL``): a batch of a layout this process has run before reuses
    its World, its kernels compiled. ``spec["pad"]`` copies of the last world run along
    (their results dropped). If the batch fails (a world diverged or overflowed), each of
    its worlds is run again alone, so that every world's result is the one it has alone.

    Returns:
        ``{"id", "worker", "wall_time", "world_steps", "worlds": [{"key", "index", "status",
        "failure", "steps", "dt", "metrics"}]}``.
    """
    import socket

    from ...engine.options import Options
    from ...engine.pool import POOL
    from ...scene.parse import parse_scenario
    from ..ensemble import run_worlds

    start = time.perf_counter()
    base = parse_scenario(spec["scene_text"], source=spec["scene_source"])
    worlds = spec["worlds"]
    scenes = [
        world_scene(base, tuple(map(tuple, w["overrides"])), w["seed"], w["law"]) for w in worlds
    ]

    def run(index: list[int], pad: int = 0):
        paths = [worlds[i]["run"] for i in index]
        for p in paths:
            if p:
                Path(p).parent.mkdir(parents=True, exist_ok=True)
        with POOL.lease() as make:
            ens = run_worlds(
                [scenes[i] for i in index] + [scenes[index[-1]]] * pad,
                until=spec["until"],
                out=paths if all(paths) and not pad else None,
                options=Options(
                    arch=spec["arch"], precision=spec["precision"], slots=spec.get("slots")
                ),
                window=spec["window"],
                worlds=make,
            )
        return [
            {
                "key": worlds[i]["key"],
                "index": worlds[i]["index"],
                "status": ens.status,
                "failure": ens.failure,
                "steps": ens.steps,
                "dt": ens.dt,
                "metrics": m,
            }
            for i, m in zip(index, ens.metrics)
        ]

    results = run(list(range(len(worlds))), spec.get("pad", 0))
    if len(worlds) > 1 and any(r["status"] != "complete" for r in results):
        results = [r for i in range(len(worlds)) for r in run([i])]
    return {
        "id": spec["id"],
        "worker": f"{socket.gethostname()}:{os.getpid()}",
        "wall_time": time.perf_counter() - start,
        "world_steps": int(sum(r["steps"] for r in results)),
        "worlds": results,
    }


@dataclass
class SweepResult:
    """What ``run_sweep`` did.

    Attributes:
        out: the output folder; path: its ``sweep.nc``.
        ran: world indices run this time; reused: world indices found in batch files.
        failed_batches: ``{batch id: error}`` of batches that raised (not written; a resume
            runs them again).
        wall_time: s. world_steps: steps x worlds run this time.
        workers: Dask workers (0: this process).
    """

    out: Path
    path: Path
    ran: list[int]
    reused: list[int]
    failed_batches: dict[str, str]
    wall_time: float
    world_steps: int
    workers: int

    def dataset(self):
        """The per-world dataset, as an ``xarray.Dataset`` (``dataset.open_sweep``)."""
        from .dataset import open_sweep

        return open_sweep(self.path)


def _identity(sweep: Sweep, arch: str, precision: str) -> dict:
    """What every world's result depends on besides its key: a resume must match it."""
    return {
        # the text and the [ice] it resolved to (Scene.identity): a changed default is
        # another sweep
        "scene_sha1": hashlib.sha1(sweep.scene.identity.encode()).hexdigest(),
        # each law's step as "auto" resolves it (rate and state's default moved 0.2 -> 0.05
        # on 2026-11-28): worlds of another step are another sweep
        "dt_safety": {law.label: sweep.scene.with_friction(law).dt_safety for law in sweep.laws},
        "until": sweep.until,
        "window": sweep.window,
        "arch": arch,
        "precision": precision,
        "taichi_ice": __version__,
    }


def load_done(out: Path, identity: dict) -> dict[str, dict]:
    """The world results the batch files of ``out`` hold, by world key; refuses a folder
    that holds a sweep of another scene or settings."""
    state = out / STATE
    if state.exists():
        old = _read_json(state)
        if not isinstance(old, dict):
            raise SweepError(
                f"{state}: damaged (not the JSON a sweep writes, or not matching its digest), so "
                "this folder's settings cannot be checked; give another --out, or delete the "
                "folder (or this file, if you are sure the folder holds this sweep) to start "
                "again"
            )
        diff = [k for k in identity if old.get(k) != identity[k]]
        if diff:
            said = ", ".join(f"{k}: {old.get(k)!r} there, {identity[k]!r} now" for k in diff)
            raise SweepError(
                f"{out}: holds a sweep with other settings ({said}); its results cannot be "
                "reused: give another --out, or delete the folder to start again"
            )
    done: dict[str, dict] = {}
    for path in sorted((out / BATCH_DIR).glob("batch-*.json")):
        batch = _read_json(path)
        try:
            worlds = [
                {**w, "batch": batch["id"], "worker": batch["worker"]} for w in batch["worlds"]
            ]
            keys = [w["key"] for w in worlds]
        except (TypeError, KeyError):
            worlds = None
        if worlds is None:
            # Written whole or not at all, so damaged from outside: set aside, and its
            # worlds run again.
            aside = path.with_name(path.name + ".damaged")
            os.replace(path, aside)
            print(
                f"sweep: {path} is damaged; moved to {aside.name}, its worlds run again",
                file=sys.stderr,
            )
            continue
        done.update(zip(keys, worlds))
    return done


def _read_json(path: Path) -> Any:
    """The JSON in ``path``, or None if it is not JSON (truncated, empty, garbled) or is a
    table whose ``digest`` does not match it (a byte damaged that still parses: a metric's
    digit, a status). Tables written before digests have none and are read as they are."""
    try:
        data = json.loads(path.read_bytes().decode("utf-8"))
    except (ValueError, UnicodeDecodeError):
        return None
    if isinstance(data, dict) and "digest" in data:
        if data.pop("digest") != record_digest(data):
            return None
    return data


def _write_json(path: Path, data: Any) -> None:
    """Write ``data`` whole or not at all (a kill mid-write leaves no half file; fsync
    before the rename, so that a power cut does not leave an empty file in its place); a
    table carries the digest ``_read_json`` checks."""
    if isinstance(data, dict):
        data = {**data, "digest": record_digest(data)}
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w") as fh:
        fh.write(json.dumps(data, indent=1, allow_nan=True) + "\n")
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def default_workers() -> int:
    """One Dask worker per CPU core."""
    return max(1, os.cpu_count() or 1)


def run_sweep(
    sweep: Sweep,
    out: str | Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    arch: str = "cpu",
    precision: str = "f64",
    progress: bool = True,
) -> SweepResult:
    """Run every world of ``sweep`` that ``out`` does not hold yet, then write ``sweep.nc``.

    Args:
        sweep: the sweep.
        out: output folder (created; a folder of the same sweep is resumed).
        workers: Dask workers of an embedded LocalCluster, one process each (default one
            per CPU core); 0 runs the batches here, one after the other, without Dask.
        scheduler: address of a running Dask scheduler (``tcp://host:8786``) to use instead.
        arch, precision: as for ``Simulation`` (every worker uses the same).
        progress: a line per batch on stderr.

    Returns:
        SweepResult. Batches that raised are listed in ``failed_batches``; their worlds are
        NaN with status 'missing' in the dataset, and a resume runs them.
    """
    from ...run.output import RunLock

    if workers is not None and not 0 <= workers <= MAX_WORKERS:
        raise SweepError(
            f"workers = {workers}: use 0 (no Dask) to {MAX_WORKERS} local workers, or "
            "--scheduler for a cluster"
        )
    out = Path(out)
    (out / BATCH_DIR).mkdir(parents=True, exist_ok=True)
    # One sweep a folder: two would both run the missing worlds and race on the dataset.
    lock = RunLock(out / "sweep")
    try:
        lock.acquire()
    except OutputError:
        other = lock.owner()
        raise SweepError(
            f"{out}: another sweep is running in this folder (pid {other.get('pid', '?')} on "
            f"{other.get('host', '?')} since {other.get('since', '?')}); wait for it, or "
            f"give another --out (if it is gone, delete {lock.path})"
        ) from None
    try:
        return _run_sweep(sweep, out, workers, scheduler, arch, precision, progress)
    finally:
        lock.release()


def _run_sweep(sweep, out: Path, workers, scheduler, arch, precision, progress) -> SweepResult:
    from .dataset import build_dataset, write_dataset

    start = time.perf_counter()
    identity = _identity(sweep, arch, precision)
    done = load_done(out, identity)
    _write_json(out / STATE, identity)
    (out / "sweep.toml").write_text(sweep.text)

    worlds = sweep.worlds()
    missing = [w for w in worlds if w.key not in done]
    reused = [w.index for w in worlds if w.key in done]
    n_workers = 0 if scheduler is None and workers == 0 else (workers or default_workers())
    runs_dir = out / "runs" if sweep.runs else None
    failed: dict[str, str] = {}
    ran: list[int] = []
    world_steps = 0
    if missing:
        with _connected(n_workers, scheduler) as client:
            if scheduler is not None:
                # Counted before planning: each model's worlds are split over the workers.
                n_workers = len(client.scheduler_info()["workers"])
            slots = contact_slots(sweep)
            batches = plan_batches(sweep, missing, max(n_workers, 1), arch, slots)
            specs = [batch_spec(sweep, b, runs_dir, arch, precision, slots) for b in batches]
            costs = {sp["id"]: batch_seconds(sweep, b) for sp, b in zip(specs, batches)}
            say = _Reporter(progress, costs, len(missing), len(reused))
            where = f"{n_workers} Dask workers" if n_workers else "this process"
            say.start(f"{scheduler} ({where})" if scheduler else where, n_workers)
            for spec, result, error in _execute(specs, client):
                if error:
                    failed[spec["id"]] = error
                    say.failed(spec, error)
                    continue
                result["worlds"] = [
                    {**w, "metrics": _keep(w["metrics"], sweep.metrics)} for w in result["worlds"]
                ]
                _write_json(out / BATCH_DIR / f"batch-{result['id']}.json", result)
                for w in result["worlds"]:
                    done[w["key"]] = {**w, "batch": result["id"], "worker": result["worker"]}
                    ran.append(w["index"])
                world_steps += result["world_steps"]
                say.done(spec, result)
    elif progress:
        print(
            f"sweep: all {len(worlds)} worlds are in {out}/{BATCH_DIR}; nothing to run",
            file=sys.stderr,
        )

    wall = time.perf_counter() - start
    log_path = out / LOG
    log = _read_json(log_path) if log_path.exists() else []
    if not isinstance(log, list):  # damaged: kept aside, a new log begins
        os.replace(log_path, log_path.with_name(log_path.name + ".damaged"))
        print(f"sweep: {log_path} was damaged; kept as {log_path.name}.damaged", file=sys.stderr)
        log = []
    log.append(
        {
            "started": time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(time.time() - wall)),
            "workers": n_workers,
            "scheduler": scheduler,
            "worlds_run": len(ran),
            "worlds_reused": len(reused),
            "failed_batches": failed,
            "wall_time": wall,
            "world_steps": world_steps,
            "world_steps_per_s": world_steps / wall if wall > 0 else math.nan,
        }
    )
    _write_json(log_path, log)
    ds = build_dataset(sweep, worlds, done, arch=arch, precision=precision)
    path = write_dataset(ds, out / DATASET)
    if progress:
        print(
            f"sweep: {len(ran)} worlds run, {len(reused)} reused, in {wall:.0f} s "
            f"({world_steps / max(wall, 1e-9):.0f} world-steps/s); wrote {path}"
            + (f"; {len(failed)} batches FAILED (run again to retry)" if failed else ""),
            file=sys.stderr,
        )
    return SweepResult(out, path, sorted(ran), reused, failed, wall, world_steps, n_workers)


def _keep(metrics: dict, names: Sequence[str]) -> dict:
    return {k: metrics[k] for k in names}


def local_cluster(workers: int):
    """A Dask ``LocalCluster`` of ``workers`` single-threaded worker processes; Taichi's own
    thread pool in each gets an equal share of the cores. (A caller that runs several sweeps
    passes its address as ``scheduler``, so the workers keep Taichi and their Worlds warm.)"""
    from dask.distributed import LocalCluster

    threads = max(1, (os.cpu_count() or 1) // workers)
    return LocalCluster(
        n_workers=workers,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        env={"TI_CPU_MAX_NUM_THREADS": str(threads)},
    )


@contextmanager
def _connected(workers: int, scheduler: str | None):
    """A Dask client of ``scheduler``'s cluster or of an embedded ``LocalCluster`` of
    ``workers`` processes (closed after); None where the batches run in this process."""
    if scheduler is None and workers == 0:
        yield None
        return
    from dask.distributed import Client

    cluster = None
    if scheduler is None:
        cluster = local_cluster(workers)
        client = Client(cluster)
    else:
        try:
            client = Client(scheduler, timeout="30s")
        except OSError as exc:
            raise SweepError(
                f"--scheduler {scheduler}: cannot reach a Dask scheduler there ({exc}); start "
                "one with `dask scheduler` and workers with `dask worker ADDRESS`"
            ) from None
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _execute(specs: list[dict], client):
    """Yield ``(spec, result, error)`` for every batch as it completes, in this process where
    ``client`` is None. Batches are submitted in ``specs``' order (longest first,
    ``plan_batches``) and the scheduler starts them in that order."""
    if client is None:
        for spec in specs:
            try:
                yield spec, run_batch(spec), None
            except Interrupted:  # Ctrl-C, SIGTERM: the sweep stops (a resume runs the batch)
                raise
            except TaichiIceError as exc:
                yield spec, None, str(exc)
        return
    from dask.distributed import as_completed

    by_key = {}
    futures = []
    for k, spec in enumerate(specs):
        f = client.submit(
            run_batch,
            spec,
            key=f"taichi-ice-batch-{spec['id']}",
            pure=False,
            priority=len(specs) - k,
        )
        by_key[f.key] = spec
        futures.append(f)
    for future in as_completed(futures):
        spec = by_key[future.key]
        try:
            yield spec, future.result(), None
        except TaichiIceError as exc:
            yield spec, None, str(exc)


def _duration(seconds: float) -> str:
    """``seconds`` as a person reads a wait: 40 s, 12 min, 3.5 h."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


class _Reporter:
    """A line on stderr per batch: what ran where, how fast, how much is left (by the batches'
    estimated cost, ``plan.batch_seconds``: a batch of a law with memory counts four times
    a Coulomb batch of as many worlds)."""

    def __init__(self, enabled: bool, costs: dict[str, float], n_worlds: int, n_reused: int):
        self.enabled, self.n_batches, self.n_worlds = enabled, len(costs), n_worlds
        self.costs, self.cost_total, self.cost_done = costs, sum(costs.values()), 0.0
        self.n_reused = n_reused
        self.k = 0
        self.worlds_done = 0
        self.start_time = time.perf_counter()

    def start(self, where: str, workers: int) -> None:
        """The line before the first batch, with the wall time the plan estimates: its cost
        over the workers, or its longest batch if that is longer."""
        if self.enabled:
            reused = f" ({self.n_reused} already done)" if self.n_reused else ""
            guess = max(self.cost_total / max(workers, 1), max(self.costs.values(), default=0))
            print(
                f"sweep: {self.n_worlds} worlds to run{reused} in {self.n_batches} batches on "
                f"{where}; about {_duration(guess)} at {BODY_STEPS_PER_SECOND / 1e6:g} M "
                "body-steps/s a worker (each batch's line below says the rate measured)",
                file=sys.stderr,
                flush=True,
            )

    def done(self, spec: dict, result: dict) -> None:
        self.k += 1
        self.worlds_done += len(spec["worlds"])
        self.cost_done += self.costs[spec["id"]]
        if not self.enabled:
            return
        elapsed = time.perf_counter() - self.start_time
        left = elapsed / max(self.cost_done, 1e-300) * (self.cost_total - self.cost_done)
        status = {w["status"] for w in result["worlds"]}
        rate = result["world_steps"] / max(result["wall_time"], 1e-9)
        print(
            f"sweep: batch {self.k}/{self.n_batches} {spec['id']} "
            f"({len(spec['worlds'])} worlds, {spec['worlds'][0]['law']['law']}) "
            f"{'/'.join(sorted(status))} in {result['wall_time']:.0f} s on {result['worker']} "
            f"({rate:.0f} world-steps/s); {self.worlds_done}/{self.n_worlds} worlds, "
            f"~{left:.0f} s left",
            file=sys.stderr,
            flush=True,
        )

    def failed(self, spec: dict, error: str) -> None:
        self.k += 1
        self.cost_done += self.costs[spec["id"]]
        if self.enabled:
            print(f"sweep: batch {spec['id']} FAILED: {error}", file=sys.stderr, flush=True)
