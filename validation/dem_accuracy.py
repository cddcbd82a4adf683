"""The DEM's accuracy against its cost, and its stability: ``python validation/dem_accuracy.py
--out DIR [--quick]``.

The DEM part of ``taichi-ice validate --dem --out DIR``; the study lives in
taichi_ice.studies.dem_accuracy (docs/accuracy.md).
"""

from taichi_ice.studies.dem_accuracy import main

if __name__ == "__main__":
    raise SystemExit(main())
