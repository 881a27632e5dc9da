"""Ring-scanning LiDAR (e.g. a 16-beam puck) simulated by ray casting.

Frame: ``Rig.T_lidar_world`` (world -> LiDAR) with the RGB camera's axes,
x right, y down, z forward; the azimuth sweep is centred on +z. A beam with
elevation e (angle above the x-z plane, i.e. towards -y, "up" in the image)
and azimuth a (towards +x, "right") has the direction

    (cos e * sin a, -sin e, cos e * cos a).

Elevations are ``beams`` values evenly spaced over [vfov_min, vfov_max];
azimuths run from -hfov/2 to +hfov/2 in ``azimuth_step`` steps. A return needs
a hit within ``max_range_m``, survives a random dropout with probability
1 - dropout, and gets Gaussian range noise along the beam.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crackgen.config.spec import LidarSpec
from crackgen.sim.raycast import MeshRaycaster
from crackgen.sim.rig import Rig
from crackgen.sim.sensors.tof import SensorError
from fusion.geometry.camera import invert_pose
from fusion.geometry.projection import project_points


@dataclass
class LidarResult:
    points_world: np.ndarray  # (K,3) measured points
    ring: np.ndarray  # (K,) int beam index, 0 = lowest elevation
    elevation_rad: np.ndarray  # (K,) beam elevation
    azimuth_rad: np.ndarray  # (K,) beam azimuth
    range_m: np.ndarray  # (K,) measured range
    n_rays: int  # rays cast (beams x azimuths), for return-rate statistics
    n_hits: int  # rays that hit the mesh within max range (before dropout)
    depth_rgb: np.ndarray  # (H,W) float32 sparse depth in the RGB view, -1 = none
    ring_rgb: np.ndarray  # (H,W) float32 ring index of the winning point, -1 = none


def beam_angles(spec: LidarSpec) -> tuple[np.ndarray, np.ndarray]:
    """Elevations (beams,) and azimuths (n_az,) of the scan pattern, radians."""
    if spec.beams == 1:
        elev = np.array([0.5 * (spec.vfov_min_rad + spec.vfov_max_rad)])
    else:
        elev = np.linspace(spec.vfov_min_rad, spec.vfov_max_rad, spec.beams)
    n_az = int(np.floor(spec.hfov_rad / spec.azimuth_step_rad + 1e-9)) + 1
    az = -0.5 * (n_az - 1) * spec.azimuth_step_rad + spec.azimuth_step_rad * np.arange(n_az)
    return elev, az


def beam_directions(elevation: np.ndarray, azimuth: np.ndarray) -> np.ndarray:
    """Unit directions (N,3) in the LiDAR frame for paired elevation/azimuth arrays."""
    ce = np.cos(elevation)
    return np.stack([ce * np.sin(azimuth), -np.sin(elevation), ce * np.cos(azimuth)], axis=1)


def simulate_lidar(spec: LidarSpec, rig: Rig, caster: MeshRaycaster, rng: np.random.Generator) -> LidarResult:
    """One full sweep, projected into the RGB view with the z-buffer."""
    if rig.T_lidar_world is None:
        raise SensorError("simulate_lidar: the rig has no LiDAR (lidar.enabled is false)")
    elev, az = beam_angles(spec)
    ring_grid, az_grid = np.meshgrid(np.arange(len(elev)), az, indexing="ij")
    ring = ring_grid.ravel()
    e, a = elev[ring], az_grid.ravel()
    T_world_lidar = invert_pose(rig.T_lidar_world)
    dirs = beam_directions(e, a) @ T_world_lidar[:3, :3].T
    origins = np.broadcast_to(T_world_lidar[:3, 3], dirs.shape).copy()
    hits = caster.cast(origins, dirs)
    n = len(ring)
    noise = rng.standard_normal(n)  # full-length draws: the stream never depends on the scene
    keep_draw = rng.random(n) >= spec.dropout
    rng_m = hits.t + spec.sigma_m * noise
    in_range = hits.hit & (hits.t <= spec.max_range_m)
    keep = in_range & keep_draw & (rng_m > 0)
    pts = origins[keep] + dirs[keep] * rng_m[keep, None]
    proj = project_points(rig.rgb, pts, {"ring": ring[keep].astype(np.float32)})
    return LidarResult(
        points_world=pts,
        ring=ring[keep],
        elevation_rad=e[keep],
        azimuth_rad=a[keep],
        range_m=rng_m[keep],
        n_rays=n,
        n_hits=int(in_range.sum()),
        depth_rgb=proj.depth,
        ring_rgb=proj.values["ring"],
    )
