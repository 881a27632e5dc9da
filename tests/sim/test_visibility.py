"""Visibility check (ring contrast) and the invisible-crack policies (empty / redraw / keep)."""
from __future__ import annotations

import numpy as np
import pytest
from test_groundtruth import grid_plane

import crackgen.sim.groundtruth as groundtruth
from crackgen.config.recipe import LabelSection
from crackgen.config.spec import CrackSpec
from crackgen.procedural.crackmap import CrackMap
from crackgen.sim.groundtruth import view_ground_truth, view_label
from crackgen.sim.raycast import MeshRaycaster
from crackgen.sim.visibility import VisibilityError, decide_label, label_contrast, ring
from fusion.geometry.camera import Camera, intrinsics_from_focal, look_at


def grey_with_line(grey=128, line=32):
    rgb = np.full((40, 60, 3), grey, np.uint8)
    rgb[18:21, 5:55] = line
    label = np.zeros((40, 60), np.uint8)
    label[18:21, 5:55] = 255
    return rgb, label


def test_dark_line_on_grey_gives_the_expected_contrast():
    rgb, label = grey_with_line()
    assert label_contrast(rgb, label) == pytest.approx((128 - 32) / 128)  # 0.75
    rgb2, _ = grey_with_line(200, 150)
    assert label_contrast(rgb2, label) == pytest.approx(0.25)
    rgb3, _ = grey_with_line(100, 100)
    assert label_contrast(rgb3, label) == pytest.approx(0.0)
    # a label wider than the dark line: its median still reads the line, the ring the grey
    wide = label.copy()
    wide[17, 5:55] = 255
    assert label_contrast(rgb, wide) == pytest.approx(0.75)
    assert label_contrast(rgb, np.zeros_like(label)) is None


def test_ring_is_a_thin_band_around_the_label():
    _, label = grey_with_line()
    r = ring(label, 2)
    assert not (r & (label > 0)).any()
    assert r[16, 30] and r[22, 30] and not r[15, 30] and not r[23, 30]
    assert r[19, 3] and not r[19, 2]
    with pytest.raises(VisibilityError, match="match"):
        label_contrast(np.zeros((5, 5, 3), np.uint8), label)


@pytest.mark.parametrize("invisible, attempt, action", [
    ("empty", 0, "empty"), ("keep", 0, "keep"), ("redraw", 0, "redraw"), ("redraw", 1, "redraw"), ("redraw", 2, "empty"),
])
def test_invisible_policies(invisible, attempt, action):
    kw = dict(min_contrast=0.1, invisible=invisible, attempt=attempt, max_redraws=2)
    d = decide_label(True, 100, 0.05, **kw)  # contrast below min
    assert (d.action, d.shows) == (action, False)
    assert decide_label(True, 0, None, **kw).action == action  # crack in view but nothing labelled
    assert decide_label(True, 100, 0.3, **kw).action == "ok"
    assert decide_label(False, 0, None, **kw).action == "ok"  # no crack in view: a plain negative


# ---- view_label on a ray-cast plane, with the contrast stubbed

def _scene():
    size, n = 2.0, 64
    verts, faces, uvs = grid_plane(size, 17)
    T = look_at(np.array([0.0, 0.0, 1.5]), np.zeros(3), np.array([0.0, -1.0, 0.0]))
    cam = Camera(intrinsics_from_focal(30, 36, 80, 60, 0, 0), T, 80, 60)
    k = np.arange(n)
    d = np.clip(1.0 - np.abs(k - 32) / 6.5, 0, None).astype(np.float32) * 0.4  # 0.4 m wide, 0.4 m deep (flat mesh)
    depth = np.tile(d, (n, 1))
    spec = CrackSpec(1, 1, 1, 0.5, 2, 0.1, 0.05, 0, 0, 0)
    cm = CrackMap(z=np.zeros_like(depth), mask=depth > 0, disp=depth, depth_m=depth, skeleton=None,
                  length_m=size, size_m=size, spec=spec)
    gt = view_ground_truth(cam, MeshRaycaster(verts, faces, uvs), cm.mask)
    return cm, gt, np.full((60, 80, 3), 128, np.uint8)


@pytest.fixture
def stub_contrast(monkeypatch):
    box = {"value": 0.5}
    monkeypatch.setattr(groundtruth, "label_contrast", lambda rgb, label: box["value"])
    return box


def test_view_label_visible_is_inside_thesis_and_narrower(stub_contrast):
    cm, gt, rgb = _scene()
    lab = view_label(LabelSection(), cm, gt, rgb)
    assert not lab.redraw and lab.meta["action"] == "ok" and lab.meta["policy"] == "visible"
    vis, thesis = lab.mask > 0, lab.thesis > 0
    assert vis.any() and not (vis & ~thesis).any() and vis.sum() < thesis.sum()
    assert lab.meta["pixel_fraction"] == pytest.approx(vis.mean())
    np.testing.assert_array_equal(lab.thesis, gt.mask)
    th = view_label(LabelSection(policy="thesis"), cm, gt, rgb)
    np.testing.assert_array_equal(th.mask, gt.mask)
    # the scene's texels, computed once and handed to each view, give the same label (what the pipeline does)
    shared = view_label(LabelSection(), cm, gt, rgb, texels=groundtruth.label_texels(LabelSection(), cm))
    np.testing.assert_array_equal(shared.mask, lab.mask)
    assert shared.meta == lab.meta
    # and a view labels from the texels it is given, not from the crack map
    none = view_label(LabelSection(), cm, gt, rgb, texels=np.zeros_like(cm.mask))
    assert not (none.mask > 0).any()


@pytest.mark.parametrize("invisible", ["empty", "keep", "redraw"])
def test_view_label_invisible_crack(stub_contrast, invisible):
    cm, gt, rgb = _scene()
    stub_contrast["value"] = 0.01
    cfg = LabelSection(invisible=invisible, max_redraws=1)
    first = view_label(cfg, cm, gt, rgb, attempt=0)
    last = view_label(cfg, cm, gt, rgb, attempt=1)
    assert first.meta["contrast"] == 0.01 and not first.meta["shows"] and last.meta["attempt"] == 1
    if invisible == "keep":
        assert (first.mask > 0).any() and not first.redraw
    elif invisible == "empty":
        assert not (first.mask > 0).any() and first.meta["pixel_fraction"] == 0.0 and not first.redraw
    else:
        assert first.redraw and not last.redraw and not (last.mask > 0).any()  # out of redraws: empty
    assert (first.thesis > 0).any()  # the thesis mask is kept whatever happens to the label
