"""Camera effects on rendered RGB views: what a real camera does to the light a clean render shows.

Why: Cycles gives noise-free, perfectly exposed, sharp, lossless images; real inspection
photos have exposure and white-balance errors, vignetting, blur, sensor noise and JPEG.
A model trained only on clean renders learns to rely on that cleanliness.

Order (one pass per view; physics first, then the camera's processing):
1. decode 8-bit sRGB to linear light (exact sRGB transfer function);
2. auto exposure: the gain g that brings the mean luma of the sRGB-encoded ``g * x`` to the drawn
   target (solved on the first view, applied to every view), as a camera's metering does; then
   exposure: ``x * 2**ev`` (scene light reaching the sensor, the metering's error);
3. vignetting: ``x * (1 - s * (r / r_corner)**2)`` (lens falloff, centre = 1);
4. defocus blur (disk or Gaussian PSF), then motion blur (line PSF): optics, in linear light;
5. Poisson-Gaussian sensor noise: ``e = Poisson(x * full_well) + Normal(0, read)``, ``x = e / full_well``,
   then clip to [0, 1] (saturation) -- so the variance is ``x / full_well + (read / full_well)**2``;
6. white balance: per-channel gains (ISP, on the linear raw), clip to [0, 1];
7. encode to sRGB, tone curve on display values: ``y = x**gamma``, then an S-curve
   ``y + c * (smoothstep(y) - y)``;
8. in-camera sharpening: an unsharp mask on the luma of the display values,
   ``rgb + a * (Y - Gauss_sigma(Y))`` (cameras sharpen their JPEGs; renders after the
   denoiser are softer than real photos: ``crackgen stats`` sharpness p50 230 against
   DeepCrack's 1280); quantise to 8 bits;
9. JPEG re-compression at the drawn quality (cv2.imencode / imdecode).

Every view of a sample gets the same transform: the same gain maps, kernels and the same
noise stream (seeded from the spec), so identical views stay identical.
All effects off returns the input arrays unchanged (no sRGB round trip).
The spec is ``crackgen.config.spec.CameraEffectsSpec``, read by attribute only, so this module
stays a pure image transform (no config import) that the trainer may use too.
"""
from __future__ import annotations

from typing import Any, Sequence

import cv2
import numpy as np

EFFECTS = ("auto_exposure", "exposure", "white_balance", "tone", "vignetting", "defocus", "motion_blur", "noise",
           "sharpen", "jpeg")
WB_REFERENCE_K = 6500.0  # the white point the camera assumes (D65-like)
WB_WAVELENGTHS_NM = (610.0, 550.0, 465.0)  # narrow-band stand-ins for the R, G, B channels


# ---- transfer functions ------------------------------------------------------------------------

def srgb_to_linear(u8: np.ndarray) -> np.ndarray:
    """uint8 sRGB -> float32 linear light in [0, 1] (IEC 61966-2-1)."""
    x = np.asarray(u8, np.float32) / 255.0
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


def linear_to_srgb(lin: np.ndarray) -> np.ndarray:
    """float linear [0, 1] -> float sRGB-encoded [0, 1] (not yet quantised)."""
    x = np.clip(lin, 0.0, 1.0)
    return np.where(x <= 0.0031308, x * 12.92, 1.055 * np.power(x, 1 / 2.4) - 0.055).astype(np.float32)


def quantise(x: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(x * 255.0), 0, 255).astype(np.uint8)


# ---- per-effect pieces (pure functions; tests call them on hand-made images) --------------------

def _planck(wavelength_nm: np.ndarray, temp_k: float) -> np.ndarray:
    lam = np.asarray(wavelength_nm, float) * 1e-9
    c2 = 1.438776877e-2  # h c / k_B (m K)
    return lam**-5 / np.expm1(c2 / (lam * temp_k))


def white_balance_gains(shift_mired: float, tint: float) -> np.ndarray:
    """RGB gains (green = 1 before tint) of a camera balanced for 6500 K under light shifted by ``shift_mired``.

    The light is a blackbody at ``1e6 / (1e6/6500 + shift)`` K, sampled at one wavelength per channel:
    a positive shift is a warmer light, so the uncorrected image turns warmer (more red, less blue).
    ``tint`` scales green by ``1 + tint`` (positive = greener, negative = magenta)."""
    temp = 1e6 / (1e6 / WB_REFERENCE_K + float(shift_mired))
    ratio = _planck(np.array(WB_WAVELENGTHS_NM), temp) / _planck(np.array(WB_WAVELENGTHS_NM), WB_REFERENCE_K)
    gains = ratio / ratio[1]
    gains[1] *= 1.0 + float(tint)
    return gains.astype(np.float32)


def vignette_gain(h: int, w: int, strength: float) -> np.ndarray:
    """H x W gain map ``1 - s * (r / r_corner)**2``: 1 at the centre, ``1 - s`` at the corners."""
    y = (np.arange(h, dtype=np.float32) - (h - 1) / 2.0)[:, None]
    x = (np.arange(w, dtype=np.float32) - (w - 1) / 2.0)[None, :]
    r2 = (x**2 + y**2) / max(((h - 1) / 2.0) ** 2 + ((w - 1) / 2.0) ** 2, 1e-12)
    return (1.0 - float(strength) * r2).astype(np.float32)


def disk_kernel(radius_px: float, supersample: int = 8) -> np.ndarray:
    """Normalised disk PSF of ``radius_px``, anti-aliased by supersampling each kernel pixel."""
    r = max(float(radius_px), 1e-3)
    half = int(np.ceil(r))
    n = 2 * half + 1
    s = (np.arange(n * supersample) + 0.5) / supersample - n / 2.0
    inside = (s[:, None] ** 2 + s[None, :] ** 2) <= r * r
    k = inside.reshape(n, supersample, n, supersample).mean(axis=(1, 3)).astype(np.float32)
    return k / k.sum()


def gaussian_kernel(radius_px: float) -> np.ndarray:
    """Gaussian PSF with the per-axis variance of a disk of ``radius_px`` (sigma = r / 2)."""
    sigma = max(float(radius_px) / 2.0, 1e-3)
    half = max(1, int(np.ceil(3 * sigma)))
    g = cv2.getGaussianKernel(2 * half + 1, sigma).astype(np.float32)
    return g @ g.T


def motion_kernel(length_px: float, angle_deg: float, supersample: int = 8) -> np.ndarray:
    """Normalised line PSF of ``length_px`` at ``angle_deg`` (0 = horizontal, counter-clockwise in the image)."""
    length = max(float(length_px), 1e-3)
    half = int(np.ceil(length / 2.0)) + 1
    n = 2 * half + 1
    k = np.zeros((n, n), np.float32)
    t = np.linspace(-length / 2.0, length / 2.0, max(2, int(np.ceil(length * supersample)) + 1))
    a = np.radians(float(angle_deg))
    xs, ys = half + t * np.cos(a), half - t * np.sin(a)
    x0, y0 = np.floor(xs).astype(int), np.floor(ys).astype(int)
    fx, fy = xs - x0, ys - y0
    for dx, dy, wgt in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        np.add.at(k, (np.clip(y0 + dy, 0, n - 1), np.clip(x0 + dx, 0, n - 1)), wgt)  # bilinear splat
    return k / k.sum()


def auto_exposure_gain(u8: np.ndarray, target_luma: float, iterations: int = 40) -> float:
    """Linear gain g whose sRGB image ``g * x`` (clipped) has mean luma ``target_luma`` (0-255; luma
    as ``crackgen stats`` measures it: Rec.601 weights on the sRGB values, OpenCV's grey).

    Solved by bisection on log2(g) over a 64-px-wide copy (mean luma rises monotonically with g);
    capped at +-8 EV so a black or white frame stays finite."""
    small = cv2.resize(np.asarray(u8), (64, max(1, round(64 * u8.shape[0] / u8.shape[1]))), interpolation=cv2.INTER_AREA)
    lin = srgb_to_linear(small)
    weights = np.array([0.299, 0.587, 0.114], np.float32)
    target = float(np.clip(target_luma, 1.0, 254.0)) / 255.0
    lo, hi = -8.0, 8.0
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        if float((linear_to_srgb(lin * np.float32(2.0**mid)) @ weights).mean()) < target:
            lo = mid
        else:
            hi = mid
    return float(2.0 ** (0.5 * (lo + hi)))


def convolve(lin: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """Convolve every channel (edges reflected, so the border keeps its brightness)."""
    return cv2.filter2D(lin, -1, kernel, borderType=cv2.BORDER_REFLECT101)


def poisson_gaussian(lin: np.ndarray, full_well_e: float, read_e: float, rng: np.random.Generator) -> np.ndarray:
    """Shot noise (Poisson in electrons, ``full_well_e`` electrons at 1.0) plus Gaussian read noise; clipped."""
    fw = float(full_well_e)
    electrons = rng.poisson(np.clip(lin, 0.0, None).astype(np.float64) * fw).astype(np.float64)
    electrons += rng.normal(0.0, float(read_e), size=lin.shape)
    return np.clip(electrons / fw, 0.0, 1.0).astype(np.float32)


def tone_curve(srgb: np.ndarray, gamma: float, contrast: float) -> np.ndarray:
    """Display-referred tone: ``y = x**gamma`` then ``y + c * (smoothstep(y) - y)``; monotone for |c| <= 1."""
    y = np.power(np.clip(srgb, 0.0, 1.0), float(gamma))
    return (y + float(contrast) * (y * y * (3.0 - 2.0 * y) - y)).astype(np.float32)


def unsharp_luma(srgb: np.ndarray, amount: float, sigma_px: float) -> np.ndarray:
    """Display-referred RGB in [0, 1] plus ``amount`` times the luma's detail above a Gaussian of
    ``sigma_px`` (the same offset on R, G and B, so edges get no colour fringes); clipped to [0, 1]."""
    x = np.asarray(srgb, np.float32)
    y = x @ np.array([0.299, 0.587, 0.114], np.float32)
    detail = y - cv2.GaussianBlur(y, (0, 0), float(sigma_px), borderType=cv2.BORDER_REFLECT101)
    return np.clip(x + np.float32(amount) * detail[..., None], 0.0, 1.0).astype(np.float32)


def jpeg(u8: np.ndarray, quality: int) -> np.ndarray:
    """Re-compress an RGB uint8 image as JPEG at ``quality`` (1-100) and decode it back."""
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(u8, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("camera_effects: JPEG encoding failed")
    return cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


# ---- the whole stage -----------------------------------------------------------------------------

def apply_camera_effects(views: Sequence[np.ndarray], spec: Any) -> list[np.ndarray]:
    """Apply ``spec`` to each uint8 H x W x 3 sRGB view, identically (see module doc for the order)."""
    views = [np.asarray(v) for v in views]
    if not spec.enabled or not spec.applied:
        return views
    gain = auto_exposure_gain(views[0], spec.auto_exposure_luma) if "auto_exposure" in spec.applied else 1.0
    return [_apply_one(v, spec, gain) for v in views]


def _apply_one(rgb: np.ndarray, s: Any, gain: float = 1.0) -> np.ndarray:
    if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"camera_effects: expected uint8 HxWx3 RGB, got {rgb.dtype} {rgb.shape}")
    on = set(s.applied)
    lin = srgb_to_linear(rgb)
    if "auto_exposure" in on:
        lin = lin * np.float32(gain)
    if "exposure" in on:
        lin = lin * np.float32(2.0**s.exposure_ev)
    if "vignetting" in on:
        lin = lin * vignette_gain(*rgb.shape[:2], s.vignette_strength)[..., None]
    if "defocus" in on:
        k = disk_kernel(s.defocus_radius_px) if s.defocus_kernel == "disk" else gaussian_kernel(s.defocus_radius_px)
        lin = convolve(lin, k)
    if "motion_blur" in on:
        lin = convolve(lin, motion_kernel(s.motion_length_px, s.motion_angle_deg))
    if "noise" in on:
        # a fresh generator per view: every view gets the same noise stream (identical views stay identical)
        lin = poisson_gaussian(lin, s.noise_full_well_e, s.noise_read_e, np.random.default_rng(s.seed))
    else:
        lin = np.clip(lin, 0.0, 1.0)
    if "white_balance" in on:
        lin = np.clip(lin * white_balance_gains(s.wb_shift_mired, s.wb_tint), 0.0, 1.0)
    srgb = linear_to_srgb(lin)
    if "tone" in on:
        srgb = tone_curve(srgb, s.tone_gamma, s.tone_contrast)
    if "sharpen" in on:
        srgb = unsharp_luma(srgb, s.sharpen_amount, s.sharpen_sigma_px)
    out = quantise(srgb)
    if "jpeg" in on:
        out = jpeg(out, s.jpeg_quality)
    return out


def describe(spec: Any) -> dict[str, Any]:
    """The metadata record: which effects ran and each one's main values."""
    if not spec.enabled or not spec.applied:
        return {"applied": []}
    on = set(spec.applied)
    meta: dict[str, Any] = {"applied": list(spec.applied)}
    if "auto_exposure" in on:
        meta["auto_exposure_luma"] = spec.auto_exposure_luma
    if "exposure" in on:
        meta["exposure_ev"] = spec.exposure_ev
    if "white_balance" in on:
        gains = [round(float(g), 4) for g in white_balance_gains(spec.wb_shift_mired, spec.wb_tint)]
        meta.update(wb_shift_mired=spec.wb_shift_mired, wb_tint=spec.wb_tint, wb_gains=gains)
    if "tone" in on:
        meta.update(tone_gamma=spec.tone_gamma, tone_contrast=spec.tone_contrast)
    if "vignetting" in on:
        meta["vignette_strength"] = spec.vignette_strength
    if "defocus" in on:
        meta.update(defocus_kernel=spec.defocus_kernel, defocus_radius_px=spec.defocus_radius_px)
    if "motion_blur" in on:
        meta.update(motion_length_px=spec.motion_length_px, motion_angle_deg=spec.motion_angle_deg)
    if "noise" in on:
        meta.update(noise_full_well_e=spec.noise_full_well_e, noise_read_e=spec.noise_read_e, noise_seed=spec.seed)
    if "sharpen" in on:
        meta.update(sharpen_amount=spec.sharpen_amount, sharpen_sigma_px=spec.sharpen_sigma_px)
    if "jpeg" in on:
        meta["jpeg_quality"] = spec.jpeg_quality
    return meta
