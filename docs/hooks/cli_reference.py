"""MkDocs hook: the command-line reference page (reference/cli.md) gets every subcommand's
``--help`` text, generated from the parser when the site is built, so it cannot drift from
the command line. The page marks the place with ``<!-- cli-help -->``.

It imports ``taichi_ice.commands.cli`` from the checkout the site is built from (the folder
of mkdocs.yml), which starts no Taichi.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

PAGE = "reference/cli.md"
MARKER = "<!-- cli-help -->"
# argparse wraps its help to the terminal's width: a fixed one makes the page the same
# wherever it is built.
WIDTH = "100"


def on_config(config):
    root = str(Path(config["config_file_path"]).resolve().parent)
    if root not in sys.path:
        sys.path.insert(0, root)
    return config


def _help_texts() -> list[tuple[str, str]]:
    from taichi_ice.commands.cli import build_parser

    columns = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = WIDTH
    try:
        parser = build_parser()
        parser.prog = "taichi-ice"
        texts = [("taichi-ice", parser.format_help())]
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        for name, command in sub.choices.items():
            texts.append((f"taichi-ice {name}", command.format_help()))
    finally:
        if columns is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = columns
    return texts


def on_page_markdown(markdown, page, config, files):
    if page.file.src_uri != PAGE:
        return markdown
    if MARKER not in markdown:
        raise ValueError(f"{PAGE}: the marker {MARKER} is missing")
    sections = [f"## `{title}`\n\n```text\n{text.rstrip()}\n```\n" for title, text in _help_texts()]
    return markdown.replace(MARKER, "\n".join(sections))
