"""Camera and ray maths against hand-computed values (OpenGL c2w axes, as Blender and nerfstudio)."""
import numpy as np

from snapshot3d.cameras import focal_from_fov, look_at, orbit_poses, pixel_rays, project


def test_identity_camera_looks_down_minus_z():
    o, d = pixel_rays(np.eye(4), fx=2.0, fy=2.0, cx=1.0, cy=1.0, width=2, height=2)
    # pixel (0, 0) centre is (0.5, 0.5): x = (0.5 - 1) / 2 = -0.25 (left), y = +0.25 (up, rows go down)
    expect = np.array([-0.25, 0.25, -1.0]) / np.linalg.norm([-0.25, 0.25, -1.0])
    np.testing.assert_allclose(d[0], expect, atol=1e-6)
    np.testing.assert_allclose(d[3], expect * [-1, -1, 1], atol=1e-6)  # pixel (1, 1): right, down
    assert np.all(o == 0)


def test_look_at_builds_opengl_axes():
    c2w = look_at([0.0, -3.0, 0.0], [0.0, 0.0, 0.0], up=(0, 0, 1))
    np.testing.assert_allclose(c2w[:3, 2], [0, -1, 0], atol=1e-12)  # +z points back, away from the target
    np.testing.assert_allclose(c2w[:3, 1], [0, 0, 1], atol=1e-12)   # y up
    np.testing.assert_allclose(c2w[:3, 0], [1, 0, 0], atol=1e-12)   # x right
    np.testing.assert_allclose(c2w[:3, 3], [0, -3, 0])


def test_projection_inverts_pixel_rays():
    c2w = look_at([1.0, -2.5, 1.2], [0.1, 0.0, 0.2])
    fx, fy, cx, cy, w, h = 50.0, 55.0, 31.0, 22.0, 64, 48
    o, d = pixel_rays(c2w, fx, fy, cx, cy, w, h)
    pts = o + 2.0 * d
    uv, depth = project(pts, c2w, fx, fy, cx, cy)
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    np.testing.assert_allclose(uv, np.stack([u.ravel(), v.ravel()], -1), atol=1e-3)
    assert np.all(depth > 0)


def test_focal_from_fov_and_orbit():
    assert abs(focal_from_fov(np.deg2rad(90.0), 200) - 100.0) < 1e-9
    poses = orbit_poses(4, radius=2.0, elevation_deg=30.0)
    np.testing.assert_allclose(np.linalg.norm(poses[:, :3, 3], axis=1), 2.0)
    np.testing.assert_allclose(poses[:, 2, 3], 2.0 * np.sin(np.deg2rad(30)))
    # every camera looks at the origin: -z axis is parallel to -position
    fwd = -poses[:, :3, 2]
    np.testing.assert_allclose(fwd, -poses[:, :3, 3] / 2.0, atol=1e-12)
    np.testing.assert_allclose(poses[0, :3, 3], [2 * np.cos(np.deg2rad(30)), 0, 1.0], atol=1e-12)
