"""[surface] steps: straight height steps (kerbs, faulted slab edges) that give scenes depth edges.

What must hold: the far side of each step line is raised by exactly its height and
nothing else moves, steps add up, the crack relief is untouched, the ray-cast depth
across a step changes by the height, and a recipe without steps draws the same
patch as before (steps are drawn after the size, from the surface stream).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from crackgen.config.recipe import parse_recipe
from crackgen.config.spec import CrackSpec, SampleSpec, StepSpec, make_spec
from crackgen.procedural.crackmap import crack_map
from crackgen.procedural.surface import surface_faces, surface_uvs, surface_vertices, with_steps
from crackgen.sim.raycast import MeshRaycaster

SPEC = CrackSpec(
    freq_x=2.0, freq_y=2.5, octaves=4, persistence=0.5, lacunarity=2.0,
    threshold=0.05, depth_m=0.02, noise_seed=77, offset_u=3.3, offset_v=8.1,
)  # fmt: skip
SIZE_M = 1.5
G = 65


def test_the_far_side_is_raised_by_the_height_and_steps_add_up():
    v = surface_vertices(crack_map(SPEC, 96, SIZE_M, measure=False), G)
    one = StepSpec(angle_rad=0.0, offset_m=0.1, height_m=0.05)  # x > 0.1 raised
    two = StepSpec(angle_rad=math.pi / 2, offset_m=-0.2, height_m=0.03)  # y > -0.2 raised
    s = with_steps(v, [one, two])
    np.testing.assert_array_equal(s[:, :2], v[:, :2])
    h = SIZE_M / (G - 1)  # vertex spacing: the ramp between the levels is this wide, centred on the line
    ramp = lambda d: np.clip(d / h + 0.5, 0, 1)  # noqa: E731
    np.testing.assert_allclose(s[:, 2] - v[:, 2], 0.05 * ramp(v[:, 0] - 0.1) + 0.03 * ramp(v[:, 1] + 0.2), atol=1e-6)
    far = (v[:, 0] > 0.1 + h / 2) & (v[:, 1] > -0.2 + h / 2)
    near = (v[:, 0] < 0.1 - h / 2) & (v[:, 1] < -0.2 - h / 2)
    np.testing.assert_allclose(s[far, 2] - v[far, 2], 0.08, atol=1e-6)  # both steps, full height
    np.testing.assert_array_equal(s[near, 2], v[near, 2])  # untouched, crack grooves included
    assert v[:, 2].min() < 0 and np.array_equal(with_steps(v, []), v) and with_steps(v, [one]) is not v


def test_a_diagonal_step_is_a_straight_wall_not_a_staircase():
    flat = surface_vertices(crack_map(SPEC, 96, SIZE_M, measure=False), G) * np.float32([1, 1, 0])
    st = StepSpec(angle_rad=math.radians(30), offset_m=0.05, height_m=0.1)
    s = with_steps(flat, [st])
    n = np.array([math.cos(st.angle_rad), math.sin(st.angle_rad)])
    t = np.linspace(-0.4, 0.4, 41)  # points along the step line, then a little to either side of it
    line = st.offset_m * n[None] + t[:, None] * np.array([-n[1], n[0]])[None]
    caster = MeshRaycaster(s, np.asarray(surface_faces(G)), np.asarray(surface_uvs(G)))
    down = np.tile([0.0, 0.0, -1.0], (len(t), 1))
    for off, want, tol in ((0.0, 0.05, 0.015), (-2.0, 0.0, 1e-5), (2.0, 0.1, 1e-5)):  # offsets in vertex spacings
        p = line + off * SIZE_M / (G - 1) * n[None]
        z = 1.0 - caster.cast(np.c_[p, np.ones(len(t))], down).t
        # on the line: mid-height all along it (a per-vertex cut would give 0 or 0.1, a staircase); beyond
        # two spacings (a triangle spans up to 1.4): exactly the two levels
        np.testing.assert_allclose(z, want, atol=tol)


def test_ray_cast_depth_jumps_by_the_step_height():
    flat = np.zeros((G * G, 3), np.float32)
    t = np.linspace(-0.5, 0.5, G)
    flat[:, 0], flat[:, 1] = np.meshgrid(t, t)[0].ravel(), np.meshgrid(t, t)[1].ravel()
    stepped = with_steps(flat, [StepSpec(angle_rad=0.0, offset_m=0.0, height_m=0.08)])
    caster = MeshRaycaster(stepped, np.asarray(surface_faces(G)), np.asarray(surface_uvs(G)))
    xs = np.array([-0.3, -0.1, 0.1, 0.3])
    origins = np.stack([xs, np.zeros(4), np.full(4, 1.0)], 1)
    hits = caster.cast(origins, np.tile([0.0, 0.0, -1.0], (4, 1)))
    np.testing.assert_allclose(hits.t, [1.0, 1.0, 0.92, 0.92], atol=1e-6)


def test_steps_are_drawn_after_the_patch_size_and_survive_the_metadata():
    base = "[dataset]\nseed = 4\n[surface]\nsize_m = { min = 1.0, max = 2.0 }\n"
    flat = parse_recipe(base)
    stepped = parse_recipe(base + "steps = { choices = [1, 2] }\nstep_height_m = { min = 0.05, max = 0.1 }\n")
    for i in range(5):
        a, b = make_spec(flat, i), make_spec(stepped, i)
        assert a.surface.steps == [] and 1 <= len(b.surface.steps) <= 2
        assert a.surface.size_m == b.surface.size_m and a.crack == b.crack and a.camera == b.camera
        for st in b.surface.steps:
            assert 0.05 <= st.height_m <= 0.1 and 0 <= st.angle_rad < math.pi
            assert abs(st.offset_m) <= 0.2 * b.surface.size_m + 1e-12
        assert SampleSpec.from_dict(b.to_dict()) == b


def test_the_steps_total_rise_stays_below_the_camera():
    text = ("[dataset]\nseed = 2\n[surface]\nsteps = 4\nstep_height_m = { min = 0.2, max = 0.3 }\n"
            "[camera]\ndistance_m = { min = 0.5, max = 0.7 }\ntilt_deg = { min = 0, max = 40 }\n")
    capped = parse_recipe(text)
    looser = parse_recipe(text.replace("steps = 4\n", "steps = 4\nstep_max_rise = 0.8\n"))
    for i in range(10):
        spec = make_spec(capped, i)
        eye = spec.camera.distance_m * math.cos(spec.camera.tilt_rad)
        hs = np.array([st.height_m for st in spec.surface.steps])
        assert len(hs) == 4 and hs.sum() == pytest.approx(0.3 * eye)  # 4 x 0.2-0.3 m would reach 0.8-1.2 m
        wide = np.array([st.height_m for st in make_spec(looser, i).surface.steps])
        assert wide.sum() == pytest.approx(0.8 * eye)
        np.testing.assert_allclose(hs / wide, 0.3 / 0.8)  # the same draws, scaled together: proportions kept
    low = parse_recipe(text.replace("{ min = 0.2, max = 0.3 }", "0.01"))
    assert [st.height_m for st in make_spec(low, 0).surface.steps] == [0.01] * 4  # under the cap: untouched
