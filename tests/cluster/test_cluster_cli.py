"""The command line on a cluster: --workers renders the single-process image, batch-queue job scripts, and
settings a cluster render refuses before any cluster starts."""
from __future__ import annotations

import numpy as np

import pathspace as ps
from pathspace.imageio import read_exr
from conftest import cornell_file, run_cli


def test_render_on_a_local_cluster(tmp_path):
    scene = cornell_file(tmp_path, 32, 32)
    out = tmp_path / "a.exr"
    done = run_cli("render", scene, "-e", "bdpt", "--spp", 6, "--seed", 2, "--workers", 2, "--task-passes", 2,
                   "-o", out, "-q")
    assert done.returncode == 0, done.stderr
    assert "Dask cluster: tcp://" in done.stdout and "dashboard http" in done.stdout
    image, _, meta = read_exr(out)
    assert meta["cluster"]["tasks"] == 3 and meta["spp"] == 6
    direct = ps.render(ps.load_scene(scene), "bdpt", spp=6, seed=2)
    assert np.abs(image - direct.image.astype(np.float32)).max() <= 1e-6 * direct.image.max()


def test_job_scripts_for_batch_queues():
    done = run_cli("cluster", "slurm", "--cores", 4, "--memory", "8GB", "--queue", "short", "--dry-run")
    assert done.returncode == 0, done.stderr
    script = done.stdout
    assert "#SBATCH --cpus-per-task=4" in script and "#SBATCH -p short" in script
    assert "--nthreads 1" in script and "--nworkers 4" in script
    done = run_cli("cluster", "pbs", "--cores", 2, "--memory", "4GB", "--dry-run")
    assert done.returncode == 0 and "#PBS" in done.stdout


def test_what_a_cluster_render_refuses_from_the_command_line(tmp_path):
    scene = cornell_file(tmp_path, 8, 8)
    out = tmp_path / "a.exr"
    for args, message in ((("--time", 1, "--workers", 2), "--time: a render on a cluster takes --spp"),
                          (("--spp", 1, "--task-passes", 2), "--task-passes: only for renders on a cluster"),
                          (("--spp", 1, "--workers", 2, "--resume"), "--resume: a render on a cluster"),
                          (("--spp", 1, "--workers", 2, "--scheduler", "tcp://x:1"), "not allowed with argument")):
        done = run_cli("render", scene, *args, "-o", out)
        assert done.returncode == 2 and message in done.stderr, (args, done.stderr)
        assert "Dask cluster" not in done.stdout
