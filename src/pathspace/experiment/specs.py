"""Naming an estimator configuration: a name and parameters, from Python or from the command line.

``"pt"``, ``("bdpt", {"mis": "balance"})``, ``EstimatorSpec("lt")`` or the
command-line form ``"bdpt:mis=balance,rr=fixed"`` (values read as TOML values:
numbers, booleans, strings, [lists]) all name one configuration; its
``label`` says it in a table or a legend.
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from typing import Any

from ..estimators import Estimator, make_estimator

__all__ = ["EstimatorSpec", "parse_value", "parse_assignment"]


def parse_value(text: str) -> Any:
    """A command-line value: a TOML value (number, boolean, "string", [list]) or else the bare text."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def parse_assignment(text: str) -> tuple[str, Any]:
    """``key=value`` as (key, parsed value); ValueError naming the text otherwise."""
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise ValueError(f"expected key=value, got {text!r}")
    return key.strip(), parse_value(value.strip())


@dataclass(frozen=True)
class EstimatorSpec:
    """An estimator name with parameters, and the label that names the pair."""

    name: str
    params: dict = field(default_factory=dict)
    label: str = ""

    def __post_init__(self) -> None:
        if not self.label:
            extra = ", ".join(f"{k}={v}" for k, v in sorted(self.params.items()))
            object.__setattr__(self, "label", self.name + (f" ({extra})" if extra else ""))

    @classmethod
    def parse(cls, value: Any) -> "EstimatorSpec":
        """A spec from a name, a (name, params) pair, a spec, or the command-line form ``name:k=v,k=v``."""
        if isinstance(value, cls):
            return value
        if isinstance(value, tuple) and len(value) == 2 and isinstance(value[1], dict):
            return cls(value[0], dict(value[1]))
        if isinstance(value, str):
            name, _, rest = value.partition(":")
            params = dict(parse_assignment(part) for part in rest.split(",") if part.strip()) if rest else {}
            return cls(name.strip(), params)
        raise ValueError(f"estimator: expected a name, (name, parameters) or 'name:key=value,...', got {value!r}")

    def make(self, **overrides: Any) -> Estimator:
        """The estimator (ValueError for unknown names or parameters)."""
        return make_estimator(self.name, **{**self.params, **overrides})
