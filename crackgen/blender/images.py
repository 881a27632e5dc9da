"""ImageSlot: the float image behind one image-texture node, refreshed per sample.

Why two images: with ``render.use_persistent_data`` Cycles keeps an image's previously
uploaded pixels after ``image.pixels.foreach_set`` (``update()``, ``update_tag()`` and
``pack()`` do not help; ``reload()`` blanks a generated image). Pointing the node at a
different image datablock does make Cycles upload it, so with ``swap=True`` the slot writes
each sample into the image the node does *not* show and then points the node at it. Two
fixed datablocks, not one per sample, keep ``bpy.data`` counts flat. Without persistent data
one image is enough (and renders exactly as before).

Why every image is written once when the slot is made: Blender allocates an image's pixel
buffer on its first ``foreach_set`` (16 MB for a 1024 px RGBA float map), so with ``swap`` the
second image's buffers appeared at the second sample (+48 MB for albedo, roughness and normal),
which read as worker memory growth after the warm-up sample. Filled at build, they are part
of the scene's fixed cost.
"""
from __future__ import annotations

import bpy
import numpy as np


class ImageSlot:
    """One (or, with ``swap``, two alternating) float RGBA images of ``px`` x ``px`` for ``node``."""

    def __init__(self, name: str, px: int, colorspace: str, swap: bool = False):
        self.px = int(px)
        self.images = [self._new(f"{name}{'_a' if swap else ''}", colorspace)]
        if swap:
            self.images.append(self._new(f"{name}_b", colorspace))
        self.nodes: list[bpy.types.Node] = []
        self._current = 0

    def _new(self, name: str, colorspace: str) -> bpy.types.Image:
        img = bpy.data.images.new(name, self.px, self.px, alpha=False, float_buffer=True)
        img.colorspace_settings.name = colorspace
        img.pixels.foreach_set(np.zeros(self.px * self.px * 4, dtype=np.float32))  # allocate its buffers now
        return img

    @property
    def image(self) -> bpy.types.Image:
        """The image the nodes show now."""
        return self.images[self._current]

    def attach(self, node: bpy.types.Node) -> None:
        node.image = self.image
        self.nodes.append(node)

    def write(self, rgba: np.ndarray) -> None:
        """Write flat float32 RGBA pixels (bottom row first) and make the nodes show them."""
        nxt = (self._current + 1) % len(self.images)
        img = self.images[nxt]
        img.pixels.foreach_set(rgba)
        img.update()
        img.update_tag()
        if nxt != self._current:
            self._current = nxt
            for node in self.nodes:
                node.image = img
