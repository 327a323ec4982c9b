"""EXR files round-trip images, variances and metadata; PNGs are sRGB-encoded with exposure."""
from __future__ import annotations

import numpy as np
import pytest

from pathspace.imageio import read_exr, to_srgb8, write_exr, write_png


def test_exr_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    image = rng.random((5, 7, 3)) * 100
    variance = rng.random((5, 7, 3))
    write_exr(tmp_path / "a.exr", image, variance, {"spp": 64, "estimator": "pt", "params": {"rr": "off"}})
    back, back_var, meta = read_exr(tmp_path / "a.exr")
    np.testing.assert_array_equal(back, image.astype(np.float32))
    np.testing.assert_array_equal(back_var, variance.astype(np.float32))
    assert meta == {"spp": 64, "estimator": "pt", "params": {"rr": "off"}}
    # A strided view (not contiguous) is written correctly too.
    write_exr(tmp_path / "b.exr", image[:, ::-1])
    np.testing.assert_array_equal(read_exr(tmp_path / "b.exr")[0], image[:, ::-1].astype(np.float32))


def test_exr_errors(tmp_path):
    with pytest.raises(ValueError, match=r"shape \(height, width, 3\)"):
        write_exr(tmp_path / "x.exr", np.zeros((4, 4)))
    with pytest.raises(FileNotFoundError):
        read_exr(tmp_path / "none.exr")
    (tmp_path / "bad.exr").write_bytes(b"not an exr")
    with pytest.raises(ValueError, match="cannot read as OpenEXR"):
        read_exr(tmp_path / "bad.exr")


def test_png_encoding(tmp_path):
    # sRGB OETF: 0 -> 0, 0.5 -> 188 (0.7354), 1 -> 255, and exposure doubles per stop.
    image = np.array([[[0.0, 0.5, 1.0], [0.25, 2.0, np.nan]]])
    np.testing.assert_array_equal(to_srgb8(image), [[[0, 188, 255], [137, 255, 0]]])
    np.testing.assert_array_equal(to_srgb8(image[:, :1] * 0 + 0.25, exposure=1.0), to_srgb8(image[:, :1] * 0 + 0.5))
    write_png(tmp_path / "x.png", image)
    from PIL import Image

    np.testing.assert_array_equal(np.asarray(Image.open(tmp_path / "x.png")), to_srgb8(image))

