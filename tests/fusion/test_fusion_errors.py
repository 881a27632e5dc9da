"""Every error the fusion package raises on purpose shares one base, and both CLIs turn it into one line."""
import importlib
import inspect
import pkgutil

import numpy as np
import pytest

import fusion
from fusion.errors import FusionError


def _fusion_modules():
    for info in pkgutil.walk_packages(fusion.__path__, "fusion."):
        yield importlib.import_module(info.name)


def test_every_fusion_error_class_derives_from_the_base():
    found = {name: cls for m in _fusion_modules() for name, cls in inspect.getmembers(m, inspect.isclass)
             if name.endswith("Error") and cls.__module__.startswith("fusion.")}
    assert len(found) >= 14, sorted(found)  # one per module that validates its input
    assert all(issubclass(cls, FusionError) and issubclass(cls, ValueError) for cls in found.values()), \
        [n for n, c in found.items() if not issubclass(c, FusionError)]


def test_cracktrain_reports_a_fusion_error_in_one_line(tmp_path, capsys):
    from trainer.cli import main

    a, b = tmp_path / "a.png", tmp_path / "b.png"
    import cv2

    cv2.imwrite(str(a), np.zeros((8, 8), np.uint8))
    cv2.imwrite(str(b), np.zeros((9, 8), np.uint8))
    assert main(["merge-stack", str(a), str(b), "--out", str(tmp_path / "f.png")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "sizes must match" in err[0]


def test_image_fusion_error_is_a_fusion_error():
    from fusion.image.fuse import ImageFusionError, fuse_images

    with pytest.raises(FusionError):
        fuse_images([np.zeros((4, 4))], 2)
    assert issubclass(ImageFusionError, FusionError)
