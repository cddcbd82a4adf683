"""Running the study: every arm of ``design`` as a sweep into ``OUT/arms/NAME``, then the
analysis (``stats``) and the report (``report``) into ``OUT``.

    from taichi_ice.experiments.study.run import run_study
    summary = run_study("out/study", layouts=64)        # study.json's content

The arms run one after the other on one Dask cluster (an embedded ``LocalCluster`` of
``workers`` processes, or ``scheduler``'s), so the workers keep Taichi and their compiled
Worlds from one arm to the next. An arm's folder is a sweep folder: run the study again
with the same ``OUT`` to resume, or with more layouts to grow it (each arm resumes on its
own and runs only the worlds it does not hold).
"""

from __future__ import annotations

import json
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from .design import design

__all__ = ["run_arms", "run_study"]


@contextmanager
def _cluster(workers: int | None, scheduler: str | None):
    """The scheduler address every arm uses (None: each arm runs in this process)."""
    if scheduler is not None or workers == 0:
        yield scheduler
        return
    from ..sweep.run import default_workers, local_cluster

    cluster = local_cluster(default_workers() if workers is None else workers)
    try:
        yield cluster.scheduler_address
    finally:
        cluster.close()


def run_arms(
    arms,
    out,
    *,
    until: float | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    arch: str = "cpu",
    precision: str = "f64",
    progress: bool = True,
) -> dict:
    """Run (or resume) every arm into ``out/arms/NAME``.

    Returns:
        ``{arm name: (Arm, its sweep's xarray Dataset, its sweep log)}``.
    """
    from ..sweep.run import run_sweep

    out = Path(out)
    results = {}
    with _cluster(workers, scheduler) as address:
        for k, arm in enumerate(arms, start=1):
            sweep = arm.sweep(until)
            if progress:
                print(
                    f"study: arm {k}/{len(arms)} {arm.name}: {arm.layouts} layouts x "
                    f"{len(sweep.laws)} models = {len(sweep.worlds())} worlds of "
                    f"{sweep.until:g} s",
                    file=sys.stderr,
                    flush=True,
                )
            folder = out / "arms" / arm.name
            result = run_sweep(
                sweep,
                folder,
                workers=workers if address is None else None,
                scheduler=address,
                arch=arch,
                precision=precision,
                progress=progress,
            )
            log = json.loads((folder / "sweep-log.json").read_text())
            results[arm.name] = (arm, result.dataset(), log)
    return results


def run_study(
    out,
    layouts: int,
    *,
    control_layouts: int | None = None,
    step_layouts: int | None = None,
    strength_layouts: int | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    until: float | None = None,
    arch: str = "cpu",
    precision: str = "f64",
    progress: bool = True,
) -> dict:
    """Run (or resume) the study into ``out`` and write study.json, study.md, study.nc and
    the figures.

    Returns:
        study.json's content.
    """
    from .report import write_report

    out = Path(out)
    start = time.perf_counter()
    arms = design(layouts, control_layouts, step_layouts, strength_layouts)
    if progress:
        n = sum(arm.layouts for arm in arms)
        print(
            f"study: {len(arms)} arms, {n} layouts in all, x 8 models = {8 * n} worlds",
            file=sys.stderr,
            flush=True,
        )
    results = run_arms(
        arms,
        out,
        until=until,
        workers=workers,
        scheduler=scheduler,
        arch=arch,
        precision=precision,
        progress=progress,
    )
    first = next(iter(results.values()))[0]
    summary = write_report(
        results, out, until=first.sweep(until).until, arch=arch, precision=precision
    )
    summary["wall_time"] = time.perf_counter() - start
    # Compact: every world's values make it megabytes; study.md is the file for people.
    (out / "study.json").write_text(json.dumps(summary, separators=(",", ":"), allow_nan=True))
    if progress:
        print(
            f"study: done in {summary['wall_time']:.0f} s; wrote {out}/study.md, study.json, "
            "study.nc, figures/",
            file=sys.stderr,
        )
    return summary
