"""float32 keeps its accuracy far from the origin: positions are stored in float64 and the
contact arithmetic runs in float32 relative to the pair (issue 10, item 4).

Each precision needs its own Taichi runtime, so each run is a child process. The reference
is the float64 run at the origin; float32 runs at the origin and 100 km away must agree with
it to float32 round-off of the bodies' size, not of the domain's (at 1e5 m a float32
position's resolution is 8 mm, more than the whole run's contact overlap).
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

CHILD = """
import json, sys
import numpy as np
from taichi_ice import backend, load_scenario
from taichi_ice.engine.world import World
precision, offset = sys.argv[1], float(sys.argv[2])
backend.init("cpu", precision)
world = World([load_scenario("free_field")], precision=precision)
world.place(world.positions() + offset, world.angles())
contacts = 0
for _ in range(20):
    world.advance(round(0.05 / world.dt))
    contacts += int(world.contact_counts()[0])
world.check()
print(json.dumps({"pos": (world.positions() - offset).tolist(), "contacts": contacts}))
"""


def run_child(precision: str, offset: float) -> dict:
    out = subprocess.run(
        [sys.executable, "-c", CHILD, precision, repr(offset)],
        capture_output=True,
        text=True,
        check=True,
        timeout=600,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("offset", [0.0, 1e5])
def test_float32_far_from_the_origin_follows_float64(taichi_runtime, offset):
    """A drifting field 100 km from the origin in float32 stays within 1e-4 m of the float64
    run at the origin over 1 s of contacts (a float32 absolute position there resolves
    only 8 mm)."""
    want = run_child("f64", 0.0)
    got = run_child("f32", offset)
    assert want["contacts"] > 0  # contacts at some of the 20 samples
    err = np.max(np.abs(np.array(got["pos"]) - np.array(want["pos"])))
    print(f"offset {offset:g} m: largest difference {err:.2e} m")
    assert err < 1e-4, err
