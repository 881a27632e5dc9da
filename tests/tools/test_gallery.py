"""`crackgen inspect`: gallery files, summary charts, and the page loads cleanly in headless Chromium."""
from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from tiny_recipes import tiny_recipe

from crackgen.tools.gallery import colorize_depth, contact_sheet, write_gallery

CHROMIUM = "/usr/bin/chromium"
RECIPE = tiny_recipe(5, near_camera=False, stereo=True)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    pytest.importorskip("bpy")
    from crackgen.config.recipe import parse_recipe
    from crackgen.datagen.pipeline import SampleProducer
    from crackgen.shards import ShardWriter, sample_key

    root = tmp_path_factory.mktemp("insp") / "ds"
    p = SampleProducer(parse_recipe(RECIPE), threads=1)
    for shard, idx in ((0, (0, 1)), (1, (2,))):
        with ShardWriter(root, shard) as w:
            for i in idx:
                members, meta = p.produce(i)
                w.add(sample_key(shard, i), {**members, "json": meta})
    p.close()
    return root


def test_colorize_depth_keeps_holes_visible():
    d = np.full((4, 4), -1, np.float32)
    d[1, 1], d[2, 2] = 1.0, 2.0
    img = colorize_depth(d)
    assert tuple(img[0, 0]) == (60, 60, 60) and tuple(img[1, 1]) != (60, 60, 60)
    assert not np.array_equal(img[1, 1], img[2, 2])  # near and far get different colours
    sparse = colorize_depth(d, sparse=True)
    assert tuple(sparse[0, 0]) != (60, 60, 60)  # the point at (1,1) is grown to 3x3
    assert tuple(sparse[3, 0]) == (60, 60, 60)


def test_contact_sheet_tiles():
    tiles = [np.full((10, 12, 3), k * 20, np.uint8) for k in range(5)]
    sheet = contact_sheet(tiles, cols=3, pad=2)
    assert sheet.shape == (2 * 12 + 2, 3 * 14 + 2, 3)
    assert (sheet[2:12, 2 + 14:14 + 14] == 20).all()


@pytest.mark.blender
def test_gallery_files_and_summary(dataset):
    index = write_gallery(dataset, page_size=2)
    assert index == dataset / "inspect" / "index.html"
    text = index.read_text()
    data = json.loads(re.search(r'<script type="application/json" id="samples">(.*?)</script>', text, re.S).group(1))
    assert [it["key"] for it in data["items"]] == ["000000-00000", "000000-00001", "000001-00002"]
    for it in data["items"]:
        assert set(it["thumbs"]) == {"rgb", "mask", "depth", "tof", "lidar", "disp_sgm"}
        for rel in it["thumbs"].values():
            assert (dataset / "inspect" / rel).is_file()
        assert it["params"]["family"] and it["params"]["crack_len_m"] > 0
    for title in ("crack-pixel fraction", "ToF fill ratio", "LiDAR fill ratio", "material family"):
        assert title in text
    assert text.count("<svg") >= 6
    assert (dataset / "inspect" / "contact_sheet.png").is_file()


SELFTEST = """<script>
window.__errs = [];
window.addEventListener('error', e => __errs.push('error: ' + (e.message || (e.target && e.target.src))), true);
const __ce = console.error; console.error = (...a) => { __errs.push('console: ' + a.join(' ')); __ce(...a); };
window.addEventListener('load', () => setTimeout(() => {
  const imgs = [...document.querySelectorAll('#grid img')];
  const r = {page1: imgs.length, broken: imgs.filter(i => !(i.complete && i.naturalWidth > 0)).map(i => i.src)};
  document.querySelector('.next').click();
  r.page2 = document.querySelectorAll('#grid .card').length;
  r.errors = __errs;
  const pre = document.createElement('pre'); pre.id = 'selftest'; pre.textContent = JSON.stringify(r);
  document.body.appendChild(pre);
}, 500));
</script>"""


@pytest.mark.blender
@pytest.mark.skipif(not Path(CHROMIUM).exists(), reason="chromium not installed")
def test_gallery_loads_in_headless_chromium(dataset, tmp_path):
    index = write_gallery(dataset, page_size=2)
    page = index.with_name("selftest.html")
    page.write_text(index.read_text().replace("<head>", "<head>" + SELFTEST, 1))
    res = subprocess.run(
        [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--no-first-run", f"--user-data-dir={tmp_path / 'profile'}",
         "--enable-logging=stderr", "--v=0", "--window-size=1400,3000", "--virtual-time-budget=10000",
         "--dump-dom", page.as_uri()],
        capture_output=True, text=True, timeout=120,
    )
    m = re.search(r'<pre id="selftest">(.*?)</pre>', res.stdout, re.S)
    assert m, res.stderr[-2000:]
    r = json.loads(m.group(1).replace("&quot;", '"').replace("&amp;", "&"))
    assert r["page1"] == 2 * 6 and r["broken"] == [], r  # 2 samples x 6 views, all decoded
    assert r["page2"] == 1  # pagination: the third sample on page 2
    assert r["errors"] == []
    console = [l for l in res.stderr.splitlines() if "CONSOLE" in l and "selftest" not in l]
    assert console == [], console
    shutil.rmtree(tmp_path / "profile", ignore_errors=True)


def test_cards_show_the_adaptation_of_each_sample():
    from crackgen.tools.gallery import _params

    adapted = {"adapt": {"applied": True, "method": "fourier", "band": 0.0312, "target": "site_3.jpg"}}
    assert _params(adapted, {})["adapt"] == "fourier 0.031 <- site_3.jpg"
    assert _params({"adapt": {"applied": True, "method": "reinhard", "target": "a.png"}}, {})["adapt"] == \
        "reinhard <- a.png"
    assert _params({"adapt": {"applied": False}}, {})["adapt"] == "none"
    assert _params({}, {})["adapt"] == "none"  # datasets made before [adapt]


def test_cards_show_shape_family_and_camera_effects(tmp_path):
    from crackgen.config.spec import CameraEffectsSpec
    from crackgen.postrender.camera_effects import describe
    from crackgen.shards import ShardWriter, sample_key
    from crackgen.tools.bench_shards import synthetic_sample
    from crackgen.tools.gallery import _params

    fx = describe(CameraEffectsSpec(enabled=True, applied=["exposure", "noise", "jpeg"], exposure_ev=0.314,
                                    noise_full_well_e=1234.4, noise_read_e=2.0, jpeg_quality=83, seed=1))
    p = _params({"camera_effects": fx, "crack": {"shape": "fracture"}}, {})
    assert p["camera_fx"] == "ev:+0.31,noise:1234e,jpeg:q83" and p["shape"] == "fracture"
    old = _params({"crack": {"length_m": 1.0}}, {})  # datasets made before shapes and camera effects
    assert old["camera_fx"] == "none" and old["shape"] == "fbm"
    assert _params({"camera_effects": {"applied": []}}, {})["camera_fx"] == "none"

    rng = np.random.default_rng(0)
    root = tmp_path / "ds"
    with ShardWriter(root, 0) as w:
        for i, meta in enumerate(({"camera_effects": fx, "crack": {"shape": "network"}}, {})):
            smp = synthetic_sample(rng, 32, 8)
            w.add(sample_key(0, i), {k: smp[k] for k in ("rgb.png", "mask.png", "depth.exr")} | {"json": meta})
    text = write_gallery(root).read_text()
    data = json.loads(re.search(r'<script type="application/json" id="samples">(.*?)</script>', text, re.S).group(1))
    assert [it["params"]["shape"] for it in data["items"]] == ["network", "fbm"]
    assert [it["params"]["camera_fx"] for it in data["items"]] == ["ev:+0.31,noise:1234e,jpeg:q83", "none"]
    assert "crack shape family" in text and "camera effects applied" in text


def test_camera_effect_labels_name_each_applied_effect_with_its_value():
    from crackgen.tools.gallery import _camfx_label

    meta = {"applied": ["auto_exposure", "noise", "sharpen", "jpeg"], "auto_exposure_luma": 151.2,
            "noise_full_well_e": 1234.4, "sharpen_amount": 1.256, "sharpen_sigma_px": 1.0, "jpeg_quality": 83}
    assert _camfx_label(meta) == "ae:151,noise:1234e,sharpen:1.26,jpeg:q83"
    assert _camfx_label({"applied": []}) == "none"
