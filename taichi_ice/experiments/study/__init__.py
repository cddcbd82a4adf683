"""The study of the paper's open question: ``stats`` (the design, bootstrap intervals,
verdicts, the claims and what carries them) and ``report`` (the run, study.json, its
markdown and figures)."""
