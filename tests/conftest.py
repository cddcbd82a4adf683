"""Test session set-up: one Taichi runtime for the whole session, on the arch asked for.

Taichi compiles each kernel once per process, so every test module shares this runtime
(float64 unless ``--precision f32``) and reuses compiled kernels.
"""

from __future__ import annotations

import os

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
