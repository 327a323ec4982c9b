"""Russian roulette: unbiased termination of random walks (Arvo & Kirk 1990; Veach 1997, sec. 2.4).

Every estimator takes the same four parameters, and every name means one
thing.  At a scattering vertex reached after ``rr_depth`` or more segments
(the camera ray is segment 1; on a light subpath, the ray leaving the light),
a walk survives with probability q and its throughput is divided by q, so
the estimate stays unbiased for any q in (0, 1].  Policies (``rr``):

``"off"``         q = 1: walks end only by escaping, absorption or ``max_depth``.
``"fixed"``       q = 1 - ``rr_probability`` (a fixed termination probability).
``"albedo"``      q = the albedo of the vertex's material (the largest channel
                  of its reflectance).  Termination probability 1 - albedo.
                  Specular (delta) materials -- mirrors, glass -- survive
                  with q = 1 on walks shorter than ``ALBEDO_TRAPPED_DEPTH``
                  (24) segments, then with at most 0.9, so that walks trapped
                  in glass by total internal reflection end: the weight grows
                  by 1/0.9 per bounce and the variance stays finite while a
                  walk leaves the glass with probability > 0.1.  Paths seen
                  through a chain of specular vertices (a caustic in a
                  mirror: specular-diffuse-specular) are sampled only by
                  walks through all of them, and 0.9 at each vertex raised
                  their variance: with q = 1 BDPT's relMSE on
                  scenes/cornell-box-specular fell by a quarter.  The depth
                  is far below the 128 of "throughput" because BDPT's walks
                  keep a wavefront until its last path ends: a trapped walk
                  holds a work item for every segment it takes, and 128
                  cost BDPT 15% more time there than 24 (16 and 48: the
                  same as 24; docs/performance.md).
``"throughput"``  q = min(largest channel of the walk's throughput after this
                  vertex, ``rr_cap``): walks carrying little energy end early
                  and a survivor's throughput is lifted back toward 1 (pbrt-v4's
                  rule, cap 1).  The throughput read is free of the 1 / eta^2
                  scaling of radiance by refraction (as Mitsuba 3 does): light
                  inside glass is not less important for being inside.  A
                  walk trapped in glass by total internal reflection keeps a
                  throughput of 1 and would go on until it escapes --
                  thousands of segments in the tessellated glass sphere of
                  scenes/cornell-box-specular, each a wavefront step of a few
                  lanes, which made path tracing there 10-20x slower to a
                  given error (benchmarks/speed.py) -- so at specular vertices
                  reached after ``TRAPPED_DEPTH`` (128) segments q is also at
                  most their albedo as the table holds it (at most 0.9).  Not
                  earlier: the weight of light escaping from such a trap
                  grows by 1/0.9 per trapped bounce, and where the traps hold
                  much of the light (a glass sphere in a white furnace) a
                  limit from depth 5 made the standard error 1.5-6x larger
                  (from depth 64: up to 1.6x; from 128: unchanged).  A
                  light subpath's throughput is measured relative to the
                  ray leaving the light, so that the choice does not
                  depend on the light's units.  Mitsuba 3 caps every vertex at
                  0.95, which gives infinite variance wherever the albedo
                  exceeds the cap (throughput then grows by albedo / cap per
                  bounce): in an albedo-0.99 furnace its finite-sample means
                  fall ~10% short.

"off", "fixed" and "albedo" are *local*: past ``rr_depth``, q depends only on
the vertex's material, the same whichever direction a walk passes the
vertex, so bidirectional estimators can include it in the vertex densities
that their MIS weights compare (as SmallVCM does; :meth:`RussianRoulette.mis_survival`;
BDPT's default includes the camera subpaths' only, see ``in_mis`` below).
(At specular vertices "albedo" depends on the depth too, beyond
``ALBEDO_TRAPPED_DEPTH``; the densities take its q = 1 there, exact for every
shorter walk.)
Those densities must be one function of the path for every strategy -- or
the weights of a path no longer sum to one and the image is biased -- so
they take q at every vertex, also where a walk had not yet reached
``rr_depth`` (the depth of a vertex differs as seen from the camera and from
the light).  "throughput" depends on the walk that reached the vertex, which
the opposite walk cannot know; bidirectional estimators then leave q out of
the MIS densities.  In both cases the weights stay a partition of unity over
the strategies, so the estimate is unbiased; they are the exact heuristic of
the true densities when ``rr_depth`` is 1, the policy is local and both walks'
q are in the densities.  A walk's
local q may also be left out of the densities on purpose (``in_mis`` False;
BDPT's ``mis_roulette``): any densities that are one function of the path
per strategy keep the estimate unbiased, and which give the lower variance
is an empirical question (docs/performance.md).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .checks import choice, integer, number

__all__ = ["RussianRoulette", "POLICIES", "SPECULAR_CONTINUATION", "TRAPPED_DEPTH", "ALBEDO_TRAPPED_DEPTH",
           "roulette_warnings"]

POLICIES = ("off", "fixed", "albedo", "throughput")
# The largest survival probability "albedo" gives lossless specular (delta) materials.
SPECULAR_CONTINUATION = 0.9
# "throughput" survival at specular vertices reached after this many segments is at most their albedo: walks
# trapped in glass by total internal reflection end.  Earlier, variance grows (see the module docstring).
TRAPPED_DEPTH = 128
# "albedo" survival at specular vertices is 1 on walks shorter than this, then at most SPECULAR_CONTINUATION.
ALBEDO_TRAPPED_DEPTH = 24


@dataclass(frozen=True)
class RussianRoulette:
    """A roulette policy (parameters ``rr``, ``rr_depth``, ``rr_probability``, ``rr_cap``); see the module."""

    policy: str = "throughput"
    start_depth: int = 5
    probability: float = 0.5
    cap: float = 1.0
    in_mis: bool = True  # a local policy's q enters the vertex densities MIS compares (see mis_survival)

    def __post_init__(self) -> None:
        choice(self.policy, "rr", POLICIES)
        integer(self.start_depth, "rr_depth", low=1)
        number(self.probability, "rr_probability", low=0.0, high=1.0, high_open=True,
               what="a termination probability in [0, 1)")
        number(self.cap, "rr_cap", low=0.0, high=1.0, low_open=True, what="a survival cap in (0, 1]")

    @property
    def local(self) -> bool:
        """Whether q depends only on the vertex (its material and depth), not on the walk that reached it."""
        return self.policy != "throughput"

    def samples_like(self, other: "RussianRoulette") -> bool:
        """Whether ``other`` terminates walks as this policy does (whatever either puts in the MIS densities)."""
        return replace(self, in_mis=other.in_mis) == other

    def describe(self) -> str:
        """The policy in words."""
        if self.policy == "off":
            return "no Russian roulette"
        rule = {"fixed": f"termination probability {self.probability:g}",
                "albedo": "survival probability = material albedo",
                "throughput": f"survival probability = max throughput, capped at {self.cap:g}"}[self.policy]
        return f"Russian roulette from depth {self.start_depth}: {rule}"

    @property
    def trapped_depth(self) -> int:
        """Walks this long or longer survive specular vertices with at most their albedo (see the module)."""
        return ALBEDO_TRAPPED_DEPTH if self.policy == "albedo" else TRAPPED_DEPTH

    def mis_survival(self, albedo: np.ndarray, specular: np.ndarray | None = None) -> np.ndarray:
        """q as multiple importance sampling puts it in the vertex densities, at vertices of materials with
        ``albedo`` (N,), specular (delta) where ``specular`` (N,) (None: none are): a local policy's survival
        past ``rr_depth``, whatever the depth ("albedo": 1 at specular vertices, as walks shorter than
        :attr:`trapped_depth` survive them); 1 for "throughput" and "off", and for any policy that is not
        ``in_mis``."""
        if not self.in_mis:
            return np.ones(albedo.shape)
        q = self._local_survival(albedo)
        if self.policy == "albedo" and specular is not None:
            q = np.where(specular, 1.0, q)
        return q

    def _local_survival(self, albedo: np.ndarray) -> np.ndarray:
        """A local policy's survival past ``rr_depth`` at vertices of materials with ``albedo`` (N,) (specular
        vertices aside); 1 for "throughput" and "off"."""
        if self.policy == "fixed":
            return np.full(albedo.shape, 1.0 - self.probability)
        if self.policy == "albedo":
            return np.clip(albedo, 0.0, 1.0)
        return np.ones(albedo.shape)

    def survival(self, depth: np.ndarray, throughput: np.ndarray | None, albedo: np.ndarray,
                 specular: np.ndarray | None = None) -> np.ndarray | None:
        """Survival probabilities (N,) at vertices reached after ``depth`` (N,) segments, or None (all survive).

        ``throughput`` (C, N) is the walk's throughput including this
        vertex's sample weight (read by "throughput" only; None otherwise
        allowed); ``albedo`` (N,) the albedo of each vertex's material
        (see :attr:`pathspace.bsdfs.MaterialTable.albedo`, at most
        :data:`SPECULAR_CONTINUATION` for specular materials); ``specular``
        (N,) bool: vertices of specular (delta) materials (None: none are),
        where "albedo" survives with 1 and "throughput" as its throughput says
        on walks shorter than :attr:`trapped_depth`, both with at most their
        albedo from there on.
        """
        if self.policy == "off" or depth.max(initial=0) < self.start_depth:
            return None
        if self.local:
            q = self._local_survival(albedo)
            if self.policy == "albedo" and specular is not None:
                q = np.where(specular & (depth < self.trapped_depth), 1.0, q)
        else:
            q = np.clip(throughput.max(axis=0), 0.0, self.cap)
            if specular is not None:
                q = np.where(specular & (depth >= self.trapped_depth), np.minimum(q, albedo), q)
        return np.where(depth >= self.start_depth, q, 1.0)


def roulette_warnings(roulette: RussianRoulette, materials, max_depth: int = -1) -> list[str]:
    """Settings with infinite variance, from the policy and the albedos of a MaterialTable alone.

    A walk that survives a vertex of albedo rho with probability q carries
    the weight rho / q on, and the second moment of its contribution grows by
    rho^2 / q per such bounce (Veach 1997, sec. 2.4): where rho^2 >= q --
    a fixed termination probability 1 - q >= 1 - rho^2, or a throughput cap
    below the albedo -- paths that keep bouncing among such surfaces make the
    variance infinite.  (In the closed Cornell boxes, whose white walls
    reflect 0.886, a fixed termination probability of 0.22 or more does.)
    """
    if roulette.policy == "fixed":
        q = 1.0 - roulette.probability
        bad = [(name, a) for name, a in zip(materials.names, materials.albedo) if a * a >= q]
        rule = f"fixed termination probability {roulette.probability:g} (survival {q:g})"
    elif roulette.policy == "throughput" and roulette.cap < 1.0:
        q = roulette.cap
        bad = [(name, a) for name, a in zip(materials.names, materials.albedo) if a > q]
        rule = f"throughput roulette capped at survival {q:g}"
    else:
        return []
    if not bad or 0 < max_depth <= roulette.start_depth:
        return []
    named = ", ".join(f"{name!r} (albedo {a:.3g})" for name, a in bad)
    return [f"{rule}: paths that keep bouncing among {named} gain weight at every bounce and have infinite "
            f"variance (survival must exceed albedo^2 for fixed roulette, the albedo for a capped throughput); "
            "use rr='albedo' or 'throughput', or a termination probability below 1 - albedo^2"]
