"""The paper's Figure 3 against exact solutions: ``python validation/single_interface.py``.

Same as ``taichi-ice validate --out DIR`` (``--out DIR`` here too); the study lives in
taichi_ice.experiments.validation.
"""

import sys

from taichi_ice.commands.validate import main

if __name__ == "__main__":
    raise SystemExit(main(["single_interface", *sys.argv[1:]]))
