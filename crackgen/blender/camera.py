"""The ONE conversion between our OpenCV cameras (K, T_cam_world) and Blender cameras.

Why one place: the RGB image, the GT mask/depth (ray cast with K, T) and every
exported camera must describe the same projection; a second hand-written
conversion is how half-pixel and sign errors creep in.

Blender's camera looks down its local -z with +y up, OpenCV's down +z with +y
down, so ``matrix_world = inv(T_cam_world) @ diag(1, -1, -1, 1)``.
Intrinsics: ``sensor_fit = 'HORIZONTAL'`` gives ``fx = lens / sensor_width * W``.
Blender's pixel (i, j) spans [i, i+1] with the view-plane centre at W/2 in edge
coordinates, i.e. at ``W/2 - 0.5`` in OpenCV pixel-centre coordinates. With the
horizontal fit, Cycles measures lens shift in units of the image *width* (the fit
dimension, not max(W, H)); +shift_x moves the view window right, so the principal
point moves left: ``cx = W/2 - 0.5 - shift_x * W``, ``cy = H/2 - 0.5 + shift_y * W``
(image y points down). tests/test_blender_render.py verifies this by projection
on non-square images.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crackgen.errors import CrackgenError
from fusion.geometry.camera import Camera, invert_pose

SENSOR_WIDTH_MM = 36.0  # any value works: lens is derived from fx for this width
_CV_TO_BLENDER = np.diag([1.0, -1.0, -1.0, 1.0])


class CameraConversionError(CrackgenError, ValueError):
    """A camera Blender's pinhole model cannot represent (skew, non-square pixels)."""


@dataclass(frozen=True)
class BlenderCameraParams:
    matrix_world: np.ndarray  # 4x4 Blender camera object -> world
    lens_mm: float
    sensor_width_mm: float
    shift_x: float  # units of image width (sensor_fit HORIZONTAL)
    shift_y: float
    width: int
    height: int


def blender_camera_params(camera: Camera, sensor_width_mm: float = SENSOR_WIDTH_MM) -> BlenderCameraParams:
    """OpenCV camera -> the Blender camera settings that render the same projection."""
    K = np.asarray(camera.K, dtype=np.float64)
    W, H = int(camera.width), int(camera.height)
    fx, fy = float(K[0, 0]), float(K[1, 1])
    if abs(K[0, 1]) > 1e-9 * fx:
        raise CameraConversionError(f"camera K has skew {K[0, 1]!r}; Blender cameras have none")
    if abs(fx - fy) > 1e-6 * fx:
        raise CameraConversionError(f"camera K has fx={fx!r} != fy={fy!r}; Blender needs square pixels")
    if not (fx > 0 and W > 0 and H > 0):
        raise CameraConversionError(f"camera needs fx > 0 and a positive size, got fx={fx!r}, {W}x{H}")
    matrix_world = invert_pose(np.asarray(camera.T_cam_world, dtype=np.float64)) @ _CV_TO_BLENDER
    return BlenderCameraParams(
        matrix_world=matrix_world,
        lens_mm=fx * sensor_width_mm / W,
        sensor_width_mm=float(sensor_width_mm),
        shift_x=-(float(K[0, 2]) - (W / 2.0 - 0.5)) / W,
        shift_y=(float(K[1, 2]) - (H / 2.0 - 0.5)) / W,
        width=W,
        height=H,
    )


def apply_camera(cam_obj, camera: Camera) -> BlenderCameraParams:
    """Set a Blender camera object (pose and intrinsics) from an OpenCV camera; returns the params."""
    from mathutils import Matrix

    p = blender_camera_params(camera)
    data = cam_obj.data
    data.type = "PERSP"
    data.sensor_fit = "HORIZONTAL"
    data.sensor_width = p.sensor_width_mm
    data.lens_unit = "MILLIMETERS"
    data.lens = p.lens_mm
    data.shift_x = p.shift_x
    data.shift_y = p.shift_y
    cam_obj.matrix_world = Matrix(p.matrix_world.tolist())
    return p
