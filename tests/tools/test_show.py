"""`crackgen show`: the point cloud lies on the rendered surface; the splat view is z-buffered."""
from __future__ import annotations

import numpy as np
import pytest
from tiny_recipes import tiny_recipe

from crackgen.tools.show import ShowError, sample_cloud, show, splat_render

RECIPE = tiny_recipe(9, near_camera=False, lidar=False)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    pytest.importorskip("bpy")
    from crackgen.config.recipe import parse_recipe
    from crackgen.datagen.pipeline import SampleProducer
    from crackgen.shards import ShardWriter, sample_key

    root = tmp_path_factory.mktemp("show") / "ds"
    p = SampleProducer(parse_recipe(RECIPE), threads=1)
    with ShardWriter(root, 0) as w:
        members, meta = p.produce(0)
        w.add(sample_key(0, 0), {**members, "json": meta})
    p.close()
    return root, members, meta


def test_splat_nearer_point_wins():
    # two points on the same view ray (looking straight down): the higher one (nearer) must show
    pts = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 0.0], [-1.0, -1.0, 0.0]])
    cols = np.array([[0, 0, 255], [255, 0, 0], [0, 255, 0], [0, 255, 0]], np.uint8)
    img = splat_render(pts, cols, size=(101, 101), elev_deg=90.0, azim_deg=0.0, splat_px=1)
    red = np.all(img == [255, 0, 0], axis=-1)
    assert red.sum() == 1 and not np.all(img == [0, 0, 255], axis=-1).any()


@pytest.mark.blender
def test_point_cloud_lies_on_the_surface(dataset, tmp_path):
    import open3d as o3d

    root, members, meta = dataset
    ply, png = tmp_path / "c.ply", tmp_path / "c.png"
    lines = show(str(root), "000000-00000", pointcloud=str(ply), png=str(png))
    assert any("numpy splat" in l or "Open3D" in l for l in lines)
    pc = o3d.io.read_point_cloud(str(ply))
    pts = np.asarray(pc.points)
    assert len(pts) == int((members["depth.exr"] > 0).sum())
    # world z of every lifted pixel is on the displaced surface: 0 down to the deepest crack
    max_depth = float(members["crackmap.exr"].max())
    assert pts[:, 2].max() < 1e-4 and pts[:, 2].min() > -max_depth - 1e-3
    half = meta["spec"]["surface"]["size_m"] / 2
    assert np.abs(pts[:, :2]).max() <= half + 1e-3
    cols = (np.asarray(pc.colors) * 255).round().astype(np.uint8)
    np.testing.assert_array_equal(cols, members["rgb.png"].reshape(-1, 3)[(members["depth.exr"] > 0).ravel()])
    import cv2

    img = cv2.imread(str(png))
    assert img is not None and (img < 250).any()


@pytest.mark.blender
def test_sparse_tof_cloud_and_bad_key(dataset, tmp_path):
    root, members, _ = dataset
    from crackgen.shards import load_sample

    s = load_sample(str(root), "000000-00000")
    pts, _ = sample_cloud(s, "tof")
    assert len(pts) == int((members["tof.exr"] > 0).sum())
    with pytest.raises(ShowError, match="no sample with key"):
        show(str(root), "000009-00009", pointcloud=str(tmp_path / "x.ply"))
    with pytest.raises(ShowError, match="no 'lidar' member"):
        sample_cloud(s, "lidar")
