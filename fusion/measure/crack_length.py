"""Skeleton geodesic diameters of a binary crack mask (the graph part of thesis 5.1.4).

``fusion.measure.crack_measure`` builds the reported quantities (tip-to-tip length with the tips
extended to the mask, total skeleton length, widths, the thesis's longest path) on top of
the per-component skeleton diameters computed here.

The thesis defines a crack's length as the longest, over pairs of mask pixels, of the
shortest path between them that stays inside the mask: the path between the two crack
tips.  The all-pairs form is quadratic or worse, so we skeletonise the mask and take
the *geodesic diameter* of each skeleton component (the longest shortest path in the
8-connected skeleton graph).  Note the skeleton stops about half a crack width short of
each tip, so this is slightly shorter than the mask-boundary definition.

Coordinates are pluggable, so the same code measures
- pixels (``coords=None``),
- metres on a metric surface map (``coords=<metres per pixel>``),
- metres in a camera view (``coords=<(H, W, 3) array of 3-D points>``, NaN = invalid;
  edges touching an invalid point are dropped).

Exactness: on trees (the normal case for thin skeletons) two Dijkstra sweeps, run for all
components at once, give the exact diameter.  Components with loops (ring cracks, merged
cracks, small triangles at junctions) use eccentricity bounds (Takes & Kosters 2011),
exact after a few sweeps on crack skeletons; near-perfect rings can need many, so a
``max_sweeps`` budget caps the work and the best path found (a lower bound; for rings
already the exact value in practice) is returned with ``CrackComponent.exact = False``.

Staircase bias: 8-connected pixel paths overestimate the length of digital lines by up
to 8 % (at 22.5 deg).  ``path_length`` is therefore measured along the geodesic
path as a polyline through every ``step_px``-th path pixel (default 4; 1 = raw graph
length).  Measured: <= 0.6 % error on digital lines at any angle, <= 3 % on arcs of
radius 8 px (chords cut the curve), vs +4..8 % for the raw graph length.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from fusion.errors import FusionError

__all__ = [
    "CrackLengthError",
    "CrackComponent",
    "skeleton",
    "skeleton_graph",
    "crack_components",
    "skeleton_length",
]

# Forward half of the 8-neighbourhood: each undirected edge is found once.
_OFFSETS = ((0, 1), (1, 0), (1, 1), (1, -1))


class CrackLengthError(FusionError):
    """Bad mask/coords given to the crack-length functions (names the argument)."""


@dataclass
class CrackComponent:
    """One connected skeleton component and its geodesic diameter."""

    path_length: float  # skeleton tip to skeleton tip along the smoothed geodesic path, units of ``coords``
    graph_length: float  # geodesic diameter in the 8-connected graph (staircase-biased, up to +8 %)
    endpoints: tuple[tuple[int, int], tuple[int, int]]  # (row, col) of the two tips
    path: np.ndarray  # (K, 2) int (row, col) skeleton pixels from tip to tip
    n_pixels: int  # skeleton pixels in the component
    pixels: np.ndarray  # (n_pixels, 2) int (row, col) of every skeleton pixel of the component
    exact: bool  # False: looped component whose sweep budget ran out (lower bound, see module doc)


@dataclass
class SkeletonGraph:
    """Skeleton pixels as graph nodes with metric edge weights."""

    rows: np.ndarray  # (n,) node row
    cols: np.ndarray  # (n,) node col
    graph: sparse.csr_matrix  # (n, n) symmetric, weights = distance between coords
    edges: np.ndarray  # (E, 2) node index pairs (each undirected edge once)
    weights: np.ndarray  # (E,) edge weights
    diagonal: np.ndarray  # (E,) bool, True for diagonal edges
    redundant: np.ndarray  # (E,) bool, diagonal edge closing a triangle with two 4-edges


def _as_mask(mask: np.ndarray) -> np.ndarray:
    m = np.asarray(mask)
    if m.ndim != 2:
        raise CrackLengthError(f"mask must be a 2-D array, got shape {m.shape}")
    if m.dtype != bool:
        if not np.issubdtype(m.dtype, np.number):
            raise CrackLengthError(f"mask must be boolean or numeric, got dtype {m.dtype}")
        m = m > 0
    return m


def skeletonize(mask: np.ndarray) -> np.ndarray:
    """skimage's skeletonize, imported here so ``import fusion`` stays light for the trainer."""
    from skimage.morphology import skeletonize as _sk

    return _sk(mask)


def skeleton(mask: np.ndarray) -> np.ndarray:
    """One-pixel-wide 8-connected skeleton (bool) of a mask (bool, or 0/255 uint8)."""
    return skeletonize(_as_mask(mask))


def _edge_weights(
    shape: tuple[int, int],
    coords: float | np.ndarray | None,
    r0: np.ndarray,
    c0: np.ndarray,
    r1: np.ndarray,
    c1: np.ndarray,
) -> np.ndarray:
    if coords is None:
        return np.hypot(r1 - r0, c1 - c0).astype(np.float64)
    c = np.asarray(coords, dtype=np.float64)
    if c.ndim == 0:
        s = float(c)
        if not (np.isfinite(s) and s > 0):
            raise CrackLengthError(f"coords as a pixel size must be a positive finite number, got {coords!r}")
        return s * np.hypot(r1 - r0, c1 - c0)
    if c.ndim != 3 or c.shape[:2] != tuple(shape) or c.shape[2] < 2:
        raise CrackLengthError(
            f"coords must be None, a pixel size, or an (H, W, 3) point array matching the mask {tuple(shape)}; "
            f"got shape {c.shape}"
        )
    return np.linalg.norm(c[r1, c1] - c[r0, c0], axis=1)


def skeleton_graph(skel: np.ndarray, coords: float | np.ndarray | None = None) -> SkeletonGraph:
    """8-connected pixel graph of a skeleton, vectorised (no per-pixel Python loop)."""
    skel = _as_mask(skel)
    h, w = skel.shape
    rows, cols = np.nonzero(skel)
    n = rows.size
    index = np.full((h, w), -1, dtype=np.int64)
    index[rows, cols] = np.arange(n)
    # Pad so every neighbour lookup is in bounds (outside = no pixel).
    pad = np.zeros((h + 2, w + 2), dtype=bool)
    pad[1:-1, 1:-1] = skel
    pidx = np.full((h + 2, w + 2), -1, dtype=np.int64)
    pidx[1:-1, 1:-1] = index

    src, dst, diag, red = [], [], [], []
    for dr, dc in _OFFSETS:
        nb = pad[1 + rows + dr, 1 + cols + dc]
        a = np.nonzero(nb)[0]
        src.append(a)
        dst.append(pidx[1 + rows[a] + dr, 1 + cols[a] + dc])
        is_diag = dr != 0 and dc != 0
        diag.append(np.full(a.size, is_diag))
        if is_diag:  # triangle with the two 4-neighbour corners?
            red.append(pad[1 + rows[a], 1 + cols[a] + dc] | pad[1 + rows[a] + dr, 1 + cols[a]])
        else:
            red.append(np.zeros(a.size, dtype=bool))
    s = np.concatenate(src)
    d = np.concatenate(dst)
    wts = _edge_weights((h, w), coords, rows[s], cols[s], rows[d], cols[d])
    ok = np.isfinite(wts)
    s, d, wts = s[ok], d[ok], wts[ok]
    diagonal = np.concatenate(diag)[ok]
    redundant = np.concatenate(red)[ok]
    # csgraph treats explicit zeros as missing edges: keep coincident 3-D points connected.
    gw = np.maximum(wts, 1e-12)
    graph = sparse.coo_matrix(
        (np.concatenate([gw, gw]), (np.concatenate([s, d]), np.concatenate([d, s]))), shape=(n, n)
    ).tocsr()
    return SkeletonGraph(rows, cols, graph, np.stack([s, d], axis=1), wts, diagonal, redundant)


def _group_argmax(values: np.ndarray, labels: np.ndarray, n_groups: int) -> np.ndarray:
    """Index of the max of ``values`` within each label group (NaN/inf treated as -inf)."""
    v = np.where(np.isfinite(values), values, -np.inf)
    order = np.lexsort((v, labels))
    last = np.searchsorted(labels[order], np.arange(n_groups), side="right") - 1
    return order[last]


def _path(pred: np.ndarray, a: int, b: int) -> np.ndarray:
    """Node indices from a to b using Dijkstra predecessors rooted at a."""
    out = [b]
    while out[-1] != a:
        p = pred[out[-1]]
        if p < 0:
            break
        out.append(int(p))
    return np.asarray(out[::-1], dtype=np.int64)


def _sweep_all(graph: sparse.csr_matrix, sources: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Dijkstra from one source per component at once (min_only: components are disjoint)."""
    dist, pred, src = csgraph.dijkstra(graph, directed=False, indices=sources, min_only=True, return_predecessors=True)
    return dist, pred, src


def _polyline_length(
    rows: np.ndarray, cols: np.ndarray, coords: float | np.ndarray | None, step: int
) -> float:
    """Length of the path as a polyline through every ``step``-th pixel (ends kept)."""
    if rows.size < 2:
        return 0.0
    idx = np.unique(np.r_[np.arange(0, rows.size, max(int(step), 1)), rows.size - 1])
    r, c = rows[idx], cols[idx]
    if coords is None or np.ndim(coords) == 0:
        scale = 1.0 if coords is None else float(coords)
        return scale * float(np.hypot(np.diff(r), np.diff(c)).sum())
    pts = np.asarray(coords, dtype=np.float64)[r, c]
    return float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())


def _bounding_diameter(sub: sparse.csr_matrix, start: int, max_sweeps: int) -> tuple[float, int, int, bool]:
    """Exact geodesic diameter of a connected graph by eccentricity bounds (Takes & Kosters 2011).

    Each Dijkstra from v gives ecc(v) and, by the triangle inequality, bounds for every w:
    ecc(w) <= ecc(v) + d(v, w) and ecc(w) >= max(d(v, w), ecc(v) - d(v, w)).  Nodes whose
    upper bound cannot beat the best diameter found are dropped; when none are left the
    diameter is exact.  Alternating far/central picks makes this a handful of sweeps on
    crack skeletons; only near-perfect rings need many (then ``max_sweeps`` caps the work and
    the best found, a lower bound, is returned with exact=False).
    """
    n = sub.shape[0]
    ecc_lo = np.zeros(n)
    ecc_hi = np.full(n, np.inf)
    alive = np.ones(n, dtype=bool)
    best, ba, bb = 0.0, start, start
    v, pick_far = start, True
    for _ in range(max_sweeps):
        d = csgraph.dijkstra(sub, directed=False, indices=v)
        far = int(np.argmax(d))
        e = float(d[far])
        if e > best:
            best, ba, bb = e, v, far
        np.maximum(ecc_lo, np.maximum(d, e - d), out=ecc_lo)
        np.minimum(ecc_hi, e + d, out=ecc_hi)
        alive &= ecc_hi > best * (1 + 1e-12) + 1e-12
        if not alive.any():
            return best, ba, bb, True
        idx = np.nonzero(alive)[0]
        # Far picks raise the lower bound, central picks (small ecc) tighten the upper bounds.
        v = int(idx[np.argmax(ecc_hi[idx])]) if pick_far else int(idx[np.argmin(ecc_lo[idx])])
        pick_far = not pick_far
    return best, ba, bb, False


def crack_components(
    mask: np.ndarray,
    coords: float | np.ndarray | None = None,
    *,
    step_px: int = 4,
    max_sweeps: int = 64,
    is_skeleton: bool = False,
    graph: SkeletonGraph | None = None,
) -> list[CrackComponent]:
    """Geodesic diameter of every 8-connected skeleton component of ``mask``.

    ``coords``: None (pixels), metres per pixel, or an (H, W, 3) point array (NaN = invalid).
    ``step_px``: polyline step along the geodesic path (see module doc; 1 = raw graph length).
    ``max_sweeps``: Dijkstra budget per looped component (see ``_bounding_diameter``).
    ``is_skeleton=True`` skips skeletonisation when the caller already has one; ``graph``
    reuses that skeleton's ``skeleton_graph(mask, coords)``.
    Components are returned longest first.  The skeleton stops short of the mask's tips:
    ``fusion.measure.crack_measure`` adds the missing ends.
    """
    if int(step_px) != step_px or step_px < 1:
        raise CrackLengthError(f"step_px must be an integer >= 1, got {step_px!r}")
    m = _as_mask(mask)
    skel = m if is_skeleton else skeletonize(m)
    g = graph if graph is not None else skeleton_graph(skel, coords)
    n = g.rows.size
    if n == 0:
        return []
    n_comp, labels = csgraph.connected_components(g.graph, directed=False)
    n_nodes = np.bincount(labels, minlength=n_comp)
    n_edges = np.bincount(labels[g.edges[:, 0]], minlength=n_comp) if g.edges.size else np.zeros(n_comp, int)
    is_tree = n_edges == n_nodes - 1

    # Two sweeps over all components at once: exact diameters for the trees.
    first = _group_argmax(np.zeros(n), labels, n_comp)  # any node per component
    d1, _, _ = _sweep_all(g.graph, first)
    a = _group_argmax(d1, labels, n_comp)
    d2, pred, _ = _sweep_all(g.graph, a)
    b = _group_argmax(d2, labels, n_comp)

    order = np.argsort(labels, kind="stable")
    starts = np.r_[0, np.cumsum(n_nodes)]
    out: list[CrackComponent] = []
    for k in range(n_comp):
        members = order[starts[k]:starts[k + 1]]
        exact = True
        if is_tree[k]:
            length, ia, ib = float(d2[b[k]]), int(a[k]), int(b[k])
            path = _path(pred, ia, ib)
        else:
            nodes = members
            sub = g.graph[nodes][:, nodes].tocsr()
            start = int(np.searchsorted(nodes, a[k]))  # the first sweep's far end: a good start
            length, la, lb, exact = _bounding_diameter(sub, start, int(max_sweeps))
            _, spred = csgraph.dijkstra(sub, directed=False, indices=la, return_predecessors=True)
            path = nodes[_path(spred, la, lb)]
            ia, ib = int(nodes[la]), int(nodes[lb])
        pix = np.stack([g.rows[path], g.cols[path]], axis=1)
        graph_length = max(float(length), 0.0)
        out.append(
            CrackComponent(
                path_length=graph_length if step_px == 1 else _polyline_length(pix[:, 0], pix[:, 1], coords, step_px),
                graph_length=graph_length,
                endpoints=((int(g.rows[ia]), int(g.cols[ia])), (int(g.rows[ib]), int(g.cols[ib]))),
                path=pix,
                n_pixels=int(n_nodes[k]),
                pixels=np.stack([g.rows[members], g.cols[members]], axis=1),
                exact=exact,
            )
        )
    out.sort(key=lambda c: c.path_length, reverse=True)
    return out


def skeleton_length(
    mask: np.ndarray, coords: float | np.ndarray | None = None, *, is_skeleton: bool = False
) -> float:
    """Total length of the skeleton including branches: the sum of its edge lengths.

    Diagonal edges that close a triangle with two 4-neighbour edges are left out so that
    staircase corners are counted once (as the path through the corner pixel).
    """
    m = _as_mask(mask)
    skel = m if is_skeleton else skeletonize(m)
    g = skeleton_graph(skel, coords)
    return float(g.weights[~g.redundant].sum())
