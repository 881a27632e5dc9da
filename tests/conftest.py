"""Shared pytest fixtures. Keep each fixture self-contained (several authors append here)."""
import pytest


@pytest.fixture
def blender_reset():
    """An empty Blender (factory settings) before and after the test; skips without bpy.

    bpy is imported here, lazily, so test modules that never ask for this fixture
    (trainer, fusion) run on machines without bpy.
    """
    bpy = pytest.importorskip("bpy")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    yield bpy
    bpy.ops.wm.read_factory_settings(use_empty=True)
