"""Guided filter against brute force, guided-filter fusion of focus/exposure pairs, and the four metrics."""

import cv2
import numpy as np
import pytest

from fusion.image.fuse import ImageFusionError, fuse_images, fusion_weights
from fusion.image.guided_filter import GuidedFilterError, guided_filter
from fusion.image.metrics import q_c, q_g, q_mi, q_y


def _brute_guided(I, p, r, eps):
    """He et al.'s algorithm written out window by window (windows clipped at the border)."""
    h, w = p.shape
    a = np.zeros((h, w))
    b = np.zeros((h, w))
    for y in range(h):
        for x in range(w):
            wi = I[max(0, y - r):y + r + 1, max(0, x - r):x + r + 1]
            wp = p[max(0, y - r):y + r + 1, max(0, x - r):x + r + 1]
            mu, pm = wi.mean(), wp.mean()
            a[y, x] = ((wi * wp).mean() - mu * pm) / (wi.var() + eps)
            b[y, x] = pm - a[y, x] * mu
    q = np.zeros((h, w))
    for y in range(h):
        for x in range(w):
            sl = (slice(max(0, y - r), y + r + 1), slice(max(0, x - r), x + r + 1))
            q[y, x] = a[sl].mean() * I[y, x] + b[sl].mean()
    return q


def test_guided_filter_matches_brute_force():
    rng = np.random.default_rng(0)
    I = rng.random((12, 15))
    p = rng.random((12, 15))
    for r, eps in ((1, 0.01), (2, 0.1), (4, 1e-4)):
        np.testing.assert_allclose(guided_filter(I, p, r, eps), _brute_guided(I, p, r, eps), atol=1e-10)


def test_guided_filter_identities():
    rng = np.random.default_rng(1)
    I = rng.random((20, 20))
    assert np.abs(guided_filter(I, I, 2, 1e-9) - I).max() < 1e-5  # p = I, eps -> 0: edges kept exactly
    np.testing.assert_allclose(guided_filter(I, np.full((20, 20), 0.3), 3, 0.1), 0.3)  # constant stays
    colour = np.repeat(I[..., None], 3, axis=2) + rng.normal(0, 1e-3, (20, 20, 3))
    out = guided_filter(colour, rng.random((20, 20)), 2, 0.01)  # colour guide (3x3 covariance) runs
    assert out.shape == (20, 20) and np.isfinite(out).all()
    with pytest.raises(GuidedFilterError, match="eps"):
        guided_filter(I, I, 2, 0.0)


def _scene(n=128):
    rng = np.random.default_rng(2)
    img = cv2.GaussianBlur(rng.random((n, n)), (0, 0), 1.5)
    img = (img - img.min()) / np.ptp(img)
    img[:, n // 3: n // 3 + 3] = 1.0  # sharp lines
    img[2 * n // 3: 2 * n // 3 + 2, :] = 0.0
    return img


def _q(x):
    return np.round(255 * x)  # 8-bit, as written and read by ``cracktrain merge-stack``


def test_fusing_two_half_focused_copies_beats_either_input():
    img = _scene()
    blur = cv2.GaussianBlur(img, (0, 0), 3.0)
    a, b = img.copy(), img.copy()
    a[:, 64:] = blur[:, 64:]  # left half in focus
    b[:, :64] = blur[:, :64]  # right half in focus
    src = [_q(a), _q(b)]
    sharp = [_q(img), _q(img)]
    for levels in (2, 3):
        fused = _q(fuse_images([a, b], levels))
        # No-reference (sources -> fused), as the thesis scores: edges of both sources are kept.
        assert q_g(src, fused) > max(q_g(src, s) for s in src)
        # Against the all-in-focus original: more of its edges and information than either input.
        for metric in (q_g, q_mi):
            assert metric(sharp, fused) > max(metric(sharp, s) for s in src), (levels, metric.__name__)
        assert np.abs(fused - _q(img)).mean() < min(np.abs(s - _q(img)).mean() for s in src)


def test_fusing_two_exposures_keeps_more_edges_than_either_input():
    img = _scene()
    dark, bright = np.clip(1.4 * img - 0.5, 0, 1), np.clip(1.4 * img + 0.1, 0, 1)  # crushed shadows / highlights
    src = [_q(dark), _q(bright)]
    fused = _q(fuse_images([dark, bright], 3))
    assert q_g(src, fused) > max(q_g(src, s) for s in src)
    assert q_g([_q(img)] * 2, fused) > max(q_g([_q(img)] * 2, s) for s in src)
    # Q_MI cannot rank a fusion against its inputs: a copy of source A scores 1 + its MI with B by
    # construction (MI(A, A) / 2 H(A) = 1/2), and 256-bin MI favours any monotone remap of a source.
    assert q_mi(src, src[0]) >= 1.0


def test_fusion_identity_and_shapes():
    img = _scene(64)
    for levels in (2, 3):
        np.testing.assert_allclose(fuse_images([img, img], levels), img, atol=1e-9)  # identical inputs
        w = fusion_weights([img, 0.5 * img, img ** 2], levels)
        assert len(w) == levels and all(np.allclose(x.sum(axis=0), 1.0) for x in w)
    colour = np.stack([img, img[::-1], img.T], axis=-1)
    assert fuse_images([colour, 0.8 * colour], 2).shape == colour.shape
    with pytest.raises(ImageFusionError, match="sizes must match"):
        fuse_images([img, img[:32]])
    with pytest.raises(ImageFusionError, match="at least 2"):
        fuse_images([img])


def test_metrics_hand_computed():
    rng = np.random.default_rng(3)
    a = rng.integers(0, 256, (32, 32)).astype(np.float64)
    # Identical sources fused into themselves: every score at its maximum.
    assert q_y([a, a], a) == pytest.approx(1.0)
    assert q_c([a, a], a) == pytest.approx(1.0)
    assert q_mi([a, a], a) == pytest.approx(2.0)  # 2 [H / 2H + H / 2H]
    assert q_g([a, a], a) == pytest.approx(0.9994 / (1 + np.exp(-7.5)) * 0.9879 / (1 + np.exp(-4.4)))
    # Q_MI: two-level images, F independent of both sources -> 0; F equal to A, B = 1 - A -> 2 again.
    x = np.array([[0, 0], [255, 255]], float)
    f = np.array([[0, 255], [0, 255]], float)
    assert q_mi([x, x], f) == pytest.approx(0.0)
    assert q_mi([x, 255 - x], x) == pytest.approx(2.0)
    # Q_C on constant windows: equal means -> 1, different -> 0.
    c = np.full((16, 16), 100.0)
    assert q_c([c, c], c) == pytest.approx(1.0)
    assert q_c([c, c], c + 50) == pytest.approx(0.0)
    # Q_G: a flat fused image keeps no edge of the sources.
    assert q_g([a, a], np.full_like(a, 128.0)) < 0.01
