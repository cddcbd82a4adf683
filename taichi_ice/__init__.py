"""taichi-ice: sea-ice rubble as a 2D discrete element model with friction that remembers.

Convex polygon floes collide through Hopkins (1992) overlap contacts; every contact carries
the rate-and-state friction law of Lishman et al. (2013), doi:10.1016/j.coldregions.2013.03.004.
The same Taichi kernels run on the CPU and on a GPU.

    from taichi_ice.physics.friction import RateState
    mu = RateState().respond(t, v)

    from taichi_ice import load_scenario, Simulation
    sim = Simulation(load_scenario("scenarios/pillar.toml"), friction=RateState())
    sim.run(until=20.0, out="runs/pillar_rs.h5")

    ds = open_run("runs/pillar_rs.h5")       # the run file as an xarray Dataset

The scenes of ``scenarios/`` ship with the package: ``load_scenario("pillar")`` loads one from
any directory.

Taichi prints a banner when it is imported ("[Taichi] version ...") and a line when it starts
("[Taichi] Starting on arch=..."); taichi-ice keeps both quiet. Set the environment variable
``ENABLE_TAICHI_HEADER_PRINT=1`` to see them again.
"""

from __future__ import annotations

import os
from typing import Any

# Before anything imports Taichi (several modules do at their top, and this package's
# __init__ runs first): Taichi prints its banner at import unless this variable says not to.
# A user's own setting wins; backend.init reads the same variable for the start-up line.
os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "0")

from ._version import __version__
from .errors import (
    CapacityError,
    DivergenceError,
    PolygonError,
    ScenarioError,
    StabilityError,
    TaichiIceError,
)

__all__ = [
    "CapacityError",
    "DivergenceError",
    "PolygonError",
    "ScenarioError",
    "Simulation",
    "StabilityError",
    "TaichiIceError",
    "__version__",
    "load_scenario",
    "open_run",
]


def __getattr__(name: str) -> Any:
    # The engine imports Taichi, which is slow to start: load it only when asked for.
    if name == "load_scenario":
        from .scene.parse import load_scenario

        return load_scenario
    if name == "open_run":
        from .run.runfile_read import open_run

        return open_run
    if name == "Simulation":
        from .run.simulation import Simulation

        return Simulation
    raise AttributeError(f"module 'taichi_ice' has no attribute {name!r}")
