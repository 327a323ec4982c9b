"""Saving and resuming renders: a render stopped (Ctrl-C, SIGTERM) or killed (SIGKILL) at any moment and
resumed gives, bit for bit, the image of an uninterrupted render; state files refuse other renders and
damaged files with errors that say what differs; no partial file ever replaces a good one."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import pathspace as ps
from pathspace import resume
from pathspace.estimators import make_estimator
from pathspace.imageio import read_exr
from pathspace.resume import StateError, load_state, read_header
from pathspace.sampler import StreamSamplers
from conftest import ROOT, scene_dict

# Renders small enough for seconds, with enough work items that saves fall mid-render: short paths
# (max_depth) end items quickly; bdpt keeps per-strategy layers (pyramid) and splats.  Both must run
# well beyond their first save: a render that finished (and removed its state) just before the kill
# failed the test in CI once, with 48 bdpt passes.
CASES = {"pt": ((32, 32), 600, {"max_depth": 3}), "bdpt": ((48, 48), 160, {"max_depth": 2, "pyramid": 2})}
SEED = 7


def assert_same_film(a: ps.Film, b: ps.Film) -> None:
    """Bit for bit the same estimate: passes, sample counts, means and variances of the image and layers."""
    assert a.passes == b.passes and a.nonfinite == b.nonfinite
    np.testing.assert_array_equal(a.count, b.count)
    np.testing.assert_array_equal(a.mean(), b.mean())
    np.testing.assert_array_equal(a.variance(), b.variance())
    assert sorted(a.layers) == sorted(b.layers)
    for name in a.layers:
        np.testing.assert_array_equal(a.layer_mean(name), b.layer_mean(name))
        np.testing.assert_array_equal(a.layer_variance(name), b.layer_variance(name))


@pytest.fixture(scope="module")
def scene_files(tmp_path_factory):
    """A scene file per estimator case (the Cornell box at the case's resolution)."""
    folder = tmp_path_factory.mktemp("scenes")
    text = (ROOT / "scenes" / "cornell-box" / "scene.toml").read_text()
    files = {}
    for name, ((width, height), _, _) in CASES.items():
        files[name] = folder / f"{name}.toml"
        files[name].write_text(text.replace("resolution = [256, 256]", f"resolution = [{width}, {height}]"))
    return files


@pytest.fixture(scope="module")
def uninterrupted(scene_files):
    """The uninterrupted render of each case."""
    out = {}
    for name, (_, spp, params) in CASES.items():
        out[name] = ps.render(ps.load_scene(scene_files[name]), name, spp=spp, seed=SEED, **params)
    return out


def cli(*args) -> list[str]:
    return [sys.executable, "-m", "pathspace.cli", *map(str, args)]


def start_render(scene_file, name, tmp_path, timeout: float = 60.0) -> tuple[Path, Path, subprocess.Popen]:
    """``pathspace render`` of a case to ``tmp_path/out.exr`` in the background, saving its state every 20 ms;
    returns (out, state, process) once the state has been saved."""
    _, spp, params = CASES[name]
    out, state = tmp_path / "out.exr", tmp_path / "out.exr.state"
    options = [x for key, value in params.items() for x in ("-p", f"{key}={value}")]
    process = subprocess.Popen(cli("render", scene_file, "-e", name, "--spp", spp, "--seed", SEED, "-o", out, "-q",
                                   "--no-png", "--save-every", 0.02, *options),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + timeout
    while not state.exists():
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline, f"no state file after {timeout} s"
        time.sleep(0.005)
    return out, state, process


@pytest.mark.parametrize("name", sorted(CASES))
def test_a_render_killed_at_a_random_moment_resumes_to_the_same_image(name, scene_files, uninterrupted, tmp_path):
    """SIGKILL at a random moment after the first save; the resumed render equals the uninterrupted one
    bit for bit (passes are seeded independently and join the restored film in the same order)."""
    _, spp, params = CASES[name]
    out, state, process = start_render(scene_files[name], name, tmp_path)
    time.sleep(np.random.default_rng().uniform(0.0, 0.2))
    assert process.poll() is None, "the render ended before it could be killed; make it longer"
    process.kill()
    process.communicate()
    assert process.returncode == -signal.SIGKILL
    saved = read_header(state)["passes"]
    assert 1 <= saved <= spp
    resumed = ps.render(ps.load_scene(scene_files[name]), name, spp=spp, seed=SEED, state_file=state, resume=True,
                        **params)
    assert resumed.stats["resumed"]["passes"] == saved and resumed.stats["spp"] == spp
    assert_same_film(resumed.film, uninterrupted[name].film)
    if name == "bdpt":
        assert len(resumed.film.layers) == 10  # (s, t) for k = 1, 2, weighted and unweighted
    assert not state.exists()  # a finished render removes its state


def test_ctrl_c_writes_what_was_rendered_and_resume_finishes(scene_files, uninterrupted, tmp_path):
    """Ctrl-C: no traceback, exit 130, the image of the completed passes, the state, and how to resume;
    ``--resume`` then writes the uninterrupted render's image and removes the state."""
    out, state, process = start_render(scene_files["pt"], "pt", tmp_path)
    process.send_signal(signal.SIGINT)
    stdout, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr
    assert "Traceback" not in stderr and stderr == ""
    match = re.search(r"stopped by SIGINT after (\d+) of 600 spp: wrote (\S+) \((\d+) spp\)", stdout)
    assert match and match[2] == str(out) and match[1] == match[3], stdout
    passes = int(match[1])
    assert 1 <= passes < 600
    assert "continue it with: pathspace render " in stdout and stdout.rstrip().endswith("--resume")
    image, _, metadata = read_exr(out)
    assert metadata["spp"] == passes and metadata["stopped"] == "SIGINT"
    saved = load_state(state)
    assert saved.passes == passes
    np.testing.assert_array_equal(image, saved.film.image().astype(np.float32))

    _, spp, params = CASES["pt"]
    done = subprocess.run(cli("render", scene_files["pt"], "--spp", spp, "--seed", SEED, "-o", out, "-q", "--no-png",
                              "-p", f"max_depth={params['max_depth']}", "--resume"),
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert f"resumed at {passes} spp" in done.stdout and not state.exists()
    image, _, metadata = read_exr(out)
    assert metadata["spp"] == spp and metadata["resumed"]["passes"] == passes and metadata["stopped"] is None
    np.testing.assert_array_equal(image, uninterrupted["pt"].image.astype(np.float32))


def test_sigterm_stops_cleanly(scene_files, uninterrupted, tmp_path):
    out, state, process = start_render(scene_files["pt"], "pt", tmp_path)
    process.send_signal(signal.SIGTERM)
    stdout, stderr = process.communicate(timeout=60)
    assert process.returncode == 143 and stderr == ""
    assert "stopped by SIGTERM after" in stdout
    passes = read_exr(out)[2]["spp"]
    assert read_header(state)["passes"] == passes
    _, spp, params = CASES["pt"]
    resumed = ps.render(ps.load_scene(scene_files["pt"]), "pt", spp=spp, seed=SEED, state_file=state, resume=True,
                        **params)
    assert_same_film(resumed.film, uninterrupted["pt"].film)


@pytest.fixture(scope="module")
def small():
    return ps.scene_from_dict(scene_dict("cornell-box", (24, 24)))


def interrupt(checkpoint) -> None:
    """A checkpoint callback that presses Ctrl-C."""
    os.kill(os.getpid(), signal.SIGINT)


class CtrlCAt:
    """An estimator whose render is stopped by Ctrl-C at its checkpoint of ``passes`` passes, exactly: its
    workers see no items from that pass on, finish those they have, and wait for the checkpoint to press
    Ctrl-C (:meth:`interrupt`).  Without the hold, workers that ran ahead of a main thread starved of the GIL
    could finish the render before it reached the checkpoint (CI saw a render that should have stopped
    complete)."""

    def __init__(self, name: str, params: dict, passes: int) -> None:
        self.estimator, self.passes, self.pressed = make_estimator(name, **params), passes, threading.Event()
        self.estimator.render_items = self._render_items

    def _render_items(self, job, next_item, counters):
        def held():
            item = next_item()
            return None if item is not None and item.passes[0] >= self.passes else item

        yield from type(self.estimator).render_items(self.estimator, job, held, counters)
        assert self.pressed.wait(60), f"the checkpoint at {self.passes} passes never came"
        job.control.check()  # raises Interrupted, as a worker that asks for an item after the stop does

    def interrupt(self, checkpoint) -> None:
        """The checkpoint callback: Ctrl-C, then the held workers go on."""
        interrupt(checkpoint)
        self.pressed.set()


@pytest.mark.parametrize("estimator, spp, params", [("pt", 200, {"max_depth": 3}), ("bdpt", 60, {"pyramid": 2}),
                                                    ("pt", 200, {"max_depth": 3, "spectral": True})])
def test_stopped_twice_and_resumed_in_process(small, estimator, spp, params, tmp_path):
    """Stopped at 4 passes, resumed, stopped again a pass later, resumed to the end: the same film as one
    render; checkpoints count the passes of the whole render across sessions."""
    state = tmp_path / "run.state"
    params = dict(params)
    spectral = {"spectral": params.pop("spectral")} if "spectral" in params else {}
    whole = ps.render(small, estimator, spp=spp, seed=3, **params, **spectral)
    handler = signal.getsignal(signal.SIGINT)   # Python's own, or SIG_IGN in a process started in the background
    stop = CtrlCAt(estimator, params, 4)
    first = ps.render(small, stop.estimator, spp=spp, seed=3, state_file=state, stop_on_signal=True,
                      checkpoints=[4], on_checkpoint=stop.interrupt, **spectral)
    assert first.stats["stopped"] == "SIGINT" and first.stats["spp"] == 4
    assert first.stats["saves"] == 1 and read_header(state)["passes"] == 4
    assert signal.getsignal(signal.SIGINT) is handler  # restored
    stop = CtrlCAt(estimator, params, 5)
    second = ps.render(small, stop.estimator, spp=spp, seed=3, state_file=state, resume=True, stop_on_signal=True,
                       checkpoints=[5], on_checkpoint=stop.interrupt, **spectral)
    assert second.stats["stopped"] == "SIGINT" and second.stats["spp"] == 5
    assert second.stats["resumed"]["passes"] == first.stats["spp"]
    assert second.stats["seconds"] > second.stats["resumed"]["seconds"] > 0
    seen = {}
    look = second.stats["spp"] + 1
    third = ps.render(small, estimator, spp=spp, seed=3, state_file=state, resume=True, checkpoints=[4, look],
                      on_checkpoint=lambda c: seen.update({c.passes: c.film.mean().copy()}), **params, **spectral)
    assert third.stats["stopped"] is None and third.stats["resumed"]["passes"] == second.stats["spp"]
    assert_same_film(third.film, whole.film)
    assert list(seen) == [look]  # the checkpoint at 4 passes was behind the restored render
    np.testing.assert_array_equal(seen[look], ps.render(small, estimator, spp=look, seed=3, **params,
                                                        **spectral).film.mean())
    assert not state.exists()


def test_time_budgets_continue_with_the_time_left(small, tmp_path):
    """A timed render stopped after 0.2 s resumes with the time left: render seconds add up to the budget.
    (Short paths: a path-tracing work item ends with its longest path.)"""
    state = tmp_path / "timed.state"
    first = ps.render(small, "pt", time=0.8, seed=1, max_depth=4, state_file=state, stop_on_signal=True,
                      checkpoints=[0.2], on_checkpoint=interrupt)
    assert first.stats["stopped"] == "SIGINT" and 0.2 <= first.stats["seconds"] < 0.8
    assert read_header(state)["seconds"] == first.stats["seconds"]
    start = time.perf_counter()
    second = ps.render(small, "pt", time=0.8, seed=1, max_depth=4, state_file=state, resume=True)
    wall = time.perf_counter() - start
    assert second.stats["resumed"]["seconds"] == first.stats["seconds"]
    assert second.stats["seconds"] >= 0.5 and second.stats["spp"] > first.stats["spp"]  # ends by its last whole item
    assert wall < 0.8 - first.stats["seconds"] + 0.5  # the time left, not the whole budget again


def stop_early(scene, state) -> None:
    """Save the state of a 200-pass render of ``scene`` stopped by Ctrl-C after 2 passes."""
    stop = CtrlCAt("pt", {"max_depth": 3}, 2)
    result = ps.render(scene, stop.estimator, spp=200, seed=3, state_file=state, stop_on_signal=True,
                       checkpoints=[2], on_checkpoint=stop.interrupt)
    assert result.stats["stopped"] == "SIGINT" and result.stats["spp"] == 2 and state.exists()


def test_a_state_belongs_to_one_render(small, tmp_path):
    state = tmp_path / "run.state"
    stop_early(small, state)
    with pytest.raises(StateError, match=r"holds an unfinished render \(\d+ of 200 spp.*resume=True"):
        ps.render(small, "pt", spp=200, seed=3, max_depth=3, state_file=state)
    with pytest.raises(StateError, match=r"seed: 3 in the state, 4 now; spp: 200 in the state, 16 now"):
        ps.render(small, "pt", spp=16, seed=4, max_depth=3, state_file=state, resume=True)
    with pytest.raises(StateError, match=r"params\.max_depth: 3 in the state, 5 now"):
        ps.render(small, "pt", spp=200, seed=3, max_depth=5, state_file=state, resume=True)
    with pytest.raises(StateError, match=r"mode: 'rgb' in the state, 'spectral' now; wavelengths: None in the "
                                         r"state, 'uniform' now"):
        ps.render(small, "pt", spp=200, seed=3, max_depth=3, spectral=True, state_file=state, resume=True)
    other = ps.scene_from_dict(scene_dict("cornell-box-point-light", (24, 24)))
    with pytest.raises(StateError, match="scene: its fingerprint differs"):
        ps.render(other, "pt", spp=200, seed=3, max_depth=3, state_file=state, resume=True)
    # resume without a state file starts afresh
    fresh = ps.render(small, "pt", spp=2, seed=3, state_file=tmp_path / "none.state", resume=True)
    assert fresh.stats["resumed"] is None and fresh.stats["spp"] == 2


def test_damaged_state_files_are_refused(small, tmp_path):
    state = tmp_path / "run.state"
    stop_early(small, state)
    good = state.read_bytes()
    load_state(state)
    for damaged, message in ((good[:-1000], "digest does not match"),
                             (good[:-40] + bytes([good[-40] ^ 1]) + good[-39:], "digest does not match"),
                             (b"P3\n2 2\n" + good, "not a pathspace render state"),
                             (good.replace(b'"format": 1', b'"format": 9', 1), "format 9; this pathspace reads "
                                                                              "format 1")):
        state.write_bytes(damaged)
        with pytest.raises(StateError, match=message):
            ps.render(small, "pt", spp=200, seed=3, max_depth=3, state_file=state, resume=True)
    state.write_bytes(good)
    older = load_state(state)
    del older.film.nonfinite  # as if written by a pathspace whose Film had other fields
    resume.save_state(state, older)
    with pytest.raises(StateError, match="the saved film's fields differ from this pathspace's Film"):
        ps.render(small, "pt", spp=200, seed=3, max_depth=3, state_file=state, resume=True)


def test_what_cannot_be_resumed_is_refused(small, tmp_path):
    state = tmp_path / "run.state"
    with pytest.raises(ValueError, match="save_every, resume and keep_state need a state_file"):
        ps.render(small, "pt", spp=2, save_every=10)
    with pytest.raises(ValueError, match="save_every: expected a number of seconds > 0"):
        ps.render(small, "pt", spp=2, state_file=state, save_every=0)
    with pytest.raises(ValueError, match="own samplers cannot be saved"):
        ps.render(small, "pt", spp=2, state_file=state, samplers=StreamSamplers(1))
    with pytest.raises(ValueError, match="no fingerprint"):
        ps.render(ps.Scene(small.camera, small.mesh, small.materials, small.lights, small.shape_names), "pt",
                  spp=2, state_file=state)
    assert not state.exists()


def test_state_writes_are_atomic(small, tmp_path, monkeypatch):
    """A save that fails halfway (disk full) leaves the previous state whole and no temporary file."""
    state = tmp_path / "run.state"
    stop_early(small, state)
    good = state.read_bytes()

    def disk_full(film, file, protocol):
        file.write(b"\x80\x05 half a pickle")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(resume.pickle, "dump", disk_full)
    with pytest.raises(OSError, match="No space left"):
        resume.save_state(state, load_state(state))
    assert state.read_bytes() == good and sorted(p.name for p in tmp_path.iterdir()) == ["run.state"]
