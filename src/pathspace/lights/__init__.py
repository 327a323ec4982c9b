"""The lights of a scene: one model per kind, and the set that chooses among them.

Models (one module each, see :mod:`pathspace.lights.base` for the interface
they share): :class:`AreaLight` (emitting triangles), :class:`PointLight`,
:class:`SpotLight`, :class:`DirectionalLight`, :class:`Environment`.
:data:`LIGHTS` names the kinds a scene's ``[[lights]]`` tables can have;
area lights come from shapes' ``emitter`` tables.

A :class:`LightSet` holds a scene's lights as *entities* -- one per emitting
triangle, one per other light -- and picks one from a discrete pmf, by
power ("power": emitted power; triangles of an area light in proportion to
their power) or uniformly over lights ("uniform": every light equally
likely, triangles of an area light by area).  Its verbs mirror the models'
(``sample_li``, ``pdf_li``, ``sample_le``, ``pdf_le``, ``le``) over entities
of any kind: lanes are grouped by kind and each group goes to its model.
Densities include the selection pmf; for delta lights (point, spot,
directional) the "pdf" is the pmf alone and the sample is flagged ``delta``.
"""
from __future__ import annotations

import dataclasses
from functools import cached_property

import numpy as np

from ..mis import LIGHT_DELTA, LIGHT_INFINITE
from ..spectra import is_spectral
from .area import MEASURES, AreaLight, AreaTables
from .base import EmissionSample, Light, LightContext, LightSample
from .directional import DirectionalLight
from .environment import Environment
from .point import PointLight
from .spot import SpotLight

__all__ = ["AreaLight", "AreaTables", "DirectionalLight", "EmissionSample", "Environment", "LIGHTS", "Light",
           "LightContext", "LightSample", "LightSet", "MEASURES", "PointLight", "SELECTIONS", "SpotLight"]

SELECTIONS = ("power", "uniform")
# The light interface before each kind became a model (issue 10), and what replaced each name.
_RENAMED = {"sample": "sample_li", "pdf_hit": "pdf_li (of the emitting triangle's entity)",
            "sample_emission": "sample_le", "origin_pdf": "pdf_le(...)[0]", "emission_pdf_dir": "pdf_le(...)[1]",
            "emitted_toward": "le (times |cos| at area lights)", "environment_radiance": "le with environment_entity",
            "pdf_environment": "pdf_li with environment_entity", "disk_center": "context.disk_center",
            "disk_radius": "context.disk_radius", "others": "lights"}
# The kinds of [[lights]] tables in scene files; area lights are shapes' emitters.  Entities are numbered
# kind by kind: area lights first, then in this order.
LIGHTS: dict[str, type[Light]] = {model.kind: model for model in (PointLight, SpotLight, DirectionalLight, Environment)}


class LightSet:
    """All lights of a scene as entities; see the module docstring.

    ``lights``: the scene's light models (area lights with their triangles).
    ``scene_radius``: of a sphere holding all geometry; the power of lights
    at infinity (for light selection) is what crosses it.  ``disk_center``,
    ``disk_radius``: a sphere holding all geometry and the camera's lens (a
    thin lens can be hit); rays from lights at infinity start on a disk just
    outside it.
    """

    def __init__(self, lights: list[Light], mesh, scene_radius: float, disk_center, disk_radius: float) -> None:
        self.lights = list(lights)
        self.context = LightContext(mesh, float(scene_radius), np.asarray(disk_center, dtype=np.float64),
                                    float(disk_radius) * 1.01 + 1e-30)
        self.models: list[type[Light]] = []
        self.tables: list = []
        kind_of, index, power, light_id = [], [], [], []
        order = (AreaLight,) + tuple(LIGHTS.values())
        unknown = {type(light).__name__ for light in self.lights if type(light) not in order}
        if unknown:
            raise ValueError(f"lights: {', '.join(sorted(unknown))} is not a registered light model "
                             f"(pathspace.lights.LIGHTS: {', '.join(LIGHTS)})")
        lights_before = 0  # light ids: the emitting triangles of an area light share one
        for model in order:
            group = [light for light in self.lights if type(light) is model]
            if model is AreaLight:
                self.area: AreaTables = model.tables(group, self.context)
                count, tables = self.area.count, self.area
                ids = np.unique(self.area.light_of, return_inverse=True)[1].ravel()
            elif group:
                count, tables = len(group), model.tables(group, self.context)
                ids = lights_before + np.arange(count)
            else:
                continue
            lights_before += int(np.unique(ids).size)
            if not count:
                continue
            self.models.append(model)
            self.tables.append(tables)
            kind_of.append(np.full(count, len(self.models) - 1))
            index.append(np.arange(count))
            power.append(np.asarray(model.power(tables, self.context), dtype=np.float64))
            light_id.append(ids)
        self.kind_of = np.concatenate(kind_of or [np.zeros(0)]).astype(np.int64)
        self.index = np.concatenate(index or [np.zeros(0)]).astype(np.int64)
        self.power = np.concatenate(power or [np.zeros(0)]).astype(np.float64)
        self.light_id = np.concatenate(light_id or [np.zeros(0)]).astype(np.int64)
        flags = [LIGHT_DELTA * model.delta + LIGHT_INFINITE * model.infinite for model in self.models]
        self.flags = np.array(flags, dtype=np.uint8).take(self.kind_of) if flags else np.zeros(0, np.uint8)
        self.environment: Light | None = None  # the light rays leaving the scene see, if any
        self.environment_entity = -1
        for k, model in enumerate(self.models):
            if model.hit_by_escaping_rays:
                self.environment = next(light for light in self.lights if type(light) is model)
                self.environment_entity = int(np.flatnonzero(self.kind_of == k)[0])

    def __getattr__(self, name: str):
        if name in _RENAMED:
            raise AttributeError(f"LightSet.{name} was renamed: use {_RENAMED[name]}")
        raise AttributeError(name)

    @property
    def count(self) -> int:
        """Number of sampling entities (emitting triangles count one each)."""
        return int(self.kind_of.size)

    @property
    def has_delta(self) -> bool:
        """Whether some light cannot be hit by rays."""
        return any(model.delta for model in self.models)

    def spectral_reasons(self) -> list[str]:
        """Why the lights need spectral rendering (empty: RGB suffices)."""
        reasons = []
        for light in self.lights:
            if any(is_spectral(getattr(light, f.name)) for f in dataclasses.fields(light)):
                reasons.append(f"a{'n' if light.kind[0] in 'aeiou' else ''} {light.kind} light emits a spectrum")
        return sorted(set(reasons))

    def __repr__(self) -> str:
        parts = [f"{self.area.count} emitting triangles in {self.area.light_count} area lights"]
        for model in self.models:
            number = sum(type(light) is model for light in self.lights)
            if model is not AreaLight:
                parts.append(f"{number} {model.kind}")
        return f"LightSet({', '.join(parts)}; total power {self.power.sum():.6g} W)"

    # -- selection ---------------------------------------------------------------------------------

    @cached_property
    def _pmfs(self) -> dict[str, np.ndarray]:
        if self.count == 0:
            return {s: np.zeros(0) for s in SELECTIONS}
        weight = np.ones(self.count)
        weight[: self.area.count] = self.area.area  # by area within a light
        per_light = np.bincount(self.light_id, weights=weight)
        return {"power": self.power / self.power.sum(),
                "uniform": weight / per_light[self.light_id] / per_light.size}

    def pmf(self, selection: str) -> np.ndarray:
        """Selection probability of every entity."""
        if selection not in SELECTIONS:
            raise ValueError(f"light selection: expected one of {SELECTIONS}, got {selection!r}")
        return self._pmfs[selection]

    def cdf(self, selection: str) -> np.ndarray:
        """Cumulative selection probabilities of the entities (the last 1), which :meth:`select` searches."""
        self.pmf(selection)
        return self._cdfs[selection]

    @cached_property
    def _cdfs(self) -> dict[str, np.ndarray]:
        cdfs = {}
        for selection in SELECTIONS:
            cdf = np.cumsum(self.pmf(selection))
            cdfs[selection] = cdf / cdf[-1] if cdf.size else cdf
        return cdfs

    def select(self, u: np.ndarray, selection: str) -> np.ndarray:
        """Entities chosen by ``selection`` from uniforms ``u`` (N,)."""
        return np.minimum(np.searchsorted(self.cdf(selection), u, side="right"), self.count - 1)

    # -- dispatch ----------------------------------------------------------------------------------

    def _groups(self, entity: np.ndarray):
        """(model, tables, lanes or None for all, index within the kind) for each kind among ``entity``."""
        if len(self.models) == 1 or not entity.size:
            return [(self.models[0], self.tables[0], None, self.index.take(entity))]
        kind = self.kind_of.take(entity)
        groups = []
        for k in np.unique(kind):
            lanes = np.flatnonzero(kind == k)
            groups.append((self.models[k], self.tables[k], lanes, self.index.take(entity.take(lanes))))
        return groups

    @staticmethod
    def _merge(parts: list, count: int):
        """One record (LightSample, EmissionSample, array or tuple of arrays) from per-kind records."""
        if len(parts) == 1 and parts[0][0] is None:
            return parts[0][1]
        first = parts[0][1]
        if isinstance(first, tuple):
            return tuple(LightSet._merge([(lanes, part[i]) for lanes, part in parts], count) for i in range(len(first)))
        if isinstance(first, np.ndarray):
            out = np.empty(first.shape[:-1] + (count,), dtype=first.dtype)
            for lanes, part in parts:
                out[..., lanes] = part
            return out
        fields = {f.name: LightSet._merge([(lanes, getattr(part, f.name)) for lanes, part in parts], count)
                  for f in dataclasses.fields(first) if getattr(first, f.name) is not None}
        return type(first)(**fields)

    def _each(self, entity: np.ndarray, call):
        """``call(model, tables, lanes, idx)`` for every kind among ``entity``, merged over lanes."""
        parts = [(lanes, call(model, tables, lanes, idx)) for model, tables, lanes, idx in self._groups(entity)]
        return self._merge(parts, entity.size)

    # -- the verbs over entities -------------------------------------------------------------------

    def sample_li(self, receivers: np.ndarray, u: np.ndarray, colours, selection: str = "power",
                  measure: str = "area") -> LightSample:
        """One light sample per receiver point (3, N) from uniforms u (3, N): a light by ``selection``, a
        point on it by ``measure``; the density includes the pmf.  Where every light is an area light and
        points are sampled by area (the default), both steps are one C pass (``ext/lights.c``, bit for bit
        the NumPy code of the other cases, :meth:`AreaTables.sample`)."""
        if self.models == [AreaLight] and measure == "area" and receivers.dtype == np.float32 and u.dtype == np.float64:
            return AreaLight.sample_li_selected(self.area, self.cdf(selection), self.pmf(selection), receivers,
                                                u, colours)
        entity = self.select(u[0], selection)
        pmf = self.pmf(selection).take(entity)
        if len(self.models) == 1:
            sample = self.models[0].sample_li(self.tables[0], self.index.take(entity), receivers, u[1:3], colours,
                                              measure)
        else:
            def call(model, tables, lanes, idx):
                return model.sample_li(tables, idx, np.take(receivers, lanes, axis=1), u[1:3, lanes],
                                       colours.take(lanes), measure)
            sample = self._each(entity, call)
        sample.pdf = sample.pdf * pmf
        sample.entity = entity
        return sample

    def pdf_li(self, entity: np.ndarray, receivers: np.ndarray, points: np.ndarray, selection: str = "power",
               measure: str = "area") -> np.ndarray:
        """Density (solid angle, with the pmf) with which :meth:`sample_li` at ``receivers`` finds ``points``
        (directions, for lights at infinity) on ``entity``."""
        pmf = self.pmf(selection).take(entity)

        def call(model, tables, lanes, idx):
            pick = (lambda a: a) if lanes is None else (lambda a: np.take(a, lanes, axis=-1))
            return model.pdf_li(tables, idx, pick(receivers), pick(points), measure)

        return pmf * self._each(entity, call)

    def sample_le(self, u: np.ndarray, colours, selection: str = "power") -> EmissionSample:
        """Rays leaving the lights, from uniforms u (5, N): a light by ``selection``, a point, a direction;
        ``pdf_pos`` includes the pmf, and ``entity`` and ``infinite`` say which light."""
        entity = self.select(u[0], selection)

        def call(model, tables, lanes, idx):
            return model.sample_le(tables, idx, u[1:5] if lanes is None else u[1:5, lanes],
                                   colours if lanes is None else colours.take(lanes), self.context)

        sample = self._each(entity, call)
        sample.pdf_pos = self.pmf(selection).take(entity) * sample.pdf_pos
        sample.entity = entity
        sample.infinite = (self.flags.take(entity) & LIGHT_INFINITE).astype(bool)
        return sample

    def pdf_le(self, entity: np.ndarray, normal: np.ndarray, direction: np.ndarray,
               selection: str = "power") -> tuple[np.ndarray, np.ndarray]:
        """(origin density with the pmf, direction density) with which :meth:`sample_le` emits ``direction``
        from a point with geometric ``normal`` on ``entity`` (see :mod:`pathspace.lights.base` for lights
        at infinity)."""
        def call(model, tables, lanes, idx):
            pick = (lambda a: a) if lanes is None else (lambda a: np.take(a, lanes, axis=-1))
            return model.pdf_le(tables, idx, pick(normal), pick(direction), self.context)

        origin, pdf_dir = self._each(entity, call)
        return self.pmf(selection).take(entity) * origin, pdf_dir

    def le(self, entity: np.ndarray, normal: np.ndarray, direction: np.ndarray, colours) -> np.ndarray:
        """What ``entity`` sends along unit ``direction`` (3, N) from a point with geometric ``normal``
        (C, N): radiance (area lights, 0 behind one-sided ones; the environment), intensity (point, spot)."""
        def call(model, tables, lanes, idx):
            pick = (lambda a: a) if lanes is None else (lambda a: np.take(a, lanes, axis=-1))
            return model.le(tables, idx, pick(normal), pick(direction), colours if lanes is None else colours.take(lanes))

        return self._each(entity, call)
