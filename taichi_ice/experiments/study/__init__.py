"""The study of the paper's open question (issue 31): ``design`` (its arms: strata by area
fraction with their own layouts, a control, the half step, two ice strengths), ``run`` (each
arm a sweep on one Dask cluster), ``stats`` (exact intervals, paired tests, Holm, power,
Kaplan-Meier, the step's bias), ``report`` (study.json, study.md, study.nc) and ``figures``."""
