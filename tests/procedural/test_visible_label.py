"""Visible-crack label on hand-made V-grooves: the width follows depth >= max(min_depth, ratio * half-width)."""
from __future__ import annotations

import numpy as np
import pytest

from crackgen.config.recipe import LabelSection
from crackgen.config.spec import CrackSpec
from crackgen.procedural.crackmap import CrackMap
from crackgen.procedural.visible_label import (
    VisibleLabelError,
    drop_small_components,
    local_half_width,
    visible_mask,
)
from crackgen.sim.groundtruth import label_texels

N, TEXEL_M = 200, 0.001  # 0.2 m patch, 1 mm texels
HALF_T = 20.5  # groove half-width (texels): crack texels 80..120, 41 texels = 41 mm
DEPTH = 0.03  # centre depth (m)
SPEC = CrackSpec(freq_x=1, freq_y=1, octaves=1, persistence=0.5, lacunarity=2, threshold=0.1, depth_m=DEPTH,
                 noise_seed=0, offset_u=0, offset_v=0)


def v_groove(depth=DEPTH, half_t=HALF_T):
    """Straight groove along v centred on texel column 100; depth falls linearly to 0 at the edge."""
    k = np.arange(N)
    d = np.clip(1.0 - np.abs(k - 100) / half_t, 0, None) * depth
    depth_m = np.tile(d.astype(np.float32), (N, 1))
    return depth_m > 0, depth_m


MID = slice(50, 150)  # rows away from the groove's ends (where the skeleton forks into the corners)


def label_width_mm(label):
    label = label[MID]
    cols = np.nonzero(label.any(axis=0))[0]
    assert (label[:, cols].all(axis=0)).all(), "a straight groove must give full label columns"
    return len(cols) * TEXEL_M * 1000


def expected_width_mm(ratio, min_depth):
    w = HALF_T * TEXEL_M
    need = max(min_depth, ratio * w)
    return max(0.0, 2 * w * (1 - need / DEPTH)) * 1000


def test_local_half_width_of_a_groove_is_its_geometric_half_width():
    mask, _ = v_groove()
    w = local_half_width(mask, TEXEL_M)
    assert np.allclose(w[MID][mask[MID]], HALF_T * TEXEL_M)  # every crack texel gets the centreline's half-width
    assert (w[~mask] == 0).all()
    assert np.median(w[mask]) == pytest.approx(HALF_T * TEXEL_M)


@pytest.mark.parametrize("ratio, min_depth", [(0.5, 0.002), (1.0, 0.0), (0.0, 0.015), (0.25, 0.012)])
def test_label_width_follows_the_rule(ratio, min_depth):
    mask, depth = v_groove()
    lab = visible_mask(mask, depth, TEXEL_M, depth_ratio=ratio, min_depth_m=min_depth)
    assert not (lab & ~mask).any()
    want = expected_width_mm(ratio, min_depth)  # 27, 13, 20.5, 20.5 mm
    assert abs(label_width_mm(lab) - want) <= 1.0 + 1e-9, (label_width_mm(lab), want)
    # the label is the centre band: symmetric about the groove centre
    cols = np.nonzero(lab[MID].any(axis=0))[0]
    assert cols.min() + cols.max() == 200


def test_shallow_wide_groove_has_no_visible_label_and_thesis_policy_keeps_it_all():
    mask, depth = v_groove(depth=0.008)  # 41 mm wide, 8 mm deep: a soft dip, not a crack
    lab = visible_mask(mask, depth, TEXEL_M, depth_ratio=0.5, min_depth_m=0.002)
    assert not lab.any()
    cm = CrackMap(z=np.zeros_like(depth), mask=mask, disp=depth, depth_m=depth, skeleton=None,
                  length_m=0.2, size_m=N * TEXEL_M, spec=SPEC)
    thesis = label_texels(LabelSection(policy="thesis"), cm)
    assert label_width_mm(thesis) == pytest.approx(2 * HALF_T)  # thesis = the full groove width, 41 mm
    deep = v_groove(depth=0.05)
    cm_deep = CrackMap(z=np.zeros_like(deep[1]), mask=deep[0], disp=deep[1], depth_m=deep[1], skeleton=None,
                       length_m=0.2, size_m=N * TEXEL_M, spec=SPEC)
    vis = label_texels(LabelSection(policy="visible", depth_ratio=0.5, min_depth_m=0.002), cm_deep)
    w = HALF_T * TEXEL_M
    assert abs(label_width_mm(vis) - 2 * w * (1 - 0.5 * w / 0.05) * 1000) <= 1.0


def test_narrow_deep_crack_is_labelled_nearly_whole():
    mask, depth = v_groove(depth=0.02, half_t=2.5)  # 5 mm wide, 20 mm deep: a dark gap
    lab = visible_mask(mask, depth, TEXEL_M, depth_ratio=1.0, min_depth_m=0.002)
    assert label_width_mm(lab) == pytest.approx(5.0)  # offsets 0, +-1, +-2: depth 20, 12, 4 mm >= 2.5 mm


def test_bad_arguments_name_the_field():
    mask, depth = v_groove()
    with pytest.raises(VisibleLabelError, match="depth_ratio"):
        visible_mask(mask, depth, TEXEL_M, depth_ratio=-1, min_depth_m=0)
    with pytest.raises(VisibleLabelError, match="shape"):
        visible_mask(mask, depth[:10], TEXEL_M, depth_ratio=1, min_depth_m=0)


def test_small_components_are_dropped_and_the_rest_kept_exactly():
    lab = np.zeros((20, 30), np.uint8)
    lab[2:4, 2:3] = 255  # 2 px
    lab[10, 5:25] = 255  # 20 px line
    lab[15:17, 20:22] = 255  # 4 px square
    out = drop_small_components(lab, 4)
    assert out[2:4, 2].sum() == 0
    np.testing.assert_array_equal(out[10], lab[10])
    np.testing.assert_array_equal(out[15:17, 20:22], lab[15:17, 20:22])
    assert np.count_nonzero(out) == 24
    np.testing.assert_array_equal(drop_small_components(lab, 0), lab)
