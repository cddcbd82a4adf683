"""Test session set-up: one Taichi runtime for the whole session, on the arch asked for.

Taichi compiles each kernel once per process, so every test module shares this runtime
(float64 unless ``--precision f32``) and reuses compiled kernels. ``make test`` runs a
pytest-xdist worker per core (at most 4), a file to a worker (``--dist loadfile``), so that a
file's tests still share their kernels; most of a run is compiling, on one core a process.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

# Compile without Taichi's advanced passes (about 3x faster, same trajectories: see
# taichi_ice/backend.py and test_backend.py), here and in the processes tests start. Most of a
# cold run of the suite is compiling. TAICHI_ICE_OPTIMIZE=1 tests the optimised kernels.
os.environ.setdefault("TAICHI_ICE_OPTIMIZE", "0")


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--arch", default="cpu", help="Taichi arch for the kernels: cpu (default) or gpu"
    )
    parser.addoption(
        "--precision", default="f64", help="Taichi default float: f64 (default) or f32"
    )


@pytest.fixture(scope="session", autouse=True)
def taichi_runtime(request: pytest.FixtureRequest) -> tuple[str, str]:
    """Start Taichi once for the session and return (arch, precision)."""
    from taichi_ice import backend

    arch = request.config.getoption("--arch")
    precision = request.config.getoption("--precision")
    backend.init(arch, precision)
    return arch, precision


def pytest_sessionfinish(session: pytest.Session) -> None:
    """Under pytest-xdist, write this worker's compiled kernels to Taichi's offline cache one
    worker at a time. Taichi writes the cache as a process exits, under a lock it gives up on
    after a few tries ("Lock .../ticache.lock failed"): the workers end together, and all but
    one lost their kernels (measured after a cold run of the suite: 108 MB cached, against
    143 MB written one worker at a time)."""
    from taichi_ice import backend

    if not os.environ.get("PYTEST_XDIST_WORKER") or backend.current() is None:
        return
    import fcntl

    import taichi as ti

    folder = Path(ti.lang.impl.current_cfg().offline_cache_file_path)
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / "taichi-ice-workers.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        ti.reset()  # Taichi ends its program here, writing its offline cache
