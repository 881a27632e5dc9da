"""fusion.measure.metric_size: a crack on a tilted plane seen by a pinhole camera, measured in metres."""

import json

import numpy as np
import pytest

from fusion.measure.metric_size import MetricSizeError, load_intrinsics, measure_in_view, surface_depth, surface_points

W, H, F = 400, 300, 450.0
K = np.array([[F, 0, W / 2 - 0.5], [0, F, H / 2 - 0.5], [0, 0, 1.0]])


def _plane_view(tilt_deg: float, dist: float = 1.0):
    """Depth of the plane through (0, 0, dist) with normal tilted by tilt_deg about the camera x axis,
    and the 3-D point seen at every pixel."""
    t = np.deg2rad(tilt_deg)
    n = np.array([0.0, np.sin(t), np.cos(t)])
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    rays = np.stack([(u - K[0, 2]) / F, (v - K[1, 2]) / F, np.ones_like(u)], axis=-1)
    z = (n @ np.array([0, 0, dist])) / (rays @ n)
    return z, rays * z[..., None], n


def test_surface_depth_fills_holes_exactly_on_a_plane():
    z, _, _ = _plane_view(40.0)
    crack = np.zeros(z.shape, bool)
    crack[140:150, 30:370] = True
    deep = np.where(crack, z + 0.02, z)  # the crack floor is 2 cm deeper
    assert np.abs(surface_depth(deep, crack) - z).max() < 1e-9
    rng = np.random.default_rng(0)
    sparse = np.where(rng.random(z.shape) < 0.02, z, -1.0)  # LiDAR-like: 2 % of the pixels
    assert np.abs(surface_depth(sparse) - z).max() < 1e-9


@pytest.mark.parametrize("tilt_deg", [0.0, 35.0, 60.0])
def test_crack_on_tilted_plane_metric_length(tilt_deg):
    z, pts, n = _plane_view(tilt_deg)
    # A straight crack on the plane, 8 mm wide: the pixels whose surface point is within 4 mm of
    # the 3-D segment (flat ends), measured against the segment's 3-D length.
    a = np.array([-0.25, 0.0, 0.0])
    a += np.array([0, 0, 1.0]) - a @ n * 0  # on the plane through (0, 0, 1)
    p0 = np.array([-0.25, -0.05, 0.0])
    p1 = np.array([0.22, 0.12, 0.0])
    for p in (p0, p1):  # lift onto the plane n . X = n . (0, 0, 1)
        p[2] = (n[2] - n[1] * p[1]) / n[2]
    d = p1 - p0
    L = np.linalg.norm(d)
    rel = pts - p0
    t = rel @ d / L
    dist = np.linalg.norm(rel - t[..., None] * d / L, axis=-1)
    mask = (t >= 0) & (t <= L) & (dist <= 0.004)
    depth = np.where(mask, z + 0.01, z)  # the crack floor is deeper: must not matter
    r = measure_in_view(mask, depth, K)
    assert len(r.components) == 1
    assert r.longest_path == pytest.approx(L, rel=0.02)
    assert r.mean_width == pytest.approx(0.008, rel=0.12)
    assert r.max_width == pytest.approx(0.008, rel=0.25)


def test_surface_points_pinhole():
    z, pts, _ = _plane_view(20.0)
    np.testing.assert_allclose(surface_points(z, K), pts, atol=1e-12)


def test_intrinsics_files(tmp_path):
    p = tmp_path / "K.json"
    p.write_text(json.dumps({"fx": 500, "fy": 510, "cx": 320, "cy": 240}))
    np.testing.assert_allclose(load_intrinsics(p), [[500, 0, 320], [0, 510, 240], [0, 0, 1]])
    p.write_text(json.dumps({"K": K.tolist()}))
    np.testing.assert_allclose(load_intrinsics(p), K)
    p.write_text(json.dumps({"fx": 500, "cx": 320}))
    with pytest.raises(MetricSizeError, match="missing fy, cy"):
        load_intrinsics(p)
    with pytest.raises(MetricSizeError, match="does not exist"):
        load_intrinsics(tmp_path / "nope.json")
    with pytest.raises(MetricSizeError, match="no valid pixel"):
        surface_depth(-np.ones((4, 4)))
