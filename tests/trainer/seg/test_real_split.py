"""Grouped train / validation / test splits: no group straddles two sides, on hand-made and DeepCrack names."""
from pathlib import Path

import pytest

from trainer.core.errors import TrainerInputError
from trainer.seg.real_split import compile_group_pattern, group_of, read_split, split_groups

DEEPCRACK = Path(__file__).resolve().parents[4] / "shared" / "data" / "real" / "deepcrack_train" / "images"


def assert_groups_whole(split, pattern=None):
    side_of = {s: side for side in ("train", "val", "test") for s in split.side(side)}
    pat = compile_group_pattern(split.group_pattern if pattern is None else pattern)
    sides_per_group = {}
    for stem, side in side_of.items():
        sides_per_group.setdefault(group_of(stem, pat), set()).add(side)
    straddling = {g: s for g, s in sides_per_group.items() if len(s) > 1}
    assert not straddling, straddling
    assert all(len(s) == 1 for s in split.group_sides().values())


def test_hand_made_tiles_stay_together_and_sides_are_disjoint():
    stems = [f"p{g}-{k}" if k else f"p{g}" for g in range(30) for k in range(g % 5 + 1)]  # groups of 1..5 tiles
    split = split_groups(stems, val_fraction=0.2, test_fraction=0.2, seed=0)
    assert sorted(split.train + split.val + split.test) == sorted(stems)
    assert not (set(split.train) & set(split.val) or set(split.train) & set(split.test) or set(split.val) & set(split.test))
    assert_groups_whole(split)
    assert len(split.groups) == 30 and split.groups["p4"] == ["p4", "p4-1", "p4-2", "p4-3", "p4-4"]
    # deterministic, and independent of the order the names come in
    assert split_groups(stems[::-1], val_fraction=0.2, test_fraction=0.2, seed=0) == split
    assert split_groups(stems, val_fraction=0.2, test_fraction=0.2, seed=1).test != split.test
    # without groups, tiles of one photo do end up on different sides: the grouping is what prevents it
    flat = split_groups(stems, val_fraction=0.2, test_fraction=0.2, seed=0, group_pattern="none")
    with pytest.raises(AssertionError):
        assert_groups_whole(flat, pattern=r"^([^-]+)-")


def test_custom_pattern_and_bad_patterns():
    stems = ["wallA_01", "wallA_02", "wallB_01", "wallB_02", "wallC_01", "wallD_01"]
    split = split_groups(stems, val_fraction=0.25, test_fraction=0.25, seed=0, group_pattern=r"^(wall\w)_")
    assert_groups_whole(split)
    assert set(split.groups) == {"wallA", "wallB", "wallC", "wallD"}
    with pytest.raises(TrainerInputError, match="needs a capture group"):
        split_groups(stems, val_fraction=0.2, test_fraction=0.2, seed=0, group_pattern=r"wall")
    with pytest.raises(TrainerInputError, match="not a regular expression"):
        split_groups(stems, val_fraction=0.2, test_fraction=0.2, seed=0, group_pattern=r"(")
    with pytest.raises(TrainerInputError, match="leave nothing to train on"):
        split_groups(stems, val_fraction=0.5, test_fraction=0.5, seed=0)
    with pytest.raises(TrainerInputError, match="test split empty"):  # one group holds everything
        split_groups(["a", "a-1", "a-2"], val_fraction=0.0, test_fraction=0.2, seed=0)


@pytest.mark.skipif(not DEEPCRACK.is_dir(), reason="needs ../shared/data/real/deepcrack_train")
def test_deepcrack_groups_never_straddle_and_sides_match_the_fractions(tmp_path):
    stems = [p.stem for p in DEEPCRACK.iterdir()]
    for seed in range(3):
        split = split_groups(stems, val_fraction=0.2, test_fraction=0.2, seed=seed)
        assert_groups_whole(split)
        assert len(split.groups) == 101  # 44 multi-tile groups (243 photos) + 57 single photos
        for side in ("val", "test"):
            assert abs(len(split.side(side)) - 60) <= 6, (seed, side, len(split.side(side)))
        # the split a run folder records reads back identical
        assert read_split(split.write(tmp_path / str(seed))) == split
    # the old file-level split put tiles of 48 of its 60 test photos in training; the grouped one puts none
    split = split_groups(stems, val_fraction=0.2, test_fraction=0.2, seed=0)
    pat = compile_group_pattern(None)
    train_groups = {group_of(s, pat) for s in split.train}
    assert not [s for s in split.test + split.val if group_of(s, pat) in train_groups]
