"""Visible label on the groove the mesh renders: a crack narrower than the vertex footprint.

A hand-made V-groove 2.4 texels wide on a mesh with a vertex every 3 texels: the footprint
mesh (``surface_vertices``) renders it as a groove wider than the crack map's mask, so a
pixel-centre ray can hit its deep walls on non-crack texels. The label must follow what
the ray sees: every pixel whose ray hits deep in the groove is labelled, and nothing
outside the groove is.
"""
from __future__ import annotations

import numpy as np
import pytest

from crackgen.config.recipe import LabelSection
from crackgen.config.spec import CrackSpec
from crackgen.procedural.crackmap import CrackMap
from crackgen.procedural.surface import mesh_depth_map, surface_faces, surface_uvs, surface_vertices
from crackgen.procedural.visible_label import VisibleLabelError, groove_visible_mask
from crackgen.sim.groundtruth import label_texels, mask_lookup, view_ground_truth
from crackgen.sim.raycast import MeshRaycaster
from fusion.geometry.camera import Camera, intrinsics_from_focal, look_at

N, SIZE_M = 240, 0.24  # 1 mm texels
G = 81  # vertex every 3 texels (3 mm)
DEPTH = 0.012
SPEC = CrackSpec(freq_x=1, freq_y=1, octaves=1, persistence=0.5, lacunarity=2, threshold=1.0, depth_m=DEPTH,
                 noise_seed=0, offset_u=0, offset_v=0)
CFG = LabelSection(policy="visible", depth_ratio=0.5, min_depth_m=0.002, min_component_px=0)


def groove_map(half_t: float) -> CrackMap:
    """Straight V-groove along v through u = 0.5 + 0.3 texel (off the vertex columns), depth DEPTH at the centre."""
    k = np.arange(N) + 0.5
    r = np.abs(k - (N / 2 + 0.3)) / half_t
    d = (np.clip(1.0 - r, 0, None) * DEPTH).astype(np.float32)
    depth = np.tile(d, (N, 1))
    mask = depth > 0
    return CrackMap(z=np.minimum(r, 1).astype(np.float32) * np.ones((N, 1), np.float32), mask=mask,
                    disp=depth / DEPTH, depth_m=depth, skeleton=None, length_m=SIZE_M, size_m=SIZE_M, spec=SPEC)


def top_camera(w=96, h=96) -> Camera:
    eye = np.array([0.004, 0.0, 0.12])  # slightly off the groove: rays see one wall more than the other
    T = look_at(eye, np.array([0.0, 0.0, 0.0]), np.array([0.0, -1.0, 0.0]))
    return Camera(intrinsics_from_focal(30, 36, w, h), T, w, h)


def view(cm: CrackMap):
    verts = surface_vertices(cm, G)
    caster = MeshRaycaster(verts, np.asarray(surface_faces(G)), np.asarray(surface_uvs(G)))
    gt = view_ground_truth(top_camera(), caster, cm.mask)
    seen_depth = -gt.hits.points[:, 2].reshape(gt.depth.shape)  # depth of the mesh point each pixel sees
    mesh_depth = mesh_depth_map(verts, G, N)
    return gt, seen_depth, mesh_depth


def test_narrow_groove_is_rendered_wider_than_its_mask_and_the_label_follows_the_rays():
    cm = groove_map(half_t=1.2)
    gt, seen, mesh_depth = view(cm)
    texel_only = mask_lookup(label_texels(CFG, cm), gt.uv)
    label = mask_lookup(label_texels(CFG, cm, mesh_depth), gt.uv)
    deep = seen >= 0.5 * DEPTH  # the ray sees the groove deeper than half its centre depth
    assert deep.sum() > 96  # at least a pixel per row
    # the crack map's texels alone miss deep wall hits (the defect this label fixes) ...
    assert (deep & ~texel_only).sum() > 0.3 * deep.sum()
    # ... the groove rule labels every one of them, and only pixels that see into the groove
    assert not (deep & ~label).any()
    assert not (label & (seen <= 0.0)).any()
    assert (texel_only <= label).all()


def test_groove_rule_on_a_wide_groove_adds_little_to_the_texel_rule():
    cm = groove_map(half_t=12.0)  # 24 mm wide: 8 vertex spacings, well held by the mesh
    gt, seen, mesh_depth = view(cm)
    texel_only = mask_lookup(label_texels(CFG, cm), gt.uv)
    label = mask_lookup(label_texels(CFG, cm, mesh_depth), gt.uv)
    rows = label.sum(axis=1)
    assert texel_only.sum() > 0
    assert (texel_only <= label).all()
    assert np.median(rows - texel_only.sum(axis=1)) <= 2  # at most a pixel each side


def test_groove_rule_width_on_a_hand_made_mesh_groove():
    """The groove rule is the visible rule on the mesh depth: centre band of half-width W (1 - need / D)."""
    half_t = 10.5
    k = np.arange(N)
    d = (np.clip(1.0 - np.abs(k - 120) / half_t, 0, None) * DEPTH).astype(np.float32)
    lab = groove_visible_mask(np.tile(d, (N, 1)), 0.001, depth_ratio=0.5, min_depth_m=0.002)
    width = lab[60:180].any(axis=0).sum()
    w = half_t * 0.001
    assert width == pytest.approx(2 * w * (1 - max(0.002, 0.5 * w) / DEPTH) * 1000, abs=1.0)


def test_mesh_depth_of_the_wrong_shape_is_refused():
    cm = groove_map(half_t=2.0)
    with pytest.raises(VisibleLabelError, match="mesh_depth_m"):
        label_texels(CFG, cm, np.zeros((10, 10), np.float32))
