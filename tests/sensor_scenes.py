"""Hand-made meshes and rigs for the sensor tests (planes, boxes), independent of the crack surface."""
from __future__ import annotations

import numpy as np

from crackgen.config.spec import LidarSpec, TofSpec
from crackgen.sim.raycast import MeshRaycaster
from crackgen.sim.rig import Rig
from fusion.geometry.camera import Camera, intrinsics_from_fov, look_at, mounted_pose


def plane_mesh(size_m: float = 4.0, z: float = 0.0, n: int = 2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Square n x n vertex grid in the plane z, centred at the origin; UV = (x, y) mapped to [0, 1]."""
    s = np.linspace(-size_m / 2, size_m / 2, n)
    x, y = np.meshgrid(s, s)
    v = np.stack([x.ravel(), y.ravel(), np.full(x.size, z)], axis=1)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1))
    a = (j * n + i).ravel()
    f = np.concatenate([np.stack([a, a + 1, a + n + 1], 1), np.stack([a, a + n + 1, a + n], 1)])
    uv = (v[:, :2] + size_m / 2) / size_m
    return v, f, uv


def box_mesh(center, size) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    import trimesh

    b = trimesh.creation.box(extents=size)
    v = np.asarray(b.vertices) + np.asarray(center, float)
    return v, np.asarray(b.faces), np.zeros((len(v), 2))


def merge(*meshes) -> MeshRaycaster:
    vs, fs, uvs, off = [], [], [], 0
    for v, f, uv in meshes:
        vs.append(v)
        fs.append(f + off)
        uvs.append(uv)
        off += len(v)
    return MeshRaycaster(np.concatenate(vs), np.concatenate(fs), np.concatenate(uvs))


def down_camera(height_m: float, width: int, height: int, hfov_deg: float, vfov_deg: float | None = None) -> Camera:
    """Camera at (0, 0, height) looking straight down; image x = world +x, image y = world -y."""
    vfov = vfov_deg if vfov_deg is not None else np.degrees(2 * np.arctan(np.tan(np.radians(hfov_deg) / 2) * height / width))
    K = intrinsics_from_fov(np.radians(hfov_deg), np.radians(vfov), width, height)
    T = look_at(np.array([0, 0, height_m]), np.zeros(3), np.array([0.0, -1.0, 0.0]))
    return Camera(K, T, width, height)


def tof_spec(**kw) -> TofSpec:
    """A noise-free ToF spec; keywords switch parts of the model on."""
    base = dict(
        enabled=True, width_px=160, height_px=120, hfov_rad=np.radians(62.0), vfov_rad=np.radians(49.0),
        offset_m=[0.05, 0.0, 0.0], rotation_rad=[0.0, 0.0, 0.0], sigma0_m=0.0, k_noise=0.0,
        amplitude_scale=1.0, min_amplitude=0.0, grazing_rad=np.pi / 2, flying_pixels=False,
        wrap_range_m=0.0, bias_m=0.0, seed=7,
    )
    base.update(kw)
    return TofSpec(**base)


def lidar_spec(**kw) -> LidarSpec:
    base = dict(
        enabled=True, beams=16, vfov_min_rad=np.radians(-15.0), vfov_max_rad=np.radians(15.0), hfov_rad=np.radians(90.0),
        azimuth_step_rad=np.radians(0.2), max_range_m=100.0, sigma_m=0.0, dropout=0.0,
        offset_m=[0.0, -0.08, 0.0], rotation_rad=[0.0, 0.0, 0.0], seed=11,
    )
    base.update(kw)
    return LidarSpec(**base)


def make_test_rig(rgb: Camera, tof: TofSpec | None = None, lidar: LidarSpec | None = None, baseline_m: float = 0.0) -> Rig:
    """Rig with sensors mounted on ``rgb`` exactly as ``crackgen.sim.rig.make_rig`` mounts them."""
    tof_cam = None
    if tof is not None:
        tof_cam = Camera(
            intrinsics_from_fov(tof.hfov_rad, tof.vfov_rad, tof.width_px, tof.height_px),
            mounted_pose(rgb.T_cam_world, tof.offset_m, tof.rotation_rad), tof.width_px, tof.height_px,
        )
    right = None
    if baseline_m > 0:
        right = Camera(rgb.K, mounted_pose(rgb.T_cam_world, [baseline_m, 0, 0], [0, 0, 0]), rgb.width, rgb.height)
    T_lidar = mounted_pose(rgb.T_cam_world, lidar.offset_m, lidar.rotation_rad) if lidar is not None else None
    return Rig(rgb=rgb, right=right, tof=tof_cam, T_lidar_world=T_lidar)


def tilted_camera(distance_m: float, tilt_deg: float, width: int, height: int, hfov_deg: float) -> Camera:
    """Camera looking at the origin from ``distance_m``, optical axis ``tilt_deg`` off the plane normal
    (towards -y); near ground at the bottom of the image, like ``crackgen.sim.rig.rgb_camera``."""
    t = np.radians(tilt_deg)
    eye = np.array([0.0, -np.sin(t), np.cos(t)]) * distance_m
    vfov = np.degrees(2 * np.arctan(np.tan(np.radians(hfov_deg) / 2) * height / width))
    K = intrinsics_from_fov(np.radians(hfov_deg), np.radians(vfov), width, height)
    return Camera(K, look_at(eye, np.zeros(3), np.array([0.0, -1.0, 0.0])), width, height)


def plane_rays(cam: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Independent analytic hit of every pixel-centre ray with the z = 0 plane: range (inf on miss)
    and cos(incidence)."""
    _, d, _ = cam.pixel_rays()
    o = cam.center
    with np.errstate(divide="ignore"):
        t = -o[2] / d[:, 2]
    t = np.where(t > 0, t, np.inf)
    return t.reshape(cam.height, cam.width), np.abs(d[:, 2]).reshape(cam.height, cam.width)
