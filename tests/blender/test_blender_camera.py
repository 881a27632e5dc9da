"""The OpenCV -> Blender camera conversion, checked against bpy's own projection matrix."""
import math

import numpy as np
import pytest

from crackgen.blender.camera import CameraConversionError, blender_camera_params
from fusion.geometry.camera import Camera, intrinsics_from_focal, look_at


def cam(w=96, h=64, cx=3.3, cy=-2.6, roll=0.3) -> Camera:
    K = intrinsics_from_focal(30.0, 36.0, w, h, cx, cy)
    T = look_at(np.array([0.3, -0.2, 0.8]), np.array([0.05, 0.02, 0.0]), np.array([0.0, 1.0, 0.0]), roll)
    return Camera(K, T, w, h)


def test_pose_is_opencv_axes_flipped():
    c = cam()
    p = blender_camera_params(c)
    R = p.matrix_world[:3, :3]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(p.matrix_world[:3, 3], c.center, atol=1e-12)
    # Blender looks down its -z: that is the OpenCV +z (optical axis) in world coordinates
    np.testing.assert_allclose(-R[:, 2], c.R[2], atol=1e-12)
    np.testing.assert_allclose(R[:, 1], -c.R[1], atol=1e-12)  # Blender +y (up) = OpenCV -y


def test_lens_from_fx():
    p = blender_camera_params(cam())
    assert p.lens_mm / p.sensor_width_mm * 96 == pytest.approx(cam().fx)


def test_refuses_skew_and_non_square_pixels():
    c = cam()
    K = c.K.copy()
    K[0, 1] = 2.0
    with pytest.raises(CameraConversionError, match="skew"):
        blender_camera_params(Camera(K, c.T_cam_world, 96, 64))
    K = c.K.copy()
    K[1, 1] *= 1.1
    with pytest.raises(CameraConversionError, match="square"):
        blender_camera_params(Camera(K, c.T_cam_world, 96, 64))


@pytest.mark.blender
@pytest.mark.parametrize("w,h", [(96, 64), (64, 96)])
def test_blender_projection_matrix_equals_K(blender_reset, w, h):
    """Project world points with Blender's own camera matrices (view + projection, NDC -> pixel
    edges) and with K, T: they agree to 1e-6 px, for landscape and portrait images."""
    bpy = blender_reset
    from crackgen.blender.camera import apply_camera

    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = w, h, 100
    obj = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    scene.collection.objects.link(obj)
    c = cam(w, h)
    apply_camera(obj, c)
    bpy.context.view_layer.update()
    P = np.array(obj.calc_matrix_camera(bpy.context.evaluated_depsgraph_get(), x=w, y=h))
    V = np.array(obj.matrix_world.inverted())
    pts = np.array([[0.0, 0.0, 0.0], [0.2, -0.1, 0.0], [-0.15, 0.2, -0.02]])
    clip = (P @ V @ np.c_[pts, np.ones(3)].T).T
    ndc = clip[:, :2] / clip[:, 3:4]
    # NDC [-1, 1] spans the pixel edges [0, W]; OpenCV pixel centres sit at +0.5, y flipped
    u = (ndc[:, 0] + 1) / 2 * w - 0.5
    v = (1 - ndc[:, 1]) / 2 * h - 0.5
    uv, _ = c.project(pts)
    np.testing.assert_allclose(np.c_[u, v], uv, atol=1e-4)
    assert math.isclose(obj.data.sensor_width, 36.0)
