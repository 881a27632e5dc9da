"""Layered stereo composites: exact views and GT on fronto-parallel planes, SGBM agrees, seeded blobs."""
import numpy as np
import pytest
from scipy.ndimage import binary_erosion

from fusion.depth.layered_stereo import (
    LayeredStereoError,
    StereoView,
    composite,
    occluder_mask,
    right_view_mask,
)
from fusion.geometry.stereo import StereoInputError, occluded_from_disparity, search_range, sgbm_disparity

H, W = 96, 160


def plane(texture: np.ndarray, disp: int) -> StereoView:
    """A fronto-parallel plane at integer disparity ``disp``: right(u) = left(u + disp)."""
    left = np.repeat(texture[..., None], 3, axis=2)
    right = np.zeros_like(left)
    right[:, : W - disp] = left[:, disp:]
    right[:, W - disp:] = left[:, :disp][:, ::-1]  # anything: these right pixels see beyond the left view
    return StereoView(left, right, np.full((H, W), float(disp), np.float32))


@pytest.fixture(scope="module")
def scenes():
    rng = np.random.default_rng(3)
    return plane(rng.integers(0, 256, (H, W), dtype=np.uint8), 10), plane(rng.integers(0, 256, (H, W), dtype=np.uint8), 13)


def box_mask() -> np.ndarray:
    m = np.zeros((H, W), bool)
    m[30:70, 60:110] = True
    return m


def test_composite_views_and_gt_are_exact_on_planes(scenes):
    bg, fg = scenes
    view = composite(bg, fg, box_mask(), jump_px=12.0)  # foreground at 10 + 12 = 22 px
    np.testing.assert_array_equal(view.gt, np.where(box_mask(), 22.0, 10.0))
    inner = binary_erosion(box_mask(), iterations=2)
    outer = ~binary_erosion(~box_mask(), iterations=2)
    np.testing.assert_array_equal(view.left[inner], fg.left[inner])
    np.testing.assert_array_equal(view.left[~outer], bg.left[~outer])
    # right view: a point at left x with disparity d is at u = x - d
    ys, xs = np.nonzero(inner)
    np.testing.assert_array_equal(view.right[ys, xs - 22], fg.left[ys, xs])
    far = ~outer & ~np.roll(outer, -22, axis=1)  # background pixels the box hides in neither view
    ys, xs = np.nonzero(far[:, 10:])
    np.testing.assert_array_equal(view.right[ys, xs], bg.left[ys, xs + 10])


def test_right_view_mask_is_the_mask_shifted_by_its_disparity():
    m = box_mask()
    np.testing.assert_array_equal(right_view_mask(m, np.full((H, W), 22.0, np.float32)), np.roll(m, -22, axis=1))
    half = right_view_mask(m, np.full((H, W), 21.5, np.float32))  # between columns: both neighbours, no gap
    np.testing.assert_array_equal(half, np.roll(m, -22, axis=1) | np.roll(m, -21, axis=1))


def test_sgbm_on_a_composite_finds_both_layers_and_fails_where_the_background_is_hidden(scenes):
    bg, fg = scenes
    view = composite(bg, fg, box_mask(), jump_px=12.0)
    disp = sgbm_disparity(view.left, view.right, search_range(view.gt, W), 5)
    ok = disp > 0
    occluded = occluded_from_disparity(view.gt)
    occluded[:, :10] = False  # the background's own left band, outside the right image
    strip = np.zeros((H, W), bool)
    strip[30:70, 48:60] = True  # the box shifts 12 px more than the background: it hides the 12 columns left of it
    np.testing.assert_array_equal(occluded, strip)
    err = np.abs(disp - view.gt)
    inner = binary_erosion(box_mask(), iterations=4)
    assert np.median(err[inner & ok]) < 0.5 and np.mean(ok[inner]) > 0.9
    clear = binary_erosion(~box_mask(), iterations=5) & ~occluded  # background away from the box edge
    clear[:, :search_range(view.gt, W)] = False  # SGBM's own left band
    assert np.median(err[clear & ok]) < 0.5
    assert np.mean(ok[occluded] & (err[occluded] < 1)) < 0.5  # hidden background: SGBM has no right answer there


def test_occluder_mask_is_seeded_and_covers_the_drawn_share():
    a = occluder_mask((H, W), np.random.default_rng(1), area=(0.2, 0.3))
    np.testing.assert_array_equal(a, occluder_mask((H, W), np.random.default_rng(1), area=(0.2, 0.3)))
    assert not np.array_equal(a, occluder_mask((H, W), np.random.default_rng(2), area=(0.2, 0.3)))
    for seed in range(5):
        assert 0.19 <= occluder_mask((H, W), np.random.default_rng(seed), area=(0.2, 0.3)).mean() <= 0.31


def test_bad_inputs_raise(scenes):
    bg, fg = scenes
    with pytest.raises(LayeredStereoError, match="foreground left"):
        composite(bg, StereoView(fg.left[:-1], fg.right, fg.gt), box_mask(), 5.0)
    with pytest.raises(LayeredStereoError, match="GT"):
        composite(bg, StereoView(fg.left, fg.right, np.full((H, W), -1, np.float32)), box_mask(), 5.0)
    with pytest.raises(StereoInputError, match="wider than 16"):
        search_range(bg.gt, 16)
    assert search_range(bg.gt, W) == 32 and search_range(bg.gt + 40, W) == 80 and search_range(bg.gt + 200, W) == 144
