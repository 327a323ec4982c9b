"""Memory needs are estimated before anything is allocated: a render that cannot fit is refused with a
message naming the setting to change; the estimate of the film is its actual size."""
from __future__ import annotations

import time
import tracemalloc

import numpy as np
import pytest

import pathspace as ps
from pathspace import cli, memory
from pathspace.memory import RenderMemoryError, estimate_render_memory, memory_needs
from conftest import CORNELL, scene_dict


def test_a_huge_resolution_is_refused_before_allocating():
    scene = ps.scene_from_dict(scene_dict("cornell-box", (100_000, 100_000)))
    start = time.perf_counter()
    tracemalloc.start()
    try:
        with pytest.raises(RenderMemoryError) as refused:
            ps.render(scene, "pt", spp=1)
        assert tracemalloc.get_traced_memory()[1] < 50 << 20
    finally:
        tracemalloc.stop()
    assert time.perf_counter() - start < 2.0
    message = str(refused.value)
    assert message.startswith("rendering 100000x100000 with pt needs ~")
    assert "GB available" in message and "film " in message
    assert "lower camera.resolution to at most about" in message and "--set camera.resolution=[" in message
    needed = float(message.split("needs ~")[1].split(" GB")[0].replace(",", ""))
    assert needed == pytest.approx(1e10 * (8 + 4 + 24 + 24 + 24 + 48) / 2 ** 30, rel=1e-3)  # film, open pass, images


def test_the_command_line_reports_it_in_one_line(tmp_path, capsys):
    code = cli.main(["render", str(CORNELL), "--set", "camera.resolution=[100000,100000]", "-q",
                     "-o", str(tmp_path / "out.exr")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "camera.resolution" in err and "Traceback" not in err
    assert not list(tmp_path.iterdir())


def test_the_advice_names_what_takes_the_memory(monkeypatch, tmp_path):
    """Spectral BDPT with a pyramid under a cgroup limit: resolution, pyramid, RGB and threads are named."""
    (tmp_path / "memory.max").write_text(str(1700 << 20))
    (tmp_path / "memory.current").write_text(str(200 << 20))
    monkeypatch.setattr(memory, "CGROUP", tmp_path)
    assert memory.available_memory() <= 1500 << 20
    scene = ps.scene_from_dict(scene_dict("cornell-box", (2000, 1000)))
    with pytest.raises(RenderMemoryError) as refused:
        ps.render(scene, "bdpt", spp=1, spectral=True, threads=4, pyramid=3)
    message = str(refused.value)
    for advice in ("camera.resolution", "-p pyramid=0", "--rgb", "fewer threads (--threads; 4 now)"):
        assert advice in message, advice
    size = message.split("at most about ")[1].split(" ")[0]
    width, height = map(int, size.split("x"))
    assert width == 2 * height and width < 2000
    monkeypatch.setattr(memory, "CGROUP", tmp_path / "none")
    result = ps.render(ps.scene_from_dict(scene_dict("cornell-box", (8, 4))), "bdpt", spp=1, pyramid=2)
    assert result.image.shape == (4, 8, 3)


@pytest.mark.parametrize("estimator, spectral, params", [("pt", False, {}), ("bdpt", True, {"pyramid": 2}),
                                                          ("lt", False, {"pyramid": 3})])
def test_the_estimate_of_the_film_is_its_size(estimator, spectral, params):
    """The film's and the layers' parts of the estimate are the bytes of the moments a render holds."""
    scene = ps.scene_from_dict(scene_dict("cornell-box", (12, 10)))
    result = ps.render(scene, estimator, spp=2, spectral=spectral, **params)
    film = result.film
    needs = memory_needs(12, 10, ps.estimators.make_estimator(estimator, **params), film.covariance, spectral,
                         threads=2, layers=len(film.layers))

    def size(moments):
        return sum(a.nbytes for a in (moments.count, moments.exponent, moments.scaled_mean, moments.scaled_m2))

    assert needs["film"] == size(film.moments)
    assert needs["layers"] == sum(size(layer) for layer in film.layers.values())
    assert (needs["layers"] > 0) == bool(params)
    images = result.image.nbytes + result.variance.nbytes + (result.xyz.nbytes if spectral else 0)
    assert needs["images"] == images
    assert estimate_render_memory(scene, ps.estimators.make_estimator(estimator, **params), film.covariance, 2,
                                  spectral) == sum(needs.values())
    assert np.all(result.film.count == 2)
