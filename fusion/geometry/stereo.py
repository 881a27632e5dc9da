"""Classical stereo for the fusion stack: SGBM disparity, left-right difference,
and other depth sensors re-expressed as disparity in the left view.

Why these three: the ToF/stereo confidence CNN (thesis Ch. 3.3, after Agresti
et al.) takes stereo disparity, ToF disparity in the left view, the left-minus-
warped-right grey difference and ToF amplitude; generator and trainer must
compute them identically, so they live here (pure numpy/OpenCV).
"""
from __future__ import annotations

import cv2
import numpy as np

from fusion.errors import FusionError
from fusion.geometry.camera import Camera
from fusion.geometry.disparity import depth_to_disparity, valid_values
from fusion.geometry.projection import project_points


class StereoInputError(FusionError):
    """Stereo images or settings that SGBM cannot use."""


def to_grey(img: np.ndarray) -> np.ndarray:
    """uint8 grey from uint8/float grey or RGB (RGB channel order, as the project stores it)."""
    a = np.asarray(img)
    if a.ndim == 3 and a.shape[2] == 3:
        a = cv2.cvtColor(a.astype(np.float32) if a.dtype != np.uint8 else a, cv2.COLOR_RGB2GRAY)
    elif a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim != 2:
        raise StereoInputError(f"expected a grey or RGB image, got shape {np.asarray(img).shape}")
    if a.dtype != np.uint8:
        a = np.clip(np.rint(a), 0, 255).astype(np.uint8)
    return a


def make_sgbm(num_disparities: int = 128, block_size: int = 5, min_disparity: int = 0, channels: int = 1) -> cv2.StereoSGBM:
    """StereoSGBM with the usual smoothness penalties P1 = 8*cn*b^2, P2 = 32*cn*b^2 (OpenCV docs)."""
    if num_disparities < 16 or num_disparities % 16:
        raise StereoInputError(f"num_disparities must be a positive multiple of 16, got {num_disparities}")
    if block_size < 1 or block_size % 2 == 0:
        raise StereoInputError(f"block_size must be odd and >= 1, got {block_size}")
    area = channels * block_size * block_size
    return cv2.StereoSGBM_create(
        minDisparity=int(min_disparity),
        numDisparities=int(num_disparities),
        blockSize=int(block_size),
        P1=8 * area,
        P2=32 * area,
        disp12MaxDiff=1,
        uniquenessRatio=10,
        speckleWindowSize=100,
        speckleRange=2,
        preFilterCap=63,
        mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY,
    )


def sgbm_disparity(
    left: np.ndarray, right: np.ndarray, num_disparities: int = 128, block_size: int = 5, min_disparity: int = 0
) -> np.ndarray:
    """Left-view disparity (px, float32) of a rectified pair; -1 where SGBM gives none."""
    gl, gr = to_grey(left), to_grey(right)
    if gl.shape != gr.shape:
        raise StereoInputError(f"left {gl.shape} and right {gr.shape} images differ in size")
    if num_disparities + max(min_disparity, 0) >= gl.shape[1]:  # OpenCV asserts, or asks for 2**64 bytes
        raise StereoInputError(f"num_disparities {num_disparities} (+ min_disparity {min_disparity}) must be "
                               f"less than the image width {gl.shape[1]} px")
    raw = make_sgbm(num_disparities, block_size, min_disparity).compute(gl, gr)  # int16, 4 fractional bits
    disp = raw.astype(np.float32) / 16.0
    disp[(raw < min_disparity * 16) | (disp <= 0)] = -1.0
    return disp


def search_range(gt: np.ndarray, width: int) -> int:
    """SGBM num_disparities covering a GT disparity's largest value (plus a 16 px margin), below the image width."""
    if width <= 16:
        raise StereoInputError(f"SGBM needs an image wider than 16 px, got {width}")
    top = float(np.max(np.where(valid_values(gt), gt, 0.0)))
    return int(min(np.ceil(top / 16.0 + 1) * 16, (width - 1) // 16 * 16))


def warp_right_to_left(right: np.ndarray, disparity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sample the right image at (u - d, v) for every left pixel: float32 image and validity mask."""
    r = np.asarray(right, dtype=np.float32)
    h, w = disparity.shape
    u, v = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    valid = np.isfinite(disparity) & (disparity > 0)
    map_x = np.where(valid, u - disparity, -1.0).astype(np.float32)
    valid &= (map_x >= 0) & (map_x <= w - 1)
    warped = cv2.remap(r, map_x, v, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return warped, valid


def left_right_difference(left: np.ndarray, right: np.ndarray, disparity: np.ndarray) -> np.ndarray:
    """Left grey minus right grey warped by ``disparity`` (float32, grey levels 0..255); 0 where
    the disparity is invalid or points outside the right image (no evidence either way)."""
    gl = to_grey(left).astype(np.float32)
    gr = to_grey(right).astype(np.float32)
    warped, valid = warp_right_to_left(gr, disparity)
    return np.where(valid, gl - warped, 0.0).astype(np.float32)


def reproject_as_disparity(
    points_world: np.ndarray,
    left: Camera,
    baseline_m: float,
    values: dict[str, np.ndarray] | None = None,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Sensor points (e.g. ToF) -> z-buffered sparse disparity f*B/Z in the left view (-1 none),
    plus any per-point ``values`` splatted with the same winners."""
    proj = project_points(left, points_world, values)
    return depth_to_disparity(proj.depth, left.fx, baseline_m), proj.values


def occluded_from_disparity(disp: np.ndarray, tol_px: float = 1.0) -> np.ndarray:
    """Left pixels not visible in the right view, from a (GT) left disparity: a pixel is occluded
    when it maps outside the right image, or when another left pixel landing on the same right
    pixel has a disparity larger by more than ``tol_px`` (it is nearer and hides it)."""
    d = np.asarray(disp, dtype=np.float64)
    h, w = d.shape
    valid = np.isfinite(d) & (d > 0)
    u = np.broadcast_to(np.arange(w), (h, w))
    xr = np.floor(u - np.where(valid, d, 0.0) + 0.5).astype(np.int64)
    inside = valid & (xr >= 0) & (xr < w)
    rows = np.broadcast_to(np.arange(h)[:, None], (h, w))
    key = rows[inside] * w + xr[inside]
    best = np.full(h * w, -np.inf)
    np.maximum.at(best, key, d[inside])
    occ = valid & ~inside
    occ[inside] = d[inside] < best[key] - tol_px
    return occ


def disparity_errors(est: np.ndarray, gt: np.ndarray, mask: np.ndarray | None = None) -> dict[str, float]:
    """MAE, RMSE (px), >1 px and >3 px error rates over pixels valid in ``gt`` (and ``mask``)
    where ``est`` is valid; ``density`` is the fraction of those GT pixels ``est`` covers."""
    ok_gt = np.isfinite(gt) & (gt > 0)
    if mask is not None:
        ok_gt &= mask
    ok = ok_gt & np.isfinite(est) & (est > 0)
    err = np.abs(est[ok] - gt[ok]).astype(np.float64)
    if err.size == 0:
        return {"mae": float("nan"), "rmse": float("nan"), "bad1": float("nan"), "bad3": float("nan"), "density": 0.0}
    return {
        "mae": float(err.mean()),
        "rmse": float(np.sqrt(np.mean(err**2))),
        "bad1": float((err > 1).mean()),
        "bad3": float((err > 3).mean()),
        "density": float(ok.sum() / max(ok_gt.sum(), 1)),
    }
