"""Modified Phong: an energy-conserving diffuse + glossy lobe (Lafortune & Willems 1994), two-sided.

f(wo, wi) = kd / pi + ks (e + 2) / (2 pi) cos^e(alpha),  alpha = angle(wi, mirror(wo)),
with kd + ks <= 1 per channel so that the albedo never exceeds one.  Sampling
picks the glossy lobe with probability mean(ks) / (mean(kd) + mean(ks)) and
otherwise the cosine-weighted diffuse lobe; the glossy lobe samples cos^e
about the mirror direction (density (e + 1) / (2 pi) cos^e).  Directions
below the surface are failed samples.  The pdf of a direction is the
mixture of both lobe densities (as in SmallVCM's Phong).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import warp
from ..spectra import Colour, ColourTable, check_colour
from ..vecmath import Frame
from .base import BSDFSample, Surface, reflect

__all__ = ["Phong"]


@dataclass
class PhongParams:
    kd: np.ndarray           # (C, N)
    ks: np.ndarray           # (C, N)
    exponent: np.ndarray     # (N,)
    glossy_prob: np.ndarray  # (N,)


@dataclass(frozen=True)
class Phong:
    """Diffuse ``diffuse`` plus glossy ``specular`` (RGB, sum <= 1 per channel) with Phong ``exponent``."""

    diffuse: Colour
    specular: Colour
    exponent: float
    kind = "phong"
    delta = False

    def __post_init__(self) -> None:
        for name in ("diffuse", "specular"):
            object.__setattr__(self, name, check_colour(getattr(self, name), name, "reflectance"))
        table_d = ColourTable([self.diffuse], "reflectance")
        table_s = ColourTable([self.specular], "reflectance")
        kd, ks = table_d.rgb[:, 0], table_s.rgb[:, 0]
        if table_d.spectral or table_s.spectral:
            kd, ks = table_d.spectra[0], table_s.spectra[0]
        if np.any(kd + ks > 1.0 + 1e-6):
            raise ValueError(f"specular: diffuse + specular must not exceed 1 per channel (energy conservation), "
                             f"got {(kd + ks).tolist()}")
        if not (np.isfinite(self.exponent) and self.exponent >= 0):
            raise ValueError(f"exponent: expected a number >= 0, got {self.exponent!r}")

    @classmethod
    def from_fields(cls, fields) -> "Phong":
        """A material table of type "phong": ``diffuse``, ``specular``, ``exponent``."""
        args = fields.colour("diffuse"), fields.colour("specular"), fields.number("exponent", low=0.0)
        fields.finish()
        return fields.build(lambda: cls(*args))

    @property
    def albedo(self) -> float:
        """Largest fraction of light it reflects (the largest channel of diffuse + specular, at most 1)."""
        kd = ColourTable([self.diffuse], "reflectance").rgb[:, 0]
        ks = ColourTable([self.specular], "reflectance").rgb[:, 0]
        return min(1.0, float((kd + ks).max()))

    @staticmethod
    def tables(materials: list["Phong"]) -> dict:
        kd = ColourTable([m.diffuse for m in materials], "reflectance")
        ks = ColourTable([m.specular for m in materials], "reflectance")
        total = kd.mean() + ks.mean()
        glossy = np.divide(ks.mean(), total, out=np.zeros_like(total), where=total > 0)
        return {"kd": kd, "ks": ks, "exponent": np.array([m.exponent for m in materials], dtype=np.float64),
                "glossy_prob": glossy}

    @staticmethod
    def gather(tables, ids, colours, options) -> PhongParams:
        return PhongParams(colours.lookup(tables["kd"], ids), colours.lookup(tables["ks"], ids),
                           tables["exponent"].take(ids), tables["glossy_prob"].take(ids))

    @staticmethod
    def _lobes(params: PhongParams, n_f, wo, cos_o, wi):
        """(cos theta_i, cos^e(alpha) term, lobe pdf) for world directions."""
        cos_i = (n_f[0] * wi[0] + n_f[1] * wi[1] + n_f[2] * wi[2]).astype(np.float64)
        r = reflect(wo.astype(np.float64), n_f.astype(np.float64), cos_o.astype(np.float64))
        cos_a = np.clip(r[0] * wi[0] + r[1] * wi[1] + r[2] * wi[2], 0.0, 1.0)
        e = params.exponent
        power = cos_a ** e
        glossy_pdf = (e + 1.0) * warp.INV_TWO_PI * power
        diffuse_pdf = np.maximum(cos_i, 0.0) * warp.INV_PI
        pdf = params.glossy_prob * glossy_pdf + (1.0 - params.glossy_prob) * diffuse_pdf
        return cos_i, power, np.where(cos_i > 0, pdf, 0.0)

    @staticmethod
    def _f_cos(params: PhongParams, cos_i, power):
        lobe = (params.exponent + 2.0) * warp.INV_TWO_PI * power
        positive = np.maximum(cos_i, 0.0)
        return (params.kd * warp.INV_PI + params.ks * lobe) * positive

    @staticmethod
    def eval(params: PhongParams, surface: Surface, wi) -> tuple[np.ndarray, np.ndarray]:
        n_f, wo, cos_o = surface.n, surface.wo, surface.cos_o
        cos_i, power, pdf = Phong._lobes(params, n_f, wo, cos_o, wi)
        return Phong._f_cos(params, cos_i, power), pdf

    @staticmethod
    def sample(params: PhongParams, surface: Surface, u, mode="radiance") -> BSDFSample:
        n_f, wo, cos_o = surface.n, surface.wo, surface.cos_o
        glossy = u[0] < params.glossy_prob
        # Glossy lobe: cos alpha = u^(1 / (e + 1)) about the mirror direction.
        r = reflect(wo.astype(np.float64), n_f.astype(np.float64), cos_o.astype(np.float64))
        cos_a = u[1] ** (1.0 / (params.exponent + 1.0))
        sin_a = np.sqrt(np.maximum(0.0, 1.0 - cos_a * cos_a))
        phi = 2.0 * np.pi * u[2]
        lobe = Frame(r).to_world(np.stack((sin_a * np.cos(phi), sin_a * np.sin(phi), cos_a)))
        # Diffuse lobe: cosine-weighted about the normal.
        sphere = warp.square_to_uniform_sphere(u[1:3]).astype(np.float64)
        cosine = n_f + sphere
        cosine /= np.maximum(np.sqrt(cosine[0] ** 2 + cosine[1] ** 2 + cosine[2] ** 2), 1e-12)
        wi = np.where(glossy, lobe, cosine).astype(np.float32)
        cos_i, power, pdf = Phong._lobes(params, n_f, wo, cos_o, wi)
        f_cos = Phong._f_cos(params, cos_i, power)
        with np.errstate(divide="ignore", invalid="ignore"):
            weight = np.where(pdf > 0, f_cos / pdf, 0.0)
        return BSDFSample(wi, weight, pdf, np.zeros(pdf.shape, dtype=bool))
