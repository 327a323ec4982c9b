"""Experiments: convergence against run time, parameter sweeps, and images for strategy studies.

    import pathspace as ps
    scene = ps.load_scene("scenes/cornell-box/scene.toml")
    ref = ps.reference(scene, spp=4096)
    conv = ps.experiment.converge(scene, ["pt", "lt", "bdpt"], ref, time=20, seeds=(0, 1))
    conv.table, conv.summary(), conv.at(seconds=10), conv.plot()
    sw = ps.experiment.sweep(scene, ("pt", {"rr": "fixed"}), {"rr_probability": [0.1, 0.5, 0.8]}, ref, spp=64)
    sw.cells    # one row per setting: metrics, efficiency, and whether it is biased

Tables are pandas DataFrames and figures matplotlib figures (the
``experiments`` extra); nothing here is imported until used.
"""
from .convergence import Convergence, converge, default_checkpoints
from .specs import EstimatorSpec, parse_assignment, parse_value
from .studies import difference, posterize, relative_error, strategy_images, weight_images, z_scores
from .sweep import Sweep, grid_cells, sweep

__all__ = ["Convergence", "EstimatorSpec", "Sweep", "converge", "default_checkpoints",
           "difference", "grid_cells", "parse_assignment", "parse_value", "posterize", "relative_error",
           "strategy_images", "sweep", "weight_images", "z_scores"]
