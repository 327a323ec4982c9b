"""The worked examples of docs/architecture.md run as written and do what the text says: a new estimator,
a new light kind and a new material, each one model and one registry entry."""
from __future__ import annotations

import re

import numpy as np

from pathspace import bsdfs, lights
from pathspace.estimators import ESTIMATORS
from conftest import ROOT, agree


def test_architecture_examples(monkeypatch):
    text = (ROOT / "docs" / "architecture.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert len(blocks) == 3
    monkeypatch.chdir(ROOT)
    saved = [dict(r) for r in (ESTIMATORS, lights.LIGHTS, bsdfs.KINDS)]  # the examples register into these
    namespace: dict = {}
    try:
        for block in blocks:
            exec(compile(block, "docs/architecture.md", "exec"), namespace)
    finally:
        for registry, before in zip((ESTIMATORS, lights.LIGHTS, bsdfs.KINDS), saved):
            registry.clear()
            registry.update(before)
    # The albedo estimator: each pixel is 2 x the albedo of what it sees (inside surfaces, not edges).
    albedo, scene = namespace["albedo"], namespace["scene"]
    on_a_surface = np.isin(albedo.image[..., 0], 2.0 * scene.materials.albedo)
    assert on_a_surface.mean() > 0.8 and albedo.stats["estimator"] == "albedo"
    # The lobe light and the translucent sheet: path tracing and BDPT estimate the same image.
    for a, b in (("lobe_pt", "lobe_bdpt"), ("sheet_pt", "sheet_bdpt")):
        assert namespace[a].image.mean() > 0.01
        ok, report = agree(namespace[a], namespace[b])
        assert ok, (a, report)
