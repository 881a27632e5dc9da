"""Image error figures on hand-made images with known answers."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crackgen.tools.image_error import crack_error, crack_region, image_error, psnr_linear, ssim_srgb


def test_psnr_of_a_constant_offset_is_known():
    ref = np.full((16, 16, 3), 0.5, np.float32)
    assert psnr_linear(ref + 0.01, ref) == pytest.approx(40.0, abs=1e-3)  # 10 log10(1 / 1e-4)
    assert psnr_linear(ref, ref) == math.inf


def test_ssim_is_one_for_equal_images_and_drops_with_noise():
    rng = np.random.default_rng(0)
    ref = rng.random((32, 32, 3), dtype=np.float32)
    assert ssim_srgb(ref, ref) == pytest.approx(1.0)
    noise = rng.normal(0, 1, ref.shape).astype(np.float32)
    a, b = ssim_srgb(ref + 0.02 * noise, ref), ssim_srgb(ref + 0.2 * noise, ref)
    assert 1.0 > a > b


def test_crack_region_is_the_mask_grown_by_the_dilation():
    mask = np.zeros((9, 9), np.uint8)
    mask[4, 4] = 255
    assert crack_region(mask, 0).sum() == 1
    assert crack_region(mask, 2).sum() == 25


def test_crack_error_sees_only_the_crack_region():
    ref = np.full((20, 20, 3), 0.4, np.float32)
    img = ref.copy()
    img[:, :10] += 0.2  # error left half only
    mask = np.zeros((20, 20), np.uint8)
    mask[5:8, 15:18] = 255  # crack in the right half
    e = image_error(img, ref, mask, dilate_px=1)
    assert e["crack_mae"] == 0.0 and e["crack_psnr"] == math.inf and e["crack_px"] == 25
    mask[5:8, 2:5] = 255  # now also on the left: 25 of 50 pixels off by 0.2
    assert crack_error(img, ref, crack_region(mask, 1))["crack_mae"] == pytest.approx(0.1, abs=1e-6)
    assert math.isnan(crack_error(img, ref, np.zeros((20, 20), bool))["crack_mae"])


def test_mismatched_shapes_are_refused():
    with pytest.raises(ValueError, match="must both be"):
        psnr_linear(np.zeros((4, 4, 3)), np.zeros((4, 5, 3)))
