"""Cameras: primary rays, importance, and the projection of world points to the image.

Conventions (those of Mitsuba 3 and pbrt): the camera looks from
``position`` toward ``look_at``; image right is ``forward x up`` and image up
is the projection of ``up``; pixel (0, 0) is the top-left corner of the
image; raster coordinates run from 0 to width (x, rightwards) and 0 to height
(y, downwards).  ``fov`` is the full opening angle in degrees along the axis
named by ``fov_axis``: ``"x"``, ``"y"``, ``"smaller"`` or ``"larger"``.

Importance is normalised as in pbrt-v4 (PerspectiveCamera::We): over the
film, with A the area of the image rectangle at distance 1 from the lens and
theta the angle to the optical axis,

    We(x_lens, w) = 1 / (A * lens_area * cos^4 theta)          (inside the frustum)

so that it integrates to one over lens area and projected solid angle.  The
directional density of primary rays through uniformly chosen film points is
p(w) = 1 / (A cos^3 theta), and their positional density 1 / lens_area.  A
pinhole has no lens area: its position is a delta (``delta_position``), it
cannot be hit by rays, and "lens_area" is taken as 1.
"""
from __future__ import annotations

import copy
import numpy as np

from . import _native
from .checks import triple
from .fields import MAX_COORDINATE, Fields
from .vecmath import dot

__all__ = ["CAMERAS", "PinholeCamera", "ThinLensCamera", "FOV_AXES"]

FOV_AXES = ("x", "y", "smaller", "larger")
# Fields of view (degrees) below this are refused: nothing real is narrower, and near 1e-150 the image
# rectangle's area (~ fov^2) underflows float64 and the camera's importance turns infinite.
MIN_FOV = 1e-6


def _view(fields: "Fields") -> dict:
    """The parameters every camera reads: position, look_at, up, fov, fov_axis, resolution."""
    view = dict(position=fields.point("position"), look_at=fields.point("look_at"),
                up=fields.direction("up", [0.0, 1.0, 0.0]),
                fov=fields.number("fov", low=MIN_FOV, high=180.0, high_open=True),
                fov_axis=fields.string("fov_axis", "smaller", choices=FOV_AXES))
    width, height = fields.vector("resolution", 2, integer=True, low=1)
    return dict(view, width=int(width), height=int(height))


class PinholeCamera:
    """A pinhole camera.  Invalid parameters raise ValueError naming the parameter."""

    delta_position = True
    lens_radius = 0.0

    def __init__(self, position, look_at, up, fov: float, width: int, height: int,
                 fov_axis: str = "smaller") -> None:
        self.position = triple(position, "position")
        self.look_at = triple(look_at, "look_at")
        self.up = triple(up, "up")
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
        if not length > 1e-12 * max(np.abs(self.position).max(), np.abs(self.look_at).max()):
            raise ValueError("look_at: must differ from position (the viewing direction is undefined)")
        self.forward = forward / length
        right = np.cross(self.forward, self.up)
        right_length = np.linalg.norm(right)
        if not right_length > 1e-9 * np.linalg.norm(self.up):
            raise ValueError("up: must not be zero or parallel to the viewing direction (look_at - position)")
        self.right = right / right_length
        self.image_up = np.cross(self.right, self.forward)

        # Half extents of the image rectangle at distance 1 along forward.
        tan_axis = np.tan(np.radians(self.fov) / 2.0)
        aspect = self.width / self.height
        axis = fov_axis
        if axis == "smaller":
            axis = "x" if self.width <= self.height else "y"
        elif axis == "larger":
            axis = "x" if self.width >= self.height else "y"
        self.tan_half = (tan_axis, tan_axis / aspect) if axis == "x" else (tan_axis * aspect, tan_axis)
        self.image_area = 4.0 * self.tan_half[0] * self.tan_half[1]

    @classmethod
    def from_fields(cls, fields: "Fields") -> "PinholeCamera":
        """A ``[camera]`` table of type "pinhole" (see docs/scene-format.md)."""
        view = _view(fields)
        fields.finish()
        return fields.build(lambda: cls(**view))

    def translated(self, offset: np.ndarray) -> "PinholeCamera":
        """The same camera moved by ``offset`` (3,) (into the scene's render space)."""
        moved = copy.copy(self)
        moved.position = self.position + offset
        moved.look_at = self.look_at + offset
        return moved

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(position={self.position.tolist()}, look_at={self.look_at.tolist()}, "
                f"up={self.up.tolist()}, fov={self.fov:g}, fov_axis={self.fov_axis!r}, "
                f"resolution={self.width}x{self.height}{self._extra_repr()})")

    def _extra_repr(self) -> str:
        return ""

    @property
    def resolution(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return (self.width, self.height)

    @property
    def pixel_count(self) -> int:
        """Number of pixels."""
        return self.width * self.height

    @property
    def lens_area(self) -> float:
        """Area of the lens (1 for a pinhole, whose position is a delta)."""
        return 1.0

    # -- primary rays -----------------------------------------------------------------------------

    def _film_directions(self, pixels: np.ndarray, jitter: np.ndarray) -> np.ndarray:
        """Unnormalised directions (3, N) float32 from the lens centre through film points ``pixel + jitter``."""
        px = (pixels % self.width).astype(np.float32) + jitter[0].astype(np.float32)
        py = (pixels // self.width).astype(np.float32) + jitter[1].astype(np.float32)
        sx = (np.float32(2.0 / self.width) * px - np.float32(1.0)) * np.float32(self.tan_half[0])
        sy = (np.float32(1.0) - np.float32(2.0 / self.height) * py) * np.float32(self.tan_half[1])
        f, r, u = (v.astype(np.float32)[:, None] for v in (self.forward, self.right, self.image_up))
        return f + r * sx + u * sy

    def generate_rays(self, pixels: np.ndarray, jitter: np.ndarray, lens: np.ndarray | None = None):
        """Primary rays through the film points ``pixel + jitter`` (jitter (2, N) in [0, 1)).

        ``pixels`` are flat indices (y * width + x).  ``lens`` (2, N) uniforms
        choose the lens point (ignored by a pinhole).  Returns origins (3, N)
        and unit directions (3, N), float32; the ray weight We cos / pdf is 1.
        """
        d = self._film_directions(pixels, jitter)
        d /= np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        origins = np.broadcast_to(self.position.astype(np.float32)[:, None], d.shape)
        return origins, d

    # -- importance ------------------------------------------------------------------------------

    def cos_to_axis(self, directions: np.ndarray) -> np.ndarray:
        """cos theta between unit directions (3, N) leaving the lens and the optical axis, float64."""
        return dot(self.forward[:, None], directions.astype(np.float64))

    def pixel_of(self, raster: np.ndarray) -> np.ndarray:
        """Flat pixel indices (N,) of raster positions (2, N), clamped to the film (NaN rows give 0; callers mask
        them)."""
        x = np.clip(np.nan_to_num(raster[0]), 0, self.width - 1).astype(np.int64)
        y = np.clip(np.nan_to_num(raster[1]), 0, self.height - 1).astype(np.int64)
        return y * self.width + x

    def raster(self, points: np.ndarray, lens_points: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Raster coordinates (2, N) float64 of world points seen through lens points, and whether they are on the film.

        For a pinhole ``lens_points`` is ignored.
        """
        to_point = points.astype(np.float64) - self.position[:, None]
        depth = dot(self.forward[:, None], to_point)
        with np.errstate(divide="ignore", invalid="ignore"):
            sx = dot(self.right[:, None], to_point) / depth / self.tan_half[0]
            sy = dot(self.image_up[:, None], to_point) / depth / self.tan_half[1]
        x = (sx + 1.0) * 0.5 * self.width
        y = (1.0 - sy) * 0.5 * self.height
        inside = (depth > 0) & (x >= 0) & (x < self.width) & (y >= 0) & (y < self.height)
        return np.stack((x, y)), inside

    def importance(self, directions: np.ndarray, lens_points: np.ndarray | None = None) -> np.ndarray:
        """We = 1 / (A lens_area cos^4 theta) for unit directions leaving lens points onto the film, else 0."""
        return self.importance_of(self.cos_to_axis(directions), self._on_film(directions, lens_points))

    def importance_of(self, cos: np.ndarray, on_film: np.ndarray) -> np.ndarray:
        """We from the cosine ``cos`` (N,) between directions leaving the lens and the axis, where ``on_film``;
        else 0."""
        cos2 = cos * cos   # cos^4 as two products: NumPy's power calls libm per element, ~20x slower
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(on_film, 1.0 / (self.image_area * self.lens_area * (cos2 * cos2)), 0.0)

    def pdf_direction(self, directions: np.ndarray, lens_points: np.ndarray | None = None) -> np.ndarray:
        """Solid-angle density 1 / (A cos^3 theta) of primary-ray directions (0 off the film)."""
        cos = self.cos_to_axis(directions)
        with np.errstate(divide="ignore", invalid="ignore"):
            value = 1.0 / (self.image_area * (cos * cos * cos))
        return np.where(self._on_film(directions, lens_points), value, 0.0)

    def _on_film(self, directions: np.ndarray, lens_points: np.ndarray | None) -> np.ndarray:
        lens = self.position[:, None] if lens_points is None else lens_points.astype(np.float64)
        return self.raster(lens + directions.astype(np.float64), lens)[1]

    def intersect_lens(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where rays (3, N) hit the lens: (distance t (N,), hit mask (N,)).  A pinhole is never hit."""
        count = origins.shape[1]
        return np.full(count, np.inf), np.zeros(count, dtype=bool)

    def sample_lens(self, u: np.ndarray) -> np.ndarray:
        """Points (3, N) float64 on the lens: the pinhole itself."""
        return np.repeat(self.position[:, None], u.shape[1], axis=1)

    def sample_importance(self, receivers: np.ndarray, u: np.ndarray):
        """Connect receivers (3, N) to the camera: for light tracing's t = 1 strategy.

        Returns (wi (3, N) unit from receiver to the lens point, We (N,), pdf (N,)
        of that lens point in solid angle at the receiver, d^2 / (|cos| lens_area)
        (for a pinhole, whose "lens area" is 1, this is a delta's conversion
        factor, as in pbrt), lens points (3, N), raster positions (2, N), valid (N,)).
        The geometry is one C pass (``ext/camera.c``), bit for bit the thin lens's NumPy code with the lens
        point at the pinhole.
        """
        receivers = np.asarray(receivers)
        if receivers.dtype not in (np.float32, np.float64):
            receivers = receivers.astype(np.float64)
        wi, pdf, raster, on_film, cos = _native.pinhole_connect(
            np.ascontiguousarray(receivers), self.position, self.forward, self.right, self.image_up,
            self.tan_half[0], self.tan_half[1], self.width, self.height, self.lens_area)
        we = self.importance_of(cos, on_film)
        return wi, we, pdf, self.sample_lens(u), raster, on_film & (we > 0)


class ThinLensCamera(PinholeCamera):
    """A thin-lens camera: a disk of radius ``aperture_radius`` focused at ``focus_distance``.

    Points at the focus distance (measured along the optical axis) are sharp.
    Its lens can be sampled and hit, so its position is not a delta.
    """

    delta_position = False

    def __init__(self, position, look_at, up, fov: float, width: int, height: int, fov_axis: str = "smaller",
                 aperture_radius: float = 0.05, focus_distance: float | None = None) -> None:
        super().__init__(position, look_at, up, fov, width, height, fov_axis)
        if not (np.isfinite(aperture_radius) and aperture_radius > 0):
            raise ValueError(f"aperture_radius: expected a number > 0, got {aperture_radius!r}")
        if focus_distance is None:
            focus_distance = float(np.linalg.norm(self.look_at - self.position))
        if not (np.isfinite(focus_distance) and focus_distance > 0):
            raise ValueError(f"focus_distance: expected a number > 0, got {focus_distance!r}")
        self.lens_radius = float(aperture_radius)
        self.focus_distance = float(focus_distance)

    @classmethod
    def from_fields(cls, fields: "Fields") -> "ThinLensCamera":
        """A ``[camera]`` table of type "thinlens": the pinhole's fields, ``aperture_radius`` and optionally
        ``focus_distance`` (default: the distance to ``look_at``)."""
        view = _view(fields)
        lens = {"aperture_radius": fields.number("aperture_radius", low=0.0, low_open=True, high=MAX_COORDINATE)}
        if fields.has("focus_distance"):
            lens["focus_distance"] = fields.number("focus_distance", low=0.0, low_open=True, high=MAX_COORDINATE)
        fields.finish()
        return fields.build(lambda: cls(**view, **lens))

    def _extra_repr(self) -> str:
        return f", aperture_radius={self.lens_radius:g}, focus_distance={self.focus_distance:g}"

    @property
    def lens_area(self) -> float:
        return np.pi * self.lens_radius ** 2

    def intersect_lens(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where rays (3, N) hit the lens disk from the scene side: (distance t (N,), hit mask (N,)).

        The lens is the disk of radius ``aperture_radius`` around ``position``
        facing ``forward``; only rays travelling against ``forward`` hit it.
        """
        o = origins.astype(np.float64) - self.position[:, None]
        d = directions.astype(np.float64)
        along = dot(self.forward[:, None], d)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -dot(self.forward[:, None], o) / along
        point = o + d * t
        hit = (along < 0) & (t > 0) & (dot(point, point) <= self.lens_radius ** 2)
        return np.where(hit, t, np.inf), hit

    def sample_lens(self, u: np.ndarray) -> np.ndarray:
        """Points (3, N) float64 uniform on the lens disk (polar mapping)."""
        r = self.lens_radius * np.sqrt(u[0])
        phi = 2.0 * np.pi * u[1]
        return (self.position[:, None] + self.right[:, None] * (r * np.cos(phi))
                + self.image_up[:, None] * (r * np.sin(phi)))

    def generate_rays(self, pixels: np.ndarray, jitter: np.ndarray, lens: np.ndarray | None = None):
        """Rays from a uniform lens point toward the in-focus point of ``pixel + jitter``."""
        d = self._film_directions(pixels, jitter).astype(np.float64)  # forward component 1
        focus = self.position[:, None] + d * self.focus_distance
        origins = self.sample_lens(lens)
        directions = focus - origins
        directions /= np.sqrt(dot(directions, directions))
        return origins.astype(np.float32), directions.astype(np.float32)

    def sample_importance(self, receivers: np.ndarray, u: np.ndarray):
        """Connect receivers (3, N) to a point on the lens drawn from ``u`` (2, N); returns what
        :meth:`PinholeCamera.sample_importance` does."""
        lens = self.sample_lens(u)
        to_lens = lens - receivers.astype(np.float64)
        dist2 = dot(to_lens, to_lens)
        dist = np.sqrt(dist2)
        wi = to_lens / dist
        raster, on_film = self.raster(receivers, lens)
        cos = self.cos_to_axis(-wi)
        we = self.importance_of(cos, on_film)
        with np.errstate(divide="ignore", invalid="ignore"):
            pdf = dist2 / (np.abs(cos) * self.lens_area)
        return wi, we, pdf, lens, raster, on_film & (we > 0)

    def raster(self, points: np.ndarray, lens_points: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Raster position of the film point whose rays through ``lens_points`` reach ``points``."""
        p = points.astype(np.float64)
        lens = self.position[:, None] if lens_points is None else lens_points.astype(np.float64)
        d = p - lens
        with np.errstate(divide="ignore", invalid="ignore"):
            focus = lens + d * (self.focus_distance / dot(self.forward[:, None], d))
        raster, inside = super().raster(focus)
        return raster, inside & (dot(self.forward[:, None], d) > 0)


CAMERAS = {"pinhole": PinholeCamera, "thinlens": ThinLensCamera}
