"""Loaders for the real reference data in ../shared/data/real (see its README).

Every loader returns plain arrays in the project conventions: disparity and
depth float32 with -1 = no value (Middlebury 0, ETH3D inf, rig PNG 0 all map to
-1), RGB uint8 in RGB order, grey uint8. A missing or unreadable file raises
``RealDataError`` naming the file.

Middlebury 2014 "Motorcycle" (Scharstein et al., GCPR 2014) at quarter size ships inside
scikit-image (``skimage.data.stereo_motorcycle``), so ``load_skimage_motorcycle`` gives a
third real scene with GT disparity that needs neither a download nor a copy here.

ETH3D two-view: ``calib.txt`` gives cam0/cam1 K (pixels), ``baseline`` in mm
and ``doffs`` = cx1 - cx0 (pixels), so Z = f * B / (d + doffs). The playground
scene has doffs = 0 and identical K for both views.

The real rig frame (FuseDepth): ToF/stereo/LiDAR depth are 16-bit PNGs in
millimetres at 512x424, registered to each other (a Kinect-v2-class ToF grid).
The source gives no intrinsics; ``RIG_DEPTH_FOV_DEG`` is the nominal Kinect v2
depth field of view (70.6 x 60 deg), good enough for geometry checks.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from fusion.errors import FusionError
from fusion.geometry.camera import Camera, intrinsics_from_fov

RIG_DEPTH_SCALE_M = 0.001  # 16-bit PNG counts -> metres
RIG_DEPTH_FOV_DEG = (70.6, 60.0)


class RealDataError(FusionError):
    """A real-data file is missing, unreadable or not in the expected format."""


def _read(path: Path, flags: int = cv2.IMREAD_UNCHANGED) -> np.ndarray:
    path = Path(path)
    if not path.is_file():
        raise RealDataError(f"{path}: file not found")
    img = cv2.imread(str(path), flags)
    if img is None:
        raise RealDataError(f"{path}: OpenCV cannot decode this image")
    return img


def read_rgb(path: Path) -> np.ndarray:
    """uint8 HxWx3 in RGB order (float TIFFs in 0..255 are rounded)."""
    img = _read(path, cv2.IMREAD_UNCHANGED)
    if img.ndim != 3 or img.shape[2] < 3:
        raise RealDataError(f"{path}: expected a colour image, got shape {img.shape}")
    img = cv2.cvtColor(img[..., :3], cv2.COLOR_BGR2RGB)
    if img.dtype != np.uint8:
        img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    return img


def read_grey(path: Path) -> np.ndarray:
    return _read(path, cv2.IMREAD_GRAYSCALE)


def read_middlebury_disparity(path: Path) -> np.ndarray:
    """Float TIFF disparity in pixels, 0 = no data -> float32 with -1 = no data."""
    d = _read(path)
    if d.ndim != 2:
        raise RealDataError(f"{path}: expected a single-channel disparity, got shape {d.shape}")
    d = d.astype(np.float32)
    d[~(np.isfinite(d) & (d > 0))] = -1.0
    return d


def read_pfm(path: Path) -> np.ndarray:
    """PFM (Pf grey / PF colour) as float32 top-down rows; the sign of the scale gives endianness."""
    path = Path(path)
    if not path.is_file():
        raise RealDataError(f"{path}: file not found")
    with path.open("rb") as fh:
        kind = fh.readline().strip()
        if kind not in (b"Pf", b"PF"):
            raise RealDataError(f"{path}: not a PFM file (header {kind[:8]!r})")
        dims = fh.readline().split()
        scale_line = fh.readline().strip()
        try:
            w, h = int(dims[0]), int(dims[1])
            scale = float(scale_line)
        except (ValueError, IndexError) as exc:
            raise RealDataError(f"{path}: bad PFM header ({exc})") from None
        data = fh.read()
    ch = 3 if kind == b"PF" else 1
    dtype = np.dtype("<f4" if scale < 0 else ">f4")
    if len(data) < w * h * ch * 4:
        raise RealDataError(f"{path}: truncated PFM ({len(data)} bytes for {w}x{h}x{ch})")
    arr = np.frombuffer(data, dtype=dtype, count=w * h * ch).reshape(h, w, ch) if ch == 3 else np.frombuffer(
        data, dtype=dtype, count=w * h).reshape(h, w)
    return np.ascontiguousarray(arr[::-1]).astype(np.float32)  # rows are stored bottom-up


def read_eth3d_disparity(path: Path) -> np.ndarray:
    """ETH3D disp0.pfm -> float32 disparity, -1 where the file has inf (no data)."""
    d = read_pfm(path)
    if d.ndim != 2:
        raise RealDataError(f"{path}: expected a single-channel PFM disparity")
    d[~(np.isfinite(d) & (d > 0))] = -1.0
    return d


@dataclass(frozen=True)
class StereoCalib:
    K0: np.ndarray
    K1: np.ndarray
    baseline_m: float
    doffs_px: float  # cx1 - cx0; Z = f*B/(d + doffs)
    width: int
    height: int
    ndisp: int

    @property
    def focal_px(self) -> float:
        return float(self.K0[0, 0])


def _matrix(text: str, path: Path, key: str) -> np.ndarray:
    nums = [float(x) for x in re.split(r"[\s;\[\]]+", text) if x]
    if len(nums) != 9:
        raise RealDataError(f"{path}: {key} must be a 3x3 matrix, got {len(nums)} numbers")
    return np.array(nums).reshape(3, 3)


def read_calib(path: Path) -> StereoCalib:
    """Middlebury-2014/ETH3D ``calib.txt`` (key=value lines; baseline in mm)."""
    path = Path(path)
    if not path.is_file():
        raise RealDataError(f"{path}: file not found")
    kv = {}
    for line in path.read_text().splitlines():
        if "=" in line:
            k, v = line.split("=", 1)
            kv[k.strip()] = v.strip()
    missing = [k for k in ("cam0", "cam1", "baseline", "width", "height") if k not in kv]
    if missing:
        raise RealDataError(f"{path}: missing keys {missing}")
    try:
        return StereoCalib(
            K0=_matrix(kv["cam0"], path, "cam0"),
            K1=_matrix(kv["cam1"], path, "cam1"),
            baseline_m=float(kv["baseline"]) / 1000.0,
            doffs_px=float(kv.get("doffs", 0.0)),
            width=int(kv["width"]),
            height=int(kv["height"]),
            ndisp=int(kv.get("ndisp", 0)),
        )
    except ValueError as exc:
        raise RealDataError(f"{path}: bad value ({exc})") from None


def load_middlebury_scene(folder: Path) -> dict:
    """Middlebury 2003 quarter-size pair: left/right RGB + grey, disparities, non-occlusion mask."""
    folder = Path(folder)
    occ = _read(folder / "occlusion.png")
    occ = occ[..., 0] if occ.ndim == 3 else occ
    out = {
        "left_rgb": read_rgb(folder / "left_rgb.tif"),
        "right_rgb": read_rgb(folder / "right_rgb.tif"),
        "disp_left": read_middlebury_disparity(folder / "disp_left.tif"),
        "disp_right": read_middlebury_disparity(folder / "disp_right.tif"),
        "nonocc": occ > 0,  # 255 (or 1) = visible in both views
    }
    out["left"] = cv2.cvtColor(out["left_rgb"], cv2.COLOR_RGB2GRAY)
    out["right"] = cv2.cvtColor(out["right_rgb"], cv2.COLOR_RGB2GRAY)
    if out["disp_left"].shape != out["left"].shape:
        raise RealDataError(f"{folder / 'disp_left.tif'}: size {out['disp_left'].shape} != image {out['left'].shape}")
    return out


def load_eth3d_scene(folder: Path) -> dict:
    """ETH3D two-view pair: grey images, disp0 (-1 none), calibration and GT depth."""
    from fusion.geometry.disparity import disparity_to_depth

    folder = Path(folder)
    calib = read_calib(folder / "calib.txt")
    left = _read(folder / "im0.png", cv2.IMREAD_GRAYSCALE)
    right = _read(folder / "im1.png", cv2.IMREAD_GRAYSCALE)
    disp = read_eth3d_disparity(folder / "disp0.pfm")
    if disp.shape != left.shape or left.shape != (calib.height, calib.width):
        raise RealDataError(f"{folder}: disp0 {disp.shape}, im0 {left.shape} and calib {calib.height}x{calib.width} disagree")
    depth = disparity_to_depth(disp, calib.focal_px, calib.baseline_m, calib.doffs_px)
    return {"left": left, "right": right, "disp_left": disp, "calib": calib, "depth_left": depth}


SKIMAGE_MOTORCYCLE = "skimage:motorcycle"  # the --real-stereo name of scikit-image's bundled pair
SKIMAGE_MOTORCYCLE_SCENE = "middlebury2014_motorcycle"


def load_skimage_motorcycle() -> dict:
    """Middlebury 2014 Motorcycle, 741x500 (scikit-image's copy): RGB + grey views, disp_left (-1 = none)."""
    try:
        from skimage import data
        left, right, disp = data.stereo_motorcycle()
    except (ImportError, OSError, ValueError) as exc:
        raise RealDataError(f"{SKIMAGE_MOTORCYCLE}: scikit-image's stereo_motorcycle is unavailable ({exc})") from None
    disp = np.asarray(disp, np.float32).copy()
    disp[~(np.isfinite(disp) & (disp > 0))] = -1.0
    return {"left_rgb": left, "right_rgb": right, "disp_left": disp,
            "left": cv2.cvtColor(left, cv2.COLOR_RGB2GRAY), "right": cv2.cvtColor(right, cv2.COLOR_RGB2GRAY)}


def rig_depth_camera(width: int = 512, height: int = 424) -> Camera:
    """Nominal pinhole of the real rig's registered depth grid, at the world origin."""
    fov = np.radians(RIG_DEPTH_FOV_DEG)
    return Camera(intrinsics_from_fov(fov[0], fov[1], width, height), np.eye(4), width, height)


def load_rig_frame(folder: Path) -> dict:
    """Real RGB + ToF + stereo + LiDAR frame: rgb uint8 (480,640,3); tof/stereo/lidar float32
    metres (424,512), -1 = no return; ``camera``: nominal pinhole of the depth grid."""
    folder = Path(folder)
    out: dict = {"rgb": read_rgb(folder / "rgb.png")}
    shape = None
    for name in ("tof", "stereo", "lidar"):
        path = folder / f"{name}.png"
        raw = _read(path)
        if raw.dtype != np.uint16 or raw.ndim != 2:
            raise RealDataError(f"{path}: expected a 16-bit single-channel depth PNG, got {raw.dtype} {raw.shape}")
        if shape is not None and raw.shape != shape:
            raise RealDataError(f"{path}: size {raw.shape} differs from the other depth maps {shape}")
        shape = raw.shape
        depth = raw.astype(np.float32) * np.float32(RIG_DEPTH_SCALE_M)
        depth[raw == 0] = -1.0
        out[name] = depth
    out["camera"] = rig_depth_camera(shape[1], shape[0])
    return out
