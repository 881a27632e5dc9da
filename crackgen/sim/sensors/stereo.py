"""Generator-side stereo: SGBM on the rendered pair, GT disparity, and the SYNTH3-style
input set of the ToF/stereo confidence fusion (thesis Ch. 3.3, Agresti et al.).

All maps live in the left (= RGB) view, in pixels, float32, -1 = no value:
stereo disparity (SGBM), ToF disparity (ToF points z-buffered into the left
view, d = f*B/Z), left-minus-warped-right grey difference (warped by the
stereo disparity, 0 where it is invalid), ToF amplitude in the left view
(-1 none), GT disparity from the ray-cast GT depth and, with a LiDAR, its
sparse disparity in the left view (the 3-channel LiDAR/stereo variant, Ch. 4.6;
its interpolated form is recomputed by ``fusion.depth.densify`` on read, so a dense
map is not stored for every sample).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crackgen.config.spec import StereoSpec
from crackgen.sim.rig import Rig
from crackgen.sim.sensors.tof import SensorError, TofResult
from fusion.geometry.disparity import depth_to_disparity
from fusion.geometry.stereo import left_right_difference, reproject_as_disparity, sgbm_disparity

SYNTH3_CHANNELS = ("disp_stereo", "disp_tof", "lr_diff", "tof_amplitude")


@dataclass
class StereoResult:
    baseline_m: float
    focal_px: float
    disp_sgm: np.ndarray  # (H,W) SGBM disparity, -1 none
    disp_gt: np.ndarray  # (H,W) f*B/Z of the GT depth, -1 where the ray misses
    disp_tof: np.ndarray | None  # (H,W) ToF disparity in the left view, -1 none
    lr_diff: np.ndarray  # (H,W) left grey - right grey warped by disp_sgm
    tof_amplitude: np.ndarray | None  # (H,W) ToF amplitude in the left view, -1 none
    disp_lidar: np.ndarray | None = None  # (H,W) LiDAR disparity f*B/Z in the left view, -1 none

    def synth3(self) -> np.ndarray:
        """(H,W,4) float32 network input in ``SYNTH3_CHANNELS`` order (needs the ToF)."""
        if self.disp_tof is None or self.tof_amplitude is None:
            raise SensorError("synth3: the SYNTH3 set needs the ToF (tof.enabled is false)")
        return np.stack([self.disp_sgm, self.disp_tof, self.lr_diff, self.tof_amplitude], axis=-1).astype(np.float32)


def rig_baseline(rig: Rig) -> float:
    """Stereo baseline (m) from the rig's camera centres, so it always matches the render."""
    if rig.right is None:
        raise SensorError("stereo: the rig has no right camera (stereo.enabled is false or baseline 0)")
    return float(np.linalg.norm(rig.right.center - rig.rgb.center))


def simulate_stereo(
    spec: StereoSpec,
    rig: Rig,
    left_rgb: np.ndarray,
    right_rgb: np.ndarray,
    gt_depth: np.ndarray,
    tof: TofResult | None = None,
    lidar_depth_rgb: np.ndarray | None = None,
) -> StereoResult:
    """Stereo maps of one sample from the rendered pair and the GT depth of the left view."""
    baseline = rig_baseline(rig)
    f = rig.rgb.fx
    shape = (rig.rgb.height, rig.rgb.width)
    for name, img in (("left_rgb", left_rgb), ("right_rgb", right_rgb), ("gt_depth", gt_depth),
                      ("lidar_depth_rgb", gt_depth if lidar_depth_rgb is None else lidar_depth_rgb)):
        if np.asarray(img).shape[:2] != shape:
            raise SensorError(f"stereo: {name} is {np.asarray(img).shape[:2]}, the RGB camera is {shape}")
    disp_sgm = sgbm_disparity(left_rgb, right_rgb, spec.num_disparities, spec.block_size)
    disp_gt = depth_to_disparity(gt_depth, f, baseline)
    disp_tof = amp = None
    if tof is not None:
        disp_tof, vals = reproject_as_disparity(tof.points_world, rig.rgb, baseline, {"amplitude": tof.points_amplitude})
        amp = vals["amplitude"]
    return StereoResult(
        baseline_m=baseline,
        focal_px=f,
        disp_sgm=disp_sgm,
        disp_gt=disp_gt,
        disp_tof=disp_tof,
        lr_diff=left_right_difference(left_rgb, right_rgb, disp_sgm),
        tof_amplitude=amp,
        # the LiDAR depth is already z-buffered in the left (= RGB) view, so d = f*B/Z per pixel
        disp_lidar=None if lidar_depth_rgb is None else depth_to_disparity(lidar_depth_rgb, f, baseline),
    )
