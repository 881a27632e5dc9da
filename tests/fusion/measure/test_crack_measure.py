"""fusion.measure.crack_measure: lengths and widths of hand-made cracks against their analytic values."""

import numpy as np
import pytest

from fusion.measure.crack_measure import longest_crack_path, measure_cracks


def _strip(shape, p0, p1, width):
    """Bool mask: pixel centres within width/2 of segment p0-p1 (row, col), flat ends."""
    rr, cc = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    d = p1 - p0
    L = np.linalg.norm(d)
    t = ((rr - p0[0]) * d[0] + (cc - p0[1]) * d[1]) / L
    n = np.abs((rr - p0[0]) * d[1] - (cc - p0[1]) * d[0]) / L
    return (t >= 0) & (t <= L) & (n <= width / 2)


def _capsule(shape, p0, p1, width):
    """Bool mask: pixel centres within width/2 of segment p0-p1 (round ends: joins arms without gaps)."""
    rr, cc = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    d = p1 - p0
    t = np.clip(((rr - p0[0]) * d[0] + (cc - p0[1]) * d[1]) / (d @ d), 0, 1)
    return np.hypot(rr - p0[0] - t * d[0], cc - p0[1] - t * d[1]) <= width / 2


@pytest.mark.parametrize("angle_deg", [0.0, 17.0, 30.0, 45.0, 72.0])
@pytest.mark.parametrize("width", [1.0, 5.0, 8.0])
def test_straight_crack_length_and_width(angle_deg, width):
    a = np.deg2rad(angle_deg)
    c = np.array([120.25, 120.25])  # off the pixel grid: |n| <= w/2 then holds w pixel rows
    half = 90.0 * np.array([np.sin(a), np.cos(a)])
    m = _strip((240, 240), c - half, c + half, width)
    r = measure_cracks(m)
    assert len(r.components) == 1
    assert r.longest_path == pytest.approx(180.0, rel=0.02)
    assert r.components[0].tip_to_tip == r.longest_path
    assert r.total_length == pytest.approx(180.0, rel=0.025)  # spurs pruned, staircase corrected
    assert r.mean_width == pytest.approx(max(width, 1.0), rel=0.08, abs=0.3)
    assert abs(r.max_width - max(width, 1.0)) <= 1.0


def test_l_shaped_crack():
    # Two arms of 120 and 90 px (centre line) meeting at a right angle, 5 px wide.
    m = _capsule((200, 200), (30, 30), (30, 150), 5) | _capsule((200, 200), (30, 150), (120, 150), 5)
    r = measure_cracks(m)
    (c,) = r.components
    assert c.tip_to_tip == pytest.approx(120 + 90 + 4, rel=0.02)  # + the round ends (2 x w/2 - 1/2 px)
    assert c.total_length == pytest.approx(c.tip_to_tip, rel=0.02)  # no branches
    assert r.mean_width == pytest.approx(5.0, rel=0.08)
    assert c.n_tips == 2


def test_y_shaped_crack_tip_to_tip_vs_total():
    # Arms of 100, 100 and 60 px from one point: tip to tip = the two long arms, total = all three.
    centre = np.array([150.0, 150.0])
    arms = [(100, 90), (100, 210), (60, 330)]
    m = np.zeros((300, 300), bool)
    for length, deg in arms:
        a = np.deg2rad(deg)
        m |= _capsule(m.shape, centre, centre + length * np.array([-np.sin(a), np.cos(a)]), 5)
    r = measure_cracks(m)
    (c,) = r.components
    assert c.n_tips == 3
    assert c.tip_to_tip == pytest.approx(200 + 4, rel=0.02)
    assert c.total_length == pytest.approx(260 + 6, rel=0.02)
    assert r.longest_path == c.tip_to_tip and r.tip_to_tip_sum == c.tip_to_tip
    assert r.mean_width == pytest.approx(5.0, rel=0.1)
    assert abs(r.max_width - 5.0) <= 1.0  # measured away from the junction


def test_curved_crack_arc():
    # Annulus sector: radius 100 px, 150 degrees, 6 px wide: centre line 100 * 150 deg.
    rr, cc = np.mgrid[0:300, 0:300].astype(np.float64)
    rad = np.hypot(rr - 150, cc - 150)
    ang = np.degrees(np.arctan2(150 - rr, cc - 150)) % 360
    m = (np.abs(rad - 100) <= 3) & (ang <= 150)
    r = measure_cracks(m)
    true = 100 * np.deg2rad(150)
    assert r.longest_path == pytest.approx(true, rel=0.02)
    assert r.total_length == pytest.approx(true, rel=0.02)
    assert r.mean_width == pytest.approx(6.0, rel=0.08)
    assert abs(r.max_width - 6.0) <= 1.0


def test_ring_half_and_full_circumference():
    rr, cc = np.mgrid[0:300, 0:300].astype(np.float64)
    m = np.abs(np.hypot(rr - 150, cc - 150) - 100) <= 2
    r = measure_cracks(m)
    (c,) = r.components
    assert c.n_tips == 0
    assert c.tip_to_tip == pytest.approx(np.pi * 100, rel=0.02)  # no tips: the farthest two points
    assert c.total_length == pytest.approx(2 * np.pi * 100, rel=0.02)


def test_components_scale_and_min_length():
    m = _strip((200, 200), (40, 20), (40, 180), 4) | _strip((200, 200), (150, 20), (150, 80), 4)
    r = measure_cracks(m)
    assert [round(c.tip_to_tip) for c in r.components] == [160, 60]
    assert r.longest_path == r.components[0].tip_to_tip
    assert r.tip_to_tip_sum == pytest.approx(220, rel=0.02)
    mm = measure_cracks(m, 0.002)  # 2 mm pixels
    assert mm.longest_path == pytest.approx(0.002 * r.longest_path)
    assert mm.mean_width == pytest.approx(0.002 * r.mean_width)
    assert len(measure_cracks(m, min_length=100).components) == 1
    assert longest_crack_path(m) == r.longest_path


def test_tilted_plane_point_map():
    # Plane rising along columns by tan(35 deg): lengths along columns grow by 1/cos, widths (along rows) do not.
    h, w, s, theta = 120, 220, 0.01, np.deg2rad(35.0)
    rr, cc = np.mgrid[0:h, 0:w].astype(np.float64)
    pts = np.stack([cc * s, rr * s, cc * s * np.tan(theta)], axis=-1)
    m = _strip((h, w), (60.25, 20), (60.25, 200), 6)
    r = measure_cracks(m, pts)
    assert r.longest_path == pytest.approx(180 * s / np.cos(theta), rel=0.02)
    assert r.mean_width == pytest.approx(6 * s, rel=0.08)


def test_empty_mask_and_json():
    r = measure_cracks(np.zeros((20, 20), bool))
    assert r.longest_path == 0.0 and r.components == [] and r.to_dict()["mean_width"] is None
