"""The command line: render and compare, BDPT strategy layers and contact sheets, one-line errors, the plan."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import time

import numpy as np
import pytest

import pathspace as ps
from pathspace import metrics
from pathspace.cli import main
from pathspace.estimators import ESTIMATORS
from pathspace.imageio import read_exr
from conftest import CORNELL, ROOT, cornell_file, run_cli


def test_render_and_compare(tmp_path):
    scene = cornell_file(tmp_path, 32, 32)

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
    scene = cornell_file(tmp_path, 24, 16)
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
    done = run_cli("info", CORNELL)
    assert done.returncode == 0
    assert "36 triangles" in done.stdout and "plan: next-event estimation + BSDF sampling" in done.stdout



def run_main(capsys, *args) -> subprocess.CompletedProcess:
    """``pathspace ARGS`` in this process (no interpreter start-up): exit code, stdout and stderr."""
    try:
        code = main([str(a) for a in args])
    except SystemExit as exit:  # argparse: --help, --version, usage errors
        code = exit.code
    out, err = capsys.readouterr()
    return subprocess.CompletedProcess(args, code, out, err)


def test_version(capsys):
    done = run_main(capsys, "--version")
    assert done.returncode == 0 and done.stdout.strip() == f"pathspace {ps.__version__}"


def test_render_help_lists_every_estimator_parameter(capsys):
    """Every -p key of every estimator, with its default and meaning, and the long-render options."""
    text = run_main(capsys, "render", "--help").stdout
    lines = text.splitlines()
    for name, cls in ESTIMATORS.items():
        section = lines.index(f"  {name}:")
        for key, default, meaning in cls.parameters():
            assert f"    {key} (default {default!r}): {meaning}" in lines[section:], (name, key)
    assert "--save-every SECONDS" in text and "--resume" in text


def one_line_error(done, command: str, *fragments: str) -> None:
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert "Traceback" not in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert done.stderr.startswith(f"pathspace {command}: error: "), done.stderr
    for fragment in fragments:
        assert fragment in done.stderr, (fragment, done.stderr)


def test_unwritable_outputs_fail_before_any_work(tmp_path, capsys):
    """Every command that writes files checks its outputs first: one line, exit 2, at once (the renders
    asked for would take hours)."""
    blocker = tmp_path / "blocker"
    blocker.write_text("a file where a folder should be")
    bad = blocker / "out"
    scene = CORNELL
    commands = {"render": ("render", scene, "--spp", 100000, "-o", f"{bad}.exr"),
                "reference": ("reference", scene, "--spp", 100000, "--cache", bad),
                "converge": ("converge", scene, "-e", "pt,bdpt", "--spp", 100000, "--reference", tmp_path / "r.exr",
                             "-o", f"{bad}.csv"),
                "export": ("export", "--mitsuba", scene, f"{bad}.xml")}
    for command, args in commands.items():
        start = time.perf_counter()
        done = run_main(capsys, *args)
        assert time.perf_counter() - start < 2.0, command
        one_line_error(done, command, "cannot write", "(a file is in the way)")
    one_line_error(run_main(capsys, "reference", scene, "--spp", 100000, "--cache", tmp_path, "-o", f"{bad}.exr"),
                   "reference", f"cannot write {bad}.exr")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["blocker"]  # nothing rendered, nothing cached
    (tmp_path / "folder.exr").mkdir()
    one_line_error(run_main(capsys, "render", scene, "-o", tmp_path / "folder.exr"), "render", "it is a folder")


def test_unknown_parameters_list_the_valid_keys(tmp_path, capsys):
    scene = CORNELL
    keys = ", ".join(key for key, _, _ in ESTIMATORS["bdpt"].parameters())
    for command, args in (("render", ("render", scene, "-e", "bdpt", "--spp", 100000, "-o", tmp_path / "x.exr")),
                          ("info", ("info", scene, "-e", "bdpt")),
                          ("reference", ("reference", scene, "-e", "bdpt", "--spp", 100000, "--cache", tmp_path))):
        one_line_error(run_main(capsys, *args, "-p", "bogus=1"), command, "estimator 'bdpt' has no parameter(s) bogus; "
                                                                  f"its parameters are: {keys}")
    one_line_error(run_main(capsys, "converge", scene, "-e", "bdpt:bogus=1", "--spp", 100000, "--reference",
                           tmp_path / "r.exr", "-o", tmp_path / "t.csv"), "converge", "has no parameter(s) bogus")
    one_line_error(run_main(capsys, "render", scene, "-p", "max_depth=-7", "-o", tmp_path / "x.exr"), "render",
                   "max_depth: expected -1 (unbounded) or an integer >= 1, got -7")
    done = run_main(capsys, "render", scene, "--save-every", "-1", "-o", tmp_path / "x.exr")
    assert done.returncode == 2 and "expected a number of seconds >= 0, got '-1'" in done.stderr


def test_state_files_on_the_command_line(tmp_path, capsys):
    """--resume without a state starts afresh and says so; a state is never overwritten without --resume,
    nor resumed by a different render."""
    scene = cornell_file(tmp_path, 16, 16)
    out = tmp_path / "out.exr"
    done = run_main(capsys, "render", scene, "--spp", 2, "-o", out, "-q", "--no-png", "--resume")
    assert done.returncode == 0, done.stderr
    assert f"no saved state at {out}.state: starting from the beginning" in done.stdout
    assert read_exr(out)[2]["spp"] == 2 and not (tmp_path / "out.exr.state").exists()

    state = tmp_path / "out.exr.state"
    # 3000 passes of 256 pixels: many work items, so the render cannot end before the SIGINT is handled.
    stopped = ps.render(ps.load_scene(scene), "pt", spp=3000, seed=0, max_depth=3, state_file=state,
                        stop_on_signal=True, checkpoints=[2],
                        on_checkpoint=lambda c: os.kill(os.getpid(), signal.SIGINT))
    assert stopped.stats["stopped"] == "SIGINT"
    done = run_main(capsys, "render", scene, "--spp", 3000, "-p", "max_depth=3", "-o", out)
    one_line_error(done, "render", f"{state} holds an unfinished render ({stopped.stats['spp']} of 3000 spp",
                   "--resume")
    done = run_main(capsys, "render", scene, "--spp", 3000, "-p", "max_depth=4", "--seed", 1, "-o", out, "--resume")
    one_line_error(done, "render", "was saved by a different render (params.max_depth: 3 in the state, 4 now; "
                                   "seed: 0 in the state, 1 now)")
    assert read_exr(out)[2]["spp"] == 2  # the earlier image is untouched
