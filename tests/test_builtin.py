"""Built-in scenes: framing, silhouettes against `cameras.project`, shading, loading and errors."""
import numpy as np
import pytest
import trimesh

from snapshot3d import builtin
from snapshot3d.builtin import builtin_scene, load_mesh, render_mesh, shared_data_dir
from snapshot3d.cameras import look_at, project
from snapshot3d.errors import UserError


def _needs_shared():
    if shared_data_dir() is None:
        pytest.skip("../shared/data is absent (a user's checkout): the shared meshes are not available")


@pytest.fixture(scope="module")
def procedural():
    return builtin_scene("procedural", n_train=6, n_test=2, size=64, seed=0)


def test_procedural_scene_is_white_framed_and_covered(procedural):
    s = procedural
    assert s.images.shape == (8, 64, 64, 3) and s.images.dtype == np.float32
    assert s.alpha.shape == (8, 64, 64) and s.c2w.dtype == np.float32 and s.box.dtype == np.float32
    assert 0.0 <= s.images.min() and s.images.max() <= 1.0 and 0.0 <= s.alpha.min() and s.alpha.max() <= 1.0
    corners = s.images[:, [0, 0, -1, -1], [0, -1, 0, -1]]
    assert np.all(corners == 1.0) and np.all(s.alpha[:, [0, 0, -1, -1], [0, -1, 0, -1]] == 0.0)
    centre = s.alpha[:, 24:40, 24:40]  # some views look through the torus, between the objects
    assert np.all(centre.mean(axis=(1, 2)) > 0.4) and np.all(centre.max(axis=(1, 2)) == 1.0)
    assert np.all(s.images[:, 24:40, 24:40][centre == 1.0].min(axis=-1) < 0.95)  # shaded, not background
    assert sorted(np.concatenate([s.train, s.test]).tolist()) == list(range(8)) and len(s.test) == 2
    assert {"radius", "fov_x_deg", "renderer"} <= set(s.info)


def test_orbit_frames_the_object_and_keeps_test_poses_apart(procedural):
    s = procedural
    eyes = s.c2w[:, :3, 3]
    np.testing.assert_allclose(np.linalg.norm(eyes, axis=1), s.info["radius"], rtol=1e-5)
    mesh = load_mesh("procedural")
    fills = []
    for c2w, (fx, fy, cx, cy) in zip(s.c2w.astype(np.float64), s.intrinsics):
        uv, depth = project(mesh.vertices, c2w, fx, fy, cx, cy)
        assert depth.min() > 0
        fills.append(np.abs(uv - (cx, cy)).max() / cx)
    assert 0.84 < max(fills) < 0.86 and min(fills) > 0.5
    gaps = np.linalg.norm(eyes[s.test][:, None] - eyes[s.train][None], axis=-1)
    assert gaps.min() > 0.05 * s.info["radius"]
    np.testing.assert_allclose(s.box[0], mesh.bounds[0] - 0.03 * mesh.extents, atol=1e-6)


def test_scene_is_deterministic_per_seed():
    a = builtin_scene("procedural", n_train=2, n_test=1, size=24, seed=3)
    b = builtin_scene("procedural", n_train=2, n_test=1, size=24, seed=3)
    c = builtin_scene("procedural", n_train=2, n_test=1, size=24, seed=4)
    assert np.array_equal(a.images, b.images) and np.array_equal(a.c2w, b.c2w)
    assert not np.allclose(a.c2w, c.c2w)


@pytest.mark.parametrize("azimuth, elevation", [(30.0, 20.0), (200.0, -10.0)])
def test_silhouette_lines_up_with_projected_vertices(azimuth, elevation):
    # Off-centre principal point, fx != fy and a non-square image exercise the fovY-only OpenCV camera.
    mesh = load_mesh("procedural")
    width, height = 96, 72
    a, e = np.deg2rad([azimuth, elevation])
    c2w = look_at(4.5 * np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)]), np.zeros(3))
    intr = np.array([70.0, 62.0, 50.5, 33.0])
    _, alpha = render_mesh(mesh, c2w[None], intr[None], width, height)
    uv, _ = project(mesh.vertices, c2w, *intr)
    vs, us = np.nonzero(alpha[0] > 0.5)
    rendered = np.array([us.min(), vs.min(), us.max() + 1, vs.max() + 1], dtype=float)
    expected = np.concatenate([uv.min(axis=0), uv.max(axis=0)])
    assert np.abs(rendered - expected).max() < 1.5, (rendered, expected)


def test_shading_does_not_depend_on_the_view():
    # A flat, uniformly coloured square seen from two very different directions has one colour.
    quad = trimesh.Trimesh([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], [[0, 1, 2], [0, 2, 3]], process=False)
    quad.visual.vertex_colors = np.tile([200, 120, 60, 255], (4, 1))
    c2w = np.stack([look_at(np.array(eye), np.zeros(3)) for eye in ([3.0, 0.5, 2.0], [-0.5, -1.0, 4.0])])
    intr = np.tile([60.0, 60.0, 32.0, 32.0], (2, 1))
    images, alpha = render_mesh(quad, c2w, intr, 64, 64)
    inner = [im[a == 1.0] for im, a in zip(images, alpha)]
    assert all(len(x) > 200 for x in inner)
    colours = np.stack([x.mean(axis=0) for x in inner])
    assert max(x.std(axis=0).max() for x in inner) < 1e-3
    np.testing.assert_allclose(colours[0], colours[1], atol=2e-3)
    assert np.all(colours[0] < np.array([200, 120, 60]) / 255 + 1e-3) and colours[0, 0] > 0.3


def test_unknown_name_is_a_one_line_user_error():
    with pytest.raises(UserError) as err:
        load_mesh("teapotz")
    assert "\n" not in str(err.value) and "procedural" in str(err.value) and "teapotz" in str(err.value)
    with pytest.raises(UserError):
        builtin_scene("nope")


def test_missing_shared_mesh_names_the_path(monkeypatch, tmp_path):
    monkeypatch.setenv("SNAPSHOT3D_SHARED_DATA", str(tmp_path))
    assert shared_data_dir() == tmp_path
    with pytest.raises(UserError) as err:
        load_mesh("spot")
    msg = str(err.value)
    assert "\n" not in msg and "shared/data/meshes/spot" in msg and "builtin:procedural ships" in msg
    monkeypatch.setenv("SNAPSHOT3D_SHARED_DATA", str(tmp_path / "absent"))
    assert shared_data_dir() is None


def test_all_builtin_names_are_known():
    assert builtin.BUILTIN_NAMES[0] == "procedural"
    assert set(builtin.BUILTIN_NAMES[1:]) == set(builtin._FILES)


@pytest.mark.parametrize("name", ["spot", "duck", "teapot", "suzanne"])
def test_shared_meshes_are_normalised(name):
    _needs_shared()
    mesh = load_mesh(name)
    np.testing.assert_allclose(mesh.bounds.mean(axis=0), 0.0, atol=1e-9)
    assert abs(mesh.extents.max() - 2.0) < 1e-9
    assert mesh.visual.kind == ("texture" if name in ("spot", "duck") else "vertex")


def test_spot_is_upright_and_textured():
    _needs_shared()
    mesh = load_mesh("spot")
    v = mesh.vertices
    top, bottom = v[v[:, 2] > np.quantile(v[:, 2], 0.97)], v[v[:, 2] < np.quantile(v[:, 2], 0.03)]
    assert top[:, 1].mean() > 0.3  # the horns (highest points) sit on the head, at +y
    assert np.abs(bottom[:, 0]).mean() > 0.15  # the lowest points are the hooves, off the midline
    s = builtin_scene("spot", n_train=2, n_test=1, size=64)
    inside = s.images[s.alpha == 1.0]
    luma = inside.mean(axis=1)
    # Black patches on a white cow: an untextured albedo of 0.9 never shades below 0.9 * AMBIENT ~ 0.29.
    assert (luma < 0.2).mean() > 0.02 and (luma > 0.5).mean() > 0.2
