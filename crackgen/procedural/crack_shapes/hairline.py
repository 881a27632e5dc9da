"""``hairline`` family: thin fractures 1-2 camera pixels wide, half the recipe depth.

The paths come from the ``fracture`` generator; only the width and depth differ: the width is
``hairline_px`` camera pixels, where one pixel covers ``pixel_m`` metres of surface
(``crackgen.config.spec.pixel_footprint_m``). Where that is narrower than a crack-map texel,
the path renderer widens it to one texel (``paths.MIN_HALF_WIDTH_PX``) so the crack survives
the map's resolution instead of breaking into dots.
"""

from __future__ import annotations

from crackgen.config.spec import CrackSpec

__all__ = ["DEPTH_SCALE", "hairline_width_m"]

DEPTH_SCALE = 0.5  # hairline centre-line depth = DEPTH_SCALE * crack.depth_m (shallower than fractures)


def hairline_width_m(spec: CrackSpec, pixel_m: float) -> float:
    """Full hairline width (m) at its widest point: ``hairline_px`` camera pixels of ``pixel_m``."""
    return float(spec.hairline_px * pixel_m)
