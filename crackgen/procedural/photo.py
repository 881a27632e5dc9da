"""The ``photo`` material family: albedo from a user's crack-free surface photo.

Why: inspection teams hold thousands of photos of sound concrete and asphalt. Their
pixels carry the real pores, aggregate and grime that procedural families lack,
without needing any labels. The photo is linearised, normalised to a plausible
albedo, scaled to ``photo_size_m`` metres per photo side, mirror-tiled with a random
rotation / flip / offset over the patch; roughness comes from local contrast and
height from a luminance high-pass (dark = low), so the normal map follows the photo.

Such folders may still hold thin cracks, which would be unlabelled cracks in our
data: ``photo_clean = "blackhat"`` removes thin, elongated dark lines (morphological
black-hat, keep only elongated components, inpaint), while round pores stay; ``"wide"``
adds a second pass at 1/12 of the shorter side for wide open cracks (measured on DeepCrack
photos: the thin pass leaves gaps wider than ~20 px; the inpainted area is then smoother
than the surface around it, which is still better than an unlabelled crack).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from crackgen.errors import CrackgenError
from crackgen.postrender.targets import TargetError, TargetPhotos
from crackgen.procedural.texgrid import TexGrid

PHOTO_WHAT = "material.photo_folder"
CLEAN_MODES = ("none", "blackhat", "wide")
WIDE_LINE_FRACTION = 1 / 12  # "wide": a second black-hat pass for dark gaps up to ~1/6 of the shorter side


class PhotoError(CrackgenError, ValueError):
    """The photo folder or one of its photos cannot be used (one line, names the folder/file)."""


@dataclass(frozen=True)
class PhotoLook:
    """How a photo becomes maps (from the ``[photo]`` table of ``photo.toml``)."""

    albedo_mean: tuple[float, float] = (0.15, 0.35)  # linear mean albedo range, drawn per sample
    roughness: float = 0.75  # roughness at average local contrast
    roughness_contrast: float = 0.15  # roughness change per unit of normalised local contrast
    contrast_m: float = 0.004  # window of the local contrast (m)
    height_m: float = 0.0004  # height std from the luminance high-pass (m)
    highpass_m: float = 0.006  # high-pass scale of the height (m)


@lru_cache(maxsize=8)
def photo_folder(folder: str) -> TargetPhotos:
    """Sorted, checked listing of a photo folder, once per process."""
    try:
        return TargetPhotos(folder, what=PHOTO_WHAT)
    except TargetError as exc:
        raise PhotoError(str(exc)) from None


def photo_name(folder: str, fraction: float) -> str:
    """The file a drawn fraction in [0, 1) selects from the sorted folder."""
    return photo_folder(folder).name_for(fraction)


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, np.float32)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


def remove_thin_dark_lines(rgb: np.ndarray, line_px: int | None = None, min_contrast: float = 12.0,
                           min_elongation: float = 4.0, min_length_px: int = 12,
                           robust: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Inpaint thin, elongated dark structures (possible cracks) of a uint8 RGB photo.

    Black-hat (closing minus image) with a disc about ``2 * line_px`` wide finds dark
    features narrower than that. Components are taken at half the threshold (hysteresis,
    so a crack is not cut into dashes) and kept if they reach the full threshold and
    their bounding-rectangle elongation is at least ``min_elongation`` and length at least
    ``min_length_px``: lines go, round ones (pores) stay. Returns (cleaned RGB, removed mask)."""
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    if line_px is None:
        line_px = max(5, int(round(min(gray.shape) / 40)))
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * line_px + 1, 2 * line_px + 1))
    bh = cv2.morphologyEx(gray, cv2.MORPH_BLACKHAT, k)
    if robust:  # median + 6 MADs: a wide crack covering much of the photo does not raise its own threshold
        med = float(np.median(bh))
        thr = max(min_contrast, med + 6.0 * 1.4826 * float(np.median(np.abs(bh - med))))
    else:
        thr = max(min_contrast, float(bh.mean() + 3.0 * bh.std()))
    strong = bh > thr
    n, labels, stats, _ = cv2.connectedComponentsWithStats((bh > 0.5 * thr).astype(np.uint8), connectivity=8)
    has_strong = np.zeros(n, bool)
    has_strong[np.unique(labels[strong])] = True
    keep = np.zeros(n, bool)
    for c in np.nonzero(has_strong)[0]:
        if c == 0 or stats[c, cv2.CC_STAT_AREA] < 3:
            continue
        ys, xs = np.nonzero(labels == c)
        (_, _), (w, h), _ = cv2.minAreaRect(np.column_stack([xs, ys]).astype(np.float32))
        long, short = max(w, h) + 1.0, min(w, h) + 1.0
        thin = stats[c, cv2.CC_STAT_AREA] / (long * short) < 0.5  # a curved or branching line fills little of its box
        keep[c] = long >= min_length_px and (long / short >= min_elongation or (thin and long >= 3 * min_length_px))
    mask = keep[labels]
    if not mask.any():
        return rgb.copy(), mask
    grow = cv2.dilate(mask.astype(np.uint8), np.ones((3, 3), np.uint8), iterations=2)
    cleaned = cv2.inpaint(np.ascontiguousarray(rgb), grow, 5, cv2.INPAINT_TELEA)
    return cleaned, grow.astype(bool)


def _cover(img: np.ndarray, grid: TexGrid, size_m: float, rng: np.random.Generator) -> np.ndarray:
    """Resample ``img`` (H, W, C float32) so its longer side spans ``size_m`` metres, then
    mirror-tile it over the patch with a random rotation, flip and offset."""
    h, w = img.shape[:2]
    side_px = max(size_m / grid.texel_m, 2.0)  # texels per photo side
    scale = side_px / max(h, w)
    if scale < 1.0:  # shrink first with area averaging: no aliasing
        img = cv2.resize(img, (max(int(round(w * scale)), 2), max(int(round(h * scale)), 2)),
                         interpolation=cv2.INTER_AREA)
        if img.ndim == 2:
            img = img[..., None]
        scale = side_px / max(img.shape[:2])
    angle = rng.uniform(0.0, 2.0 * math.pi)
    flip = rng.random() < 0.5
    off = rng.uniform(0.0, 1.0, 2) * np.asarray(img.shape[1::-1], float)
    c, s = math.cos(angle) / scale, math.sin(angle) / scale
    fx = -1.0 if flip else 1.0
    # output texel (i, j) -> source pixel: rotate/scale about the patch centre, then offset
    m = np.asarray([[c * fx, -s, 0.0], [s * fx, c, 0.0]], np.float64)
    centre = (grid.px - 1) / 2.0
    m[:, 2] = off - m[:, :2] @ np.asarray([centre, centre])
    out = cv2.warpAffine(img, m, (grid.px, grid.px), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                         borderMode=cv2.BORDER_REFLECT_101)
    return out.reshape(grid.px, grid.px, -1)


def photo_maps(rgb: np.ndarray, grid: TexGrid, size_m: float, clean: str, look: PhotoLook,
               rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(albedo (T,T,3) linear, roughness (T,T), height (T,T) m) of one uint8 RGB photo."""
    if clean not in CLEAN_MODES:
        raise PhotoError(f"material.photo_clean: unknown mode {clean!r} (known: {', '.join(CLEAN_MODES)})")
    if clean in ("blackhat", "wide"):
        rgb, _ = remove_thin_dark_lines(rgb)
    if clean == "wide":  # then the wide, open cracks a thin pass leaves (close-up photos of wide cracks)
        rgb, _ = remove_thin_dark_lines(rgb, line_px=max(5, int(round(min(rgb.shape[:2]) * WIDE_LINE_FRACTION))),
                                        robust=True)
    lin = srgb_to_linear(rgb.astype(np.float32) / 255.0)
    tex = _cover(lin, grid, size_m, rng)
    albedo = np.ascontiguousarray(tex[..., :3])
    lum = albedo @ np.asarray([0.2126, 0.7152, 0.0722], np.float32)
    target = rng.uniform(*look.albedo_mean)
    albedo *= np.float32(target / max(float(lum.mean()), 1e-4))
    np.clip(albedo, 0.0, 0.9, out=albedo)
    lum = albedo @ np.asarray([0.2126, 0.7152, 0.0722], np.float32)
    rel = lum / max(float(lum.mean()), 1e-4)
    # roughness from local contrast (rough, porous texture looks busy), normalised per photo
    sig_c = max(look.contrast_m / grid.texel_m, 0.5)
    mu = cv2.GaussianBlur(rel, (0, 0), sig_c)
    std = np.sqrt(np.maximum(cv2.GaussianBlur(rel * rel, (0, 0), sig_c) - mu * mu, 0.0))
    z = (std - std.mean()) / max(float(std.std()), 1e-6)
    roughness = np.clip(look.roughness + look.roughness_contrast * z, 0.0, 1.0).astype(np.float32)
    # height from a luminance high-pass: dark pores and gaps are low
    hp = rel - cv2.GaussianBlur(rel, (0, 0), max(look.highpass_m / grid.texel_m, 0.5))
    height = (hp * np.float32(look.height_m / max(float(hp.std()), 1e-6))).astype(np.float32)
    return albedo, roughness, height
