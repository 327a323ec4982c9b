"""Renamed: the estimators live in :mod:`pathspace.estimators` (one word for the concept)."""

RENAMED = {"make_integrator": "pathspace.estimators.make_estimator", "ESTIMATORS": "pathspace.estimators.ESTIMATORS",
           "bdpt_mis": "pathspace.mis"}


def __getattr__(name: str):
    new = RENAMED.get(name, f"pathspace.estimators.{name}")
    raise AttributeError(f"pathspace.integrators.{name} was renamed: use {new}")
