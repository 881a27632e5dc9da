"""Offset time-of-flight camera simulated by ray casting (thesis 5.2, step 6).

Model, per ToF pixel (each part switchable from ``TofSpec``):

* geometry: a pinhole ray through the pixel centre hits the mesh at range d
  (radial distance) with incidence angle theta;
* amplitude A = amplitude_scale * albedo * cos(theta) / d^2 (Lambertian return,
  active illumination co-located with the sensor);
* mixed ("flying") pixels: a pixel integrates the light of its whole footprint.
  Where the centre-range image is not locally smooth (a depth discontinuity:
  occlusion edge, crack wall, surface border) the pixel is re-sampled with a
  3x3 grid of sub-rays and the returns are summed as phasors,
  S = sum A_i exp(i 2 pi d_i / wrap), range = arg(S) wrap / 2 pi; without a wrap
  range this is its small-phase limit, the amplitude-weighted mean range. So a
  mixed pixel lands *between* foreground and background, as on real sensors;
* range noise: Gaussian with sigma = sigma0 + k * d^2 / A (shot noise grows as
  the return weakens; defaults give BlenSor's 4 mm at 5 m for albedo 0.5);
* per-sample bias, then phase wrap: range mod wrap_range_m;
* dropout: amplitude < min_amplitude or theta > grazing; a return with no
  amplitude (A = 0) is always dropped, even with min_amplitude = 0.

The measured points go to world and are splatted into the RGB view with the
z-buffer of ``fusion.geometry.projection`` (thesis eq. 5.7-5.9).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np

from crackgen.config.spec import TofSpec
from crackgen.errors import CrackgenError
from crackgen.sim.raycast import MeshRaycaster
from crackgen.sim.rig import Rig
from fusion.geometry.camera import Camera
from fusion.geometry.projection import project_points

AlbedoFn = Callable[[np.ndarray], np.ndarray]  # (N,2) UV -> (N,) grey albedo in [0, 1]

LUMA = np.array([0.2126, 0.7152, 0.0722])  # Rec.709 luminance of linear RGB
SUBRAY_OFFSETS = np.array([-1.0, 0.0, 1.0]) / 3.0  # 3x3 sub-cell centres of one pixel, px
MIX_DETECT_M = 5e-4  # non-planarity (m) above which a pixel is re-sampled with sub-rays


class SensorError(CrackgenError, ValueError):
    """A sensor cannot be simulated with the given rig/spec."""


@dataclass
class TofResult:
    camera: Camera  # the ToF camera (K, T_cam_world, size)
    range_m: np.ndarray  # (h,w) float32 measured radial range, -1 = no return / dropped
    depth_m: np.ndarray  # (h,w) float32 measured planar depth in the ToF frame, -1 = none
    amplitude: np.ndarray  # (h,w) float32 return amplitude (0 where the ray hits nothing)
    true_range_m: np.ndarray  # (h,w) float32 noise-free pixel-centre range, -1 = miss
    incidence_rad: np.ndarray  # (h,w) float32 incidence angle at the return (NaN on miss)
    mixed: np.ndarray  # (h,w) bool pixels whose value is a sub-ray mixture
    valid: np.ndarray  # (h,w) bool pixels with a measurement
    points_world: np.ndarray  # (K,3) measured points of the valid pixels (row-major order)
    points_amplitude: np.ndarray  # (K,) their amplitude
    depth_rgb: np.ndarray  # (H,W) float32 sparse depth in the RGB view, -1 = none
    amplitude_rgb: np.ndarray  # (H,W) float32 amplitude of the winning point in the RGB view, -1 = none


def constant_albedo(value: float = 0.5) -> AlbedoFn:
    """Uniform grey albedo, for tests and for materials without maps."""
    return lambda uv: np.full(len(uv), float(value))


def albedo_from_map(albedo: np.ndarray) -> AlbedoFn:
    """Bilinear grey albedo lookup in a (T,T,3) linear albedo map (or (T,T) grey) indexed
    [j, i], i along u, row 0 at v = 0 (the crack-map/material UV convention)."""
    a = np.asarray(albedo, dtype=np.float32)
    grey = (a @ LUMA.astype(np.float32)) if a.ndim == 3 else a
    grey = np.ascontiguousarray(grey, dtype=np.float32)
    n_v, n_u = grey.shape

    def lookup(uv: np.ndarray) -> np.ndarray:
        n = len(uv)
        cols = 1024  # cv2.remap wants maps with < 32767 rows: lay the N lookups out as a 2-D grid
        rows = max(1, -(-n // cols))
        x = np.full(rows * cols, -1.0, dtype=np.float32)
        y = np.full(rows * cols, -1.0, dtype=np.float32)
        x[:n] = uv[:, 0] * n_u - 0.5  # texel centres sit at (i + 0.5) / n_u
        y[:n] = uv[:, 1] * n_v - 0.5
        out = cv2.remap(grey, x.reshape(rows, cols), y.reshape(rows, cols), cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_REPLICATE)
        return out.ravel()[:n].astype(np.float64)

    return lookup


def amplitude_of(spec: TofSpec, albedo: np.ndarray, cos_inc: np.ndarray, range_m: np.ndarray) -> np.ndarray:
    """A = amplitude_scale * albedo * cos(theta) / d^2."""
    return spec.amplitude_scale * albedo * cos_inc / np.square(range_m)


def range_sigma(spec: TofSpec, range_m: np.ndarray, amplitude: np.ndarray) -> np.ndarray:
    """sigma = sigma0 + k * d^2 / A (m); infinite where there is no amplitude."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return spec.sigma0_m + spec.k_noise * np.square(range_m) / amplitude


def _returns(spec: TofSpec, caster: MeshRaycaster, albedo_at: AlbedoFn, origins: np.ndarray, dirs: np.ndarray):
    """Cast rays; range (inf on miss), amplitude (0 on miss), cos(incidence) (NaN on miss)."""
    hits = caster.cast(origins, dirs)
    n = hits.normals[hits.hit]
    cos_inc = np.full(len(hits.t), np.nan)
    cos_inc[hits.hit] = np.abs(np.einsum("ij,ij->i", n, dirs[hits.hit])) / np.linalg.norm(n, axis=1)
    amp = np.zeros(len(hits.t))
    if hits.hit.any():
        alb = np.clip(np.asarray(albedo_at(hits.uv[hits.hit]), dtype=np.float64), 0.0, None)
        amp[hits.hit] = amplitude_of(spec, alb, cos_inc[hits.hit], hits.t[hits.hit])
    return hits.t, amp, cos_inc


_SECOND_DIFF = [np.array(k, np.float32) for k in (
    [[0, 0, 0], [1, -2, 1], [0, 0, 0]], [[0, 1, 0], [0, -2, 0], [0, 1, 0]],
    [[1, 0, 0], [0, -2, 0], [0, 0, 1]], [[0, 0, 1], [0, -2, 0], [1, 0, 0]],
)]
_BOX3 = np.ones((3, 3), np.uint8)


def _discontinuities(depth_img: np.ndarray, threshold_m: float) -> np.ndarray:
    """Pixels whose surface is not locally planar: a miss/hit change in the 3x3 neighbourhood,
    or a second difference of inverse depth along a row, column or diagonal that, scaled
    back to metres (times z^2), exceeds ``threshold_m``. Inverse planar depth is linear in
    pixel coordinates on any plane, so tilted planes are never flagged, only real edges."""
    hit = np.isfinite(depth_img)
    z = np.where(hit, depth_img, 1.0)
    inv = np.where(hit, 1.0 / z, 0.0).astype(np.float32)
    curv = np.zeros(depth_img.shape, np.float32)
    for k in _SECOND_DIFF:
        curv = np.maximum(curv, np.abs(cv2.filter2D(inv, -1, k, borderType=cv2.BORDER_REPLICATE)))
    curv[[0, -1], :] = 0.0  # no second difference across the image border
    curv[:, [0, -1]] = 0.0
    out = hit & (curv * np.square(z) > threshold_m)
    h8 = hit.astype(np.uint8)
    out |= cv2.dilate(h8, _BOX3, borderType=cv2.BORDER_REPLICATE) != cv2.erode(h8, _BOX3, borderType=cv2.BORDER_REPLICATE)
    return out


def _mix_pixels(
    spec: TofSpec, cam: Camera, caster: MeshRaycaster, albedo_at: AlbedoFn, flat_idx: np.ndarray,
    centre: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Range, amplitude and cos(incidence) of the pixels ``flat_idx`` integrated over 3x3 sub-rays."""
    u = (flat_idx % cam.width).astype(np.float64)
    v = (flat_idx // cam.width).astype(np.float64)
    du, dv = np.meshgrid(SUBRAY_OFFSETS, SUBRAY_OFFSETS)
    sub = np.stack([du.ravel(), dv.ravel()], axis=1)
    sub = sub[np.any(sub != 0, axis=1)]  # the centre ray is already cast
    n_sub = len(sub) + 1
    pu = (u[:, None] + sub[None, :, 0]).ravel()
    pv = (v[:, None] + sub[None, :, 1]).ravel()
    d_cam = np.stack([pu, pv, np.ones_like(pu)], axis=1) @ np.linalg.inv(cam.K).T
    d_cam /= np.linalg.norm(d_cam, axis=1, keepdims=True)
    dirs = d_cam @ cam.R
    origins = np.broadcast_to(cam.center, dirs.shape).copy()
    t, amp, cos_inc = _returns(spec, caster, albedo_at, origins, dirs)
    m = len(flat_idx)
    t = np.concatenate([centre[0][flat_idx, None], t.reshape(m, -1)], axis=1)
    amp = np.concatenate([centre[1][flat_idx, None], amp.reshape(m, -1)], axis=1)
    cos_inc = np.concatenate([centre[2][flat_idx, None], cos_inc.reshape(m, -1)], axis=1)
    tz = np.where(np.isfinite(t), t, 0.0)
    total = amp.sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        if spec.wrap_range_m > 0:
            phase = np.exp(1j * 2.0 * np.pi * tz / spec.wrap_range_m)
            s = (amp * phase).sum(axis=1)
            rng_mix = np.mod(np.angle(s), 2.0 * np.pi) * spec.wrap_range_m / (2.0 * np.pi)
            amp_mix = np.abs(s) / n_sub
        else:
            rng_mix = (amp * tz).sum(axis=1) / total
            amp_mix = total / n_sub
        cos_mix = np.nansum(amp * np.nan_to_num(cos_inc), axis=1) / total
    none = total <= 0
    rng_mix[none] = np.inf
    amp_mix[none] = 0.0
    cos_mix[none] = np.nan
    return rng_mix, amp_mix, cos_mix


def simulate_tof(
    spec: TofSpec,
    rig: Rig,
    caster: MeshRaycaster,
    albedo_at: AlbedoFn,
    rng: np.random.Generator,
    mix_detect_m: float = MIX_DETECT_M,
) -> TofResult:
    """Simulate one ToF frame and project it into the RGB view (see module doc)."""
    cam = rig.tof
    if cam is None:
        raise SensorError("simulate_tof: the rig has no ToF camera (tof.enabled is false)")
    h, w = cam.height, cam.width
    origins, dirs, z_per_t = cam.pixel_rays()
    t, amp, cos_inc = _returns(spec, caster, albedo_at, origins, dirs)
    true_range = np.where(np.isfinite(t), t, -1.0)

    mixed = np.zeros(h * w, dtype=bool)
    if spec.flying_pixels:
        cand = np.flatnonzero(_discontinuities((t * z_per_t).reshape(h, w), mix_detect_m).ravel())
        if len(cand):
            r_mix, a_mix, c_mix = _mix_pixels(spec, cam, caster, albedo_at, cand, (t, amp, cos_inc))
            t, amp, cos_inc = t.copy(), amp.copy(), cos_inc.copy()
            t[cand], amp[cand], cos_inc[cand] = r_mix, a_mix, c_mix
            mixed[cand] = True

    # A return without light (A = 0: black albedo, or mixed phasors that cancel) is
    # no measurement: its sigma is infinite, so it is dropped, never kept as a noise-free range.
    hit = np.isfinite(t) & (amp > 0)
    meas = np.where(hit, t, np.nan)
    noise = rng.standard_normal(h * w)  # drawn for every pixel: the stream never depends on the scene
    if spec.sigma0_m > 0 or spec.k_noise > 0:
        sig = np.where(hit, range_sigma(spec, np.where(hit, t, 1.0), np.where(hit, amp, 1.0)), np.inf)
        hit &= np.isfinite(sig)
        meas = np.where(hit, meas + noise * np.where(hit, sig, 0.0), np.nan)
    meas = meas + spec.bias_m
    if spec.wrap_range_m > 0:
        meas = np.mod(meas, spec.wrap_range_m)

    valid = hit & np.isfinite(meas) & (meas > 0)
    if spec.min_amplitude > 0:
        valid &= amp >= spec.min_amplitude
    incidence = np.arccos(np.clip(cos_inc, 0.0, 1.0))
    if spec.grazing_rad < np.pi / 2:
        valid &= np.nan_to_num(incidence, nan=np.pi) <= spec.grazing_rad

    range_img = np.where(valid, meas, -1.0)
    depth_img = np.where(valid, meas * z_per_t, -1.0)
    idx = np.flatnonzero(valid)
    points = origins[idx] + dirs[idx] * meas[idx, None]
    p_amp = amp[idx]
    proj = project_points(rig.rgb, points, {"amplitude": p_amp})
    shape = (h, w)
    return TofResult(
        camera=cam,
        range_m=range_img.astype(np.float32).reshape(shape),
        depth_m=depth_img.astype(np.float32).reshape(shape),
        amplitude=amp.astype(np.float32).reshape(shape),
        true_range_m=true_range.astype(np.float32).reshape(shape),
        incidence_rad=incidence.astype(np.float32).reshape(shape),
        mixed=mixed.reshape(shape),
        valid=valid.reshape(shape),
        points_world=points,
        points_amplitude=p_amp,
        depth_rgb=proj.depth,
        amplitude_rgb=proj.values["amplitude"],
    )
