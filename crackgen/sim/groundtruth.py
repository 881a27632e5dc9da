"""Exact GT depth and crack mask in a camera view, by ray casting its pixel centres.

Why a ray cast and not a rasterised emission pass (the thesis's choice): the
lookup happens at the exact pixel-centre ray, so anti-aliasing cannot smear the
mask, and depth/mask/ToF share one code path on one mesh. A pixel is crack iff
the visible surface point's UV lies in a crack texel of the crack map.

Which texels are crack is the ``[label]`` policy: ``thesis`` = M = Z < t (eq. 5.5);
``visible`` (default) = the crack texels deep relative to their opening
(``crackgen.procedural.visible_label``), looked up per pixel by the same rule, then
components smaller than ``min_component_px`` camera pixels are dropped. Either way the
rendered RGB is checked (``crackgen.sim.visibility``) and a crack that does not show is
emptied, kept or redrawn as the recipe says.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from crackgen.config.recipe import LabelSection
from crackgen.procedural.crackmap import CrackMap, nearest_texel
from crackgen.procedural.visible_label import (
    VisibleLabelError,
    drop_small_components,
    groove_visible_mask,
    visible_mask,
)
from crackgen.sim.raycast import MeshRaycaster, RayHits
from crackgen.sim.visibility import decide_label, label_contrast
from fusion.geometry.camera import Camera


@dataclass
class ViewGroundTruth:
    depth: np.ndarray  # (H,W) float32 planar z, -1 where the ray misses the surface
    mask: np.ndarray  # (H,W) uint8 0/255
    uv: np.ndarray  # (H,W,2) hit UV, NaN on miss
    hits: RayHits


def mask_lookup(crack_mask: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Nearest-texel crack mask at UVs (crack-map convention: [j, i], i along u, row 0 at v = 0)."""
    ok = np.isfinite(uv).all(axis=-1)
    uv = np.nan_to_num(uv)
    return nearest_texel(crack_mask, uv[..., 0], uv[..., 1]) & ok


def view_ground_truth(camera: Camera, caster: MeshRaycaster, crack_mask: np.ndarray) -> ViewGroundTruth:
    origins, dirs, z_per_t = camera.pixel_rays()
    hits = caster.cast(origins, dirs)
    depth = np.where(hits.hit, hits.t * z_per_t, -1.0).astype(np.float32)
    shape = (camera.height, camera.width)
    uv = hits.uv.reshape(*shape, 2)
    mask = (mask_lookup(crack_mask, uv) * 255).astype(np.uint8)
    return ViewGroundTruth(depth=depth.reshape(shape), mask=mask, uv=uv, hits=hits)


@dataclass
class ViewLabel:
    """The label of one view under the recipe's ``[label]`` policy, and its check."""

    mask: np.ndarray  # (H,W) uint8 0/255: the label written as mask.png
    thesis: np.ndarray  # (H,W) uint8 0/255: eq. 5.5 mask (mask_thesis.png when the policy is visible)
    redraw: bool  # the crack does not show and the recipe asks for a new one
    meta: dict[str, Any] = field(default_factory=dict)  # meta["label"]


def label_texels(cfg: LabelSection, cm: CrackMap, mesh_depth_m: np.ndarray | None = None) -> np.ndarray:
    """Bool crack-map texels that are labelled crack under ``cfg.policy``.

    ``mesh_depth_m``: the rendered mesh's depth (m) at the crack map's texel centres
    (``surface.mesh_depth_map``). Given, the visible label also takes the visible part of
    the groove the mesh renders (``groove_visible_mask``), which is wider than the crack
    map's mask for cracks narrower than the vertex footprint."""
    if cfg.policy == "thesis":
        return cm.mask
    label = visible_mask(cm.mask, cm.depth_m, cm.texel_m, depth_ratio=cfg.depth_ratio,
                         min_depth_m=cfg.min_depth_m, skel=cm.skeleton)
    if mesh_depth_m is not None:
        if np.shape(mesh_depth_m) != cm.mask.shape:
            raise VisibleLabelError(f"mesh_depth_m must have the crack map's shape {cm.mask.shape}, got {np.shape(mesh_depth_m)}")
        label |= groove_visible_mask(mesh_depth_m, cm.texel_m, depth_ratio=cfg.depth_ratio,
                                     min_depth_m=cfg.min_depth_m)
    return label


def view_label(cfg: LabelSection, cm: CrackMap, gt: ViewGroundTruth, rgb: np.ndarray, attempt: int = 0,
               mesh_depth_m: np.ndarray | None = None, texels: np.ndarray | None = None) -> ViewLabel:
    """Label of the view ``gt`` was cast for, checked on the clean render ``rgb``
    (``mesh_depth_m``: see ``label_texels``). ``texels``: ``label_texels(cfg, cm, mesh_depth_m)`` when the caller
    already has it: it is a property of the scene, so the views of one scene share it."""
    thesis = gt.mask
    if cfg.policy == "thesis":
        label = thesis.copy()
    else:
        if texels is None:
            texels = label_texels(cfg, cm, mesh_depth_m)
        label = (mask_lookup(texels, gt.uv) * 255).astype(np.uint8)
        label = drop_small_components(label, cfg.min_component_px)
    px = int(np.count_nonzero(label))
    contrast = label_contrast(rgb, label)
    d = decide_label(bool(thesis.any()), px, contrast, min_contrast=cfg.min_contrast, invisible=cfg.invisible,
                     attempt=attempt, max_redraws=cfg.max_redraws)
    if d.label_emptied:
        label = np.zeros_like(label)
    meta = {
        "policy": cfg.policy,
        "pixel_fraction": float(np.count_nonzero(label)) / float(label.size),
        "thesis_pixel_fraction": float(np.count_nonzero(thesis)) / float(thesis.size),
        "contrast": None if contrast is None else float(contrast),
        "shows": d.shows,
        "action": d.action,
        "attempt": int(attempt),
    }
    return ViewLabel(mask=label, thesis=thesis, redraw=d.action == "redraw", meta=meta)
