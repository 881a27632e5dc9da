"""Real-data loaders and the fusion geometry on real sensor data (../shared/data/real).

SGBM errors vs GT are printed (run with -s) and bounded loosely; the measured values
go into the issue notes.
"""
from pathlib import Path

import numpy as np
import pytest

from fusion.geometry.camera import Camera, mounted_pose
from fusion.geometry.projection import reproject_depth
from fusion.geometry.real_data import (
    RealDataError,
    load_eth3d_scene,
    load_middlebury_scene,
    load_rig_frame,
    read_calib,
    read_eth3d_disparity,
    read_pfm,
)
from fusion.geometry.stereo import disparity_errors, occluded_from_disparity, reproject_as_disparity, sgbm_disparity

REAL = Path(__file__).resolve().parents[3].parent / "shared" / "data" / "real"
pytestmark = pytest.mark.skipif(not REAL.is_dir(), reason="../shared/data/real is absent")


def test_middlebury_loader_and_sgbm_error():
    s = load_middlebury_scene(REAL / "stereo" / "middlebury2003_cones")
    assert s["left"].shape == s["disp_left"].shape == (375, 450) and s["left_rgb"].dtype == np.uint8
    d = s["disp_left"]
    assert d.min() == -1 and 0 < d[d > 0].min() and d.max() < 64
    # Our occlusion test from GT disparity agrees with the dataset's own non-occlusion mask.
    occ = occluded_from_disparity(d)
    assert ((~occ) == s["nonocc"])[d > 0].mean() > 0.98
    est = sgbm_disparity(s["left"], s["right"], num_disparities=64, block_size=5)
    m = disparity_errors(est, d, s["nonocc"])
    print(f"\nMiddlebury cones SGBM (nonocc): {m}")
    assert m["mae"] < 1.0 and m["bad3"] < 0.05 and m["density"] > 0.8


def test_eth3d_loader_calib_and_sgbm_error():
    s = load_eth3d_scene(REAL / "stereo" / "eth3d_playground")
    c = s["calib"]
    assert (c.width, c.height) == (941, 490) and c.baseline_m == pytest.approx(0.0595549) and c.doffs_px == 0.0
    d = s["disp_left"]
    assert d.shape == (490, 941) and 0.3 < (d > 0).mean() < 0.7  # "about half the pixels are valid"
    z = s["depth_left"]
    v = d > 0
    np.testing.assert_allclose(z[v], c.focal_px * c.baseline_m / d[v], rtol=1e-5)
    occ = occluded_from_disparity(d)
    est = sgbm_disparity(s["left"], s["right"], num_disparities=64, block_size=5)
    m = disparity_errors(est, d, ~occ)
    print(f"\nETH3D playground SGBM (valid, nonocc): {m}")
    assert m["mae"] < 1.0 and m["bad3"] < 0.05 and m["density"] > 0.7


def test_pfm_rows_are_flipped_to_top_down(tmp_path):
    a = np.arange(12, dtype="<f4").reshape(3, 4)
    p = tmp_path / "x.pfm"
    p.write_bytes(b"Pf\n4 3\n-1.0\n" + a[::-1].tobytes())
    np.testing.assert_array_equal(read_pfm(p), a)
    b = a.astype(">f4")
    p.write_bytes(b"Pf\n4 3\n1.0\n" + b[::-1].tobytes())
    np.testing.assert_array_equal(read_pfm(p), a)


def test_bad_files_name_the_file(tmp_path):
    with pytest.raises(RealDataError, match="nothere.pfm: file not found"):
        read_eth3d_disparity(tmp_path / "nothere.pfm")
    bad = tmp_path / "bad.pfm"
    bad.write_bytes(b"P6\n1 1\n255\n\x00\x00\x00")
    with pytest.raises(RealDataError, match="bad.pfm: not a PFM"):
        read_pfm(bad)
    cal = tmp_path / "calib.txt"
    cal.write_text("cam0=[1 0 0; 0 1 0]\n")
    with pytest.raises(RealDataError, match="calib.txt: missing keys"):
        read_calib(cal)
    with pytest.raises(RealDataError, match="rgb.png: file not found"):
        load_rig_frame(tmp_path)


def test_rig_frame_loads_and_reprojects():
    f = load_rig_frame(REAL / "rgbd_tof_stereo_lidar_sample")
    assert f["rgb"].shape == (480, 640, 3) and f["rgb"].dtype == np.uint8
    for k in ("tof", "stereo", "lidar"):
        assert f[k].shape == (424, 512) and f[k].dtype == np.float32 and f[k].min() == -1
    assert 0.01 < (f["lidar"] > 0).mean() < 0.04  # "about 2% filled"
    # Registered sensors agree in metres on common pixels.
    for k in ("stereo", "lidar"):
        m = (f["tof"] > 0) & (f[k] > 0)
        assert np.median(np.abs(f["tof"][m] - f[k][m]) / f[k][m]) < 0.05
    cam: Camera = f["camera"]
    # Back-project the ToF and splat it into the same camera: the same depth comes back.
    same = reproject_depth(cam, f["tof"], cam)
    v = f["tof"] > 0
    assert (same[v] > 0).mean() > 0.99
    np.testing.assert_allclose(same[v & (same > 0)], f["tof"][v & (same > 0)], rtol=1e-5)
    # Into a virtual left camera 6 cm to the left: ToF as disparity d = f*B/Z (z-buffered).
    left = Camera(cam.K, mounted_pose(cam.T_cam_world, [-0.06, 0.0, 0.0], [0, 0, 0]), cam.width, cam.height)
    pts = cam.backproject(f["tof"]).reshape(-1, 3)
    pts = pts[np.isfinite(pts).all(1)]
    disp, _ = reproject_as_disparity(pts, left, 0.06)
    dep = reproject_depth(cam, f["tof"], left)
    ok = disp > 0
    assert ok.mean() > 0.5
    np.testing.assert_allclose(disp[ok], cam.fx * 0.06 / dep[ok], rtol=1e-5)
