"""Network inputs of the confidence CNN, built the same way for shards, files and real scenes.

Two variants (thesis Ch. 3.3 / 4.6, Agresti et al. 2019), channels in order:

* ``tof`` (4): stereo disparity, ToF disparity in the left view, left grey
  minus right grey warped by the stereo disparity, ToF amplitude;
* ``lidar`` (3): stereo disparity, LiDAR disparity, left grey minus right grey
  warped by the LiDAR disparity;
* ``lidar4`` (4, ours): the ``lidar`` channels plus left grey minus right grey
  warped by the *stereo* disparity. The thesis's LiDAR input carries photometric
  evidence for the LiDAR only; where SGBM matched the wrong pixel (occlusions,
  repeated texture) only this channel shows it, as the ToF variant's does.

The candidate maps (channels 0 and 1) are made dense first: stereo holes and
the sparse ToF/LiDAR by ``fusion.depth.densify`` (normalised convolution by default),
unless the caller passes maps that are already dense (an external stereo
network, a depth-completion network). The two candidates are what the fusion
rules pick from, so the CNN scores exactly the values that get fused.
``other_bm3d`` > 0 denoises the densified ToF/LiDAR candidate with BM3D (that
sigma, disparity px) before anything is computed from it: on real scenes a
BM3D-filtered LiDAR alone beats every fusion of the raw one, so the CNN is
trained to decide between stereo and the *filtered* map, the one it has to beat.

``stereo_valid`` keeps where the stereo map had a measured value before its
holes were filled: a filled hole is an interpolation across an occlusion or a
matching failure, not a measurement, and on real scenes it is where stereo is
worst (Middlebury Cones: 22 % of the pixels, 4.4 px filled-stereo error against
0.6 px for the LiDAR), so the fusion rules can refuse it (``fuse_scene``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusion.depth.densify import fill_nearest, interpolate_sparse, valid_values
from fusion.depth.postfilter import bm3d_disparity
from fusion.errors import FusionError
from fusion.geometry.stereo import left_right_difference

VARIANTS = {"tof": ("disp_stereo", "disp_tof", "lr_diff", "tof_amplitude"),
            "lidar": ("disp_stereo", "disp_lidar", "lr_diff_lidar"),
            "lidar4": ("disp_stereo", "disp_lidar", "lr_diff_lidar", "lr_diff_stereo")}
OTHER_NAME = {"tof": "ToF", "lidar": "LiDAR", "lidar4": "LiDAR"}
LIDAR_VARIANTS = ("lidar", "lidar4")  # variants whose other sensor is a LiDAR (simulated from GT on real scenes)


class FusionInputError(FusionError):
    """Missing or mis-sized maps for a fusion input variant."""


@dataclass
class FusionInputs:
    """One scene's CNN input (H,W,C) float32 and its two dense candidate disparities."""

    variant: str
    x: np.ndarray  # (H,W,C) raw (unnormalised) channels in VARIANTS[variant] order
    stereo_valid: np.ndarray  # (H,W) bool: the stereo input had a value here (not a filled hole)

    @property
    def stereo(self) -> np.ndarray:
        return self.x[..., 0]

    @property
    def other(self) -> np.ndarray:
        return self.x[..., 1]


def _shape_check(shape: tuple[int, int], **maps: np.ndarray | None) -> None:
    for name, m in maps.items():
        if m is not None and np.asarray(m).shape[:2] != shape:
            raise FusionInputError(f"{name} is {np.asarray(m).shape[:2]}, stereo disparity is {shape}")


def dense_other(disp_other: np.ndarray, densify: str, other_bm3d: float = 0.0) -> np.ndarray:
    """The ToF/LiDAR candidate: densified, then BM3D-denoised when ``other_bm3d`` > 0."""
    if other_bm3d < 0:
        raise FusionInputError(f"other_bm3d must be >= 0 (BM3D sigma in disparity px), got {other_bm3d}")
    do = interpolate_sparse(disp_other, densify)
    return bm3d_disparity(do, other_bm3d) if other_bm3d > 0 else do


def _lidar_channels(disp_lidar: np.ndarray, left: np.ndarray, right: np.ndarray,
                    densify: str, other_bm3d: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The LiDAR variant's channels 1 and 2: the densified LiDAR and the grey difference warped by it."""
    do = dense_other(disp_lidar, densify, other_bm3d)
    return do, left_right_difference(left, right, do)


def build_inputs(
    variant: str,
    disp_stereo: np.ndarray,
    disp_other: np.ndarray,
    left: np.ndarray,
    right: np.ndarray,
    amplitude: np.ndarray | None = None,
    densify: str = "normconv",
    other_bm3d: float = 0.0,
) -> FusionInputs:
    """Input stack of ``variant`` from sparse or dense maps (all in the left view, -1 = none)."""
    if variant not in VARIANTS:
        raise FusionInputError(f"unknown fusion variant {variant!r}; choose from {', '.join(VARIANTS)}")
    shape = np.asarray(disp_stereo).shape
    _shape_check(shape, disp_other=disp_other, left=left, right=right, amplitude=amplitude)
    if not valid_values(disp_other).any():
        raise FusionInputError(f"the {OTHER_NAME[variant]} disparity has no valid pixel")
    stereo_valid = valid_values(disp_stereo)
    ds = interpolate_sparse(disp_stereo, densify) if stereo_valid.any() else np.full(shape, -1, np.float32)
    if variant == "tof":
        if amplitude is None:
            raise FusionInputError("the tof variant needs the ToF amplitude")
        do = dense_other(disp_other, densify, other_bm3d)
        amp = fill_nearest(amplitude)
        lr = left_right_difference(left, right, ds)
        x = np.stack([ds, do, lr, np.maximum(amp, 0.0)], axis=-1)
    else:
        do, lr = _lidar_channels(disp_other, left, right, densify, other_bm3d)
        chans = [ds, do, lr] + ([left_right_difference(left, right, ds)] if variant == "lidar4" else [])
        x = np.stack(chans, axis=-1)
    return FusionInputs(variant, x.astype(np.float32), stereo_valid)


def replace_lidar(inputs: FusionInputs, disp_lidar: np.ndarray, left: np.ndarray, right: np.ndarray,
                  densify: str = "normconv", other_bm3d: float = 0.0) -> FusionInputs:
    """A LiDAR-variant input with another LiDAR map: channels 1 and 2 rebuilt, the (already
    densified) stereo channel, its validity and (``lidar4``) its grey difference kept, so the
    stereo is not densified again."""
    if inputs.variant not in LIDAR_VARIANTS:
        raise FusionInputError(f"replace_lidar needs a lidar-variant input, got {inputs.variant!r}")
    _shape_check(inputs.x.shape[:2], disp_lidar=disp_lidar, left=left, right=right)
    if not valid_values(disp_lidar).any():
        raise FusionInputError("the LiDAR disparity has no valid pixel")
    x = inputs.x.copy()
    x[..., 1], x[..., 2] = _lidar_channels(disp_lidar, left, right, densify, other_bm3d)
    return FusionInputs(inputs.variant, x, inputs.stereo_valid)
