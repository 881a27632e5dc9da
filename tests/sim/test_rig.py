"""Rig geometry: look-at, stereo baseline sign, mounted sensors, meta roundtrip."""
import numpy as np
import pytest

from crackgen.config.recipe import Recipe
from crackgen.config.spec import make_spec
from crackgen.sim.rig import make_rig
from fusion.geometry.camera import Camera, invert_pose


@pytest.fixture
def spec():
    r = Recipe.model_validate({"stereo": {"enabled": True}})
    return make_spec(r, 5)


def test_target_projects_to_principal_point(spec):
    cam = make_rig(spec).rgb
    target = np.array([[spec.camera.target_x_m, spec.camera.target_y_m, 0.0]])
    uv, z = cam.project(target)
    np.testing.assert_allclose(uv[0], cam.K[:2, 2], atol=1e-9)
    assert z[0] == pytest.approx(spec.camera.distance_m)


def test_rotation_is_proper_and_distance_matches(spec):
    cam = make_rig(spec).rgb
    R = cam.R
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    assert cam.center[2] > 0  # above the surface
    np.testing.assert_allclose(invert_pose(cam.T_world_cam), cam.T_cam_world, atol=1e-12)


def test_stereo_disparity_is_f_b_over_z(spec):
    rig = make_rig(spec)
    pts = np.array([[0.1, -0.2, 0.0], [0.0, 0.05, -0.01]])
    uvl, zl = rig.rgb.project(pts)
    uvr, zr = rig.right.project(pts)
    np.testing.assert_allclose(zl, zr, atol=1e-12)
    np.testing.assert_allclose(uvl[:, 0] - uvr[:, 0], rig.rgb.fx * spec.camera.baseline_m / zl, rtol=1e-9)
    np.testing.assert_allclose(uvl[:, 1], uvr[:, 1], atol=1e-9)


def test_tof_sits_at_offset_in_rgb_frame(spec):
    rig = make_rig(spec)
    c_rgb_frame = rig.rgb.to_camera(rig.tof.center[None])[0]
    np.testing.assert_allclose(c_rgb_frame, spec.tof.offset_m, atol=1e-12)


def test_backproject_inverts_project(spec):
    cam = make_rig(spec).rgb
    depth = np.full((cam.height, cam.width), 0.8, np.float32)
    depth[0, 0] = -1
    pts = cam.backproject(depth)
    assert np.isnan(pts[0, 0]).all()
    uv, z = cam.project(pts[5:7, 10:12].reshape(-1, 3))
    np.testing.assert_allclose(z, 0.8, rtol=1e-6)
    np.testing.assert_allclose(uv, [[10, 5], [11, 5], [10, 6], [11, 6]], atol=1e-6)


def test_meta_roundtrip(spec):
    cam = make_rig(spec).rgb
    back = Camera.from_meta(cam.to_meta())
    np.testing.assert_array_equal(back.K, cam.K)
    np.testing.assert_array_equal(back.T_cam_world, cam.T_cam_world)
