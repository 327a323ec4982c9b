"""EXR files round-trip images, variances and metadata; PNGs are sRGB-encoded with exposure."""
from __future__ import annotations

import os

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



def test_a_failed_write_leaves_the_old_file_whole(tmp_path, monkeypatch):
    """A write that dies halfway (a full disk) leaves the previous EXR and PNG intact and no temporary
    file; a write that succeeds is flushed to disk (the file and its folder) before and after the rename."""
    import OpenEXR
    from PIL import Image

    image = np.full((4, 6, 3), 0.5)
    write_exr(tmp_path / "a.exr", image)
    write_png(tmp_path / "a.png", image)
    good = {name: (tmp_path / name).read_bytes() for name in ("a.exr", "a.png")}

    class HalfWrittenExr:
        def __init__(self, header, channels):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def write(self, path):
            with open(path, "wb") as file:
                file.write(good["a.exr"][:100])
            raise OSError(28, "No space left on device")

    def half_written_png(self, path, format=None, **options):
        with open(path, "wb") as file:
            file.write(good["a.png"][:20])
        raise OSError(28, "No space left on device")

    with monkeypatch.context() as patch:
        patch.setattr(OpenEXR, "File", HalfWrittenExr)
        patch.setattr(Image.Image, "save", half_written_png)
        with pytest.raises(OSError, match="No space left"):
            write_exr(tmp_path / "a.exr", image * 2)
        with pytest.raises(OSError, match="No space left"):
            write_png(tmp_path / "a.png", image * 2)
    assert {name: (tmp_path / name).read_bytes() for name in good} == good
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.exr", "a.png"]
    np.testing.assert_array_equal(read_exr(tmp_path / "a.exr")[0], 0.5)

    synced = []
    monkeypatch.setattr(os, "fsync", lambda descriptor: synced.append(descriptor))
    write_exr(tmp_path / "a.exr", image * 2)
    assert len(synced) == 2  # the temporary file, then the folder after the rename
    np.testing.assert_array_equal(read_exr(tmp_path / "a.exr")[0], 1.0)
