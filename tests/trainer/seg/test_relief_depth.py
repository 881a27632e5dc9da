"""Local-relief depth input: plane/low-pass removal on hand-made surfaces, sparse depth, validity default."""
import argparse

import numpy as np
import pytest

from trainer.core.options import options_from
from trainer.seg.builders import DataOptions, add_data_args
from trainer.seg.config import DataArgs
from trainer.seg.depth import normalise_depth, relief_mm

H, W, F = 96, 128, 150.0  # image size and focal length (px) of the hand-made camera
GROOVE_M = 0.010


def _rays() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    return u, (u - W / 2) / F, (v - H / 2) / F


def tilted_plane() -> np.ndarray:
    """Planar z of a world plane tilted ~29 deg about y and ~9 deg about x, 0.8 m from the camera."""
    _, x, y = _rays()
    n = np.array([np.sin(0.5), 0.15, np.cos(0.5)])
    n /= np.linalg.norm(n)
    return (0.8 / (n[0] * x + n[1] * y + n[2])).astype(np.float32)


def cylinder(radius_m: float = 1.5, dist_m: float = 0.8) -> np.ndarray:
    """Planar z of a vertical cylinder (a column or tunnel lining) seen from outside: curved across x."""
    _, x, _ = _rays()
    cz = dist_m + radius_m
    a, b, c = x**2 + 1, -2 * cz, cz**2 - radius_m**2
    return ((-b - np.sqrt(b * b - 4 * a * c)) / (2 * a)).astype(np.float32)


def with_groove(z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(depth with a 5-px wide, 10 mm deep vertical groove, groove mask, far-from-groove mask)."""
    u, _, _ = _rays()
    groove = np.abs(u - 70) <= 2
    far = np.abs(u - 70) > 8
    out = z.copy()
    out[groove] += GROOVE_M
    return out, groove, far


@pytest.mark.parametrize("method", ["plane", "lowpass"])
def test_tilted_plane_is_removed_and_groove_reads_minus_10mm(method):
    z, groove, far = with_groove(tilted_plane())
    mm, ok = relief_mm(z, method)
    assert ok.all()
    assert np.abs(mm[far]).max() < 0.01  # plane gone (away from the groove: < 10 um)
    assert np.allclose(mm[groove], -10.0, atol=0.05)  # crack is negative, in millimetres
    d, v = normalise_depth(z, mode="relief", relief=method, relief_range_mm=20.0)
    assert np.allclose(d[groove], -0.5, atol=0.005) and np.abs(d[far]).max() < 1e-3 and v.min() == 1.0
    # the same groove under the fixed 0.2-5 m normalisation: 0.2% of the input range
    fixed, _ = normalise_depth(z)
    assert abs(float(fixed[groove].mean() - fixed[~groove & ~far].mean())) < 0.003


def test_relief_is_clipped_to_the_range():
    z, groove, _ = with_groove(tilted_plane())
    d, _ = normalise_depth(z, mode="relief", relief="plane", relief_range_mm=5.0)
    assert np.allclose(d[groove], -1.0)  # 10 mm > 5 mm range -> clipped


def test_lowpass_follows_a_curved_surface_plane_does_not():
    """Why lowpass is the default: a 1.5 m radius column sags ~30 mm across the view."""
    z, groove, far = with_groove(cylinder())
    assert (z[far].max() - z[far].min()) > 0.02
    low, _ = relief_mm(z, "lowpass")
    plane, _ = relief_mm(z, "plane")
    assert np.abs(low[far]).max() < 1.0  # sub-mm away from the groove
    assert np.abs(plane[far]).max() > 10.0  # the sag stays in the plane-removed relief
    assert -10.5 < low[groove].mean() < -9.0


@pytest.mark.parametrize("method", ["plane", "lowpass"])
def test_sparse_depth_with_holes_is_finite_and_validity_is_exact(method):
    z, groove, far = with_groove(tilted_plane())
    rng = np.random.default_rng(3)
    keep = rng.random(z.shape) < 0.06  # ToF-like: 6% of pixels measured
    keep[:, :20] = False  # and a whole missing band
    sparse = np.where(keep, z, -1.0).astype(np.float32)
    sparse[0, :5] = [0.0, np.nan, np.inf, -np.inf, -1.0]  # every "no value" convention
    keep[0, :5] = False
    d, v = normalise_depth(sparse, mode="relief", relief=method)
    assert np.isfinite(d).all() and np.isfinite(v).all()
    assert np.array_equal(v.astype(bool), keep)
    assert np.all(d[~keep] == 0.0)
    assert np.abs(d[keep & far]).max() < 1e-3
    assert np.allclose(d[keep & groove], -0.5, atol=0.01)


def test_no_valid_depth_gives_zeros():
    d, v = normalise_depth(np.full((8, 8), -1.0, np.float32), mode="relief")
    assert not d.any() and not v.any()


def _parse(*argv: str) -> DataArgs:
    p = argparse.ArgumentParser()
    add_data_args(p)
    return options_from(DataArgs, p.parse_args(list(argv)))


def test_validity_channel_defaults_on_for_sparse_depth_and_can_be_turned_off():
    assert DataOptions.from_args(_parse("--depth", "tof")).channels == "rgbdv"
    assert DataOptions.from_args(_parse("--depth", "lidar")).channels == "rgbdv"
    assert DataOptions.from_args(_parse("--depth", "gt")).channels == "rgbd"
    assert DataOptions.from_args(_parse("--depth", "gt", "--valid-channel")).channels == "rgbdv"
    assert DataOptions.from_args(_parse("--depth", "tof", "--no-valid-channel")).channels == "rgbd"
    assert DataOptions.from_args(_parse()).channels == "rgb"
