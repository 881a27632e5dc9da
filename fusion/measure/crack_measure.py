"""What a user wants to know about the cracks in a mask: lengths and widths, per crack and in one number.

Definitions (all in the units of ``coords``: pixels, metres per pixel, or an (H, W, 3) point map):

- ``tip_to_tip`` (per component, thesis 5.1.4): the longest shortest in-mask path between
  two mask pixels, i.e. crack tip to crack tip.  Computed as the skeleton's geodesic diameter
  (``fusion.measure.crack_length``) plus, at each end that is a skeleton tip, the distance from the
  skeleton tip to the last mask pixel straight ahead (the skeleton stops about half a width
  short of each tip).  Measured between pixel centres, like the thesis's boundary pixels, so a
  one-pixel line over 81 pixels is 80 px long.
- ``longest_path`` (whole image, the headline): the thesis's single number, the longest
  in-mask path over the image = the largest ``tip_to_tip`` (paths cannot leave a component).
- ``total_length`` (per component and summed): every skeleton branch, each free end extended
  to the mask the same way: the length of crack there is, branches included.  Each 8-connected
  step is corrected for the staircase at the skeleton's local angle (``_step_correction``).
- ``mean_width``: mask area / ``total_length`` (exact for a strip of constant width; in 3-D
  the area is the sum of per-pixel surface patches).  ``max_width``: the largest local width,
  measured edge to edge along the skeleton's normal (perpendicular to the crack's 3-D
  direction for point maps), averaged over 5 x 5 skeleton neighbours, at skeleton pixels
  away from junctions (where "across" is undefined).

Rings and networks: a closed ring has no tips, so its ``tip_to_tip`` is half its
circumference (the farthest two points along the crack) and its ``total_length`` the whole
circumference.  A network (cells of joined cracks) is one component: ``tip_to_tip`` is the
longest route through it without shortcuts, ``total_length`` the length of all its cracks;
for networks ``total_length`` is the quantity that scales with damage.

For metric sizes in a camera view pass ``coords`` = the 3-D points of the *surface* at every
pixel (``fusion.measure.metric_size.surface_points``): the crack's own depth values (its floor) would
make the path zig-zag in depth.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import cv2
import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from fusion.measure.crack_length import (
    CrackComponent,
    CrackLengthError,
    _as_mask,
    crack_components,
    skeleton_graph,
    skeletonize,
)

__all__ = ["ComponentMeasurement", "CrackMeasurement", "measure_cracks", "longest_crack_path"]

WINDOW = 7  # skeleton window (px) for the local direction
STEP = 0.25  # marching step (px) towards the mask edge
_EIGHT = np.ones((3, 3), bool)


@dataclass
class ComponentMeasurement:
    """One connected crack (one skeleton component); lengths and widths in ``coords`` units."""

    tip_to_tip: float
    total_length: float
    mean_width: float
    max_width: float
    area: float  # mask area of the component (coords units squared)
    endpoints: tuple[tuple[int, int], tuple[int, int]]  # (row, col) skeleton ends of the tip-to-tip path
    n_tips: int  # free skeleton ends (0 for a ring)
    exact: bool  # False: looped component whose diameter search ran out of budget (lower bound)


@dataclass
class CrackMeasurement:
    """Every crack of a mask: the thesis headline and the per-component figures (longest first)."""

    longest_path: float  # thesis 5.1.4: the longest in-mask path over the image (headline)
    tip_to_tip_sum: float  # sum over components of their tip-to-tip lengths
    total_length: float  # all skeleton branches, ends extended to the mask
    mean_width: float  # total mask area / total_length
    max_width: float  # largest local width
    components: list[ComponentMeasurement] = field(default_factory=list)

    def to_dict(self) -> dict:
        """JSON-ready; NaN (not measurable) becomes None."""
        def clean(v):
            if isinstance(v, float):
                return v if np.isfinite(v) else None
            if isinstance(v, dict):
                return {k: clean(x) for k, x in v.items()}
            if isinstance(v, (list, tuple)):
                return [clean(x) for x in v]
            return v
        return clean(asdict(self))


def _check_coords(shape: tuple[int, int], coords) -> np.ndarray | float:
    if coords is None:
        return 1.0
    c = np.asarray(coords, dtype=np.float64)
    if c.ndim == 0:
        if not (np.isfinite(c) and c > 0):
            raise CrackLengthError(f"coords as a pixel size must be a positive finite number, got {coords!r}")
        return float(c)
    if c.ndim != 3 or c.shape[:2] != tuple(shape) or c.shape[2] != 3:
        raise CrackLengthError(
            f"coords must be None, a pixel size, or an (H, W, 3) point array matching the mask {tuple(shape)}; "
            f"got shape {c.shape}")
    return c


def _sample(coords: np.ndarray | float, r: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Points at continuous (row, col): bilinear in a point map, or scaled pixel positions."""
    if np.ndim(coords) == 0:
        return float(coords) * np.stack([c, r], axis=-1)
    out = np.empty(r.shape + (3,))
    for k in range(3):  # order=1 with NaN neighbours gives NaN: invalid stays invalid
        out[..., k] = ndimage.map_coordinates(coords[..., k], [r, c], order=1, mode="nearest")
    return out


def _dist(coords, r0, c0, r1, c1) -> np.ndarray:
    return np.linalg.norm(_sample(coords, r1, c1) - _sample(coords, r0, c0), axis=-1)


def _pixel_area(coords: np.ndarray | float, shape: tuple[int, int]) -> np.ndarray | float:
    """Area each pixel covers: s^2, or |dX/dcol x dX/drow| of the point map (NaN where invalid)."""
    if np.ndim(coords) == 0:
        return float(coords) ** 2
    d_r = np.gradient(coords, axis=0)
    d_c = np.gradient(coords, axis=1)
    return np.linalg.norm(np.cross(d_c, d_r), axis=-1)


def _directions(skel: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangent (drow, dcol) of the skeleton at each pixel (principal axis of the skeleton
    pixels in a WINDOW window) and the mean offset of those pixels (points inward at tips)."""
    h = WINDOW // 2
    pad = np.pad(skel, h)
    sums = dict.fromkeys(("n", "r", "c", "rr", "cc", "rc"), 0.0)
    for dr in range(-h, h + 1):  # gather at the skeleton pixels only: cheap on sparse skeletons
        for dc in range(-h, h + 1):
            on = pad[rows + h + dr, cols + h + dc].astype(np.float64)
            sums["n"] = sums["n"] + on
            sums["r"] = sums["r"] + on * dr
            sums["c"] = sums["c"] + on * dc
            sums["rr"] = sums["rr"] + on * dr * dr
            sums["cc"] = sums["cc"] + on * dc * dc
            sums["rc"] = sums["rc"] + on * dr * dc
    n = np.maximum(sums["n"], 1.0)
    mr, mc = sums["r"] / n, sums["c"] / n
    crr, ccc, crc = sums["rr"] / n - mr * mr, sums["cc"] / n - mc * mc, sums["rc"] / n - mr * mc
    theta = 0.5 * np.arctan2(2 * crc, ccc - crr)  # angle from the column axis
    tangent = np.stack([np.sin(theta), np.cos(theta)], axis=1)
    return tangent, np.stack([mr, mc], axis=1)


def _exit_distance(mask: np.ndarray, rows: np.ndarray, cols: np.ndarray, dirs: np.ndarray, t_max: float) -> np.ndarray:
    """Distance (px) from each pixel centre along its direction to the mask edge.

    Samples sit at odd multiples of STEP / 2 (never on a pixel border, so both directions
    round alike); the edge is put midway between the last sample inside and the first outside."""
    if rows.size == 0:
        return np.zeros(0)
    ts = np.arange(0.5 * STEP, t_max + STEP, STEP)
    h, w = mask.shape
    out = np.full(rows.size, ts[-1])
    for lo in range(0, rows.size, 4096):  # bounded memory on large masks
        sl = slice(lo, lo + 4096)
        r = np.floor(rows[sl, None] + ts[None, :] * dirs[sl, 0:1] + 0.5).astype(np.intp)
        c = np.floor(cols[sl, None] + ts[None, :] * dirs[sl, 1:2] + 0.5).astype(np.intp)
        inside = (r >= 0) & (r < h) & (c >= 0) & (c < w)
        inside[inside] = mask[r[inside], c[inside]]
        outside = ~inside
        first = np.argmax(outside, axis=1)
        out[sl] = np.where(outside.any(axis=1), ts[first], ts[-1])
    return out - 0.5 * STEP


def _edt(m: np.ndarray) -> np.ndarray:
    """Euclidean distance (px) of each True pixel to the nearest False one or the image border
    (outside the image counts as background; OpenCV: fast, exact mask)."""
    pad = np.pad(m.astype(np.uint8), 1)
    return cv2.distanceTransform(pad, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[1:-1, 1:-1]


def _prune_spurs(skel: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """Drop the short branches thinning leaves towards the corners of a thick crack's end.

    A branch from a free end to a junction that is shorter than twice the half-width at the
    junction (``dt``) lies within the crack's own width: it is no crack of its own.
    """
    skel = skel.copy()
    deg = _degrees(skel, skel.shape)
    h, w = skel.shape
    longest = 2 * float(dt.max()) + 2
    for r0, c0 in zip(*np.nonzero(deg == 1)):
        path, prev, cur = [], None, (int(r0), int(c0))
        while True:
            path.append(cur)
            if deg[cur] >= 3 or len(path) > longest:
                break
            nbs = [(cur[0] + dr, cur[1] + dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1)
                   if (dr or dc) and 0 <= cur[0] + dr < h and 0 <= cur[1] + dc < w and skel[cur[0] + dr, cur[1] + dc]
                   and (cur[0] + dr, cur[1] + dc) != prev and (cur[0] + dr, cur[1] + dc) not in path]
            junction = [q for q in nbs if deg[q] >= 3]
            nxt = junction[0] if junction else (nbs[0] if len(nbs) == 1 else None)
            if nxt is None:
                break
            prev, cur = cur, nxt
        if deg[cur] >= 3 and len(path) - 1 < 2.0 * dt[cur]:
            for q in path[:-1]:
                skel[q] = False
    return skel


def _window_mean(skel: np.ndarray, rows: np.ndarray, cols: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Mean of per-skeleton-pixel ``values`` over the skeleton pixels in a 5 x 5 window (NaN ignored)."""
    ok = np.isfinite(values)
    img = np.zeros((skel.shape[0] + 4, skel.shape[1] + 4))
    cnt = np.zeros_like(img)
    img[rows[ok] + 2, cols[ok] + 2] = values[ok]
    cnt[rows[ok] + 2, cols[ok] + 2] = 1.0
    s = np.zeros(rows.size)
    n = np.zeros(rows.size)
    for dr in range(-2, 3):
        for dc in range(-2, 3):
            s += img[rows + 2 + dr, cols + 2 + dc]
            n += cnt[rows + 2 + dr, cols + 2 + dc]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, s / n, np.nan)


def _step_correction(tangent: np.ndarray) -> np.ndarray:
    """Factor from 8-connected step length to true length for a digital line at the tangent's angle.

    A line at angle a (0..45 deg from its major axis) advances one pixel along that axis per
    step and takes a diagonal step on a share tan(a) of them: steps sum to 1 + (sqrt 2 - 1) tan a
    per 1 / cos(a) of true length (up to +8 % at 22.5 deg).  Exact on digital lines.
    """
    a = np.arctan2(np.minimum(np.abs(tangent[:, 0]), np.abs(tangent[:, 1])),
                   np.maximum(np.abs(tangent[:, 0]), np.abs(tangent[:, 1])))
    return (1.0 / np.cos(a)) / (1.0 + (np.sqrt(2.0) - 1.0) * np.tan(a))


def _degrees(skel: np.ndarray, shape: tuple[int, int], g=None) -> np.ndarray:
    """(H, W) skeleton degree without staircase-corner diagonals (0 off the skeleton)."""
    g = skeleton_graph(skel) if g is None else g
    keep = ~g.redundant
    deg = np.bincount(g.edges[keep].ravel(), minlength=g.rows.size)
    out = np.zeros(shape, np.int64)
    out[g.rows, g.cols] = deg
    return out


def _tip_extensions(m: np.ndarray, pts, rows: np.ndarray, cols: np.ndarray, deg: np.ndarray, tangent: np.ndarray,
                    inward: np.ndarray, t_max: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Free ends extended along the tangent to the last mask pixel ahead (the skeleton stops short of the tip).

    Returns (is_tip per skeleton pixel, indices of the tips, extension length per skeleton pixel).
    """
    is_tip = deg[rows, cols] <= 1
    tip_dir = tangent.copy()
    flip = (tip_dir * inward).sum(axis=1) > 0  # point away from the skeleton behind the tip
    tip_dir[flip] *= -1
    isolated = deg[rows, cols] == 0
    ext_px = np.zeros(rows.size)
    sel = np.nonzero(is_tip)[0]
    ext_px[sel] = np.maximum(_exit_distance(m, rows[sel], cols[sel], tip_dir[sel], t_max) - 0.5, 0.0)
    ext = np.zeros(rows.size)
    end_r, end_c = rows[sel] + ext_px[sel] * tip_dir[sel, 0], cols[sel] + ext_px[sel] * tip_dir[sel, 1]
    ext[sel] = np.nan_to_num(_dist(pts, rows[sel].astype(float), cols[sel].astype(float), end_r, end_c))
    if isolated.any():  # a lone skeleton pixel: the blob's extent both ways along its long axis
        iso = np.nonzero(isolated)[0]
        back = np.maximum(_exit_distance(m, rows[iso], cols[iso], -tip_dir[iso], t_max) - 0.5, 0.0)
        ext[iso] += np.nan_to_num(_dist(pts, rows[iso].astype(float), cols[iso].astype(float),
                                        rows[iso] - back * tip_dir[iso, 0], cols[iso] - back * tip_dir[iso, 1]))
    return is_tip, sel, ext


def _local_widths(m: np.ndarray, pts, skel: np.ndarray, rows: np.ndarray, cols: np.ndarray, tangent: np.ndarray,
                  t_max: float) -> np.ndarray:
    """Width across the crack at every skeleton pixel: edge to edge along the normal, perpendicular to the
    crack in 3-D (on a foreshortened surface the image normal is not), averaged over 5 x 5 skeleton neighbours."""
    normal = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1)
    t_pos = _exit_distance(m, rows, cols, normal, t_max)
    t_neg = _exit_distance(m, rows, cols, -normal, t_max)
    across = (_sample(pts, rows + t_pos * normal[:, 0], cols + t_pos * normal[:, 1])
              - _sample(pts, rows - t_neg * normal[:, 0], cols - t_neg * normal[:, 1]))
    along = (_sample(pts, rows + tangent[:, 0], cols + tangent[:, 1])
             - _sample(pts, rows - tangent[:, 0], cols - tangent[:, 1]))
    along /= np.maximum(np.linalg.norm(along, axis=1, keepdims=True), 1e-300)
    width = np.linalg.norm(across - (across * along).sum(axis=1, keepdims=True) * along, axis=1)
    return _window_mean(skel, rows, cols, width)


def _near_junction(deg: np.ndarray, dt: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Skeleton pixels close enough to a junction that the width there spans two branches."""
    junction = deg >= 3
    if not junction.any():
        return np.zeros(rows.size, bool)
    jr, jc = np.nonzero(junction)
    d_j, _ = cKDTree(np.stack([jr, jc], axis=1)).query(np.stack([rows, cols], axis=1))
    return d_j < 2.0 * dt[rows, cols] + 1.0


def _summary(out: list[ComponentMeasurement]) -> CrackMeasurement:
    """The image's figures from its kept components, longest first."""
    out = sorted(out, key=lambda c: c.tip_to_tip, reverse=True)
    if not out:
        return CrackMeasurement(0.0, 0.0, 0.0, float("nan"), float("nan"), [])
    total = float(sum(c.total_length for c in out))
    area = float(sum(c.area for c in out))
    widths = [c.max_width for c in out if np.isfinite(c.max_width)]
    return CrackMeasurement(
        longest_path=out[0].tip_to_tip,
        tip_to_tip_sum=float(sum(c.tip_to_tip for c in out)),
        total_length=total,
        mean_width=area / total if total > 0 else float("nan"),
        max_width=max(widths) if widths else float("nan"),
        components=out,
    )


def measure_cracks(
    mask: np.ndarray,
    coords: float | np.ndarray | None = None,
    *,
    min_length: float = 0.0,
    step_px: int = 4,
    max_sweeps: int = 64,
) -> CrackMeasurement:
    """Lengths and widths of every crack in ``mask`` (see module doc for the definitions).

    ``coords``: None (pixels), metres per pixel, or an (H, W, 3) surface point map (NaN =
    invalid).  Components whose ``tip_to_tip`` is below ``min_length`` (``coords`` units) are
    dropped, e.g. speckle in predicted masks.
    """
    m = _as_mask(mask)
    pts = _check_coords(m.shape, coords)
    dt = _edt(m)
    skel = _prune_spurs(skeletonize(m), dt)
    g = skeleton_graph(skel, None if np.ndim(pts) == 0 else pts)
    comps: list[CrackComponent] = crack_components(
        skel, None if np.ndim(pts) == 0 else pts, step_px=step_px, max_sweeps=max_sweeps, is_skeleton=True, graph=g)
    if not comps:
        return CrackMeasurement(0.0, 0.0, 0.0, float("nan"), float("nan"), [])
    scale = float(pts) if np.ndim(pts) == 0 else 1.0  # crack_components ran in pixels for a scalar pixel size
    rows, cols = np.nonzero(skel)
    deg = _degrees(skel, m.shape, g)
    tangent, inward = _directions(skel, rows, cols)
    t_max = 2.0 * float(dt.max()) + 2.0

    is_tip, sel, ext = _tip_extensions(m, pts, rows, cols, deg, tangent, inward, t_max)
    width = _local_widths(m, pts, skel, rows, cols, tangent, t_max)
    near_j = _near_junction(deg, dt, rows, cols)

    # Skeleton component of every skeleton pixel, and each mask component's area.
    index = np.full(m.shape, -1, np.int64)
    for k, c in enumerate(comps):
        index[c.pixels[:, 0], c.pixels[:, 1]] = k
    comp_of = index[rows, cols]
    mask_lab, n_mask = ndimage.label(m, structure=_EIGHT)
    area_px = _pixel_area(pts, m.shape)
    if np.ndim(area_px) == 0:
        mask_area = np.bincount(mask_lab.ravel(), minlength=n_mask + 1) * float(area_px)
    else:
        mask_area = ndimage.sum_labels(np.nan_to_num(area_px), mask_lab, index=np.arange(n_mask + 1))
    skel_lab = mask_lab[rows, cols]
    comps_per_mask = np.bincount(mask_lab[[c.pixels[0, 0] for c in comps], [c.pixels[0, 1] for c in comps]],
                                 minlength=n_mask + 1)

    keep = ~g.redundant
    # Skeleton length with branches, each step corrected for the staircase at the local angle.
    node_of = np.full(m.shape, -1, np.int64)
    node_of[rows, cols] = np.arange(rows.size)
    fix = _step_correction(tangent)
    e0 = node_of[g.rows[g.edges[keep, 0]], g.cols[g.edges[keep, 0]]]
    e1 = node_of[g.rows[g.edges[keep, 1]], g.cols[g.edges[keep, 1]]]
    edge_len = g.weights[keep] * 0.5 * (fix[e0] + fix[e1])
    edge_comp = comp_of[e0]
    branch_len = scale * np.bincount(edge_comp, weights=edge_len, minlength=len(comps))
    tip_len = np.bincount(comp_of[is_tip], weights=ext[is_tip], minlength=len(comps))
    n_tips = np.bincount(comp_of[is_tip], minlength=len(comps))
    pos = {(int(r), int(c)): i for i, (r, c) in enumerate(zip(rows[sel], cols[sel]))}

    out: list[ComponentMeasurement] = []
    for k, c in enumerate(comps):
        tips = [ext[sel[pos[e]]] if e in pos else 0.0 for e in c.endpoints]
        if c.endpoints[0] == c.endpoints[1]:  # a lone skeleton pixel: its ext already holds both ways
            tips = tips[:1]
        tip_to_tip = c.path_length * scale + float(sum(tips))
        total = float(branch_len[k] + tip_len[k])
        ml = int(skel_lab[comp_of == k][0])
        area = float(mask_area[ml]) / max(int(comps_per_mask[ml]), 1)
        wk = (comp_of == k)
        away = wk & ~near_j
        wsel = width[away] if away.any() else width[wk]
        wsel = wsel[np.isfinite(wsel)]
        out.append(ComponentMeasurement(
            tip_to_tip=tip_to_tip,
            total_length=total,
            mean_width=area / total if total > 0 else float("nan"),
            max_width=float(wsel.max()) if wsel.size else float("nan"),
            area=area,
            endpoints=c.endpoints,
            n_tips=int(n_tips[k]),
            exact=c.exact,
        ))
    return _summary([c for c in out if c.tip_to_tip >= min_length])


def longest_crack_path(mask: np.ndarray, coords: float | np.ndarray | None = None, **kw) -> float:
    """The thesis's crack length (5.1.4): the longest in-mask path over the image."""
    return measure_cracks(mask, coords, **kw).longest_path
