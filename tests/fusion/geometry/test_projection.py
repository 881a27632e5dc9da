"""Z-buffered projection (thesis eq. 5.7-5.9) and depth<->disparity on hand-computed cases."""
import numpy as np
import pytest

from fusion.geometry.camera import Camera, look_at
from fusion.geometry.disparity import DisparityError, depth_to_disparity, disparity_to_depth
from fusion.geometry.projection import ProjectionError, project_depth, project_points, reproject_depth

K = np.array([[100.0, 0.0, 31.5], [0.0, 100.0, 23.5], [0.0, 0.0, 1.0]])


def cam(T=None, w=64, h=48) -> Camera:
    return Camera(K, np.eye(4) if T is None else T, w, h)


def test_hand_computed_pixel_and_depth():
    # (0.1, -0.05, 2): u = 100*0.05 + 31.5 = 36.5 -> rounds to 37 (floor(x + 0.5)); v = -2.5 + 23.5 = 21
    d = project_depth(cam(), np.array([[0.1, -0.05, 2.0]]))
    assert d[21, 37] == pytest.approx(2.0)
    assert (d > 0).sum() == 1
    assert np.all(d[d != d[21, 37]] == -1.0)


def test_rounds_to_nearest_pixel_centre():
    z = 1.0
    pts = np.array([[(u - 31.5) / 100 * z, 0.0, z] for u in (10.49, 20.51, -0.49, 63.49)])
    d = project_depth(cam(), pts)
    assert not (d[23] > 0).any()  # y = 0 -> v = cy = 23.5 -> floor(24.0) = row 24
    cols = np.flatnonzero(d[24] > 0)
    np.testing.assert_array_equal(cols, [0, 10, 21, 63])


def test_nearest_depth_wins_whatever_the_order():
    near, far = np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 3.0])  # same ray -> same pixel
    for pts in (np.stack([near, far]), np.stack([far, near]), np.stack([far, near, far * 2])):
        proj = project_points(cam(), pts, {"id": np.arange(len(pts), dtype=float)})
        assert proj.depth[24, 32] == pytest.approx(1.0)
        assert proj.filled.sum() == 1
        winner = int(proj.index[24, 32])
        np.testing.assert_allclose(pts[winner], near)
        assert proj.values["id"][24, 32] == winner


def test_many_points_zbuffer_matches_bruteforce():
    rng = np.random.default_rng(0)
    pts = rng.uniform([-0.5, -0.4, 0.5], [0.5, 0.4, 3.0], size=(5000, 3))
    d = project_depth(cam(), pts)
    uv = pts[:, :2] / pts[:, 2:3] * 100 + K[:2, 2]
    col, row = np.floor(uv[:, 0] + 0.5).astype(int), np.floor(uv[:, 1] + 0.5).astype(int)
    ok = (col >= 0) & (col < 64) & (row >= 0) & (row < 48)
    ref = np.full((48, 64), np.inf)
    for r, c, z in zip(row[ok], col[ok], pts[ok, 2]):
        ref[r, c] = min(ref[r, c], z)
    ref[np.isinf(ref)] = -1
    np.testing.assert_allclose(d, ref, rtol=1e-6)


def test_behind_camera_and_nan_points_are_ignored():
    d = project_depth(cam(), np.array([[0.0, 0.0, -1.0], [np.nan, 0, 1], [0.0, 0.0, 0.0]]))
    assert np.all(d == -1)


def test_posed_camera_depth_is_planar_z():
    T = look_at(np.array([0.3, -0.2, 2.0]), np.zeros(3), np.array([0.0, -1.0, 0.0]))
    c = cam(T)
    pts = np.array([[0.05, 0.02, 0.0]])
    d = project_depth(c, pts)
    r, col = np.argwhere(d > 0)[0]
    assert d[r, col] == pytest.approx(c.to_camera(pts)[0, 2], rel=1e-6)


def test_reproject_depth_roundtrip_same_camera():
    T = look_at(np.array([0.0, 0.0, 1.5]), np.zeros(3), np.array([0.0, -1.0, 0.0]))
    c = cam(T)
    depth = np.full((48, 64), 1.5, np.float32)
    depth[:5] = -1
    out = reproject_depth(c, depth, c)
    np.testing.assert_allclose(out, depth, atol=1e-6)


def test_bad_shapes_raise_clear_errors():
    with pytest.raises(ProjectionError, match="points_world"):
        project_points(cam(), np.zeros((3, 2)))
    with pytest.raises(ProjectionError, match="values\\['a'\\]"):
        project_points(cam(), np.zeros((3, 3)), {"a": np.zeros(2)})


def test_disparity_depth_roundtrip_and_invalid():
    depth = np.array([[1.0, 2.0, -1.0, 0.0, np.inf, np.nan]], np.float32)
    disp = depth_to_disparity(depth, 500.0, 0.1)
    np.testing.assert_allclose(disp[0, :2], [50.0, 25.0])
    assert np.all(disp[0, 2:] == -1)
    back = disparity_to_depth(disp, 500.0, 0.1)
    np.testing.assert_allclose(back[0, :2], [1.0, 2.0], rtol=1e-6)
    assert np.all(back[0, 2:] == -1)
    assert disparity_to_depth(np.array([10.0]), 500.0, 0.1, doffs_px=40.0)[0] == pytest.approx(1.0)
    with pytest.raises(DisparityError, match="baseline_m"):
        depth_to_disparity(depth, 500.0, 0.0)
