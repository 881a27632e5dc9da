"""Fusion rules, confidence targets, metrics, densifier and post-filters on hand-made maps."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fusion.depth.confidence import FusionRuleError, confidence_target, fuse_max, fuse_weighted, softmax_weights
from fusion.depth.densify import DensifyError, interpolate_sparse
from fusion.depth.inputs import FusionInputError, build_inputs
from fusion.depth.metrics import average_metrics, disparity_metrics, format_table
from fusion.depth.postfilter import PostFilter, PostFilterError, bm3d_disparity, clahe_disparity


def test_confidence_target_is_exp_of_minus_abs_error_and_masks_missing_values():
    d = np.array([[10.0, 12.0], [-1.0, 10.5]], np.float32)
    gt = np.array([[10.0, 10.0], [10.0, -1.0]], np.float32)
    c = confidence_target(d, gt)
    assert c[0, 0] == pytest.approx(1.0)
    assert c[0, 1] == pytest.approx(math.exp(-2.0))
    assert c[1, 0] == 0.0  # no estimate: zero confidence
    assert np.isnan(c[1, 1])  # no GT: not scored


def test_max_rule_takes_the_more_confident_value_ties_to_the_other_sensor():
    ds = np.array([[1.0, 2.0, 3.0, -1.0, 5.0]], np.float32)
    do = np.array([[10.0, 20.0, 30.0, 40.0, -1.0]], np.float32)
    cs = np.array([[0.9, 0.1, 0.5, 0.9, 0.1]], np.float32)
    co = np.array([[0.1, 0.9, 0.5, 0.1, 0.9]], np.float32)
    np.testing.assert_array_equal(fuse_max(ds, do, cs, co), [[1.0, 20.0, 30.0, 40.0, 5.0]])
    none = np.full((1, 1), -1.0, np.float32)
    assert fuse_max(none, none, np.zeros((1, 1)), np.zeros((1, 1)))[0, 0] == -1.0
    with pytest.raises(FusionRuleError):
        fuse_max(ds, do[:, :3], cs, co)


def test_weighted_rule_is_the_softmax_mean():
    ds, do = np.array([[2.0, 2.0, -1.0]], np.float32), np.array([[4.0, 4.0, 7.0]], np.float32)
    cs, co = np.array([[0.0, 1.0, 0.0]], np.float32), np.array([[0.0, 0.0, 0.0]], np.float32)
    ws, wo = softmax_weights(cs, co)
    np.testing.assert_allclose(ws + wo, 1.0)
    e = math.e
    expected = [3.0, (2.0 * e + 4.0) / (e + 1.0), 7.0]  # equal weights; e:1; stereo missing -> ToF as is
    np.testing.assert_allclose(fuse_weighted(ds, do, cs, co)[0], expected, rtol=1e-6)


def test_metrics_on_a_hand_made_map():
    gt = np.array([[10.0, 10.0, 10.0, 10.0, -1.0, 10.0]], np.float32)
    est = np.array([[10.5, 11.5, 12.5, 16.0, 3.0, -1.0]], np.float32)
    m = disparity_metrics(est, gt)  # scored: errors 0.5, 1.5, 2.5, 6 (no GT at 4, no estimate at 5)
    err = np.array([0.5, 1.5, 2.5, 6.0])
    assert m["mae"] == pytest.approx(err.mean())
    assert m["mse"] == pytest.approx((err**2).mean())
    assert m["rmse"] == pytest.approx(math.sqrt((err**2).mean()))
    assert (m["bad1"], m["bad2"], m["bad3"], m["bad5"]) == (75.0, 50.0, 25.0, 25.0)
    assert m["density"] == pytest.approx(4 / 5)
    m2 = disparity_metrics(gt, gt)
    avg = average_metrics([m, m2])
    assert avg["mae"] == pytest.approx(err.mean() / 2)
    assert "| stereo | " in format_table({"stereo": avg})
    empty = disparity_metrics(np.full_like(gt, -1.0), gt)
    assert math.isnan(empty["mae"]) and empty["density"] == 0.0


@pytest.mark.parametrize("method", ["normconv", "nearest"])
def test_densify_fills_holes_and_keeps_measurements(method):
    yy, xx = np.mgrid[:40, :50]
    plane = (20 + 0.1 * xx + 0.05 * yy).astype(np.float32)
    measured = np.random.default_rng(0).random(plane.shape) < 0.2
    sparse = np.where(measured, plane, -1.0).astype(np.float32)
    dense = interpolate_sparse(sparse, method)
    assert (dense > 0).all()
    np.testing.assert_array_equal(dense[measured], plane[measured])
    tol = 0.3 if method == "nearest" else 0.1
    assert np.abs(dense - plane).mean() < tol
    with pytest.raises(DensifyError):
        interpolate_sparse(sparse, "linear")


def test_bm3d_denoises_a_plane_and_clahe_keeps_holes():
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[:48, :48]
    plane = (25 + 0.05 * xx + 0.02 * yy).astype(np.float32)
    noisy = plane + rng.normal(0, 0.5, plane.shape).astype(np.float32)
    noisy[0, 0] = -1.0
    den = bm3d_disparity(noisy, 0.5)
    ok = noisy > 0
    assert den[0, 0] == -1.0
    assert np.abs(den - plane)[ok].mean() < 0.5 * np.abs(noisy - plane)[ok].mean()
    cl = clahe_disparity(noisy)
    assert cl[0, 0] == -1.0 and (cl[ok] > 0).all()
    with pytest.raises(PostFilterError):
        PostFilter("median")
    with pytest.raises(PostFilterError):
        PostFilter("bm3d", "during")


def test_inputs_have_the_variant_channels_and_dense_candidates():
    rng = np.random.default_rng(1)
    h, w = 24, 40
    left = rng.integers(0, 255, (h, w, 3), dtype=np.uint8)
    right = np.roll(left, -4, axis=1)  # disparity 4 px everywhere
    stereo = np.full((h, w), 4.0, np.float32)
    stereo[:, :4] = -1.0
    tof = np.full((h, w), -1.0, np.float32)
    tof[::2, ::2] = 4.2
    amp = np.where(tof > 0, 0.3, -1.0).astype(np.float32)
    x = build_inputs("tof", stereo, tof, left, right, amp).x
    assert x.shape == (h, w, 4) and (x[..., 0] > 0).all() and (x[..., 1] > 0).all() and (x[..., 3] >= 0).all()
    assert np.abs(x[:, 4:, 2]).max() == 0  # left minus right warped by the right disparity vanishes
    x3 = build_inputs("lidar", stereo, tof, left, right).x
    assert x3.shape == (h, w, 3)
    with pytest.raises(FusionInputError):
        build_inputs("tof", stereo, tof, left, right, None)
    with pytest.raises(FusionInputError):
        build_inputs("lidar", stereo, tof[:10], left, right)


def test_scanline_lidar_samples_the_gt_on_evenly_spaced_rows():
    from fusion.depth.scanline_lidar import scanline_lidar

    gt = np.full((50, 30), 12.0, np.float32)
    gt[:, :3] = -1.0  # no GT: no return
    lid = scanline_lidar(gt, 5, np.random.default_rng(0), sigma_px=0.0, dropout=0.0)
    rows = np.flatnonzero((lid > 0).any(axis=1))
    np.testing.assert_array_equal(rows, [0, 12, 24, 37, 49])
    assert (lid[rows][:, 3:] == 12.0).all() and (lid[:, :3] == -1).all()
    noisy = scanline_lidar(gt, 5, np.random.default_rng(0), sigma_px=0.5, dropout=0.5)
    hit = noisy > 0
    assert 0.3 < hit[rows][:, 3:].mean() < 0.7 and 0.3 < np.std(noisy[hit] - 12.0) < 0.7


def test_random_scanline_lidar_draws_its_quality_in_range_and_is_seeded():
    from fusion.depth.scanline_lidar import random_scanline_lidar

    gt = np.full((200, 40), 20.0, np.float32)
    draws = [random_scanline_lidar(gt, np.random.default_rng(s)) for s in range(40)]
    for lid, p in draws:
        rows = np.flatnonzero((lid > 0).any(axis=1))
        assert 10 <= p["lines"] <= 50 and len(rows) <= p["lines"]  # 4-20 rows apart on 200 rows
        assert 0.05 <= p["sigma_px"] <= 1.0 and 0.0 <= p["dropout"] <= 0.3
        assert abs(np.std(lid[lid > 0] - 20.0) - p["sigma_px"]) < 0.25 * p["sigma_px"] + 0.02
    assert len({p["lines"] for _, p in draws}) > 10  # the density really varies
    a, pa = random_scanline_lidar(gt, np.random.default_rng(7))
    b, pb = random_scanline_lidar(gt, np.random.default_rng(7))
    assert pa == pb and np.array_equal(a, b)
