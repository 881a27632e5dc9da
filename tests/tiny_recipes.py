"""Tiny recipe text for tests that render: small surface, 64x48-ish images, 1-2 spp."""
from __future__ import annotations


def tiny_recipe(
    seed: int,
    *,
    samples: int | None = None,
    shard_size: int | None = None,
    name: str | None = None,
    width: int = 64,
    height: int = 48,
    grid_px: int = 48,
    spp: int = 1,
    near_camera: bool = True,
    tof_px: tuple[int, int] = (32, 24),
    flying_pixels: bool = True,
    lidar: bool = True,
    stereo: bool = False,
) -> str:
    ds = [f"seed = {seed}"]
    if name:
        ds.insert(0, f'name = "{name}"')
    if samples is not None:
        ds.append(f"samples = {samples}")
    if shard_size is not None:
        ds.append(f"shard_size = {shard_size}")
    size = "size_m = { min = 1.6, max = 2.0 }\n" if near_camera else ""
    dist = "distance_m = { min = 0.7, max = 0.9 }\n" if near_camera else ""
    text = (
        "[dataset]\n" + "\n".join(ds) + "\n"
        f"[surface]\n{size}grid_px = {grid_px}\ncrackmap_px = 128\n"
        "[material]\ntexture_px = 64\n"
        f"[camera]\nwidth_px = {width}\nheight_px = {height}\n{dist}"
        f"[render]\nsamples = {spp}\ndenoise = false\nmax_bounces = 1\n"
        f"[tof]\nwidth_px = {tof_px[0]}\nheight_px = {tof_px[1]}\n"
        + ("" if flying_pixels else "flying_pixels = false\n")
    )
    text += "[lidar]\nbeams = 8\nazimuth_step_deg = 1.0\n" if lidar else "[lidar]\nenabled = false\n"
    if stereo:
        text += "[stereo]\nenabled = true\nnum_disparities = 16\n"
    return text
