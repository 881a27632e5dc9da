"""fusion.measure.crack_length: skeleton geodesic diameter on hand-made cracks, in px, metres and 3-D."""

import cv2
import numpy as np
import pytest
from scipy.sparse import csgraph

from fusion.measure.crack_length import (
    CrackLengthError,
    crack_components,
    skeleton,
    skeleton_graph,
    skeleton_length,
)
from fusion.measure.crack_measure import measure_cracks


def crack_length(mask, coords=None, *, min_length=0.0, step_px=4):
    """Sum of the skeleton diameters of the components (what the skeleton alone measures)."""
    return sum(c.path_length for c in crack_components(mask, coords, step_px=step_px) if c.path_length >= min_length)


def _blank(h=120, w=120):
    return np.zeros((h, w), np.uint8)


def test_straight_one_pixel_line_px_and_metres():
    m = _blank()
    m[60, 10:91] = 255  # 81 pixels -> 80 px between the tip centres
    assert crack_length(m) == pytest.approx(80.0)
    assert crack_length(m, 0.002) == pytest.approx(0.16)
    (c,) = crack_components(m)
    assert c.exact and c.n_pixels == 81
    assert sorted(c.endpoints) == [(60, 10), (60, 90)]
    assert len(c.path) == 81


def test_thick_straight_line_within_a_width():
    m = _blank()
    m[58:63, 10:91] = 255  # 5 px wide, 81 long: skeleton tips sit inside the mask ends
    length = crack_length(m)
    assert 80.0 - 5.0 <= length <= 80.0


def test_diagonal_45_exact():
    m = _blank()
    for k in range(71):
        m[20 + k, 15 + k] = 1
    assert crack_length(m, step_px=1) == pytest.approx(70 * np.sqrt(2))
    assert crack_length(m) == pytest.approx(70 * np.sqrt(2))


@pytest.mark.parametrize("angle_deg", [10.0, 22.5, 33.0, 60.0])
def test_diagonal_any_angle_within_one_percent(angle_deg):
    # Digital lines: raw 8-connected graph length is biased up to +8 %; the polyline
    # measurement along the geodesic must be within 1 % of the Euclidean length.
    m = _blank(200, 200)
    a = np.deg2rad(angle_deg)
    p0 = np.array([20, 20])
    p1 = np.round(p0 + 150 * np.array([np.cos(a), np.sin(a)])).astype(int)
    cv2.line(m, tuple(map(int, p0)), tuple(map(int, p1)), 255, 1)
    true = float(np.linalg.norm(p1 - p0))
    assert crack_length(m) == pytest.approx(true, rel=0.01)
    assert crack_length(m, step_px=1) >= true  # graph metric never under-measures a line


def test_l_shaped_crack():
    m = _blank()
    m[20, 20:61] = 1  # 40 px arm
    m[20:51, 60] = 1  # 30 px arm, sharing the corner pixel
    (c,) = crack_components(m, step_px=1)
    # The geodesic cuts the corner pixel with one diagonal step: 39 + sqrt(2) + 29.
    assert c.graph_length == pytest.approx(68 + np.sqrt(2))
    assert sorted(c.endpoints) == [(20, 20), (50, 60)]
    # The polyline measurement cuts the corner by at most a few px.
    assert 66.0 <= crack_length(m) <= 70.0
    assert crack_length(m, 0.5) == pytest.approx(0.5 * crack_length(m))


def test_thick_l_shape_close_to_centreline():
    m = _blank(160, 160)
    cv2.line(m, (20, 30), (120, 30), 255, 5)
    cv2.line(m, (120, 30), (120, 130), 255, 5)
    # Centre line 100 + 100 px; skeleton tips stop within ~a width of the ends, corner cut.
    assert 190.0 <= crack_length(m) <= 205.0


def test_separate_cracks_sum_and_t_junction():
    m = _blank()
    m[10, 10:51] = 1  # 40
    m[100, 10:41] = 1  # 30
    assert crack_length(m) == pytest.approx(70.0)
    assert len(crack_components(m)) == 2
    assert crack_length(m, min_length=35.0) == pytest.approx(40.0)

    t = _blank()
    t[30, 10:91] = 1  # bar 80
    t[31:61, 50] = 1  # stem 30 below the bar centre
    (c,) = crack_components(t, step_px=1)
    # Longest tip-to-tip path: one bar tip, the junction, down the stem (or the other tip).
    assert c.graph_length == pytest.approx(80.0)  # bar (80) vs 40 + sqrt(2) + 29 = 70.4
    assert skeleton_length(t) == pytest.approx(80.0 + 30.0)


def test_ring_is_half_circumference_and_sweeps_agree():
    m = _blank(200, 200)
    cv2.circle(m, (100, 100), 60, 255, 1)
    # A ring is the worst case for the eccentricity bounds (every node is a diameter end):
    # certified with a large budget; with a tiny one the lower bound is already exact.
    exact = crack_components(m, max_sweeps=10_000)
    approx = crack_components(m, max_sweeps=3)
    assert exact[0].exact and not approx[0].exact
    assert approx[0].graph_length == pytest.approx(exact[0].graph_length)
    assert exact[0].path_length == pytest.approx(np.pi * 60, rel=0.02)


def test_tilted_plane_3d_coords():
    # A plane rising along x: z = x * tan(theta); pixel pitch s.  A crack along x is
    # longer by 1/cos(theta) in 3-D, one along y is unchanged.
    h, w, s, theta = 100, 100, 0.01, np.deg2rad(35.0)
    rr, cc = np.mgrid[0:h, 0:w].astype(np.float64)
    pts = np.stack([cc * s, rr * s, cc * s * np.tan(theta)], axis=-1)
    m = _blank(h, w)
    m[50, 10:81] = 1  # 70 px along x
    assert crack_length(m, pts) == pytest.approx(70 * s / np.cos(theta))
    m2 = _blank(h, w)
    m2[10:81, 50] = 1  # 70 px along y
    assert crack_length(m2, pts) == pytest.approx(70 * s)
    # Invalid points cut the crack: edges touching NaN points are dropped.
    pts[:, 40] = np.nan
    assert crack_length(m, pts) == pytest.approx((29 + 39) * s / np.cos(theta))  # cols 10..39 and 41..80


def _random_crossing_lines(rng):
    m = _blank(96, 96)
    for _k in range(5):
        p = rng.integers(5, 90, size=4)
        cv2.line(m, (int(p[0]), int(p[1])), (int(p[2]), int(p[3])), 255, int(rng.integers(1, 5)))
    return m


def _looped_shapes():
    m = _blank(96, 96)
    cv2.circle(m, (30, 30), 15, 255, 1)  # lollipop: ring + stick
    cv2.line(m, (45, 30), (90, 40), 255, 1)
    cv2.circle(m, (30, 75), 12, 255, 1)  # two rings joined by a bar
    cv2.circle(m, (70, 75), 10, 255, 1)
    cv2.line(m, (42, 75), (60, 75), 255, 1)
    return m


def test_graph_diameter_matches_brute_force_all_pairs():
    # Trees (two sweeps) and looped components (eccentricity bounds) against all-pairs Dijkstra.
    rng = np.random.default_rng(0)
    masks = [_random_crossing_lines(rng) for _ in range(3)] + [_looped_shapes()]
    n_looped = 0
    for m in masks:
        skel = skeleton(m)
        g = skeleton_graph(skel)
        d = csgraph.shortest_path(g.graph, directed=False)
        d[~np.isfinite(d)] = -1
        _, labels = csgraph.connected_components(g.graph, directed=False)
        for k in np.unique(labels):
            nodes = labels == k
            n_looped += int(np.count_nonzero(nodes[g.edges[:, 0]]) > nodes.sum() - 1)
        comps = crack_components(skel, is_skeleton=True, step_px=1, max_sweeps=10_000)
        brute = sorted((d[np.ix_(labels == k, labels == k)].max() for k in np.unique(labels)), reverse=True)
        np.testing.assert_allclose([c.graph_length for c in comps], brute, rtol=1e-9)
        assert all(c.exact for c in comps)
    assert n_looped >= 3  # the looped code path was exercised


def test_empty_and_dtypes():
    assert crack_length(_blank()) == 0.0
    assert crack_components(np.zeros((10, 10), bool)) == []
    m = _blank()
    m[5, 5] = 1
    (c,) = crack_components(m)
    assert c.path_length == 0.0 and c.n_pixels == 1


def test_bad_inputs():
    with pytest.raises(CrackLengthError, match="mask must be a 2-D"):
        crack_components(np.zeros((4, 4, 3)))
    with pytest.raises(CrackLengthError, match="coords"):
        crack_components(np.ones((4, 4)), np.zeros((5, 4, 3)))
    with pytest.raises(CrackLengthError, match="pixel size"):
        crack_components(np.ones((4, 4)), -0.1)
    with pytest.raises(CrackLengthError, match="step_px"):
        crack_components(np.ones((4, 4)), step_px=0)
    with pytest.raises(CrackLengthError, match="coords"):
        measure_cracks(np.ones((4, 4)), np.zeros((4, 4, 2)))
