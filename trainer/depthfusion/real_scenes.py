"""Real-data check of the LiDAR/stereo fusion: real stereo pairs with GT, LiDAR simulated from the GT.

For each folder of ``../shared/data/real/stereo`` (Middlebury 2003 or ETH3D /
Middlebury 2014 two-view, recognised by their files), or ``skimage:motorcycle``
(Middlebury 2014 Motorcycle as shipped in scikit-image, a scene no setting was
chosen on): SGBM disparity of the real pair
(``fusion.geometry.stereo``), a scan-line LiDAR sampled from the GT with noise
(``fusion.depth.scanline_lidar``, seeded per scene), the 3-channel inputs, then the
same rows as ``fusion-eval``. The CNN is the one trained on synthetic shards.
"""
from __future__ import annotations

import argparse
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fusion.depth.inputs import FusionInputError, build_inputs
from fusion.depth.scanline_lidar import scanline_lidar
from fusion.geometry.real_data import (
    SKIMAGE_MOTORCYCLE,
    SKIMAGE_MOTORCYCLE_SCENE,
    RealDataError,
    load_eth3d_scene,
    load_middlebury_scene,
    load_skimage_motorcycle,
)
from fusion.geometry.stereo import search_range, sgbm_disparity
from trainer.core.errors import TrainerInputError
from trainer.depthfusion.data import FusionScene


def add_real_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("real stereo with simulated LiDAR (LiDAR checkpoints)")
    g.add_argument("--real-stereo", action="append", default=[], metavar="DIR",
                   help="a Middlebury-2003 or ETH3D/Middlebury-2014 two-view folder with GT disparity, or "
                        f"{SKIMAGE_MOTORCYCLE} (scikit-image's Middlebury 2014 pair; repeatable)")
    g.add_argument("--lidar-lines", type=int, default=32, help="simulated scan lines over the image height")
    g.add_argument("--lidar-sigma-px", type=float, default=0.25, help="simulated LiDAR noise (disparity px)")
    g.add_argument("--lidar-dropout", type=float, default=0.1, help="fraction of lost returns")
    g.add_argument("--seed", type=int, default=0)


def load_real_pair(folder: str | Path) -> tuple[str, np.ndarray, np.ndarray, np.ndarray]:
    """(scene name, left, right, GT disparity with -1 = none) of a Middlebury or ETH3D folder, or scikit-image's pair."""
    try:
        if str(folder) == SKIMAGE_MOTORCYCLE:
            s = load_skimage_motorcycle()
            return SKIMAGE_MOTORCYCLE_SCENE, s["left_rgb"], s["right_rgb"], s["disp_left"]
        folder = Path(folder)
        if not folder.is_dir():
            raise TrainerInputError(f"--real-stereo {folder} is not a folder (or {SKIMAGE_MOTORCYCLE})")
        if (folder / "disp0.pfm").is_file():
            s = load_eth3d_scene(folder)
            return folder.name, s["left"], s["right"], s["disp_left"]
        if (folder / "disp_left.tif").is_file():
            s = load_middlebury_scene(folder)
            return folder.name, s["left_rgb"], s["right_rgb"], s["disp_left"]
    except RealDataError as exc:
        raise TrainerInputError(str(exc)) from None
    raise TrainerInputError(f"--real-stereo {folder}: neither ETH3D/Middlebury 2014 (disp0.pfm) nor Middlebury 2003 "
                            f"(disp_left.tif)")


@dataclass(frozen=True)
class SimulatedLidar:
    """The scan-line LiDAR simulated from a real scene's GT disparity (``fusion-eval --lidar-*``)."""

    lines: int = 32
    sigma_px: float = 0.25
    dropout: float = 0.1
    seed: int = 0


def real_scene(folder: str | Path, lidar_sim: SimulatedLidar, densify: str, variant: str = "lidar",
               other_bm3d: float = 0.0) -> FusionScene:
    name, left, right, gt = load_real_pair(folder)
    stereo = sgbm_disparity(left, right, num_disparities=search_range(gt, gt.shape[1]))
    rng = np.random.default_rng(np.random.SeedSequence([lidar_sim.seed, zlib.crc32(name.encode())]))
    lidar = scanline_lidar(gt, lidar_sim.lines, rng, lidar_sim.sigma_px, lidar_sim.dropout)
    try:
        inp = build_inputs(variant, stereo, lidar, left, right, None, densify, other_bm3d)
    except FusionInputError as exc:
        raise TrainerInputError(f"--real-stereo {folder}: {exc}") from None
    return FusionScene(name, inp.x, gt.astype(np.float32), inp.stereo_valid)
