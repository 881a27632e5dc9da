"""The post-render stages: apply a sample's drawn ``CameraEffectsSpec`` and ``AdaptSpec`` to its RGB views.

Why a separate module: the generator's pipeline and ``crackgen adapt`` (re-adapting
shards that are already rendered) run the very same step, so a dataset adapted later
matches one adapted while rendering. Only the RGB views change; the metadata records
the method, its parameters and the target photo's file name.
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from crackgen.config.spec import AdaptSpec, CameraEffectsSpec
from crackgen.postrender.adapt import adapt_views
from crackgen.postrender.camera_effects import apply_camera_effects, auto_exposure_gain, describe
from crackgen.postrender.targets import TargetPhotos
from crackgen.shards.members import RGB_MEMBERS


def adapt_members(spec: AdaptSpec, members: Mapping[str, Any],
                  targets: TargetPhotos | None) -> tuple[dict[str, Any], dict[str, Any]]:
    """(members with adapted RGB views, metadata). ``members`` maps ``rgb.png``-style names to arrays."""
    if not spec.enabled:
        return dict(members), {"applied": False}
    if targets is None:
        raise ValueError("adapt: the sample asks for adaptation but no target photo folder is loaded")
    names = [f"{m}.png" for m in RGB_MEMBERS if f"{m}.png" in members]  # left view first
    name = targets.name_for(spec.target_fraction)
    target = targets.load(name)
    views = adapt_views([np.asarray(members[n]) for n in names], target, spec.method, spec.band)
    out = dict(members)
    out.update(zip(names, views))
    meta = {"applied": True, "method": spec.method, "target": name, "target_folder": spec.target,
            "views": [n.split(".")[0] for n in names]}
    if spec.method == "fourier":
        meta["band"] = spec.band
    return out, meta


def camera_effects_members(spec: CameraEffectsSpec, members: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """(members with camera effects on every RGB view, metadata); every other member is passed through as is."""
    names = [f"{m}.png" for m in RGB_MEMBERS if f"{m}.png" in members]  # left view first
    meta = describe(spec)
    if not meta["applied"]:
        return dict(members), meta
    views = [np.asarray(members[n]) for n in names]
    if "auto_exposure" in spec.applied:  # the gain the metering chose (cheap: a 64-px bisection)
        meta["auto_exposure_ev"] = round(float(np.log2(auto_exposure_gain(views[0], spec.auto_exposure_luma))), 4)
    out = dict(members)
    out.update(zip(names, apply_camera_effects(views, spec)))
    meta["views"] = [n.split(".")[0] for n in names]
    return out, meta
