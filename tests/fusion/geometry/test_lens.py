"""Brown-Conrady lens warp: OpenCV's own undistort gives the pinhole image back; labels stay on their lines."""
import cv2
import numpy as np
import pytest

from fusion.geometry.lens import Distortion, LensError, canvas_K, canvas_margins, distortion_map, undistort_pixels, warp

W, H = 160, 120
K = np.array([[140.0, 0, W / 2 - 0.5 + 1.5], [0, 140.0, H / 2 - 0.5 - 2.0], [0, 0, 1]])
LENSES = [Distortion(k1=-0.28, k2=0.06, p1=0.0008, p2=-0.0006), Distortion(k1=0.12, k2=-0.01), Distortion(k1=-0.1, k3=0.02)]


def grid_image(shape_hw):
    """A pinhole image of blurred random texture (120-200) crossed by thin dark straight lines at random
    positions and angles (no period, so a shift between two copies has one answer)."""
    h, w = shape_hw
    rng = np.random.default_rng(7)
    img = cv2.GaussianBlur(rng.uniform(0, 1, (h, w)).astype(np.float32), (0, 0), 3)
    img = 120 + 80 * (img - img.min()) / (img.max() - img.min())
    for _ in range(14):
        x0, y0 = rng.uniform(0, w), rng.uniform(0, h)
        a = rng.uniform(0, np.pi)
        p0 = (int(x0 - 400 * np.cos(a)), int(y0 - 400 * np.sin(a)))
        p1 = (int(x0 + 400 * np.cos(a)), int(y0 + 400 * np.sin(a)))
        cv2.line(img, p0, p1, 20.0, 1)
    return np.dstack([img] * 3).astype(np.uint8)


@pytest.mark.parametrize("lens", LENSES, ids=["barrel", "pincushion", "k3"])
def test_the_distortion_map_inverts_opencvs_model(lens):
    rng = np.random.default_rng(0)
    uv = rng.uniform([0, 0], [W - 1, H - 1], (200, 2))
    pin = undistort_pixels(uv, K, lens)
    xy = (np.c_[pin, np.ones(len(pin))] @ np.linalg.inv(K).T)[:, :2]
    proj, _ = cv2.projectPoints(np.c_[xy, np.ones(len(xy))], np.zeros(3), np.zeros(3), K, lens.coeffs)
    assert np.abs(proj.reshape(-1, 2) - uv).max() < 1e-4  # distorting the looked-up point lands on the pixel


@pytest.mark.parametrize("lens", LENSES, ids=["barrel", "pincushion", "k3"])
def test_cv2_undistort_with_the_exported_coefficients_gives_back_the_pinhole_image(lens):
    margins = canvas_margins(K, lens, W, H)
    if lens.k1 < 0:
        assert min(margins) > 0  # a barrel lens sees past the pinhole frame on every side
    canvas = grid_image((H + margins[1] + margins[3], W + margins[0] + margins[2]))
    maps = distortion_map(K, lens, W, H, margins)
    assert maps[0].min() >= 0 and maps[0].max() <= canvas.shape[1] - 1  # every look-up lands on the canvas
    assert maps[1].min() >= 0 and maps[1].max() <= canvas.shape[0] - 1
    distorted = warp(canvas, maps, nearest=False)
    back = cv2.undistort(distorted, K, lens.coeffs)
    pinhole = canvas[margins[1]:margins[1] + H, margins[0]:margins[0] + W]
    c = (slice(H // 4, 3 * H // 4), slice(W // 4, 3 * W // 4))  # the image centre region
    a, b = back[c][..., 0].astype(np.float32), pinhole[c][..., 0].astype(np.float32)
    shift, _ = cv2.phaseCorrelate(a, b)
    assert np.hypot(*shift) < 1.0, shift
    assert np.median(np.abs(a - b)) < 12
    # the label, warped by nearest neighbour with the same map, stays on the dark lines of the image
    label = (pinhole[..., 0] < 60).astype(np.uint8) * 255
    label_canvas = (canvas[..., 0] < 60).astype(np.uint8) * 255
    warped = warp(label_canvas, maps, nearest=True)
    assert set(np.unique(warped)) <= {0, 255}
    assert np.mean(distorted[..., 0][warped > 0]) < 70 < np.mean(distorted[..., 0][warped == 0])
    assert label.sum() > 0


def test_sparse_maps_keep_their_holes_and_values():
    lens = LENSES[0]
    margins = canvas_margins(K, lens, W, H)
    rng = np.random.default_rng(1)
    sparse = np.full((H + margins[1] + margins[3], W + margins[0] + margins[2]), -1.0, np.float32)
    idx = rng.integers(0, sparse.size, 400)
    sparse.flat[idx] = rng.uniform(0.5, 3.0, 400).astype(np.float32)
    out = warp(sparse, distortion_map(K, lens, W, H, margins), nearest=True)
    assert out.dtype == np.float32 and out.shape == (H, W)
    assert set(np.unique(out[out < 0])) == {-1.0}  # holes stay -1, never blended
    assert np.isin(out[out > 0], sparse[sparse > 0]).all()  # every value is a measured one


def test_canvas_camera_and_a_lens_that_folds_back():
    Kc = canvas_K(K, (5, 7, 5, 7))
    assert Kc[0, 2] == K[0, 2] + 5 and Kc[1, 2] == K[1, 2] + 7 and Kc[0, 0] == K[0, 0]
    with pytest.raises(LensError, match="folds back"):
        canvas_margins(K, Distortion(k1=-0.9, k2=0.0), W, H)
    # r - 0.3 r^3 peaks at r_d = 0.70: it reaches 0.6, never 0.8
    assert Distortion(k1=-0.3).reaches(0.6) and not Distortion(k1=-0.3).reaches(0.8)
