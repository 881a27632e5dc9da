"""Recipe: the TOML file a dataset is made from, validated into typed models.

Every field has a default and a unit in its name (``_m``, ``_deg``, ``_px``,
``_k``, ``_w``) or in its doc. Random parameters are distributions:
a constant, ``{min = a, max = b}`` (uniform) or ``{choices = [...], weights = [...]}``.
Unknown keys are errors, and so is any number that is not finite (TOML has ``nan``
and ``inf`` literals, and a NaN slips through every ``<``/``>`` range check).
``load_recipe`` refuses a bad recipe before any work, with one
``field.path: problem`` line per problem (``RecipeError``).
"""
from __future__ import annotations

import hashlib
import math
import tomllib
from pathlib import Path
from typing import Annotated, Any, Callable, Literal, Union

import numpy as np
from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError, model_validator
from pydantic_core import PydanticCustomError

from crackgen.errors import CrackgenError
from fusion.geometry.lens import Distortion

Scalar = Union[bool, int, float, str]


class RecipeError(CrackgenError, ValueError):
    """A recipe that cannot be used; ``problems`` holds one line per problem."""

    def __init__(self, problems: list[str], source: str = "recipe"):
        self.problems = problems
        self.source = source
        super().__init__("\n".join(problems))


class Dist(BaseModel):
    """A constant, a uniform ``{min, max}`` or a weighted ``{choices, weights}``."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    value: Scalar | None = None
    min: float | None = None
    max: float | None = None
    choices: list[Scalar] | None = None
    weights: list[float] | None = None

    @model_validator(mode="before")
    @classmethod
    def _wrap_constant(cls, data: Any) -> Any:
        if isinstance(data, (bool, int, float, str)):
            return {"value": data}
        if isinstance(data, list):
            raise PydanticCustomError("dist", "a list is not a distribution; use {choices = [...]}")
        return data

    @model_validator(mode="after")
    def _check_form(self) -> "Dist":
        _check_finite(self)
        forms = [self.value is not None, self.min is not None or self.max is not None, self.choices is not None]
        if sum(forms) != 1:
            raise PydanticCustomError("dist", "give a constant, {min, max} or {choices, weights}")
        if forms[1]:
            if self.min is None or self.max is None:
                missing = "min" if self.min is None else "max"
                raise PydanticCustomError("dist_sub", "{sub}: required with a range", {"sub": missing})
            if not self.max > self.min:
                raise PydanticCustomError("dist_sub", "{sub}: must be > {ref}", {"sub": "max", "ref": "min"})
        if forms[2]:
            if len(self.choices) == 0:
                raise PydanticCustomError("dist_sub", "{sub}: must not be empty", {"sub": "choices"})
            if self.weights is not None:
                if len(self.weights) != len(self.choices):
                    raise PydanticCustomError(
                        "dist_sub", "{sub}: must have one weight per choice", {"sub": "weights"}
                    )
                if any(w < 0 for w in self.weights) or sum(self.weights) <= 0:
                    raise PydanticCustomError(
                        "dist_sub", "{sub}: must be >= 0 with a positive sum", {"sub": "weights"}
                    )
        elif self.weights is not None:
            raise PydanticCustomError("dist_sub", "{sub}: only allowed with choices", {"sub": "weights"})
        return self

    def support(self) -> list[Scalar]:
        """Values the distribution can produce (range ends for uniform)."""
        if self.value is not None:
            return [self.value]
        if self.choices is not None:
            return list(self.choices)
        return [self.min, self.max]

    def draw(self, rng: np.random.Generator) -> Any:
        """One draw. Always consumes exactly one random number, so spec layouts stay stable."""
        u = float(rng.random())
        if self.value is not None:
            return self.value
        if self.choices is not None:
            w = np.asarray(self.weights if self.weights is not None else [1.0] * len(self.choices), float)
            cdf = np.cumsum(w / w.sum())
            return self.choices[min(int(np.searchsorted(cdf, u, side="right")), len(self.choices) - 1)]
        return float(self.min + (self.max - self.min) * u)

    def describe(self) -> str:
        if self.value is not None:
            return repr(self.value)
        if self.choices is not None:
            w = f" weights={self.weights}" if self.weights else ""
            return f"choice{self.choices}{w}"
        return f"uniform[{self.min:g}, {self.max:g}]"


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _check_finite(d: Dist) -> None:
    """Refuse NaN/inf anywhere in a distribution, naming the part (constant, min, max, choices, weights)."""
    if _is_number(d.value) and not math.isfinite(d.value):
        raise PydanticCustomError("dist", f"must be a finite number, got {d.value!r}", {})
    for sub in ("min", "max"):
        v = getattr(d, sub)
        if v is not None and not math.isfinite(v):
            raise PydanticCustomError("dist_sub", f"{{sub}}: must be a finite number, got {v!r}", {"sub": sub})
    for sub in ("choices", "weights"):
        bad = [v for v in getattr(d, sub) or [] if _is_number(v) and not math.isfinite(v)]
        if bad:
            raise PydanticCustomError("dist_sub", f"{{sub}}: every entry must be a finite number, got {bad[0]!r}", {"sub": sub})


def _numeric(lo: float, hi: float, integer: bool = False, lo_open: bool = False) -> Callable[[Dist], Dist]:
    def check(d: Dist) -> Dist:
        for v in d.support():
            if not _is_number(v):
                raise PydanticCustomError("dist", f"must be a number, got {v!r}", {})
            if integer and d.min is None and float(v) != int(v):
                raise PydanticCustomError("dist", f"must be an integer, got {v!r}", {})
            if (v <= lo if lo_open else v < lo) or v > hi:
                lb = "(" if lo_open else "["
                raise PydanticCustomError("dist", f"must be within {lb}{lo:g}, {hi:g}], got {v!r}", {})
        if integer and d.min is not None:
            raise PydanticCustomError("dist", "must be a constant or {choices}: an integer parameter", {})
        return d

    return check


def _one_of(*allowed: str) -> Callable[[Dist], Dist]:
    def check(d: Dist) -> Dist:
        if d.min is not None:
            raise PydanticCustomError("dist", "must be a constant or {choices}, not a range", {})
        for v in d.support():
            if v not in allowed:
                raise PydanticCustomError("dist", f"unknown value {v!r}; allowed: {', '.join(allowed)}", {})
        return d

    return check


class Section(BaseModel):
    # allow_inf_nan=False: plain float fields refuse nan/inf (pydantic's ge/le pass NaN otherwise)
    model_config = ConfigDict(extra="forbid", validate_default=True, allow_inf_nan=False)


# Field helpers: _t = numeric distribution type with range, _c = categorical type, _d = default + doc.
def _t(lo: float, hi: float, integer: bool = False, lo_open: bool = False) -> Any:
    return Annotated[Dist, AfterValidator(_numeric(lo, hi, integer, lo_open))]


def _c(*allowed: str) -> Any:
    return Annotated[Dist, AfterValidator(_one_of(*allowed))]


def _d(default: Any, doc: str) -> Any:
    return Field(default_factory=lambda: Dist.model_validate(default), description=doc)


FAMILIES = ("asphalt", "concrete", "masonry", "steel", "blockwork", "photo")  # = blender_assets/materials/*.toml
CLUTTER_KINDS = ("pores", "gaps", "stains", "moss", "patch", "voids")  # append only: new kinds draw last  # = crackgen.procedural.clutter.CLUTTER
SHAPES = ("fbm", "fracture", "network", "hairline", "stairstep")  # = crackgen.procedural.crack_shapes


class DatasetSection(Section):
    name: str = Field("crackgen", description="dataset name, written to the manifest")
    seed: int = Field(0, ge=0, le=2**63 - 1, description="root seed; sample i uses SeedSequence([seed, i])")
    samples: int = Field(8, ge=1, le=10_000_000, description="number of samples")
    shard_size: int = Field(4, ge=1, le=100_000, description="samples per shard (the unit of work)")


class CrackSection(Section):
    frequency_x: _t(0, 64, lo_open=True) = _d({"min": 1.5, "max": 4.0}, "fBm base frequency f_x, cycles per surface width")
    frequency_y: _t(0, 64, lo_open=True) = _d({"min": 1.5, "max": 4.0}, "fBm base frequency f_y, cycles per surface height")
    octaves: _t(1, 12, integer=True) = _d({"choices": [4, 5, 6]}, "fBm octaves O (integer)")
    persistence: _t(0, 1, lo_open=True) = _d({"min": 0.45, "max": 0.6}, "fBm persistence P (amplitude ratio per octave)")
    lacunarity: _t(1, 4, lo_open=True) = _d({"min": 1.9, "max": 2.2}, "fBm lacunarity L (frequency ratio per octave)")
    threshold: _t(0, 1, lo_open=True) = _d({"min": 0.015, "max": 0.04}, "mask = Z < threshold; sets crack width (unitless)")
    depth_m: _t(0, 0.2) = _d({"min": 0.004, "max": 0.015}, "crack depth (m) at the crack centre line")
    probability: float = Field(1.0, ge=0, le=1, description="chance that a sample has a crack at all; the rest are crack-free (fraction)")
    shape: _c(*SHAPES) = _d({"choices": ["fbm"]}, "crack shape family per sample: fbm (thesis), fracture, network, hairline or stairstep (along a wall's mortar joints; a fracture on surfaces without bricks)")
    shape_by_family: dict[str, Annotated[Dist, AfterValidator(_one_of(*SHAPES))]] = Field(
        default_factory=dict, description="per material family, its own shape distribution instead of shape, e.g. masonry = { choices = [\"stairstep\", \"hairline\"] }")
    width_m: _t(0, 0.5, lo_open=True) = _d(
        {"min": 0.002, "max": 0.012}, "fracture/network: full crack width at its widest point (m)"
    )
    count: _t(1, 16, integer=True) = _d({"choices": [1, 2, 3], "weights": [0.5, 0.35, 0.15]}, "fracture/hairline: main cracks per patch (integer)")
    branches: _t(0, 16, integer=True) = _d({"choices": [0, 1, 2, 3]}, "fracture/hairline: side branches per main crack (integer)")
    jaggedness: _t(0, 1) = _d(
        {"min": 0.08, "max": 0.2}, "path roughness: midpoint displacement s.d. / segment length, every octave (unitless)"
    )
    cells: _t(2, 200, integer=True) = _d({"choices": [6, 8, 10, 12, 16, 20]}, "network: Voronoi cells per patch (integer)")
    gaps: _t(0, 0.9) = _d({"min": 0.1, "max": 0.3}, "network: fraction of cell boundaries left uncracked")
    hairline_px: _t(0.5, 4) = _d({"min": 1.0, "max": 2.0}, "hairline: full width in camera pixels at the look-at point (px)")
    wall: _t(0, 1, lo_open=True) = _d(
        1.0, "fracture/network/hairline: share of the half-width the crack wall slopes over; 1 = V-groove, "
             "smaller = steep walls and a flat floor (fraction)"
    )

    @model_validator(mode="after")
    def _families_known(self) -> "CrackSection":
        for fam in self.shape_by_family:
            if fam not in FAMILIES:
                raise PydanticCustomError("field_ref", "{sub}: unknown material family %r (known: %s)"
                                          % (fam, ", ".join(FAMILIES)), {"sub": "shape_by_family"})
        return self


class SurfaceSection(Section):
    size_m: _t(0.05, 100, lo_open=True) = _d({"min": 2.0, "max": 3.0}, "side of the square surface patch (m)")
    grid_px: int = Field(384, ge=8, le=4096, description="mesh vertices per side")
    crackmap_px: int = Field(1024, ge=16, le=8192, description="crack map resolution per side (px)")
    steps: _t(0, 8, integer=True) = _d(0, "straight height steps across the patch (kerb, faulted slab edge): count per sample (integer, 0 = flat)")
    step_height_m: _t(0.001, 1) = _d({"min": 0.02, "max": 0.15}, "height of each step, raised side towards the cameras (m)")
    step_offset: _t(-0.5, 0.5) = _d({"min": -0.2, "max": 0.2}, "signed distance of a step's line from the patch centre (fraction of the side)")
    step_max_rise: float = Field(0.3, gt=0, le=0.8, description="the steps' total height is scaled down to at most this fraction of the camera's height above the patch (fraction)")
    size_fov: _t(0, 20) = _d(0.0, "patch side as a multiple of the camera's view width at the look-at point (0 = off: size_m); for recipes whose distance spans close-ups to metres")

    @model_validator(mode="after")
    def _fov_all_or_nothing(self) -> "SurfaceSection":
        sup = self.size_fov.support()
        if any(v > 0 for v in sup) and not all(v >= 0.5 for v in sup):
            raise PydanticCustomError("field_ref", "{sub}: 0 (off) or every value >= 0.5 (the patch must cover the view)",
                                      {"sub": "size_fov"})
        return self


class DistractorSection(Section):
    joint: float = Field(0.2, ge=0, le=1, description="probability of a straight joint line")
    sealant: float = Field(0.15, ge=0, le=1, description="probability of a sealant strip")
    stain: float = Field(0.3, ge=0, le=1, description="probability of stains")
    marking: float = Field(0.15, ge=0, le=1, description="probability of a painted road marking")
    formwork: float = Field(0.0, ge=0, le=1, description="probability of formwork panel joints and tie holes (concrete only)")
    rust_streak: float = Field(0.0, ge=0, le=1, description="probability of rust streaks running down from a few sources (not on asphalt)")


class ClutterSection(Section):
    """Real-world surface clutter, never labelled: the dark non-crack structure real photos have."""

    pores: float = Field(0.0, ge=0, le=1, description="probability of pores and voids (dark pits, 0.5-5 mm)")
    gaps: float = Field(0.0, ge=0, le=1, description="probability of aggregate gaps (short dark curved gaps between stones)")
    stains: float = Field(0.0, ge=0, le=1, description="probability of small stains (grime and rust spots)")
    moss: float = Field(0.0, ge=0, le=1, description="probability of moss / lichen in low areas")
    patch: float = Field(0.0, ge=0, le=1, description="probability of a paint or patch repair (other material, visible edge)")
    voids: float = Field(0.0, ge=0, le=1, description="probability of bugholes / surface voids (sparse dark holes, 3-24 mm)")
    amount: _t(0, 1) = _d({"min": 0.3, "max": 1.0}, "amount (number / coverage) of each present kind, fraction of its maximum")


class MaterialSection(Section):
    family: _c(*FAMILIES) = _d(
        {"choices": list(FAMILIES[:5]), "weights": [0.4, 0.3, 0.1, 0.1, 0.1]},
        "material family (blender_assets/materials); 'photo' needs photo_folder",
    )
    texture_px: int = Field(1024, ge=16, le=8192, description="texture map resolution per side (px)")
    hue_shift: _t(-0.5, 0.5) = _d({"min": -0.05, "max": 0.05}, "colour variation (fraction)")
    value_scale: _t(0, 4, lo_open=True) = _d({"min": 0.8, "max": 1.2}, "albedo brightness multiplier")
    roughness_offset: _t(-1, 1) = _d({"min": -0.1, "max": 0.1}, "added to the family roughness")
    crack_darkening: _t(0, 1) = _d({"min": 0.15, "max": 0.45}, "albedo multiplier inside cracks")
    crack_roughness: _t(0, 1) = _d({"min": 0.8, "max": 1.0}, "roughness inside cracks")
    distractors: DistractorSection = Field(default_factory=DistractorSection)
    crack_cavity: _t(0, 1) = _d(0.0, "cavity darkening inside cracks (0 = off, 1 = near-black at deep narrow centres)")
    crack_dirt: float = Field(0.0, ge=0, le=1, description="probability of dust / debris partly filling the cracks")
    crack_spall: float = Field(0.0, ge=0, le=1, description="probability of spalled (chipped) crack edges, unlabelled")
    photo_folder: str = Field("", max_length=4096, description='folder of crack-free surface photos for family "photo"')
    photo_size_m: _t(0.01, 100) = _d({"min": 0.3, "max": 1.0}, "surface side covered by one photo side (m)")
    photo_clean: _c("none", "blackhat", "wide") = _d("blackhat", "photo: suppress dark lines (possible cracks) before use: blackhat (thin lines) or wide (also wide open cracks)")
    clutter: ClutterSection = Field(default_factory=ClutterSection)
    joint_relief_m: _t(0, 0.05) = _d(
        0.0, "masonry/blockwork: mortar recess below the brick faces as mesh relief (m), so raking light casts the "
        "course-edge shadows of a real wall; 0 = the family's recess in the normal map only")

    @model_validator(mode="after")
    def _photo_needs_folder(self) -> "MaterialSection":
        w = self.family.weights or [1.0] * len(self.family.support())
        if any(v == "photo" and wt > 0 for v, wt in zip(self.family.support(), w)) and not self.photo_folder.strip():
            raise PydanticCustomError("field_ref", "{sub}: required when family can be 'photo'", {"sub": "photo_folder"})
        return self


class LightsSection(Section):
    count: _t(1, 8, integer=True) = _d({"choices": [1, 2]}, "number of lights (integer)")
    kind: _c("sun", "area", "spot", "point") = _d(
        {"choices": ["sun", "area", "spot"], "weights": [0.5, 0.3, 0.2]}, "light type"
    )
    elevation_deg: _t(1, 90) = _d({"min": 20, "max": 80}, "light elevation above the surface (deg)")
    azimuth_deg: _t(-360, 360) = _d({"min": 0, "max": 360}, "light azimuth (deg)")
    distance_m: _t(0.1, 1000, lo_open=True) = _d({"min": 2.0, "max": 5.0}, "area/spot/point distance to the surface centre (m)")
    irradiance_w_m2: _t(0, 1000) = _d(
        {"min": 2.0, "max": 6.0},
        "area/spot/point irradiance at the surface centre (W/m^2); power = E*4*pi*d^2 (point, spot) or E*pi*d^2 (area)",
    )
    sun_irradiance_w_m2: _t(0, 1000) = _d({"min": 2.0, "max": 6.0}, "sun strength (W/m^2, Blender units)")
    sun_angle_deg: _t(0, 30) = _d({"min": 0.5, "max": 5.0}, "sun angular diameter (deg): shadow softness")
    size_m: _t(0, 100) = _d({"min": 0.1, "max": 1.0}, "area light size / point+spot radius (m)")
    spot_angle_deg: _t(1, 180) = _d({"min": 30, "max": 70}, "spot cone angle (deg)")
    color_temp_k: _t(1000, 40000) = _d({"min": 3500, "max": 7500}, "light colour temperature (K)")
    ambient_strength: _t(0, 100) = _d({"min": 0.05, "max": 0.4}, "sky/ambient strength (0 = off)")
    ambient_color_temp_k: _t(1000, 40000) = _d({"min": 5500, "max": 10000}, "sky colour temperature (K)")
    sky: float = Field(0.0, ge=0, le=1, description="probability that the world is a procedural daylight sky (Hosek-Wilkie; sun where the first sun lamp is) instead of the uniform ambient (0 = off)")
    sky_turbidity: _t(1, 10) = _d({"min": 2.0, "max": 8.0}, "sky haze (2 = clear blue, 10 = hazy white)")
    sky_ground_albedo: _t(0, 1) = _d({"min": 0.1, "max": 0.5}, "ground reflectance lighting the sky from below (0..1)")
    sky_overcast: float = Field(0.3, ge=0, le=1, description="probability that a sky sample is overcast")
    sky_overcast_amount: _t(0, 1) = _d({"min": 0.6, "max": 1.0}, "overcast: share of the sky that is a uniform cloud deck, and how much the sun lamps are dimmed (0..1)")


class ShadowSection(Section):
    probability: float = Field(0.6, ge=0, le=1, description="chance that a sample has a shadow occluder")
    pattern: _c("noise", "shapes", "stripes") = _d({"choices": ["noise", "shapes", "stripes"]}, "occluder alpha pattern")
    height_m: _t(0.01, 100) = _d({"min": 0.2, "max": 0.8}, "occluder distance from the surface along the light (m)")
    size_m: _t(0.01, 100) = _d({"min": 1.0, "max": 2.5}, "occluder side (m)")
    coverage: _t(0, 1) = _d({"min": 0.3, "max": 0.7}, "opaque fraction of the occluder")
    softness: _t(0, 0.5) = _d({"min": 0.0, "max": 0.05}, "edge blur, fraction of occluder size")
    offset_m: _t(-100, 100) = _d({"min": -0.3, "max": 0.3}, "occluder centre offset across the light ray (m)")


class DistortionSection(Section):
    """Brown-Conrady lens distortion, OpenCV convention (``fusion.geometry.lens``), drawn per sample. Off by default."""

    probability: float = Field(0.0, ge=0, le=1, description="share of samples taken through a distorting lens (0 = pinhole, the default)")
    k1: _t(-1, 1) = _d({"min": -0.1, "max": 0.05}, "radial k1 (negative = barrel: wide-angle lenses)")
    k2: _t(-1, 1) = _d({"min": 0.0, "max": 0.04}, "radial k2")
    k3: _t(-1, 1) = _d(0.0, "radial k3")
    p1: _t(-0.05, 0.05) = _d({"min": -0.001, "max": 0.001}, "tangential p1 (decentring)")
    p2: _t(-0.05, 0.05) = _d({"min": -0.001, "max": 0.001}, "tangential p2 (decentring)")


class CameraSection(Section):
    width_px: int = Field(512, ge=8, le=16384, description="RGB image width (px)")
    height_px: int = Field(512, ge=8, le=16384, description="RGB image height (px)")
    distance_m: _t(0.05, 100) = _d({"min": 0.6, "max": 1.2}, "camera to look-at point (m)")
    tilt_deg: _t(0, 80) = _d({"min": 0, "max": 25}, "optical axis vs surface normal (deg)")
    azimuth_deg: _t(-360, 360) = _d({"min": 0, "max": 360}, "camera azimuth (deg)")
    roll_deg: _t(-180, 180) = _d({"min": -10, "max": 10}, "roll about the optical axis (deg)")
    focal_mm: _t(1, 1000) = _d({"min": 24, "max": 40}, "focal length (mm)")
    sensor_width_mm: float = Field(36.0, gt=0, le=100, description="sensor width (mm)")
    principal_jitter_px: _t(-1000, 1000) = _d({"min": -4, "max": 4}, "optical-centre jitter (px)")
    target_jitter_m: _t(-100, 100) = _d({"min": -0.1, "max": 0.1}, "look-at point jitter on the surface (m)")
    distortion: DistortionSection = Field(default_factory=DistortionSection)
    views_per_scene: int = Field(1, ge=1, le=64, description="samples made from one surface, crack and material build, "
                                 "each with its own camera pose, lights, shadow and sensors (1 = a new scene per sample)")

    @model_validator(mode="after")
    def _lens_does_not_fold(self) -> "CameraSection":
        """Every lens the ranges allow must map the widest view one-to-one (the warp needs an inverse)."""
        d = self.distortion
        if d.probability <= 0:
            return self
        f_px = min(self.focal_mm.support()) / self.sensor_width_mm * self.width_px
        # the corner at the widest view, with the largest principal-point jitter
        jitter = max(abs(v) for v in self.principal_jitter_px.support())
        r = math.hypot(self.width_px / 2 + jitter, self.height_px / 2 + jitter) / f_px
        for k1 in d.k1.support():  # the slope is linear in (k1, k2, k3): its worst case is a corner of the box
            for k2 in d.k2.support():
                for k3 in d.k3.support():
                    if not Distortion(k1=k1, k2=k2, k3=k3).reaches(1.05 * r):
                        raise PydanticCustomError(
                            "field_ref", "{sub}: k1 = %g, k2 = %g, k3 = %g fold the lens back before the image corner "
                            "at the shortest focal_mm (no one-to-one warp); narrow the ranges" % (k1, k2, k3),
                            {"sub": "distortion"})
        return self


class RenderSection(Section):
    samples: int = Field(16, ge=1, le=65536, description="Cycles samples per pixel")
    denoise: bool = Field(True, description="OpenImageDenoise")
    threads: int = Field(0, ge=0, le=1024, description="Cycles threads (0 = split between workers)")
    device: str = Field("cpu", pattern="^(cpu|gpu)$", description="cpu | gpu (falls back to cpu with a warning)")
    max_bounces: int = Field(4, ge=0, le=128, description="Cycles max light bounces (total, caps every kind below)")
    # Speed/quality knobs (issue 12). Every default is Blender 4.5's factory value, so a recipe
    # without them renders exactly as before; `crackgen bench --sweep` measures what they buy.
    adaptive_sampling: bool = Field(True, description="Cycles adaptive sampling: stop pixels whose noise is below adaptive_threshold")
    adaptive_threshold: float = Field(0.01, ge=0, le=1, description="adaptive sampling noise threshold (0 = automatic from samples)")
    adaptive_min_samples: int = Field(0, ge=0, le=65536, description="samples before adaptive sampling may stop a pixel (0 = automatic)")
    denoise_prefilter: Literal["none", "fast", "accurate"] = Field(
        "accurate", description="OIDN prefilter of the albedo/normal guide passes: none, fast or accurate")
    denoise_passes: Literal["rgb", "rgb_albedo", "rgb_albedo_normal"] = Field(
        "rgb_albedo_normal", description="guide passes given to OIDN: rgb, rgb_albedo or rgb_albedo_normal")
    denoise_quality: Literal["high", "balanced", "fast"] = Field("high", description="OIDN quality: high, balanced or fast")
    diffuse_bounces: int = Field(4, ge=0, le=1024, description="Cycles max diffuse bounces")
    glossy_bounces: int = Field(4, ge=0, le=1024, description="Cycles max glossy bounces")
    transmission_bounces: int = Field(12, ge=0, le=1024, description="Cycles max transmission bounces")
    transparent_bounces: int = Field(8, ge=0, le=1024, description="Cycles max transparent bounces (the shadow occluder is transparent)")
    caustics_reflective: bool = Field(True, description="Cycles reflective caustics (false = filtered out)")
    caustics_refractive: bool = Field(True, description="Cycles refractive caustics (false = filtered out)")
    light_tree: bool = Field(True, description="Cycles light tree (many-light sampling)")
    fast_gi: bool = Field(False, description="Cycles fast GI approximation (AO after ao_bounces bounces)")
    ao_bounces: int = Field(1, ge=0, le=1024, description="fast GI: bounces before the AO approximation takes over")
    clamp_direct: float = Field(0.0, ge=0, le=1e6, description="Cycles direct-light sample clamp (0 = off)")
    clamp_indirect: float = Field(10.0, ge=0, le=1e6, description="Cycles indirect-light sample clamp (0 = off)")
    persistent_data: bool = Field(False, description="keep Cycles scene data between samples (textures swap between two images)")


class TofSection(Section):
    enabled: bool = Field(True, description="simulate the offset ToF camera")
    width_px: int = Field(320, ge=8, le=4096, description="ToF sensor width (px)")
    height_px: int = Field(240, ge=8, le=4096, description="ToF sensor height (px)")
    hfov_deg: float = Field(62.0, gt=1, lt=179, description="ToF horizontal field of view (deg)")
    vfov_deg: float = Field(49.0, gt=1, lt=179, description="ToF vertical field of view (deg)")
    offset_x_m: _t(-10, 10) = _d({"min": 0.02, "max": 0.08}, "ToF offset right of the RGB camera (m)")
    offset_y_m: _t(-10, 10) = _d({"min": -0.01, "max": 0.01}, "ToF offset down from the RGB camera (m)")
    offset_z_m: _t(-10, 10) = _d({"min": -0.005, "max": 0.005}, "ToF offset forward of the RGB camera (m)")
    rotation_jitter_deg: _t(-45, 45) = _d({"min": -1.0, "max": 1.0}, "per-axis rotation jitter vs RGB camera (deg)")
    sigma0_m: float = Field(0.001, ge=0, le=1, description="range noise floor sigma0 (m); 0 = off")
    k_noise: float = Field(2.4e-6, ge=0, le=1, description="sigma = sigma0 + k*d^2/A (m); 4 mm at 5 m, albedo 0.5")
    amplitude_scale: float = Field(1.0, gt=0, le=1e6, description="A = scale*albedo*cos(theta)/d^2")
    min_amplitude: float = Field(0.005, ge=0, le=1e6, description="dropout below this amplitude (0 = off)")
    grazing_deg: float = Field(80.0, gt=0, le=90, description="dropout beyond this incidence angle (deg; 90 = off)")
    flying_pixels: bool = Field(True, description="mixed pixels at depth discontinuities")
    wrap_range_m: float = Field(0.0, ge=0, le=1000, description="phase-wrap (unambiguous) range (m); 0 = off")
    bias_m: _t(-1, 1) = _d({"min": -0.003, "max": 0.003}, "per-sample range bias (m)")


class LidarSection(Section):
    enabled: bool = Field(True, description="simulate the ring-scanning LiDAR")
    beams: int = Field(16, ge=1, le=512, description="number of beams (rings)")
    vfov_min_deg: float = Field(-15.0, ge=-90, le=90, description="lowest beam elevation (deg)")
    vfov_max_deg: float = Field(15.0, ge=-90, le=90, description="highest beam elevation (deg)")
    hfov_deg: float = Field(90.0, gt=0, le=360, description="azimuth sweep centred on the optical axis (deg)")
    azimuth_step_deg: float = Field(0.2, gt=0, le=10, description="azimuth resolution (deg)")
    max_range_m: float = Field(100.0, gt=0, le=10000, description="maximum range (m)")
    sigma_m: float = Field(0.02, ge=0, le=10, description="range noise std (m); 0 = off")
    dropout: float = Field(0.05, ge=0, lt=1, description="random return loss fraction")
    offset_x_m: _t(-10, 10) = _d({"min": -0.05, "max": 0.05}, "LiDAR offset right of the RGB camera (m)")
    offset_y_m: _t(-10, 10) = _d({"min": -0.12, "max": -0.06}, "LiDAR offset down from the RGB camera (m)")
    offset_z_m: _t(-10, 10) = _d(0.0, "LiDAR offset forward of the RGB camera (m)")
    rotation_jitter_deg: _t(-45, 45) = _d({"min": -1.0, "max": 1.0}, "per-axis rotation jitter (deg)")

    @model_validator(mode="after")
    def _order(self) -> "LidarSection":
        if not self.vfov_max_deg > self.vfov_min_deg:
            raise PydanticCustomError("field_ref", "{sub}: must be > {ref}", {"sub": "vfov_max_deg", "ref": "vfov_min_deg"})
        return self


class StereoSection(Section):
    enabled: bool = Field(False, description="render a right camera and compute SGBM disparity")
    baseline_m: _t(0.001, 10) = _d({"min": 0.06, "max": 0.12}, "stereo baseline (m)")
    num_disparities: int = Field(128, ge=16, le=1024, multiple_of=16, description="SGBM search range (px, x16)")
    block_size: int = Field(5, ge=1, le=31, description="SGBM block size (odd, px)")
    sgbm_input: Literal["clean", "camera"] = Field(
        "clean", description="images SGBM matches: clean = the render; camera = after [camera_effects] "
        "(noise, blur, JPEG), as a real stereo camera sees them")

    @model_validator(mode="after")
    def _odd(self) -> "StereoSection":
        if self.block_size % 2 == 0:
            raise PydanticCustomError("field_ref", "{sub}: must be odd", {"sub": "block_size"})
        return self


ADAPT_METHODS = ("fourier", "reinhard", "histogram")  # = crackgen.postrender.adapt.METHODS


class AdaptSection(Section):
    """Post-render appearance adaptation toward a folder of unlabeled target photos (RGB views only)."""

    target: str = Field("", max_length=4096,
                        description='folder of unlabeled target photos ("" = off; relative to the working directory)')
    probability: float = Field(1.0, ge=0.0, le=1.0, description="chance that a sample is adapted (0..1)")
    method: _c(*ADAPT_METHODS) = _d(
        {"choices": list(ADAPT_METHODS), "weights": [0.5, 0.25, 0.25]},
        "fourier (FDA low-frequency amplitude swap), reinhard (Lab mean/std) or histogram (per-channel CDF)",
    )
    band: _t(0.0, 0.5) = _d({"min": 0.005, "max": 0.05},
                            "fourier: half-width of the swapped low-frequency square (fraction of min(H, W))")

    @property
    def enabled(self) -> bool:
        return bool(self.target.strip()) and self.probability > 0


class CameraEffectsSection(Section):
    """Post-render camera effects on the RGB views (labels, depth and sensors untouched).

    Each effect has its own probability; the order and formulas are in
    ``crackgen.postrender.camera_effects``. Off by default."""

    enabled: bool = Field(False, description="apply camera effects to the RGB views (false = off)")
    exposure: float = Field(0.5, ge=0, le=1, description="probability of an exposure error (0..1)")
    exposure_ev: _t(-8, 8) = _d({"min": -1.0, "max": 1.0}, "exposure shift (EV, stops): linear light x 2**ev")
    white_balance: float = Field(0.5, ge=0, le=1, description="probability of a white-balance error (0..1)")
    wb_shift_mired: _t(-300, 300) = _d(
        {"min": -40.0, "max": 40.0},
        "light colour-temperature shift vs the camera's 6500 K white (mired = 1e6/K); positive = warmer image",
    )
    wb_tint: _t(-0.5, 0.5) = _d({"min": -0.05, "max": 0.05}, "green gain x (1 + tint) (fraction; negative = magenta)")
    tone: float = Field(0.5, ge=0, le=1, description="probability of a tone curve (0..1)")
    tone_gamma: _t(0.2, 5) = _d({"min": 0.8, "max": 1.25}, "exponent on display values y = x**gamma (unitless; >1 darker)")
    tone_contrast: _t(-1, 1) = _d(
        {"min": -0.3, "max": 0.5}, "S-curve strength c: y + c*(smoothstep(y) - y) (unitless; 0 = none)"
    )
    vignetting: float = Field(0.5, ge=0, le=1, description="probability of vignetting (0..1)")
    vignette_strength: _t(0, 0.95) = _d(
        {"min": 0.1, "max": 0.5}, "fraction of light lost at the image corners: gain 1 - s*(r/r_corner)^2"
    )
    defocus: float = Field(0.3, ge=0, le=1, description="probability of defocus blur (0..1)")
    defocus_kernel: _c("disk", "gaussian") = _d({"choices": ["disk", "gaussian"]}, "defocus PSF shape")
    defocus_radius_px: _t(0, 50, lo_open=True) = _d(
        {"min": 0.5, "max": 2.0}, "defocus PSF radius (px); gaussian sigma = radius/2"
    )
    motion_blur: float = Field(0.2, ge=0, le=1, description="probability of motion blur (0..1)")
    motion_length_px: _t(0, 100, lo_open=True) = _d({"min": 1.0, "max": 6.0}, "motion blur line length (px)")
    motion_angle_deg: _t(-360, 360) = _d({"min": 0.0, "max": 180.0}, "motion direction in the image (deg, 0 = x)")
    noise: float = Field(0.8, ge=0, le=1, description="probability of Poisson-Gaussian sensor noise (0..1)")
    noise_full_well_e: _t(1, 1e7) = _d(
        {"min": 500.0, "max": 5000.0}, "electrons at linear 1.0: shot-noise variance = x/full_well (e-)"
    )
    noise_read_e: _t(0, 1e4) = _d({"min": 1.0, "max": 5.0}, "read-noise std (electrons)")
    jpeg: float = Field(0.5, ge=0, le=1, description="probability of JPEG re-compression (0..1)")
    jpeg_quality: _t(1, 100) = _d({"min": 60.0, "max": 95.0}, "JPEG quality (1-100, rounded to an integer)")
    auto_exposure: float = Field(0.0, ge=0, le=1, description="probability of auto exposure: the gain that brings the "
                                 "image's mean luma to a drawn target, before any exposure error (0..1)")
    auto_exposure_luma: _t(1, 254) = _d({"min": 100.0, "max": 180.0},
                                        "auto exposure: target mean luma of the sRGB image (0-255)")
    sharpen: float = Field(0.0, ge=0, le=1, description="probability of in-camera sharpening: an unsharp mask on the "
                           "luma before JPEG (0..1)")
    sharpen_amount: _t(0, 10) = _d({"min": 0.5, "max": 2.0}, "sharpening gain on the luma detail (unitless; 0 = none)")
    sharpen_sigma_px: _t(0, 20, lo_open=True) = _d({"min": 0.7, "max": 1.5},
                                                   "sharpening Gaussian sigma (px): the detail scale boosted")


class LabelSection(Section):
    """What the GT mask marks: the crack a person sees (visible) or the thesis mask Z < t (eq. 5.5)."""

    policy: Literal["visible", "thesis"] = Field("visible",
                        description="visible: crack deep relative to its opening (thesis mask kept as mask_thesis.png); thesis: Z < t")
    depth_ratio: float = Field(0.5, ge=0, le=100,
                               description="visible: crack texel depth must be >= ratio x local crack half-width (unitless)")
    min_depth_m: float = Field(0.002, ge=0, le=1, description="visible: crack texel depth must also be >= this (m)")
    min_component_px: int = Field(4, ge=0, le=1_000_000,
                                  description="visible: drop label components smaller than this (camera px; 0 = keep all)")
    min_contrast: float = Field(0.1, ge=0, le=1,
                                description="crack shows if (ring - inside) / ring median luminance >= this (unitless)")
    invisible: Literal["empty", "redraw", "keep"] = Field("empty",
                           description="crack that does not show: empty (label cleared), redraw (new crack) or keep")
    max_redraws: int = Field(2, ge=0, le=100, description="redraw: new cracks tried before falling back to empty")


# (section, key) -> default of options that a recipe's hash leaves out while at that default (see Recipe.hash).
HASH_NEUTRAL_DEFAULTS: dict[tuple[str, str], Any] = {
    ("camera", "views_per_scene"): 1,
    ("material.distractors", "formwork"): 0.0,
    ("material.distractors", "rust_streak"): 0.0,
    ("material", "joint_relief_m"): Dist(value=0.0),
}


class Recipe(Section):
    dataset: DatasetSection = Field(default_factory=DatasetSection)
    crack: CrackSection = Field(default_factory=CrackSection)
    surface: SurfaceSection = Field(default_factory=SurfaceSection)
    material: MaterialSection = Field(default_factory=MaterialSection)
    lights: LightsSection = Field(default_factory=LightsSection)
    shadow: ShadowSection = Field(default_factory=ShadowSection)
    camera: CameraSection = Field(default_factory=CameraSection)
    render: RenderSection = Field(default_factory=RenderSection)
    tof: TofSection = Field(default_factory=TofSection)
    lidar: LidarSection = Field(default_factory=LidarSection)
    stereo: StereoSection = Field(default_factory=StereoSection)
    adapt: AdaptSection = Field(default_factory=AdaptSection)
    camera_effects: CameraEffectsSection = Field(default_factory=CameraEffectsSection)
    label: LabelSection = Field(default_factory=LabelSection)

    # set by load_recipe; not part of the schema
    _text: str = ""

    @model_validator(mode="after")
    def _stereo_input(self) -> "Recipe":
        if self.stereo.enabled and self.stereo.sgbm_input == "camera" and not self.camera_effects.enabled:
            raise PydanticCustomError("field_ref", "{sub}: \"camera\" needs [camera_effects] enabled = true",
                                      {"sub": "stereo.sgbm_input"})
        if self.stereo.enabled and self.stereo.num_disparities >= self.camera.width_px:
            raise PydanticCustomError("field_ref", "{sub}: must be less than {ref} (SGBM searches inside the image)",
                                      {"sub": "stereo.num_disparities", "ref": "camera.width_px"})
        return self

    @property
    def text(self) -> str:
        """The TOML text the recipe came from (stored in the manifest)."""
        return self._text

    @property
    def hash(self) -> str:
        """sha256 of the canonical (defaults filled) recipe, so equivalent files hash alike.

        Options added after datasets were made (``HASH_NEUTRAL_DEFAULTS``) are left out while at their default,
        so those datasets keep their hash: their shards stay byte-identical and ``--resume`` accepts them."""
        leave_out: dict[str, Any] = {}
        for (section, key), default in HASH_NEUTRAL_DEFAULTS.items():
            parts = section.split(".")
            obj = self
            for part in parts:
                obj = getattr(obj, part)
            if getattr(obj, key) == default:
                node = leave_out
                for part in parts:
                    node = node.setdefault(part, {})
                node[key] = True
        return hashlib.sha256(self.model_dump_json(exclude=leave_out or None).encode()).hexdigest()

    @property
    def num_shards(self) -> int:
        return -(-self.dataset.samples // self.dataset.shard_size)


def _format_errors(err: ValidationError) -> list[str]:
    lines = []
    for e in err.errors():
        loc = ".".join(str(p) for p in e["loc"] if not str(p).startswith("function-after"))
        ctx = e.get("ctx") or {}
        if e["type"] == "extra_forbidden":
            lines.append(f"{loc}: unknown key")
        elif e["type"] == "finite_number":
            lines.append(f"{loc}: must be a finite number, got {e['input']!r}")
        elif "sub" in ctx:
            text = e["msg"].split(": ", 1)[1]
            if "ref" in ctx:
                text = text.replace(str(ctx["ref"]), f"{loc}.{ctx['ref']}" if loc else str(ctx["ref"]))
            lines.append(f"{loc + '.' if loc else ''}{ctx['sub']}: {text}")
        else:
            lines.append(f"{loc or 'recipe'}: {e['msg']}")
    return lines


def parse_recipe(text: str, source: str = "recipe") -> Recipe:
    """Validate TOML text; raise RecipeError with one line per problem."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise RecipeError([f"{source}: not valid TOML: {exc}"], source) from None
    try:
        recipe = Recipe.model_validate(data)
    except ValidationError as exc:
        raise RecipeError(_format_errors(exc), source) from None
    recipe._text = text
    return recipe


def load_recipe(path: str | Path) -> Recipe:
    p = Path(path)
    if not p.is_file():
        raise RecipeError([f"{p}: recipe file not found"], str(p))
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise RecipeError([f"{p}: cannot read recipe: {exc}"], str(p)) from None
    return parse_recipe(text, str(p))


def summary(recipe: Recipe) -> str:
    """Human summary for ``crackgen validate``."""
    d = recipe.dataset
    lines = [
        f"dataset {d.name!r}: {d.samples} samples in {recipe.num_shards} shards of {d.shard_size}, seed {d.seed}",
        f"image {recipe.camera.width_px}x{recipe.camera.height_px} px, {recipe.render.samples} spp "
        f"({recipe.render.device}, denoise={'on' if recipe.render.denoise else 'off'})",
        f"sensors: tof={'on' if recipe.tof.enabled else 'off'} "
        f"({recipe.tof.width_px}x{recipe.tof.height_px}), lidar={'on' if recipe.lidar.enabled else 'off'} "
        f"({recipe.lidar.beams} beams), stereo={'on' if recipe.stereo.enabled else 'off'}",
    ]
    for name in ("crack", "surface", "material", "lights", "shadow", "camera"):
        sec = getattr(recipe, name)
        parts = []
        for key, val in sec:
            if isinstance(val, Dist):
                parts.append(f"{key}={val.describe()}")
        if parts:
            lines.append(f"  [{name}] " + ", ".join(parts))
    lines.append(f"recipe hash {recipe.hash[:16]}")
    return "\n".join(lines)
