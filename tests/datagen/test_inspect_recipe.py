"""recipes/inspect.toml validates, every part of it is drawn, and it renders at a tiny size (CI-sized)."""
from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from crackgen.config.recipe import load_recipe
from crackgen.config.recipe_overrides import apply_sets
from crackgen.config.spec import make_spec, pixel_footprint_m
from crackgen.datagen.pipeline import SampleProducer

RECIPE = Path(__file__).resolve().parents[2] / "recipes" / "inspect.toml"


def test_inspect_recipe_draws_every_surface_distance_lens_and_sky():
    r = load_recipe(RECIPE)
    specs = [make_spec(r, i) for i in range(400)]
    families = Counter(s.material.family for s in specs)
    assert len(families) == 5 and min(families.values()) >= 0.1 * len(specs), families
    assert {s.crack.shape for s in specs if s.material.family == "masonry"} >= {"stairstep", "hairline"}
    assert "stairstep" not in {s.crack.shape for s in specs if s.material.family in ("asphalt", "concrete", "steel")}
    dist = [s.camera.distance_m for s in specs]
    assert min(dist) <= 0.3 and max(dist) >= 3.0
    px = [pixel_footprint_m(s.camera) for s in specs]  # mm per pixel spans an order of magnitude
    assert max(px) / min(px) > 10
    assert 0.2 < np.mean([s.lens.enabled for s in specs]) < 0.5 and 0.25 < np.mean([s.sky.enabled for s in specs]) < 0.55
    darkening = [s.material.crack_darkening for s in specs]
    assert 0.08 < np.mean(np.array(darkening) > 0.8) < 0.3  # faint cracks: a thin tail (v4), present but not common


@pytest.mark.blender
@pytest.mark.slow
def test_inspect_recipe_renders_at_a_tiny_size():
    r = apply_sets(load_recipe(RECIPE), ["camera.width_px=64", "camera.height_px=64", "render.samples=2",
                                          "render.denoise=false", "surface.grid_px=96", "surface.crackmap_px=256",
                                          "material.texture_px=128", "camera.principal_jitter_px=0"])
    prod = SampleProducer(r, threads=1)
    try:
        seen = set()
        for i in range(40):  # until a masonry sample and a lens and a sky have rendered
            s = make_spec(r, i)
            key = (s.material.family == "masonry", s.lens.enabled, s.sky.enabled)
            if key in seen:
                continue
            seen.add(key)
            out = prod.make(i)
            assert out.members["rgb.png"].shape == (64, 64, 3) and out.members["mask.png"].shape == (64, 64)
            assert set(np.unique(out.members["mask.png"])) <= {0, 255}
            if len(seen) >= 4:
                break
    finally:
        prod.close()
    assert any(k[1] for k in seen) and any(k[2] for k in seen) and any(k[0] for k in seen)
