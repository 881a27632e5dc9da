"""Ray-cast GT: depth on a plane matches the analytic depth; the mask follows the hit UVs."""
import numpy as np
import pytest

from crackgen.sim.groundtruth import mask_lookup, view_ground_truth
from crackgen.sim.raycast import MeshRaycaster
from fusion.geometry.camera import Camera, intrinsics_from_focal, look_at


def grid_plane(size_m: float, g: int, z=None):
    x = np.linspace(-size_m / 2, size_m / 2, g)
    X, Y = np.meshgrid(x, x)
    Z = np.zeros_like(X) if z is None else z(X, Y)
    verts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], 1)
    i = np.arange(g - 1)
    I, J = np.meshgrid(i, i)
    a = (J * g + I).ravel()
    faces = np.concatenate([np.stack([a, a + 1, a + g + 1], 1), np.stack([a, a + g + 1, a + g], 1)])
    u = np.linspace(0, 1, g)
    U, V = np.meshgrid(u, u)
    return verts, faces, np.stack([U.ravel(), V.ravel()], 1)


def tilted_camera(w=80, h=60):
    eye = np.array([0.2, -0.3, 1.0])
    T = look_at(eye, np.array([0.0, 0.0, 0.0]), np.array([0.0, -1.0, 0.0]), roll_rad=0.1)
    return Camera(intrinsics_from_focal(30, 36, w, h, 1.5, -2.0), T, w, h)


def test_plane_depth_matches_analytic():
    verts, faces, uvs = grid_plane(4.0, 9)
    cam = tilted_camera()
    gt = view_ground_truth(cam, MeshRaycaster(verts, faces, uvs), np.zeros((8, 8), bool))
    # analytic: ray through pixel p: X = C + s*d_world (d_cam has z=1, so s = planar depth)
    d_cam = cam.pixel_directions()
    d_world = d_cam @ cam.R
    s = -cam.center[2] / d_world[:, 2]
    np.testing.assert_allclose(gt.depth.ravel(), s, atol=2e-6)
    assert (gt.mask == 0).all()


def test_mask_pixels_hit_crack_texels_only():
    size = 2.0
    verts, faces, uvs = grid_plane(size, 17)
    crack = np.zeros((40, 40), bool)
    crack[18:22, 5:35] = True  # a horizontal bar in texel space
    cam = tilted_camera(120, 90)
    gt = view_ground_truth(cam, MeshRaycaster(verts, faces, uvs), crack)
    pts = cam.backproject(gt.depth)
    on = gt.mask == 255
    assert on.sum() > 20
    # world point -> texel, must be a crack texel (up to float rounding at texel borders)
    i = np.floor((pts[..., 0] / size + 0.5) * 40).astype(int)
    j = np.floor((pts[..., 1] / size + 0.5) * 40).astype(int)
    inside = crack[np.clip(j, 0, 39), np.clip(i, 0, 39)]
    agree = (inside == on)[np.isfinite(pts[..., 0])]
    assert agree.mean() > 0.995
    # the projection of the bar's centre lands on a crack pixel
    centre = np.array([[((5 + 35) / 2 / 40 - 0.5) * size, (20 / 40 - 0.5) * size, 0.0]])
    uv, _ = cam.project(centre)
    u, v = np.round(uv[0]).astype(int)
    assert gt.mask[v, u] == 255


def test_misses_are_minus_one_and_not_crack():
    verts, faces, uvs = grid_plane(0.2, 5)  # small patch: most rays miss
    cam = tilted_camera()
    gt = view_ground_truth(cam, MeshRaycaster(verts, faces, uvs), np.ones((4, 4), bool))
    miss = gt.depth == -1
    assert miss.any() and (~miss).any()
    assert (gt.mask[miss] == 0).all() and (gt.mask[~miss] == 255).all()


def test_mask_lookup_texel_edges():
    m = np.zeros((4, 4), bool)
    m[1, 2] = True
    uv = np.array([[2 / 4 + 1e-9, 1 / 4 + 1e-9], [2 / 4 - 1e-9, 1 / 4 + 1e-9], [np.nan, np.nan], [1.0, 1.0]])
    assert mask_lookup(m, uv).tolist() == [True, False, False, False]


def test_bad_uv_shape_is_refused():
    verts, faces, uvs = grid_plane(1.0, 3)
    with pytest.raises(ValueError, match="uvs must be"):
        MeshRaycaster(verts, faces, uvs[:-1])
