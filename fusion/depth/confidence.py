"""Confidence targets and the two fusion rules of the ToF/LiDAR-stereo confidence fusion.

Thesis Ch. 3.3 / 4.6 after Agresti et al. 2019:

* target confidence of a candidate map D: C* = exp(-|D - D_GT|) (1 = exact);
* max rule (eq. 3.25 / 4.11): D_F = D_o where C_o >= C_s, else D_s
  (o = the other sensor, ToF or LiDAR; ties go to it, as in the thesis);
* weighted rule (eq. 4.12): D_F = D_o softmax(C)_o + D_s softmax(C)_s.

Where one candidate has no value (-1) the other one is taken; where neither
has, the result is -1.
"""
from __future__ import annotations

import numpy as np

from fusion.depth.densify import valid_values
from fusion.errors import FusionError


class FusionRuleError(FusionError):
    """Candidate and confidence maps of different shapes."""


def _check(*maps: np.ndarray) -> None:
    shapes = {np.shape(m) for m in maps}
    if len(shapes) != 1:
        raise FusionRuleError(f"disparity and confidence maps must share one shape, got {sorted(shapes)}")


def confidence_target(disp: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """C* = exp(-|D - D_GT|) (float32); 0 where D has no value, NaN where the GT has none (not scored)."""
    _check(disp, gt)
    d = np.asarray(disp, dtype=np.float64)
    g = np.asarray(gt, dtype=np.float64)
    out = np.where(valid_values(d), np.exp(-np.abs(d - g)), 0.0)
    return np.where(valid_values(g), out, np.nan).astype(np.float32)


def fuse_max(d_stereo: np.ndarray, d_other: np.ndarray, c_stereo: np.ndarray, c_other: np.ndarray) -> np.ndarray:
    """Max-confidence rule: the other sensor's value where its confidence >= stereo's, else stereo's."""
    _check(d_stereo, d_other, c_stereo, c_other)
    ds, do = np.asarray(d_stereo, np.float32), np.asarray(d_other, np.float32)
    vs, vo = valid_values(ds), valid_values(do)
    take_other = vo & (~vs | (np.asarray(c_other) >= np.asarray(c_stereo)))
    return np.where(take_other, do, np.where(vs, ds, -1.0)).astype(np.float32)


def softmax_weights(c_stereo: np.ndarray, c_other: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """softmax over the two confidences per pixel: (w_stereo, w_other), summing to 1."""
    cs, co = np.asarray(c_stereo, np.float64), np.asarray(c_other, np.float64)
    m = np.maximum(cs, co)
    es, eo = np.exp(cs - m), np.exp(co - m)
    return es / (es + eo), eo / (es + eo)


def fuse_weighted(d_stereo: np.ndarray, d_other: np.ndarray, c_stereo: np.ndarray, c_other: np.ndarray) -> np.ndarray:
    """Softmax-weighted rule: D_o softmax(C)_o + D_s softmax(C)_s; one valid candidate is taken as is."""
    _check(d_stereo, d_other, c_stereo, c_other)
    ds, do = np.asarray(d_stereo, np.float64), np.asarray(d_other, np.float64)
    vs, vo = valid_values(ds), valid_values(do)
    ws, wo = softmax_weights(c_stereo, c_other)
    both = ws * ds + wo * do
    out = np.where(vs & vo, both, np.where(vo, do, np.where(vs, ds, -1.0)))
    return out.astype(np.float32)
