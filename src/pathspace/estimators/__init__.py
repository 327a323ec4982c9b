"""Estimators of the light-transport integral, by name.

``make_estimator(name, **params)`` builds one.  Every estimator is a
dataclass whose fields are its parameters (see
:mod:`pathspace.estimators.base` for the contract and
``Estimator.parameters()`` for each parameter's meaning), so parameters are
reachable by name from Python, the command line and sweeps.  Adding an
estimator is one module and one entry in :data:`ESTIMATORS`.
"""
from __future__ import annotations

import dataclasses

from .base import Estimator
from .bdpt import BDPT
from .lt import LightTracer
from .mlt import MLT
from .mmlt import MMLT
from .pssmlt import PSSMLT
from .pt import PathTracer

__all__ = ["ESTIMATORS", "Estimator", "make_estimator"]

ESTIMATORS: dict[str, type[Estimator]] = {"pt": PathTracer, "lt": LightTracer, "bdpt": BDPT, "pssmlt": PSSMLT,
                                             "mmlt": MMLT, "mlt": MLT}


def make_estimator(name: str, **params) -> Estimator:
    """The estimator called ``name`` with the given parameters (ValueError for unknown names or parameters)."""
    if name not in ESTIMATORS:
        raise ValueError(f"unknown estimator {name!r}; available: {', '.join(ESTIMATORS)}")
    cls = ESTIMATORS[name]
    known = [f.name for f in dataclasses.fields(cls) if f.init]
    unknown = sorted(set(params) - set(known))
    if unknown:
        raise ValueError(f"estimator {name!r} has no parameter(s) {', '.join(unknown)}; "
                         f"its parameters are: {', '.join(known)}")
    return cls(**params)
