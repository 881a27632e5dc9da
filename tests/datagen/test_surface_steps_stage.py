"""[surface] steps through the whole sample: renderer, ray caster and sensors see the same step."""
from __future__ import annotations

import numpy as np
import pytest
from tiny_recipes import tiny_recipe

from crackgen.config.recipe import parse_recipe
from crackgen.datagen.pipeline import SampleProducer

STEP = "[surface]\nsteps = 1\nstep_height_m = 0.1\nstep_offset = 0.0\n"


def _make(text: str):
    prod = SampleProducer(parse_recipe(text), threads=1)
    try:
        return prod.make(0)
    finally:
        prod.close()


@pytest.mark.blender
@pytest.mark.slow
def test_a_step_moves_the_raised_side_closer_by_its_height_in_every_depth_member():
    base = tiny_recipe(3, stereo=True, width=96, height=72, grid_px=96)
    flat, step = _make(base), _make(base.replace("[surface]\n", STEP))
    st = step.meta["spec"]["surface"]["steps"]
    assert len(st) == 1 and st[0]["height_m"] == 0.1 and step.meta["spec"]["camera"] == flat.meta["spec"]["camera"]
    cam = step.meta["spec"]["camera"]
    eye_z = cam["distance_m"] * np.cos(cam["tilt_rad"])
    d0, d1 = flat.members["depth.exr"], step.members["depth.exr"]
    ok = (d0 > 0) & (d1 > 0) & (flat.members["mask.png"] == 0) & (step.members["mask.png"] == 0)
    ratio = d1[ok] / d0[ok]
    # along one pixel ray, planar depth scales with the height left to the plane: (eye_z - h) / eye_z
    on_flat, raised = np.abs(ratio - 1) < 2e-3, np.abs(ratio - (eye_z - 0.1) / eye_z) < 2e-3
    assert on_flat.mean() > 0.15 and raised.mean() > 0.15 and (on_flat | raised).mean() > 0.85
    g0, g1 = flat.members["disp_gt.exr"], step.members["disp_gt.exr"]
    both = (g0 > 0) & (g1 > 0)
    assert np.abs(g1[both] - g0[both]).max() > 1.0  # a disparity edge stereo and LiDAR now have to handle
    assert step.meta["depth"]["render_vs_raycast_median_abs_m"] < 5e-3  # Cycles rendered the stepped mesh the ray caster hit
    assert np.abs(step.members["rgb.png"].astype(int) - flat.members["rgb.png"]).mean() > 2.0
