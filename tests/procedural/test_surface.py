"""crackgen.procedural.surface: displaced grid geometry, topology, winding and export."""

import dataclasses

import numpy as np
import pytest
import trimesh

from crackgen.config.spec import CrackSpec
from crackgen.procedural.crackmap import CrackMap, crack_map
from crackgen.procedural.surface import (
    SurfaceError,
    centreline_depth_kept,
    export_mesh,
    mesh_depth_at_uv,
    mesh_depth_map,
    surface_faces,
    surface_mesh,
    surface_uvs,
    surface_vertices,
)

SPEC = CrackSpec(
    freq_x=2.0, freq_y=2.5, octaves=4, persistence=0.5, lacunarity=2.0,
    threshold=0.05, depth_m=0.02, noise_seed=77, offset_u=3.3, offset_v=8.1,
)  # fmt: skip
SIZE_M = 1.5


@pytest.fixture(scope="module")
def cm():
    return crack_map(SPEC, 96, SIZE_M, measure=False)


def _bilinear_by_hand(img: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Independent bilinear lookup between texel centres (texel k centre at (k+0.5)/N)."""
    n = img.shape[0]
    x = np.clip(u * n - 0.5, 0, n - 1)
    y = np.clip(v * n - 0.5, 0, n - 1)
    x0 = np.minimum(np.floor(x).astype(int), n - 2)
    y0 = np.minimum(np.floor(y).astype(int), n - 2)
    fx, fy = x - x0, y - y0
    img = img.astype(np.float64)
    return (
        img[y0, x0] * (1 - fx) * (1 - fy)
        + img[y0, x0 + 1] * fx * (1 - fy)
        + img[y0 + 1, x0] * (1 - fx) * fy
        + img[y0 + 1, x0 + 1] * fx * fy
    )


def test_topology_and_uvs():
    g = 7
    f = surface_faces(g)
    uv = surface_uvs(g)
    assert f.shape == (2 * (g - 1) ** 2, 3) and f.min() == 0 and f.max() == g * g - 1
    assert uv.shape == (g * g, 2)
    # vertex (i, j) has index j*g + i and UV (i/(g-1), j/(g-1))
    i, j = 4, 2
    np.testing.assert_allclose(uv[j * g + i], [i / (g - 1), j / (g - 1)])
    assert surface_faces(g) is f  # cached
    with pytest.raises(SurfaceError, match="grid_px"):
        surface_faces(1)


def test_vertices_follow_the_crack_map(cm):
    g = 61
    v = surface_vertices(cm, g, sampling="point")
    uv = surface_uvs(g).astype(np.float64)
    assert v.shape == (g * g, 3) and v.dtype == np.float32
    np.testing.assert_allclose(v[:, 0], (uv[:, 0] - 0.5) * SIZE_M, atol=1e-6)
    np.testing.assert_allclose(v[:, 1], (uv[:, 1] - 0.5) * SIZE_M, atol=1e-6)
    expected = -_bilinear_by_hand(cm.depth_m, uv[:, 0], uv[:, 1])
    np.testing.assert_allclose(v[:, 2], expected, atol=1e-8)
    assert v[:, 2].max() == 0.0 and v[:, 2].min() >= -SPEC.depth_m
    assert np.any(v[:, 2] < -0.2 * SPEC.depth_m)  # some crack is actually carved


def test_vertices_on_texel_centres_equal_the_map():
    # With a 3-texel map and a 7-vertex grid, u = i/6 equals the texel centre (k + 0.5)/3
    # for i = 1, 3, 5 (k = 0, 1, 2): those vertices must carry the texel's depth exactly.
    small = crack_map(SPEC, 3, SIZE_M, measure=False)
    small.depth_m[:] = np.arange(9, dtype=np.float32).reshape(3, 3) * 1e-3  # distinct values
    v = surface_vertices(small, 7, sampling="point")
    for i, k in [(1, 0), (3, 1), (5, 2)]:
        for j, l in [(1, 0), (3, 1), (5, 2)]:
            assert v[j * 7 + i, 2] == pytest.approx(-small.depth_m[l, k], abs=1e-9)


def test_mesh_normals_point_up_and_metric_size(cm):
    mesh = surface_mesh(cm, 48)
    assert len(mesh.vertices) == 48 * 48 and len(mesh.faces) == 2 * 47 * 47
    assert np.all(mesh.face_normals[:, 2] > 0)
    assert np.all(mesh.vertex_normals[:, 2] > 0)
    np.testing.assert_allclose(mesh.bounds[:, :2], [[-SIZE_M / 2] * 2, [SIZE_M / 2] * 2], atol=1e-6)
    np.testing.assert_allclose(mesh.visual.uv, surface_uvs(48))
    # A crack-free map gives a flat plane with normals exactly +z and area size^2.
    flat = crack_map(dataclasses.replace(SPEC, threshold=1e-9), 32, SIZE_M, measure=False)
    fm = surface_mesh(flat, 16)
    np.testing.assert_allclose(fm.face_normals, np.tile([0.0, 0.0, 1.0], (len(fm.faces), 1)), atol=1e-6)
    assert fm.area == pytest.approx(SIZE_M**2, rel=1e-6)


@pytest.mark.parametrize("ext", [".ply", ".glb"])
def test_export_reloads(cm, tmp_path, ext):
    mesh = surface_mesh(cm, 32)
    path = export_mesh(mesh, tmp_path / f"surface{ext}")
    back = trimesh.load(path, force="mesh", process=False)
    assert len(back.vertices) == len(mesh.vertices)
    assert len(back.faces) == len(mesh.faces)
    np.testing.assert_allclose(back.bounds, mesh.bounds, atol=1e-6)


def test_export_bad_paths(cm, tmp_path):
    mesh = surface_mesh(cm, 8)
    with pytest.raises(SurfaceError, match="extension"):
        export_mesh(mesh, tmp_path / "surface.obj")
    with pytest.raises(SurfaceError, match="does not exist"):
        export_mesh(mesh, tmp_path / "missing" / "surface.ply")


def _groove(n: int, size_m: float, centre_u: float, half_w_texels: float, depth_m: float) -> CrackMap:
    """Hand-made straight V-groove along v, centred at u = centre_u: depth falls linearly to 0 at the edge."""
    x = (np.arange(n) + 0.5) / n
    d = np.clip(1.0 - np.abs(x - centre_u) * n / half_w_texels, 0, None) * depth_m
    depth = np.tile(d.astype(np.float32), (n, 1))
    mask = depth > 0
    skel = np.zeros_like(mask)
    skel[:, int(centre_u * n)] = True
    return CrackMap(z=np.zeros_like(depth), mask=mask, disp=depth, depth_m=depth, skeleton=skel,
                    length_m=size_m, size_m=size_m, spec=SPEC)


def test_mesh_depth_is_the_rendered_triangles():
    # a plane tilted along u and v is held exactly by both triangles of each cell
    g = 9
    uv = surface_uvs(g).astype(np.float64)
    verts = np.zeros((g * g, 3), np.float32)
    verts[:, 2] = -(0.01 * uv[:, 0] + 0.02 * uv[:, 1])
    rng = np.random.default_rng(0)
    u, v = rng.random(500), rng.random(500)
    np.testing.assert_allclose(mesh_depth_at_uv(verts, g, u, v), 0.01 * u + 0.02 * v, atol=1e-7)
    # one raised vertex: only its six incident triangles change, linearly (the v00-v11 split)
    verts[:, 2] = 0
    verts[4 * g + 4, 2] = -1.0  # vertex (i=4, j=4)
    d = 1 / (g - 1)
    assert mesh_depth_at_uv(verts, g, np.array([4 * d]), np.array([4 * d]))[0] == pytest.approx(1.0)
    # cell (4,4), a=0.5 >= b=0.25: triangle v00(4,4), v10, v11 -> 1 - a = 0.5
    assert mesh_depth_at_uv(verts, g, np.array([4.5 * d]), np.array([4.25 * d]))[0] == pytest.approx(0.5)
    # cell (3,4), a=0.75 >= b=0.5: v00, v10 = (4,4), v11 -> weight a - b = 0.25
    assert mesh_depth_at_uv(verts, g, np.array([3.75 * d]), np.array([4.5 * d]))[0] == pytest.approx(0.25)
    # cell (3,4), b=0.75 > a=0.25: triangle v00, v11, v01 does not touch (4,4)
    assert mesh_depth_at_uv(verts, g, np.array([3.25 * d]), np.array([4.75 * d]))[0] == 0.0
    # cell (3,3), b > a: v00, v11 = (4,4), v01 -> weight a = 0.25
    assert mesh_depth_at_uv(verts, g, np.array([3.25 * d]), np.array([3.75 * d]))[0] == pytest.approx(0.25)
    assert mesh_depth_map(verts, g, 16).shape == (16, 16)


def test_footprint_sampling_keeps_the_depth_of_a_narrow_groove():
    # 1024-texel map, 384-vertex grid (the defaults): a V-groove 3 texels wide (7 mm at 2.5 m),
    # on a vertex, a quarter and half a vertex spacing off it
    n, g, size, depth = 1024, 384, 2.5, 0.01
    spacing = 1.0 / (g - 1)
    point, foot = [], []
    for phase in (0.0, 0.25, 0.5):
        cm = _groove(n, size, centre_u=(100 + phase) * spacing, half_w_texels=1.5, depth_m=depth)
        point.append(np.median(centreline_depth_kept(cm, surface_vertices(cm, g, sampling="point"), g)))
        foot.append(np.median(centreline_depth_kept(cm, surface_vertices(cm, g), g)))
    # measured: point 0.88 / 0.47 / 0.22, footprint 0.96 / 0.77 / 0.83
    assert np.mean(point) < 0.6 and min(point) < 0.3  # between vertices most of the depth is lost
    assert np.mean(foot) > 0.8 and min(foot) > 0.7
    assert all(f > p for f, p in zip(foot, point))
    # never deeper than the crack map anywhere (max over a footprint of map values)
    assert surface_vertices(cm, g)[:, 2].min() >= -depth - 1e-7
    # a wide groove (many vertices across) is held the same way by both samplings at its centre
    wide = _groove(n, size, centre_u=0.5, half_w_texels=40, depth_m=depth)
    kp = centreline_depth_kept(wide, surface_vertices(wide, g, sampling="point"), g)
    kf = centreline_depth_kept(wide, surface_vertices(wide, g), g)
    assert np.median(kp) > 0.95 and np.median(kf) > 0.95


def test_unknown_sampling_is_refused(cm):
    with pytest.raises(SurfaceError, match="sampling"):
        surface_vertices(cm, 8, sampling="max")


def test_crack_slope_is_counted_once_between_mesh_and_normal_map(cm):
    from crackgen.config.spec import MaterialSpec
    from crackgen.procedural.materials import material_maps, resample_crack

    spec = MaterialSpec(family="concrete", seed=3, texture_px=96, hue_shift=0.0, value_scale=1.0,
                        roughness_offset=0.0, crack_darkening=0.3, crack_roughness=0.9)
    flat = dataclasses.replace(cm, depth_m=np.zeros_like(cm.depth_m))
    micro = material_maps(spec, flat).height_m  # the surface relief without any crack
    _, crack_depth = resample_crack(cm, 96)
    full = material_maps(spec, cm).height_m  # old behaviour: the normal map carries the whole crack
    np.testing.assert_allclose(full, micro - crack_depth, atol=1e-6)
    g = 48
    held = mesh_depth_map(surface_vertices(cm, g), g, 96)
    once = material_maps(spec, cm, held).height_m  # only what the mesh lacks
    np.testing.assert_allclose(once, micro - (crack_depth - held), atol=1e-6)
    # a mesh that holds the crack exactly leaves the normal map with the micro relief alone
    np.testing.assert_allclose(material_maps(spec, cm, crack_depth).height_m, micro, atol=1e-6)
    assert np.abs(once - micro).max() < np.abs(full - micro).max()
