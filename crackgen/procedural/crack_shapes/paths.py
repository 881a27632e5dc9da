"""Polyline crack paths: jagged by midpoint displacement, rendered as a normalised distance field.

Generators work in patch units (u, v in [0, 1], widths as a fraction of the patch side), so a
spec gives the same crack at any map resolution; ``render_paths`` takes texel coordinates of
the crack map (see ``crackmap``): x runs along u (column i), y along v (row j), and the centre
of texel [j, i] is at (x, y) = (i, j), i.e. x = u * N - 0.5.

The field is ``r = d / w`` where d is the distance from a texel centre to the nearest path
segment and w the path's half-width there (interpolated along the segment); r < 1 is inside
the crack, so the mask width is exactly 2 w wherever the crack is, with no blobs.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial import cKDTree

__all__ = ["Path", "MIN_HALF_WIDTH_PX", "STEP", "jagged_line", "arc_fraction", "smooth_wobble", "to_texels", "render_paths"]

# Half-widths are floored at just over half a texel: every point of a path then lies within
# that distance of some texel centre in each column/row it crosses, so the mask of even the
# thinnest crack (a hairline narrower than a texel) is one texel wide and 8-connected instead
# of breaking into dots. This is the "widen to one texel" rule.
MIN_HALF_WIDTH_PX = 0.55

STEP = 1.0 / 1024  # longest path segment, patch units: one texel of the default 1024-px map
_K_NEAREST = 4  # candidate segments per texel (the nearest by midpoint); see render_paths


@dataclass
class Path:
    """One crack centre line: vertices (K, 2) as (x, y) and half-width (K,), same unit (patch or texels)."""

    xy: np.ndarray
    half_width: np.ndarray


def jagged_line(a: np.ndarray, b: np.ndarray, jaggedness: float, rng: np.random.Generator, step: float = STEP) -> np.ndarray:
    """Vertices from ``a`` to ``b``, each segment's midpoint pushed sideways by N(0, jaggedness * its
    length), halving until segments are <= ``step``: roughness at every octave (fractal)."""
    pts = np.array([a, b], dtype=np.float64)
    for _ in range(60):
        seg = pts[1:] - pts[:-1]
        length = np.hypot(seg[:, 0], seg[:, 1])
        long = np.nonzero(length > step)[0]  # only these are split: ~uniform spacing, fewer vertices
        if len(long) == 0:
            break
        normal = np.stack([-seg[long, 1], seg[long, 0]], axis=1) / length[long, None]
        mid = 0.5 * (pts[long + 1] + pts[long]) + normal * (rng.normal(size=len(long)) * jaggedness * length[long])[:, None]
        pts = np.insert(pts, long + 1, mid, axis=0)
    return pts


def arc_fraction(xy: np.ndarray) -> np.ndarray:
    """Cumulative arc length of each vertex as a fraction of the whole path, in [0, 1]."""
    seg = np.hypot(*np.diff(xy, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    return s / max(s[-1], 1e-12)


def smooth_wobble(s: np.ndarray, rng: np.random.Generator, amplitude: float, waves: int = 3) -> np.ndarray:
    """1 + a smooth random variation (a few random sine waves) of about +-``amplitude`` along ``s``."""
    k = rng.uniform(1.0, 4.0, waves)
    phase = rng.uniform(0, 2 * np.pi, waves)
    amp = rng.uniform(0.5, 1.0, waves)
    w = (amp[:, None] * np.sin(2 * np.pi * k[:, None] * s[None, :] + phase[:, None])).sum(0) / amp.sum()
    return 1.0 + amplitude * w


def to_texels(paths: list[Path], size_px: int) -> list[Path]:
    """Patch-unit paths -> texel coordinates of an N-px map (x = u * N - 0.5, widths * N)."""
    return [Path(xy=p.xy * size_px - 0.5, half_width=p.half_width * size_px) for p in paths]


def _segments(paths: list[Path]) -> tuple[np.ndarray, ...]:
    """All segments: start A (S, 2), end B (S, 2), half-width at A and at B (floored, see above)."""
    a, b, wa, wb = [], [], [], []
    for p in paths:
        if len(p.xy) < 2:
            continue
        w = np.maximum(p.half_width, MIN_HALF_WIDTH_PX)
        a.append(p.xy[:-1])
        b.append(p.xy[1:])
        wa.append(w[:-1])
        wb.append(w[1:])
    if not a:
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), np.zeros(0)
    return np.concatenate(a), np.concatenate(b), np.concatenate(wa), np.concatenate(wb)


def render_paths(paths: list[Path], size_px: int) -> np.ndarray:
    """Normalised distance r = d / w (float32, (N, N), clipped to 1; 1 = outside every crack).

    Only texels near a path are evaluated: a distance transform from the rasterised vertices
    picks the band within the widest half-width (plus the vertex spacing); there each texel
    takes the smallest d / w over the ``_K_NEAREST`` segments whose midpoints are closest
    (the nearest segment is among them up to half a segment length), so crossing paths merge
    as a union.
    """
    n = int(size_px)
    r = np.ones((n, n), dtype=np.float32)
    a, b, wa, wb = _segments(paths)
    if len(a) == 0:
        return r
    spacing = float(np.hypot(*(b - a).T).max())
    w_max = float(max(wa.max(), wb.max()))
    margin = int(np.ceil(w_max + spacing + 2.0))
    lo, hi = -margin, n - 1 + margin
    near = np.all((a >= lo) & (a <= hi), axis=1) | np.all((b >= lo) & (b <= hi), axis=1)
    a, b, wa, wb = a[near], b[near], wa[near], wb[near]
    if len(a) == 0:
        return r
    # Band: texels within w_max (+ slack for vertex spacing and rounding) of any vertex.
    m = n + 2 * margin
    seeds = np.full((m, m), 255, dtype=np.uint8)
    v = np.rint(np.concatenate([a, b]) + margin).astype(np.intp)
    ok = np.all((v >= 0) & (v < m), axis=1)
    seeds[v[ok, 1], v[ok, 0]] = 0
    dist = cv2.distanceTransform(seeds, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[margin : margin + n, margin : margin + n]
    rows, cols = np.nonzero(dist <= w_max + 0.5 * spacing + 1.0)
    if rows.size == 0:
        return r
    q = np.stack([cols, rows], axis=1).astype(np.float64)
    k = min(_K_NEAREST, len(a))
    # Only segments that can hold a texel (d < w <= w_max; midpoint within d + half a segment).
    _, idx = cKDTree(0.5 * (a + b)).query(q, k=k, distance_upper_bound=w_max + spacing + 1.0)
    idx = idx.reshape(len(q), k)
    # Misses come back as index S: a dummy segment far away.
    far = np.full((1, 2), -1e9)
    a, b, wa, wb = np.vstack([a, far]), np.vstack([b, far]), np.append(wa, 1.0), np.append(wb, 1.0)
    sa, sb = a[idx], b[idx]  # (Q, k, 2)
    ab = sb - sa
    t = np.clip(((q[:, None, :] - sa) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0.0, 1.0)
    d = np.hypot(*(sa + t[..., None] * ab - q[:, None, :]).transpose(2, 0, 1))
    w = wa[idx] + t * (wb[idx] - wa[idx])
    r[rows, cols] = np.minimum(d / w, 1.0).min(axis=1)
    return r
