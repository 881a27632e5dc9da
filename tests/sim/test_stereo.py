"""Stereo: SGBM accuracy on a render-free textured plane, GT/ToF disparity in the left view,
left-right difference, and the SYNTH3-style set."""
import cv2
import numpy as np
import pytest
from sensor_scenes import make_test_rig, merge, plane_mesh, tilted_camera, tof_spec

from crackgen.config.spec import StereoSpec
from crackgen.sim.groundtruth import view_ground_truth
from crackgen.sim.sensors import sensor_rng
from crackgen.sim.sensors.stereo import SYNTH3_CHANNELS, simulate_stereo
from crackgen.sim.sensors.tof import SensorError, constant_albedo, simulate_tof
from fusion.geometry.disparity import depth_to_disparity
from fusion.geometry.stereo import StereoInputError, left_right_difference, sgbm_disparity

PLANE_M = 4.0


@pytest.fixture(scope="module")
def texture():
    rng = np.random.default_rng(42)
    t = cv2.GaussianBlur(rng.random((1024, 1024)).astype(np.float32), (0, 0), 1.5)
    t = (t - t.min()) / (t.max() - t.min())
    return (t * 255).astype(np.float32)


def render(cam, caster, texture) -> np.ndarray:
    """Render-free image: texture looked up at the UV of each pixel-centre ray hit (uint8 RGB)."""
    uv = view_ground_truth(cam, caster, np.zeros((2, 2), bool)).uv
    n = texture.shape[0]
    mx = np.nan_to_num(uv[..., 0] * n - 0.5, nan=-10).astype(np.float32)
    my = np.nan_to_num(uv[..., 1] * n - 0.5, nan=-10).astype(np.float32)
    g = cv2.remap(texture, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    g = np.clip(np.rint(g), 0, 255).astype(np.uint8)
    return np.repeat(g[..., None], 3, axis=2)


@pytest.fixture(scope="module")
def scene(texture):
    caster = merge(plane_mesh(PLANE_M, n=2))
    rgb = tilted_camera(1.0, 25, 192, 144, 60)
    spec = tof_spec(width_px=160, height_px=120, offset_m=[0.05, 0.0, 0.0])
    rig = make_test_rig(rgb, spec, baseline_m=0.08)
    left, right = render(rig.rgb, caster, texture), render(rig.right, caster, texture)
    gt = view_ground_truth(rig.rgb, caster, np.zeros((2, 2), bool)).depth
    return caster, rig, spec, left, right, gt


def test_sgbm_on_textured_plane_median_error_below_one_px(scene):
    _, rig, _, left, right, gt = scene
    disp = sgbm_disparity(left, right, num_disparities=32, block_size=5)
    gt_disp = depth_to_disparity(gt, rig.rgb.fx, 0.08)
    assert 8 < np.median(gt_disp[gt_disp > 0]) < 24  # the search range covers the scene
    ok = (disp > 0) & (gt_disp > 0)
    assert ok.mean() > 0.6
    err = np.abs(disp[ok] - gt_disp[ok])
    assert np.median(err) < 1.0, np.median(err)
    assert np.all(disp[~(disp > 0)] == -1)


def test_simulate_stereo_maps_agree(scene):
    caster, rig, tspec, left, right, gt = scene
    tof = simulate_tof(tspec, rig, caster, constant_albedo(0.5), sensor_rng(0))
    st = simulate_stereo(StereoSpec(enabled=True, baseline_m=0.08, num_disparities=32, block_size=5), rig, left, right, gt, tof)
    assert st.baseline_m == pytest.approx(0.08)
    # GT disparity is f*B/Z of the GT depth.
    m = gt > 0
    np.testing.assert_allclose(st.disp_gt[m], rig.rgb.fx * 0.08 / gt[m], rtol=1e-5)
    # Noise-free ToF disparity in the left view agrees with GT where filled (tilted plane:
    # rounding to the nearest pixel moves a point by <= 0.71 px, i.e. |grad d| * 0.71).
    f = st.disp_tof > 0
    assert f.mean() > 0.2
    gy, gx = np.gradient(st.disp_gt)
    bound = 0.71 * np.hypot(gx, gy) + 1e-3
    assert np.all(np.abs(st.disp_tof[f] - st.disp_gt[f]) <= bound[f])
    assert np.all(st.tof_amplitude[f] > 0) and np.all(st.tof_amplitude[~f] == -1)
    # Warping by a good disparity explains the right image: the difference shrinks a lot.
    v = st.disp_sgm > 0
    raw = np.abs(left[..., 0].astype(float) - right[..., 0].astype(float))[v].mean()
    assert np.abs(st.lr_diff[v]).mean() < 0.3 * raw
    assert np.all(st.lr_diff[~v] == 0)
    x = st.synth3()
    assert x.shape == (*gt.shape, len(SYNTH3_CHANNELS)) and x.dtype == np.float32
    np.testing.assert_array_equal(x[..., 1], st.disp_tof)


def test_left_right_difference_with_exact_disparity_is_small():
    rng = np.random.default_rng(1)
    right = cv2.GaussianBlur(rng.random((40, 80)).astype(np.float32), (0, 0), 2.0) * 255
    d = 6.0
    left = np.zeros_like(right)
    left[:, 6:] = right[:, :-6]  # left(u) = right(u - d)
    disp = np.full(right.shape, d, np.float32)
    diff = left_right_difference(left, right, disp)
    assert np.abs(diff[:, 6:]).max() < 0.51  # uint8 rounding only
    assert np.all(diff[:, :6] == 0)  # warped outside the right image: no evidence


def test_bad_stereo_inputs_raise(scene):
    _, rig, _, left, right, gt = scene
    with pytest.raises(StereoInputError, match="multiple of 16"):
        sgbm_disparity(left, right, num_disparities=30)
    with pytest.raises(StereoInputError, match="differ in size"):
        sgbm_disparity(left, right[:-1])
    w = left.shape[1]
    nd = ((w - 1) // 16) * 16  # OpenCV itself asserts (or asks for 2**64 bytes) once the search reaches the width
    with pytest.raises(StereoInputError, match=f"less than the image width {w} px"):
        sgbm_disparity(left, right, num_disparities=nd, min_disparity=w - nd)
    sgbm_disparity(left, right, num_disparities=nd, min_disparity=w - nd - 1)  # the widest search OpenCV takes
    st = simulate_stereo(StereoSpec(True, 0.08, 32, 5), rig, left, right, gt, None)
    with pytest.raises(SensorError, match="needs the ToF"):
        st.synth3()
    with pytest.raises(SensorError, match="lidar_depth_rgb"):
        simulate_stereo(StereoSpec(True, 0.08, 32, 5), rig, left, right, gt, None, gt[:-1])


def test_lidar_disparity_is_f_b_over_z_of_the_lidar_depth(scene):
    _, rig, _, left, right, gt = scene
    lidar = np.full_like(gt, -1.0)
    lidar[::7] = gt[::7]  # scan lines
    st = simulate_stereo(StereoSpec(True, 0.08, 32, 5), rig, left, right, gt, None, lidar)
    ok = lidar > 0
    np.testing.assert_allclose(st.disp_lidar[ok], rig.rgb.fx * 0.08 / lidar[ok], rtol=1e-5)
    assert np.all(st.disp_lidar[~ok] == -1)
