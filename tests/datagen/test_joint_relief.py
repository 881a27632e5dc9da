"""``[material] joint_relief_m``: brick and block walls get their mortar recess in the mesh the cameras, the
ray caster and every sensor share, so raking light casts the course-edge shadows of a real wall."""
from __future__ import annotations

import numpy as np
import pytest

from crackgen.config.recipe import parse_recipe
from crackgen.config.spec import make_spec
from crackgen.datagen.pipeline import SampleProducer, _Timer

WALL = """
[crack]
probability = 0.0
[surface]
size_m = { min = 0.6, max = 0.7 }
grid_px = 256
[material]
family = "masonry"
texture_px = 512
"""


def _build(text: str, index: int = 0):
    recipe = parse_recipe(text)
    spec = make_spec(recipe, index)
    return spec, SampleProducer(recipe)._scene_build(spec, 0, _Timer(index))


def test_the_scene_mesh_carries_the_joint_recess_and_the_crack_relief_stays_apart():
    spec, build = _build(WALL + "joint_relief_m = { min = 0.006, max = 0.009 }\n")
    depth = spec.material.joint_relief_m
    assert 0.006 <= depth <= 0.009
    dz = build.world[:, 2] - build.vertices[:, 2]
    assert dz.max() <= 1e-7 and dz.min() == pytest.approx(-depth, rel=0.02)
    recessed = dz < -0.5 * depth
    assert 0.05 < recessed.mean() < 0.35  # the joints of a running bond, not the brick faces
    assert np.abs(build.vertices[:, 2]).max() == 0.0  # no crack: the crack relief (for labels) has no joints
    # the ray caster sees what the renderer gets
    np.testing.assert_array_equal(build.caster.vertices, build.world)


def test_without_joint_relief_the_mesh_is_the_crack_relief():
    _, build = _build(WALL)
    assert build.maps.relief_m is None and build.world is build.vertices
