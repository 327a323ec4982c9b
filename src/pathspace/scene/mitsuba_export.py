"""pathspace scenes as Mitsuba 3 scenes: scene XML with PLY meshes, or the scene dict of ``mi.load_dict``.

Every shape becomes a PLY mesh of its triangles in world coordinates (binary little-endian, float64
vertices; ``face_normals`` so that Mitsuba shades them flat, as pathspace does); pathspace's two-sided
materials become Mitsuba BSDFs wrapped in ``twosided`` (dielectrics need not be); lights, camera, film
(with a box filter, pathspace's) and the scene's samples per pixel map as docs/mitsuba.md lists.  The
written scene reads back through :mod:`pathspace.scene.mitsuba_xml` to the same scene.

What Mitsuba 3 cannot express raises one :class:`SceneError` listing each part (dispersive glass, Phong, a
two-sided emitter, a spot light's smooth falloff); what it expresses with a stated difference (the
shadowing term of rough conductors) is listed in one
:class:`~pathspace.scene.mitsuba_xml.MitsubaWarning`.
"""
from __future__ import annotations

import math
import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable
from xml.sax.saxutils import quoteattr

import numpy as np

from ..bsdfs import Conductor, Dielectric, Diffuse, Mirror
from ..camera import PinholeCamera, ThinLensCamera
from ..extras import optional_import
from ..fields import SceneError
from ..lights import AreaLight, DirectionalLight, Environment, PointLight, SpotLight
from ..spectra import GRID, SampledSpectrum, is_spectral
from ..vecmath import orthonormal_basis
from .mitsuba_xml import MitsubaWarning, nearest_distance
from .model import Scene

__all__ = ["LookAt", "export_mitsuba", "mitsuba_dict", "mitsuba_xml", "write_ply"]

# Mitsuba's tag of each plugin the exporter writes.
_TAGS = {"path": "integrator", "perspective": "sensor", "thinlens": "sensor", "hdrfilm": "film", "box": "rfilter",
         "independent": "sampler", "twosided": "bsdf", "diffuse": "bsdf", "conductor": "bsdf", "roughconductor": "bsdf",
         "dielectric": "bsdf", "ply": "shape", "area": "emitter", "point": "emitter", "spot": "emitter",
         "directional": "emitter", "constant": "emitter"}
_TRIPLES = {"position": "point", "direction": "vector"}


@dataclass(frozen=True)
class LookAt:
    """A ``to_world`` transform given as Mitsuba's lookat: world ``origin``, ``target`` and ``up``."""

    origin: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float]


@dataclass
class _Export:
    """A scene as a Mitsuba 3 scene dict (transforms as :class:`LookAt`) and the meshes (file, world
    vertices, faces) it refers to."""

    description: dict[str, Any]
    meshes: list[tuple[Path, np.ndarray, np.ndarray]]

    def write_meshes(self) -> list[Path]:
        """Write the PLY files (creating their folder); returns their paths."""
        for mesh_path, vertices, faces in self.meshes:
            mesh_path.parent.mkdir(parents=True, exist_ok=True)
            write_ply(mesh_path, vertices, faces)
        return [mesh_path for mesh_path, _, _ in self.meshes]


def export_mitsuba(scene: Scene, path: str | Path) -> list[Path]:
    """Write ``scene`` as Mitsuba 3 scene XML at ``path``, its meshes as PLY files in the folder
    ``STEM-meshes`` beside it; returns the files written.  Raises a SceneError listing what Mitsuba cannot
    express (before writing anything); warns (:class:`MitsubaWarning`) about what it expresses differently."""
    path = Path(path)
    folder = path.parent / f"{path.stem}-meshes"
    export = _export(scene, folder, relative_to=path.parent)
    meshes = export.write_meshes()
    path.write_text(mitsuba_xml(export.description), encoding="utf-8")
    return [path] + meshes


def mitsuba_dict(scene: Scene, mesh_folder: str | Path) -> dict[str, Any]:
    """``scene`` as a Mitsuba 3 scene dict for ``mi.load_dict`` (call ``mi.set_variant`` first); its meshes
    are written as PLY files into ``mesh_folder``.  Reports as :func:`export_mitsuba` does."""
    mi = optional_import("mitsuba", "mitsuba_dict", extra="mitsuba")
    if mi.variant() is None:
        raise RuntimeError("mitsuba_dict: choose a Mitsuba variant first, e.g. mitsuba.set_variant('scalar_rgb')")
    export = _export(scene, Path(mesh_folder).resolve(), relative_to=None)
    export.write_meshes()

    def convert(value: Any) -> Any:
        if isinstance(value, LookAt):
            return mi.ScalarTransform4f().look_at(origin=value.origin, target=value.target, up=value.up)
        if isinstance(value, dict):
            return {key: convert(item) for key, item in value.items()}
        return value

    return convert(export.description)


def write_ply(path: str | Path, vertices: np.ndarray, faces: np.ndarray) -> None:
    """A binary little-endian PLY file of triangles: float64 vertices x, y, z; faces as a uchar count and
    three int32 indices."""
    header = ("ply\nformat binary_little_endian 1.0\ncomment written by pathspace\n"
              f"element vertex {len(vertices)}\nproperty double x\nproperty double y\nproperty double z\n"
              f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n")
    records = np.zeros(len(faces), dtype=[("count", "u1"), ("index", "<i4", (3,))])
    records["count"], records["index"] = 3, faces
    Path(path).write_bytes(header.encode("ascii") + np.ascontiguousarray(vertices, dtype="<f8").tobytes()
                           + records.tobytes())


def mitsuba_xml(description: dict[str, Any]) -> str:
    """Mitsuba 3 scene XML of a scene dict whose transforms are :class:`LookAt`."""
    lines = ['<?xml version="1.0" encoding="utf-8"?>', "<!-- written by pathspace (docs/mitsuba.md) -->",
             '<scene version="3.0.0">']
    for key, value in description.items():
        if key != "type":
            lines += _xml_object(value, 1, key)
    return "\n".join(lines + ["</scene>", ""])


def _xml_object(value: dict, depth: int, object_id: str | None = None) -> list[str]:
    pad = "    " * depth
    attrs = f" type={quoteattr(value['type'])}" + (f" id={quoteattr(object_id)}" if object_id else "")
    tag = _TAGS[value["type"]]
    children = [line for name, item in value.items() if name != "type" for line in _xml_property(name, item, depth + 1)]
    return [f"{pad}<{tag}{attrs}>", *children, f"{pad}</{tag}>"] if children else [f"{pad}<{tag}{attrs}/>"]


def _xml_property(name: str, value: Any, depth: int) -> list[str]:
    pad, key = "    " * depth, quoteattr(name)
    if isinstance(value, LookAt):
        origin, target, up = (quoteattr(", ".join(map(repr, v))) for v in (value.origin, value.target, value.up))
        return [f"{pad}<transform name={key}>", f"{pad}    <lookat origin={origin} target={target} up={up}/>",
                f"{pad}</transform>"]
    if isinstance(value, dict):
        kind = value["type"]
        if kind == "rgb":
            return [f"{pad}<rgb name={key} value={quoteattr(', '.join(map(repr, value['value'])))}/>"]
        if kind == "spectrum":
            pairs = ", ".join(f"{w!r}:{v!r}" for w, v in value["value"])
            return [f"{pad}<spectrum name={key} value={quoteattr(pairs)}/>"]
        if kind == "ref":
            return [f"{pad}<ref id={quoteattr(value['id'])}/>"]
        return _xml_object(value, depth)
    if isinstance(value, bool):
        return [f"{pad}<boolean name={key} value=\"{'true' if value else 'false'}\"/>"]
    if isinstance(value, int):
        return [f"{pad}<integer name={key} value=\"{value}\"/>"]
    if isinstance(value, float):
        return [f"{pad}<float name={key} value=\"{value!r}\"/>"]
    if isinstance(value, str):
        return [f"{pad}<string name={key} value={quoteattr(value)}/>"]
    return [f"{pad}<{_TRIPLES[name]} name={key} value={quoteattr(', '.join(map(repr, value)))}/>"]


def _colour(value: Any) -> dict:
    """An RGB triple as ``rgb``; a spectrum as the wavelength:value pairs pathspace interpolates (a sampled
    spectrum's own; a blackbody's or an illuminant's on pathspace's 1 nm grid)."""
    if not is_spectral(value):
        return {"type": "rgb", "value": [float(x) for x in value]}
    if isinstance(value, SampledSpectrum):
        pairs = zip(value.wavelengths, np.multiply(value.values, value.scale))
    else:
        pairs = zip(GRID, value.on_grid())
    return {"type": "spectrum", "value": [(float(w), float(v)) for w, v in pairs]}


def _bsdf(name: str, material: Any, problems: list[str], notes: list[str]) -> dict:
    """The Mitsuba BSDF of a material (its two-sided models wrapped in ``twosided``)."""
    if isinstance(material, Diffuse):
        inner = {"type": "diffuse", "reflectance": _colour(material.reflectance)}
    elif isinstance(material, Mirror):
        inner = {"type": "conductor", "material": "none", "specular_reflectance": _colour(material.reflectance)}
    elif isinstance(material, Conductor):
        inner = {"type": "roughconductor", "distribution": "ggx", "alpha": float(material.alpha),
                 "eta": _colour(material.eta), "k": _colour(material.k)}
        notes.append(f"material {name!r}: Mitsuba's roughconductor shadows with the separable Smith term "
                     "G1(wi) G1(wo), pathspace's conductor with the height-correlated form: they differ at grazing "
                     "angles on rough surfaces")
    elif isinstance(material, Dielectric):
        if material.dispersive:
            problems.append(f"material {name!r}: a dispersive dielectric ({material.ior}); Mitsuba's has one index")
            return {"type": "dielectric"}
        return {"type": "dielectric", "int_ior": float(material.ior), "ext_ior": 1.0}
    else:
        problems.append(f"material {name!r}: Mitsuba 3 has no {material.kind} model")
        return {"type": "diffuse"}
    return {"type": "twosided", "material": inner}


def _clip_planes(scene: Scene) -> tuple[float, float]:
    """Near and far clipping planes that cut no geometry: half the nearest distance to the geometry (less the
    lens radius) over the secant of the image corner, and twice the farthest vertex distance."""
    camera, mesh = scene.camera, scene.mesh
    farthest = float(np.linalg.norm(mesh.vertices - camera.position, axis=1).max()) + camera.lens_radius
    nearest = nearest_distance(mesh.vertices, mesh.indices, camera.position) - camera.lens_radius
    near = 0.5 * nearest / math.hypot(1.0, *camera.tan_half)
    return (near if near > 0 else 1e-7 * farthest), 2.0 * farthest


def _sensor(scene: Scene, problems: list[str]) -> dict:
    camera = scene.camera
    if type(camera) not in (PinholeCamera, ThinLensCamera):
        problems.append(f"camera: Mitsuba 3 has no counterpart of {type(camera).__name__}")
    near, far = _clip_planes(scene)
    film = {"type": "hdrfilm", "width": camera.width, "height": camera.height, "rfilter": {"type": "box"}}
    sensor = {"type": "thinlens" if isinstance(camera, ThinLensCamera) else "perspective", "fov": float(camera.fov),
              "fov_axis": camera.fov_axis, "near_clip": near, "far_clip": far,
              "to_world": LookAt(tuple(scene.to_world(camera.position).tolist()),
                                 tuple(scene.to_world(camera.look_at).tolist()), tuple(camera.up.tolist())),
              "film": film}
    if isinstance(camera, ThinLensCamera):
        sensor.update(aperture_radius=camera.lens_radius, focus_distance=camera.focus_distance)
    if scene.render_spp is not None:
        sensor["sampler"] = {"type": "independent", "sample_count": int(scene.render_spp)}
    return sensor


def _light(light: Any, to_world: Callable[[Any], np.ndarray], problems: list[str]) -> dict:
    """A point, spot, directional or environment light as a Mitsuba emitter (``to_world``: the scene's)."""
    if isinstance(light, PointLight):
        return {"type": "point", "position": to_world(light.position).tolist(),
                "intensity": _colour(light.intensity)}
    if isinstance(light, SpotLight):
        if light.falloff_start < light.cone_angle:
            problems.append(f"spot light at {to_world(light.position).tolist()}: falloff_start "
                            f"{light.falloff_start:g} < cone_angle {light.cone_angle:g}: pathspace's smooth falloff "
                            "has no Mitsuba counterpart (Mitsuba's is linear in angle); a hard edge has")
        up = orthonormal_basis(light.axis[:, None])[0][:, 0]
        return {"type": "spot", "to_world": LookAt(tuple(to_world(light.position).tolist()),
                                                   tuple(to_world(light.look_at).tolist()), tuple(up.tolist())),
                "intensity": _colour(light.intensity), "cutoff_angle": float(light.cone_angle),
                "beam_width": float(light.cone_angle)}
    if isinstance(light, DirectionalLight):
        return {"type": "directional", "direction": [float(x) for x in light.direction],
                "irradiance": _colour(light.irradiance)}
    if isinstance(light, Environment):
        return {"type": "constant", "radiance": _colour(light.radiance)}
    problems.append(f"light {light!r}: Mitsuba 3 has no counterpart")
    return {"type": "point"}


def _unique(name: str, taken: set[str]) -> str:
    while name in taken:
        name += "'"
    taken.add(name)
    return name


def _export(scene: Scene, folder: Path, relative_to: Path | None) -> _Export:
    """The Mitsuba description of ``scene``; mesh files are named in ``folder`` (relative to ``relative_to``
    when given)."""
    problems: list[str] = []
    notes: list[str] = []
    taken = {"type", "integrator", "sensor"}
    # Mitsuba's path tracer with unbounded depth: the full solution, as pathspace's estimators by default.
    description: dict[str, Any] = {"type": "scene", "integrator": {"type": "path", "max_depth": -1},
                                   "sensor": _sensor(scene, problems)}
    material_ids = []
    for name, material in zip(scene.materials.names, scene.materials.materials):
        material_ids.append(_unique(name, taken))
        description[material_ids[-1]] = _bsdf(name, material, problems, notes)
    area_lights = [light for light in scene.lights.lights if isinstance(light, AreaLight)]
    emitter_of = np.full(scene.mesh.triangle_count, -1)
    for k, light in enumerate(area_lights):
        emitter_of[light.triangles] = k
    meshes = []
    for i, shape_name in enumerate(scene.shape_names):
        triangles = np.flatnonzero(scene.mesh.shape == i)
        groups = sorted(set(zip(scene.mesh.material[triangles].tolist(), emitter_of[triangles].tolist())))
        for part, (material, emitter) in enumerate(groups):
            chosen = triangles[(scene.mesh.material[triangles] == material) & (emitter_of[triangles] == emitter)]
            used, faces = np.unique(scene.mesh.indices[chosen], return_inverse=True)
            key = _unique(shape_name if part == 0 else f"{shape_name}#{part}", taken)
            mesh_path = folder / f"{len(meshes):03d}-{re.sub(r'[^A-Za-z0-9_.-]+', '_', key)}.ply"
            meshes.append((mesh_path, scene.to_world(scene.mesh.vertices[used]), faces.reshape(-1, 3)))
            filename = (mesh_path.relative_to(relative_to) if relative_to else mesh_path).as_posix()
            shape = {"type": "ply", "filename": filename,
                     "face_normals": True, "bsdf": {"type": "ref", "id": material_ids[material]}}
            if emitter >= 0:
                light = area_lights[emitter]
                if light.two_sided:
                    problems.append(f"shape {shape_name!r}: a two-sided emitter; Mitsuba's area lights emit on one "
                                    "side")
                shape["emitter"] = {"type": "area", "radiance": _colour(light.radiance)}
            description[key] = shape
    for k, light in enumerate(light for light in scene.lights.lights if not isinstance(light, AreaLight)):
        description[_unique(f"light-{k}", taken)] = _light(light, scene.to_world, problems)
    if problems:
        raise SceneError(f"{scene.source or '(scene)'}: cannot be written as a Mitsuba 3 scene:\n  "
                         + "\n  ".join(problems))
    if notes:
        warnings.warn(f"{scene.source or '(scene)'}: written for Mitsuba 3 with {len(notes)} difference(s):\n  "
                      + "\n  ".join(notes), MitsubaWarning, stacklevel=3)
    return _Export(description, meshes)
