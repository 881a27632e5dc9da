"""Visible-crack label in surface coordinates: the crack texels a person sees as a crack.

The thesis mask (M = Z < t, eq. 5.5) also marks the shallow edges of the V-profile and
wide, shallow loops of the crack map that barely render. Real datasets label the dark
gap a person sees, so this label keeps only crack texels that are *deep relative to
their opening*:

    visible = M  and  depth >= max(min_depth_m, depth_ratio * w)

where ``w`` is the local half-width of the crack (m). Why this rule (and not a learned or
rendered one): a point at depth d at the bottom of a gap of half-width w sees the sky
through a cone of half-angle atan(w / d), so its sky view factor is about
w^2 / (w^2 + d^2). ``d >= ratio * w`` is the same as a view factor <= 1 / (1 + ratio^2):
at ratio 1 the texel gets at most half the diffuse light of the open surface, which is
where a gap reads as dark. It is pure geometry on the crack map, so the label stays
exact and aligned (looked up per camera pixel like the thesis mask). ``min_depth_m``
drops grooves too shallow to shade at all.

For a V-groove of half-width w and centre depth D, depth falls linearly to 0 at the edge,
so the label is the centre band of half-width w * (1 - max(min_depth_m, ratio * w) / D)
(empty when that is <= 0).

``w`` is measured with scipy's Euclidean distance transform: the inside distance to the
nearest non-crack texel at the crack's skeleton, minus half a texel (the edge lies
between texel centres), handed to every crack texel from its nearest skeleton texel.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage

from crackgen.errors import CrackgenError

__all__ = ["VisibleLabelError", "local_half_width", "visible_mask", "groove_visible_mask", "drop_small_components",
           "GROOVE_EPS_M"]

GROOVE_EPS_M = 1e-5  # mesh depth (m) above which a texel lies in the rendered groove (float noise is far below)


class VisibleLabelError(CrackgenError, ValueError):
    """Bad visible-label arguments (names the argument)."""


def local_half_width(mask: np.ndarray, texel_m: float, skel: np.ndarray | None = None) -> np.ndarray:
    """(N, N) float32 local crack half-width (m) at each crack texel, 0 outside the mask."""
    mask = np.asarray(mask, dtype=bool)
    out = np.zeros(mask.shape, np.float32)
    if not mask.any():
        return out
    if skel is None:
        from fusion.measure.crack_length import skeleton

        skel = skeleton(mask)
    skel = np.asarray(skel, dtype=bool) & mask
    if not skel.any():  # degenerate: every texel is its own centre
        skel = mask
    inside = ndimage.distance_transform_edt(mask)  # texels to the nearest non-crack texel centre
    half = np.maximum(inside - 0.5, 0.5) * float(texel_m)  # texel centre -> mask edge
    idx = ndimage.distance_transform_edt(~skel, return_distances=False, return_indices=True)
    w = half[idx[0], idx[1]]
    out[mask] = w[mask]
    return out


def visible_mask(
    mask: np.ndarray,
    depth_m: np.ndarray,
    texel_m: float,
    *,
    depth_ratio: float,
    min_depth_m: float,
    skel: np.ndarray | None = None,
) -> np.ndarray:
    """Bool (N, N): crack texels with depth >= max(min_depth_m, depth_ratio * local half-width)."""
    mask = np.asarray(mask, dtype=bool)
    depth = np.asarray(depth_m, dtype=np.float32)
    if mask.ndim != 2 or depth.shape != mask.shape:
        raise VisibleLabelError(f"visible label: mask {mask.shape} and depth_m {depth.shape} must be equal 2-D shapes")
    if not (np.isfinite(texel_m) and texel_m > 0):
        raise VisibleLabelError(f"visible label: texel_m must be > 0 (m), got {texel_m!r}")
    if not (np.isfinite(depth_ratio) and depth_ratio >= 0):
        raise VisibleLabelError(f"label.depth_ratio must be >= 0, got {depth_ratio!r}")
    if not (np.isfinite(min_depth_m) and min_depth_m >= 0):
        raise VisibleLabelError(f"label.min_depth_m must be >= 0 (m), got {min_depth_m!r}")
    w = local_half_width(mask, texel_m, skel)
    need = np.maximum(np.float32(min_depth_m), np.float32(depth_ratio) * w)
    return mask & (depth >= need) & (depth > 0)


def groove_visible_mask(mesh_depth_m: np.ndarray, texel_m: float, *, depth_ratio: float,
                        min_depth_m: float) -> np.ndarray:
    """Bool (N, N): the same rule on the groove the *mesh* renders, sampled at crack-map texels.

    Why: the displaced mesh holds each crack at its vertices' footprint
    (``surface_vertices``), so a crack narrower than about two vertex spacings is rendered
    as a groove wider than its crack-map mask, with steep walls outside that mask. A
    pixel-centre ray that hits such a wall sees the dark gap but lands on a non-crack
    texel: measured on close-up renders, the texel rule alone left a median 42 % of the
    dark crack pixels unlabelled. A ray hit lies on the mesh, so the mesh depth at its UV
    is the depth of what the pixel sees; applying the visible rule to the mesh groove
    (depth >= max(min_depth_m, ratio * the groove's own local half-width)) labels the
    part of the rendered gap that is deep relative to its opening."""
    depth = np.asarray(mesh_depth_m, dtype=np.float32)
    return visible_mask(depth > GROOVE_EPS_M, depth, texel_m, depth_ratio=depth_ratio, min_depth_m=min_depth_m)


def drop_small_components(label: np.ndarray, min_px: int) -> np.ndarray:
    """Same dtype as ``label``, with 8-connected components of fewer than ``min_px`` pixels cleared.

    Applied in the camera view: the pixels kept are unchanged, so the label stays exact."""
    import cv2

    lab = np.asarray(label)
    on = lab > 0
    if min_px <= 1 or not on.any():
        return lab.copy()
    n, comp, stats, _ = cv2.connectedComponentsWithStats(on.astype(np.uint8), connectivity=8)
    small = stats[:, cv2.CC_STAT_AREA] < int(min_px)
    small[0] = False  # background
    out = lab.copy()
    out[small[comp] & on] = 0
    return out
