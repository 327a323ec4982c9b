"""Reading and writing images: OpenEXR for data, PNG for looking at.

EXR files are float32 (OpenEXR does not store float64): the image as the
``RGB`` layer (linear sRGB), its per-pixel variance (of the mean) as the
``variance`` layer (channels ``variance.R/G/B``), for spectral renders
optionally CIE XYZ as the ``xyz`` layer (``xyz.X/Y/Z``), further named layers
(per-strategy images of bidirectional renders: ``s1t2.weighted.R``, ...), and render metadata
as string attributes of the header, prefixed ``pathspace.``.  PNGs are 8-bit sRGB after an exposure
scale, with the sRGB transfer function from colour-science.

Every file is written through :func:`atomic_output`: to a temporary file in
the same folder, flushed to disk, then renamed over the target, so a crash
or a full disk never leaves a truncated file in place of a good one.
"""
from __future__ import annotations

import json
import os
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

import numpy as np

__all__ = ["write_exr", "read_exr", "write_png", "png_bytes", "to_srgb8", "display", "atomic_output"]

METADATA_PREFIX = "pathspace."


@contextmanager
def atomic_output(path: str | os.PathLike) -> Iterator[Path]:
    """The path of a temporary file beside ``path`` (``.NAME.PID.tmp``, same folder, hence same file
    system) for the caller to write; when the block ends without an exception, the file is flushed
    to disk (fsync) and renamed over ``path`` (``os.replace``, atomic), and the rename is flushed too.
    If the block fails, the temporary file is removed and ``path`` is untouched: no partial file ever
    replaces a good one.  A process killed meanwhile leaves at most the hidden temporary file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        yield temporary
        _fsync(temporary)
        os.replace(temporary, path)
        _fsync(path.parent)
    finally:
        if temporary.exists():
            temporary.unlink()


def _fsync(path: Path) -> None:
    """Flush a file's (or a folder's: its entries) data to disk."""
    descriptor = os.open(path, os.O_RDONLY)
    try:
        os.fsync(descriptor)
    finally:
        os.close(descriptor)


def _check_image(image: np.ndarray, name: str) -> np.ndarray:
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"{name} must have shape (height, width, 3), got {image.shape}")
    return image


def write_exr(path: str | os.PathLike, image: np.ndarray, variance: np.ndarray | None = None,
              metadata: dict[str, Any] | None = None, xyz: np.ndarray | None = None,
              layers: dict[str, np.ndarray] | None = None) -> None:
    """Write an (H, W, 3) image, optionally its variance, CIE XYZ, further named RGB ``layers``
    (channels ``NAME.R/G/B``) and metadata to an OpenEXR file (float32, ZIP)."""
    import OpenEXR

    image = _check_image(image, "image")
    channels = {"RGB": np.ascontiguousarray(image, dtype=np.float32)}
    if variance is not None:
        variance = _check_image(variance, "variance")
        if variance.shape != image.shape:
            raise ValueError(f"variance shape {variance.shape} differs from image shape {image.shape}")
        # Pixels with fewer than two samples have no variance estimate (inf); store them as inf too.
        for c, name in enumerate("RGB"):
            channels[f"variance.{name}"] = np.ascontiguousarray(variance[:, :, c], dtype=np.float32)
    if xyz is not None:
        xyz = _check_image(xyz, "xyz")
        for c, name in enumerate("XYZ"):
            channels[f"xyz.{name}"] = np.ascontiguousarray(xyz[:, :, c], dtype=np.float32)
    for layer, values in (layers or {}).items():
        values = _check_image(values, f"layer {layer!r}")
        if values.shape != image.shape or layer in ("RGB", "variance", "xyz"):
            raise ValueError(f"layer {layer!r}: expected a new name and shape {image.shape}, got {values.shape}")
        for c, name in enumerate("RGB"):
            channels[f"{layer}.{name}"] = np.ascontiguousarray(values[:, :, c], dtype=np.float32)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for key, value in (metadata or {}).items():
        header[METADATA_PREFIX + key] = value if isinstance(value, str) else json.dumps(value, default=str)
    with atomic_output(path) as temporary:
        with OpenEXR.File(header, channels) as exr:
            exr.write(str(temporary))


def read_exr(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray | None, dict[str, Any]]:
    """Read (image (H, W, 3) float32, variance or None, metadata) from an EXR written by :func:`write_exr`.

    Files from other programs work too if they hold R, G and B channels.
    """
    import OpenEXR

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such EXR file")
    try:
        with OpenEXR.File(str(path)) as exr:
            channels = {name: np.array(ch.pixels) for name, ch in exr.channels().items()}
            header = dict(exr.header())
    except Exception as error:  # OpenEXR raises RuntimeError/OSError variants for bad files
        raise ValueError(f"{path}: cannot read as OpenEXR: {error}") from None
    if "RGB" in channels:
        image = channels["RGB"]
    elif all(c in channels for c in "RGB"):
        image = np.stack([channels[c] for c in "RGB"], axis=-1)
    else:
        raise ValueError(f"{path}: no RGB channels (found {', '.join(sorted(channels))})")
    variance = channels.get("variance")
    metadata = {}
    for key, value in header.items():
        if key.startswith(METADATA_PREFIX):
            name = key[len(METADATA_PREFIX):]
            try:
                metadata[name] = json.loads(value)
            except (TypeError, ValueError):
                metadata[name] = value
    return image.astype(np.float32), (variance.astype(np.float32) if variance is not None else None), metadata


def display(image: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """The display image of linear RGB (H, W, 3): scaled by 2**exposure, clipped to [0, 1] (NaN as 0) and
    encoded with the sRGB transfer function (IEC 61966-2-1), float64 in [0, 1]."""
    from ._colour import colour

    scaled = np.clip(np.nan_to_num(np.asarray(image, dtype=np.float64) * 2.0 ** exposure, nan=0.0), 0.0, 1.0)
    return np.asarray(colour.cctf_encoding(scaled, function="sRGB"), dtype=np.float64)


def to_srgb8(image: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """Linear RGB (H, W, 3) -> 8-bit sRGB: the :func:`display` image rounded to 8 bits."""
    return np.round(display(image, exposure) * 255.0).astype(np.uint8)


def png_bytes(image: np.ndarray, exposure: float = 0.0) -> bytes:
    """The 8-bit sRGB PNG of linear RGB (H, W, 3), in memory (see :func:`to_srgb8`)."""
    from io import BytesIO

    from PIL import Image

    buffer = BytesIO()
    Image.fromarray(to_srgb8(_check_image(image, "image"), exposure), mode="RGB").save(buffer, format="PNG")
    return buffer.getvalue()


def write_png(path: str | os.PathLike, image: np.ndarray, exposure: float = 0.0) -> None:
    """Write linear RGB (H, W, 3) as an 8-bit sRGB PNG (see :func:`to_srgb8`)."""
    from PIL import Image

    image = _check_image(image, "image")
    with atomic_output(path) as temporary:
        Image.fromarray(to_srgb8(image, exposure), mode="RGB").save(str(temporary), format="PNG")
