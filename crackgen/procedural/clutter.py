"""Real-world clutter painted into the material maps: never cracks, never labelled.

Why: a segmenter trained on clean surfaces marks the pores, aggregate gaps and dark
texture of real concrete and asphalt as crack (precision 0.2-0.4). These painters add
that dark non-crack structure as hard negatives: pores and voids with a shadowed side,
short closed gaps between aggregate stones, small stains, moss in low areas, and
paint / patch repairs with a visible edge.

Like distractors, each kind draws only from its own seed and blends with a weight that
is exactly zero outside the mask it returns. They change albedo / roughness / height
only; the GT crack mask comes from the crack map alone.
"""
from __future__ import annotations

import math
from typing import Callable

import cv2
import numpy as np
from numba import njit, prange

from crackgen.procedural.distractors import _cut, _seed
from crackgen.procedural.texgrid import TexGrid, clip01, quantile_fast, smoothstep


def _rng(seed: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(seed), 0xC1A7]))


@njit(cache=True, parallel=True)
def _worley(x, cell, jit, present, d1, d2, near, ox, oy):  # pragma: no cover
    """Per texel: distance to the nearest (d1) and second nearest (d2) seed point of a
    jittered grid (at most one point per cell, ``present`` says which cells have one),
    the nearest point's flat cell index and the offset to it (ox, oy), metres."""
    p = x.size
    n = present.shape[1]
    for j in prange(p):
        cy = int(x[j] / cell)
        for i in range(p):
            cx = int(x[i] / cell)
            b1 = 1e30
            b2 = 1e30
            bi = -1
            bx = 0.0
            by = 0.0
            for dy in range(-2, 3):
                yy = cy + dy + 2
                for dx in range(-2, 3):
                    xx = cx + dx + 2
                    if not present[yy, xx]:
                        continue
                    ddx = x[i] - (cx + dx + jit[yy, xx, 0]) * cell
                    ddy = x[j] - (cy + dy + jit[yy, xx, 1]) * cell
                    d = math.sqrt(ddx * ddx + ddy * ddy)
                    if d < b1:
                        b2 = b1
                        b1 = d
                        bi = yy * n + xx
                        bx = ddx
                        by = ddy
                    elif d < b2:
                        b2 = d
            d1[j, i] = b1
            d2[j, i] = b2
            near[j, i] = bi
            ox[j, i] = bx
            oy[j, i] = by


def worley(grid: TexGrid, cell: float, presence: float, rng: np.random.Generator):
    """Jittered-grid Worley distances over the texture: (d1, d2, nearest index, ox, oy, n)."""
    n = int(math.ceil(grid.size_m / cell)) + 4
    jit = rng.random((n, n, 2))
    present = rng.random((n, n)) < presence
    shape = (grid.px, grid.px)
    d1, d2, ox, oy = (np.empty(shape, np.float64) for _ in range(4))
    near = np.empty(shape, np.int64)
    _worley(grid.x_m, float(cell), jit, present, d1, d2, near, ox, oy)
    return d1, d2, near, ox, oy, n


def pores(rng: np.random.Generator, grid: TexGrid, amount: float, albedo, roughness, height) -> np.ndarray:
    """Pores and voids: many small dark pits (0.5-5 mm, mostly small) with a height dent,
    a darker shadow side and a faint dark rim."""
    r_lo, r_hi = 0.00025, float(rng.uniform(0.0012, 0.0025))
    cell = max(2.2 * r_hi, 1.5 * grid.texel_m)
    presence = float(np.clip(amount * rng.uniform(0.3, 0.7), 0.0, 1.0))
    d1, _, near, ox, oy, n = worley(grid, cell, presence, rng)
    # log-uniform radius per cell: many small pores, few large voids
    radius = np.exp(rng.uniform(math.log(r_lo), math.log(r_hi), n * n))
    r_px = radius[np.maximum(near, 0)]
    r_eff = np.maximum(r_px, 0.5 * grid.texel_m)  # a sub-texel pore still darkens its texel
    rn = np.where(near >= 0, d1 / r_eff, 9.0)
    inside = smoothstep(1.15, 0.85, rn.astype(np.float32))
    rim = smoothstep(1.6, 1.15, rn.astype(np.float32)) * np.float32(0.35)
    # coverage of a texel by a sub-texel pore: area ratio
    cover = np.minimum((r_px / r_eff) ** 2, 1.0).astype(np.float32)
    w, mask = _cut(np.maximum(inside * cover, rim * cover))
    phi = rng.uniform(0.0, 2.0 * math.pi)
    side = ((ox * math.cos(phi) + oy * math.sin(phi)) / r_eff).astype(np.float32)  # -1..1 across the pit
    dark = np.float32(rng.uniform(0.08, 0.25)) * (1.0 + 0.6 * np.clip(side, -1.0, 1.0))
    k = np.where(inside > rim, 1.0 - (1.0 - dark) * w, 1.0 - np.float32(0.3) * w).astype(np.float32)
    albedo *= k[..., None]
    roughness += w * (np.float32(0.95) - roughness)
    bowl = np.sqrt(np.clip(1.0 - rn * rn, 0.0, 1.0)).astype(np.float32)
    height -= (r_px * np.float32(rng.uniform(0.6, 1.2))).astype(np.float32) * bowl * (w > 0)
    return mask


def voids(rng: np.random.Generator, grid: TexGrid, amount: float, albedo, roughness, height) -> np.ndarray:
    """Bugholes and surface voids: sparse dark holes 3-24 mm across with ragged outlines, a
    shadowed side and a darker core. Why: on real photos the pore-sized painter (``pores``, up to
    5 mm) leaves the larger dark blobs of concrete and open asphalt as the main false positive
    of a model trained on renders; these are compact (round to oblong), never long."""
    r_lo, r_hi = 0.0015, float(rng.uniform(0.005, 0.012))
    cell = 3.0 * r_hi
    presence = float(np.clip(amount * rng.uniform(0.05, 0.25), 0.0, 1.0))
    d1, _, near, ox, oy, n = worley(grid, cell, presence, rng)
    radius = np.exp(rng.uniform(math.log(r_lo), math.log(r_hi), n * n))  # log-uniform: few large voids
    r_px = np.maximum(radius[np.maximum(near, 0)], grid.texel_m)
    ragged = grid.field(_seed(rng), 1.5 * r_hi, 2) * np.float32(rng.uniform(0.1, 0.25))
    rn = np.where(near >= 0, d1 / r_px, 9.0).astype(np.float32) * (1.0 + ragged)
    w, mask = _cut(smoothstep(1.1, 0.9, rn))
    phi = rng.uniform(0.0, 2.0 * math.pi)
    side = np.clip((ox * math.cos(phi) + oy * math.sin(phi)) / r_px, -1.0, 1.0).astype(np.float32)
    core = np.clip(1.0 - rn, 0.0, 1.0)  # 1 at the centre, 0 at the edge
    dark = np.float32(rng.uniform(0.08, 0.35)) * (1.0 + 0.7 * side) * (1.0 - 0.5 * core)
    albedo *= (1.0 - (1.0 - dark) * w)[..., None]
    roughness += w * (np.float32(0.95) - roughness)
    bowl = np.sqrt(np.clip(1.0 - rn * rn, 0.0, 1.0)).astype(np.float32)
    height -= (r_px * np.float32(rng.uniform(0.5, 1.0))).astype(np.float32) * bowl * (w > 0)
    return mask


def gaps(rng: np.random.Generator, grid: TexGrid, amount: float, albedo, roughness, height) -> np.ndarray:
    """Aggregate gaps: thin dark curved gaps along the borders of exposed stones (Voronoi
    edges), kept only in short pieces so they stay short and closed, never long cracks."""
    stone = float(rng.uniform(0.006, 0.02))
    d1, d2, _, _, _, _ = worley(grid, stone, 1.0, rng)
    half = max(float(rng.uniform(0.0003, 0.0008)), 0.3 * grid.texel_m)
    t = 0.5 * grid.texel_m
    edge = smoothstep(half + t, max(half - t, 0.0), ((d2 - d1) * 0.5).astype(np.float32))
    edge *= np.float32(min(1.0, 2.0 * half / grid.texel_m))  # sub-texel gaps darken partly
    keep_f = grid.field(_seed(rng), stone * 0.8, 2)
    thr = quantile_fast(keep_f, 1.0 - float(np.clip(amount * rng.uniform(0.15, 0.4), 0.0, 1.0)))
    w, mask = _cut(edge * smoothstep(thr, thr + 0.25, keep_f))
    dark = np.float32(rng.uniform(0.08, 0.25))
    albedo *= (1.0 - (1.0 - dark) * w)[..., None]
    roughness += w * (np.float32(0.95) - roughness)
    height -= np.float32(rng.uniform(0.001, 0.003)) * w
    return mask


def stains(rng: np.random.Generator, grid: TexGrid, amount: float, albedo, roughness, height) -> np.ndarray:
    """Small stains: grime or rust spots a few centimetres across."""
    f = grid.field(_seed(rng), rng.uniform(0.02, 0.08), 4, 0.6)
    thr = quantile_fast(f, 1.0 - float(np.clip(amount * rng.uniform(0.03, 0.12), 0.0, 1.0)))
    w, mask = _cut(smoothstep(thr, thr + rng.uniform(0.3, 0.8), f) * np.float32(rng.uniform(0.4, 0.8)))
    if rng.random() < 0.5:  # grime
        tint = np.asarray([1.0, 0.95, 0.88], np.float32) * np.float32(rng.uniform(0.3, 0.6))
    else:  # rust
        tint = np.asarray([1.0, 0.6, 0.35], np.float32) * np.float32(rng.uniform(0.5, 0.8))
    albedo *= 1.0 + w[..., None] * (tint - 1.0)
    return mask


def moss(rng: np.random.Generator, grid: TexGrid, amount: float, albedo, roughness, height) -> np.ndarray:
    """Moss / lichen: greenish patches that prefer the low areas of the height map."""
    scale = rng.uniform(0.03, 0.15)
    f = grid.field(_seed(rng), scale, 4, 0.6)
    smooth = cv2.GaussianBlur(height, (0, 0), max(0.5 * scale / grid.texel_m, 0.5))  # low areas, not grooves
    h = smooth - smooth.mean()
    low = -h / max(float(h.std()), 1e-9)
    g = f + np.float32(0.7) * np.clip(low, -3, 3).astype(np.float32)
    thr = quantile_fast(g, 1.0 - float(np.clip(amount * rng.uniform(0.05, 0.2), 0.0, 1.0)))
    w, mask = _cut(smoothstep(thr, thr + 0.4, g) * np.float32(rng.uniform(0.6, 0.95)))
    green = np.asarray([rng.uniform(0.05, 0.12), rng.uniform(0.1, 0.18), rng.uniform(0.02, 0.05)], np.float32)
    if rng.random() < 0.3:  # pale lichen
        green = np.asarray([0.35, 0.38, 0.25], np.float32) * np.float32(rng.uniform(0.7, 1.0))
    albedo += w[..., None] * (green * (1.0 + 0.2 * f)[..., None] - albedo)
    roughness += w * (np.float32(rng.uniform(0.9, 1.0)) - roughness)
    height += np.float32(rng.uniform(0.0002, 0.001)) * w
    return mask


def patch(rng: np.random.Generator, grid: TexGrid, amount: float, albedo, roughness, height) -> np.ndarray:
    """Paint or patch repair: a rectangle or blob of another, smoother material, with a
    visible dark seam at its edge."""
    side = grid.size_m * float(rng.uniform(0.15, 0.3 + 0.3 * amount))
    cx, cy = rng.uniform(0.2, 0.8, 2) * grid.size_m
    ang = rng.uniform(0.0, math.pi)
    across, along = grid.line_coords(float(ang), (float(cx), float(cy)))
    aspect = float(rng.uniform(0.4, 1.0))
    if rng.random() < 0.5:  # rectangle: signed distance inside is positive
        inside_d = np.minimum(side / 2 - np.abs(along), side * aspect / 2 - np.abs(across))
    else:  # blob: noisy ellipse
        wob = grid.field(_seed(rng), side * 0.3, 3) * np.float32(0.15 * side)
        r = np.sqrt((along / (side / 2)) ** 2 + (across / (side * aspect / 2)) ** 2)
        inside_d = (1.0 - r) * np.float32(side / 2) + wob
    t = grid.texel_m
    body = smoothstep(-0.5 * t, 0.5 * t, inside_d)
    seam_w = max(float(rng.uniform(0.0005, 0.0015)), 0.5 * t)
    seam = smoothstep(seam_w + t, seam_w, np.abs(inside_d)) * np.float32(rng.uniform(0.3, 0.6))
    w, mask = _cut(np.maximum(body, seam))
    mean = albedo.reshape(-1, 3).mean(axis=0)
    color = (mean * rng.uniform(0.6, 1.5) * (1.0 + rng.normal(0.0, 0.08, 3))).astype(np.float32)
    clip01(color)
    fine = grid.field(_seed(rng), 0.02, 2)
    mat = color * (1.0 + np.float32(0.04) * fine)[..., None]
    b = np.where(mask, body, 0.0).astype(np.float32)
    albedo += b[..., None] * (mat - albedo)
    s = np.where(mask, seam, 0.0).astype(np.float32)
    albedo *= (1.0 - s)[..., None]
    roughness += b * (np.float32(rng.uniform(0.35, 0.65)) - roughness)
    height += np.float32(rng.uniform(0.0005, 0.002)) * b - np.float32(0.001) * s
    return mask


CLUTTER: dict[str, Callable[..., np.ndarray]] = {
    "pores": pores,
    "gaps": gaps,
    "stains": stains,
    "moss": moss,
    "patch": patch,
    "voids": voids,
}


def paint_clutter(kind: str, seed: int, amount: float, grid: TexGrid, albedo, roughness, height) -> np.ndarray:
    """Paint one clutter kind in place; returns the bool mask of texels it changed."""
    return CLUTTER[kind](_rng(seed), grid, float(amount), albedo, roughness, height)
