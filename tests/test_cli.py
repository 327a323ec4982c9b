"""The command line: render and compare, BDPT strategy layers and contact sheets, one-line errors, the plan."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

import pathspace as ps
from pathspace import metrics
from pathspace.imageio import read_exr
from conftest import ROOT


def run_cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "pathspace.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd)


def test_render_and_compare(tmp_path):
    scene = tmp_path / "scene.toml"
    text = (ROOT / "scenes" / "cornell-box" / "scene.toml").read_text()
    scene.write_text(text.replace("resolution = [256, 256]", "resolution = [32, 32]"))

    out = tmp_path / "out" / "a.exr"
    done = run_cli("render", scene, "--spp", 4, "--seed", 3, "-o", out, "-q", "-p", "max_depth=3")
    assert done.returncode == 0, done.stderr
    assert "pt (rgb): 4 spp at 32x32" in done.stdout and "M samples/s" in done.stdout
    assert out.exists() and out.with_suffix(".png").exists()
    image, variance, meta = read_exr(out)
    assert image.shape == (32, 32, 3) and variance.shape == (32, 32, 3)
    assert meta["spp"] == 4 and meta["params"]["max_depth"] == 3
    direct = ps.render(ps.load_scene(scene), spp=4, seed=3, max_depth=3)
    np.testing.assert_array_equal(image, direct.image.astype(np.float32))

    done = run_cli("render", scene, "--spp", 4, "--seed", 4, "-o", tmp_path / "b.exr", "-q", "--no-png")
    assert done.returncode == 0 and not (tmp_path / "b.png").exists()
    compared = run_cli("compare", tmp_path / "b.exr", out, "--json")
    values = json.loads(compared.stdout)
    assert set(values) == {"mse", "rmse", "relmse", "mape", "smape"} and values["mse"] > 0
    expected = metrics.compare(read_exr(tmp_path / "b.exr")[0], image)
    assert values == pytest.approx(expected, rel=1e-12)
    same = json.loads(run_cli("compare", out, out, "--json").stdout)
    assert same == {"mse": 0.0, "rmse": 0.0, "relmse": 0.0, "mape": 0.0, "smape": 0.0}


def test_bdpt_pyramid_from_the_command_line(tmp_path):
    """-p pyramid=K writes every strategy's images as EXR layers and two labelled contact sheets."""
    scene = tmp_path / "scene.toml"
    text = (ROOT / "scenes" / "cornell-box" / "scene.toml").read_text()
    scene.write_text(text.replace("resolution = [256, 256]", "resolution = [24, 16]"))
    out = tmp_path / "bd.exr"
    done = run_cli("render", scene, "-e", "bdpt", "--spp", 4, "-o", out, "-q", "-p", "pyramid=2", "-p",
                   "strategy=[1,2]", "-p", "mis=single")
    assert done.returncode == 0, done.stderr
    import OpenEXR
    from PIL import Image

    with OpenEXR.File(str(out)) as exr:
        layers = {name.split(".")[0] for name in exr.channels() if name.startswith("s")}
        single = np.array(exr.channels()["s1t2.weighted"].pixels)
    assert layers == {"s0t2", "s1t1", "s0t3", "s1t2", "s2t1"}  # k = 1, 2 with a pinhole: no t = 0
    image, _, meta = read_exr(out)
    np.testing.assert_allclose(single, image, rtol=1e-6)  # only (1, 2) is weighted in
    assert meta["params"]["strategy"] == [1, 2]
    for kind in ("weighted", "unweighted"):
        sheet = Image.open(tmp_path / f"bd.strategies-{kind}.png")
        assert sheet.size[0] > 4 * 24 and sheet.size[1] > 2 * 16


def test_cli_errors_are_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[camera]\nposition = [0, 0]\n')
    done = run_cli("render", bad, "-o", tmp_path / "x.exr")
    assert done.returncode == 2
    assert done.stderr.strip().startswith("pathspace render: error:") and "camera.position" in done.stderr
    assert "Traceback" not in done.stderr
    done = run_cli("render", ROOT / "scenes" / "furnace" / "scene.toml", "-p", "bogus=1", "-o", tmp_path / "y.exr")
    assert done.returncode == 2 and "has no parameter(s) bogus" in done.stderr


def test_info_prints_the_plan():
    done = run_cli("info", ROOT / "scenes" / "cornell-box" / "scene.toml")
    assert done.returncode == 0
    assert "36 triangles" in done.stdout and "plan: next-event estimation + BSDF sampling" in done.stdout

