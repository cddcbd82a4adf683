"""``python -m taichi_ice`` is the ``taichi-ice`` command."""

from .cli import main

raise SystemExit(main())
