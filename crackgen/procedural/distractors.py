"""Crack-like features that are NOT cracks, painted into the material maps.

Why: a segmenter trained only on cracks learns "dark thin line = crack". Saw-cut
joints, sealant strips, stains and road markings teach it otherwise. They change
albedo / roughness / height only; the GT crack mask never sees them.

Every parameter is drawn from the distractor's own seed, so adding a distractor
never changes the rest of the sample. Each painter blends with a weight that is
exactly zero outside the returned mask, so "where it painted" is exact.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from crackgen.procedural.texgrid import TexGrid, quantile_fast, smoothstep

MIN_WEIGHT = 0.05  # blend weights below this are dropped so the mask is exact


def _rng(seed: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(seed), 0xD157]))


def _seed(rng: np.random.Generator) -> int:
    return int(rng.integers(0, 2**31 - 1))


def _cut(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Zero negligible weights; return (weights, mask)."""
    mask = w > MIN_WEIGHT
    return np.where(mask, w, np.float32(0.0)).astype(np.float32), mask


def _line_angle(rng: np.random.Generator) -> float:
    """Mostly along a surface axis (joints/markings follow the slab/lane), sometimes any angle."""
    if rng.random() < 0.7:
        return float(rng.choice([0.0, math.pi / 2]) + rng.normal(0.0, 0.03))
    return float(rng.uniform(0.0, math.pi))


def _band(grid: TexGrid, dist: np.ndarray, half_width: np.ndarray | float) -> np.ndarray:
    """Anti-aliased 1 inside |dist| < half_width, 0 outside, one texel transition."""
    t = grid.texel_m * 0.5
    return smoothstep(half_width + t, half_width - t, np.abs(dist))


def joint(rng: np.random.Generator, grid: TexGrid, albedo, roughness, height) -> np.ndarray:
    """Straight saw-cut joint across the patch: narrow dark groove with slightly spalled edges."""
    across, along = grid.line_coords(_line_angle(rng), tuple(rng.uniform(0.15, 0.85, 2) * grid.size_m))
    half = rng.uniform(0.002, 0.005)
    spall = 1.0 + rng.uniform(0.1, 0.35) * grid.profile(_seed(rng), along, rng.uniform(0.02, 0.08))
    half_w = np.maximum(half * spall, 0.6 * grid.texel_m)
    w, mask = _cut(_band(grid, across, half_w))
    dark = np.float32(rng.uniform(0.2, 0.5))
    albedo *= (1.0 - (1.0 - dark) * w)[..., None]
    roughness += w * (np.float32(rng.uniform(0.85, 1.0)) - roughness)
    height -= np.float32(rng.uniform(0.005, 0.025)) * w
    return mask


def sealant(rng: np.random.Generator, grid: TexGrid, albedo, roughness, height) -> np.ndarray:
    """Wavy strip of dark, glossy, slightly raised bitumen sealant."""
    across, along = grid.line_coords(_line_angle(rng), tuple(rng.uniform(0.2, 0.8, 2) * grid.size_m))
    wave = rng.uniform(0.005, 0.04) * grid.profile(_seed(rng), along, rng.uniform(0.15, 0.5))
    half = rng.uniform(0.008, 0.025) * (1.0 + 0.15 * grid.profile(_seed(rng), along, 0.05))
    d = across - wave
    w, mask = _cut(_band(grid, d, half))
    color = np.float32(rng.uniform(0.01, 0.03)) * np.asarray([1.0, 1.0, 0.95], np.float32)
    albedo += w[..., None] * (color - albedo)
    roughness += w * (np.float32(rng.uniform(0.08, 0.3)) - roughness)
    bulge = np.clip(1.0 - (d / half) ** 2, 0.0, 1.0)
    height += np.float32(rng.uniform(0.0005, 0.002)) * bulge * w
    return mask


def stain(rng: np.random.Generator, grid: TexGrid, albedo, roughness, height) -> np.ndarray:
    """Blotchy patches from thresholded fBm: oil (dark, glossy) or dirt/water (darker, tinted)."""
    f = grid.field(_seed(rng), rng.uniform(0.15, 0.6), 4, 0.55, 2.0, (1.0, float(rng.uniform(1.0, 2.0))))
    thr = quantile_fast(f, 1.0 - rng.uniform(0.08, 0.3))
    w, mask = _cut(smoothstep(thr, thr + rng.uniform(0.3, 1.0), f) * np.float32(rng.uniform(0.4, 0.8)))
    if rng.random() < 0.5:  # oil
        target = np.full(3, rng.uniform(0.01, 0.03), np.float32)
        albedo += w[..., None] * (target - albedo)
        roughness += w * (np.float32(rng.uniform(0.2, 0.45)) - roughness)
    else:  # dirt / damp
        tint = np.asarray([1.0, rng.uniform(0.8, 0.95), rng.uniform(0.6, 0.85)], np.float32) * np.float32(
            rng.uniform(0.35, 0.7)
        )
        albedo *= (1.0 + w[..., None] * (tint - 1.0))
    return mask


def marking(rng: np.random.Generator, grid: TexGrid, albedo, roughness, height) -> np.ndarray:
    """White or yellow road paint stripe: smoother, slightly raised, worn, sometimes dashed."""
    across, along = grid.line_coords(_line_angle(rng), tuple(rng.uniform(0.2, 0.8, 2) * grid.size_m))
    w = _band(grid, across, rng.uniform(0.05, 0.1))
    if rng.random() < 0.3:  # dashed
        period, duty = rng.uniform(1.0, 3.0), rng.uniform(0.4, 0.7)
        ph = np.mod(along + rng.uniform(0, period), period)
        w *= smoothstep(duty * period + grid.texel_m, duty * period, ph)
    wear = grid.field(_seed(rng), rng.uniform(0.008, 0.03), 4)
    worn = rng.uniform(0.0, 0.4)
    if worn > 0.01:
        thr = quantile_fast(wear, worn)
        w *= smoothstep(thr - 0.1, thr + 0.1, wear)
    w, mask = _cut(w)
    base = [0.72, 0.71, 0.66] if rng.random() < 0.6 else [0.75, 0.45, 0.03]
    color = np.asarray(base, np.float32) * np.float32(rng.uniform(0.8, 1.05))
    paint = color * (1.0 + 0.06 * wear)[..., None]
    albedo += w[..., None] * (paint - albedo)
    roughness += w * (np.float32(rng.uniform(0.3, 0.55)) - roughness)
    height += np.float32(rng.uniform(0.0003, 0.0015)) * w
    return mask


def formwork(rng: np.random.Generator, grid: TexGrid, albedo, roughness, height) -> np.ndarray:
    """Cast-in-place concrete's formwork pattern: a grid of straight panel joints (a thin dark grout-loss line
    or a light fin) every 0.6-2.4 m, with rows of dark tie holes. Straight, regular and line-like: the
    false positive a bridge inspector's model must not take for a crack."""
    angle = float(rng.normal(0.0, 0.01))
    du, dv = rng.uniform(0.6, 2.4), rng.uniform(0.3, 1.2)
    if rng.random() < 0.5:
        du, dv = dv, du
    across, along = grid.line_coords(angle, (0.0, 0.0))  # across ~ v (rows), along ~ u (columns)
    half = rng.uniform(0.002, 0.006)
    ph_u, ph_v = rng.uniform(0.0, du), rng.uniform(0.0, dv)
    # distance to the nearest joint of each family, wrapped into [-spacing/2, spacing/2)
    to_col = np.mod(along - ph_u + du / 2, du) - du / 2
    to_row = np.mod(across - ph_v + dv / 2, dv) - dv / 2
    w_line = np.maximum(_band(grid, to_col, max(half, 0.6 * grid.texel_m)),
                        _band(grid, to_row, max(half, 0.6 * grid.texel_m)))
    fin = rng.random() < 0.35  # a light, slightly raised fin instead of a dark grout-loss line
    tone = np.float32(rng.uniform(1.2, 1.4) if fin else rng.uniform(0.35, 0.7))
    w_line = w_line * np.float32(rng.uniform(0.7, 1.0))
    w_hole = np.zeros_like(w_line)
    if rng.random() < 0.6:  # tie holes at 1/4 and 3/4 of the panel's width and height
        r = rng.uniform(0.008, 0.015)
        hu = np.mod(along - ph_u, du / 2) - du / 4
        hv = np.mod(across - ph_v, dv / 2) - dv / 4
        w_hole = _band(grid, np.sqrt(hu * hu + hv * hv), r)
    (w_line, line), (w_hole, hole) = _cut(w_line), _cut(w_hole)
    w, mask = np.maximum(w_line, w_hole), line | hole
    albedo *= (1.0 + w_line * (tone - 1.0))[..., None]
    albedo *= (1.0 - np.float32(rng.uniform(0.5, 0.8)) * w_hole)[..., None]
    roughness += w * (np.float32(rng.uniform(0.75, 0.95)) - roughness)
    height += np.float32(rng.uniform(0.0005, 0.002) if fin else -rng.uniform(0.0005, 0.002)) * w_line
    height -= np.float32(rng.uniform(0.005, 0.02)) * w_hole
    return mask


def rust_streak(rng: np.random.Generator, grid: TexGrid, albedo, roughness, height) -> np.ndarray:
    """Rust run-off below a few sources (ties, bolts, exposed bars): orange-brown streaks that fade down the
    surface, narrow at the source and fraying into drips; long, thin and darker than the surface."""
    down = math.pi / 2 + float(rng.normal(0.0, 0.05))  # the surface's "down" is +v
    drips = grid.field(_seed(rng), rng.uniform(0.01, 0.03), 3, 0.5, 2.0, (0.15, 2.0))
    total = np.zeros((grid.px, grid.px), np.float32)
    for _ in range(int(rng.integers(1, 5))):
        src = tuple(rng.uniform(0.05, 0.9, 2) * grid.size_m)
        across, along = grid.line_coords(down, src)
        length = rng.uniform(0.1, 0.8)
        w0 = rng.uniform(0.008, 0.03)
        t = np.clip(along / length, 0.0, None)
        half = w0 * (1.0 + rng.uniform(0.3, 1.5) * np.minimum(t, 1.0))
        fade = np.exp(-1.2 * t) * smoothstep(1.0, 0.6, t) * smoothstep(-0.01, 0.0, along)  # ends at its length
        total = np.maximum(total, _band(grid, across, half) * fade * np.clip(0.7 + 0.3 * drips, 0.0, 1.0))
    w, mask = _cut(total * np.float32(rng.uniform(0.6, 0.95)))
    rust = np.asarray([0.45, 0.19, 0.06], np.float32) * np.float32(rng.uniform(0.6, 1.1))
    albedo += w[..., None] * (rust - albedo)
    roughness += w * (np.float32(rng.uniform(0.7, 0.9)) - roughness)
    return mask


DISTRACTORS: dict[str, Callable[..., np.ndarray]] = {
    "joint": joint,
    "sealant": sealant,
    "stain": stain,
    "marking": marking,
    "formwork": formwork,
    "rust_streak": rust_streak,
}


def paint_distractor(kind: str, seed: int, grid: TexGrid, albedo, roughness, height) -> np.ndarray:
    """Paint one distractor in place; returns the bool mask of texels it changed."""
    return DISTRACTORS[kind](_rng(seed), grid, albedo, roughness, height)
