"""Furnace scenes: closed enclosures with analytic radiance.

Inside a closed diffuse enclosure whose walls all emit radiance Le and
reflect with albedo rho, radiance is the same everywhere and in every
direction: L = Le + rho L, so L = Le / (1 - rho).  Every estimator must
reproduce it, for every channel and every pixel.
"""
from __future__ import annotations

from ..scene import Scene, scene_from_dict

__all__ = ["furnace_scene", "furnace_radiance"]


def furnace_radiance(albedo: float, emission: float) -> float:
    """The exact radiance Le / (1 - rho) inside a furnace."""
    if not 0.0 <= albedo < 1.0:
        raise ValueError(f"albedo must lie in [0, 1) for a finite answer, got {albedo}")
    return emission / (1.0 - albedo)


def furnace_scene(albedo: float, emission: float = 1.0, resolution: tuple[int, int] = (32, 32),
                  size: float = 2.0) -> Scene:
    """A cube of edge ``size`` centred at the origin, emitting and reflecting inward, seen from its centre."""
    return scene_from_dict({
        "name": f"furnace albedo={albedo:g}",
        "camera": {"position": [0.0, 0.0, 0.0], "look_at": [0.0, 0.0, -1.0], "up": [0.0, 1.0, 0.0],
                   "fov": 90.0, "resolution": list(resolution)},
        "materials": {"wall": {"type": "diffuse", "reflectance": [albedo] * 3}},
        "shapes": [{"name": "enclosure", "type": "box", "size": [size] * 3, "material": "wall",
                    "flip_normals": True, "emitter": {"radiance": [emission] * 3}}],
    }, source=f"<furnace albedo={albedo:g}>")
