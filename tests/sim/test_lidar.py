"""LiDAR: scan lines on the specified elevations, range limits, dropout rate, projection."""
import numpy as np
import pytest
from sensor_scenes import down_camera, lidar_spec, make_test_rig, merge, plane_mesh

from crackgen.sim.groundtruth import view_ground_truth
from crackgen.sim.sensors import sensor_rng
from crackgen.sim.sensors.lidar import beam_angles, simulate_lidar
from crackgen.sim.sensors.tof import SensorError


@pytest.fixture(scope="module")
def plane():
    return merge(plane_mesh(20.0))


def lidar_frame(points_world: np.ndarray, T_lidar_world: np.ndarray) -> np.ndarray:
    return points_world @ T_lidar_world[:3, :3].T + T_lidar_world[:3, 3]


def test_scan_lines_fall_on_expected_elevations(plane):
    spec = lidar_spec(sigma_m=0.02, rotation_rad=[0.03, -0.02, 0.01])
    rig = make_test_rig(down_camera(1.5, 128, 96, 60), lidar=spec)
    res = simulate_lidar(spec, rig, plane, sensor_rng(spec.seed))
    p = lidar_frame(res.points_world, rig.T_lidar_world)
    r = np.linalg.norm(p, axis=1)
    elev = np.arcsin(-p[:, 1] / r)  # elevation: above the x-z plane, towards -y
    az = np.arctan2(p[:, 0], p[:, 2])
    expected = np.radians(np.linspace(-15, 15, 16))
    np.testing.assert_allclose(elev, expected[res.ring], atol=1e-5)  # noise is along the beam
    np.testing.assert_allclose(az, res.azimuth_rad, atol=1e-5)
    assert set(np.unique(res.ring)) == set(range(16))
    # Azimuths: -45..45 deg in 0.2 deg steps, centred.
    e, a = beam_angles(spec)
    assert len(a) == 451 and a[0] == pytest.approx(-a[-1]) and np.diff(a) == pytest.approx(np.radians(0.2))
    # Range noise std matches sigma_m.
    _, true_t = ray_plane(rig, res)
    assert abs((r - true_t).std() / 0.02 - 1) < 0.1


def ray_plane(rig, res):
    from fusion.geometry.camera import invert_pose

    o = invert_pose(rig.T_lidar_world)[:3, 3]
    d = res.points_world - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return d, -o[2] / d[:, 2]


def test_dropout_rate_and_max_range(plane):
    spec = lidar_spec(dropout=0.3)
    rig = make_test_rig(down_camera(1.5, 64, 48, 60), lidar=spec)
    res = simulate_lidar(spec, rig, plane, sensor_rng(5))
    kept = len(res.ring) / res.n_hits
    n = res.n_hits
    assert n == res.n_rays  # every beam hits the big plane
    assert abs(kept - 0.7) < 4 * np.sqrt(0.3 * 0.7 / n)
    # Max range: the LiDAR looks straight down from height h, so a beam's range to the plane is
    # h / cos(angle to the optical axis) = h / (cos e cos a).
    h = invert_center_height(rig)
    spec2 = lidar_spec(max_range_m=h * 1.05)
    res2 = simulate_lidar(spec2, rig, plane, sensor_rng(5))
    e, a = beam_angles(spec2)
    E, A = np.meshgrid(e, a, indexing="ij")
    true_range = h / (np.cos(E) * np.cos(A))
    assert len(res2.ring) == (true_range <= h * 1.05).sum()
    assert res2.range_m.max() <= h * 1.05


def invert_center_height(rig) -> float:
    from fusion.geometry.camera import invert_pose

    return float(invert_pose(rig.T_lidar_world)[2, 3])


def test_projected_lidar_depth_matches_ground_truth(plane):
    spec = lidar_spec()
    rgb = down_camera(1.5, 128, 96, 60)
    rig = make_test_rig(rgb, lidar=spec)
    res = simulate_lidar(spec, rig, plane, sensor_rng(0))
    gt = view_ground_truth(rgb, plane, np.zeros((2, 2), bool)).depth
    f = res.depth_rgb > 0
    assert f.sum() > 500
    np.testing.assert_allclose(res.depth_rgb[f], gt[f], atol=1e-5)  # fronto-parallel plane: depth constant
    assert set(np.unique(res.ring_rgb[f]).astype(int)) <= set(range(16))


def test_lidar_disabled_raises(plane):
    with pytest.raises(SensorError, match="no LiDAR"):
        simulate_lidar(lidar_spec(), make_test_rig(down_camera(1.5, 64, 48, 60)), plane, sensor_rng(0))
