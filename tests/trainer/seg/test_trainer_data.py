"""Real-folder loading, depth conversion/alignment, joint augmentation, bad inputs."""
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from trainer.core.errors import TrainerInputError
from trainer.core.holdout import split_fraction
from trainer.core.imageio import read_float_map
from trainer.seg.augment import RGB_MEAN, RGB_STD, SampleConfig, sample_generator, sample_to_tensors
from trainer.seg.depth import align_to_rgb, disparity_to_depth, normalise_depth
from trainer.seg.sources import RealFolder
from trainer.seg.stream import SegStream, mix_repeat

REAL = Path(__file__).resolve().parents[3].parent / "shared" / "data" / "real"


@pytest.mark.skipif(not (REAL / "deepcrack_train").is_dir(), reason="shared real data absent")
def test_deepcrack_folder_shapes_and_binary_masks():
    folder = RealFolder(REAL / "deepcrack_train")
    assert len(folder) == 300
    stems = folder.keys[:3]
    sub = RealFolder(REAL / "deepcrack_train", stems=stems)
    for stem in stems:
        s = sub.load(stem)
        assert s["rgb"].shape == (384, 544, 3) and s["rgb"].dtype == np.uint8
        assert s["mask"].shape == (384, 544) and set(np.unique(s["mask"])) <= {0, 255}
        assert 0 < (s["mask"] > 0).mean() < 0.5
    ds = SegStream(SampleConfig(), real=sub, train=False)
    items = list(ds)
    assert [it["key"] for it in items] == stems
    assert items[0]["image"].shape == (3, 384, 544) and set(items[0]["mask"].unique().tolist()) <= {0.0, 1.0}


def test_split_folder_keeps_the_stem_order_of_the_same_stems_in_the_whole_folder(tmp_path):
    """'a.png' sorts after 'a-1.png' by file name but before it by stem: both ways of naming a
    training split must list (and so draw) its samples in one order."""

    from trainer.experiments.split import run_split

    src = tmp_path / "src"
    (src / "images").mkdir(parents=True)
    (src / "masks").mkdir()
    img, m = np.full((8, 8, 3), 128, np.uint8), np.zeros((8, 8), np.uint8)
    for stem in ("a", "a-1", "a-2", "b", "b-1", "c"):
        cv2.imwrite(str(src / "images" / f"{stem}.png"), img)
        cv2.imwrite(str(src / "masks" / f"{stem}.png"), m)
    split = run_split(str(src), str(tmp_path / "split"), val_fraction=0.0, test_fraction=0.34, seed=0,
                      group_pattern="none")
    whole = RealFolder(src, stems=split.train).keys
    assert RealFolder(tmp_path / "split" / "train").keys == whole == sorted(split.train)
    assert RealFolder(src).keys == ["a", "a-1", "a-2", "b", "b-1", "c"]


def test_disparity_to_depth_and_nearest_alignment_without_bleeding():
    f, B = 100.0, 0.1
    disp = np.linspace(2.0, 20.0, 20 * 30, dtype=np.float32).reshape(20, 30)
    disp[5:9, 10:16] = 0.0  # no data
    disp[0, 0] = np.inf
    z = disparity_to_depth(disp, f, B)
    ok = (disp > 0) & np.isfinite(disp)
    np.testing.assert_allclose(z[ok], f * B / disp[ok], rtol=1e-6)
    assert np.all(z[~ok] == -1)
    out = align_to_rgb(z, (40, 80))  # scale 2 -> 40x60, centred with 10 px of -1 each side
    assert out.shape == (40, 80)
    assert np.all(out[:, :10] == -1) and np.all(out[:, 70:] == -1)
    np.testing.assert_array_equal(out[:, 10:70], np.repeat(np.repeat(z, 2, 0), 2, 1))
    inner = out[:, 10:70]
    assert set(np.unique(inner[inner > 0])) <= set(np.unique(z[z > 0]))  # nothing interpolated
    d, v = normalise_depth(out, near_m=0.0, far_m=10.0)
    assert np.all(d[out == -1] == 0) and np.all(v[out == -1] == 0) and np.all(v[out > 0] == 1)
    np.testing.assert_allclose(d[out > 0], out[out > 0] / 10.0, rtol=1e-6)


def test_rgbd_folder_disparity_pipeline(tmp_path):
    (tmp_path / "images").mkdir()
    (tmp_path / "masks").mkdir()
    (tmp_path / "disp").mkdir()
    cv2.imwrite(str(tmp_path / "images/a.png"), np.full((40, 80, 3), 128, np.uint8))
    cv2.imwrite(str(tmp_path / "masks/a.png"), np.zeros((40, 80), np.uint8))
    disp = np.full((20, 30), 4.0, np.float32)
    disp[:, :5] = 0
    cv2.imwrite(str(tmp_path / "disp/a.tif"), disp)
    f = RealFolder(tmp_path, depth_dir="disp", depth_kind="disparity", focal_px=100, baseline_m=0.1)
    s = f.load("a")
    assert s["depth"].shape == (40, 80)
    assert set(np.unique(s["depth"])) == {-1.0, np.float32(100 * 0.1 / 4.0)}
    t = sample_to_tensors(s, SampleConfig(channels="rgbdv", near_m=0.0, far_m=5.0))
    assert t["image"].shape == (5, 40, 80)
    valid = t["image"][4]
    assert torch.all(t["image"][3][valid == 0] == 0)
    assert torch.allclose(t["image"][3][valid == 1], torch.tensor(2.5 / 5.0))
    assert int(valid.sum()) == 40 * 50  # 25 valid source columns -> 50 px, 40 rows



def test_exr_depth_map_is_read_with_its_values(tmp_path):
    import OpenEXR

    depth = np.linspace(0.3, 2.0, 6 * 8, dtype=np.float32).reshape(6, 8)
    depth[0, :3] = -1
    OpenEXR.File({"type": OpenEXR.scanlineimage}, {"Z": depth}).write(str(tmp_path / "d.exr"))
    assert np.array_equal(read_float_map(tmp_path / "d.exr"), depth)

def _marker_sample(h=64, w=64):
    rgb = np.full((h, w, 3), 40, np.uint8)
    depth = np.full((h, w), 3.0, np.float32)
    mask = np.zeros((h, w), np.uint8)
    rgb[10:24, 30:48] = 250
    depth[10:24, 30:48] = 1.0
    mask[10:24, 30:48] = 255
    depth[50:, :8] = -1  # a hole: must stay invalid, never bleed
    return {"key": "m", "rgb": rgb, "mask": mask, "depth": depth}


@pytest.mark.parametrize("seed", range(6))
def test_augmentation_keeps_rgb_depth_mask_aligned(seed):
    cfg = SampleConfig(channels="rgbdv", near_m=0.0, far_m=4.0, crop=40, rotate_deg=30, scale_min=0.8, scale_max=1.4)
    t = sample_to_tensors(_marker_sample(), cfg, sample_generator(7, 0, seed))
    x, m = t["image"], t["mask"][0]
    assert x.shape == (5, 40, 40) and m.shape == (40, 40)
    depth, valid = x[3], x[4]
    assert torch.all(depth[valid == 0] == 0)  # invalid (hole or rotation fill) -> 0
    vals_in, vals_out = depth[(m == 1)], depth[(m == 0) & (valid == 1)]
    if vals_in.numel():
        assert torch.unique(vals_in).numel() == 1  # one marker depth, exactly on the mask
        assert valid[m == 1].min() == 1
    if vals_out.numel():
        assert torch.unique(vals_out).numel() == 1
        if vals_in.numel():
            assert vals_in[0] < vals_out[0]  # near marker stays nearer after brightness/contrast
    rgb = (x[:3] * RGB_STD + RGB_MEAN).mean(0)
    k = torch.ones(1, 1, 3, 3)
    inner = torch.nn.functional.conv2d(m[None, None], k, padding=1)[0, 0] == 9
    outer = (torch.nn.functional.conv2d(m[None, None], k, padding=1)[0, 0] == 0) & (valid == 1)
    if inner.any() and outer.any():
        assert rgb[inner].min() > rgb[outer].max()  # bright marker only where the mask is


def test_augmentation_is_deterministic_per_sample_generator():
    cfg = SampleConfig(channels="rgbd", crop=32)
    a = sample_to_tensors(_marker_sample(), cfg, sample_generator(1, 2, 3))
    b = sample_to_tensors(_marker_sample(), cfg, sample_generator(1, 2, 3))
    c = sample_to_tensors(_marker_sample(), cfg, sample_generator(1, 2, 4))
    assert torch.equal(a["image"], b["image"]) and torch.equal(a["mask"], b["mask"])
    assert not torch.equal(a["image"], c["image"])


def _folder(tmp_path, n=4, bad_size=None):
    (tmp_path / "images").mkdir()
    (tmp_path / "masks").mkdir()
    for i in range(n):
        cv2.imwrite(str(tmp_path / f"images/{i:03d}.png"), np.full((32, 48, 3), 100, np.uint8))
        shape = (16, 16) if i == bad_size else (32, 48)
        cv2.imwrite(str(tmp_path / f"masks/{i:03d}.png"), np.zeros(shape, np.uint8))
    return tmp_path


def test_bad_inputs_name_the_file_or_are_skipped(tmp_path):
    root = _folder(tmp_path, n=4, bad_size=2)
    (root / "images/003.png").write_bytes(b"not an image")
    folder = RealFolder(root)
    with pytest.raises(TrainerInputError, match="002.png"):
        folder.load("002")
    with pytest.raises(TrainerInputError, match="003.png"):
        folder.load("003")
    with pytest.raises(TrainerInputError, match="002.png"):
        list(SegStream(SampleConfig(), real=folder, train=False))
    keys = [t["key"] for t in SegStream(SampleConfig(), real=folder, train=False, skip_bad=True)]
    assert keys == ["000", "001"]
    with pytest.raises(TrainerInputError, match="no 'images/'"):
        RealFolder(tmp_path / "nothing")


def test_split_and_mix_rules():
    names = [f"{i:05d}" for i in range(300)]
    train, test = split_fraction(names, 0.2, seed=3)
    assert len(test) == 60 and not set(train) & set(test) and sorted(train + test) == names
    assert split_fraction(list(reversed(names)), 0.2, seed=3) == (train, test)  # order-independent
    assert split_fraction(names, 0.2, seed=4)[1] != test
    assert mix_repeat(300, 10000) == 33 and 33 * 300 < 10000 <= 34 * 300
    assert mix_repeat(300, 900) == 2 and mix_repeat(300, 100) == 1


def test_grouped_split_holds_whole_groups_out_and_equals_the_plain_split_for_singletons():
    from trainer.core.holdout import split_fraction_by_group

    names = [f"{i:06d}-{i:05d}" for i in range(40)]
    assert split_fraction_by_group(names, lambda n: n, 0.25, seed=5) == split_fraction(names, 0.25, seed=5)
    train, val = split_fraction_by_group(names, lambda n: str(int(n[-5:]) // 4), 0.3, seed=5)
    assert sorted(train + val) == names and len(val) == 12  # 10 groups of 4: 3 held out
    assert not {int(n[-5:]) // 4 for n in train} & {int(n[-5:]) // 4 for n in val}


def test_shard_source_keeps_the_views_of_one_scene_on_one_side(tmp_path):
    """A recipe with views_per_scene = 4: the synthetic validation split holds out whole scenes, never
    single views whose siblings train (with one view per scene the split is the per-key one, as before)."""
    from crackgen.shards import Manifest, ShardWriter, sample_key
    from crackgen.tools.bench_shards import synthetic_sample
    from trainer.core.holdout import key_in_val
    from trainer.seg.sources import ShardSource

    rng = np.random.default_rng(0)
    infos = []
    for s in range(3):
        with ShardWriter(tmp_path, s) as w:
            for i in range(s * 6, s * 6 + 6):  # 6 per shard: scenes of 4 views straddle shards
                smp = synthetic_sample(rng, 32, 8)
                w.add(sample_key(s, i), {k: smp[k] for k in ("rgb.png", "mask.png", "depth.exr", "json")})
        infos.append(w.info)

    def sides(k):
        m = Manifest(tmp_path, recipe_text="", recipe_hash="h", recipe_canonical={"camera": {"views_per_scene": k}},
                     num_shards=3, shard_size=6)
        for info in infos:
            m.mark_done(info)
        m.save()
        train = ShardSource(tmp_path, depth="gt", val_fraction=0.4, split="train", seed=2)
        val = ShardSource(tmp_path, depth="gt", val_fraction=0.4, split="val", seed=2)
        return [x for ks in train.shard_keys for x in ks], [x for ks in val.shard_keys for x in ks]

    train, val = sides(4)
    assert len(train) + len(val) == 18 and val and train
    scenes = lambda keys: {int(k[-5:]) // 4 for k in keys}  # noqa: E731
    assert not scenes(train) & scenes(val)
    train1, val1 = sides(1)
    assert sorted(val1) == sorted(k for k in train1 + val1 if key_in_val(k, 0.4, 2))
