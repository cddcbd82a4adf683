"""Speed against accuracy, and stability: ``python validation/speed_accuracy.py --out DIR``.

Same as ``taichi-ice validate --speed --out DIR``; the study lives in taichi_ice.studies.
"""

from taichi_ice.studies.speed_accuracy import main

if __name__ == "__main__":
    raise SystemExit(main())
