"""The Blender 4.5 / 5.0 differences the renderer isolates: multilayer EXR selection and a
render file without a Depth pass (bpy 5.0.1 as a module writes only Combined)."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import OpenEXR
import pytest

bpy = pytest.importorskip("bpy")

from crackgen.blender.render import RenderError, read_render_exr, set_multilayer_exr  # noqa: E402

pytestmark = pytest.mark.blender


def _settings(with_media_type: bool) -> SimpleNamespace:
    props = {"file_format": None, **({"media_type": None} if with_media_type else {})}
    return SimpleNamespace(bl_rna=SimpleNamespace(properties=props), file_format="PNG", media_type="IMAGE")


def test_multilayer_exr_by_file_format_on_45_and_media_type_on_50():
    old, new = _settings(False), _settings(True)
    set_multilayer_exr(old)
    set_multilayer_exr(new)
    assert old.file_format == "OPEN_EXR_MULTILAYER" and old.media_type == "IMAGE"  # 4.5: untouched
    assert new.media_type == "MULTI_LAYER_IMAGE" and new.file_format == "OPEN_EXR_MULTILAYER"


def test_this_blender_accepts_the_multilayer_setting():
    s = bpy.context.scene.render.image_settings
    set_multilayer_exr(s)
    assert s.file_format == "OPEN_EXR_MULTILAYER"


def _combined_only_exr(path, rgb: np.ndarray) -> None:
    channels = {f"ViewLayer.Combined.{c}": np.ascontiguousarray(rgb[..., i]) for i, c in enumerate("RGB")}
    channels["ViewLayer.Combined.A"] = np.ones(rgb.shape[:2], np.float32)
    with OpenEXR.File({"compression": OpenEXR.NO_COMPRESSION}, channels) as f:
        f.write(str(path))


def test_a_render_without_depth_pass_is_an_error_unless_depth_is_optional(tmp_path):
    rgb = np.random.default_rng(0).random((5, 7, 3), dtype=np.float32)
    path = tmp_path / "render.exr"
    _combined_only_exr(path, rgb)
    with pytest.raises(RenderError, match="Depth.Z"):
        read_render_exr(str(path), depth_optional=False)
    got_rgb, depth = read_render_exr(str(path), depth_optional=True)
    np.testing.assert_array_equal(got_rgb, rgb)
    assert depth.shape == (5, 7) and (depth == -1).all()
