"""`crackgen show DIR KEY`: one sample as a coloured point cloud (.ply) and an oblique PNG view.

The cloud is the RGB camera's depth map (or the sparse ToF/LiDAR map projected into
that view) lifted to world coordinates with the stored K and T_cam_world, coloured by
the RGB pixels, so it is also a visual check that depth, RGB and cameras agree.

PNG: Open3D's OffscreenRenderer needs EGL/OpenGL; where that is missing it aborts the
whole process rather than raising, so it is probed once in a subprocess and, when it
is not usable (headless machines without EGL, e.g. ours), the view is drawn by a
numpy z-buffered orthographic splat instead (``splat_render``).
"""
from __future__ import annotations

import functools
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np

from crackgen.errors import CrackgenError
from fusion.geometry.camera import Camera


class ShowError(CrackgenError, ValueError):
    """Bad sample/key/output for ``crackgen show`` (names what is wrong)."""


def sample_cloud(sample: dict, source: str = "depth") -> tuple[np.ndarray, np.ndarray]:
    """(N,3) world points and (N,3) uint8 colours of the valid pixels of ``sample[source]``."""
    key = sample.get("__key__", "?")
    meta = sample.get("meta") or {}
    if source not in sample:
        raise ShowError(f"{key}: sample has no {source!r} member")
    try:
        cam = Camera.from_meta(meta["cameras"]["rgb"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ShowError(f"{key}: metadata has no usable cameras.rgb ({exc})") from None
    depth = np.asarray(sample[source], np.float32)
    if depth.shape != (cam.height, cam.width):
        raise ShowError(f"{key}: {source} is {depth.shape}, cameras.rgb is {cam.height}x{cam.width}")
    pts = cam.backproject(depth).reshape(-1, 3)
    rgb = np.asarray(sample["rgb"], np.uint8).reshape(-1, 3)
    ok = np.isfinite(pts).all(axis=1)
    return pts[ok], rgb[ok]


def write_ply(path: str | Path, points: np.ndarray, colors: np.ndarray) -> Path:
    """Binary PLY via Open3D (imported here only: the trainer never needs it)."""
    import open3d as o3d

    p = Path(path)
    if p.suffix.lower() != ".ply":
        raise ShowError(f"{p}: point cloud output must end in .ply")
    p.parent.mkdir(parents=True, exist_ok=True)
    pc = o3d.geometry.PointCloud()
    pc.points = o3d.utility.Vector3dVector(points.astype(np.float64))
    pc.colors = o3d.utility.Vector3dVector(colors.astype(np.float64) / 255.0)
    if not o3d.io.write_point_cloud(str(p), pc, write_ascii=False):
        raise ShowError(f"{p}: Open3D could not write the point cloud")
    return p


def _view_rotation(elev_deg: float, azim_deg: float) -> np.ndarray:
    """World -> view rotation looking down at the z = 0 surface from elevation/azimuth."""
    from scipy.spatial.transform import Rotation

    # view axes: x right, y down, z into the screen; start looking straight down (-z world)
    base = np.array([[1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]])
    tilt = Rotation.from_euler("x", -(90.0 - elev_deg), degrees=True).as_matrix()
    spin = Rotation.from_euler("z", azim_deg, degrees=True).as_matrix()
    return tilt @ base @ spin


def splat_render(points: np.ndarray, colors: np.ndarray, size: tuple[int, int] = (800, 600),
                 elev_deg: float = 50.0, azim_deg: float = 30.0, splat_px: int | None = None,
                 z_exaggeration: float = 1.0) -> np.ndarray:
    """Orthographic, z-buffered point splat (H,W,3 uint8) seen obliquely; no OpenGL needed."""
    w, h = size
    img = np.full((h, w, 3), 255, np.uint8)
    if len(points) == 0:
        return img
    p = points - points.mean(axis=0)
    p = p * np.array([1.0, 1.0, z_exaggeration])
    v = p @ _view_rotation(elev_deg, azim_deg).T
    lo, hi = v[:, :2].min(axis=0), v[:, :2].max(axis=0)
    scale = 0.92 * min(w / max(hi[0] - lo[0], 1e-9), h / max(hi[1] - lo[1], 1e-9))
    centre = (lo + hi) / 2
    u = np.round((v[:, 0] - centre[0]) * scale + w / 2).astype(np.int64)
    r = np.round((v[:, 1] - centre[1]) * scale + h / 2).astype(np.int64)
    if splat_px is None:  # about the grid spacing of a dense depth map, so the surface looks closed
        splat_px = int(np.clip(np.ceil(0.9 * min(w, h) / np.sqrt(len(points))), 1, 8))
    order = np.argsort(-v[:, 2], kind="stable")  # far first, near last: near points overwrite
    u, r, c = u[order], r[order], colors[order]
    for du in range(splat_px):
        for dv in range(splat_px):
            uu, rr = u + du, r + dv
            ok = (uu >= 0) & (uu < w) & (rr >= 0) & (rr < h)
            img[rr[ok], uu[ok]] = c[ok]
    return img


@functools.lru_cache(maxsize=1)
def open3d_offscreen_available() -> bool:
    """Probe Open3D offscreen rendering in a subprocess (it aborts without EGL)."""
    code = ("import open3d as o3d\n"
            "r = o3d.visualization.rendering.OffscreenRenderer(32, 32)\n"
            "print('CRACKGEN_O3D_OK')\n")
    try:
        res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return res.returncode == 0 and "CRACKGEN_O3D_OK" in res.stdout


def open3d_render(points: np.ndarray, colors: np.ndarray, size: tuple[int, int] = (800, 600)) -> np.ndarray:
    import open3d as o3d

    w, h = size
    r = o3d.visualization.rendering.OffscreenRenderer(w, h)
    pc = o3d.geometry.PointCloud()
    pc.points = o3d.utility.Vector3dVector(points.astype(np.float64))
    pc.colors = o3d.utility.Vector3dVector(colors.astype(np.float64) / 255.0)
    mat = o3d.visualization.rendering.MaterialRecord()
    mat.shader = "defaultUnlit"
    mat.point_size = 2.0
    r.scene.set_background([1, 1, 1, 1])
    r.scene.add_geometry("cloud", pc, mat)
    c = points.mean(axis=0)
    ext = float(np.ptp(points, axis=0).max())
    r.setup_camera(45.0, c, c + np.array([0.6, -0.6, 1.0]) * ext, [0, 0, 1])
    return np.asarray(r.render_to_image())[:, :, :3].copy()


def show(root: str, key: str, pointcloud: str | None = None, png: str | None = None,
         source: str = "depth") -> list[str]:
    """Write the point cloud and/or PNG of sample ``key``; returns lines for the user."""
    from crackgen.shards import ShardError, load_sample

    try:
        sample = load_sample(root, key, members={"rgb", source, "meta"})
    except ShardError as exc:
        raise ShowError(str(exc)) from None
    pts, cols = sample_cloud(sample, source)
    if len(pts) == 0:
        raise ShowError(f"{key}: {source} has no valid pixels")
    lines = [f"{key}: {len(pts)} points from {source}"]
    if pointcloud:
        lines.append(f"point cloud: {write_ply(pointcloud, pts, cols)}")
    if png:
        p = Path(png)
        p.parent.mkdir(parents=True, exist_ok=True)
        if open3d_offscreen_available():
            img, how = open3d_render(pts, cols), "Open3D offscreen"
        else:
            img, how = splat_render(pts, cols, z_exaggeration=5.0), "numpy splat (Open3D offscreen needs EGL: not available)"
        if not cv2.imwrite(str(p), cv2.cvtColor(img, cv2.COLOR_RGB2BGR)):
            raise ShowError(f"{p}: cannot write PNG")
        lines.append(f"view: {p} ({how})")
    return lines
