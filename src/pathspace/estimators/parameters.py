"""The parameters estimators share, declared once: name, meaning, check (and a default per estimator).

An estimator's class body reads, e.g., ``rr: str = roulette_policy("throughput")``;
the meaning and the validation (with the same error message everywhere)
live here, so a sweep can pass one parameter set to every estimator.
"""
from __future__ import annotations

from functools import partial

from ..bsdfs import DIFFUSE_SAMPLING
from ..checks import choice, integer, number
from ..lights import MEASURES, SELECTIONS
from ..mis import HEURISTICS, StrategySubset
from ..roulette import POLICIES
from .base import parameter

__all__ = ["max_depth", "roulette_policy", "roulette_depth", "roulette_probability", "roulette_cap", "light_rr",
           "light_rr_depth", "light_rr_probability", "light_rr_cap",
           "mis_heuristic", "mis_beta", "mis_roulette", "MIS_ROULETTE", "mis_strategy", "mis_strategies",
           "diffuse_sampling", "light_selection", "light_measure", "pyramid", "underlying_rr", "underlying_rr_depth",
           "or_none", "KERNELS", "kernel"]

KERNELS = ("fused", "numpy")


def max_depth(default: int = -1):
    """Longest path in segments; -1 is unbounded."""
    return parameter(default, "longest path in segments; -1 is unbounded (the full solution)",
                     partial(integer, low=1, unbounded=-1))


def roulette_policy(default: str):
    """Russian roulette policy (see :mod:`pathspace.roulette`)."""
    return parameter(default, "Russian roulette: 'off', 'fixed' (survival 1 - rr_probability), 'albedo' "
                              "(survival = material albedo), 'throughput' (survival = max throughput, capped at rr_cap)",
                     partial(choice, options=POLICIES))


def roulette_depth(default: int):
    """First depth (segments) at which roulette applies."""
    return parameter(default, "roulette applies at vertices reached after at least this many segments",
                     partial(integer, low=1))


def roulette_probability(default: float = 0.5):
    """Termination probability of the "fixed" policy."""
    return parameter(default, "termination probability of rr='fixed'",
                     partial(number, low=0.0, high=1.0, high_open=True, what="a termination probability in [0, 1)"))


def roulette_cap(default: float = 1.0):
    """Largest survival probability of the "throughput" policy."""
    return parameter(default, "largest survival probability of rr='throughput'",
                     partial(number, low=0.0, high=1.0, low_open=True, what="a survival cap in (0, 1]"))


def or_none(check):
    """``check`` that lets None ("use the default") through."""
    return lambda value, name: None if value is None else check(value, name)


def light_rr():
    """The light subpaths' own roulette policy; None: ``rr``."""
    return parameter(None, "roulette policy of light subpaths (default: rr)", or_none(partial(choice, options=POLICIES)))


def light_rr_depth():
    """The light subpaths' ``rr_depth``; None: ``rr_depth``."""
    return parameter(None, "rr_depth of light subpaths (default: rr_depth)", or_none(partial(integer, low=1)))


def light_rr_probability():
    """The light subpaths' ``rr_probability``; None: ``rr_probability``."""
    return parameter(None, "rr_probability of light subpaths (default: rr_probability)",
                     or_none(partial(number, low=0.0, high=1.0, high_open=True,
                                     what="a termination probability in [0, 1)")))


def light_rr_cap():
    """The light subpaths' ``rr_cap``; None: ``rr_cap``."""
    return parameter(None, "rr_cap of light subpaths (default: rr_cap)",
                     or_none(partial(number, low=0.0, high=1.0, low_open=True, what="a survival cap in (0, 1]")))


MIS_ROULETTE = ("auto", "both", "camera", "light", "none")


def mis_roulette(default: str = "auto"):
    """Which subpaths' local roulette enters the vertex densities MIS compares."""
    return parameter(default, "which subpaths' local Russian roulette (survival probability) enters the vertex "
                              "densities MIS compares: 'auto' ('camera' where the light subpaths' roulette is "
                              "'albedo', else 'both'), 'both', 'camera' (the light subpaths' is left out), 'light' or "
                              "'none'; any choice is unbiased", partial(choice, options=MIS_ROULETTE))


def underlying_rr():
    """A Metropolis estimator's roulette policy for the estimator it runs on; None: that estimator's default."""
    return parameter(None, "Russian roulette policy (default: the underlying estimator's)",
                     or_none(partial(choice, options=POLICIES)))


def underlying_rr_depth():
    """A Metropolis estimator's ``rr_depth`` for the estimator it runs on; None: that estimator's default."""
    return parameter(None, "rr_depth (default: the underlying estimator's)", or_none(partial(integer, low=1)))


def mis_strategies():
    """The strategies BDPT's MIS combines (see :class:`pathspace.mis.StrategySubset`)."""
    return parameter(None, "the strategies MIS combines (default: all): a condition on s, t and k = s + t - 1 such "
                           "as 's != 0 and t != 0', or a list of [s, t] pairs; the others get weight 0",
                     or_none(lambda value, name: StrategySubset(value)))


def mis_heuristic(default: str, options: tuple[str, ...] = HEURISTICS):
    """The MIS heuristic (see :mod:`pathspace.mis`)."""
    return parameter(default, f"MIS heuristic: {', '.join(repr(o) for o in options)}",
                     partial(choice, options=options))


def mis_beta(default: float = 2.0):
    """Exponent of the power heuristic."""
    return parameter(default, "exponent of the power heuristic",
                     partial(number, low=0.0, low_open=True, what="a finite number > 0"))


def mis_strategy():
    """The strategy (s, t) of mis="single"."""
    return parameter(None, "the strategy (s, t) kept by mis='single', e.g. [2, 2]")


def diffuse_sampling(default: str = "cosine"):
    """BSDF sampling technique of diffuse surfaces."""
    return parameter(default, "sampling of diffuse surfaces: 'cosine' or 'uniform' hemisphere",
                     partial(choice, options=DIFFUSE_SAMPLING))


def light_selection(default: str = "power"):
    """How a light is chosen for a light sample."""
    return parameter(default, "choose the light to sample by 'power' or 'uniform'ly", partial(choice, options=SELECTIONS))


def light_measure(default: str = "area"):
    """How points on emitting triangles are sampled."""
    return parameter(default, "sample points on emitting triangles by 'area' or 'solid_angle'",
                     partial(choice, options=MEASURES))


def pyramid(default: int = 0):
    """Record per-strategy images of paths up to this many segments."""
    return parameter(default, "record each strategy's unweighted and weighted image for paths up to this many "
                              "segments (Veach's pyramid; 0: none)", partial(integer, low=0))


def kernel(work: str):
    """Where ``work`` is done: a fused C kernel (where the scene allows it) or the NumPy reference code; the
    image is the same bit for bit, so a render resumes across the two."""
    return parameter("fused", f"where {work} is done: 'fused' (one C pass where the scene allows; the same image) "
                              "or 'numpy' (the reference code)", partial(choice, options=KERNELS), image=False)
