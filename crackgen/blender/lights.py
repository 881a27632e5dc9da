"""Lights and ambient sky of the live scene: a fixed pool, re-parameterised per sample.

Why a pool: creating and deleting light datablocks per sample grows ``bpy.data``
and forces Cycles to rebuild its light tree; instead ``max_lights`` lights are made
once and unused ones are hidden (``hide_render`` and zero energy). A light's type
(sun/area/spot/point) is a property of its datablock and changes in place.
Colour temperature uses Blender's own blackbody (``Light.use_temperature``, and a
Blackbody node for the sky), whose colour is normalised to unit luminance, so
``intensity`` keeps its meaning whatever the temperature.
"""
from __future__ import annotations

import math

import bpy
import numpy as np
from mathutils import Matrix

from crackgen.config.spec import AmbientSpec, LightSpec, SkySpec
from crackgen.errors import CrackgenError

LIGHT_KINDS = ("sun", "area", "spot", "point")


class LightError(CrackgenError, ValueError):
    """A light spec the pool cannot show (names the field)."""


def light_direction(elevation_rad: float, azimuth_rad: float) -> np.ndarray:
    """Unit vector from the surface centre toward the light (world frame, z up)."""
    ce = math.cos(elevation_rad)
    return np.array([ce * math.cos(azimuth_rad), ce * math.sin(azimuth_rad), math.sin(elevation_rad)])


def frame_facing(d: np.ndarray) -> np.ndarray:
    """3x3 rotation whose local +z is ``d`` (lights shine down local -z; planes face +z).

    Local x is horizontal (perpendicular to d and world z) so the frame is well defined
    for every elevation except straight overhead, where world x is used.
    """
    d = np.asarray(d, float) / np.linalg.norm(d)
    x = np.cross([0.0, 0.0, 1.0], d)
    if np.linalg.norm(x) < 1e-9:
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(d, x)
    return np.stack([x, y, d], axis=1)


def light_matrix(spec: LightSpec) -> np.ndarray:
    """4x4 world pose of a light: at ``distance_m`` along its direction, shining at the surface centre."""
    d = light_direction(spec.elevation_rad, spec.azimuth_rad)
    M = np.eye(4)
    M[:3, :3] = frame_facing(d)
    M[:3, 3] = spec.distance_m * d
    return M


class LightPool:
    """``max_lights`` light objects created once; ``update`` shows the sample's lights."""

    def __init__(self, scene: bpy.types.Scene, max_lights: int):
        if max_lights < 1:
            raise LightError(f"max_lights must be >= 1, got {max_lights!r}")
        self.objects: list[bpy.types.Object] = []
        for k in range(int(max_lights)):
            data = bpy.data.lights.new(f"crackgen_light_{k}", "SUN")
            obj = bpy.data.objects.new(f"crackgen_light_{k}", data)
            scene.collection.objects.link(obj)
            data.use_temperature = True
            data.use_shadow = True
            obj.hide_render = True
            self.objects.append(obj)

    def update(self, lights: list[LightSpec], sun_scale: float = 1.0) -> list[dict]:
        """Pose and parameterise the first ``len(lights)`` lights, hide the rest; returns their meta.

        ``sun_scale`` multiplies every sun lamp's strength (an overcast sky dims the sun)."""
        if len(lights) > len(self.objects):
            raise LightError(f"spec has {len(lights)} lights but the scene was built for {len(self.objects)} (max_lights)")
        meta = []
        for k, obj in enumerate(self.objects):
            data = obj.data
            if k >= len(lights):
                obj.hide_render = True
                data.energy = 0.0
                continue
            s = lights[k]
            if s.kind not in LIGHT_KINDS:
                raise LightError(f"lights[{k}].kind must be one of {', '.join(LIGHT_KINDS)}, got {s.kind!r}")
            if data.type != s.kind.upper():
                data.type = s.kind.upper()
                data = obj.data  # type change re-wraps the datablock as the new subclass
            data.temperature = float(s.color_temp_k)
            data.energy = float(s.intensity) * (float(sun_scale) if s.kind == "sun" else 1.0)
            if s.kind == "sun":
                data.angle = float(s.size_m)
            elif s.kind == "area":
                data.shape = "SQUARE"
                data.size = float(s.size_m)
            else:
                data.shadow_soft_size = float(s.size_m)
                if s.kind == "spot":
                    data.spot_size = float(s.spot_angle_rad)
                    data.spot_blend = 0.15  # soft cone edge; not a spec draw (fixed look)
            M = light_matrix(s)
            obj.matrix_world = Matrix(M.tolist())
            obj.hide_render = False
            meta.append({"kind": s.kind, "rgb": [float(x) for x in data.temperature_color], "matrix_world": M.tolist()})
        return meta


# A Hosek-Wilkie sky (no sun disc) lights a horizontal white plane with 0.05-0.19 of a uniform background of
# strength 1 (sun 20-70 deg, turbidity 2-8; measured with Cycles). This gain makes a mid sky (45 deg, turbidity 5)
# as bright as the uniform ambient of the same strength, so ambient_strength keeps its meaning; clear skies are
# then dimmer and bluer, hazy ones brighter and whiter, as outdoors.
SKY_GAIN = 8.0


class Sky:
    """The world, two node trees built once: a uniform ambient (Background <- Blackbody) and a procedural
    daylight sky (Hosek-Wilkie texture x SKY_GAIN, mixed with the uniform colour by the overcast share).
    ``update`` points the scene at one of them, so samples without a sky render exactly as before."""

    def __init__(self, scene: bpy.types.Scene):
        self.scene = scene
        world = bpy.data.worlds.new("crackgen_world")
        world.use_nodes = True
        nt = world.node_tree
        nt.nodes.clear()
        out = nt.nodes.new("ShaderNodeOutputWorld")
        bg = nt.nodes.new("ShaderNodeBackground")
        bb = nt.nodes.new("ShaderNodeBlackbody")
        nt.links.new(bb.outputs["Color"], bg.inputs["Color"])
        nt.links.new(bg.outputs["Background"], out.inputs["Surface"])
        scene.world = world
        self.world = world
        self._strength = bg.inputs["Strength"]
        self._temperature = bb.inputs["Temperature"]
        self.sky_world = self._build_sky()

    def _build_sky(self) -> bpy.types.World:
        world = bpy.data.worlds.new("crackgen_sky")
        world.use_nodes = True
        nt = world.node_tree
        nt.nodes.clear()
        out = nt.nodes.new("ShaderNodeOutputWorld")
        bg = nt.nodes.new("ShaderNodeBackground")
        tex = nt.nodes.new("ShaderNodeTexSky")
        tex.sky_type = "HOSEK_WILKIE"
        gain = nt.nodes.new("ShaderNodeVectorMath")
        gain.operation = "SCALE"
        gain.inputs["Scale"].default_value = SKY_GAIN
        bb = nt.nodes.new("ShaderNodeBlackbody")
        mix = nt.nodes.new("ShaderNodeMixRGB")
        nt.links.new(tex.outputs["Color"], gain.inputs[0])
        nt.links.new(gain.outputs["Vector"], mix.inputs["Color1"])
        nt.links.new(bb.outputs["Color"], mix.inputs["Color2"])
        nt.links.new(mix.outputs["Color"], bg.inputs["Color"])
        nt.links.new(bg.outputs["Background"], out.inputs["Surface"])
        self._sky_tex, self._sky_mix = tex, mix.inputs["Fac"]
        self._sky_strength, self._sky_temperature = bg.inputs["Strength"], bb.inputs["Temperature"]
        return world

    def update(self, ambient: AmbientSpec, sky: SkySpec | None = None) -> None:
        if not (ambient.strength >= 0 and math.isfinite(ambient.strength)):
            raise LightError(f"ambient.strength must be >= 0, got {ambient.strength!r}")
        if sky is None or not sky.enabled:
            self.scene.world = self.world
            self._strength.default_value = float(ambient.strength)
            self._temperature.default_value = float(ambient.color_temp_k)
            return
        if not (1.0 <= sky.turbidity <= 10.0 and 0.0 <= sky.ground_albedo <= 1.0 and 0.0 <= sky.overcast <= 1.0):
            raise LightError(f"sky: turbidity 1..10, ground_albedo and overcast 0..1, got {sky}")
        self.scene.world = self.sky_world
        self._sky_tex.sun_direction = tuple(float(v) for v in light_direction(sky.sun_elevation_rad, sky.sun_azimuth_rad))
        self._sky_tex.turbidity = float(sky.turbidity)
        self._sky_tex.ground_albedo = float(sky.ground_albedo)
        self._sky_mix.default_value = float(sky.overcast)
        self._sky_strength.default_value = float(ambient.strength)
        self._sky_temperature.default_value = float(ambient.color_temp_k)
