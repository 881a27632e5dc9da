"""[camera.distortion] through the whole sample: off changes nothing; on, every RGB-view member is warped by
one lens, the exported K and coefficients undo it (cv2.undistort), and the label stays on the dark crack."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from tiny_recipes import tiny_recipe

from crackgen.config.recipe import RecipeError, parse_recipe
from crackgen.datagen.pipeline import SampleProducer
from crackgen.shards.codecs import encode_json, encode_member
from crackgen.sim.visibility import label_contrast

W, H = 96, 72
# one straight, wide, dark crack seen from straight above (hand-made: no branches, barely jagged)
STRAIGHT = """
[crack]
shape = "fracture"
width_m = 0.05
depth_m = 0.05
wall = 0.2
count = 1
branches = 0
jaggedness = 0.0
[material]
texture_px = 128
crack_darkening = 0.3
crack_cavity = 1.0
[camera]
width_px = 96
height_px = 72
distance_m = 0.9
tilt_deg = 0
focal_mm = 30
principal_jitter_px = 0
target_jitter_m = 0
"""
LENS = "[camera.distortion]\nprobability = 1.0\nk1 = -0.3\nk2 = 0.05\np1 = 0.0005\np2 = -0.0005\n"


def _make(text: str, index: int = 0):
    prod = SampleProducer(parse_recipe(text), threads=1)
    try:
        return prod.make(index)
    finally:
        prod.close()


def _recipe(lens: str) -> str:
    base = tiny_recipe(5, width=W, height=H, grid_px=96, spp=4, lidar=False)
    base = base.replace("[material]\ntexture_px = 64\n", "").replace(f"[camera]\nwidth_px = {W}\nheight_px = {H}\n"
                                                                      "distance_m = { min = 0.7, max = 0.9 }\n", "")
    return base + STRAIGHT + lens


@pytest.mark.blender
@pytest.mark.slow
def test_distortion_off_leaves_the_sample_as_it_was():
    plain = _make(tiny_recipe(3, lidar=False))
    off = _make(tiny_recipe(3, lidar=False) + "[camera.distortion]\nprobability = 0.0\n")
    assert "lens" not in plain.meta["spec"] and "dist" not in plain.meta["cameras"]["rgb"]
    assert encode_json(plain.meta) == encode_json(off.meta)  # the sample's JSON, byte for byte
    assert plain.members.keys() == off.members.keys()
    for k in plain.members:
        assert encode_member(k.rsplit(".", 1)[-1], plain.members[k]) == encode_member(k.rsplit(".", 1)[-1], off.members[k]), k


@pytest.mark.blender
@pytest.mark.slow
def test_a_distorted_sample_undistorts_to_its_pinhole_render_and_its_label_stays_on_the_crack():
    pin, lens = _make(_recipe("")), _make(_recipe(LENS))
    cam = lens.meta["cameras"]["rgb"]
    K, dist = np.array(cam["K"]), np.array(cam["dist"])
    assert np.allclose(K, pin.meta["cameras"]["rgb"]["K"]) and (cam["width"], cam["height"]) == (W, H)
    assert np.allclose(dist, [-0.3, 0.05, 0.0005, -0.0005, 0.0])  # OpenCV order k1, k2, p1, p2, k3
    assert min(cam["canvas"]["margins_ltrb"]) > 0  # barrel: rendered wider than the frame
    for name in ("rgb.png", "mask.png", "depth.exr", "tof.exr"):
        assert lens.members[name].shape[:2] == (H, W), name
    assert set(np.unique(lens.members["mask.png"])) <= {0, 255}
    tof = lens.members["tof.exr"]
    assert (tof[tof < 0] == -1).all()  # sparse holes stay -1 (nearest neighbour, never blended)

    # the label lands on the dark crack pixels of the distorted RGB
    label = lens.members["mask.png"] > 0
    assert label.sum() > 30
    assert label_contrast(lens.members["rgb.png"], label) > 0.3
    # the distortion moved the crack: the distorted label is not the pinhole label
    assert (label != (pin.members["mask.png"] > 0)).sum() > 20

    # undistorting with the exported K and coefficients gives back the pinhole render in the centre region
    c = (slice(H // 4, 3 * H // 4), slice(W // 4, 3 * W // 4))
    back = cv2.undistort(lens.members["mask.png"], K, dist)
    pin_mask = pin.members["mask.png"]
    ys, xs = np.nonzero(pin_mask[c] > 0)
    yb, xb = np.nonzero(back[c] > 127)
    assert ys.size > 10 and yb.size > 10
    assert abs(ys.mean() - yb.mean()) < 1.0 and abs(xs.mean() - xb.mean()) < 1.0
    grey = [cv2.cvtColor(x, cv2.COLOR_RGB2GRAY).astype(np.float32)[c]
            for x in (cv2.undistort(lens.members["rgb.png"], K, dist), pin.members["rgb.png"])]
    shift, _ = cv2.phaseCorrelate(grey[0], grey[1])
    assert np.hypot(*shift) < 1.0, shift
    d_back = cv2.undistort(lens.members["depth.exr"], K, dist, None, None)
    assert np.median(np.abs(d_back[c] - pin.members["depth.exr"][c])) < 2e-3  # metres


def test_a_lens_that_folds_back_is_refused_in_the_recipe():
    with pytest.raises(RecipeError, match="camera.distortion: k1 = -0.9"):
        parse_recipe(tiny_recipe(1) + "[camera.distortion]\nprobability = 0.5\nk1 = { min = -0.9, max = 0.0 }\n")
    parse_recipe(tiny_recipe(1) + "[camera.distortion]\nprobability = 0.5\n")  # the default ranges are fine


@pytest.mark.blender
@pytest.mark.slow
def test_the_bench_copy_of_the_linear_render_is_in_the_distorted_frame():
    """`crackgen bench --sweep` compares the scene-linear render with the label: both must be the output frame
    (the canvas is wider: a 272 px render against a 256 px label stopped a sweep of recipes/inspect.toml)."""
    prod = SampleProducer(parse_recipe(_recipe(LENS)), threads=1, keep_linear=True)
    try:
        s = prod.make(0)
    finally:
        prod.close()
    lum = s.rgb_linear.mean(axis=2)
    assert lum.shape == (H, W) and lum.dtype == np.float32
    label = s.members["mask.png"] > 0
    assert lum[label].mean() < 0.6 * lum[~label].mean()  # on the dark crack, as the label is
