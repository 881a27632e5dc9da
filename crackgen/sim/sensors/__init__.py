"""Ray-cast depth sensors on the sample's mesh (replaces BlenSor): ToF, LiDAR, stereo set.

All sensors take the one ``MeshRaycaster`` the pipeline builds per sample, so the
BVH is built once and every sensor sees exactly the geometry the renderer draws.
Random draws come only from the Generator passed in (seed it with ``sensor_rng``).
"""
from __future__ import annotations

import numpy as np


def sensor_rng(seed: int) -> np.random.Generator:
    """The Generator for one sensor of one sample, from the seed stored in its spec."""
    return np.random.default_rng(int(seed))
