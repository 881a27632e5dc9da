"""SampleSpec: every random draw of one sample, as plain data.

A spec depends only on (recipe, index). The root of a sample's randomness is
``SeedSequence([recipe.dataset.seed, index])``; each recipe section draws from its
own child stream of that root (``SECTION_STREAMS``), so switching stereo on, or
changing the number of lights, never moves the draws of any other section.
Everything downstream (crack map, materials, renderer, sensors) is a pure
function of the spec, so output is identical whatever the worker count/order.

Units: metres and radians; pixel quantities end in ``_px``.
World frame: the surface lies in the z = 0 plane, centred on the origin, z up.
"""
from __future__ import annotations

import dataclasses
import json
import math
import typing
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from crackgen.config.recipe import CLUTTER_KINDS, AdaptSection, CameraEffectsSection, Recipe

# 2: one random stream per section (SECTION_STREAMS) instead of one shared stream.
SPEC_VERSION = 2

# Stream number of each section's draws: the child SeedSequence([seed, index], spawn_key=(n,)).
# Append-only: never renumber or reuse a number (that would change every existing dataset);
# a new section takes the next free number.
SECTION_STREAMS: dict[str, int] = {
    "crack": 0,
    "surface": 1,
    "material": 2,
    "lights": 3,
    "ambient": 4,
    "shadow": 5,
    "camera": 6,
    "stereo": 7,
    "render": 8,
    "tof": 9,
    "lidar": 10,
    "adapt": 11,
    "camera_effects": 12,
    "lens": 13,
    "sky": 14,
}

# Distractors that belong to some surfaces only (drawn for every family, painted on these).
SURFACE_DISTRACTORS: dict[str, tuple[str, ...]] = {
    "formwork": ("concrete",),
    "rust_streak": ("concrete", "masonry", "blockwork", "steel"),
}

# Families whose mortar joints ``[material] joint_relief_m`` recesses into the mesh (their family file has bricks).
JOINT_RELIEF_FAMILIES = ("masonry", "blockwork")

# Sections drawn once per scene (``[camera] views_per_scene``): every view of a scene shares its crack, surface
# and material. The other sections are drawn per sample (view), keyed by the sample's own index.
SCENE_SECTIONS = ("crack", "surface", "material")


@dataclass
class CrackSpec:
    """Thesis eq. 5.3-5.6 parameters plus the per-sample noise seed/offset."""

    freq_x: float  # noise frequency across the surface (cycles per surface width)
    freq_y: float
    octaves: int
    persistence: float
    lacunarity: float
    threshold: float  # mask = Z < threshold; larger -> wider cracks
    depth_m: float  # displacement (m) where D reaches its maximum (= threshold)
    noise_seed: int  # OpenSimplex seed
    offset_u: float  # random offset of the noise domain, noise units
    offset_v: float
    # Shape family and crack-free share (issue 9); defaults = the thesis fbm map, so old spec JSON loads.
    present: bool = True  # False: crack-free sample (empty map)
    shape: str = "fbm"  # fbm | fracture | network | hairline (crackgen.procedural.crack_shapes)
    shape_seed: int = 0  # seeds the fracture/network/hairline path generator
    width_m: float = 0.0  # fracture/network: full width at the widest point (m)
    count: int = 1  # fracture/hairline: main cracks
    branches: int = 0  # fracture/hairline: side branches per main crack
    jaggedness: float = 0.0  # midpoint-displacement s.d. / segment length
    cells: int = 0  # network: Voronoi cells
    gaps: float = 0.0  # network: fraction of boundaries left uncracked
    hairline_px: float = 1.5  # hairline: full width in camera pixels
    wall: float = 1.0  # path families: share of the half-width the wall slopes over (1 = V-groove)


@dataclass
class StepSpec:
    """A straight height step across the surface (kerb, faulted slab edge): real scenes have depth
    edges, where interpolated LiDAR/ToF and stereo fail differently; a flat patch has none."""

    angle_rad: float  # direction of the step normal n = (cos, sin) in the surface plane
    offset_m: float  # the line is n . (x, y) = offset_m; the side beyond it is raised
    height_m: float  # raised by this much towards the cameras (+z)


@dataclass
class SurfaceSpec:
    size_m: float  # side of the square patch (m)
    grid_px: int  # mesh vertices per side
    crackmap_px: int  # crack map resolution per side (surface coordinates)
    steps: list[StepSpec] = field(default_factory=list)  # height steps (empty: the flat patch)


@dataclass
class DistractorSpec:
    """A non-crack feature painted into the material; its mask stays empty."""

    kind: str  # joint | sealant | stain | marking
    seed: int


@dataclass
class ClutterSpec:
    """Real-world clutter painted into the material (pores, gaps, stains, moss, patch); never labelled."""

    kind: str  # crackgen.config.recipe.CLUTTER_KINDS
    seed: int
    amount: float  # 0..1, fraction of the kind's maximum number / coverage


@dataclass
class MaterialSpec:
    family: str  # asphalt | concrete | masonry | steel (blender_assets/materials/*.toml)
    seed: int  # seeds the texture noise
    texture_px: int  # albedo/roughness/normal map resolution per side
    hue_shift: float  # small colour variation, fraction of the family's base colour
    value_scale: float  # brightness multiplier of the albedo
    roughness_offset: float  # added to the family roughness
    crack_darkening: float  # albedo multiplier inside the crack (0..1)
    crack_roughness: float  # roughness inside the crack (0..1)
    distractors: list[DistractorSpec] = field(default_factory=list)
    # Defaults below keep older spec JSON loadable and mean "as before" (off).
    crack_cavity: float = 0.0  # cavity darkening inside cracks (0 = off)
    crack_dirt: bool = False  # dust / debris partly filling the cracks
    crack_spall: bool = False  # chipped crack edges (texture only, unlabelled)
    crack_seed: int = 0  # seeds dirt and spall
    photo_folder: str = ""  # family "photo": the recipe's folder of crack-free photos
    photo_fraction: float = 0.0  # which photo: fraction in [0, 1) of the sorted folder listing
    photo_size_m: float = 0.0  # surface side covered by one photo side (m)
    photo_clean: str = "none"  # none | blackhat
    clutter: list[ClutterSpec] = field(default_factory=list)
    joint_relief_m: float = 0.0  # brick/block families: mortar recess carried by the mesh (m); 0 = normal map only


@dataclass
class LightSpec:
    kind: str  # sun | area | spot | point
    elevation_rad: float  # above the surface plane
    azimuth_rad: float
    distance_m: float  # from the surface centre (ignored for sun)
    intensity: float  # sun: irradiance W/m^2; others: power W
    color_temp_k: float
    size_m: float  # area size / point+spot radius (m); sun: angular diameter (rad)
    spot_angle_rad: float  # spot cone angle (ignored otherwise)


@dataclass
class AmbientSpec:
    strength: float  # world background strength (0 = off)
    color_temp_k: float


@dataclass
class SkySpec:
    """A procedural daylight sky as the world (``[lights] sky``); left out of the sample JSON when off.

    The sky's sun is where the first sun lamp is (so the sky's bright side, the lamp and its cast
    shadows agree); without a sun lamp it is the drawn direction. ``overcast`` (0 = clear) is the share
    of the sky that is a uniform cloud deck and how much every sun lamp is dimmed."""

    enabled: bool = False
    turbidity: float = 0.0
    ground_albedo: float = 0.0
    overcast: float = 0.0
    sun_elevation_rad: float = 0.0
    sun_azimuth_rad: float = 0.0


@dataclass
class ShadowSpec:
    """Occluder between one light and the surface (thesis 5.2.5); invisible to cameras."""

    enabled: bool
    pattern: str  # noise | shapes | stripes
    seed: int
    light_index: int  # which light it blocks
    height_m: float  # distance from the surface along the light direction
    size_m: float  # side of the square occluder
    coverage: float  # opaque fraction of the occluder (0..1)
    softness: float  # edge blur, fraction of the occluder size
    offset_x_m: float  # occluder centre offset perpendicular to the light ray
    offset_y_m: float


@dataclass
class CameraSpec:
    width_px: int
    height_px: int
    distance_m: float  # camera centre to target point
    tilt_rad: float  # angle between optical axis and the surface normal
    azimuth_rad: float
    roll_rad: float
    focal_mm: float
    sensor_width_mm: float
    cx_offset_px: float  # principal point jitter from the image centre
    cy_offset_px: float
    target_x_m: float  # look-at point on the surface
    target_y_m: float
    baseline_m: float  # right stereo camera along +x of the camera; 0 = none


@dataclass
class RenderKnobs:
    """Cycles speed/quality knobs, named as in [render]; defaults = Blender 4.5 factory values (the
    renders before they existed; older sample JSON lacks them). The renderer's settings reuse this."""

    adaptive_sampling: bool = True
    adaptive_threshold: float = 0.01
    adaptive_min_samples: int = 0
    denoise_prefilter: str = "accurate"
    denoise_passes: str = "rgb_albedo_normal"
    denoise_quality: str = "high"
    diffuse_bounces: int = 4
    glossy_bounces: int = 4
    transmission_bounces: int = 12
    transparent_bounces: int = 8
    caustics_reflective: bool = True
    caustics_refractive: bool = True
    light_tree: bool = True
    fast_gi: bool = False
    ao_bounces: int = 1
    clamp_direct: float = 0.0
    clamp_indirect: float = 10.0
    persistent_data: bool = False


@dataclass(kw_only=True)
class RenderSpec(RenderKnobs):
    samples: int
    denoise: bool
    threads: int  # 0 = let Cycles decide
    device: str  # cpu | gpu
    seed: int  # Cycles seed
    max_bounces: int


RENDER_KNOBS = tuple(f.name for f in dataclasses.fields(RenderKnobs))  # copied 1:1 from [render]


@dataclass
class TofSpec:
    enabled: bool
    width_px: int
    height_px: int
    hfov_rad: float
    vfov_rad: float
    offset_m: list[float]  # ToF centre in the RGB camera frame (OpenCV: x right, y down, z fwd)
    rotation_rad: list[float]  # small xyz Euler rotation relative to the RGB camera
    sigma0_m: float  # range noise floor
    k_noise: float  # sigma = sigma0 + k * d^2 / A
    amplitude_scale: float  # A = scale * albedo * cos(theta) / d^2
    min_amplitude: float  # dropout below this amplitude (0 = off)
    grazing_rad: float  # dropout when incidence angle exceeds this (pi/2 = off)
    flying_pixels: bool  # mixed pixels at depth discontinuities
    wrap_range_m: float  # unambiguous range; 0 = no phase wrap
    bias_m: float  # per-sample range bias
    seed: int


@dataclass
class LidarSpec:
    enabled: bool
    beams: int
    vfov_min_rad: float
    vfov_max_rad: float
    hfov_rad: float  # azimuth sweep centred on the optical axis
    azimuth_step_rad: float
    max_range_m: float
    sigma_m: float
    dropout: float  # fraction of returns lost at random
    offset_m: list[float]  # in the RGB camera frame (OpenCV)
    rotation_rad: list[float]
    seed: int


@dataclass
class StereoSpec:
    enabled: bool
    baseline_m: float
    num_disparities: int  # SGBM search range (multiple of 16)
    block_size: int  # SGBM block size (odd)
    sgbm_input: str = "clean"  # clean | camera: the images SGBM matches (older sample JSON: clean)


@dataclass
class AdaptSpec:
    """Post-render appearance adaptation of the RGB views (``[adapt]``).

    The target photo is drawn as a fraction in [0, 1) of the sorted target folder, so
    the spec stays a pure draw; the stage resolves it to a file name (in the metadata)."""

    enabled: bool = False
    method: str = ""  # fourier | reinhard | histogram
    band: float = 0.0  # fourier only: fraction of min(H, W)
    target: str = ""  # the recipe's target folder
    target_fraction: float = 0.0


@dataclass
class LensSpec:
    """Lens distortion of the RGB views (``[camera.distortion]``, OpenCV's Brown-Conrady model, ``fusion.geometry.lens``).

    Left out of the sample JSON when off, so pinhole samples read exactly as before it existed."""

    enabled: bool = False
    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0


@dataclass
class CameraEffectsSpec:
    """Post-render camera effects of the RGB views (``[camera_effects]``).

    ``applied`` names the effects that run, in ``crackgen.postrender.camera_effects.EFFECTS`` order;
    the values of the others stay neutral."""

    enabled: bool = False
    applied: list[str] = field(default_factory=list)
    exposure_ev: float = 0.0  # stops: linear x 2**ev
    wb_shift_mired: float = 0.0  # light colour-temperature shift (mired)
    wb_tint: float = 0.0  # green gain x (1 + tint)
    tone_gamma: float = 1.0
    tone_contrast: float = 0.0
    vignette_strength: float = 0.0  # fraction of light lost at the corners
    defocus_kernel: str = ""  # disk | gaussian
    defocus_radius_px: float = 0.0
    motion_length_px: float = 0.0
    motion_angle_deg: float = 0.0
    noise_full_well_e: float = 0.0  # electrons at linear 1.0
    noise_read_e: float = 0.0  # read-noise std (electrons)
    jpeg_quality: int = 0
    seed: int = 0  # seeds the sensor noise
    auto_exposure_luma: float = 0.0  # target mean sRGB luma (0-255) of auto exposure
    sharpen_amount: float = 0.0  # unsharp-mask gain on the luma detail
    sharpen_sigma_px: float = 0.0  # unsharp-mask Gaussian sigma (px)


@dataclass
class SampleSpec:
    index: int
    recipe_seed: int
    crack: CrackSpec
    surface: SurfaceSpec
    material: MaterialSpec
    lights: list[LightSpec]
    ambient: AmbientSpec
    shadow: ShadowSpec
    camera: CameraSpec
    render: RenderSpec
    tof: TofSpec
    lidar: LidarSpec
    stereo: StereoSpec
    adapt: AdaptSpec = field(default_factory=AdaptSpec)
    camera_effects: CameraEffectsSpec = field(default_factory=CameraEffectsSpec)
    version: int = SPEC_VERSION
    lens: LensSpec = field(default_factory=LensSpec)
    sky: SkySpec = field(default_factory=SkySpec)

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        for name in ("lens", "sky"):  # off: the sample's JSON is what it was before the option existed
            if not getattr(self, name).enabled:
                del d[name]
        if not self.material.joint_relief_m:  # likewise for joints in the normal map only
            del d["material"]["joint_relief_m"]
        return d

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "SampleSpec":
        return _from_dict(cls, data)

    @classmethod
    def from_json(cls, text: str) -> "SampleSpec":
        return cls.from_dict(json.loads(text))


def _from_dict(tp: Any, value: Any) -> Any:
    """Rebuild nested dataclasses from ``asdict`` output, by type hints."""
    if dataclasses.is_dataclass(tp):
        hints = typing.get_type_hints(tp)
        names = {f.name for f in dataclasses.fields(tp)}
        unknown = set(value) - names
        if unknown:
            raise ValueError(f"{tp.__name__}: unknown keys {sorted(unknown)}")
        return tp(**{k: _from_dict(hints[k], v) for k, v in value.items()})
    origin = typing.get_origin(tp)
    if origin is list:
        (item,) = typing.get_args(tp)
        return [_from_dict(item, v) for v in value]
    if tp is float:
        return float(value)
    if tp is int:
        return int(value)
    return value


def local_light_power(kind: str, irradiance_w_m2: float, distance_m: float) -> float:
    """Blender power (W) giving ``irradiance_w_m2`` on-axis at ``distance_m``, so every light kind
    is as bright as a sun of the same strength (point/spot radiate over 4*pi sr, an area light
    is a Lambertian emitter: pi)."""
    solid = math.pi if kind == "area" else 4.0 * math.pi
    return float(irradiance_w_m2 * solid * distance_m**2)


def pixel_footprint_m(camera: CameraSpec) -> float:
    """Side (m) of one camera pixel on the surface at the look-at point, fronto-parallel:
    distance * sensor_width / (focal * width_px). Hairline widths are set in these pixels."""
    return float(camera.distance_m * camera.sensor_width_mm / (camera.focal_mm * camera.width_px))


def section_rng(recipe_seed: int, index: int, section: str, attempt: int = 0) -> np.random.Generator:
    """The Generator that section ``section`` of sample ``index`` draws from.

    It is the child of the sample's root ``SeedSequence([recipe_seed, index])`` keyed by the
    section's fixed number: ``SeedSequence(root entropy, spawn_key=(n,))``, which is exactly
    ``root.spawn(n + 1)[n]``. Keying by a fixed number, rather than spawning a list as long as
    today's sections, makes each stream depend on nothing but its own number: a section can be
    drawn alone, in any order, and appending a section to the table leaves the others untouched.

    ``attempt`` >= 1 re-keys the crack stream only (``spawn_key=(0, attempt)``): a sample whose
    crack does not show is redrawn ([label] invisible = "redraw") with a new, deterministic crack
    and everything else unchanged. Attempt 0 is the original stream, byte for byte.
    """
    if section not in SECTION_STREAMS:
        raise ValueError(f"section_rng: unknown section {section!r}; known: {', '.join(SECTION_STREAMS)}")
    if int(attempt) < 0:
        raise ValueError(f"section_rng: attempt must be >= 0, got {attempt!r}")
    key: tuple[int, ...] = (SECTION_STREAMS[section],)
    if section == "crack" and int(attempt) > 0:
        key = (SECTION_STREAMS[section], int(attempt))
    seq = np.random.SeedSequence([int(recipe_seed), int(index)], spawn_key=key)
    return np.random.default_rng(seq)


def _seed(rng: np.random.Generator) -> int:
    """A seed for a downstream Generator (noise, texture, sensor)."""
    return int(rng.integers(0, 2**31 - 1))


def _crack(recipe: Recipe, rng: np.random.Generator, family: str) -> CrackSpec:
    """``family``: the sample's material family, whose own shape distribution (``shape_by_family``) is used
    when the recipe gives one; either way the shape is one draw at the same place in the stream."""
    c = recipe.crack
    return CrackSpec(
        freq_x=c.frequency_x.draw(rng),
        freq_y=c.frequency_y.draw(rng),
        octaves=int(c.octaves.draw(rng)),
        persistence=c.persistence.draw(rng),
        lacunarity=c.lacunarity.draw(rng),
        threshold=c.threshold.draw(rng),
        depth_m=c.depth_m.draw(rng),
        noise_seed=_seed(rng),
        offset_u=float(rng.uniform(-1000.0, 1000.0)),
        offset_v=float(rng.uniform(-1000.0, 1000.0)),
        # Appended after the thesis draws and always made (whatever the family), so the draws
        # above, and so every fbm map, stay byte-identical for existing recipes.
        present=bool(rng.random() < c.probability),
        shape=str(c.shape_by_family.get(family, c.shape).draw(rng)),
        shape_seed=_seed(rng),
        width_m=c.width_m.draw(rng),
        count=int(c.count.draw(rng)),
        branches=int(c.branches.draw(rng)),
        jaggedness=c.jaggedness.draw(rng),
        cells=int(c.cells.draw(rng)),
        gaps=c.gaps.draw(rng),
        hairline_px=c.hairline_px.draw(rng),
        wall=c.wall.draw(rng),  # appended last: the draws above are unchanged
    )


def _material(recipe: Recipe, rng: np.random.Generator) -> MaterialSpec:
    m = recipe.material
    spec = MaterialSpec(
        family=str(m.family.draw(rng)),
        seed=_seed(rng),
        texture_px=m.texture_px,
        hue_shift=m.hue_shift.draw(rng),
        value_scale=m.value_scale.draw(rng),
        roughness_offset=m.roughness_offset.draw(rng),
        crack_darkening=m.crack_darkening.draw(rng),
        crack_roughness=m.crack_roughness.draw(rng),
    )
    # Every kind draws its coin and its seed whether present or not, last in the stream: changing
    # one probability changes only whether that kind appears, never another draw.
    for kind in ("joint", "sealant", "stain", "marking"):
        present = rng.random() < getattr(m.distractors, kind)
        seed = _seed(rng)
        if present:
            spec.distractors.append(DistractorSpec(kind=kind, seed=seed))
    _material_appearance(m, rng, spec)
    return spec


def _material_appearance(m: Any, rng: np.random.Generator, spec: MaterialSpec) -> None:
    """Crack interior, photo and clutter draws: appended after every older material draw and always
    made, so recipes without these features keep every earlier draw byte-identical."""
    cavity = float(m.crack_cavity.draw(rng))
    dirt = bool(rng.random() < m.crack_dirt)
    spall = bool(rng.random() < m.crack_spall)
    crack_seed = _seed(rng)
    fraction = float(rng.random())
    photo_size = float(m.photo_size_m.draw(rng))
    clean = str(m.photo_clean.draw(rng))
    spec.crack_cavity, spec.crack_dirt, spec.crack_spall, spec.crack_seed = cavity, dirt, spall, crack_seed
    if spec.family == "photo":
        spec.photo_folder, spec.photo_fraction, spec.photo_size_m, spec.photo_clean = (
            m.photo_folder, fraction, photo_size, clean)
    amount = m.clutter.amount
    for kind in CLUTTER_KINDS:
        present = rng.random() < getattr(m.clutter, kind)
        seed, a = _seed(rng), float(amount.draw(rng))
        if present:
            spec.clutter.append(ClutterSpec(kind=kind, seed=seed, amount=a))
    for kind, families in SURFACE_DISTRACTORS.items():  # after every older draw: their coins move nothing else
        present = rng.random() < getattr(m.distractors, kind)
        seed = _seed(rng)
        if present and spec.family in families:
            spec.distractors.append(DistractorSpec(kind=kind, seed=seed))
    relief = float(m.joint_relief_m.draw(rng))  # always drawn, last: it moves no other draw
    if spec.family in JOINT_RELIEF_FAMILIES:
        spec.joint_relief_m = relief


def _lights(recipe: Recipe, rng: np.random.Generator) -> list[LightSpec]:
    """Count first, then a fixed number of draws per light, so light i is the same for any count > i."""
    li = recipe.lights
    lights = []
    for _ in range(int(li.count.draw(rng))):
        kind = str(li.kind.draw(rng))
        distance = li.distance_m.draw(rng)
        light = LightSpec(
            kind=kind,
            elevation_rad=math.radians(li.elevation_deg.draw(rng)),
            azimuth_rad=math.radians(li.azimuth_deg.draw(rng)),
            distance_m=distance,
            intensity=0.0,
            color_temp_k=li.color_temp_k.draw(rng),
            size_m=li.size_m.draw(rng),
            spot_angle_rad=math.radians(li.spot_angle_deg.draw(rng)),
        )
        local_irradiance = li.irradiance_w_m2.draw(rng)  # both strengths and the sun angle are always
        sun_irradiance = li.sun_irradiance_w_m2.draw(rng)  # drawn, so the kind never shifts later draws
        sun_angle = math.radians(li.sun_angle_deg.draw(rng))
        if kind == "sun":
            light.intensity, light.size_m = sun_irradiance, sun_angle
        else:
            light.intensity = local_light_power(kind, local_irradiance, distance)
        lights.append(light)
    return lights


def _shadow(recipe: Recipe, rng: np.random.Generator, n_lights: int) -> ShadowSpec:
    sh = recipe.shadow
    enabled = bool(rng.random() < sh.probability)
    pattern = str(sh.pattern.draw(rng))
    seed = _seed(rng)
    # One uniform scaled to the light count (not integers(0, n), whose consumption may vary):
    # light_index is the one shadow value that depends on another section, by design.
    light_index = min(int(rng.random() * n_lights), n_lights - 1)
    return ShadowSpec(
        enabled=enabled,
        pattern=pattern,
        seed=seed,
        light_index=light_index,
        height_m=sh.height_m.draw(rng),
        size_m=sh.size_m.draw(rng),
        coverage=sh.coverage.draw(rng),
        softness=sh.softness.draw(rng),
        offset_x_m=sh.offset_m.draw(rng),
        offset_y_m=sh.offset_m.draw(rng),
    )


def _camera(recipe: Recipe, rng: np.random.Generator, baseline_m: float) -> CameraSpec:
    ca = recipe.camera
    return CameraSpec(
        width_px=ca.width_px,
        height_px=ca.height_px,
        distance_m=ca.distance_m.draw(rng),
        tilt_rad=math.radians(ca.tilt_deg.draw(rng)),
        azimuth_rad=math.radians(ca.azimuth_deg.draw(rng)),
        roll_rad=math.radians(ca.roll_deg.draw(rng)),
        focal_mm=ca.focal_mm.draw(rng),
        sensor_width_mm=ca.sensor_width_mm,
        cx_offset_px=ca.principal_jitter_px.draw(rng),
        cy_offset_px=ca.principal_jitter_px.draw(rng),
        target_x_m=ca.target_jitter_m.draw(rng),
        target_y_m=ca.target_jitter_m.draw(rng),
        baseline_m=baseline_m,  # drawn by the stereo section; copied here for the rig
    )


def _lens(recipe: Recipe, rng: np.random.Generator) -> LensSpec:
    d = recipe.camera.distortion
    if d.probability <= 0:  # off: no draw at all (its own stream, so nothing else moves either way)
        return LensSpec()
    on = float(rng.random()) < d.probability
    k = {name: float(getattr(d, name).draw(rng)) for name in ("k1", "k2", "k3", "p1", "p2")}
    return LensSpec(enabled=True, **k) if on else LensSpec()


def _sky(recipe: Recipe, rng: np.random.Generator, lights: list[LightSpec]) -> SkySpec:
    li = recipe.lights
    if li.sky <= 0:  # off: no draw at all (its own stream)
        return SkySpec()
    on = float(rng.random()) < li.sky
    turbidity, albedo = float(li.sky_turbidity.draw(rng)), float(li.sky_ground_albedo.draw(rng))
    overcast_on = float(rng.random()) < li.sky_overcast
    amount = float(li.sky_overcast_amount.draw(rng))
    elevation, azimuth = math.radians(li.elevation_deg.draw(rng)), math.radians(li.azimuth_deg.draw(rng))
    sun = next((L for L in lights if L.kind == "sun"), None)
    if sun is not None:  # the sky's sun is the lamp's: one direction for sky, lamp and cast shadows
        elevation, azimuth = sun.elevation_rad, sun.azimuth_rad
    if not on:
        return SkySpec()
    return SkySpec(enabled=True, turbidity=turbidity, ground_albedo=albedo, overcast=amount if overcast_on else 0.0,
                   sun_elevation_rad=float(elevation), sun_azimuth_rad=float(azimuth))


def _stereo(recipe: Recipe, rng: np.random.Generator) -> StereoSpec:
    st = recipe.stereo
    baseline = st.baseline_m.draw(rng)  # drawn even when off: the stream stays the same
    return StereoSpec(
        enabled=st.enabled,
        baseline_m=baseline if st.enabled else 0.0,
        num_disparities=st.num_disparities,
        block_size=st.block_size,
        sgbm_input=st.sgbm_input,
    )


def _tof(recipe: Recipe, rng: np.random.Generator) -> TofSpec:
    t = recipe.tof
    return TofSpec(
        enabled=t.enabled,
        width_px=t.width_px,
        height_px=t.height_px,
        hfov_rad=math.radians(t.hfov_deg),
        vfov_rad=math.radians(t.vfov_deg),
        offset_m=[t.offset_x_m.draw(rng), t.offset_y_m.draw(rng), t.offset_z_m.draw(rng)],
        rotation_rad=[math.radians(t.rotation_jitter_deg.draw(rng)) for _ in range(3)],
        sigma0_m=t.sigma0_m,
        k_noise=t.k_noise,
        amplitude_scale=t.amplitude_scale,
        min_amplitude=t.min_amplitude,
        grazing_rad=math.radians(t.grazing_deg),
        flying_pixels=t.flying_pixels,
        wrap_range_m=t.wrap_range_m,
        bias_m=t.bias_m.draw(rng),
        seed=_seed(rng),
    )


def _lidar(recipe: Recipe, rng: np.random.Generator) -> LidarSpec:
    li = recipe.lidar
    return LidarSpec(
        enabled=li.enabled,
        beams=li.beams,
        vfov_min_rad=math.radians(li.vfov_min_deg),
        vfov_max_rad=math.radians(li.vfov_max_deg),
        hfov_rad=math.radians(li.hfov_deg),
        azimuth_step_rad=math.radians(li.azimuth_step_deg),
        max_range_m=li.max_range_m,
        sigma_m=li.sigma_m,
        dropout=li.dropout,
        offset_m=[li.offset_x_m.draw(rng), li.offset_y_m.draw(rng), li.offset_z_m.draw(rng)],
        rotation_rad=[math.radians(li.rotation_jitter_deg.draw(rng)) for _ in range(3)],
        seed=_seed(rng),
    )


def draw_adapt(a: AdaptSection, rng: np.random.Generator) -> AdaptSpec:
    """Every draw is made even when adaptation is off or skipped, so toggling it moves nothing.

    Public because ``crackgen adapt`` draws for already-rendered samples the same way."""
    applied = bool(rng.random() < a.probability)
    method, band, fraction = str(a.method.draw(rng)), float(a.band.draw(rng)), float(rng.random())
    if not (a.enabled and applied):
        return AdaptSpec()
    return AdaptSpec(enabled=True, method=method, band=band if method == "fourier" else 0.0,
                     target=a.target, target_fraction=fraction)


# The order the camera-effects stage applies them (crackgen.postrender.camera_effects.EFFECTS, tested equal).
CAMERA_EFFECTS_ORDER = ("auto_exposure", "exposure", "white_balance", "tone", "vignetting", "defocus", "motion_blur",
                        "noise", "sharpen", "jpeg")


def draw_camera_effects(c: CameraEffectsSection, rng: np.random.Generator) -> CameraEffectsSpec:
    """Every draw is made even when the section or an effect is off, so toggling one moves nothing.

    Per effect, in a fixed order: its coin, then its values; the noise seed last."""
    def coin(p: float) -> bool:
        return bool(rng.random() < p)

    on = {
        "exposure": (coin(c.exposure), {"exposure_ev": float(c.exposure_ev.draw(rng))}),
        "white_balance": (coin(c.white_balance), {"wb_shift_mired": float(c.wb_shift_mired.draw(rng)),
                                                  "wb_tint": float(c.wb_tint.draw(rng))}),
        "tone": (coin(c.tone), {"tone_gamma": float(c.tone_gamma.draw(rng)),
                                "tone_contrast": float(c.tone_contrast.draw(rng))}),
        "vignetting": (coin(c.vignetting), {"vignette_strength": float(c.vignette_strength.draw(rng))}),
        "defocus": (coin(c.defocus), {"defocus_kernel": str(c.defocus_kernel.draw(rng)),
                                      "defocus_radius_px": float(c.defocus_radius_px.draw(rng))}),
        "motion_blur": (coin(c.motion_blur), {"motion_length_px": float(c.motion_length_px.draw(rng)),
                                              "motion_angle_deg": float(c.motion_angle_deg.draw(rng))}),
        "noise": (coin(c.noise), {"noise_full_well_e": float(c.noise_full_well_e.draw(rng)),
                                  "noise_read_e": float(c.noise_read_e.draw(rng))}),
        "jpeg": (coin(c.jpeg), {"jpeg_quality": int(round(float(c.jpeg_quality.draw(rng))))}),
    }
    seed = _seed(rng)
    # appended after the seed, so adding auto exposure moved none of the draws above
    on["auto_exposure"] = (coin(c.auto_exposure), {"auto_exposure_luma": float(c.auto_exposure_luma.draw(rng))})
    on["sharpen"] = (coin(c.sharpen), {"sharpen_amount": float(c.sharpen_amount.draw(rng)),  # appended last, likewise
                                       "sharpen_sigma_px": float(c.sharpen_sigma_px.draw(rng))})
    if not c.enabled:
        return CameraEffectsSpec()
    spec = CameraEffectsSpec(enabled=True, seed=seed)
    for name in CAMERA_EFFECTS_ORDER:
        applied, values = on[name]
        if applied:
            spec.applied.append(name)
            for k, v in values.items():
                setattr(spec, k, v)
    return spec


def _surface(recipe: Recipe, rng: np.random.Generator, cameras: list[CameraSpec]) -> SurfaceSpec:
    """Patch size (``size_m``, or ``size_fov`` times the widest view of the scene's cameras), then the steps
    (drawn after it, so a recipe without steps keeps its sizes).

    Steps add up (terraces), so their total height is capped at ``step_max_rise`` of the lowest
    camera's height above the patch: four 25 cm steps under a camera 0.6 m up would put the
    surface at the lens (a measured 3400 px disparity), and disparity grows as 1 / (1 - rise)."""
    s = recipe.surface
    if max(s.size_fov.support()) > 0:  # sized to the view (a new option: its own draw order)
        view = max(pixel_footprint_m(c) * max(c.width_px, c.height_px) / max(math.cos(c.tilt_rad), 0.2)
                   for c in cameras)
        offset = max(max(abs(c.target_x_m), abs(c.target_y_m)) for c in cameras)
        size = float(s.size_fov.draw(rng)) * view + 2.0 * offset
    else:
        size = float(s.size_m.draw(rng))
    steps = [StepSpec(angle_rad=float(rng.uniform(0.0, math.pi)), offset_m=float(s.step_offset.draw(rng)) * size,
                      height_m=float(s.step_height_m.draw(rng))) for _ in range(int(s.steps.draw(rng)))]
    cap = min(s.step_max_rise * c.distance_m * math.cos(c.tilt_rad) for c in cameras)
    total = sum(st.height_m for st in steps)
    if total > cap:
        steps = [dataclasses.replace(st, height_m=st.height_m * cap / total) for st in steps]
    return SurfaceSpec(size_m=size, grid_px=s.grid_px, crackmap_px=s.crackmap_px, steps=steps)


def scene_of(recipe: Recipe, index: int) -> int:
    """The scene sample ``index`` is a view of: ``index // views_per_scene`` (the sample itself when 1)."""
    return int(index) // recipe.camera.views_per_scene


def scene_cameras(recipe: Recipe, index: int) -> list[CameraSpec]:
    """The cameras of every view of sample ``index``'s scene, each from its own sample's streams: what the
    shared surface must cover and what the shared crack map is sized for. Depends on (recipe, index) only."""
    k = recipe.camera.views_per_scene
    first = scene_of(recipe, index) * k
    seed = recipe.dataset.seed
    return [_camera(recipe, section_rng(seed, v, "camera"), _stereo(recipe, section_rng(seed, v, "stereo")).baseline_m)
            for v in range(first, first + k)]


def crack_pixel_m(recipe: Recipe, spec: SampleSpec) -> float:
    """Camera pixel (m) the crack map sizes hairlines for: the widest of the scene's views (a hairline is at
    least ``hairline_px`` wide in every view); with one view per scene, that view's own."""
    return max(pixel_footprint_m(c) for c in scene_cameras(recipe, spec.index))


def make_spec(recipe: Recipe, index: int, attempt: int = 0) -> SampleSpec:
    """Draw every random parameter of sample ``index`` of ``recipe``, each section from its own stream.

    ``attempt`` > 0 redraws the crack only (see ``section_rng``); 0 is the sample as first drawn."""
    if not isinstance(recipe, Recipe):
        raise TypeError(f"make_spec: recipe must be a Recipe, got {type(recipe).__name__}")

    def rng(section: str) -> np.random.Generator:
        key = scene_of(recipe, index) if section in SCENE_SECTIONS else index
        return section_rng(recipe.dataset.seed, key, section, attempt)

    li = recipe.lights
    a = rng("ambient")
    lights = _lights(recipe, rng("lights"))
    stereo = _stereo(recipe, rng("stereo"))
    camera = _camera(recipe, rng("camera"), stereo.baseline_m)  # before the surface: the steps stay below it
    cameras = scene_cameras(recipe, index)  # [camera] with one view per scene
    material = _material(recipe, rng("material"))  # before the crack: its shape may depend on the family
    r = recipe.render
    return SampleSpec(
        index=int(index),
        recipe_seed=int(recipe.dataset.seed),
        crack=_crack(recipe, rng("crack"), material.family),
        surface=_surface(recipe, rng("surface"), cameras),
        material=material,
        lights=lights,
        ambient=AmbientSpec(strength=li.ambient_strength.draw(a), color_temp_k=li.ambient_color_temp_k.draw(a)),
        shadow=_shadow(recipe, rng("shadow"), len(lights)),
        camera=camera,
        render=RenderSpec(
            samples=r.samples, denoise=r.denoise, threads=r.threads, device=r.device,
            seed=_seed(rng("render")), max_bounces=r.max_bounces, **{k: getattr(r, k) for k in RENDER_KNOBS},
        ),
        tof=_tof(recipe, rng("tof")),
        lidar=_lidar(recipe, rng("lidar")),
        stereo=stereo,
        adapt=draw_adapt(recipe.adapt, rng("adapt")),
        camera_effects=draw_camera_effects(recipe.camera_effects, rng("camera_effects")),
        lens=_lens(recipe, rng("lens")),
        sky=_sky(recipe, rng("sky"), lights),
    )
