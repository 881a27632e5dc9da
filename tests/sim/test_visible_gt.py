"""Visible GT: the crack-map crack clipped to what the camera sees, measured in metres on the surface."""
import dataclasses

import numpy as np
import pytest
from sensor_scenes import plane_mesh

from crackgen.config.recipe import Recipe
from crackgen.config.spec import make_spec
from crackgen.procedural.crackmap import CrackMap
from crackgen.sim.groundtruth import view_ground_truth
from crackgen.sim.raycast import MeshRaycaster
from crackgen.sim.visible_gt import visible_ground_truth, visible_texels
from fusion.geometry.camera import Camera, intrinsics_from_focal, look_at

SIZE, N = 2.0, 400
TEXEL = SIZE / N


def _bar_map() -> CrackMap:
    """One straight 1.5 m crack along x (rows 198..201: 4 texels = 2 cm wide), 1 cm deep, on a 2 m patch."""
    mask = np.zeros((N, N), bool)
    mask[198:202, 50:350] = True
    depth = np.where(mask, np.float32(0.01), np.float32(0)).astype(np.float32)
    spec = dataclasses.replace(make_spec(Recipe(), 0).crack)
    return CrackMap(z=(~mask).astype(np.float32), mask=mask, disp=depth, depth_m=depth, skeleton=None,
                    length_m=float("nan"), size_m=SIZE, spec=spec)


def _camera(target_x: float, w=160, h=120) -> Camera:
    eye = np.array([target_x, -0.1, 1.2])
    T = look_at(eye, np.array([target_x, 0.0, 0.0]), np.array([0.0, -1.0, 0.0]))
    return Camera(intrinsics_from_focal(35, 36, w, h), T, w, h)


def _uv(cam: Camera, cm: CrackMap):
    verts, faces, uvs = plane_mesh(SIZE)
    return view_ground_truth(cam, MeshRaycaster(verts, faces, uvs), cm.mask).uv


def test_visible_part_is_clipped_to_the_view():
    cm = _bar_map()
    cam = _camera(0.0)
    seen = visible_texels(cm, cam, _uv(cam, cm))
    assert seen.any() and not (seen & ~cm.mask).any()
    # seen texels are exactly the crack texels whose centre projects into the image
    jj, ii = np.nonzero(cm.mask)
    pix, _ = cam.project(np.stack([(ii + 0.5) * TEXEL - 1, (jj + 0.5) * TEXEL - 1, 0 * ii], 1))
    inside = (pix[:, 0] > -0.5) & (pix[:, 0] < cam.width - 0.5) & (pix[:, 1] > -0.5) & (pix[:, 1] < cam.height - 0.5)
    assert seen[jj, ii].sum() == pytest.approx(inside.sum(), abs=8)  # up to pixel-border rounding

    rec = visible_ground_truth(cm, cam, _uv(cam, cm))
    # The bar crosses the whole view: its visible length is the view's width on the surface.
    cols = ii[inside]
    expected = (cols.max() - cols.min()) * TEXEL
    assert rec["longest_path_m"] == pytest.approx(expected, rel=0.02)
    assert rec["longest_path_m"] < 1.5
    assert rec["mean_width_m"] == pytest.approx(0.02, rel=0.05)
    (c,) = rec["components"]
    assert c["max_depth_m"] == pytest.approx(0.01) and c["mean_depth_m"] == pytest.approx(0.01)


def test_crack_out_of_view_has_no_visible_gt():
    cm = _bar_map()
    cam = _camera(0.0)
    cm.mask[:] = False
    cm.mask[10:14, 10:40] = True  # a crack in a corner of the patch, far outside the view
    rec = visible_ground_truth(cm, cam, _uv(cam, cm))
    assert rec["texels"] == 0 and rec["longest_path_m"] is None and rec["components"] == []
