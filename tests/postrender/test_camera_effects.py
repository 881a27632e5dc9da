"""Camera effects: each effect does what its formula says on hand-made images; views stay identical;
labels, depth and sensors pass through untouched; off is the identity; draws are deterministic."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from crackgen.config.recipe import RecipeError, parse_recipe
from crackgen.config.spec import CameraEffectsSpec, make_spec
from crackgen.postrender import camera_effects as ce
from crackgen.postrender.stage import camera_effects_members

ALL_ON = "\n".join(f"{e} = 1.0" for e in ce.EFFECTS)


def spec(*applied: str, **values) -> CameraEffectsSpec:
    return CameraEffectsSpec(enabled=True, applied=list(applied), **values)


def flat(value: int, h: int = 64, w: int = 80) -> np.ndarray:
    return np.full((h, w, 3), value, np.uint8)


def textured(seed: int = 0, h: int = 96, w: int = 128) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.clip(rng.normal(120, 50, (h, w, 3)), 0, 255).astype(np.uint8)


def hf_energy(img: np.ndarray) -> float:
    g = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY).astype(np.float64)
    return float(cv2.Laplacian(g, cv2.CV_64F)[4:-4, 4:-4].var())


# ---- identity and round trip ----------------------------------------------------------------------

def test_all_off_is_the_identity():
    img = textured()
    for s in (CameraEffectsSpec(), spec(), CameraEffectsSpec(enabled=False, applied=["jpeg"], jpeg_quality=10)):
        (out,) = ce.apply_camera_effects([img], s)
        assert out is img or np.array_equal(out, img)


def test_srgb_round_trip_is_exact_for_every_8bit_value():
    v = np.arange(256, dtype=np.uint8).reshape(1, 256, 1).repeat(3, axis=2)
    assert np.array_equal(ce.quantise(ce.linear_to_srgb(ce.srgb_to_linear(v))), v)
    (out,) = ce.apply_camera_effects([v], spec("exposure", exposure_ev=0.0))  # the full path with a neutral effect
    assert np.array_equal(out, v)


# ---- each effect ----------------------------------------------------------------------------------

def test_plus_one_ev_doubles_linear_light_until_it_clips():
    v = np.arange(256, dtype=np.uint8).reshape(1, 256, 1).repeat(3, axis=2)
    (out,) = ce.apply_camera_effects([v], spec("exposure", exposure_ev=1.0))
    lin_in, lin_out = ce.srgb_to_linear(v), ce.srgb_to_linear(out)
    below = 2 * lin_in < 0.99
    np.testing.assert_allclose(lin_out[below], 2 * lin_in[below], rtol=0.03, atol=2e-3)
    assert (out[~(2 * lin_in <= 1.0)] == 255).all()
    (dark,) = ce.apply_camera_effects([v], spec("exposure", exposure_ev=-1.0))
    np.testing.assert_allclose(ce.srgb_to_linear(dark), lin_in / 2, rtol=0.03, atol=2e-3)


@pytest.mark.parametrize("start, target", [(40, 150), (200, 110), (120, 120)])
def test_auto_exposure_brings_the_mean_luma_to_its_target(start, target):
    rng = np.random.default_rng(3)
    img = np.clip(rng.normal(start, 0.15 * start, (96, 128, 3)), 0, 255).astype(np.uint8)
    (out,) = ce.apply_camera_effects([img], spec("auto_exposure", auto_exposure_luma=float(target)))
    luma = cv2.cvtColor(out, cv2.COLOR_RGB2GRAY).astype(np.float64).mean()
    assert luma == pytest.approx(target, abs=2.5)
    g = ce.auto_exposure_gain(img, target)
    assert (g > 1) == (target > cv2.cvtColor(img, cv2.COLOR_RGB2GRAY).mean() + 3) or start == target


def test_auto_exposure_is_one_gain_for_every_view_and_recorded():
    left, right = textured(4), textured(5)
    s = spec("auto_exposure", auto_exposure_luma=170.0)
    out_l, out_r = ce.apply_camera_effects([left, right], s)
    g = ce.auto_exposure_gain(left, 170.0)
    for src, out in ((left, out_l), (right, out_r)):  # the left view's gain on both, not each its own
        np.testing.assert_array_equal(out, ce.quantise(ce.linear_to_srgb(ce.srgb_to_linear(src) * np.float32(g))))
    _, meta = camera_effects_members(s, {"rgb.png": left, "right.png": right})
    assert meta["auto_exposure_luma"] == 170.0 and meta["auto_exposure_ev"] == pytest.approx(np.log2(g), abs=1e-4)


def test_auto_exposure_draws_leave_the_other_effects_unchanged():
    base = "[camera_effects]\nenabled = true\n"
    a = [make_spec(parse_recipe(base), i).camera_effects for i in range(20)]
    b = [make_spec(parse_recipe(base + "auto_exposure = 1.0\n"), i).camera_effects for i in range(20)]
    for x, y in zip(a, b):
        assert y.applied[0] == "auto_exposure" and y.applied[1:] == x.applied and 100 <= y.auto_exposure_luma <= 180
        assert {k: v for k, v in vars(y).items() if k not in ("applied", "auto_exposure_luma")} == \
            {k: v for k, v in vars(x).items() if k not in ("applied", "auto_exposure_luma")}


def test_stage_order_matches_the_spec_order():
    from crackgen.config.spec import CAMERA_EFFECTS_ORDER

    assert CAMERA_EFFECTS_ORDER == ce.EFFECTS


def test_vignetting_darkens_corners_not_the_centre():
    img = flat(180, 65, 81)
    (out,) = ce.apply_camera_effects([img], spec("vignetting", vignette_strength=0.4))
    lin_in, lin_out = ce.srgb_to_linear(img)[..., 0], ce.srgb_to_linear(out)[..., 0]
    assert abs(int(out[32, 40, 0]) - 180) <= 1  # centre unchanged
    for y, x in ((0, 0), (0, 80), (64, 0), (64, 80)):
        assert lin_out[y, x] == pytest.approx(0.6 * lin_in[y, x], rel=0.02)
    g = ce.vignette_gain(65, 81, 0.4)
    assert g[32, 40] == pytest.approx(1.0) and g.min() == pytest.approx(0.6)
    assert (np.diff(g[32, 40:]) < 0).all()  # falls monotonically outward


def test_white_balance_gains_follow_the_colour_temperature():
    assert np.allclose(ce.white_balance_gains(0.0, 0.0), 1.0)
    warm, cool = ce.white_balance_gains(40.0, 0.0), ce.white_balance_gains(-40.0, 0.0)
    assert warm[0] > 1.0 > warm[2] and cool[2] > 1.0 > cool[0] and warm[1] == cool[1] == 1.0
    assert ce.white_balance_gains(0.0, 0.1)[1] == pytest.approx(1.1)
    img = flat(100)
    (out,) = ce.apply_camera_effects([img], spec("white_balance", wb_shift_mired=40.0))
    lin = ce.srgb_to_linear(out)[0, 0]
    np.testing.assert_allclose(lin, ce.srgb_to_linear(img)[0, 0] * warm, rtol=0.02)


def test_tone_curve_is_monotone_and_neutral_at_gamma_1_contrast_0():
    x = np.linspace(0, 1, 1001, dtype=np.float32)
    np.testing.assert_allclose(ce.tone_curve(x, 1.0, 0.0), x, atol=1e-6)
    for g, c in ((0.8, -1.0), (1.25, 1.0), (1.0, 0.5)):
        y = ce.tone_curve(x, g, c)
        assert (np.diff(y) >= -1e-7).all() and y[0] == pytest.approx(0) and y[-1] == pytest.approx(1)
    s = ce.tone_curve(x, 1.0, 0.5)
    assert s[250] < x[250] and s[750] > x[750]  # an S: darker shadows, brighter highlights


@pytest.mark.parametrize("blur", [
    spec("defocus", defocus_kernel="disk", defocus_radius_px=2.0),
    spec("defocus", defocus_kernel="gaussian", defocus_radius_px=2.0),
    spec("motion_blur", motion_length_px=5.0, motion_angle_deg=30.0),
], ids=["disk", "gaussian", "motion"])
def test_blur_lowers_high_frequency_energy_and_keeps_flat_areas(blur):
    img = textured()
    (out,) = ce.apply_camera_effects([img], blur)
    assert hf_energy(out) < 0.3 * hf_energy(img)
    (f,) = ce.apply_camera_effects([flat(140)], blur)
    assert np.abs(f.astype(int) - 140).max() <= 1  # kernels sum to 1, borders reflected


def test_sharpen_raises_high_frequency_energy_keeps_flat_areas_and_adds_no_colour():
    blurred = cv2.GaussianBlur(textured(), (0, 0), 1.5)  # a soft render
    (out,) = ce.apply_camera_effects([blurred], spec("sharpen", sharpen_amount=1.5, sharpen_sigma_px=1.0))
    assert hf_energy(out) > 2.0 * hf_energy(blurred)
    (f,) = ce.apply_camera_effects([flat(140)], spec("sharpen", sharpen_amount=2.0, sharpen_sigma_px=1.0))
    assert np.abs(f.astype(int) - 140).max() <= 1
    grey = np.repeat(blurred[..., :1], 3, axis=2)  # a grey image stays grey: the detail is luma, added to R, G, B alike
    (g,) = ce.apply_camera_effects([grey], spec("sharpen", sharpen_amount=2.0, sharpen_sigma_px=1.0))
    assert np.array_equal(g[..., 0], g[..., 1]) and np.array_equal(g[..., 1], g[..., 2])


def test_sharpen_overshoots_both_sides_of_an_edge_and_zero_amount_is_neutral():
    x = np.full((1, 41), 0.3, np.float32)
    x[:, 20:] = 0.6
    edge = np.repeat(x[..., None], 3, axis=2)
    y = ce.unsharp_luma(edge, 1.0, 1.5)[0, :, 0]
    assert y[19] < 0.3 - 0.02 and y[20] > 0.6 + 0.02  # the dark side darker, the bright side brighter
    assert y[0] == pytest.approx(0.3, abs=1e-6) and y[-1] == pytest.approx(0.6, abs=1e-6)
    np.testing.assert_allclose(ce.unsharp_luma(edge, 0.0, 1.5), edge, atol=1e-7)


def test_sharpen_draws_leave_the_other_effects_unchanged():
    base = "[camera_effects]\nenabled = true\nauto_exposure = 0.5\n"
    a = [make_spec(parse_recipe(base), i).camera_effects for i in range(20)]
    b = [make_spec(parse_recipe(base + "sharpen = 1.0\nsharpen_amount = {min = 1, max = 2}\n"), i).camera_effects
         for i in range(20)]
    for x, y in zip(a, b):
        assert y.applied == [e for e in ce.EFFECTS if e in x.applied or e == "sharpen"]
        assert 1.0 <= y.sharpen_amount <= 2.0 and 0.7 <= y.sharpen_sigma_px <= 1.5
        assert {k: v for k, v in vars(y).items() if not k.startswith(("applied", "sharpen"))} == \
            {k: v for k, v in vars(x).items() if not k.startswith(("applied", "sharpen"))}
    assert all(x.sharpen_amount == 0.0 for x in a)  # off by default: neutral values


def test_motion_blur_acts_along_its_direction_only():
    stripes = np.zeros((64, 64, 3), np.uint8)
    stripes[::4] = 255  # horizontal stripes: constant along x
    (along,) = ce.apply_camera_effects([stripes], spec("motion_blur", motion_length_px=6.0, motion_angle_deg=0.0))
    (across,) = ce.apply_camera_effects([stripes], spec("motion_blur", motion_length_px=6.0, motion_angle_deg=90.0))
    assert np.abs(along.astype(int) - stripes).max() <= 1
    assert np.abs(across.astype(int) - stripes).max() > 100


@pytest.mark.parametrize("kernel", [ce.disk_kernel(0.7), ce.disk_kernel(3.3), ce.gaussian_kernel(1.5),
                                    ce.motion_kernel(4.5, 37.0), ce.motion_kernel(1.0, 0.0)])
def test_kernels_are_normalised_and_centred(kernel):
    assert kernel.sum() == pytest.approx(1.0, abs=1e-5) and (kernel >= 0).all()
    yy, xx = np.indices(kernel.shape)
    c = (kernel.shape[0] - 1) / 2
    assert (kernel * yy).sum() == pytest.approx(c, abs=0.05) and (kernel * xx).sum() == pytest.approx(c, abs=0.05)


def test_noise_variance_follows_the_poisson_gaussian_law():
    full_well, read = 1000.0, 5.0  # levels >= 50 e-: far from the clip at 0
    levels = np.array([0.05, 0.1, 0.3, 0.6], np.float32)
    lin = np.repeat(levels, 100_000).reshape(4, -1)
    noisy = ce.poisson_gaussian(lin, full_well, read, np.random.default_rng(1))
    expected = levels / full_well + (read / full_well) ** 2
    var = noisy.var(axis=1)
    np.testing.assert_allclose(var, expected, rtol=0.05)
    np.testing.assert_allclose(noisy.mean(axis=1), levels, atol=2e-3)  # unbiased away from 0 and 1
    slope, intercept = np.polyfit(noisy.mean(axis=1), var, 1)
    assert slope == pytest.approx(1 / full_well, rel=0.1) and intercept == pytest.approx((read / full_well) ** 2, rel=0.3)


def test_stage_noise_grows_with_signal():
    s = spec("noise", noise_full_well_e=300.0, noise_read_e=1.0, seed=7)
    stds = []
    for v in (40, 120, 230):
        (out,) = ce.apply_camera_effects([flat(v, 200, 200)], s)
        stds.append(ce.srgb_to_linear(out).std())
    assert stds[0] < stds[1] < stds[2]


def test_jpeg_changes_the_image_and_keeps_shape_and_dtype():
    img = textured()
    errs = []
    for q in (95, 50, 10):
        (out,) = ce.apply_camera_effects([img], spec("jpeg", jpeg_quality=q))
        assert out.shape == img.shape and out.dtype == np.uint8 and not np.array_equal(out, img)
        errs.append(np.abs(out.astype(int) - img).mean())
    assert errs[0] < errs[1] < errs[2]  # lower quality, larger error


# ---- the stage: views, labels, determinism ------------------------------------------------------

def all_on_spec(seed: int = 3) -> CameraEffectsSpec:
    return make_spec(parse_recipe(f"[dataset]\nseed = {seed}\n[camera_effects]\nenabled = true\n{ALL_ON}"), 0) \
        .camera_effects


def members(img: np.ndarray) -> dict:
    h, w = img.shape[:2]
    rng = np.random.default_rng(5)
    return {
        "rgb.png": img, "right.png": img.copy(),
        "mask.png": (rng.random((h, w)) > 0.9).astype(np.uint8) * 255,
        "depth.exr": rng.random((h, w)).astype(np.float32),
        "tof.exr": rng.random((h, w)).astype(np.float32),
        "tofraw.exr": {"Z": rng.random((8, 8)).astype(np.float32), "A": rng.random((8, 8)).astype(np.float32)},
    }


def test_all_effects_together_identical_views_and_untouched_labels():
    s = all_on_spec()
    assert s.applied == list(ce.EFFECTS)
    m = members(textured())
    out, meta = camera_effects_members(s, m)
    assert np.array_equal(out["rgb.png"], out["right.png"]) and not np.array_equal(out["rgb.png"], m["rgb.png"])
    for k in ("mask.png", "depth.exr", "tof.exr", "tofraw.exr"):
        assert out[k] is m[k]  # passed through as the very same object: byte-identical
    assert meta["applied"] == list(ce.EFFECTS) and meta["views"] == ["rgb", "right"]
    assert meta["jpeg_quality"] == s.jpeg_quality and meta["noise_seed"] == s.seed and len(meta["wb_gains"]) == 3
    again, meta2 = camera_effects_members(all_on_spec(), members(textured()))
    assert np.array_equal(again["rgb.png"], out["rgb.png"]) and meta2 == meta  # deterministic per seed


def test_views_get_the_same_gain_maps():
    # different views, same transform: a deterministic effect acts as the same per-pixel gain on both
    s = spec("exposure", "vignetting", "white_balance", exposure_ev=0.5, vignette_strength=0.3, wb_shift_mired=25.0)
    left, right = flat(60, 50, 70), flat(90, 50, 70)
    out_l, out_r = ce.apply_camera_effects([left, right], s)
    gl = ce.srgb_to_linear(out_l) / ce.srgb_to_linear(left)
    gr = ce.srgb_to_linear(out_r) / ce.srgb_to_linear(right)
    np.testing.assert_allclose(gl, gr, rtol=0.03)


def test_noise_depends_on_the_seed():
    img = flat(120)
    a = ce.apply_camera_effects([img], spec("noise", noise_full_well_e=500.0, noise_read_e=2.0, seed=1))[0]
    b = ce.apply_camera_effects([img], spec("noise", noise_full_well_e=500.0, noise_read_e=2.0, seed=1))[0]
    c = ce.apply_camera_effects([img], spec("noise", noise_full_well_e=500.0, noise_read_e=2.0, seed=2))[0]
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_off_stage_returns_members_unchanged():
    m = members(textured())
    out, meta = camera_effects_members(CameraEffectsSpec(), m)
    assert meta == {"applied": []} and all(out[k] is m[k] for k in m)


# ---- recipe and draws ----------------------------------------------------------------------------

def test_draws_follow_the_recipe_probabilities_and_ranges():
    r = parse_recipe("[camera_effects]\nenabled = true\nexposure = 1.0\nwhite_balance = 0.0\ntone = 0.0\n"
                     "vignetting = 0.0\ndefocus = 0.0\nmotion_blur = 0.0\nnoise = 0.5\njpeg = 0.0\n"
                     "exposure_ev = {min = 0.2, max = 0.4}\njpeg_quality = {min = 70, max = 80}")
    specs = [make_spec(r, i).camera_effects for i in range(200)]
    assert all(s.enabled and s.applied[0] == "exposure" and 0.2 <= s.exposure_ev < 0.4 for s in specs)
    noisy = sum("noise" in s.applied for s in specs)
    assert 70 < noisy < 130
    assert all(set(s.applied) <= {"exposure", "noise"} for s in specs)
    assert all(s.noise_full_well_e == 0.0 for s in specs if "noise" not in s.applied)  # neutral when not applied
    assert len({s.seed for s in specs}) == 200
    assert not any(make_spec(parse_recipe(""), i).camera_effects.enabled for i in range(5))


@pytest.mark.parametrize("text, field", [
    ("[camera_effects]\nbogus = 1", "camera_effects.bogus: unknown key"),
    ("[camera_effects]\njpeg_quality = 150", "camera_effects.jpeg_quality"),
    ("[camera_effects]\nnoise = 1.5", "camera_effects.noise"),
    ('[camera_effects]\ndefocus_kernel = "box"', "camera_effects.defocus_kernel"),
])
def test_bad_camera_effects_recipe_names_the_field(text, field):
    with pytest.raises(RecipeError, match=field):
        parse_recipe(text)
