"""ToF simulation: geometry agreement with GT, fill ratio, noise statistics, dropout rules,
mixed pixels, phase wrap, extrinsics (occlusion shadows) and determinism."""
import numpy as np
import pytest
from sensor_scenes import box_mesh, down_camera, make_test_rig, merge, plane_mesh, plane_rays, tilted_camera, tof_spec

from crackgen.sim.groundtruth import view_ground_truth
from crackgen.sim.sensors import sensor_rng
from crackgen.sim.sensors.tof import SensorError, albedo_from_map, constant_albedo, range_sigma, simulate_tof

NO_CRACK = np.zeros((4, 4), dtype=bool)


@pytest.fixture(scope="module")
def box_scene():
    return merge(plane_mesh(4.0), box_mesh([0.0, 0.0, 0.15], [0.3, 0.3, 0.3]))


@pytest.fixture(scope="module")
def plane_scene():
    return merge(plane_mesh(40.0))


def smooth_region(depth: np.ndarray, tol_m: float = 1e-3) -> np.ndarray:
    """Pixels whose 3x3 GT neighbourhood is hit and spans < tol: away from occlusion edges and walls."""
    from scipy.ndimage import maximum_filter, minimum_filter

    d = np.where(depth > 0, depth, np.nan)
    big = np.where(np.isnan(d), np.inf, d)
    small = np.where(np.isnan(d), -np.inf, d)
    return np.isfinite(d) & (maximum_filter(small, 3) - minimum_filter(big, 3) < tol_m)


def test_noise_off_matches_ground_truth_depth(box_scene):
    rgb = down_camera(1.2, 128, 96, 60)
    spec = tof_spec(width_px=160, height_px=120, offset_m=[0.05, 0.01, 0.0], rotation_rad=[0.01, -0.02, 0.005])
    res = simulate_tof(spec, make_test_rig(rgb, spec), box_scene, constant_albedo(0.5), np.random.default_rng(0))
    gt = view_ground_truth(rgb, box_scene, NO_CRACK).depth
    filled = res.depth_rgb > 0
    check = filled & smooth_region(gt)
    assert check.sum() > 0.3 * filled.sum()
    err = np.abs(res.depth_rgb[check] - gt[check])
    assert err.max() <= 1e-3, err.max()
    # Every ToF point lies on the mesh: z = 0 (ground) or 0.3 (box top) or on a wall |x|,|y| = 0.15.
    p = res.points_world
    on = (np.abs(p[:, 2]) < 1e-5) | (np.abs(p[:, 2] - 0.3) < 1e-5) | (np.abs(np.abs(p[:, :2]) - 0.15) < 1e-5).any(1)
    assert on.all()


def test_fill_ratio_matches_resolution_ratio(plane_scene):
    # Fronto-parallel plane, both cameras looking straight down: a ToF pixel maps to an RGB step of
    # s = f_rgb / f_tof (> 1 px per axis), so no two points share an RGB pixel and, in any window of
    # N_x x N_y RGB pixels inside the ToF footprint, the count is (N_x/s_x +- 1)(N_y/s_y +- 1):
    # relative tolerance s_x/N_x + s_y/N_y (+ 1e-3 slack).
    rgb = down_camera(1.5, 256, 192, 60)
    spec = tof_spec(width_px=160, height_px=120)
    res = simulate_tof(spec, make_test_rig(rgb, spec), plane_scene, constant_albedo(0.5), np.random.default_rng(0))
    Kt, Kr = res.camera.K, rgb.K
    sx, sy = Kr[0, 0] / Kt[0, 0], Kr[1, 1] / Kt[1, 1]
    assert sx > 1 and sy > 1
    landed = (res.depth_rgb > 0).sum()
    uv, z = rgb.project(res.points_world)
    inside = ((np.floor(uv + 0.5) >= 0) & (np.floor(uv + 0.5) < [256, 192])).all(1)
    assert landed == inside.sum()  # no collisions at this resolution ratio
    win = (slice(40, 152), slice(48, 208))  # 112 x 160 px, inside the ToF footprint
    rr, cc = np.nonzero(res.depth_rgb > 0)
    assert rr.min() < 40 and rr.max() >= 152 and cc.min() < 48 and cc.max() >= 208
    fill = (res.depth_rgb[win] > 0).mean()
    expected = 1.0 / (sx * sy)
    tol = sx / 160 + sy / 112 + 1e-3
    assert abs(fill / expected - 1) < tol, (fill, expected, tol)


@pytest.mark.parametrize("sigma0,k,albedo", [(0.002, 0.0, 0.5), (0.0, 2.4e-6, 0.05), (0.001, 2.4e-6, 0.1)])
def test_range_noise_matches_sigma_model(plane_scene, sigma0, k, albedo):
    rgb = tilted_camera(3.0, 50, 64, 48, 60)
    spec = tof_spec(width_px=200, height_px=150, sigma0_m=sigma0, k_noise=k, bias_m=0.0)
    res = simulate_tof(spec, make_test_rig(rgb, spec), plane_scene, constant_albedo(albedo), sensor_rng(3))
    d, cos_inc = plane_rays(res.camera)  # independent geometry
    A = spec.amplitude_scale * albedo * cos_inc / d**2
    np.testing.assert_allclose(res.amplitude, A, rtol=1e-4)
    sig = sigma0 + k * d**2 / A
    ok = res.valid
    resid = (res.range_m - d)[ok]
    z = resid / sig[ok]
    assert abs(z.std() - 1) < 0.1 and abs(z.mean()) < 0.05
    # The d^4 dependence: near and far thirds of the image each match their own sigma.
    for part in np.array_split(np.argsort(d[ok]), 3):
        rms_sigma = np.sqrt(np.mean(sig[ok][part] ** 2))
        assert abs(resid[part].std() / rms_sigma - 1) < 0.1
    np.testing.assert_allclose(range_sigma(spec, np.array([5.0]), np.array([0.02])), sigma0 + k * 25 / 0.02)


def test_default_noise_is_four_mm_at_five_m():
    from crackgen.config.recipe import Recipe
    from crackgen.config.spec import make_spec

    spec = make_spec(Recipe(), 0).tof
    A = spec.amplitude_scale * 0.5 * 1.0 / 25.0
    assert range_sigma(spec, np.array([5.0]), np.array([A]))[0] == pytest.approx(0.004, rel=0.05)


def test_bias_and_phase_wrap(plane_scene):
    rgb = down_camera(1.7, 64, 48, 60)
    spec = tof_spec(bias_m=0.01, wrap_range_m=1.0)
    res = simulate_tof(spec, make_test_rig(rgb, spec), plane_scene, constant_albedo(0.5), sensor_rng(1))
    d, _ = plane_rays(res.camera)
    np.testing.assert_allclose(res.range_m, np.mod(d + 0.01, 1.0), atol=2e-6)
    assert res.valid.all()


def test_amplitude_dropout_drops_exactly_the_weak_pixels(plane_scene):
    rgb = tilted_camera(2.5, 60, 64, 48, 60)
    base = tof_spec(width_px=120, height_px=90)
    cam = make_test_rig(rgb, base).tof
    d, cos_inc = plane_rays(cam)
    A = 0.5 * cos_inc / d**2
    thr = float(np.median(A[np.isfinite(d)]))
    spec = tof_spec(width_px=120, height_px=90, min_amplitude=thr)
    res = simulate_tof(spec, make_test_rig(rgb, spec), plane_scene, constant_albedo(0.5), sensor_rng(2))
    clear = np.abs(A - thr) > 1e-5 * thr
    np.testing.assert_array_equal(res.valid[clear], (A >= thr)[clear])
    assert 0.4 < res.valid.mean() < 0.6


def test_grazing_dropout_drops_exactly_the_oblique_pixels(plane_scene):
    rgb = tilted_camera(2.0, 45, 64, 48, 60)
    spec = tof_spec(width_px=120, height_px=90, grazing_rad=np.radians(45.0))
    res = simulate_tof(spec, make_test_rig(rgb, spec), plane_scene, constant_albedo(0.5), sensor_rng(2))
    _, cos_inc = plane_rays(res.camera)
    theta = np.degrees(np.arccos(cos_inc))
    clear = np.abs(theta - 45.0) > 1e-3
    np.testing.assert_array_equal(res.valid[clear], (theta <= 45.0)[clear])
    assert 0.2 < res.valid.mean() < 0.8


def test_albedo_map_lookup_follows_uv_convention():
    alb = np.zeros((8, 16, 3))
    alb[:, 8:] = 1.0  # u >= 0.5 bright
    alb[6:, :, 0] = 0.5  # rows j >= 6 (v >= 0.75) tinted
    f = albedo_from_map(alb)
    g = f(np.array([[0.1, 0.1], [0.9, 0.1], [0.1, 0.95]]))
    np.testing.assert_allclose(g, [0.0, 1.0, 0.5 * 0.2126], atol=1e-6)


def test_mixed_pixels_fall_between_surfaces(box_scene):
    rgb = down_camera(1.2, 64, 48, 60)
    spec = tof_spec(width_px=160, height_px=120, flying_pixels=True)
    rig = make_test_rig(rgb, spec)
    on = simulate_tof(spec, rig, box_scene, constant_albedo(0.5), sensor_rng(0))
    off = simulate_tof(tof_spec(width_px=160, height_px=120), rig, box_scene, constant_albedo(0.5), sensor_rng(0))
    z_on = on.points_world[:, 2]
    z_off = off.points_world[:, 2]
    between = lambda z: (z > 0.01) & (z < 0.29)  # noqa: E731 - neither ground nor box top
    # Without mixing, points off ground/top are on walls only (|x| or |y| = 0.15); mixing creates points in mid-air.
    wall = (np.abs(np.abs(off.points_world[:, :2]) - 0.15) < 1e-5).any(1)
    assert not (between(z_off) & ~wall).any()
    flying = between(z_on) & ~(np.abs(np.abs(on.points_world[:, :2]) - 0.15) < 1e-5).any(1)
    assert flying.sum() > 50
    # Mixed ranges lie within the span of the true ranges of the pixel's 3x3 neighbourhood.
    from scipy.ndimage import maximum_filter, minimum_filter

    tr = on.true_range_m
    hi, lo = maximum_filter(tr, 3), minimum_filter(np.where(tr > 0, tr, np.inf), 3)
    m = on.mixed & on.valid
    assert m.any() and np.all((on.range_m[m] >= lo[m] - 1e-4) & (on.range_m[m] <= hi[m] + 1e-4))
    # Away from edges nothing changes.
    np.testing.assert_array_equal(on.range_m[~on.mixed], off.range_m[~on.mixed])


@pytest.mark.parametrize("side", [+1, -1])
def test_tof_offset_moves_occlusion_shadow(box_scene, side):
    # ToF to the right of the RGB camera sees the box from the right, so the ground just left
    # of the box (visible to the RGB camera) is hidden from it, and vice versa.
    rgb = down_camera(1.2, 128, 96, 60)
    spec = tof_spec(width_px=320, height_px=240, offset_m=[0.15 * side, 0.0, 0.0])
    res = simulate_tof(spec, make_test_rig(rgb, spec), box_scene, constant_albedo(0.5), sensor_rng(0))
    gt = view_ground_truth(rgb, box_scene, NO_CRACK).depth
    holes = (gt > 0) & (res.depth_rgb < 0)
    rows, cols = np.nonzero(holes)
    assert len(cols) > 60
    centre_col = rgb.project(np.array([[0.0, 0.0, 0.3]]))[0][0, 0]
    if side > 0:
        assert np.all(cols < centre_col)
    else:
        assert np.all(cols > centre_col)


def test_deterministic_given_seed_and_needs_tof(box_scene):
    rgb = down_camera(1.2, 64, 48, 60)
    spec = tof_spec(sigma0_m=0.002, k_noise=2e-6, flying_pixels=True)
    rig = make_test_rig(rgb, spec)
    a = simulate_tof(spec, rig, box_scene, constant_albedo(0.5), sensor_rng(spec.seed))
    b = simulate_tof(spec, rig, box_scene, constant_albedo(0.5), sensor_rng(spec.seed))
    np.testing.assert_array_equal(a.range_m, b.range_m)
    np.testing.assert_array_equal(a.depth_rgb, b.depth_rgb)
    with pytest.raises(SensorError, match="no ToF camera"):
        simulate_tof(spec, make_test_rig(rgb, None), box_scene, constant_albedo(0.5), sensor_rng(0))


@pytest.mark.parametrize("sigma0,k", [(0.0, 2.4e-6), (0.001, 2.4e-6), (0.002, 0.0), (0.0, 0.0)])
def test_zero_amplitude_returns_are_dropped_not_perfect(plane_scene, sigma0, k):
    # Left half of the plane (x < 0, u < 0.5) is black: its returns carry no light, so sigma = k d^2 / 0
    # is infinite. With min_amplitude = 0 (dropout off) they must still be no measurement (-1), while
    # the grey half keeps its noise at sigma0 + k d^2 / A.
    albedo = 0.2
    rgb = down_camera(1.5, 64, 48, 60)
    spec = tof_spec(width_px=200, height_px=150, sigma0_m=sigma0, k_noise=k, min_amplitude=0.0)
    half_black = lambda uv: np.where(uv[:, 0] < 0.5, 0.0, albedo)  # noqa: E731
    res = simulate_tof(spec, make_test_rig(rgb, spec), plane_scene, half_black, sensor_rng(4))
    cam = res.camera
    d, cos_inc = plane_rays(cam)  # independent geometry
    _, dirs, _ = cam.pixel_rays()
    x = (cam.center[0] + dirs[:, 0] * d.ravel()).reshape(d.shape)
    black, grey = x < -1e-3, x > 1e-3
    assert black.sum() > 1000 and grey.sum() > 1000
    assert not res.valid[black].any()
    assert (res.range_m[black] == -1).all() and (res.depth_m[black] == -1).all()
    assert (res.points_world[:, 0] > -1e-3).all()  # nothing from the black half reaches the RGB view
    assert res.valid[grey].all()
    sig = sigma0 + k * d**2 / (spec.amplitude_scale * albedo * cos_inc / d**2)
    resid = (res.range_m - d)[grey]
    if sigma0 == 0 and k == 0:
        assert np.abs(resid).max() < 1e-5
    else:
        z = resid / sig[grey]
        assert abs(z.std() - 1) < 0.1 and abs(z.mean()) < 0.05
