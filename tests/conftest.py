"""Shared fixtures: the repository's scenes and small variants of them."""
from __future__ import annotations

import copy
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

import pathspace as ps
from pathspace.bsdfs import Diffuse
from pathspace.estimators.subpaths import FIELDS, SURFACE, Subpaths
from pathspace.validate import compare_estimates

ROOT = Path(__file__).resolve().parent.parent
CORNELL = ROOT / "scenes" / "cornell-box" / "scene.toml"


def run_cli(*args, cwd=None) -> subprocess.CompletedProcess:
    """``pathspace ARGS`` in a fresh interpreter, output captured."""
    return subprocess.run([sys.executable, "-m", "pathspace.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd)


def cornell_file(folder, width: int, height: int):
    """The Cornell box scene file at ``width`` x ``height``, written to ``folder/scene.toml``."""
    scene = folder / "scene.toml"
    scene.write_text(CORNELL.read_text().replace("resolution = [256, 256]", f"resolution = [{width}, {height}]"))
    return scene


def repository_scene(name: str, resolution=(24, 24), **overrides) -> ps.Scene:
    """The scene ``scenes/NAME/scene.toml`` loaded at ``resolution`` (with any other overrides)."""
    return ps.load_scene(ROOT / "scenes" / name / "scene.toml", **{"camera.resolution": list(resolution)},
                         **overrides)


def same_bits(a: np.ndarray, b: np.ndarray, what: str = "") -> None:
    """a and b hold the same numbers bit for bit (compared as integers: -0.0 differs from 0.0, and NaNs of the
    same payload agree)."""
    a, b = np.ascontiguousarray(a), np.ascontiguousarray(b)
    assert a.dtype == b.dtype and a.shape == b.shape, what
    if a.dtype.kind == "f":
        a, b = a.view(f"i{a.itemsize}"), b.view(f"i{b.itemsize}")
    np.testing.assert_array_equal(a, b, err_msg=what)


def extreme(rng: np.random.Generator, n: int, rows: int | None = None, share: float = 0.01) -> np.ndarray:
    """n positive numbers (or rows of them) over 300 decades, a ``share`` each of them zero, negative zero,
    infinite or NaN."""
    x = 10.0 ** rng.uniform(-150, 150, n if rows is None else (rows, n))
    for value in (0.0, -0.0, np.inf, np.nan):
        x[..., rng.random(n) < share] = value
    return x


def extreme_normals_and_directions(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(unit normals, unit directions back) (3, n) float64 of made-up vertices: seen from both sides and edge-on,
    some directions NaN, some normals zero (no cosine factor) or NaN."""
    normal = rng.normal(size=(3, n))
    normal /= np.linalg.norm(normal, axis=0)
    wo = rng.normal(size=(3, n))
    wo /= np.linalg.norm(wo, axis=0)
    edge = rng.random(n) < 0.03
    wo[:, edge] = np.cross(normal.T, rng.normal(size=(n, 3))).T[:, edge]   # edge-on (cos ~ 0)
    wo[:, edge] /= np.linalg.norm(wo[:, edge], axis=0)
    wo[:, rng.random(n) < 0.01] = np.nan
    normal[:, rng.random(n) < 0.02] = 0.0                                   # no normal: cos_at is 1
    normal[:, rng.random(n) < 0.01] = np.nan
    return normal, wo


def made_up_side(sc, rng: np.random.Generator, n: int, connect: int, points: np.ndarray | None = None) -> Subpaths:
    """n one-vertex subpaths of diffuse surface vertices inside the scene's bounds (at ``points`` where given):
    seen from both sides and edge-on, some with zero or NaN normals or NaN directions back or positions; extreme
    throughputs, densities and survival probabilities."""
    low, high = sc.mesh.vertices.min(axis=0), sc.mesh.vertices.max(axis=0)
    p = rng.uniform(low, high, (n, 3)).T if points is None else points.copy()
    p[:, rng.random(n) < 0.005] = np.nan
    normal, wo = extreme_normals_and_directions(rng, n)
    diffuse = np.flatnonzero([type(m) is Diffuse for m in sc.materials.materials])
    fields = dict.fromkeys(FIELDS)
    fields.update(lane=np.arange(n), index=rng.integers(1, 6, n), p=p.astype(np.float32),
                  n=normal.astype(np.float32), eps=np.full(n, 1e-5, np.float32), wo=wo.astype(np.float32),
                  beta=extreme(rng, n, 3), delta=np.zeros(n, bool), kind=np.full(n, SURFACE, np.int8),
                  material=rng.choice(diffuse, n), entity=np.full(n, -1), u=rng.random((connect, n)),
                  infinite=np.zeros(n, bool),
                  **{name: extreme(rng, n) for name in ("fwd", "rev", "g_prev", "q", "q_rev")})
    return Subpaths(offset=np.arange(n + 1), terminated=np.zeros(n, bool), **fields)


def nothing_blocked(scene, a, eps_a, n_a, b, eps_b, n_b, lanes=None, b_lanes=None) -> np.ndarray:
    """A stand-in for :func:`pathspace.estimators.visibility.segment_blocked` under which no segment is blocked."""
    return np.zeros(a.shape[1] if lanes is None else lanes.size, bool)


def extreme_arrivals(mesh, rng: np.random.Generator, n: int):
    """(triangles, barycentrics b1, b2, geometric normals, directions (3, n) float32) of n rays arriving on random
    triangles of ``mesh`` (about as many of each material): from both sides, at grazing angles, some along NaN
    directions."""
    prim = balanced_triangles(mesh, rng, n)
    b1, b2 = rng.random(n), rng.random(n)
    flip = b1 + b2 > 1
    b1[flip], b2[flip] = 1 - b1[flip], 1 - b2[flip]
    b1, b2 = b1.astype(np.float32), b2.astype(np.float32)
    _, normal, _ = mesh.hit_geometry(prim, b1, b2)
    tangent = np.cross(normal.T, rng.normal(size=(n, 3))).T
    tangent /= np.linalg.norm(tangent, axis=0)
    height = np.where(rng.random(n) < 0.3, 10.0 ** rng.uniform(-9, -2, n), rng.uniform(0.0, 1.0, n))
    side = np.where(rng.random(n) < 0.5, 1.0, -1.0)
    direction = -(side * height * normal + np.sqrt(1 - height ** 2) * tangent)   # toward the surface
    direction = (direction / np.linalg.norm(direction, axis=0)).astype(np.float32)
    direction[:, rng.random(n) < 0.01] = np.nan
    return prim, b1, b2, normal, direction


def sky_quad_scene() -> ps.Scene:
    """A grey quad under a uniform sky (an environment light), seen by a pinhole camera at 8x8."""
    return ps.scene_from_dict({
        "camera": {"position": [0, 0, 5], "look_at": [0, 0, 0], "fov": 30, "resolution": [8, 8]},
        "materials": {"grey": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}},
        "shapes": [{"type": "quad", "corner": [-1, -1, 0], "edge_u": [2, 0, 0], "edge_v": [0, 2, 0],
                    "material": "grey"}],
        "lights": [{"type": "environment", "radiance": [1, 1, 1]}]})


def balanced_triangles(mesh, rng: np.random.Generator, n: int) -> np.ndarray:
    """n random triangles (int32) of ``mesh``, about as many of each of its materials (a scene's spheres have far
    more triangles than its walls)."""
    groups = [np.flatnonzero(mesh.material == m) for m in np.unique(mesh.material)]
    group = rng.integers(0, len(groups), n)
    prim = np.empty(n, np.int32)
    for k, triangles in enumerate(groups):
        mine = group == k
        prim[mine] = rng.choice(triangles, int(mine.sum()))
    return prim


def count_lanes(monkeypatch, kernel: str, argument: int) -> list[int]:
    """Wrap ``_native.<kernel>`` so that it counts the lanes it is given (the size of its positional
    ``argument``); returns the count, a list of one number that grows with each call."""
    from pathspace import _native

    lanes, original = [0], getattr(_native, kernel)

    def counted(*args):
        lanes[0] += args[argument].size
        return original(*args)

    monkeypatch.setattr(_native, kernel, counted)
    return lanes


def scene_dict(name: str, resolution=(32, 32)) -> dict:
    """The scene file ``scenes/NAME/scene.toml`` as a dict, with another resolution."""
    data = tomllib.loads((ROOT / "scenes" / name / "scene.toml").read_text())
    data["camera"]["resolution"] = list(resolution)
    return data


def cornell_dict(resolution=(64, 64)) -> dict:
    """The Cornell box scene file as a dict, with another resolution."""
    return scene_dict("cornell-box", resolution)


def scaled(data: dict, factor: float) -> dict:
    """The same scene with every length multiplied by ``factor`` (radiance is scale-free)."""
    data = copy.deepcopy(data)
    for shape in data["shapes"]:
        shape.setdefault("transform", {})
        transform = shape["transform"]
        transform["scale"] = np.multiply(transform.get("scale", 1.0), factor).tolist()
        transform["translate"] = (np.asarray(transform.get("translate", [0.0, 0.0, 0.0])) * factor).tolist()
    camera = data["camera"]
    for key in ("position", "look_at"):
        camera[key] = (np.asarray(camera[key]) * factor).tolist()
    if "focus_distance" in camera:
        camera["focus_distance"] *= factor
        camera["aperture_radius"] *= factor
    return data


def moved(data: dict, rotation: np.ndarray, translation) -> dict:
    """The same scene with every position x mapped to R x + t (``rotation`` R, ``translation`` t): its shapes
    become inline triangles in world coordinates; the camera and point-like lights move with them."""
    scene = ps.scene_from_dict(data)
    world = scene.to_world(scene.mesh.vertices)
    out = copy.deepcopy(data)
    out["shapes"] = []
    for i, shape in enumerate(data["shapes"]):
        used, local = np.unique(scene.mesh.indices[scene.mesh.shape == i], return_inverse=True)
        entry = {key: value for key, value in shape.items() if key in ("name", "material", "emitter")}
        entry.update(type="triangles", vertices=(world[used] @ rotation.T + translation).tolist(),
                     triangles=local.reshape(-1, 3).tolist())
        out["shapes"].append(entry)
    for table, keys in [(out["camera"], ("position", "look_at"))] + [(light, ("position", "look_at"))
                                                                      for light in out.get("lights", [])]:
        for key in keys:
            if key in table:
                table[key] = (rotation @ np.asarray(table[key], dtype=float) + translation).tolist()
    for table, key in [(out["camera"], "up")] + [(light, "direction") for light in out.get("lights", [])]:
        if key in table or key == "up":
            table[key] = (rotation @ np.asarray(table.get(key, [0.0, 1.0, 0.0]), dtype=float)).tolist()
    return out


def rotation_about(axis, degrees: float) -> np.ndarray:
    """The 3x3 rotation by ``degrees`` about ``axis`` (Rodrigues' formula)."""
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    angle = np.radians(degrees)
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def agree(a, b, block=8, alpha=1e-3, mask=None) -> tuple[bool, str]:
    """Whether renders ``a`` and ``b`` estimate the same image (block-wise z-test), and the report;
    pixels outside ``mask`` are left out (set equal in both)."""
    image_b, variance_b = b.image, b.variance
    if mask is not None:
        image_b = np.where(mask[..., None], b.image, a.image)
        variance_b = np.where(mask[..., None], b.variance, a.variance)
    result = compare_estimates(a.image, a.variance, image_b, variance_b, block=block, alpha=alpha)
    return result.passed, str(result)


@pytest.fixture(scope="session")
def cornell() -> ps.Scene:
    """The Cornell box at its native 256 x 256."""
    return ps.load_scene(CORNELL)


@pytest.fixture(scope="session")
def cornell_small() -> ps.Scene:
    """The Cornell box at 64 x 64."""
    return ps.scene_from_dict(cornell_dict((64, 64)), source="cornell-64")


def no_nonfinite(result) -> bool:
    """Neither a pixel sample nor a connection was dropped for a NaN or Inf."""
    return result.stats["nonfinite"] == 0 and result.stats["nonfinite_contributions"] == 0


def mean_and_error(result, channel=0) -> tuple[float, float]:
    """Mean over pixels of one channel and its standard error (pixels are independent)."""
    values = result.image[..., channel]
    return values.mean(), np.sqrt(result.variance[..., channel].sum()) / values.size
