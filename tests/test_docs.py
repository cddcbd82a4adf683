"""The documentation site builds with no warning, as ``make docs`` builds it.

``mkdocs build --strict`` turns every warning into a failure: a broken link or anchor, a
missing snippet (the examples the pages include), a page left out of the nav, a docstring
the API reference cannot read. The test extra installs MkDocs (the docs extra), so this runs
in CI; without MkDocs it is skipped.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_the_site_builds_with_no_warning(tmp_path: Path) -> None:
    """mkdocs build --strict succeeds, logs no warning, and writes the pages and the API."""
    for module in ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python"):
        pytest.importorskip(module, reason="the docs extra builds the site")
    site = tmp_path / "site"
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}  # Material's banner about MkDocs 2
    command = ["build", "--strict", "--config-file", ROOT / "mkdocs.yml", "--site-dir", site]
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", *map(str, command)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log
    assert "WARNING" not in log, log
    for page in ("index.html", "getting-started/index.html", "examples/index.html"):
        assert (site / page).is_file(), page
    # The reference was read from the docstrings, not left as an empty page.
    reference = (site / "reference" / "scene" / "index.html").read_text(encoding="utf-8")
    assert "scene_from_dict" in reference and "ScenarioError" in reference
    # The command-line reference was generated from the parser (docs/hooks/cli_reference.py).
    cli = (site / "reference" / "cli" / "index.html").read_text(encoding="utf-8")
    assert "usage: taichi-ice sweep" in cli and "--scheduler" in cli
    # The example code is included from examples/, as the tests run it (not left a marker).
    examples = (site / "examples" / "index.html").read_text(encoding="utf-8")
    assert "channel_scene" in examples and "--8&lt;--" not in examples
