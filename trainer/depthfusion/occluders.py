"""``cracktrain fusion --occluders K``: training scenes with a depth edge, from the renders themselves.

Each training scene gets K more versions with another training scene pasted
in front of it inside a random blob, nearer by a drawn disparity jump
(``fusion.depth.layered_stereo``). SGBM is run again on the composited pair, so its
failures at the new edge (half-occlusions, a smeared boundary, the fattened
foreground) are SGBM's own, and a scan-line LiDAR is drawn from the composited
GT (``random_scanline_lidar``), so its interpolation smears across the edge as a
real one does. Only training scenes are used, for both layers.
"""
from __future__ import annotations

import zlib
from typing import Sequence

import numpy as np

from fusion.depth.inputs import FusionInputs, build_inputs
from fusion.depth.layered_stereo import StereoView, composite, occluder_mask
from fusion.depth.scanline_lidar import random_scanline_lidar
from fusion.geometry.stereo import search_range, sgbm_disparity, to_grey
from trainer.core.errors import TrainerInputError

Grey = tuple[np.ndarray, np.ndarray] | None
JUMP_PX = (2.0, 24.0)  # foreground nearer than the background by this much disparity (uniform; Cones: 5-30 px)
SGBM_BLOCK = 5  # recipes/stereo_tof.toml's [stereo] block_size


def occluder_scene(key: str, background: StereoView, foreground: StereoView, rng: np.random.Generator,
                   variant: str, densify: str = "normconv", other_bm3d: float = 0.0
                   ) -> tuple[str, FusionInputs, np.ndarray, Grey]:
    """One composited scene (key, inputs, GT, lidar4 greys): blob, jump and LiDAR drawn from
    ``rng``; SGBM on the composited views. ``trainer.depthfusion.data`` makes it a FusionScene."""
    mask = occluder_mask(background.gt.shape, rng)
    view = composite(background, foreground, mask, float(rng.uniform(*JUMP_PX)))
    stereo = sgbm_disparity(view.left, view.right, search_range(view.gt, view.gt.shape[1]), SGBM_BLOCK)
    lidar, _ = random_scanline_lidar(view.gt, rng)
    inp = build_inputs(variant, stereo, lidar, view.left, view.right, None, densify, other_bm3d)
    grey = (to_grey(view.left), to_grey(view.right)) if variant == "lidar4" else None
    return key, inp, view.gt, grey


def occluder_scenes(views: Sequence[tuple[str, StereoView]], copies: int, seed: int, variant: str,
                    densify: str = "normconv", other_bm3d: float = 0.0, progress: bool = False
                    ) -> list[tuple[str, FusionInputs, np.ndarray, Grey]]:
    """``copies`` composited scenes per view, keys ``KEY~occluderJ``: the foreground is another
    of ``views``, drawn with everything else from a Generator seeded by (seed, key, J)."""
    from tqdm import tqdm

    if copies > 0 and len(views) < 2:
        raise TrainerInputError(f"--occluders pastes one training scene in front of another: needs at least 2 "
                                f"training scenes, got {len(views)}")
    out = []
    for i, (key, bg) in enumerate(tqdm(views, desc="occluder scenes", unit="scene", disable=not progress)):
        for j in range(copies):
            rng = np.random.default_rng(np.random.SeedSequence([seed, zlib.crc32(key.encode()), j, 1]))
            k = int(rng.integers(len(views) - 1))
            fg = views[k + (k >= i)][1]
            out.append(occluder_scene(f"{key}~occluder{j}", bg, fg, rng, variant, densify, other_bm3d))
    return out
