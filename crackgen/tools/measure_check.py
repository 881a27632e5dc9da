"""``crackgen measure-check``: the camera-view crack measurement against the generator's own GT.

For every sample with a visible crack, the rendered thesis mask (``mask_thesis.png``, or
``mask.png`` under ``[label] policy = "thesis"``) is measured in metres with the ray-cast
depth and the camera's K (``fusion.measure.metric_size.measure_in_view``: what ``cracktrain predict
--intrinsics`` does with a perfect mask and depth), and compared with the sample JSON's
``visible`` record (the same quantities on the crack map, exact geometry).  Reported per
quantity: the median and 90th percentile of |measured - GT| / GT over the samples.

What the error holds: the image sees the crack at the camera's resolution (a few px wide,
thin parts drop out or split a crack in two), the GT at the crack map's (sub-mm texels).
"""
from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from crackgen.errors import CrackgenError

QUANTITIES = ("longest_path", "tip_to_tip_sum", "total_length", "mean_width", "max_width")
MIN_TEXELS = 1  # samples whose visible GT has fewer crack texels are skipped (nothing in view)


class MeasureCheckError(CrackgenError, ValueError):
    """Bad dataset for the measurement check (names the path / sample)."""


def _relative_errors(rows: list[dict[str, Any]]) -> dict[str, dict[str, float | int | None]]:
    out: dict[str, dict[str, float | int | None]] = {}
    for q in QUANTITIES:
        e = np.array([abs(r["measured"][q] - r["gt"][q]) / r["gt"][q] for r in rows
                      if r["gt"][q] and r["measured"][q] is not None], dtype=np.float64)
        out[q] = {"n": int(e.size), "median": float(np.median(e)) if e.size else None,
                  "p90": float(np.percentile(e, 90)) if e.size else None,
                  "bias": float(np.median([(r["measured"][q] - r["gt"][q]) / r["gt"][q] for r in rows
                                           if r["gt"][q] and r["measured"][q] is not None])) if e.size else None}
    return out


def measure_check(path: str | os.PathLike, limit: int | None = None, progress: bool = True) -> dict[str, Any]:
    """Per-sample measured vs GT figures and their relative-error summary (see module doc)."""
    from tqdm import tqdm

    from crackgen.shards import ShardError, iter_samples, open_dataset
    from fusion.measure.metric_size import measure_in_view

    try:
        ds = open_dataset(str(path))
    except ShardError as exc:
        raise MeasureCheckError(f"{path}: not a crackgen dataset ({exc})") from None
    if not ds.shards:
        raise MeasureCheckError(f"{path}: no shards")
    rows: list[dict[str, Any]] = []
    skipped = 0
    times: list[float] = []
    try:
        it = iter_samples(ds.shards, members=["mask", "mask_thesis", "depth", "meta"])
        for i, s in enumerate(tqdm(it, total=limit or ds.num_samples, desc="measure-check", disable=not progress)):
            if limit and i >= limit:
                break
            meta = s.get("meta") or {}
            vis = meta.get("visible")
            if vis is None:
                raise MeasureCheckError(f"{path}: sample {s['__key__']} has no 'visible' GT (made before it existed?)")
            if (vis.get("texels") or 0) < MIN_TEXELS or "depth" not in s:
                skipped += 1
                continue
            mask = s["mask_thesis"] if "mask_thesis" in s else s["mask"]
            if not (mask > 0).any():
                skipped += 1
                continue
            K = np.asarray(meta["cameras"]["rgb"]["K"], dtype=np.float64)
            t0 = time.perf_counter()
            m = measure_in_view(mask > 0, s["depth"], K)
            times.append(time.perf_counter() - t0)
            rows.append({
                "key": s["__key__"],
                "shape": meta.get("crack", {}).get("shape"),
                "gt": {q: vis.get(f"{q}_m") for q in QUANTITIES},
                "measured": {q: (float(getattr(m, q)) if np.isfinite(getattr(m, q)) else None) for q in QUANTITIES},
                "components": {"gt": len(vis.get("components", [])), "measured": len(m.components)},
            })
    except ShardError as exc:
        raise MeasureCheckError(str(exc)) from None
    if not rows:
        raise MeasureCheckError(f"{path}: no sample with a visible crack to check")
    shapes = sorted({str(r["shape"]) for r in rows})
    return {"path": str(path), "samples": len(rows), "skipped": skipped,
            "median_measure_s": float(np.median(times)), "errors": _relative_errors(rows),
            "errors_by_shape": {sh: _relative_errors([r for r in rows if str(r["shape"]) == sh]) for sh in shapes},
            "per_sample": rows}


def format_check(res: dict[str, Any]) -> str:
    lines = [f"{res['samples']} samples checked ({res['skipped']} without a visible crack skipped); "
             f"median {1e3 * res['median_measure_s']:.0f} ms per measurement",
             f"{'quantity':<16} {'n':>4} {'median rel. err':>16} {'p90 rel. err':>13} {'median bias':>12}"]
    def pct(v):
        return "-" if v is None else f"{100 * v:.1f}%"

    for q, e in res["errors"].items():
        lines.append(f"{q:<16} {e['n']:>4} {pct(e['median']):>16} {pct(e['p90']):>13} {pct(e['bias']):>12}")
    lines.append("by crack shape, median / p90 relative error:")
    lines.append(f"{'shape':<10} {'n':>4} " + " ".join(f"{q:>18}" for q in QUANTITIES))
    for sh, errs in res.get("errors_by_shape", {}).items():
        n = errs[QUANTITIES[0]]["n"]
        cells = " ".join(f"{pct(errs[q]['median']) + ' / ' + pct(errs[q]['p90']):>18}" for q in QUANTITIES)
        lines.append(f"{sh:<10} {n:>4} {cells}")
    return "\n".join(lines)


def write_json(res: dict[str, Any], out: str | os.PathLike) -> Path:
    p = Path(out)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(res, indent=2))
    return p
