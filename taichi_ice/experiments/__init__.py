"""Many runs and what they answer: ensembles, sweeps on Dask, the paper's reproduction, the
study of its open question, the validation studies and the benchmarks.

Layer 5 of the package (docs/architecture.md): imports run and everything below; argparse
lives one layer up, in ``commands``.
"""
