"""crackgen.procedural.crackmap: thesis eq. 5.3-5.6, determinism, resolution independence, UV lookups."""

import dataclasses

import numpy as np
import pytest

from crackgen.config.recipe import Recipe
from crackgen.config.spec import CrackSpec, SampleSpec, make_spec
from crackgen.procedural.crackmap import CrackMapError, crack_map, depth_at_uv, mask_at_uv, texel_centres
from crackgen.procedural.noise import fbm
from fusion.measure.crack_length import crack_components


def _spec(**over) -> CrackSpec:
    base = CrackSpec(
        freq_x=2.5, freq_y=3.0, octaves=4, persistence=0.5, lacunarity=2.0,
        threshold=0.04, depth_m=0.01, noise_seed=1234, offset_u=17.3, offset_v=-4.1,
    )  # fmt: skip
    return dataclasses.replace(base, **over)


def test_follows_the_equations():
    s = _spec()
    cm = crack_map(s, 128, 2.0)
    assert cm.z.dtype == cm.disp.dtype == cm.depth_m.dtype == np.float32
    assert cm.z.shape == cm.mask.shape == (128, 128)
    assert np.all(cm.z >= 0)
    assert np.array_equal(cm.mask, cm.z < np.float32(s.threshold))
    assert 0.01 < cm.coverage < 0.5
    assert np.all(cm.disp >= 0) and np.all(cm.disp[~cm.mask] == 0)
    assert cm.disp.max() <= s.threshold
    np.testing.assert_allclose(cm.disp[cm.mask], s.threshold - cm.z[cm.mask], atol=1e-7)
    np.testing.assert_allclose(cm.depth_m, cm.disp / s.threshold * s.depth_m, rtol=1e-5, atol=1e-9)
    assert cm.depth_m.max() <= s.depth_m * (1 + 1e-6)


def test_z_is_abs_fbm_at_texel_centres():
    s = _spec()
    n = 64
    cm = crack_map(s, n, 1.0, measure=False)
    for j, i in [(0, 0), (10, 40), (63, 63)]:
        u = np.array([(i + 0.5) / n * s.freq_x + s.offset_u])
        v = np.array([(j + 0.5) / n * s.freq_y + s.offset_v])
        ref = abs(fbm(u, v, s.noise_seed, s.octaves, s.persistence, s.lacunarity)[0, 0])
        assert cm.z[j, i] == pytest.approx(ref, abs=1e-6)
    np.testing.assert_allclose(texel_centres(4), [0.125, 0.375, 0.625, 0.875])


def test_determinism_and_sensitivity():
    s = _spec()
    a = crack_map(s, 96, 2.0)
    b = crack_map(_spec(), 96, 2.0)
    assert np.array_equal(a.z, b.z) and np.array_equal(a.mask, b.mask) and a.length_m == b.length_m
    for other in (_spec(noise_seed=1235), _spec(offset_u=17.8), _spec(offset_v=-3.6)):
        c = crack_map(other, 96, 2.0, measure=False)
        assert np.abs(c.z - a.z).mean() > 0.02
        assert not np.array_equal(c.mask, a.mask)


def test_spec_json_roundtrip_gives_same_map():
    spec = make_spec(Recipe(), 3)
    again = SampleSpec.from_json(spec.to_json())
    a = crack_map(spec.crack, 64, spec.surface.size_m, measure=False)
    b = crack_map(again.crack, 64, spec.surface.size_m, measure=False)
    assert np.array_equal(a.z, b.z)


def test_resolution_independence_exact_at_3x():
    # The centre of texel k at N is the centre of texel 3k+1 at 3N, so the maps agree there.
    s = _spec(octaves=6)
    lo = crack_map(s, 64, 2.0, measure=False)
    hi = crack_map(s, 192, 2.0, measure=False)
    np.testing.assert_allclose(hi.z[1::3, 1::3], lo.z, atol=2e-6)


@pytest.mark.parametrize("index", [0, 1])
def test_resolution_independence_512_vs_1024(index):
    # 1024 texel centres sit a quarter 512-texel either side of the 512 centre; the 2x2 mean
    # cancels the linear term, leaving curvature and |.|-kink errors.  Those are tiny on
    # average (< 1 % of the field's std) but large at single pixels where the finest octave
    # is near the 512 Nyquist limit, so we bound the mean error and require a high mask IoU.
    s = make_spec(Recipe(), index).crack
    a = crack_map(s, 512, 2.0, measure=False)
    b = crack_map(s, 1024, 2.0, measure=False)
    zb = b.z.reshape(512, 2, 512, 2).mean(axis=(1, 3))
    assert np.abs(zb - a.z).mean() < 0.01 * a.z.std()
    mb = b.mask.reshape(512, 2, 512, 2).mean(axis=(1, 3)) >= 0.5
    iou = (mb & a.mask).sum() / (mb | a.mask).sum()
    assert iou > 0.8


def test_gt_length_metric_and_scale():
    s = _spec()
    cm = crack_map(s, 256, 2.0)
    assert cm.length_m > 0
    assert cm.length_m == pytest.approx(sum(c.path_length for c in crack_components(cm.mask, 2.0 / 256)))
    assert cm.skeleton is not None and cm.skeleton.sum() > 0 and not np.any(cm.skeleton & ~cm.mask)
    # Same noise (same u, v) on a patch twice as big: same mask, twice the metres.
    big = crack_map(s, 256, 4.0)
    assert np.array_equal(big.mask, cm.mask)
    assert big.length_m == pytest.approx(2 * cm.length_m)
    # Skeleton length never exceeds the number of skeleton texels times the texel diagonal.
    assert cm.length_m <= cm.skeleton.sum() * cm.texel_m * np.sqrt(2)
    skip = crack_map(s, 256, 2.0, measure=False)
    assert skip.skeleton is None and np.isnan(skip.length_m)


def test_uv_lookups():
    s = _spec()
    n = 64
    cm = crack_map(s, n, 2.0, measure=False)
    t = texel_centres(n)
    uu, vv = np.meshgrid(t, t)  # [j, i]
    assert np.array_equal(mask_at_uv(cm, uu, vv), cm.mask)
    np.testing.assert_allclose(depth_at_uv(cm, uu, vv), cm.depth_m, atol=1e-9)
    # Texel [j, i] covers u in [i/N, (i+1)/N): its lower edge belongs to it.
    assert mask_at_uv(cm, np.array([5 / n]), np.array([7 / n]))[0] == cm.mask[7, 5]
    # Clamping outside [0, 1].
    assert mask_at_uv(cm, np.array([-0.2, 1.0, 1.7]), np.array([0.5, 0.5, 0.5])).tolist() == [
        cm.mask[32, 0], cm.mask[32, n - 1], cm.mask[32, n - 1]
    ]  # fmt: skip
    # Bilinear: half-way between two texel centres along u is the mean.
    mid = depth_at_uv(cm, np.array([(10 + 1.0) / n]), np.array([t[20]]))[0]
    assert mid == pytest.approx(0.5 * (cm.depth_m[20, 10] + cm.depth_m[20, 11]), abs=1e-9)
    corner = depth_at_uv(cm, np.array([0.0, 1.0]), np.array([0.0, 1.0]))
    np.testing.assert_allclose(corner, [cm.depth_m[0, 0], cm.depth_m[-1, -1]], atol=1e-9)
    with pytest.raises(CrackMapError, match="same shape"):
        mask_at_uv(cm, np.zeros(3), np.zeros(4))


@pytest.mark.parametrize(
    "kwargs, over, word",
    [
        ({"size_px": 1}, {}, "size_px"),
        ({"size_m": 0.0}, {}, "size_m"),
        ({}, {"threshold": 0.0}, "threshold"),
        ({}, {"depth_m": -0.01}, "depth_m"),
        ({}, {"freq_x": 0.0}, "freq_x"),
    ],
)
def test_bad_arguments(kwargs, over, word):
    args = {"size_px": 32, "size_m": 1.0} | kwargs
    with pytest.raises(CrackMapError, match=word):
        crack_map(_spec(**over), **args)
