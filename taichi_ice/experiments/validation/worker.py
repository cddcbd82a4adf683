"""The command line and environment of a validation study's worker process (``dem_accuracy``
and ``speed_accuracy`` start them: Taichi holds one precision per process)."""

from __future__ import annotations

import os
import sys
from pathlib import Path


def study_worker(study: str, precision: str, *args: str) -> tuple[list[str], dict[str, str]]:
    """The command line and environment of a study's worker process, ``python -m
    taichi_ice.commands.validate STUDY --worker PRECISION ARGS``, with this tree's package
    first on ``PYTHONPATH``: a worker runs the code of the study that started it, however
    that was started."""
    root = str(Path(__file__).resolve().parents[3])  # the folder that holds taichi_ice/
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [root, env.get("PYTHONPATH")]))
    cmd = [sys.executable, "-m", "taichi_ice.commands.validate", study, "--worker", precision]
    return [*cmd, *args], env


__all__ = ["study_worker"]
