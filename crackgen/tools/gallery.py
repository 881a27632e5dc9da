"""`crackgen inspect DIR`: a static HTML gallery of a dataset, plus a contact sheet PNG.

Why static: the gallery must open from a file browser or an artefact store with no
server. Thumbnails are small PNG files under ``DIR/inspect/thumbs/``; the page holds
the per-sample metadata as inline JSON and pages through it with a few lines of
vanilla JS (``loading="lazy"`` images), so thousands of samples stay light. The
dataset summary (counts, crack-pixel fraction, sparse-depth fill, parameter
histograms) is inline SVG made here, no plotting library.

Colour maps: depth uses TURBO scaled to the sample's valid range; pixels with no value
(-1) are drawn dark grey so sensor holes stay visible. Sparse LiDAR points are grown
to 3x3 px in the thumbnails so they can be seen (the data is not changed).
"""
from __future__ import annotations

import html
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

import cv2
import numpy as np

from crackgen.errors import CrackgenError

THUMB_W = 192
HOLE_BGR = (60, 60, 60)
CONTACT_COLS = 8


class InspectError(CrackgenError, ValueError):
    """The dataset cannot be inspected (names the path)."""


# ---------------------------------------------------------------- images

def _fit(img: np.ndarray, width: int = THUMB_W, nearest: bool = False) -> np.ndarray:
    h, w = img.shape[:2]
    if w <= width:
        return img
    size = (width, max(1, round(h * width / w)))
    return cv2.resize(img, size, interpolation=cv2.INTER_NEAREST if nearest else cv2.INTER_AREA)


def colorize_depth(depth: np.ndarray, sparse: bool = False, lo: float | None = None,
                   hi: float | None = None) -> np.ndarray:
    """RGB uint8 TURBO map of a depth/disparity map; no-value pixels (<= 0) dark grey."""
    d = np.asarray(depth, np.float32)
    valid = np.isfinite(d) & (d > 0)
    out = np.empty(d.shape + (3,), np.uint8)
    out[:] = HOLE_BGR[::-1]
    if valid.any():
        v = d[valid]
        lo = float(np.percentile(v, 1)) if lo is None else lo
        hi = float(np.percentile(v, 99)) if hi is None else hi
        scale = 255.0 / max(hi - lo, 1e-6)
        g = np.clip((d - lo) * scale, 0, 255).astype(np.uint8)
        rgb = cv2.cvtColor(cv2.applyColorMap(g, cv2.COLORMAP_TURBO), cv2.COLOR_BGR2RGB)
        if sparse:
            # grow points to 3x3 so single-pixel returns show in a thumbnail
            kernel = np.ones((3, 3), np.uint8)
            grown = cv2.dilate(valid.astype(np.uint8), kernel) > 0
            idx = cv2.dilate(np.where(valid, g, 0).astype(np.uint8), kernel)
            rgb = cv2.cvtColor(cv2.applyColorMap(idx, cv2.COLORMAP_TURBO), cv2.COLOR_BGR2RGB)
            out[grown] = rgb[grown]
        else:
            out[valid] = rgb[valid]
    return out


def mask_overlay(rgb: np.ndarray, mask: np.ndarray, alpha: float = 0.6) -> np.ndarray:
    """RGB with crack pixels tinted red."""
    out = rgb.astype(np.float32).copy()
    m = mask > 127
    out[m] = (1 - alpha) * out[m] + alpha * np.array([255, 0, 0], np.float32)
    return np.clip(out, 0, 255).astype(np.uint8)


def _write_png(path: Path, rgb: np.ndarray) -> None:
    img = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR) if rgb.ndim == 3 else rgb
    if not cv2.imwrite(str(path), img):
        raise InspectError(f"{path}: cannot write PNG")


# ---------------------------------------------------------------- summary charts

def svg_histogram(values: Iterable[float], title: str, bins: int = 20, width: int = 260, height: int = 120) -> str:
    """Inline SVG bar histogram of numeric values (empty note when there are none)."""
    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], float)
    head = f'<figure class="chart"><figcaption>{html.escape(title)}</figcaption>'
    if v.size == 0:
        return head + "<p>no values</p></figure>"
    lo, hi = float(v.min()), float(v.max())
    if hi <= lo:
        hi = lo + 1e-9
    counts, edges = np.histogram(v, bins=bins, range=(lo, hi))
    return head + _bars(counts.tolist(), [f"{edges[i]:.3g}–{edges[i + 1]:.3g}" for i in range(bins)],
                        width, height, f"{lo:.3g}", f"{hi:.3g}") + "</figure>"


def svg_counts(counts: dict[str, int], title: str, width: int = 260, height: int = 120) -> str:
    head = f'<figure class="chart"><figcaption>{html.escape(title)}</figcaption>'
    if not counts:
        return head + "<p>no values</p></figure>"
    keys = sorted(counts)
    return head + _bars([counts[k] for k in keys], keys, width, height, None, None, labels=True) + "</figure>"


def _bars(counts: list[int], tips: list[str], width: int, height: int, lo: str | None, hi: str | None,
          labels: bool = False) -> str:
    n = len(counts)
    top = max(max(counts), 1)
    plot_h = height - 18
    bw = width / n
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" role="img">']
    for i, c in enumerate(counts):
        h = plot_h * c / top
        parts.append(f'<rect x="{i * bw + 1:.1f}" y="{plot_h - h:.1f}" width="{max(bw - 2, 1):.1f}" '
                     f'height="{h:.1f}" fill="#4a7bd0"><title>{html.escape(str(tips[i]))}: {c}</title></rect>')
        if labels:
            parts.append(f'<text x="{i * bw + bw / 2:.1f}" y="{height - 4}" font-size="10" '
                         f'text-anchor="middle">{html.escape(str(tips[i]))[:10]} ({c})</text>')
    if lo is not None:
        parts.append(f'<text x="0" y="{height - 4}" font-size="10">{html.escape(lo)}</text>')
        parts.append(f'<text x="{width}" y="{height - 4}" font-size="10" text-anchor="end">{html.escape(hi)}</text>')
    parts.append("</svg>")
    return "".join(parts)


# ---------------------------------------------------------------- gallery

@dataclass
class _Entry:
    key: str
    thumbs: dict[str, str]  # view -> relative path
    params: dict[str, Any]


def _adapt_label(a: dict[str, Any]) -> str:
    """``fourier 0.031 <- site_12.jpg`` for an adapted sample, ``none`` otherwise."""
    if not a.get("applied"):
        return "none"
    band = f" {a['band']:.3f}" if "band" in a else ""
    return f"{a.get('method')}{band} <- {a.get('target')}"


_CAMFX_SHORT = {  # effect -> (short name, metadata key of its main value, format)
    "auto_exposure": ("ae", "auto_exposure_luma", "{:.0f}"),
    "exposure": ("ev", "exposure_ev", "{:+.2f}"),
    "white_balance": ("wb", "wb_shift_mired", "{:+.0f}mired"),
    "tone": ("gamma", "tone_gamma", "{:.2f}"),
    "vignetting": ("vig", "vignette_strength", "{:.2f}"),
    "defocus": ("defocus", "defocus_radius_px", "{:.1f}px"),
    "motion_blur": ("motion", "motion_length_px", "{:.1f}px"),
    "noise": ("noise", "noise_full_well_e", "{:.0f}e"),
    "sharpen": ("sharpen", "sharpen_amount", "{:.2f}"),
    "jpeg": ("jpeg", "jpeg_quality", "q{}"),
}


def _camfx_label(c: dict[str, Any]) -> str:
    """``ev:+0.31,noise:1200e,jpeg:q83``: each applied camera effect with its main value; ``none`` otherwise."""
    parts = []
    for name in c.get("applied") or []:
        short, key, fmt = _CAMFX_SHORT.get(name, (name, None, ""))
        value = c.get(key) if key else None
        parts.append(short + (":" + fmt.format(value) if value is not None else ""))
    return ",".join(parts) or "none"


def _params(meta: dict[str, Any], sample: dict[str, Any]) -> dict[str, Any]:
    spec = meta.get("spec", {})
    cam = spec.get("camera", {})
    crack = meta.get("crack", {})
    lights = spec.get("lights", [])
    p: dict[str, Any] = {
        "family": meta.get("material", {}).get("family") or spec.get("material", {}).get("family"),
        "shape": (meta.get("crack") or {}).get("shape", "fbm"),
        "distractors": ",".join(meta.get("material", {}).get("distractors", [])) or "-",
        "lights": ",".join(L.get("kind", "?") for L in lights),
        "shadow": meta.get("shadow", {}).get("pattern") if meta.get("shadow", {}).get("enabled") else "none",
        "cam_dist_m": cam.get("distance_m"),
        "tilt_deg": math.degrees(cam["tilt_rad"]) if "tilt_rad" in cam else None,
        "focal_mm": cam.get("focal_mm"),
        "crack_len_m": crack.get("length_m"),  # whole patch: sum of skeleton diameters
        "visible_len_m": (meta.get("visible") or {}).get("longest_path_m"),  # thesis length of the part in view
        "crack_px_frac": crack.get("pixel_fraction"),
        "adapt": _adapt_label(meta.get("adapt") or {}),
        "camera_fx": _camfx_label(meta.get("camera_effects") or {}),
    }
    if "mask" in sample and p["crack_px_frac"] is None:
        p["crack_px_frac"] = float((sample["mask"] > 127).mean())
    for s in ("tof", "lidar"):
        if s in sample:
            p[f"{s}_fill"] = float((sample[s] > 0).mean())
    return {k: (round(v, 4) if isinstance(v, float) else v) for k, v in p.items()}


def _thumbs(sample: dict[str, Any], tdir: Path, key: str) -> dict[str, str]:
    views: dict[str, np.ndarray] = {}
    rgb = sample.get("rgb")
    if rgb is not None:
        views["rgb"] = _fit(rgb)
        if "mask" in sample:
            views["mask"] = _fit(mask_overlay(rgb, sample["mask"]))
    depth = sample.get("depth")
    lo = hi = None
    if depth is not None:
        v = depth[depth > 0]
        if v.size:
            lo, hi = float(np.percentile(v, 1)), float(np.percentile(v, 99))
        views["depth"] = _fit(colorize_depth(depth, False, lo, hi))
    for s in ("tof", "lidar"):
        if s in sample and isinstance(sample[s], np.ndarray):
            # sparse maps share the dense map's colour scale so they can be compared by eye
            views[s] = _fit(colorize_depth(sample[s], True, lo, hi), nearest=True)
    if "disp_sgm" in sample:
        views["disp_sgm"] = _fit(colorize_depth(sample["disp_sgm"], False))
    out = {}
    for name, img in views.items():
        fn = f"{key}_{name}.png"
        _write_png(tdir / fn, img)
        out[name] = f"thumbs/{fn}"
    return out


def contact_sheet(tiles: list[np.ndarray], cols: int = CONTACT_COLS, pad: int = 2) -> np.ndarray:
    """Grid of equally sized RGB tiles (smaller ones padded) on a dark background."""
    if not tiles:
        raise InspectError("contact sheet: no tiles")
    th = max(t.shape[0] for t in tiles)
    tw = max(t.shape[1] for t in tiles)
    cols = min(cols, len(tiles))
    rows = -(-len(tiles) // cols)
    sheet = np.full((rows * (th + pad) + pad, cols * (tw + pad) + pad, 3), 30, np.uint8)
    for k, t in enumerate(tiles):
        r, c = divmod(k, cols)
        y, x = pad + r * (th + pad), pad + c * (tw + pad)
        sheet[y:y + t.shape[0], x:x + t.shape[1]] = t
    return sheet


def write_gallery(root: str | os.PathLike, page_size: int = 24, limit: int | None = None,
                  contact_max: int = 64) -> Path:
    """Write ``ROOT/inspect/index.html`` (+ thumbs/, contact_sheet.png); returns the index path."""
    from crackgen.shards import ShardError, iter_samples

    root = Path(root)
    if not root.is_dir():
        raise InspectError(f"{root}: dataset directory not found")
    if page_size < 1:
        raise InspectError(f"--page-size must be >= 1, got {page_size}")
    idir = root / "inspect"
    tdir = idir / "thumbs"
    tdir.mkdir(parents=True, exist_ok=True)
    for old in tdir.glob("*.png"):
        old.unlink()
    entries: list[_Entry] = []
    tiles: list[np.ndarray] = []
    want = {"rgb", "mask", "depth", "tof", "lidar", "disp_sgm", "meta"}
    try:
        for s in iter_samples(str(root), members=want):
            key = s["__key__"]
            meta = s.get("meta") or {}
            entries.append(_Entry(key, _thumbs(s, tdir, key), _params(meta, s)))
            if len(tiles) < contact_max and "rgb" in s:
                t = _fit(mask_overlay(s["rgb"], s["mask"]) if "mask" in s else s["rgb"], 128)
                tiles.append(t)
            if limit is not None and len(entries) >= limit:
                break
    except ShardError as exc:
        raise InspectError(str(exc)) from None
    if not entries:
        raise InspectError(f"{root}: no samples found")
    _write_png(idir / "contact_sheet.png", contact_sheet(tiles))
    index = idir / "index.html"
    index.write_text(_page(root, entries, page_size), encoding="utf-8")
    return index


def _summary_html(entries: list[_Entry]) -> str:
    P = [e.params for e in entries]

    def col(k: str) -> list[float]:
        return [p[k] for p in P if isinstance(p.get(k), (int, float))]

    def counts(k: str, split: bool = False, method_only: bool = False, name_only: bool = False) -> dict[str, int]:
        out: dict[str, int] = {}
        for p in P:
            vals = str(p.get(k)).split(",") if split else [str(p.get(k))]
            if method_only:
                vals = [v.split(" ", 1)[0] for v in vals]
            if name_only:  # "ev:+0.31" -> "ev"
                vals = [v.split(":", 1)[0] for v in vals]
            for v in vals:
                out[v] = out.get(v, 0) + 1
        return out

    charts = [
        svg_histogram(col("crack_px_frac"), "crack-pixel fraction"),
        svg_histogram(col("tof_fill"), "ToF fill ratio (RGB view)"),
        svg_histogram(col("lidar_fill"), "LiDAR fill ratio (RGB view)"),
        svg_histogram(col("crack_len_m"), "GT crack length, whole patch (m)"),
        svg_histogram(col("visible_len_m"), "GT longest crack path in view (m)"),
        svg_histogram(col("cam_dist_m"), "camera distance (m)"),
        svg_histogram(col("tilt_deg"), "camera tilt (deg)"),
        svg_counts(counts("family"), "material family"),
        svg_counts(counts("shape"), "crack shape family"),
        svg_counts(counts("lights", split=True), "light kinds"),
        svg_counts(counts("shadow"), "shadow pattern"),
        svg_counts(counts("adapt", method_only=True), "site adaptation method"),
        svg_counts(counts("camera_fx", split=True, name_only=True), "camera effects applied"),
    ]
    return "".join(charts)


_CSS = """
body{font-family:system-ui,sans-serif;margin:1em;background:#fafafa;color:#222}
h1{font-size:1.3em} .charts{display:flex;flex-wrap:wrap;gap:12px}
.chart{margin:0;background:#fff;border:1px solid #ddd;padding:6px}
.chart figcaption{font-size:12px;font-weight:600}
.card{background:#fff;border:1px solid #ddd;margin:8px 0;padding:6px}
.card h3{margin:0 0 4px 0;font-size:14px;font-family:monospace}
.views{display:flex;flex-wrap:wrap;gap:4px}
.views figure{margin:0;font-size:11px;text-align:center}
.views img{display:block;image-rendering:pixelated;max-width:192px}
.params{font-size:12px;font-family:monospace;white-space:pre-wrap}
nav button{margin:0 4px}
"""

_JS = """
(function(){
  const data = JSON.parse(document.getElementById('samples').textContent);
  const pageSize = data.page_size, items = data.items;
  const pages = Math.max(1, Math.ceil(items.length / pageSize));
  let page = 0;
  const grid = document.getElementById('grid');
  function esc(s){return String(s).replace(/[&<>"]/g, c => ({'&':'&amp;','<':'&lt;','>':'&gt;','"':'&quot;'}[c]));}
  function render(){
    const start = page * pageSize, rows = [];
    for (const it of items.slice(start, start + pageSize)) {
      const views = Object.entries(it.thumbs).map(([name, src]) =>
        '<figure><img loading="lazy" alt="' + esc(it.key + ' ' + name) + '" src="' + esc(src) + '">' +
        '<figcaption>' + esc(name) + '</figcaption></figure>').join('');
      const params = Object.entries(it.params).map(([k, v]) => esc(k) + '=' + esc(v)).join('  ');
      rows.push('<div class="card"><h3>' + esc(it.key) + '</h3><div class="views">' + views +
                '</div><div class="params">' + params + '</div></div>');
    }
    grid.innerHTML = rows.join('');
    for (const el of document.querySelectorAll('.pageinfo'))
      el.textContent = 'page ' + (page + 1) + ' / ' + pages + ' (' + items.length + ' samples)';
    document.body.dataset.page = String(page);
  }
  function go(d){ page = Math.min(pages - 1, Math.max(0, page + d)); render(); window.scrollTo(0, 0); }
  for (const b of document.querySelectorAll('.prev')) b.addEventListener('click', () => go(-1));
  for (const b of document.querySelectorAll('.next')) b.addEventListener('click', () => go(1));
  const m = /page=(\\d+)/.exec(location.hash); if (m) page = Math.min(pages - 1, +m[1]);
  render();
})();
"""


def _page(root: Path, entries: list[_Entry], page_size: int) -> str:
    data = {"page_size": page_size, "items": [{"key": e.key, "thumbs": e.thumbs, "params": e.params} for e in entries]}
    # </ inside inline JSON would end the script element early
    blob = json.dumps(data, separators=(",", ":")).replace("</", "<\\/")
    manifest_note = ""
    mpath = root / "manifest.json"
    if mpath.is_file():
        try:
            m = json.loads(mpath.read_text(encoding="utf-8"))
            manifest_note = (f"recipe {html.escape(str(m.get('recipe_hash', ''))[:16])}, "
                             f"{len(m.get('shards', []))} shards, generator {html.escape(str(m.get('generator_version')))}")
        except (OSError, ValueError):
            manifest_note = "manifest unreadable"
    nav = '<nav><button class="prev">&larr; prev</button><span class="pageinfo"></span>' \
          '<button class="next">next &rarr;</button></nav>'
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>crackgen: {html.escape(root.name)}</title>
<style>{_CSS}</style></head>
<body>
<h1>{html.escape(root.name)}: {len(entries)} samples</h1>
<p>{manifest_note}. Contact sheet: <a href="contact_sheet.png">contact_sheet.png</a>.
Depth colour: TURBO over the sample's 1-99 % range (ToF/LiDAR on the dense depth's scale; LiDAR points grown
to 3x3 px); dark grey = no value.</p>
<section class="charts">{_summary_html(entries)}</section>
{nav}
<div id="grid"></div>
{nav}
<script type="application/json" id="samples">{blob}</script>
<script>{_JS}</script>
</body></html>
"""
