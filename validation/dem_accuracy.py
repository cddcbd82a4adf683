"""The DEM's accuracy against its cost, and its stability: ``python validation/dem_accuracy.py
--out DIR [--quick]``.

The DEM part of ``taichi-ice validate --dem --out DIR``; the study lives in
taichi_ice.experiments.validation.dem_accuracy (docs/accuracy.md).
"""

import sys

from taichi_ice.commands.validate import main

if __name__ == "__main__":
    raise SystemExit(main(["dem_accuracy", *sys.argv[1:]]))
