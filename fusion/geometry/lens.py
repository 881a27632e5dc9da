"""Brown–Conrady lens distortion in OpenCV's convention, as a warp of pinhole images.

Why a warp: the renderer and the ray caster are pinhole cameras. A real lens maps the
pinhole (undistorted) normalised point ``x`` to ``distort(x)`` with

    r² = x² + y²,  radial = 1 + k1 r² + k2 r⁴ + k3 r⁶
    x_d = x·radial + 2 p1 x y + p2 (r² + 2 x²)
    y_d = y·radial + p1 (r² + 2 y²) + 2 p2 x y

and the pixel is ``K @ [x_d, y_d, 1]`` (OpenCV's ``distCoeffs = (k1, k2, p1, p2, k3)``).
So each pixel of the distorted image looks up the pinhole image at ``K @ undistort(K⁻¹ p)``;
``cv2.undistort`` with the same ``K`` and coefficients gives the pinhole image back.

Barrel distortion (k1 < 0) sees more than the pinhole frame, so the pinhole image is
rendered on a larger *canvas*: the same focal length, the principal point moved by the
margins (``canvas_margins``). Every member in the RGB view is warped with one map: images
bilinearly, labels, depth and sparse sensor maps by nearest neighbour, so they stay aligned.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from fusion.errors import FusionError

DIST_ORDER = ("k1", "k2", "p1", "p2", "k3")  # OpenCV's distCoeffs order
_ITER = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-10)


class LensError(FusionError):
    """Coefficients whose lens folds back inside the image (no one-to-one warp exists)."""


@dataclass(frozen=True)
class Distortion:
    """Brown–Conrady coefficients (OpenCV convention)."""

    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0

    @property
    def coeffs(self) -> np.ndarray:
        """``distCoeffs`` for OpenCV: (k1, k2, p1, p2, k3)."""
        return np.array([getattr(self, k) for k in DIST_ORDER], np.float64)

    def distort(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) undistorted normalised points -> distorted normalised points (the model above)."""
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        radial = 1 + self.k1 * r2 + self.k2 * r2 ** 2 + self.k3 * r2 ** 3
        xd = x * radial + 2 * self.p1 * x * y + self.p2 * (r2 + 2 * x * x)
        yd = y * radial + self.p1 * (r2 + 2 * y * y) + 2 * self.p2 * x * y
        return np.stack([xd, yd], axis=1)

    def reaches(self, r_d: float, steps: int = 4096) -> bool:
        """The radial part maps [0, r_u] one-to-one onto [0, r_d] for some r_u: walking out from the centre,
        the distorted radius reaches ``r_d`` before the lens folds back (d r_d / d r <= 0)."""
        r = np.linspace(0.0, 4.0 * r_d + 1.0, steps)
        rd = r * (1 + self.k1 * r ** 2 + self.k2 * r ** 4 + self.k3 * r ** 6)
        slope = 1 + 3 * self.k1 * r ** 2 + 5 * self.k2 * r ** 4 + 7 * self.k3 * r ** 6
        folds = np.nonzero(slope <= 0)[0]
        end = folds[0] if folds.size else len(r)
        return bool(np.any(rd[:end] >= r_d))


def undistort_pixels(uv: np.ndarray, K: np.ndarray, dist: Distortion) -> np.ndarray:
    """(N, 2) pixels of the distorted image -> where they are in the pinhole image with the same K."""
    pts = np.asarray(uv, np.float64).reshape(-1, 1, 2)
    out = cv2.undistortPointsIter(pts, K, dist.coeffs, None, K, _ITER)
    return out.reshape(-1, 2)


def _border(width: int, height: int) -> np.ndarray:
    xs, ys = np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64)
    return np.concatenate([np.stack([xs, np.zeros_like(xs)], 1), np.stack([xs, np.full_like(xs, height - 1)], 1),
                           np.stack([np.zeros_like(ys), ys], 1), np.stack([np.full_like(ys, width - 1), ys], 1)])


def canvas_margins(K: np.ndarray, dist: Distortion, width: int, height: int) -> tuple[int, int, int, int]:
    """(left, top, right, bottom) pixels the pinhole canvas needs beyond the W x H frame so that every
    distorted pixel (and its bilinear neighbours) looks up a rendered pixel."""
    Kinv = np.linalg.inv(K)
    corners = np.array([[0, 0], [width - 1, 0], [0, height - 1], [width - 1, height - 1]], np.float64)
    r_max = float(np.max(np.linalg.norm((np.c_[corners, np.ones(4)] @ Kinv.T)[:, :2], axis=1)))
    if not dist.reaches(1.05 * r_max):
        raise LensError(f"lens distortion {dist} folds back before the image corner (normalised radius "
                        f"{r_max:.2f}): no one-to-one warp")
    uv = undistort_pixels(_border(width, height), K, dist)
    back = dist.distort((np.c_[uv, np.ones(len(uv))] @ Kinv.T)[:, :2])
    if not np.allclose(np.c_[back, np.ones(len(back))] @ K.T[:, :2], _border(width, height), atol=1e-3):
        raise LensError(f"lens distortion {dist}: the inverse did not converge at the image border")
    left = max(0.0, -uv[:, 0].min())
    top = max(0.0, -uv[:, 1].min())
    right = max(0.0, uv[:, 0].max() - (width - 1))
    bottom = max(0.0, uv[:, 1].max() - (height - 1))
    return tuple(int(np.ceil(m)) + 1 if m > 0 else 0 for m in (left, top, right, bottom))  # type: ignore[return-value]


def canvas_K(K: np.ndarray, margins: tuple[int, int, int, int]) -> np.ndarray:
    """The pinhole canvas camera: same focal length, principal point moved by the left/top margins."""
    Kc = np.array(K, np.float64, copy=True)
    Kc[0, 2] += margins[0]
    Kc[1, 2] += margins[1]
    return Kc


def distortion_map(K: np.ndarray, dist: Distortion, width: int, height: int,
                   margins: tuple[int, int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(map_x, map_y) float32 (H, W): the canvas pixel each distorted pixel centre looks up (for cv2.remap)."""
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    uv = undistort_pixels(np.stack([u.ravel(), v.ravel()], 1), K, dist)
    map_x = (uv[:, 0] + margins[0]).reshape(height, width).astype(np.float32)
    map_y = (uv[:, 1] + margins[1]).reshape(height, width).astype(np.float32)
    return map_x, map_y


def warp(image: np.ndarray, maps: tuple[np.ndarray, np.ndarray], nearest: bool) -> np.ndarray:
    """Resample a canvas-sized image into the distorted frame; ``nearest`` for labels, depth and sparse maps
    (no value is ever blended with its neighbour or with a "no measurement" -1)."""
    a = np.asarray(image)
    interp = cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR
    if a.dtype == np.float32 and a.ndim == 2 or a.dtype == np.uint8 or nearest:
        return cv2.remap(a, maps[0], maps[1], interp, borderMode=cv2.BORDER_REPLICATE)
    return cv2.remap(a.astype(np.float32), maps[0], maps[1], interp, borderMode=cv2.BORDER_REPLICATE).astype(a.dtype)
