"""Target photo folder: checked up front with one-line errors; stable selection."""
import cv2
import numpy as np
import pytest

from crackgen.postrender.targets import TargetError, TargetPhotos


def _write(folder, name, value):
    cv2.imwrite(str(folder / name), np.full((8, 8, 3), value, np.uint8))


def test_missing_empty_unreadable(tmp_path):
    with pytest.raises(TargetError, match="no such folder"):
        TargetPhotos(tmp_path / "nope")
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(TargetError, match="no photos"):
        TargetPhotos(tmp_path)
    _write(tmp_path, "a.png", 10)
    (tmp_path / "b.jpg").write_bytes(b"not a jpeg at all")
    with pytest.raises(TargetError, match="b.jpg: unreadable"):
        TargetPhotos(tmp_path)


def test_sorted_selection_and_load(tmp_path):
    for i, name in enumerate(["c.png", "a.png", "b.png"]):
        _write(tmp_path, name, 10 * (i + 1))
    t = TargetPhotos(tmp_path)
    assert [p.name for p in t.paths] == ["a.png", "b.png", "c.png"]
    assert [t.name_for(f) for f in (0.0, 0.34, 0.99)] == ["a.png", "b.png", "c.png"]
    assert t.load("c.png")[0, 0, 0] == 10
