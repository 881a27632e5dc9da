"""The lens stage: every RGB-view member of a canvas-rendered sample warped into the distorted frame.

Why one stage over all members: the RGB, the right view, the label, the depth and every
sensor map projected into the RGB view must stay on the same pixels, so one map
(``fusion.geometry.lens.distortion_map``) resamples them all: rendered views bilinearly, everything
else by nearest neighbour (a label stays 0/255, a sparse map keeps its -1 holes and its
measured values unblended). Members outside the RGB view (``tofraw``, ``crackmap``) are
left as they are. See ``crackgen.sim.rig`` for the canvas.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from crackgen.shards.members import member_for_file
from crackgen.sim.rig import Rig
from fusion.geometry.lens import distortion_map, warp


def lens_maps(rig: Rig) -> tuple[np.ndarray, np.ndarray]:
    """(map_x, map_y): the canvas pixel each output pixel looks up."""
    assert rig.lens is not None and rig.K_out is not None
    out = rig.output_camera(rig.rgb)
    return distortion_map(rig.K_out, rig.lens, out.width, out.height, rig.margins)


def warp_view_members(members: dict[str, Any], maps: tuple[np.ndarray, np.ndarray]) -> dict[str, Any]:
    """A copy of ``members`` with every RGB-view member in the distorted frame."""
    out = dict(members)
    for name, value in members.items():
        m = member_for_file(name)
        if m is not None and m.in_rgb_view:
            out[name] = warp(value, maps, nearest=not m.is_rgb)
    return out


def canvas_coverage(maps: tuple[np.ndarray, np.ndarray], canvas_hw: tuple[int, int]) -> np.ndarray:
    """Bool (H_canvas, W_canvas): the canvas pixels the distorted frame looks at (for the visible-crack GT)."""
    h, w = canvas_hw
    cols = np.clip(np.rint(maps[0]).astype(np.int64), 0, w - 1)
    rows = np.clip(np.rint(maps[1]).astype(np.int64), 0, h - 1)
    seen = np.zeros((h, w), bool)
    seen[rows, cols] = True
    return seen
