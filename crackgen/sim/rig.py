"""The sensor rig of one sample: RGB (+ right) camera, ToF camera and LiDAR poses.

Pure numpy, from the SampleSpec only, so the renderer, the ray-cast sensors and
the written metadata all use the very same K and T (OpenCV convention).

With lens distortion (``spec.lens``) the renderer, the ray caster and every sensor work on a
pinhole *canvas*: the RGB camera with the same focal length and pose, grown by the margins
the lens needs (``fusion.geometry.lens.canvas_margins``). ``lens_warp`` then turns every RGB-view
member into the distorted W x H image of the camera that is exported (``rgb_out``: the
recipe's K, plus the coefficients).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crackgen.config.spec import SampleSpec
from fusion.geometry.camera import Camera, intrinsics_from_focal, intrinsics_from_fov, look_at, mounted_pose
from fusion.geometry.lens import Distortion, canvas_K, canvas_margins


@dataclass(frozen=True)
class Rig:
    rgb: Camera
    right: Camera | None  # stereo right camera (same K, +baseline along rgb x)
    tof: Camera | None
    T_lidar_world: np.ndarray | None  # LiDAR frame: same axes as the RGB camera (z = sweep centre)
    lens: Distortion | None = None  # the RGB views' lens; None = pinhole
    margins: tuple[int, int, int, int] = (0, 0, 0, 0)  # canvas beyond the output frame: left, top, right, bottom
    K_out: np.ndarray | None = None  # the exported (output) camera's K, with a lens

    def output_camera(self, cam: Camera) -> Camera:
        """The camera a view is exported as: itself, or with a lens the W x H camera of the recipe's K."""
        if self.lens is None:
            return cam
        l, t, r, b = self.margins
        return Camera(self.K_out, cam.T_cam_world, cam.width - l - r, cam.height - t - b)

    def to_meta(self) -> dict:
        out = {"rgb": self.output_camera(self.rgb).to_meta()}
        if self.lens is not None:
            # OpenCV's distCoeffs (k1, k2, p1, p2, k3) of the rgb (and right) view: cv2.undistort(img, K, dist)
            out["rgb"]["dist"] = self.lens.coeffs.tolist()
            out["rgb"]["canvas"] = {"margins_ltrb": list(self.margins), "K": self.rgb.K.tolist()}
        if self.right is not None:
            out["right"] = self.output_camera(self.right).to_meta()
            if self.lens is not None:
                out["right"]["dist"] = self.lens.coeffs.tolist()
        if self.tof is not None:
            out["tof"] = self.tof.to_meta()
        if self.T_lidar_world is not None:
            out["lidar"] = {"T_cam_world": self.T_lidar_world.tolist()}
        return out


def rgb_camera(spec: SampleSpec) -> Camera:
    c = spec.camera
    target = np.array([c.target_x_m, c.target_y_m, 0.0])
    toward_cam = np.array([np.sin(c.tilt_rad) * np.cos(c.azimuth_rad), np.sin(c.tilt_rad) * np.sin(c.azimuth_rad), np.cos(c.tilt_rad)])
    eye = target + c.distance_m * toward_cam
    # Image-down points horizontally toward the camera's foot, so the near ground is at the bottom.
    down_hint = np.array([np.cos(c.azimuth_rad), np.sin(c.azimuth_rad), 0.0])
    T = look_at(eye, target, down_hint, c.roll_rad)
    K = intrinsics_from_focal(c.focal_mm, c.sensor_width_mm, c.width_px, c.height_px, c.cx_offset_px, c.cy_offset_px)
    return Camera(K, T, c.width_px, c.height_px)


def make_rig(spec: SampleSpec) -> Rig:
    rgb = rgb_camera(spec)
    lens, margins, K_out = None, (0, 0, 0, 0), None
    if spec.lens.enabled:
        L = spec.lens
        lens = Distortion(k1=L.k1, k2=L.k2, p1=L.p1, p2=L.p2, k3=L.k3)
        margins = canvas_margins(rgb.K, lens, rgb.width, rgb.height)
        K_out = rgb.K
        rgb = Camera(canvas_K(rgb.K, margins), rgb.T_cam_world, rgb.width + margins[0] + margins[2],
                     rgb.height + margins[1] + margins[3])
    right = None
    if spec.stereo.enabled and spec.camera.baseline_m > 0:
        right = Camera(rgb.K, mounted_pose(rgb.T_cam_world, [spec.camera.baseline_m, 0.0, 0.0], [0.0, 0.0, 0.0]), rgb.width, rgb.height)
    tof = None
    if spec.tof.enabled:
        t = spec.tof
        tof = Camera(
            intrinsics_from_fov(t.hfov_rad, t.vfov_rad, t.width_px, t.height_px),
            mounted_pose(rgb.T_cam_world, t.offset_m, t.rotation_rad),
            t.width_px,
            t.height_px,
        )
    T_lidar = None
    if spec.lidar.enabled:
        T_lidar = mounted_pose(rgb.T_cam_world, spec.lidar.offset_m, spec.lidar.rotation_rad)
    return Rig(rgb=rgb, right=right, tof=tof, T_lidar_world=T_lidar, lens=lens, margins=margins, K_out=K_out)
