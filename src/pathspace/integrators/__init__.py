"""Estimators of the light-transport integral, by name.

``make_integrator(name, **params)`` builds one; every estimator is a
dataclass whose fields are its parameters (documented in its module), so the
parameters are reachable by name from Python, the command line and sweeps.
"""
from __future__ import annotations

import dataclasses

from .base import TILE_PIXELS, WorkItem, work_layout
from .bdpt import BDPT
from .lt import LightTracer
from .pt import PathTracer

__all__ = ["ESTIMATORS", "make_integrator", "WorkItem", "TILE_PIXELS", "work_layout"]

ESTIMATORS = {"pt": PathTracer, "lt": LightTracer, "bdpt": BDPT}


def make_integrator(name: str, **params):
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
