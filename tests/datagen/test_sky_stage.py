"""[lights] sky: off changes nothing; on, the sky's sun is the sun lamp's, and an overcast sky dims the sun."""
from __future__ import annotations

import numpy as np
import pytest
from tiny_recipes import tiny_recipe

from crackgen.config.recipe import parse_recipe
from crackgen.config.spec import make_spec
from crackgen.datagen.pipeline import SampleProducer
from crackgen.shards.codecs import encode_json

SUN = ("[lights]\ncount = 1\nkind = \"sun\"\nsun_irradiance_w_m2 = {sun}\nambient_strength = 0.3\n"
       "ambient_color_temp_k = 6500\nelevation_deg = 50\n{sky}")


def _make(text: str):
    prod = SampleProducer(parse_recipe(text), threads=1)
    try:
        return prod.make(0)
    finally:
        prod.close()


def _recipe(sun: float = 4.0, sky: str = "") -> str:
    return tiny_recipe(9, spp=4, lidar=False) + SUN.format(sun=sun, sky=sky)


def test_the_sky_sun_is_the_sun_lamp_and_draws_follow_the_recipe():
    r = parse_recipe(tiny_recipe(1) + "[lights]\nsky = 0.5\nsky_overcast = 0.5\nkind = {choices = [\"sun\", \"area\"]}\n")
    specs = [make_spec(r, i) for i in range(200)]
    on = [s for s in specs if s.sky.enabled]
    assert 70 < len(on) < 130 and all(2 <= s.sky.turbidity <= 8 for s in on)
    assert 20 < sum(s.sky.overcast > 0 for s in on) < len(on) - 20
    with_sun = [s for s in on if any(L.kind == "sun" for L in s.lights)]
    assert with_sun
    for s in with_sun:
        sun = next(L for L in s.lights if L.kind == "sun")
        assert (s.sky.sun_elevation_rad, s.sky.sun_azimuth_rad) == (sun.elevation_rad, sun.azimuth_rad)
    assert all("sky" not in s.to_dict() for s in specs if not s.sky.enabled)
    # the sky has its own stream: switching it on moves no other draw
    plain = parse_recipe(tiny_recipe(1) + "[lights]\nkind = {choices = [\"sun\", \"area\"]}\n")
    for i in range(20):
        a, b = make_spec(plain, i), make_spec(r, i)
        assert a.lights == b.lights and a.camera == b.camera and a.crack == b.crack


@pytest.mark.blender
@pytest.mark.slow
def test_sky_off_is_unchanged_clear_sky_renders_and_overcast_turns_the_sun_off():
    plain, off = _make(_recipe()), _make(_recipe(sky="sky = 0.0\n"))
    assert "sky" not in plain.meta["spec"] and encode_json(plain.meta) == encode_json(off.meta)
    assert np.array_equal(plain.members["rgb.png"], off.members["rgb.png"])

    clear = _make(_recipe(sky="sky = 1.0\nsky_overcast = 0.0\nsky_turbidity = 2.0\n"))
    assert clear.meta["spec"]["sky"]["enabled"] and clear.meta["spec"]["sky"]["overcast"] == 0.0
    assert np.array_equal(clear.members["mask.png"], plain.members["mask.png"])  # only the light changed
    rgb_plain, rgb_clear = (x.members["rgb.png"].astype(float) for x in (plain, clear))
    assert np.abs(rgb_clear - rgb_plain).mean() > 2.0
    # a clear sky is blue: relative to the uniform white-ish ambient, the picture turns bluer
    bluer = lambda x: x[..., 2].mean() / x[..., 0].mean()  # noqa: E731
    assert bluer(rgb_clear) > bluer(rgb_plain)

    # fully overcast: the world is the uniform cloud deck and the sun lamp is dimmed to nothing, so the
    # render matches the uniform world with the sun switched off (up to sampling noise), not the sunny one
    overcast = _make(_recipe(sky="sky = 1.0\nsky_overcast = 1.0\nsky_overcast_amount = 1.0\n"))
    no_sun = _make(_recipe(sun=0.0))
    d_dark = np.abs(overcast.members["rgb.png"].astype(float) - no_sun.members["rgb.png"]).mean()
    d_sunny = np.abs(overcast.members["rgb.png"].astype(float) - rgb_plain).mean()
    assert d_dark < 2.0 and d_sunny > 4 * d_dark, (d_dark, d_sunny)
