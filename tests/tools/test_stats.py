"""`crackgen stats` on hand-made masks of known widths and component counts, as a folder and as shards."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from crackgen.shards import ShardWriter, sample_key
from crackgen.tools.cli import main
from crackgen.tools.stats import StatsError, compute_stats, count_components, crack_widths, image_stats

H, W = 64, 96


def line(width: int, vertical: bool = False) -> np.ndarray:
    m = np.zeros((H, W), np.uint8)
    if vertical:
        m[4:60, 40:40 + width] = 255
    else:
        m[30:30 + width, 8:88] = 255
    return m


def blobs() -> np.ndarray:
    m = np.zeros((H, W), np.uint8)
    cv2.circle(m, (20, 32), 6, 255, -1)
    cv2.circle(m, (70, 32), 8, 255, -1)
    return m


def grey(value: int = 150) -> np.ndarray:
    return np.full((H, W, 3), value, np.uint8)


@pytest.mark.parametrize("width", [1, 2, 3, 4, 5, 8])
@pytest.mark.parametrize("vertical", [False, True])
def test_straight_line_width_is_its_pixel_width(width, vertical):
    w = crack_widths(line(width, vertical))
    assert np.median(w) == pytest.approx(width, abs=0.01)


@pytest.mark.parametrize("angle_deg", [10, 30, 45, 60])
@pytest.mark.parametrize("width", [5, 7, 10])
def test_slanted_band_width_within_a_pixel(angle_deg, width):
    # pixels whose centre lies within width/2 of a slanted line: a band of known perpendicular width
    yy, xx = np.mgrid[0:160, 0:160].astype(float) - 80
    a = np.radians(angle_deg)
    across, along = np.abs(-xx * np.sin(a) + yy * np.cos(a)), np.abs(xx * np.cos(a) + yy * np.sin(a))
    m = ((across < width / 2) & (along < 60)).astype(np.uint8) * 255
    assert abs(np.median(crack_widths(m)) - width) <= 0.75  # pixel staircase at 45 deg: +0.66


def test_components_and_empty_masks():
    assert count_components(blobs()) == 2
    assert count_components(line(3)) == 1
    assert count_components(np.zeros((H, W), np.uint8)) == 0
    assert crack_widths(np.zeros((H, W), np.uint8)).size == 0


def test_image_statistics_on_known_images():
    s = image_stats(grey(150), line(5))
    assert s.fraction == pytest.approx(5 * 80 / (H * W)) and s.components == 1 and s.size == (W, H)
    assert s.brightness == pytest.approx(150, abs=0.5) and s.contrast == pytest.approx(0, abs=1e-6)
    assert s.sharpness == pytest.approx(0, abs=1e-6)
    assert s.label_contrast == pytest.approx(0.0)  # a label on a flat grey image does not show
    checker = (np.indices((H, W)).sum(0) % 2 * 255).astype(np.uint8)
    c = image_stats(np.dstack([checker] * 3), line(5))
    assert c.contrast == pytest.approx(127.5, abs=1) and c.sharpness > 1e5


def test_label_contrast_of_faint_and_dark_cracks():
    """A crack painted at 90 % / 50 % / 0 % of the surface's grey: contrast 0.1 / 0.5 / 1; none without a crack."""
    for shade, want in ((0.9, 0.1), (0.5, 0.5), (0.0, 1.0)):
        img = grey(200)
        img[line(3) > 0] = round(200 * shade)
        assert image_stats(img, line(3)).label_contrast == pytest.approx(want, abs=0.01)
    assert image_stats(grey(200), np.zeros((H, W), np.uint8)).label_contrast is None


def cases() -> list[tuple[np.ndarray, np.ndarray]]:
    """Three 5-px lines, one two-blob image, one crack-free image."""
    return [(grey(100), line(5)), (grey(120), line(5, vertical=True)), (grey(140), line(5)),
            (grey(160), blobs()), (grey(180), np.zeros((H, W), np.uint8))]


def check(s: dict) -> None:
    assert s["images"] == 5 and s["crack_free"] == 1 and s["crack_free_pct"] == pytest.approx(20)
    rows = s["rows"]
    assert rows["components"]["p50"] == 1 and rows["components"]["mean"] == pytest.approx((1 + 1 + 1 + 2 + 0) / 5)
    assert rows["brightness"]["p50"] == pytest.approx(140, abs=0.5)
    assert rows["brightness"]["mean"] == pytest.approx(140, abs=0.5)
    # line skeleton pixels outnumber blob skeleton pixels: the median width is the lines' 5 px
    assert rows["width_px"]["p50"] == pytest.approx(5, abs=0.01)
    assert s["sizes"] == {f"{W}x{H}": 5}
    assert rows["label_contrast"]["p50"] == pytest.approx(0.0)  # labels on flat grey: nothing shows


def test_folder_form(tmp_path, capsys):
    root = tmp_path / "real"
    (root / "images").mkdir(parents=True)
    (root / "masks").mkdir()
    for i, (img, m) in enumerate(cases()):
        cv2.imwrite(str(root / "images" / f"{i:03d}.jpg"), img)
        cv2.imwrite(str(root / "masks" / f"{i:03d}.png"), m)
    check(compute_stats(root, progress=False))
    out = tmp_path / "s.json"
    assert main(["stats", str(root), "--json-out", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "crack width (px)" in text and "crack-free images: 20.0 % (1 of 5)" in text and f"wrote {out}" in text
    check(json.loads(out.read_text()))
    assert compute_stats(root, limit=2, progress=False)["images"] == 2
    # two folders side by side: one row per statistic, one p10/p50/p90 block per folder
    other = tmp_path / "other"
    (other / "images").mkdir(parents=True)
    (other / "masks").mkdir()
    cv2.imwrite(str(other / "images" / "x.png"), grey(90))
    cv2.imwrite(str(other / "masks" / "x.png"), line(3))
    assert main(["stats", str(root), str(other), "--json-out", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "real (5)" in text and "other (1)" in text
    width_row = next(t for t in text.splitlines() if t.startswith("crack width (px)")).split()
    assert [float(v) for v in width_row[3:]] == pytest.approx([5, 5, 5, 3, 3, 3], abs=0.01)
    assert [r["images"] for r in json.loads(out.read_text())] == [5, 1]


def test_shard_form(tmp_path):
    root = tmp_path / "ds"
    items = cases()
    for shard in range(2):
        with ShardWriter(root, shard) as w:
            for i, (img, m) in enumerate(items[shard * 3:shard * 3 + 3]):
                w.add(sample_key(shard, i), {"rgb.png": img, "mask.png": m, "json": {"index": i}})
    check(compute_stats(root, progress=False))
    assert compute_stats(root, limit=4, progress=False)["images"] == 4


def test_bad_paths_get_one_line_errors(tmp_path, capsys):
    with pytest.raises(StatsError, match="not a folder"):
        compute_stats(tmp_path / "missing")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(StatsError, match="neither a crackgen dataset nor an images/ \\+ masks/ folder"):
        compute_stats(empty)
    (empty / "images").mkdir()
    (empty / "masks").mkdir()
    cv2.imwrite(str(empty / "images" / "a.png"), grey())
    cv2.imwrite(str(empty / "masks" / "b.png"), line(3))
    assert main(["stats", str(empty), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "no image in images/ has a mask of the same name" in err and len(err.strip().splitlines()) == 1
