"""Which samples are views of one scene: the unit a hold-out split must keep on one side.

With ``[camera] views_per_scene = K`` > 1 the samples ``i`` and ``j`` are views of one surface, crack and
material build when ``i // K == j // K`` (``crackgen.config.spec.scene_of``). Their images overlap, so a
train/validation split by sample would put siblings of one scene on both sides. The trainer reads the
grouping from the manifest, without importing the recipe code.
"""
from __future__ import annotations

import os
import tomllib
from typing import Any, Mapping

from crackgen.shards.manifest import Manifest, ManifestError


def views_per_scene(root: str | os.PathLike, storage_options: Mapping[str, Any] | None = None) -> int:
    """``[camera] views_per_scene`` of the recipe a dataset was made with (1 without a manifest or the key)."""
    if not Manifest.exists(root, storage_options):
        return 1
    m = Manifest.load(root, storage_options)
    camera = (m.recipe_canonical or {}).get("camera")
    if camera is None:  # manifests before 2026-12-03 hold only the recipe text (with any --set applied)
        try:
            camera = tomllib.loads(m.recipe_text).get("camera", {})
        except tomllib.TOMLDecodeError as exc:
            raise ManifestError(f"{m.path}: recipe_text is not valid TOML: {exc}") from None
    k = camera.get("views_per_scene", 1)
    if not isinstance(k, int) or k < 1:
        raise ManifestError(f"{m.path}: camera.views_per_scene must be a positive integer, got {k!r}")
    return k


def scene_group(key: str, views: int) -> str:
    """The hold-out group of sample ``key`` (``SHARD-INDEX``): the key itself with one view per scene, else
    ``scene-N`` for the scene it is a view of."""
    if views == 1:
        return key
    _, _, index = key.rpartition("-")
    if not index.isdigit():
        raise ValueError(f"sample key {key!r} does not end in a sample index")
    return f"scene-{int(index) // views:06d}"
