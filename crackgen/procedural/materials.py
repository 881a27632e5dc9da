"""Procedural PBR texture maps (albedo, roughness, normal) for a cracked surface patch.

Why families are data: a material family (asphalt, concrete, masonry, steel, ...) is a
TOML file in ``blender_assets/materials/`` listing its base colour, noise layers,
speckles (aggregate stones, pores), an optional brick pattern and an optional paint
coat. Adding or tuning a family needs no code. All randomness comes from
``MaterialSpec.seed`` (and each distractor's own seed) through explicit Generators.

Maps share the crack map's index convention: ``array[j, i]``, i along u = world +x,
j along v = world +y, row 0 at v = 0 (as Blender stores images), over the same
``size_m`` square. Mortar joints, saw-cut joints, sealant, stains and markings change
the texture only (brick and block joints go into the mesh instead when ``joint_relief_m`` > 0:
``MaterialMaps.relief_m``); the GT crack mask comes from the crack map alone.
"""
from __future__ import annotations

import math
import os
import re
import sys
import tomllib
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Annotated, Literal, Protocol

import cv2
import numpy as np
from numba import njit, prange
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from crackgen.config.spec import MaterialSpec
from crackgen.errors import CrackgenError
from crackgen.procedural.clutter import CLUTTER, paint_clutter
from crackgen.procedural.crack_shapes.stairstep import JointGrid
from crackgen.procedural.distractors import DISTRACTORS, paint_distractor
from crackgen.procedural.photo import PhotoError, PhotoLook, photo_folder, photo_maps
from crackgen.procedural.texgrid import TexGrid, clip01, quantile_fast, smoothstep

ASSETS_ENV = "CRACKGEN_ASSETS"


class MaterialError(CrackgenError, ValueError):
    """A material family file or material spec that cannot be used (one line, names file/field)."""


# ----------------------------------------------------------------------------- family schema

Unit = Annotated[float, Field(ge=0.0, le=1.0)]
RGB = tuple[Unit, Unit, Unit]  # linear RGB in [0, 1]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _ordered(pair: tuple[float, float], name: str) -> None:
    if pair[0] > pair[1]:
        raise ValueError(f"{name}: min must be <= max")


class NoiseLayer(_Model):
    """fBm that modulates one channel. Amplitude: albedo = relative std of brightness
    (or blend weight towards ``color``), roughness = absolute std, height = metres std."""

    target: Literal["albedo", "roughness", "height"]
    scale_m: float = Field(gt=0, le=100, description="base feature size (m)")
    amplitude: float = Field(ge=0, le=1, description="see class doc")
    octaves: int = Field(4, ge=1, le=10)
    persistence: float = Field(0.5, gt=0, le=1)
    lacunarity: float = Field(2.0, gt=1, le=4)
    stretch: tuple[Annotated[float, Field(gt=0, le=100)], Annotated[float, Field(gt=0, le=100)]] = (1.0, 1.0)
    color: RGB | None = Field(None, description="albedo only: blend towards this colour where the noise is high")

    @model_validator(mode="after")
    def _color_only_albedo(self) -> "NoiseLayer":
        if self.color is not None and self.target != "albedo":
            raise ValueError("color: only allowed when target = 'albedo'")
        return self


class Speckles(_Model):
    """Randomly placed elliptical grains (aggregate stones, sand, pores) on a jittered grid."""

    coverage: float = Field(gt=0, le=1, description="fraction of the area covered (approx.)")
    size_m: tuple[Annotated[float, Field(gt=0, le=1)], Annotated[float, Field(gt=0, le=1)]] = Field(
        description="grain diameter range (m)"
    )
    colors: list[RGB] = Field(min_length=1)
    color_jitter: float = Field(0.1, ge=0, le=1, description="relative brightness std per grain")
    height_m: float = Field(0.0, ge=-0.05, le=0.05, description="dome height (m); negative = pits")
    roughness: Unit | None = None
    aspect: float = Field(1.5, ge=1, le=5, description="max elongation of a grain")
    edge: float = Field(0.3, ge=0.01, le=1, description="soft edge, fraction of the radius")

    @model_validator(mode="after")
    def _order(self) -> "Speckles":
        _ordered(self.size_m, "size_m")
        return self


class Bricks(_Model):
    """Brick / block bond. Mortar joints are texture (recessed, own colour), never cracks."""

    size_m: tuple[Annotated[float, Field(gt=0, le=10)], Annotated[float, Field(gt=0, le=10)]] = Field(
        description="brick length (along u) and height (along v), m"
    )
    mortar_m: float = Field(gt=0, le=0.2, description="mortar joint width (m)")
    mortar_color: RGB
    mortar_roughness: Unit = 0.95
    mortar_depth_m: float = Field(0.004, ge=0, le=0.1, description="brick face above the mortar (m)")
    colors: list[RGB] = Field(min_length=1)
    color_jitter: float = Field(0.15, ge=0, le=1, description="relative brightness std per brick")
    bond_offset: float = Field(0.5, ge=0, le=1, description="row-to-row shift, fraction of the brick pitch")
    bevel_m: float = Field(0.003, ge=0, le=0.1, description="rounded brick edge width (m)")
    edge_noise_m: float = Field(0.0015, ge=0, le=0.05, description="irregularity of brick edges (m)")


class Paint(_Model):
    """A paint coat with chips that show rust / bare metal underneath."""

    colors: list[RGB] = Field(min_length=1)
    color_jitter: float = Field(0.1, ge=0, le=1)
    roughness: Unit = 0.4
    thickness_m: float = Field(0.0003, ge=0, le=0.01, description="paint step height at chip edges (m)")
    chip_coverage: tuple[Unit, Unit] = Field((0.05, 0.3), description="fraction of area chipped, drawn per sample")
    chip_scale_m: float = Field(0.1, gt=0, le=10)
    chip_octaves: int = Field(5, ge=1, le=10)
    rust_colors: list[RGB] = Field(min_length=1)
    rust_roughness: Unit = 0.9
    rust_fraction: Unit = Field(0.6, description="share of chipped area that is rust (rest bare base)")
    rust_halo: float = Field(0.4, ge=0, le=5, description="rust stain width around chips (noise std units)")

    @model_validator(mode="after")
    def _order(self) -> "Paint":
        _ordered(self.chip_coverage, "chip_coverage")
        return self


class PhotoParams(_Model):
    """How the ``photo`` family turns a user's photo into maps (``[photo]`` in ``photo.toml``)."""

    albedo_mean: tuple[Unit, Unit] = Field((0.15, 0.35), description="linear mean albedo range, drawn per sample")
    roughness: Unit = Field(0.75, description="roughness at average local contrast")
    roughness_contrast: float = Field(0.15, ge=0, le=1, description="roughness change per std of local contrast")
    contrast_m: float = Field(0.004, gt=0, le=1, description="local contrast window (m)")
    height_m: float = Field(0.0004, ge=0, le=0.05, description="height std from the luminance high-pass (m)")
    highpass_m: float = Field(0.006, gt=0, le=1, description="height high-pass scale (m)")

    @model_validator(mode="after")
    def _order(self) -> "PhotoParams":
        _ordered(self.albedo_mean, "albedo_mean")
        return self


class Family(_Model):
    """One material family, as read from ``blender_assets/materials/<name>.toml``."""

    name: str
    description: str = ""
    base_color: RGB
    color_variation: float = Field(0.1, ge=0, le=1, description="per-sample colour jitter (relative)")
    roughness: Unit
    layers: list[NoiseLayer] = Field(default_factory=list)
    speckles: list[Speckles] = Field(default_factory=list)
    bricks: Bricks | None = None
    paint: Paint | None = None
    photo: PhotoParams | None = None


def assets_dir() -> Path:
    """``$CRACKGEN_ASSETS``, the repo's ``blender_assets/`` next to the package (source or
    editable install), or ``<prefix>/share/crackgen/blender_assets`` (wheel install)."""
    env = os.environ.get(ASSETS_ENV)
    if env:
        return Path(env)
    repo = Path(__file__).resolve().parents[2] / "blender_assets"
    if repo.is_dir():
        return repo
    return Path(sys.prefix) / "share" / "crackgen" / "blender_assets"


def list_families() -> list[str]:
    return sorted(p.stem for p in (assets_dir() / "materials").glob("*.toml"))


def load_family(name: str) -> Family:
    """Parse and validate ``<assets>/materials/<name>.toml``; MaterialError names file and field."""
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9_\-]+", name):
        raise MaterialError(f"material family name {name!r} is not a plain name")
    path = assets_dir() / "materials" / f"{name}.toml"
    if not path.is_file():
        known = ", ".join(list_families()) or "none"
        raise MaterialError(f"{path}: unknown material family {name!r} (available: {known})")
    return _load_family_file(str(path), path.stat().st_mtime_ns)


@lru_cache(maxsize=32)
def _load_family_file(path: str, _mtime_ns: int) -> Family:
    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise MaterialError(f"{path}: not valid TOML: {exc}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise MaterialError(f"{path}: cannot read family file: {exc}") from None
    data.setdefault("name", Path(path).stem)
    try:
        return Family.model_validate(data)
    except ValidationError as exc:
        raise MaterialError(f"{path}: {_format_error(exc)}") from None


def _format_error(exc: ValidationError) -> str:
    parts = []
    for e in exc.errors():
        loc = ".".join(str(p) for p in e["loc"])
        msg = "unknown key" if e["type"] == "extra_forbidden" else e["msg"].removeprefix("Value error, ")
        parts.append(f"{loc}: {msg}" if loc else msg)
    return "; ".join(parts)


# ----------------------------------------------------------------------------- maps


class CrackMapLike(Protocol):
    mask: np.ndarray  # bool (N, N)
    depth_m: np.ndarray  # float32 (N, N), crack depth in metres (>= 0)
    size_m: float


@dataclass
class MaterialMaps:
    """Texture maps of one sample, ``[j, i]`` indexed like the crack map, T = texture_px."""

    albedo: np.ndarray  # (T,T,3) float32 linear RGB in [0, 1]
    roughness: np.ndarray  # (T,T) float32 in [0, 1]
    normal: np.ndarray  # (T,T,3) float32 tangent-space normal encoded (n + 1) / 2, +Y = +v (OpenGL)
    height_m: np.ndarray  # (T,T) float32 micro height (m) the normal map is derived from, plus crack depth the mesh lacks
    distractor_mask: np.ndarray  # (T,T) bool where distractors were painted (GT mask stays empty there)
    crack_mask: np.ndarray  # (T,T) bool crack map mask resampled (nearest) to T
    clutter_mask: np.ndarray | None = None  # (T,T) bool where clutter was painted (never labelled)
    relief_m: np.ndarray | None = None  # (T,T) float32 joint relief (m, <= 0 in the mortar) for the mesh, or None
    photo: str = ""  # family "photo": the photo's file name

    @property
    def px(self) -> int:
        return self.albedo.shape[0]


def _rng(seed: int, stream: int) -> np.random.Generator:
    """Independent Generator per purpose, derived only from the spec's seed."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), int(stream)]))


def _seed(rng: np.random.Generator) -> int:
    return int(rng.integers(0, 2**31 - 1))


def resample_crack(cm: CrackMapLike, px: int) -> tuple[np.ndarray, np.ndarray]:
    """Crack mask (nearest, texel-centre aligned) and depth (bilinear) at ``px`` x ``px``."""
    mask = np.asarray(cm.mask, dtype=bool)
    depth = np.asarray(cm.depth_m, dtype=np.float32)
    if mask.ndim != 2 or depth.shape != mask.shape:
        raise MaterialError(f"crack map: mask {mask.shape} and depth_m {depth.shape} must be equal 2-D shapes")
    nv, nu = mask.shape
    if (nv, nu) == (px, px):
        return mask.copy(), depth.copy()
    iu = np.minimum(((np.arange(px) + 0.5) * nu / px).astype(np.int64), nu - 1)
    iv = np.minimum(((np.arange(px) + 0.5) * nv / px).astype(np.int64), nv - 1)
    return mask[np.ix_(iv, iu)], cv2.resize(depth, (px, px), interpolation=cv2.INTER_LINEAR)


def normal_from_height(height_m: np.ndarray, texel_m: float) -> np.ndarray:
    """Tangent-space normal map encoded in [0, 1] (OpenGL: +X = +u, +Y = +v), from height in metres."""
    dh_dv, dh_du = np.gradient(height_m.astype(np.float32), texel_m)
    inv = 1.0 / np.sqrt(dh_du * dh_du + dh_dv * dh_dv + 1.0)
    n = np.empty(height_m.shape + (3,), np.float32)
    n[..., 0] = -dh_du * inv
    n[..., 1] = -dh_dv * inv
    n[..., 2] = inv
    return n * 0.5 + 0.5


def material_maps(spec: MaterialSpec, cm: CrackMapLike, mesh_depth_m: np.ndarray | None = None) -> MaterialMaps:
    """Albedo, roughness, normal and height maps for ``spec`` over the crack map's patch.

    ``mesh_depth_m`` (T, T): the crack depth the displaced mesh already holds at each texel
    (``surface.mesh_depth_map``). Given, the height (and so the normal map) carries only the
    rest, crack depth - mesh depth, so the crack slope is shaded once; None = all of it."""
    fam = load_family(spec.family)
    for k, d in enumerate(spec.distractors):
        if d.kind not in DISTRACTORS:
            known = ", ".join(DISTRACTORS)
            raise MaterialError(f"material.distractors[{k}].kind: unknown kind {d.kind!r} (known: {known})")
    for k, c in enumerate(spec.clutter):
        if c.kind not in CLUTTER:
            raise MaterialError(f"material.clutter[{k}].kind: unknown kind {c.kind!r} (known: {', '.join(CLUTTER)})")
    px = int(spec.texture_px)
    if px < 4:
        raise MaterialError(f"material.texture_px: must be >= 4, got {px}")
    if not (float(cm.size_m) > 0):
        raise MaterialError(f"crack map: size_m must be > 0, got {cm.size_m}")
    grid = TexGrid(px, float(cm.size_m))
    rng = _rng(spec.seed, 0)

    # Per-sample base colour: family variation, then the spec's hue / value draws.
    base = np.asarray(fam.base_color, np.float64)
    # (brick_joints repeats these two draws: keep them first, and keep their order)
    base = base * math.exp(fam.color_variation * rng.normal()) * (1.0 + 0.3 * fam.color_variation * rng.normal(size=3))
    albedo = np.empty((px, px, 3), np.float32)
    albedo[:] = base.astype(np.float32)
    roughness = np.full((px, px), fam.roughness, np.float32)
    height = np.zeros((px, px), np.float32)

    photo = ""
    if spec.family == "photo":
        photo = _photo(spec, fam, grid, albedo, roughness, height)
    relief = None
    if fam.bricks is not None:
        if spec.joint_relief_m > 0:  # the recess goes into the mesh (``surface.with_relief``), not the normal map
            relief = np.zeros((px, px), np.float32)
            _bricks(fam.bricks, grid, rng, albedo, roughness, relief, depth_m=spec.joint_relief_m)
            relief -= np.float32(spec.joint_relief_m)  # brick faces at z = 0, mortar joints below
        else:
            _bricks(fam.bricks, grid, rng, albedo, roughness, height)
    for sp in fam.speckles:
        _speckles(sp, grid, rng, albedo, roughness, height)
    if fam.paint is not None:
        _paint(fam.paint, grid, rng, albedo, roughness, height)
    for layer in fam.layers:
        _layer(layer, grid, rng, albedo, roughness, height)

    # hue_shift: warm (+) / cool (-) tint as a fraction of the colour; value_scale: brightness.
    tint = np.asarray([1.0 + spec.hue_shift, 1.0, 1.0 - spec.hue_shift], np.float32)
    albedo *= tint * np.float32(spec.value_scale)
    roughness += np.float32(spec.roughness_offset)

    distractor_mask = np.zeros((px, px), bool)
    for d in spec.distractors:
        distractor_mask |= paint_distractor(d.kind, d.seed, grid, albedo, roughness, height)
    clutter_mask = np.zeros((px, px), bool)
    for c in spec.clutter:
        clutter_mask |= paint_clutter(c.kind, c.seed, c.amount, grid, albedo, roughness, height)

    crack_mask, crack_depth = resample_crack(cm, px)
    idx = np.nonzero(crack_mask)
    crng = _rng(spec.seed, 1)
    dark = spec.crack_darkening * crng.uniform(0.8, 1.2, size=idx[0].size).astype(np.float32)
    albedo[idx] *= dark[:, None]
    roughness[idx] = spec.crack_roughness
    crack_interior(spec, grid, crack_mask, crack_depth, albedo, roughness, height)
    if mesh_depth_m is not None and np.shape(mesh_depth_m) != crack_depth.shape:
        raise MaterialError(f"mesh_depth_m must have shape {crack_depth.shape}, got {np.shape(mesh_depth_m)}")
    height -= crack_depth if mesh_depth_m is None else crack_depth - np.asarray(mesh_depth_m, np.float32)

    clip01(albedo)
    clip01(roughness)
    return MaterialMaps(
        albedo=albedo,
        roughness=roughness,
        normal=normal_from_height(height, grid.texel_m),
        height_m=height,
        distractor_mask=distractor_mask,
        crack_mask=crack_mask,
        clutter_mask=clutter_mask,
        photo=photo,
        relief_m=relief,
    )


# ----------------------------------------------------------------------------- photo family and crack interiors


def _photo(spec: MaterialSpec, fam: Family, grid: TexGrid, albedo, roughness, height) -> str:
    """Replace the base maps with the drawn photo's; returns its file name."""
    if not spec.photo_folder:
        raise MaterialError("material.photo_folder: required for family 'photo'")
    try:
        folder = photo_folder(spec.photo_folder)
        name = folder.name_for(spec.photo_fraction)
        rgb = folder.load(name)
    except (PhotoError, CrackgenError) as exc:
        raise MaterialError(str(exc)) from None
    look = PhotoLook(**fam.photo.model_dump()) if fam.photo is not None else PhotoLook()
    size = spec.photo_size_m if spec.photo_size_m > 0 else 0.5
    a, r, h = photo_maps(rgb, grid, size, spec.photo_clean, look, _rng(spec.seed, 3))
    albedo[:], roughness[:] = a, r
    height += h
    return name


def cavity_factor(crack_mask: np.ndarray, crack_depth: np.ndarray, texel_m: float, strength: float) -> np.ndarray:
    """Albedo multiplier (T,T) for light lost in the crack cavity: 1 outside cracks.

    A texel ``h`` below the surface, ``e1`` from the near rim and ``e2`` from the far rim
    (local width minus e1) receives the cosine-weighted sky view of a 2-D slot,
    (e1 / sqrt(e1^2 + h^2) + e2 / sqrt(e2^2 + h^2)) / 2: deep, narrow centres go near
    black, the rims keep at least half their light (sharp dark cores, as in real photos)."""
    out = np.ones(crack_mask.shape, np.float32)
    if strength <= 0 or not crack_mask.any():
        return out
    dt = cv2.distanceTransform(crack_mask.astype(np.uint8), cv2.DIST_L2, 5)
    r = int(min(max(math.ceil(float(dt.max())), 1), 15))
    half_w = cv2.dilate(dt, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1)))
    t = np.float32(texel_m)
    e1 = np.maximum(dt - 0.5, 0.5) * t
    e2 = np.maximum(2.0 * half_w - dt - 0.5, 0.5) * t
    h = np.maximum(crack_depth, 0.0)
    view = 0.5 * (e1 / np.sqrt(e1 * e1 + h * h) + e2 / np.sqrt(e2 * e2 + h * h))
    out[crack_mask] = 1.0 - np.float32(strength) * (1.0 - view[crack_mask])
    return out


def crack_interior(spec: MaterialSpec, grid: TexGrid, crack_mask: np.ndarray, crack_depth: np.ndarray,
                   albedo, roughness, height) -> None:
    """Cavity darkening, dirt fill and spalled edges (each off by default: today's look)."""
    if spec.crack_cavity > 0:
        albedo *= cavity_factor(crack_mask, crack_depth, grid.texel_m, spec.crack_cavity)[..., None]
    if not (spec.crack_dirt or spec.crack_spall) or not crack_mask.any():
        return
    rng = _rng(spec.crack_seed, 0x5BA1)
    dirt_seed, spall_seed = _seed(rng), _seed(rng)  # both always drawn: one never moves the other
    if spec.crack_dirt:
        _crack_dirt(np.random.default_rng(dirt_seed), grid, crack_mask, crack_depth, albedo, roughness, height)
    if spec.crack_spall:
        _crack_spall(np.random.default_rng(spall_seed), grid, crack_mask, albedo, roughness, height)


def _crack_dirt(rng: np.random.Generator, grid: TexGrid, crack_mask, crack_depth, albedo, roughness, height) -> None:
    """Dust and debris lying in parts of the crack: lighter than the cavity, rough, partly filling it."""
    f = grid.field(_seed(rng), rng.uniform(0.02, 0.08), 3)
    thr = float(np.quantile(f[crack_mask], 1.0 - rng.uniform(0.2, 0.6)))
    w = smoothstep(thr, thr + 0.4, f) * crack_mask * np.float32(rng.uniform(0.6, 1.0))
    outside = albedo[~crack_mask].mean(axis=0) if (~crack_mask).any() else albedo.reshape(-1, 3).mean(axis=0)
    dust = (outside * rng.uniform(0.6, 1.0) * np.asarray([1.0, 0.95, 0.85])).astype(np.float32)
    albedo += w[..., None] * (dust - albedo)
    roughness += w * (np.float32(1.0) - roughness)
    height += w * crack_depth * np.float32(rng.uniform(0.3, 0.8))


def _crack_spall(rng: np.random.Generator, grid: TexGrid, crack_mask, albedo, roughness, height) -> None:
    """Chipped crack edges: small dents just outside the crack border (texture only, unlabelled)."""
    t = np.float32(grid.texel_m)
    d = cv2.distanceTransform((~crack_mask).astype(np.uint8), cv2.DIST_L2, 5) * t
    reach = np.float32(rng.uniform(0.002, 0.006)) * (1.0 + 0.6 * grid.field(_seed(rng), 0.01, 2))
    sel = grid.field(_seed(rng), rng.uniform(0.01, 0.03), 2)
    thr = quantile_fast(sel, 1.0 - rng.uniform(0.2, 0.5))
    w = smoothstep(reach + t, reach, d) * smoothstep(thr, thr + 0.3, sel) * ~crack_mask
    slope = np.clip(1.0 - d / np.maximum(reach, t), 0.0, 1.0)
    height -= w * slope * np.float32(rng.uniform(0.001, 0.004))
    albedo *= (1.0 - w * np.float32(rng.uniform(0.15, 0.4)))[..., None]
    roughness += w * (np.float32(0.95) - roughness)


# ----------------------------------------------------------------------------- family parts


def _layer(layer: NoiseLayer, grid: TexGrid, rng: np.random.Generator, albedo, roughness, height) -> None:
    f = grid.field(
        _seed(rng), layer.scale_m, layer.octaves, layer.persistence, layer.lacunarity, layer.stretch,
        offset=tuple(rng.uniform(-500, 500, 2)),
    )
    a = np.float32(layer.amplitude)
    if layer.target == "albedo":
        if layer.color is None:
            albedo *= np.maximum(1.0 + a * f, 0.0)[..., None]
        else:
            w = clip01(a * f)[..., None]
            albedo += w * (np.asarray(layer.color, np.float32) - albedo)
    elif layer.target == "roughness":
        roughness += a * f
    else:
        height += a * f


# Per-cell grain parameters (last axis of ``cells``), all drawn in one Generator call.
_JX, _JY, _INV_R, _COS, _SIN, _ASPECT, _R, _G, _B = range(9)


@njit(cache=True, parallel=True)
def _paint_grains(x, cell, cells, edge, rough, height_m, albedo, roughness, height):  # pragma: no cover
    """Worley search over the 3x3 neighbouring cells for the grain nearest (in its own
    elliptical metric) to each texel, then blend that grain into the maps in place."""
    p = x.size
    for j in prange(p):
        cy = int(x[j] / cell)
        for i in range(p):
            cx = int(x[i] / cell)
            best = 1.0
            by = -1
            bx = -1
            for dy in range(-1, 2):
                yy = cy + dy + 1
                for dx in range(-1, 2):
                    xx = cx + dx + 1
                    ir = cells[yy, xx, 2]
                    if ir == 0.0:
                        continue
                    ddx = x[i] - (cx + dx + cells[yy, xx, 0]) * cell
                    ddy = x[j] - (cy + dy + cells[yy, xx, 1]) * cell
                    c = cells[yy, xx, 3]
                    s = cells[yy, xx, 4]
                    a1 = c * ddx + s * ddy
                    a2 = (c * ddy - s * ddx) * cells[yy, xx, 5]
                    r = math.sqrt(a1 * a1 + a2 * a2) * ir
                    if r < best:
                        best = r
                        by = yy
                        bx = xx
            if by < 0:
                continue
            t = min((1.0 - best) / edge, 1.0)
            w = t * t * (3.0 - 2.0 * t)
            for k in range(3):
                albedo[j, i, k] += w * (cells[by, bx, 6 + k] - albedo[j, i, k])
            if rough >= 0.0:
                roughness[j, i] += w * (rough - roughness[j, i])
            height[j, i] += height_m * math.sqrt(max(1.0 - best * best, 0.0))


def _speckles(sp: Speckles, grid: TexGrid, rng: np.random.Generator, albedo, roughness, height) -> None:
    r_lo, r_hi = sp.size_m[0] / 2, sp.size_m[1] / 2
    mean_area = math.pi * (r_lo * r_lo + r_lo * r_hi + r_hi * r_hi) / 3.0 / ((1.0 + sp.aspect) / 2.0)
    # At most one grain per cell, and no grain reaches beyond the neighbouring cells.
    cell = max(r_hi, math.sqrt(mean_area / sp.coverage))
    presence = min(1.0, sp.coverage * cell * cell / mean_area)
    n = int(math.ceil(grid.size_m / cell)) + 2
    u = rng.random((n, n, 7), dtype=np.float32)
    cells = np.empty((n, n, 9), np.float32)
    cells[..., _JX:_JY + 1] = u[..., 0:2]
    cells[..., _INV_R] = np.where(u[..., 2] < presence, 1.0 / (r_lo + (r_hi - r_lo) * u[..., 3]), 0.0)
    ang = np.float32(math.pi) * u[..., 4]
    cells[..., _COS] = np.cos(ang)
    cells[..., _SIN] = np.sin(ang)
    cells[..., _ASPECT] = 1.0 + (sp.aspect - 1.0) * u[..., 5]
    palette = np.asarray(sp.colors, np.float32)
    # Brightness jitter: uniform with the std of ``color_jitter`` (log scale).
    gain = np.exp(np.float32(sp.color_jitter * math.sqrt(12.0)) * (u[..., 6] - 0.5))
    cells[..., _R:_B + 1] = palette[rng.integers(0, len(palette), (n, n))] * gain[..., None]
    np.clip(cells[..., _R:_B + 1], 0.0, 1.0, out=cells[..., _R:_B + 1])
    rough = -1.0 if sp.roughness is None else float(sp.roughness)
    _paint_grains(grid.x_m, cell, cells, sp.edge, rough, sp.height_m, albedo, roughness, height)


@njit(cache=True, parallel=True)
def _paint_bricks(x, ox, oy, pitch_x, pitch_y, mortar, bond, bevel, jit_x, jit_y, colors, rough,
                  mortar_color, mortar_rough, depth, albedo, roughness, height):  # pragma: no cover
    """Running bond: mortar occupies the first ``mortar`` metres of each pitch; bricks get
    per-brick colour/roughness and a bevelled face ``depth`` above the mortar."""
    p = x.size
    n_rows, n_cols = rough.shape
    for j in prange(p):
        for i in range(p):
            yy = x[j] + oy + jit_y[j, i]
            row = math.floor(yy / pitch_y)
            fy = yy - row * pitch_y
            sh = row * bond
            xx = x[i] + ox + jit_x[j, i] + pitch_x * (sh - math.floor(sh))
            col = math.floor(xx / pitch_x)
            fx = xx - col * pitch_x
            e = min(min(fx - mortar, pitch_x - fx), min(fy - mortar, pitch_y - fy))
            t = min(max(e / bevel, 0.0), 1.0)
            w = t * t * (3.0 - 2.0 * t)
            r = min(max(int(row) + 1, 0), n_rows - 1)
            c = min(max(int(col) + 1, 0), n_cols - 1)
            for k in range(3):
                albedo[j, i, k] = mortar_color[k] + w * (colors[r, c, k] - mortar_color[k])
            roughness[j, i] = mortar_rough + w * (rough[r, c] - mortar_rough)
            height[j, i] += depth * w


def _brick_origin(b: Bricks, rng: np.random.Generator) -> tuple[float, float, float, float]:
    """(pitch_x, pitch_y, ox, oy): the bond's pitch and its random origin, the first draws of ``_bricks``."""
    pitch_x, pitch_y = b.size_m[0] + b.mortar_m, b.size_m[1] + b.mortar_m
    return pitch_x, pitch_y, float(rng.uniform(0, pitch_x)), float(rng.uniform(0, pitch_y))


def brick_joints(spec: MaterialSpec) -> JointGrid | None:
    """The mortar joint layout ``material_maps`` paints for ``spec`` (None for a family without bricks):
    the same draws from the same stream, so a crack can follow the very joints of the wall."""
    fam = load_family(spec.family)
    if fam.bricks is None:
        return None
    rng = _rng(spec.seed, 0)
    rng.normal()  # the base colour's two draws in material_maps, then _bricks' origin
    rng.normal(size=3)
    pitch_x, pitch_y, ox, oy = _brick_origin(fam.bricks, rng)
    return JointGrid(pitch_x=pitch_x, pitch_y=pitch_y, mortar_m=fam.bricks.mortar_m, bond=fam.bricks.bond_offset,
                     ox=ox, oy=oy)


def _bricks(b: Bricks, grid: TexGrid, rng: np.random.Generator, albedo, roughness, height,
            depth_m: float | None = None) -> None:
    """Paint the bond; brick faces rise ``depth_m`` (default: the family's ``mortar_depth_m``) above the mortar."""
    pitch_x, pitch_y, ox, oy = _brick_origin(b, rng)
    if b.edge_noise_m > 0:
        f = grid.field(_seed(rng), 0.03, 2) * np.float32(b.edge_noise_m)
        jx, jy = f, np.ascontiguousarray(f.T)  # transposed: a second, nearly independent field
    else:
        jx = jy = np.zeros((grid.px, grid.px), np.float32)
    n_rows = int(math.ceil((grid.size_m + 2 * pitch_y) / pitch_y)) + 2
    n_cols = int(math.ceil((grid.size_m + 3 * pitch_x) / pitch_x)) + 2
    palette = np.asarray(b.colors, np.float64)
    colors = palette[rng.integers(0, len(palette), (n_rows, n_cols))]
    colors *= np.exp(b.color_jitter * rng.normal(size=(n_rows, n_cols, 1)))
    colors *= 1.0 + 0.15 * b.color_jitter * rng.normal(size=(n_rows, n_cols, 3))
    rough = np.clip(float(roughness.mean()) + 0.05 * rng.normal(size=(n_rows, n_cols)), 0, 1)
    _paint_bricks(
        grid.x_m, ox, oy, pitch_x, pitch_y, b.mortar_m, b.bond_offset, max(b.bevel_m, grid.texel_m * 0.5),
        jx, jy, np.clip(colors, 0, 1).astype(np.float32), rough.astype(np.float32),
        np.asarray(b.mortar_color, np.float32), float(b.mortar_roughness),
        float(b.mortar_depth_m if depth_m is None else depth_m), albedo, roughness, height,
    )


def _paint(p: Paint, grid: TexGrid, rng: np.random.Generator, albedo, roughness, height) -> None:
    """Paint coat over the current maps; chips (thresholded fBm) expose rust or bare base."""
    jitter = math.exp(p.color_jitter * rng.normal()) * (1 + 0.2 * p.color_jitter * rng.normal(size=3))
    color = np.clip(np.asarray(p.colors[int(rng.integers(len(p.colors)))]) * jitter, 0, 1).astype(np.float32)
    rust_c = np.asarray(p.rust_colors[int(rng.integers(len(p.rust_colors)))], np.float32)
    coverage = rng.uniform(*p.chip_coverage)
    f = grid.field(_seed(rng), p.chip_scale_m, p.chip_octaves, 0.55)
    thr = quantile_fast(f, 1.0 - coverage) if coverage > 0 else np.inf
    chip = smoothstep(thr - 0.03, thr + 0.03, f)
    # Rust creeping under the paint just outside the chips.
    halo = smoothstep(thr - p.rust_halo, thr, f) * (1.0 - chip) * np.float32(0.6) if p.rust_halo > 0 else 0 * chip
    # Under the paint: rust on ``rust_fraction`` of the area, bare base elsewhere.
    g = grid.field(_seed(rng), p.chip_scale_m * 0.3, 3)
    g_thr = quantile_fast(g, 1.0 - p.rust_fraction)
    rust = smoothstep(g_thr - 0.3, g_thr + 0.3, g)
    under = albedo + rust[..., None] * (rust_c - albedo)
    under_rough = roughness + rust * (np.float32(p.rust_roughness) - roughness)
    paint = color + halo[..., None] * (rust_c - color)
    albedo[:] = paint + chip[..., None] * (under - paint)
    roughness[:] = p.roughness + chip * (under_rough - np.float32(p.roughness))
    height += np.float32(p.thickness_m) * (1.0 - chip) + np.float32(0.0002) * rust * chip


# ----------------------------------------------------------------------------- preview


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def save_preview(maps: MaterialMaps, path: str | Path, max_px: int = 512) -> Path:
    """PNG contact sheet: albedo (sRGB) | roughness | normal | height, distractors outlined in cyan.

    Rows are flipped so +v points up, as the patch looks from above.
    """
    def fit(img: np.ndarray) -> np.ndarray:
        s = img.shape[0]
        return cv2.resize(img, (max_px, max_px), interpolation=cv2.INTER_AREA) if s > max_px else img

    alb = (linear_to_srgb(maps.albedo) * 255 + 0.5).astype(np.uint8)
    if maps.distractor_mask.any():
        inner = cv2.erode(maps.distractor_mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        edge = maps.distractor_mask & ~inner
        alb[edge] = (0, 255, 255)
    rough = np.repeat((maps.roughness * 255 + 0.5).astype(np.uint8)[..., None], 3, axis=2)
    nrm = (np.clip(maps.normal, 0, 1) * 255 + 0.5).astype(np.uint8)
    h = maps.height_m
    lo, hi = np.percentile(h, [1, 99])
    hv = (np.clip((h - lo) / max(hi - lo, 1e-9), 0, 1) * 255).astype(np.uint8)
    hgt = np.repeat(hv[..., None], 3, axis=2)
    sheet = np.concatenate([fit(a) for a in (alb, rough, nrm, hgt)], axis=1)[::-1]
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(out), cv2.cvtColor(np.ascontiguousarray(sheet), cv2.COLOR_RGB2BGR)):
        raise MaterialError(f"{out}: could not write preview PNG")
    return out
