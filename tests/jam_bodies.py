"""The jam both test_resume and test_contacts_output run: three 1 m squares pressed onto a
fixed floor (200 kN each), pushed along it by a kinematic pusher against a fixed wall."""

from __future__ import annotations


def jam_bodies(push: float = 0.02, tilt: float = 0.0, probe_pusher: bool = False) -> list[dict]:
    """The scene's [[body]] tables: the floor and the wall (both probes), the pusher at
    ``push`` m/s (a probe too if ``probe_pusher``), and the squares, block i turned by
    ``tilt`` x i rad."""
    square = {"shape": "rectangle", "width": 1.0, "length": 1.0}
    pusher = {
        "name": "pusher",
        "kind": "kinematic",
        "shape": "rectangle",
        "width": 0.5,
        "length": 0.9,
        "position": [-1.752, 0.5],
        "velocity": [push, 0.0],
    }
    if probe_pusher:
        pusher["probe"] = True
    blocks = []
    for i in range(-1, 2):
        block = {"name": f"block{i}", **square, "position": [i * 1.001, 0.501]}
        if tilt:
            block["angle"] = tilt * i
        blocks.append({**block, "force": [0.0, -2e5]})
    return [
        {
            "name": "floor",
            "kind": "fixed",
            "shape": "rectangle",
            "width": 6.0,
            "length": 0.5,
            "position": [1.0, -0.25],
            "probe": True,
        },
        {
            "name": "wall",
            "kind": "fixed",
            "shape": "rectangle",
            "width": 0.5,
            "length": 2.0,
            "position": [1.752, 1.0],
            "probe": True,
        },
        pusher,
        *blocks,
    ]
