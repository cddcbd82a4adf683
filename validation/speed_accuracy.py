"""Speed against accuracy, and stability: ``python validation/speed_accuracy.py --out DIR``.

Same as ``taichi-ice validate --speed --out DIR``; the study lives in
taichi_ice.experiments.validation.
"""

import sys

from taichi_ice.commands.validate import main

if __name__ == "__main__":
    raise SystemExit(main(["speed_accuracy", *sys.argv[1:]]))
