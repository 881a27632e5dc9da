"""Pinhole camera model in the OpenCV convention (x right, y down, z forward).

Pixel (u, v) integer coordinates are pixel *centres* (OpenCV), so a camera
whose optical axis hits the image centre has ``cx = W/2 - 0.5``. Every sensor
(RGB, right, ToF) and the trainer's real-data geometry use this one model.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Camera:
    K: np.ndarray  # 3x3 intrinsics, pixels
    T_cam_world: np.ndarray  # 4x4 world -> camera
    width: int
    height: int

    @property
    def R(self) -> np.ndarray:
        return self.T_cam_world[:3, :3]

    @property
    def t(self) -> np.ndarray:
        return self.T_cam_world[:3, 3]

    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates."""
        return -self.R.T @ self.t

    @property
    def T_world_cam(self) -> np.ndarray:
        return invert_pose(self.T_cam_world)

    @property
    def fx(self) -> float:
        return float(self.K[0, 0])

    def to_camera(self, points_world: np.ndarray) -> np.ndarray:
        """(N,3) world points -> (N,3) camera-frame points."""
        return points_world @ self.R.T + self.t

    def project(self, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N,3) world points -> (N,2) continuous pixel coords and (N,) planar depth z."""
        pc = self.to_camera(np.asarray(points_world, dtype=np.float64))
        z = pc[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uvw = pc @ self.K.T
            uv = uvw[:, :2] / uvw[:, 2:3]
        return uv, z

    def pixel_directions(self) -> np.ndarray:
        """(H*W,3) camera-frame ray directions through pixel centres, with z = 1 (row-major)."""
        u, v = np.meshgrid(np.arange(self.width, dtype=np.float64), np.arange(self.height, dtype=np.float64))
        pix = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], axis=1)
        return pix @ np.linalg.inv(self.K).T

    def pixel_rays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World-frame rays through every pixel centre: origins (N,3), unit dirs (N,3), and
        ``z_per_t`` (N,) = planar depth per unit ray length, so ``depth = t_hit * z_per_t``."""
        d_cam = self.pixel_directions()
        norm = np.linalg.norm(d_cam, axis=1)
        d_world = (d_cam / norm[:, None]) @ self.R  # R^T applied to row vectors
        origins = np.broadcast_to(self.center, d_world.shape).copy()
        return origins, d_world, 1.0 / norm

    def backproject(self, depth: np.ndarray) -> np.ndarray:
        """(H,W) planar depth (-1/invalid = no value) -> (H,W,3) world points, NaN where invalid."""
        d = np.asarray(depth, dtype=np.float64)
        pts_cam = self.pixel_directions().reshape(self.height, self.width, 3) * d[..., None]
        pts = pts_cam.reshape(-1, 3) @ self.R + self.center
        pts = pts.reshape(self.height, self.width, 3)
        pts[~(np.isfinite(d) & (d > 0))] = np.nan
        return pts

    def to_meta(self) -> dict:
        return {"K": self.K.tolist(), "T_cam_world": self.T_cam_world.tolist(), "width": self.width, "height": self.height}

    @classmethod
    def from_meta(cls, meta: dict) -> "Camera":
        return cls(np.asarray(meta["K"], float), np.asarray(meta["T_cam_world"], float), int(meta["width"]), int(meta["height"]))


def invert_pose(T: np.ndarray) -> np.ndarray:
    R, t = T[:3, :3], T[:3, 3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ t
    return out


def intrinsics_from_focal(
    focal_mm: float, sensor_width_mm: float, width: int, height: int, cx_offset_px: float = 0.0, cy_offset_px: float = 0.0
) -> np.ndarray:
    """K for a horizontally fitted sensor (Blender's sensor_fit='HORIZONTAL'), square pixels."""
    f = focal_mm / sensor_width_mm * width
    return np.array(
        [[f, 0.0, width / 2.0 - 0.5 + cx_offset_px], [0.0, f, height / 2.0 - 0.5 + cy_offset_px], [0.0, 0.0, 1.0]]
    )


def intrinsics_from_fov(hfov_rad: float, vfov_rad: float, width: int, height: int) -> np.ndarray:
    """K from full horizontal/vertical fields of view (edge to edge of the image)."""
    fx = width / 2.0 / np.tan(hfov_rad / 2.0)
    fy = height / 2.0 / np.tan(vfov_rad / 2.0)
    return np.array([[fx, 0.0, width / 2.0 - 0.5], [0.0, fy, height / 2.0 - 0.5], [0.0, 0.0, 1.0]])


def look_at(eye: np.ndarray, target: np.ndarray, down_hint: np.ndarray, roll_rad: float = 0.0) -> np.ndarray:
    """T_cam_world of a camera at ``eye`` looking at ``target``; image-down (+y) follows
    ``down_hint`` projected off the optical axis, then the image is rolled by ``roll_rad``."""
    eye = np.asarray(eye, float)
    z = np.asarray(target, float) - eye
    z /= np.linalg.norm(z)
    y = np.asarray(down_hint, float) - np.dot(down_hint, z) * z
    n = np.linalg.norm(y)
    if n < 1e-9:
        raise ValueError("look_at: down_hint is parallel to the optical axis")
    y /= n
    x = np.cross(y, z)
    c, s = np.cos(roll_rad), np.sin(roll_rad)
    x, y = c * x + s * y, -s * x + c * y
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z])
    T[:3, 3] = -T[:3, :3] @ eye
    return T


def mounted_pose(T_parent_world: np.ndarray, offset_m, rotation_rad) -> np.ndarray:
    """T_child_world for a sensor mounted at ``offset_m`` (parent camera frame) with a small
    xyz Euler rotation ``rotation_rad`` relative to the parent camera."""
    from scipy.spatial.transform import Rotation

    R_off = Rotation.from_euler("xyz", rotation_rad).as_matrix()
    T_parent_child = np.eye(4)
    T_parent_child[:3, :3] = R_off
    T_parent_child[:3, 3] = np.asarray(offset_m, float)
    return invert_pose(T_parent_child) @ T_parent_world
