"""Cameras: generate primary rays from pixel positions.

Conventions (those of Mitsuba 3 and pbrt): the camera looks from
``position`` toward ``look_at``; image right is ``forward x up`` and image up
is the projection of ``up``; pixel (0, 0) is the top-left corner of the image;
raster coordinates run from 0 to width (x, rightwards) and 0 to height (y,
downwards).  ``fov`` is the full opening angle in degrees along the axis
named by ``fov_axis``: ``"x"``, ``"y"``, ``"smaller"`` or ``"larger"`` (of the
two image dimensions).
"""
from __future__ import annotations

import numpy as np

__all__ = ["PinholeCamera"]

FOV_AXES = ("x", "y", "smaller", "larger")


class PinholeCamera:
    """A pinhole camera (a delta in position: it cannot be hit by rays).

    The image it forms is the pixel average of incident radiance (box pixel
    filter): a primary ray through a uniformly jittered point of a pixel has
    weight 1.  Invalid parameters raise ValueError naming the parameter.
    """

    def __init__(self, position, look_at, up, fov: float, width: int, height: int,
                 fov_axis: str = "smaller") -> None:
        self.position = _vec3(position, "position")
        self.look_at = _vec3(look_at, "look_at")
        self.up = _vec3(up, "up")
        if not (isinstance(width, (int, np.integer)) and isinstance(height, (int, np.integer))
                and width > 0 and height > 0):
            raise ValueError(f"resolution: expected two positive integers, got {width!r} x {height!r}")
        if not (0.0 < float(fov) < 180.0):
            raise ValueError(f"fov: expected an angle in degrees strictly between 0 and 180, got {fov}")
        if fov_axis not in FOV_AXES:
            raise ValueError(f"fov_axis: expected one of {FOV_AXES}, got {fov_axis!r}")
        self.fov, self.fov_axis, self.width, self.height = float(fov), fov_axis, int(width), int(height)

        forward = self.look_at - self.position
        length = np.linalg.norm(forward)
        if not length > 1e-12 * max(1.0, np.abs(self.position).max()):
            raise ValueError("look_at: must differ from position (the viewing direction is undefined)")
        self.forward = forward / length
        right = np.cross(self.forward, self.up)
        right_length = np.linalg.norm(right)
        if not right_length > 1e-9 * np.linalg.norm(self.up):
            raise ValueError("up: must not be zero or parallel to the viewing direction (look_at - position)")
        self.right = right / right_length
        self.image_up = np.cross(self.right, self.forward)

        # Half extents of the image plane at distance 1 along forward.
        tan_axis = np.tan(np.radians(self.fov) / 2.0)
        aspect = self.width / self.height
        axis = fov_axis
        if axis == "smaller":
            axis = "x" if self.width <= self.height else "y"
        elif axis == "larger":
            axis = "x" if self.width >= self.height else "y"
        self.tan_half = (tan_axis, tan_axis / aspect) if axis == "x" else (tan_axis * aspect, tan_axis)

    def __repr__(self) -> str:
        return (f"PinholeCamera(position={self.position.tolist()}, look_at={self.look_at.tolist()}, "
                f"up={self.up.tolist()}, fov={self.fov:g}, fov_axis={self.fov_axis!r}, "
                f"resolution={self.width}x{self.height})")

    @property
    def resolution(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return (int(self.width), int(self.height))

    @property
    def pixel_count(self) -> int:
        """Number of pixels."""
        return int(self.width) * int(self.height)

    def generate_rays(self, pixels: np.ndarray, jitter: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Primary rays through the points ``pixel + jitter`` of the image.

        ``pixels`` are flat pixel indices (row-major, y * width + x); ``jitter``
        a (2, N) array of offsets in [0, 1) within each pixel.  Returns origins
        (3, N) (a read-only broadcast of the camera position) and unit
        directions (3, N), both float32.
        """
        px = (pixels % self.width).astype(np.float32) + jitter[0].astype(np.float32)
        py = (pixels // self.width).astype(np.float32) + jitter[1].astype(np.float32)
        sx = (np.float32(2.0 / self.width) * px - np.float32(1.0)) * np.float32(self.tan_half[0])
        sy = (np.float32(1.0) - np.float32(2.0 / self.height) * py) * np.float32(self.tan_half[1])
        f, r, u = (v.astype(np.float32)[:, None] for v in (self.forward, self.right, self.image_up))
        d = f + r * sx + u * sy
        d /= np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        origins = np.broadcast_to(self.position.astype(np.float32)[:, None], d.shape)
        return origins, d


def _vec3(value, name: str) -> np.ndarray:
    array = np.asarray(value, dtype=np.float64)
    if array.shape != (3,) or not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: expected 3 finite numbers, got {value!r}")
    return array
