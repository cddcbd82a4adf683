"""The worker processes of the DEM accuracy study (``dem_accuracy``): one per precision and
integrator, as many at a time as the cores, and their indexes merged into one per precision.

Taichi holds one precision per process and compiles faster in a process with few kernels,
and the study's integrators share no kernel (each compiles its own): a process for each
loses nothing to compiling, and on 2 cores the study takes about half the wall time of one
worker per precision, one after the other (``docs/accuracy.md``).
"""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np

from .worker import study_worker


def jsonable(x):
    """``json.dumps``' ``default`` for the indexes: NumPy scalars and arrays, tuples."""
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, tuple):
        return list(x)
    raise TypeError(type(x))


def command(precision: str, folder: Path, quick: bool, until: float | None, integrator: str):
    """The command line and environment of a worker: one precision and one integrator into
    ``folder`` (``worker.study_worker``)."""
    args = ["--out", str(folder), "--integrators", integrator] + (["--quick"] if quick else [])
    if until is not None:
        args += ["--until", str(until)]
    return study_worker("dem_accuracy", precision, *args)


def run_workers(jobs: list[tuple[str, str, list[str], dict]], slots: int, log) -> None:
    """Run the workers, at most ``slots`` at a time, in the order given (longest first: the
    last to start are the shortest). ``jobs``: (precision, integrator, command line,
    environment). A worker that fails stops the others (what they wrote stays) and raises,
    naming its command."""
    waiting, running = list(jobs), []
    try:
        while waiting or running:
            while waiting and len(running) < slots:
                precision, integrator, cmd, env = waiting.pop(0)
                log(f"dem accuracy: {precision} {integrator} worker process ...")
                running.append((subprocess.Popen(cmd, env=env), cmd))
            time.sleep(0.2)
            for proc, cmd in list(running):
                code = proc.poll()
                if code is None:
                    continue
                running.remove((proc, cmd))
                if code != 0:
                    raise RuntimeError(f"dem accuracy worker failed (exit {code}): {' '.join(cmd)}")
    finally:
        for proc, _cmd in running:
            proc.terminate()
            proc.wait()


def spawned(
    out_dir: Path, cfg: dict[str, Any], precisions: list[str], until: float | None, slots: int, log
) -> dict[str, dict]:
    """Every run of ``precisions`` in worker processes, a process for each precision and
    integrator, ``slots`` at a time (the timed runs are a world alone, a thread each: as
    many as the cores), longest first: float64 before float32, the analytic steps before
    Euler. Returns each precision's merged index (also written to
    ``out_dir/dem_runs/<precision>/index.json``, which the study's ``reuse`` reads)."""
    order = {"midstep": 0, "coupled": 1, "analytic": 2, "euler": 3}
    jobs = [
        (p, i, out_dir / "dem_runs" / p / i)
        for p in precisions
        for i in sorted(cfg["integrators"], key=lambda i: order.get(i, len(order)))
    ]
    jobs.sort(key=lambda job: job[0] != "f64")
    run_workers(
        [(p, i, *command(p, folder, cfg["quick"], until, i)) for p, i, folder in jobs], slots, log
    )
    parts = {}
    for p in precisions:
        mine = [
            (i, json.loads((out_dir / "dem_runs" / p / i / "index.json").read_text()))
            for i in cfg["integrators"]  # the records in the study's order of integrators
        ]
        parts[p] = merged(p, mine)
        index = out_dir / "dem_runs" / p / "index.json"
        index.write_text(json.dumps(parts[p], default=jsonable))
    return parts


def merged(precision: str, parts: list[tuple[str, dict]]) -> dict:
    """One precision's index from its integrators' workers (``parts``: integrator, index):
    their records in order, each ``arrays`` path relative to the precision's folder."""
    index: dict[str, Any] = {"precision": precision, "records": [], "workers": []}
    for integrator, part in parts:
        for record in part["records"]:
            if "arrays" in record:
                record = {**record, "arrays": f"{integrator}/{record['arrays']}"}
            index["records"].append(record)
        if "stability" in part:
            index.setdefault("stability", {}).update(part["stability"])
        index["advanced_optimization"] = part.get("advanced_optimization")
        index["optimize"] = part.get("optimize")
        index["workers"].append({"integrator": integrator, "wall_s": part.get("wall_s")})
    return index


__all__ = ["command", "jsonable", "merged", "run_workers", "spawned"]
