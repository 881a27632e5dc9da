"""``[camera] views_per_scene``: one surface, crack and material build serves K camera poses.

Each view is its own sample (label, depth and sensors of its own pose), and a sample still depends only on
(recipe, index): the views of one scene that fall in different shards build the scene again in another
worker, and must come out byte for byte as when one worker reused it.
"""
from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from run_watch import done_shards, wait_for
from tiny_recipes import tiny_recipe

from crackgen.config.recipe import parse_recipe
from crackgen.config.spec import make_spec, pixel_footprint_m, scene_cameras, scene_of
from crackgen.datagen.generate import GenerateOptions, generate
from crackgen.shards import iter_samples
from crackgen.shards.manifest import Manifest

K = 3
BASE = tiny_recipe(21, name="views", samples=7, shard_size=2, spp=2)
VIEWS = BASE.replace("[camera]\n", f"[camera]\nviews_per_scene = {K}\n", 1)


# ---------------------------------------------------------------- the draws (no rendering)

def test_views_of_a_scene_share_crack_surface_and_material_and_nothing_else():
    r = parse_recipe(VIEWS)
    specs = [make_spec(r, i) for i in range(7)]
    assert [scene_of(r, i) for i in range(7)] == [0, 0, 0, 1, 1, 1, 2]
    for a, b in ((0, 1), (0, 2), (3, 5)):
        assert specs[a].crack == specs[b].crack and specs[a].surface == specs[b].surface
        assert specs[a].material == specs[b].material
        assert specs[a].camera != specs[b].camera and specs[a].render.seed != specs[b].render.seed
        assert specs[a].tof.seed != specs[b].tof.seed  # each view its own sensor noise
    assert specs[2].crack != specs[3].crack  # the next scene is a new one
    # a view's own sections are the ones a one-view recipe draws for that index
    one = parse_recipe(BASE)
    for i in (1, 4):
        assert make_spec(one, i).camera == specs[i].camera and make_spec(one, i).lights == specs[i].lights


def test_the_shared_surface_covers_every_view_of_its_scene():
    r = parse_recipe(VIEWS.replace("[surface]\n", "[surface]\nsize_fov = { min = 1.2, max = 1.4 }\n", 1))
    for i in (0, 3):
        spec = make_spec(r, i)
        for cam in scene_cameras(r, i):
            view = pixel_footprint_m(cam) * max(cam.width_px, cam.height_px) / max(math.cos(cam.tilt_rad), 0.2)
            assert spec.surface.size_m >= 1.2 * view


def test_one_view_per_scene_is_todays_recipe():
    """Set to 1 explicitly or left out: the same recipe hash, so the same shards (and --resume accepts both)."""
    explicit = parse_recipe(BASE.replace("[camera]\n", "[camera]\nviews_per_scene = 1\n", 1))
    assert explicit.hash == parse_recipe(BASE).hash
    assert parse_recipe(VIEWS).hash != parse_recipe(BASE).hash
    assert make_spec(explicit, 5) == make_spec(parse_recipe(BASE), 5)


# ---------------------------------------------------------------- rendered views

def _content(root: Path) -> dict[str, dict]:
    return {s["__key__"]: s for s in iter_samples(str(root))}


def _assert_same_bytes(a: Path, b: Path) -> None:
    ma, mb = Manifest.load(a), Manifest.load(b)
    names = [r.name for r in ma.done()]
    assert names == [r.name for r in mb.done()] == [f"shard-{i:06d}.tar" for i in range(4)]
    for ra, rb in zip(ma.done(), mb.done()):
        assert ra.sha256 == rb.sha256, f"{ra.name}: sha256 differs"
        assert (a / ra.name).read_bytes() == (b / rb.name).read_bytes(), ra.name


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("views") / "ref"
    summary = generate(parse_recipe(VIEWS), GenerateOptions(out=str(out), workers=1, progress=False))
    assert summary.ok, summary.lines()
    return out


@pytest.mark.blender
@pytest.mark.slow
def test_each_view_has_its_own_label_depth_and_sensors_on_the_shared_crack(reference):
    c = _content(reference)
    s = [c[k] for k in sorted(c)]
    assert [x["meta"]["scene"] for x in s[:4]] == [
        {"index": 0, "view": 0, "views_per_scene": K}, {"index": 0, "view": 1, "views_per_scene": K},
        {"index": 0, "view": 2, "views_per_scene": K}, {"index": 1, "view": 0, "views_per_scene": K}]
    np.testing.assert_array_equal(s[0]["crackmap"], s[2]["crackmap"])  # one crack map per scene
    assert not np.array_equal(s[0]["crackmap"], s[3]["crackmap"])
    for a, b in ((0, 1), (1, 2)):
        assert not np.array_equal(s[a]["depth"], s[b]["depth"])  # another pose, another view
        assert not np.array_equal(s[a]["tof"], s[b]["tof"])
    for x in s:
        # the per-view geometry check: Blender's depth pass (the reused mesh) against this view's ray cast
        assert x["meta"]["depth"]["render_vs_raycast_median_abs_m"] < 1e-3, x["__key__"]
        assert (x["depth"] > 0).all()


@pytest.mark.blender
@pytest.mark.slow
def test_two_workers_give_byte_identical_shards(reference, tmp_path):
    """Scenes 0 and 1 straddle shards: with two workers a scene is built twice, in two processes."""
    summary = generate(parse_recipe(VIEWS), GenerateOptions(out=str(tmp_path / "w2"), workers=2, progress=False))
    assert summary.ok
    _assert_same_bytes(reference, tmp_path / "w2")


@pytest.mark.blender
@pytest.mark.slow
def test_kill_then_resume_gives_byte_identical_shards(reference, tmp_path):
    recipe = tmp_path / "views.toml"
    recipe.write_text(VIEWS)
    out = tmp_path / "killed"
    exe = str(Path(sys.executable).with_name("crackgen"))
    proc = subprocess.Popen([exe, "generate", str(recipe), "--out", str(out), "--workers", "1", "--no-progress"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    # killed once the manifest records the first shard, with the second (scene 0's last view) unfinished
    wait_for(lambda: done_shards(out) >= 1 or proc.poll() is not None, 240, "the first finished shard")
    assert proc.poll() is None, "the run ended before it could be killed"
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    assert 1 <= len(Manifest.load(out).done()) < 4
    p = subprocess.run([exe, "generate", str(recipe), "--out", str(out), "--resume", "--workers", "2", "--no-progress"],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    _assert_same_bytes(reference, out)
