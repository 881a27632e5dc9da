"""Stair-step cracks run in the very mortar joints the wall's material paints; shapes drawn per surface."""
import dataclasses

import numpy as np
import pytest

from crackgen.config.recipe import RecipeError, parse_recipe
from crackgen.config.spec import MaterialSpec, make_spec
from crackgen.procedural.crackmap import crack_map
from crackgen.procedural.materials import brick_joints, load_family, material_maps

SIZE_M, PX = 1.2, 768  # 1.6 mm texels: a 10 mm joint is 6 texels wide
STAIR = parse_recipe('[crack]\nshape = "stairstep"\nwidth_m = 0.006\njaggedness = 0.1\ncount = 1\n'
                     '[material]\nfamily = "masonry"\n')


def _mortar(family: str, seed: int) -> tuple[np.ndarray, MaterialSpec]:
    """Bool (PX, PX): texels the material paints as mortar (recessed: the brick faces stand mortar_depth_m proud)."""
    spec = MaterialSpec(family=family, seed=seed, texture_px=PX, hue_shift=0.0, value_scale=1.0, roughness_offset=0.0,
                        crack_darkening=1.0, crack_roughness=0.9)
    flat = dataclasses.replace(make_spec(STAIR, 0).crack, present=False)
    maps = material_maps(spec, crack_map(flat, PX, SIZE_M, measure=False))
    depth = load_family(family).bricks.mortar_depth_m
    return maps.height_m < 0.5 * depth, spec


@pytest.mark.parametrize("family,seed", [("masonry", 3), ("masonry", 8), ("blockwork", 5)])
def test_brick_joints_are_where_the_material_paints_its_mortar(family, seed):
    mortar, spec = _mortar(family, seed)
    j = brick_joints(spec)
    y = (np.arange(PX) + 0.5) * SIZE_M / PX
    rows = [r for r in range(-2, 40) if 0.02 < j.bed_y(r) and j.bed_y(r) + j.pitch_y < SIZE_M - 0.02]
    on_bed = np.array([mortar[int(j.bed_y(r) / SIZE_M * PX)].mean() for r in rows])
    mid_course = np.array([mortar[int((j.bed_y(r) + 0.5 * j.pitch_y) / SIZE_M * PX)].mean() for r in rows])
    assert on_bed.min() > 0.8 and mid_course.max() < 0.35, (on_bed.min(), mid_course.max())
    assert y.size == PX and brick_joints(dataclasses.replace(spec, family="concrete")) is None


def test_a_stairstep_crack_lies_in_the_joints_and_climbs_several_courses():
    for i in range(4):
        s = make_spec(STAIR, i)
        spec = dataclasses.replace(s.material, texture_px=PX)
        mortar, _ = _mortar("masonry", spec.seed)
        j = brick_joints(spec)
        cm = crack_map(dataclasses.replace(s.crack, present=True), PX, SIZE_M, joints=j)
        skel = cm.skeleton
        assert skel.sum() > 100
        assert mortar[skel].mean() > 0.85, (i, mortar[skel].mean())  # the centre line is in the mortar (edge noise aside)
        rows, cols = np.nonzero(skel)
        assert np.ptp(rows) * SIZE_M / PX > 2 * j.pitch_y  # more than two courses high
        assert np.ptp(cols) * SIZE_M / PX > j.pitch_x  # and stepping sideways as it climbs
        # with no joints (a surface without bricks) the same spec is drawn as a fracture
        frac = crack_map(dataclasses.replace(s.crack, present=True, shape="fracture"), 256, SIZE_M)
        assert np.array_equal(crack_map(dataclasses.replace(s.crack, present=True), 256, SIZE_M).mask, frac.mask)


def test_shapes_per_family_change_only_the_shape_draw():
    base = '[material]\nfamily = { choices = ["masonry", "concrete"] }\n[crack]\nshape = "fracture"\n'
    per = base + '[crack.shape_by_family]\nmasonry = { choices = ["stairstep", "hairline"], weights = [3, 1] }\n'
    a, b = parse_recipe(base), parse_recipe(per)
    shapes = {"masonry": [], "concrete": []}
    for i in range(80):
        sa, sb = make_spec(a, i), make_spec(b, i)
        shapes[sb.material.family].append(sb.crack.shape)
        assert dataclasses.replace(sb.crack, shape=sa.crack.shape) == sa.crack and sa.material == sb.material
    assert set(shapes["concrete"]) == {"fracture"}
    assert set(shapes["masonry"]) == {"stairstep", "hairline"} and shapes["masonry"].count("stairstep") > 20
    with pytest.raises(RecipeError, match="crack.shape_by_family: unknown material family 'granite'"):
        parse_recipe('[crack.shape_by_family]\ngranite = "fracture"\n')
    with pytest.raises(RecipeError, match="unknown value 'zigzag'"):
        parse_recipe('[crack.shape_by_family]\nmasonry = "zigzag"\n')
