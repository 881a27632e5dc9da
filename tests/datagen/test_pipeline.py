"""SampleProducer: members follow the data contract and agree with each other geometrically."""
from __future__ import annotations

import numpy as np
import pytest
from tiny_recipes import tiny_recipe

from crackgen.config.recipe import parse_recipe
from crackgen.config.spec import make_spec
from crackgen.datagen.pipeline import STAGES, SampleProducer
from crackgen.sim.rig import make_rig

pytestmark = [pytest.mark.blender, pytest.mark.slow]

RECIPE = tiny_recipe(3, width=80, height=60, grid_px=64, spp=2, tof_px=(40, 30), flying_pixels=False, stereo=True)


@pytest.fixture(scope="module")
def produced():
    recipe = parse_recipe(RECIPE)
    p = SampleProducer(recipe, threads=1)
    samples = [p.make(i) for i in (0, 1)]
    again = p.make(0)  # after sample 1: must not depend on what the process rendered before
    p.close()
    return recipe, samples, again


def test_members_follow_the_contract(produced):
    _, samples, _ = produced
    m = samples[0].members
    assert set(m) == {"rgb.png", "mask.png", "mask_thesis.png", "depth.exr", "crackmap.exr", "tof.exr", "tofraw.exr", "lidar.exr",
                      "right.png", "disp_sgm.exr", "disp_gt.exr", "disp_tof.exr", "tofamp.exr",
                      "disp_lidar.exr"}
    assert m["rgb.png"].shape == (60, 80, 3) and m["rgb.png"].dtype == np.uint8
    assert m["right.png"].shape == (60, 80, 3)
    assert m["mask.png"].dtype == np.uint8 and set(np.unique(m["mask.png"])) <= {0, 255}
    for k in ("depth.exr", "tof.exr", "lidar.exr", "disp_sgm.exr", "disp_gt.exr", "disp_tof.exr"):
        a = m[k]
        assert a.shape == (60, 80) and a.dtype == np.float32, k
        assert np.all((a > 0) | (a == -1)), f"{k}: no-value must be exactly -1"
    assert m["tofraw.exr"]["Z"].shape == (30, 40) and m["tofraw.exr"]["A"].shape == (30, 40)
    # SYNTH3 fusion inputs: ToF disparity is f*B/Z of ToF points in the left view
    meta = samples[0].meta
    f = meta["cameras"]["rgb"]["K"][0][0]
    B = meta["spec"]["camera"]["baseline_m"]
    ok = m["disp_tof.exr"] > 0
    assert ok.mean() > 0.05 and ((m["tofamp.exr"] > 0) == ok).all()
    np.testing.assert_allclose(m["disp_tof.exr"][ok], f * B / m["tof.exr"][ok], rtol=1e-4)
    # LiDAR/stereo variant: LiDAR disparity in the left view is f*B/Z of the LiDAR depth there
    ok = m["lidar.exr"] > 0
    assert ok.any() and ((m["disp_lidar.exr"] > 0) == ok).all()
    np.testing.assert_allclose(m["disp_lidar.exr"][ok], f * B / m["lidar.exr"][ok], rtol=1e-4)


def test_meta_has_spec_cameras_and_timings_stay_out_of_it(produced):
    recipe, samples, _ = produced
    meta = samples[1].meta
    spec = make_spec(recipe, 1)
    assert meta["spec"] == spec.to_dict()
    rig = make_rig(spec).to_meta()
    for cam in ("rgb", "right", "tof", "lidar"):
        np.testing.assert_allclose(meta["cameras"][cam]["T_cam_world"], rig[cam]["T_cam_world"])
    np.testing.assert_allclose(meta["cameras"]["rgb"]["K"], rig["rgb"]["K"])
    assert meta["seeds"]["seed_sequence"] == [recipe.dataset.seed, 1]
    timings = samples[1].timings
    assert set(timings) <= set(STAGES) and {"render", "crackmap", "tof", "lidar", "stereo"} <= set(timings)
    assert all(v >= 0 for v in timings.values())
    assert "timings" not in meta  # run-dependent: would make two runs' shards differ
    assert meta["crack"]["length_m"] > 0 and meta["material"]["family"] == spec.material.family
    vis = meta["visible"]  # GT size of the crack in view: at most the whole patch's
    assert vis["label"] == "thesis" and vis["unit"] == "m"
    if vis["texels"]:
        # polyline (longest path) and step-corrected (total) lengths differ by up to ~2 % on one branch
        assert 0 < vis["longest_path_m"] <= 1.05 * vis["total_length_m"] <= 1.5 * meta["crack"]["length_m"]
    import json

    json.dumps(meta, allow_nan=False)  # strict JSON


def test_geometry_agrees_between_render_raycast_and_sensors(produced):
    _, samples, _ = produced
    for s in samples:
        m = s.members
        depth = m["depth.exr"]
        # Blender's depth pass vs the ray-cast GT depth: same mesh, so sub-millimetre agreement
        assert s.meta["depth"]["render_vs_raycast_median_abs_m"] < 1e-3
        # the camera looks at the surface from 0.7-0.9 m: the whole view is surface
        assert (depth > 0).all() and 0.5 < np.median(depth) < 1.1
        # ToF (no flying pixels here) measures the same surface: small noise around GT depth
        tof = m["tof.exr"]
        ok = tof > 0
        assert ok.mean() > 0.05
        assert np.median(np.abs(tof[ok] - depth[ok])) < 0.01
        lid = m["lidar.exr"]
        ok = lid > 0
        assert ok.any() and np.median(np.abs(lid[ok] - depth[ok])) < 0.05
        # GT disparity is f*B/Z of the GT depth
        spec_cam = s.meta["cameras"]
        f = spec_cam["rgb"]["K"][0][0]
        c_l = -np.array(spec_cam["rgb"]["T_cam_world"])[:3, :3].T @ np.array(spec_cam["rgb"]["T_cam_world"])[:3, 3]
        c_r = -np.array(spec_cam["right"]["T_cam_world"])[:3, :3].T @ np.array(spec_cam["right"]["T_cam_world"])[:3, 3]
        B = np.linalg.norm(c_r - c_l)
        np.testing.assert_allclose(m["disp_gt.exr"], f * B / depth, rtol=1e-4)


def test_same_index_gives_same_content_whatever_came_before(produced):
    _, samples, again = produced
    for k in ("rgb.png", "mask.png", "depth.exr", "tof.exr", "lidar.exr", "disp_sgm.exr"):
        np.testing.assert_array_equal(samples[0].members[k], again.members[k], err_msg=k)
    assert samples[0].meta == again.meta


def test_stage_failure_names_sample_and_stage(produced):
    from crackgen.datagen.pipeline import PipelineError

    recipe, _, _ = produced
    bad = recipe.model_copy(update={"surface": recipe.surface.model_copy(update={"crackmap_px": 1})})
    p = SampleProducer(bad)
    with pytest.raises(PipelineError, match=r"sample 4: crackmap: CrackMapError"):
        p.make(4)
