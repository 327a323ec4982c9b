"""Figures: each call draws what it says (axes, labels, colour bars), on matplotlib's Agg backend."""
from __future__ import annotations

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")

import pathspace as ps  # noqa: E402
from pathspace import plot  # noqa: E402
from conftest import scene_dict  # noqa: E402


@pytest.fixture(scope="module")
def render():
    scene = ps.scene_from_dict(scene_dict("cornell-box", (16, 16)))
    return ps.render(scene, "bdpt", spp=8, seed=1, pyramid=2, max_depth=2)


def test_grid_labels_every_image(render):
    figure = plot.grid({"a": render, "b": render.image * 2}, exposure=-1)
    titles = [ax.get_title() for ax in figure.axes if ax.get_title()]
    assert titles == ["a", "b"]
    shown = figure.axes[0].images[0].get_array()
    np.testing.assert_allclose(shown, ps.imageio.display(render.image, -1))


def test_error_map_has_a_colour_bar(render):
    ax = plot.error_map(render.image - render.image.mean(), title="difference", label="W/sr/m2")
    assert len(ax.figure.axes) == 2 and ax.get_title() == "difference"
    lo, hi = ax.images[0].get_clim()
    assert lo == -hi


def test_crop_and_inset(render):
    assert plot.crop(render.image, (2, 3, 5, 4)).shape == (4, 5, 3)
    with pytest.raises(ValueError, match="does not lie within"):
        plot.crop(render.image, (10, 10, 10, 10))
    ax = plot.show(render)
    zoom = plot.inset(ax, render.image, (0, 0, 4, 4))
    assert zoom.images[0].get_array().shape == (4, 4, 3)


def test_pyramid_shows_every_strategy(render):
    figure = plot.pyramid(render.strategies)
    titles = {ax.get_title() for ax in figure.axes if ax.get_title()}
    assert titles == {f"s={s}, t={t}" for s, t in render.strategies}


def test_convergence_plot_labels_slopes_and_runs_too_short_for_one():
    pd = pytest.importorskip("pandas")
    from pathspace.experiment import Convergence

    rows = [{"estimator": "pt", "seed": seed, "seconds": t, "spp": t, "relmse": 1.0 / t, "final": t == 4}
            for seed in (0, 1) for t in (1, 2, 4)]
    rows += [{"estimator": "bdpt", "seed": 0, "seconds": 4.0, "spp": 1, "relmse": 0.1, "final": True}]
    ax = plot.convergence_plot(Convergence(pd.DataFrame(rows), ("relmse",)))
    labels = [text.get_text() for text in ax.get_legend().get_texts()]
    assert labels == ["pt (slope -1.00)", "bdpt (too few snapshots for a slope)"]
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
