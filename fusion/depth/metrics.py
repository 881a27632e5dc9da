"""Disparity error metrics of the fusion evaluation (thesis Tables 3.6-3.8, 4.x).

Per scene: MSE, MAE, RMSE (px) and the percentage of pixels with absolute
error above 1, 2, 3 and 5 px, over the pixels where the GT has a value (and an
optional mask), among those where the estimate has one; ``density`` says what
fraction of the GT pixels the estimate covers, so sparse maps are not silently
favoured. The dataset figure is the mean of the per-scene figures, as in the
thesis tables.
"""
from __future__ import annotations

import math
from typing import Iterable, Mapping, Sequence

import numpy as np

from fusion.depth.densify import valid_values

BAD_THRESHOLDS_PX = (1, 2, 3, 5)
METRIC_KEYS = ("mse", "mae", "rmse") + tuple(f"bad{t}" for t in BAD_THRESHOLDS_PX) + ("density",)


def disparity_metrics(est: np.ndarray, gt: np.ndarray, mask: np.ndarray | None = None) -> dict[str, float]:
    """Scene metrics; ``bad<t>`` in percent. NaN errors (density 0) when no pixel can be scored."""
    if np.shape(est) != np.shape(gt):
        raise ValueError(f"estimate {np.shape(est)} and GT {np.shape(gt)} differ in shape")
    ok_gt = valid_values(gt)
    if mask is not None:
        ok_gt &= np.asarray(mask, dtype=bool)
    ok = ok_gt & valid_values(est)
    err = np.abs(np.asarray(est, np.float64)[ok] - np.asarray(gt, np.float64)[ok])
    out = {k: math.nan for k in METRIC_KEYS}
    out["density"] = float(ok.sum() / max(int(ok_gt.sum()), 1))
    if err.size:
        out["mse"] = float(np.mean(err**2))
        out["mae"] = float(err.mean())
        out["rmse"] = math.sqrt(out["mse"])
        for t in BAD_THRESHOLDS_PX:
            out[f"bad{t}"] = 100.0 * float((err > t).mean())
    return out


def average_metrics(per_scene: Iterable[Mapping[str, float]]) -> dict[str, float]:
    """Mean over scenes of each metric, skipping scenes where it is NaN."""
    rows = list(per_scene)
    out = {}
    for k in METRIC_KEYS:
        vals = [r[k] for r in rows if not math.isnan(r[k])]
        out[k] = float(np.mean(vals)) if vals else math.nan
    return out


def format_table(rows: Mapping[str, Mapping[str, float]], keys: Sequence[str] = METRIC_KEYS) -> str:
    """Markdown table, one row per map (``stereo``, ``ToF``, ``fused, max``, ...)."""
    names = {"mse": "MSE", "mae": "MAE", "rmse": "RMSE", "density": "density"}
    head = [names.get(k, f">{k[3:]} px %") for k in keys]
    lines = ["| map | " + " | ".join(head) + " |", "|---|" + "---|" * len(keys)]
    for name, m in rows.items():
        lines.append(f"| {name} | " + " | ".join(f"{m[k]:.3f}" if k != "density" else f"{m[k]:.2f}" for k in keys) + " |")
    return "\n".join(lines)
