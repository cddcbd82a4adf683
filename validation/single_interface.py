"""The paper's Figure 3 against exact solutions: ``python validation/single_interface.py``.

Same as ``taichi-ice validate --out DIR`` (``--out DIR`` here too); the study lives in
taichi_ice.studies.
"""

from taichi_ice.studies.single_interface import main

if __name__ == "__main__":
    raise SystemExit(main())
