"""The C kernel of the pinhole camera's connections (ext/camera.c) against the NumPy code it replaces.

``PinholeCamera.sample_importance`` (light tracing's and BDPT's t = 1 strategy) takes the direction to the
pinhole, the density, the raster position and the cosine from ``_native.pinhole_connect``.  The reference is
the NumPy code the thin lens keeps (``ThinLensCamera.sample_importance``), run on the pinhole: its lens point
is then the pinhole, as before the kernel.  Compared bit for bit on receivers in view, beside and behind the
camera, on the film's edges, at the pinhole itself and far away, float32 and float64, for cameras of several
shapes; then the kernel's refusals.
"""
from __future__ import annotations

import numpy as np
import pytest

from pathspace import _native
from pathspace.camera import PinholeCamera, ThinLensCamera

CAMERAS = [
    PinholeCamera([0.0, 0.0, 3.4], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 40.0, 64, 64),
    PinholeCamera([1.0, -2.0, 0.5], [0.3, 0.2, -1.0], [0.2, 0.1, 1.0], 75.0, 90, 31, "larger"),
    PinholeCamera([1e3, 2e3, -5e2], [1e3 + 1.0, 2e3, -5e2], [0.0, 0.0, 1.0], 10.0, 17, 200, "x"),
]


def receivers_for(camera: PinholeCamera, rng: np.random.Generator, n: int) -> np.ndarray:
    """Points in front of the camera through the film and past its edges, some behind it, a few at the
    pinhole, a few far away."""
    sx, sy = rng.uniform(-1.3, 1.3, (2, n))
    depth = rng.exponential(3.0, n) * np.where(rng.random(n) < 0.15, -1.0, 1.0)
    direction = (camera.forward[:, None] + camera.right[:, None] * sx * camera.tan_half[0]
                 + camera.image_up[:, None] * sy * camera.tan_half[1])
    points = camera.position[:, None] + direction * depth
    points[:, :5] = camera.position[:, None]
    points[:, 5:10] *= 1e5
    edge = (np.array([1.0, -1.0, 1.0, -1.0]), np.array([1.0, 1.0, -1.0, -1.0]))   # the film's corners
    points[:, 10:14] = camera.position[:, None] + (camera.forward[:, None] + camera.right[:, None] * edge[0]
                                                   * camera.tan_half[0] + camera.image_up[:, None] * edge[1]
                                                   * camera.tan_half[1]) * 2.0
    return points


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("index", range(len(CAMERAS)))
def test_pinhole_connect_equals_the_numpy_reference(index, dtype):
    camera = CAMERAS[index]
    rng = np.random.default_rng(index)
    receivers = receivers_for(camera, rng, 5000).astype(dtype)
    u = rng.random((2, 5000))
    got = camera.sample_importance(receivers, u)
    with np.errstate(divide="ignore", invalid="ignore"):   # the reference divides 0 / 0 at the pinhole
        expected = ThinLensCamera.sample_importance(camera, receivers, u)
    for name, a, b in zip(("wi", "we", "pdf", "lens", "raster", "valid"), got, expected):
        assert a.dtype == b.dtype and a.shape == b.shape, name
        np.testing.assert_array_equal(a, b, err_msg=name)
    valid = got[5]
    assert valid.any() and not valid.all()
    assert np.isnan(got[0]).any() == (dtype == np.float64 or index > 0)   # at the pinhole, if float32 holds it


def arguments(camera: PinholeCamera = CAMERAS[0]) -> list:
    return [np.zeros((3, 4), np.float32), camera.position, camera.forward, camera.right, camera.image_up,
            camera.tan_half[0], camera.tan_half[1], camera.width, camera.height, 1.0]


@pytest.mark.parametrize("position, value, error, match", [
    (0, np.zeros((2, 4), np.float32), ValueError, "3 rows"),
    (0, np.zeros((3, 4), np.int32), TypeError, "receivers"),
    (0, np.zeros((4, 3), np.float32).T, ValueError, "receivers must be C-contiguous"),
    (1, np.zeros(2), ValueError, "position must have 3 entries"),
    (2, np.zeros(3, np.float32), TypeError, "forward"),
    (4, [0.0, 1.0, 0.0], TypeError, "image_up"),
])
def test_pinhole_connect_refuses_bad_arguments(position, value, error, match):
    args = arguments()
    args[position] = value
    with pytest.raises(error, match=match):
        _native.pinhole_connect(*args)
