"""Scattering models and the material table of a scene.

Models: :class:`Diffuse` (Lambertian), :class:`Phong` (modified Phong,
energy-conserving), :class:`Mirror` (delta), :class:`Dielectric` (smooth
glass, delta), :class:`Conductor` (rough GGX metal).  See
:mod:`pathspace.bsdfs.base` for the interface they share.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from ..roulette import SPECULAR_CONTINUATION
from ..spectra import is_spectral
from .base import MODES, BSDFSample, Surface
from .conductor import Conductor
from .diffuse import SAMPLING as DIFFUSE_SAMPLING
from .diffuse import Diffuse
from .dielectric import Dielectric
from .mirror import Mirror
from .phong import Phong

__all__ = ["BSDFSample", "Conductor", "DIFFUSE_SAMPLING", "Dielectric", "Diffuse", "KINDS", "MODES",
           "MaterialLanes", "MaterialTable", "Mirror", "Phong", "Surface"]

KINDS = {model.kind: model for model in (Diffuse, Phong, Mirror, Dielectric, Conductor)}


class MaterialTable:
    """The materials of a scene, grouped by kind, with per-kind parameter tables.

    Attributes
    ----------
    names : material names, in id order
    materials : the material descriptions (dataclasses of :data:`KINDS`)
    kinds : the model classes present, in first-use order
    kind_of : (M,) int32, position in ``kinds`` of each material's model
    local_id : (M,) int32, index of each material within its kind's tables
    tables : per kind, the parameter tables of its materials
    delta : (M,) bool, whether a material only has delta lobes
    delta_names : the names of those materials
    albedo : (M,) float64, the largest fraction of light each material reflects (Russian roulette's
        "albedo" policy; see :mod:`pathspace.roulette`), lossless delta materials capped at
        ``SPECULAR_CONTINUATION`` (the survival of walks trapped in them)
    """

    def __init__(self, names: list[str], materials: list) -> None:
        if len(names) != len(materials):
            raise ValueError("one name per material is required")
        self.names = list(names)
        self.materials = list(materials)
        self.kinds: list = []
        members: list[list] = []
        self.kind_of = np.zeros(len(materials), dtype=np.int32)
        self.local_id = np.zeros(len(materials), dtype=np.int32)
        for i, material in enumerate(materials):
            model = type(material)
            if model not in self.kinds:
                self.kinds.append(model)
                members.append([])
            k = self.kinds.index(model)
            self.kind_of[i] = k
            self.local_id[i] = len(members[k])
            members[k].append(material)
        self.tables = [model.tables(group) for model, group in zip(self.kinds, members)]
        self.delta = np.array([type(m).delta for m in materials], dtype=bool)
        self.delta_names = [name for name, delta in zip(self.names, self.delta) if delta]
        self.albedo = np.array([min(m.albedo, SPECULAR_CONTINUATION) if m.delta else m.albedo for m in materials])

    def __len__(self) -> int:
        return len(self.materials)

    def spectral_reasons(self) -> list[str]:
        """Why the materials need spectral rendering (empty: RGB suffices)."""
        reasons = []
        for name, material in zip(self.names, self.materials):
            if getattr(material, "dispersive", False):
                reasons.append(f"material {name!r} is dispersive")
            elif any(is_spectral(getattr(material, f.name)) for f in dataclasses.fields(material)):
                reasons.append(f"material {name!r} has spectral data")
        return reasons

    def __repr__(self) -> str:
        return "MaterialTable(" + ", ".join(f"{n}={m}" for n, m in zip(self.names, self.materials)) + ")"

    def gather(self, kind: int, material_ids: np.ndarray, colours, options):
        """Per-lane parameters of model ``kinds[kind]`` for lanes using ``material_ids`` (all of that kind)."""
        return self.kinds[kind].gather(self.tables[kind], self.local_id.take(material_ids), colours, options)


class MaterialLanes:
    """The materials of a wavefront's lanes, grouped by kind, parameters gathered once.

    ``eval`` and ``sample`` run each kind's functions on its lanes and
    assemble full-width results; with a single kind among the lanes no
    lanes are moved at all.
    """

    def __init__(self, table: MaterialTable, material_ids: np.ndarray, colours, options: dict) -> None:
        self.count = int(material_ids.size)
        self.channels = colours.channels
        kind = table.kind_of.take(material_ids) if len(table.kinds) > 1 else None
        present = [0] if kind is None else np.flatnonzero(np.bincount(kind, minlength=len(table.kinds))).tolist()
        if len(present) == 1:      # one kind among these lanes: no lanes are moved
            self.groups = [(table.kinds[present[0]], None, table.gather(present[0], material_ids, colours, options))]
        else:
            self.groups = []
            for k in present:
                idx = np.flatnonzero(kind == k)
                self.groups.append((table.kinds[k], idx, table.gather(k, material_ids.take(idx), colours.take(idx),
                                                                      options)))
        self.delta = table.delta.take(material_ids) if table.delta.any() else None

    def part(self, specular: bool) -> tuple[np.ndarray, "MaterialLanes"]:
        """(lanes, their materials): the lanes whose material is specular (delta), or is not, and a
        :class:`MaterialLanes` of those lanes alone that reuses the parameters already gathered for them."""
        if self.delta is None:
            lanes = np.arange(self.count) if not specular else np.zeros(0, np.int64)
        else:
            lanes = np.flatnonzero(self.delta if specular else ~self.delta)
        kept = [group for group in self.groups if group[0].delta == specular]
        part = MaterialLanes.__new__(MaterialLanes)
        part.count, part.channels = int(lanes.size), self.channels
        part.delta = np.full(lanes.size, True) if specular else None
        part.groups = [(model, None if len(kept) == 1 else np.searchsorted(lanes, idx), params)
                       for model, idx, params in kept]
        return lanes, part

    def eval(self, surface: Surface, wi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """f |cos| (C, N) and pdf (N,) of every lane's material (zero for delta materials)."""
        if self.groups[0][1] is None:
            model, _, params = self.groups[0]
            return model.eval(params, surface, wi)
        f_cos, pdf = np.zeros((self.channels, self.count)), np.zeros(self.count)
        for model, idx, params in self.groups:
            f_cos[:, idx], pdf[idx] = model.eval(params, surface.take(idx), np.take(wi, idx, axis=1))
        return f_cos, pdf

    def sample(self, surface: Surface, u: np.ndarray, mode: str = "radiance") -> BSDFSample:
        """One sampled direction per lane from its material."""
        if self.groups[0][1] is None:
            model, _, params = self.groups[0]
            return model.sample(params, surface, u, mode)
        out = BSDFSample(np.zeros((3, self.count), dtype=np.float32), np.zeros((self.channels, self.count)),
                         np.zeros(self.count), np.zeros(self.count, dtype=bool), np.zeros(self.count, dtype=bool))
        for model, idx, params in self.groups:
            s = model.sample(params, surface.take(idx), u[:, idx], mode)
            out.wi[:, idx], out.weight[:, idx], out.pdf[idx], out.delta[idx] = s.wi, s.weight, s.pdf, s.delta
            if s.terminated is not None:
                out.terminated[idx] = s.terminated
            if s.eta is not None:
                if out.eta is None:
                    out.eta = np.ones(self.count)
                out.eta[idx] = s.eta
        return out
