"""``python -m taichi_ice`` is the ``taichi-ice`` command."""

from .commands.cli import main

raise SystemExit(main())
