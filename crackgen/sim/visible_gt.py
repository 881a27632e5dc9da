"""GT crack size for the part of the crack a camera sees: the ``visible`` key of the sample JSON.

The crack map's ``length_m`` covers the whole 1-3 m surface patch; a measurement from one
image can only see the crack inside the view.  So the crack-map mask (the thesis mask,
Z < t: what ``mask_thesis.png`` / the thesis-policy ``mask.png`` show) is clipped to the
texels the camera sees, and measured on the surface with ``fusion.measure.crack_measure`` at the
crack map's texel size: the same definitions as a measurement from the image, but exact
geometry, in metres on the (flat) surface patch.

A crack texel is seen when its opening (the texel centre on the surface plane z = 0)
projects into the image and the pixel ray there reaches it: the ray's hit UV lies within
the pixel's footprint of the texel, widened by how far a ray can travel sideways inside the
crack (deepest crack depth x tan(incidence)): a crack is seen through its opening, so its own
walls do not hide it.
Anything else in the way (the patch edge, relief) does.

Severity data (thesis: longer cracks are deeper, after Paris-Erdogan): each visible
component carries its lengths with the mean and maximum crack depth (m) over its texels.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from scipy import ndimage

from crackgen.procedural.crackmap import CrackMap
from fusion.geometry.camera import Camera
from fusion.measure.crack_measure import measure_cracks

__all__ = ["visible_texels", "visible_ground_truth"]

MAX_COMPONENTS = 50  # per-component records kept in the JSON (longest first)
_EIGHT = np.ones((3, 3), bool)


def _footprint_texels(uv: np.ndarray, n: int) -> np.ndarray:
    """(H, W) texels one camera pixel spans on the surface (largest UV step to a neighbour)."""
    du = np.abs(np.diff(uv, axis=1, append=np.nan)) * n
    dv = np.abs(np.diff(uv, axis=0, append=np.nan)) * n
    step = np.fmax(np.fmax(du[..., 0], du[..., 1]), np.fmax(dv[..., 0], dv[..., 1]))  # NaN only where all are
    ok = np.isfinite(step)
    return np.where(ok, step, step[ok].max() if ok.any() else 1.0)


def visible_texels(cm: CrackMap, camera: Camera, uv: np.ndarray, texels: np.ndarray | None = None) -> np.ndarray:
    """Bool (N, N): crack texels (``texels``, default the thesis mask) the camera sees (module doc).

    ``uv``: (H, W, 2) hit UV per camera pixel (NaN on a miss), from ``view_ground_truth``."""
    mask = cm.mask if texels is None else texels
    n = cm.size_px
    jj, ii = np.nonzero(mask)
    out = np.zeros_like(mask, dtype=bool)
    if jj.size == 0:
        return out
    u = (ii + 0.5) / n
    v = (jj + 0.5) / n
    world = np.stack([(u - 0.5) * cm.size_m, (v - 0.5) * cm.size_m, np.zeros_like(u)], axis=1)
    pix, z = camera.project(world)
    col = np.floor(pix[:, 0] + 0.5).astype(np.intp)
    row = np.floor(pix[:, 1] + 0.5).astype(np.intp)
    inside = (z > 0) & (col >= 0) & (col < camera.width) & (row >= 0) & (row < camera.height)
    k = np.nonzero(inside)[0]
    hit = uv[row[k], col[k]]
    ok = np.isfinite(hit).all(axis=1)
    off = np.hypot(hit[:, 0] - u[k], hit[:, 1] - v[k]) * n  # texels between hit and texel
    ray = world[k] - camera.center
    tan_inc = np.hypot(ray[:, 0], ray[:, 1]) / np.maximum(np.abs(ray[:, 2]), 1e-9)
    wall = float(cm.depth_m.max()) / cm.texel_m * tan_inc  # how far a ray can travel inside the crack
    tol = _footprint_texels(uv, n)[row[k], col[k]] + 1.0 + wall
    seen = ok & (off <= tol)
    out[jj[k[seen]], ii[k[seen]]] = True
    return out


def visible_ground_truth(cm: CrackMap, camera: Camera, uv: np.ndarray) -> dict[str, Any]:
    """The ``visible`` record: the seen crack's lengths and widths (m) on the surface, per component
    with depth statistics; ``texels`` = seen crack texels (0: nothing to measure, quantities null)."""
    seen = visible_texels(cm, camera, uv)
    rec: dict[str, Any] = {"label": "thesis", "unit": "m", "texel_m": cm.texel_m, "texels": int(seen.sum())}
    keys = ("longest_path", "tip_to_tip_sum", "total_length", "mean_width", "max_width")
    if not seen.any():
        rec.update({f"{k}_m": None for k in keys})
        rec["components"] = []
        return rec
    jj, ii = np.nonzero(seen)
    r0, r1 = max(jj.min() - 2, 0), min(jj.max() + 3, cm.size_px)
    c0, c1 = max(ii.min() - 2, 0), min(ii.max() + 3, cm.size_px)
    crop = seen[r0:r1, c0:c1]
    depth = cm.depth_m[r0:r1, c0:c1]
    meas = measure_cracks(crop, cm.texel_m)
    rec.update({f"{k}_m": _num(getattr(meas, k)) for k in keys})
    lab, _ = ndimage.label(crop, structure=_EIGHT)
    comps = []
    for c in meas.components[:MAX_COMPONENTS]:
        region = lab == lab[c.endpoints[0]]
        d = depth[region]
        comps.append({
            "tip_to_tip_m": _num(c.tip_to_tip),
            "total_length_m": _num(c.total_length),
            "mean_width_m": _num(c.mean_width),
            "max_width_m": _num(c.max_width),
            "mean_depth_m": _num(float(d.mean())) if d.size else None,
            "max_depth_m": _num(float(d.max())) if d.size else None,
            "tips": c.n_tips,
        })
    rec["components"] = comps
    return rec


def _num(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None
