"""`--backend ray` on a local 2-CPU Ray instance, writing to object storage (a local moto S3).

The content check needs no Blender in the test process: GT mask and depth depend only on
the geometry, so they are recomputed from each sample's spec (crack map -> mesh -> ray
cast) and must equal what the Ray workers wrote to S3.
"""
from __future__ import annotations

import socket

import numpy as np
import pytest
from tiny_recipes import tiny_recipe

pytestmark = [pytest.mark.blender, pytest.mark.slow]

RECIPE = tiny_recipe(21, samples=4, shard_size=2, lidar=False)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def s3():
    pytest.importorskip("s3fs")
    moto_server = pytest.importorskip("moto.server")
    port = _free_port()
    server = moto_server.ThreadedMotoServer(ip_address="127.0.0.1", port=port)
    server.start()
    opts = {"key": "testing", "secret": "testing",
            "client_kwargs": {"endpoint_url": f"http://127.0.0.1:{port}", "region_name": "us-east-1"}}
    import boto3

    boto3.client("s3", endpoint_url=f"http://127.0.0.1:{port}", region_name="us-east-1",
                 aws_access_key_id="testing", aws_secret_access_key="testing").create_bucket(Bucket="crackgen-test")
    yield opts
    server.stop()


def test_ray_backend_writes_to_s3(s3):
    pytest.importorskip("ray")
    from crackgen.config.recipe import parse_recipe
    from crackgen.config.spec import SampleSpec
    from crackgen.datagen.generate import GenerateOptions, generate
    from crackgen.procedural.crackmap import crack_map
    from crackgen.procedural.surface import surface_faces, surface_uvs, surface_vertices
    from crackgen.shards import iter_samples, verify_dataset
    from crackgen.shards.manifest import Manifest
    from crackgen.sim.groundtruth import view_ground_truth
    from crackgen.sim.raycast import MeshRaycaster
    from crackgen.sim.rig import make_rig

    url = "s3://crackgen-test/ds"
    recipe = parse_recipe(RECIPE)
    summary = generate(recipe, GenerateOptions(out=url, workers=2, backend="ray", storage_options=s3, progress=False))
    assert summary.ok, summary.lines()
    assert summary.samples == 4 and summary.shards == 2

    m = Manifest.load(url, s3)
    assert len(m.done()) == 2 and m.recipe_hash == recipe.hash
    assert verify_dataset(url, storage_options=s3) == []
    keys = []
    for s in iter_samples(url, storage_options=s3):
        keys.append(s["__key__"])
        spec = SampleSpec.from_dict(s["meta"]["spec"])
        cm = crack_map(spec.crack, size_px=spec.surface.crackmap_px, size_m=spec.surface.size_m)
        g = spec.surface.grid_px
        caster = MeshRaycaster(surface_vertices(cm, g), np.asarray(surface_faces(g)), np.asarray(surface_uvs(g)))
        gt = view_ground_truth(make_rig(spec).rgb, caster, cm.mask)
        np.testing.assert_array_equal(s["mask_thesis"], gt.mask)  # eq. 5.5 mask, ray cast again here
        assert ((s["mask"] > 0) <= (s["mask_thesis"] > 0)).all()  # the visible label lies inside it
        np.testing.assert_array_equal(s["depth"], gt.depth)
        assert s["rgb"].shape == (48, 64, 3) and "tof" in s
    assert keys == ["000000-00000", "000000-00001", "000001-00002", "000001-00003"]

    # resume against object storage: everything verified, nothing redone
    again = generate(recipe, GenerateOptions(out=url, workers=2, backend="ray", resume=True,
                                             storage_options=s3, progress=False))
    assert again.ok and again.shards == 0 and again.skipped_shards == 2


def test_ray_worker_replaced_after_each_shard(tmp_path):
    """--worker-max-shards reaches Ray as max_calls: on one CPU, two shards run in two worker processes."""
    pytest.importorskip("ray")
    from crackgen.config.recipe import parse_recipe
    from crackgen.datagen.generate import GenerateOptions, generate

    summary = generate(parse_recipe(RECIPE), GenerateOptions(out=str(tmp_path / "ds"), workers=1, backend="ray",
                                                             worker_max_shards=1, progress=False))
    assert summary.ok, summary.lines()
    assert summary.shards == 2 and summary.worker_processes == 2
