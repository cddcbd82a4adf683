"""The command line, ``taichi-ice``: the parser of every subcommand and what each runs.
The only place argparse lives.

Layer 6, the top of the package (docs/architecture.md).
"""
