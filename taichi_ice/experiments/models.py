"""The friction models of the paper's experiment and what the paper says of each.

Holds the pillar scene the paper runs (``DEFAULT_SCENE``), its four friction models
(``models``), the variants that separate rate from memory (``variants``), and the colour,
title and finding of each model's label, which ``paper`` (the reproduction), its summary and
figures, and ``study.report`` (the study's figures) share. Running and reporting live there,
not here.

A model's label is its law's ``Law.label`` (``mu0.5``, ``rate-state_healing``): the tables
below are keyed by those labels, and by ``rate-state_strength1MPa`` / ``3MPa``, the paper's
runs with an ice strength, which no law names.
"""

from __future__ import annotations

from importlib import resources

# The bundled scene (package data), so that the command works from an installed wheel.
DEFAULT_SCENE = resources.files("taichi_ice").joinpath("scenarios").joinpath("pillar.toml")

MODEL_COLOURS = {
    "mu0.1": "C0",
    "mu0.5": "C1",
    "mu0.9": "C3",
    "rate-state": "C2",
    "rate-state_healing": "C4",
    "rate-state_relaxing": "C6",
    "steady-state": "C7",
    "memory-only": "C5",
    "rate-state_strength1MPa": "C8",
    "rate-state_strength3MPa": "C9",
}
MODEL_TITLES = {
    "mu0.1": r"$\mu$ = 0.1",
    "mu0.5": r"$\mu$ = 0.5",
    "mu0.9": r"$\mu$ = 0.9",
    "rate-state": "rate and state",
    "rate-state_healing": "rate and state, healing below V*",
    "rate-state_relaxing": "rate and state, mu0 below V*, interface kept",
    "steady-state": "steady-state law (rate, no memory)",
    "memory-only": "memory only (B = A)",
    "rate-state_strength1MPa": "rate and state, ice strength 1 MPa",
    "rate-state_strength3MPa": "rate and state, ice strength 3 MPa",
}

# What the paper says of each model (its section "Variable friction within a simple DEM").
PAPER_FINDINGS = {
    "mu0.1": "blocks slide easily past the pillar; forces never higher than 1 kN",
    "mu0.5": "jams form and break; energy loss concentrated in two events (~14 s and ~19 s)",
    "mu0.9": "the blocks jam, the jam is never broken; force and energy loss rise dramatically",
    "rate-state": "jams form and break; frictional loss rises more steadily than for mu = 0.5",
}


def models():
    """The paper's four friction models, ``(label, law)`` in its order; the label is the
    law's ``Law.label`` (``mu0.1``, ``mu0.5``, ``mu0.9``, ``rate-state``)."""
    from ..physics.friction import Coulomb, RateState

    return [(law.label, law) for law in (Coulomb(0.1), Coulomb(0.5), Coulomb(0.9), RateState())]


def variants():
    """The choices that separate rate from memory, run over the same layouts as the paper's
    models: the law with today's earlier rule below V* (healing), the steady-state law and
    memory only. ``(label, law)``, the label the law's ``Law.label`` (``rate-state_healing``,
    ``steady-state``, ``memory-only``)."""
    from ..physics.friction import MemoryOnly, RateState, SteadyState

    return [
        (law.label, law) for law in (RateState(below_v_star="healing"), SteadyState(), MemoryOnly())
    ]


__all__ = [
    "DEFAULT_SCENE",
    "MODEL_COLOURS",
    "MODEL_TITLES",
    "PAPER_FINDINGS",
    "models",
    "variants",
]
