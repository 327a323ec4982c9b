"""Cameras: direction density (chi-square), importance normalisation, raster projection, thin lens, and the
conventions (orientation, field of view, which side of the image the Cornell box's red wall is on)."""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace.camera import PinholeCamera, ThinLensCamera
from pathspace.validate import chi2_test_directions

CAMERAS = {
    "pinhole": PinholeCamera([0, 0, 0], [0, 0, 1], [0, 1, 0], 60.0, 40, 30),
    "thinlens": ThinLensCamera([0, 0, 0], [0, 0, 1], [0, 1, 0], 60.0, 40, 30, aperture_radius=0.2,
                               focus_distance=3.0),
}


@pytest.mark.parametrize("name", CAMERAS)
def test_primary_ray_directions_follow_pdf_direction(name):
    """Rays through uniform film points leave a lens point (the pinhole, or a fixed point on the thin
    lens) with density pdf_direction (1 / (A cos^3 theta) for the pinhole)."""
    camera = CAMERAS[name]
    lens_u = np.array([[0.3], [0.8]])
    lens_point = camera.generate_rays(np.array([0]), np.full((2, 1), 0.5), lens_u)[0].astype(np.float64)

    def sample(u):
        count = u.shape[1]
        pixels = np.minimum((u[0] * camera.pixel_count).astype(np.int64), camera.pixel_count - 1)
        _, d = camera.generate_rays(pixels, u[1:3], np.repeat(lens_u, count, axis=1))
        return d, np.ones(count, bool)

    def pdf(d):
        return camera.pdf_direction(d, np.repeat(lens_point, d.shape[1], axis=1))

    result = chi2_test_directions(sample, pdf, sample_count=400_000, dims=3, res_z=200, res_phi=100)
    assert result.passed, str(result)


@pytest.mark.parametrize("name", CAMERAS)
def test_importance_over_sampling_density_is_one(name):
    """We cos / (p_position p_direction) = 1 for every primary ray: importance and pdfs agree."""
    camera = CAMERAS[name]
    rng = np.random.default_rng(0)
    pixels = rng.integers(0, camera.pixel_count, 1000)
    origins, directions = camera.generate_rays(pixels, rng.random((2, 1000)), rng.random((2, 1000)))
    lens = origins.astype(np.float64)
    we = camera.importance(directions, lens)
    cos = camera.cos_to_axis(directions)
    pdf_pos = 1.0 / camera.lens_area
    np.testing.assert_allclose(we * cos / (pdf_pos * camera.pdf_direction(directions, lens)), 1.0, rtol=1e-9)


@pytest.mark.parametrize("name", CAMERAS)
def test_importance_integrates_to_one_over_lens_area(name):
    """The normalisation of We, independently of the camera's own sampling: over directions drawn
    uniformly on the sphere, the integral of We cos at a lens point is 1 / lens_area (pbrt-v4's
    convention: We cos integrates to 1 over lens area and solid angle)."""
    camera = CAMERAS[name]
    rng = np.random.default_rng(5)
    count = 2_000_000
    d = rng.standard_normal((3, count))
    d /= np.linalg.norm(d, axis=0)
    lens = camera.sample_lens(rng.random((2, count)))
    lens_area = np.pi * 0.2 ** 2 if name == "thinlens" else 1.0  # a pinhole's "area" is 1 by convention
    f = camera.importance(d, lens) * np.maximum(camera.cos_to_axis(d), 0.0) * 4 * np.pi * lens_area
    mean, error = f.mean(), f.std() / np.sqrt(count)
    assert abs(mean - 1.0) < 4 * error and error < 0.01, (mean, error)


@pytest.mark.parametrize("name", CAMERAS)
def test_raster_inverts_ray_generation(name):
    camera = CAMERAS[name]
    rng = np.random.default_rng(1)
    pixels = rng.integers(0, camera.pixel_count, 500)
    jitter = rng.random((2, 500))
    origins, directions = camera.generate_rays(pixels, jitter, rng.random((2, 500)))
    points = origins.astype(np.float64) + directions.astype(np.float64) * rng.uniform(1, 10, 500)
    raster, inside = camera.raster(points, origins.astype(np.float64))
    assert inside.all()
    expected = np.stack((pixels % camera.width + jitter[0], pixels // camera.width + jitter[1]))
    np.testing.assert_allclose(raster, expected, atol=2e-4)


def test_thin_lens_focus():
    """Every lens point sends a pixel's rays through one point on the focus plane (so it is sharp there)."""
    camera = CAMERAS["thinlens"]
    rng = np.random.default_rng(2)
    pixels = np.full(200, 17 * 40 + 9)
    jitter = np.full((2, 200), 0.5)
    origins, directions = camera.generate_rays(pixels, jitter, rng.random((2, 200)))
    t = (3.0 - origins[2]) / directions[2]
    focus = origins + directions * t
    assert np.ptp(focus[0]) < 1e-5 and np.ptp(focus[1]) < 1e-5
    assert np.ptp(origins[0]) > 0.1  # the lens points are spread over the aperture


def test_sample_importance_connects_to_the_lens():
    camera = CAMERAS["thinlens"]
    rng = np.random.default_rng(3)
    receivers = np.stack((rng.uniform(-1, 1, 300), rng.uniform(-1, 1, 300), rng.uniform(2, 6, 300)))
    wi, we, pdf, lens, raster, valid = camera.sample_importance(receivers, rng.random((2, 300)))
    assert valid.mean() > 0.5
    # wi points from the receiver to the lens point; the lens point lies on the lens disk.
    np.testing.assert_allclose(receivers + wi * np.linalg.norm(lens - receivers, axis=0), lens, atol=1e-9)
    assert np.all(np.hypot(lens[0], lens[1]) <= 0.2 + 1e-12) and np.allclose(lens[2], 0.0)
    # The pdf converts the lens area density to solid angle at the receiver: d^2 / (cos A_lens).
    d2 = np.sum((lens - receivers) ** 2, axis=0)
    np.testing.assert_allclose(pdf, d2 / (np.abs(camera.cos_to_axis(-wi)) * camera.lens_area))


def test_rays_can_hit_the_thin_lens_but_not_the_pinhole():
    """Rays from scene points toward sampled lens points hit the lens at that point; a pinhole is never hit."""
    camera = CAMERAS["thinlens"]
    rng = np.random.default_rng(4)
    receivers = np.stack((rng.uniform(-1, 1, 200), rng.uniform(-1, 1, 200), rng.uniform(2, 6, 200)))
    lens = camera.sample_lens(rng.random((2, 200)))
    direction = (lens - receivers) / np.linalg.norm(lens - receivers, axis=0)
    t, hit = camera.intersect_lens(receivers, direction)
    assert hit.all()
    np.testing.assert_allclose(receivers + direction * t, lens, atol=1e-9)
    # Rays travelling away from the scene, or passing beside the aperture, miss.
    assert not camera.intersect_lens(receivers, -direction)[1].any()
    beside = lens + np.array([[0.5], [0.0], [0.0]])
    miss_dir = (beside - receivers) / np.linalg.norm(beside - receivers, axis=0)
    assert not camera.intersect_lens(receivers, miss_dir)[1].any()
    assert not CAMERAS["pinhole"].intersect_lens(receivers, direction)[1].any()



def test_camera_orientation_and_fov():
    cam = PinholeCamera([0, 0, 3.9], [0, 0, 0], [0, 1, 0], 40.0, 200, 100, fov_axis="x")
    centre = np.array([50 * 200 + 100])  # pixel (x=100, y=50): its top-left corner is the image centre
    _, d = cam.generate_rays(centre, np.zeros((2, 1)))
    np.testing.assert_allclose(d[:, 0], [0, 0, -1], atol=1e-7)
    # Left edge of the image looks toward -x at half the horizontal fov; top edge toward +y.
    _, left = cam.generate_rays(np.array([50 * 200]), np.array([[0.0], [0.0]]))
    np.testing.assert_allclose(np.degrees(np.arctan2(-left[0, 0], -left[2, 0])), 20.0, rtol=1e-5)
    _, top = cam.generate_rays(np.array([100]), np.zeros((2, 1)))
    assert top[1, 0] > 0
    # fov_axis = "y" puts the angle on the vertical axis; "smaller" picks y for a wide image.
    tall = PinholeCamera([0, 0, 3.9], [0, 0, 0], [0, 1, 0], 40.0, 200, 100, fov_axis="smaller")
    _, up = tall.generate_rays(np.array([100]), np.zeros((2, 1)))
    np.testing.assert_allclose(np.degrees(np.arctan2(up[1, 0], -up[2, 0])), 20.0, rtol=1e-5)


def test_cornell_box_image_orientation(cornell_small):
    """The red wall (world -x) appears on the left of the image, the green one on the right."""
    image = ps.render(cornell_small, spp=4, seed=1, max_depth=2).image
    left, right = image[32, 2], image[32, -3]
    assert left[0] > 2 * left[1] and right[1] > 2 * right[0]

