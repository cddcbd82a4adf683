"""Rubble-field throughput on the lattice box: ``taichi-ice bench --scene lattice``, f64, no Box2D.

The paper's diamonds in zig-zag columns whose neighbours touch edge to edge, 54 % of a closed
box (``taichi_ice.experiments.bench.scenes.lattice_scene``), at 1e3 to 1e5 blocks. Everything
else, and every option, is ``taichi-ice bench`` (``taichi_ice.experiments.bench``) with these
defaults.

    python benchmarks/rubble_field.py --out out/bench
    python benchmarks/rubble_field.py --sizes 1000 10000 100000 --steps 100 --law rate-state
    python benchmarks/rubble_field.py --quick --out /tmp/bench     # 1e3 blocks, 20 steps
    python benchmarks/rubble_field.py --arch gpu --sizes 100000 1000000 --profile

Writes ``rubble_field.csv``, ``rubble_field.json`` and ``rubble_field.png`` into ``--out``.
"""

from __future__ import annotations

import argparse
import sys

from taichi_ice.commands.bench import add_options
from taichi_ice.errors import TaichiIceError
from taichi_ice.experiments.bench import bench_command


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_options(parser)
    parser.set_defaults(scene="lattice", name="rubble_field", precision=["f64"], box2d=False)
    args = parser.parse_args(argv)
    try:
        return bench_command(args)
    except TaichiIceError as exc:
        parser.error(str(exc))


if __name__ == "__main__":
    sys.exit(main())
