"""Discrete shadow structure on a ground raster (NumPy/OpenCV).

For a posed mesh and a light direction this rasterises, on a top-down grid of
the receiver plane z = 0:

- the hard shadow H: the union of the faces projected along L. It is filled
  by winding number from the boundary of the lit faces (the silhouette,
  oriented by the faces), with a scanline accumulation that costs
  O(edge-row crossings + pixels), not O(faces x pixels); open or
  inconsistently oriented meshes add the faces turned away as a second layer;
- the silhouette edges, each drawn with its index, and of those the ones on
  H's boundary;
- for every pixel, the nearest boundary edge (a Voronoi labelling by
  distance transform) and the distance to it.

These are the discrete choices of the model (which edge governs a point,
inside or outside); the continuous part in ``penumbra`` differentiates
through the governing edge's geometry.
"""

from __future__ import annotations

import dataclasses
import functools
from concurrent.futures import Executor

import numpy as np

from .camera import GroundGrid
from .parallel_loops import loop_helper
from .threads import share

__all__ = ["ShadowRaster", "project_to_ground", "rasterise_shadow", "winding_fill", "winding_count_fill",
           "layer_count_fill",
           "winding_at_points", "winding_count_at_points", "draw_segment_labels", "candidate_labels"]


def project_to_ground(points: np.ndarray, light: np.ndarray, plane_z: float = 0.0) -> np.ndarray:
    """Project world points (..., 3) along light directions (3,) or (..., 3) onto z = plane_z.

    Returns (..., 2).
    """
    lam = (points[..., 2] - plane_z) / light[..., 2]
    return points[..., :2] - lam[..., None] * light[..., :2]


@dataclasses.dataclass(frozen=True)
class ShadowRaster:
    """The discrete shadow structure on ``grid``.

    hard (H, W) uint8 hard shadow; edge_label (H, W) int32 index of the governing
    silhouette edge (-1 where none exists); boundary_dist_px (H, W) float32
    distance in pixels to the nearest boundary edge pixel.
    """

    grid: GroundGrid
    hard: np.ndarray
    edge_label: np.ndarray
    boundary_dist_px: np.ndarray
    edge_neighbours: np.ndarray | None = None  # (S, 2) outline edges sharing each end vertex, -1: none
    edge_outline_fraction: np.ndarray | None = None  # (S,) how much of each edge is on the outline
    depth_count: np.ndarray | None = None  # (H, W) float32: how many layers of the mesh each pixel's ray crosses

    def lookup(self, xy: np.ndarray):
        """(hard, edge_label, boundary distance in metres) at world points (N, 2+), nearest pixel.

        Points outside the raster get hard = 0, label -1 and infinite distance.
        """
        cr = np.rint(self.grid.to_pixel(xy)).astype(np.int64)
        inside = ((cr[:, 0] >= 0) & (cr[:, 0] < self.grid.width) & (cr[:, 1] >= 0)
                  & (cr[:, 1] < self.grid.height))
        c = np.clip(cr[:, 0], 0, self.grid.width - 1)
        r = np.clip(cr[:, 1], 0, self.grid.height - 1)
        hard = np.where(inside, self.hard[r, c], 0)
        label = np.where(inside, self.edge_label[r, c], -1)
        dist = np.where(inside, self.boundary_dist_px[r, c] * self.grid.pixel_m, np.inf)
        return hard, label, dist


def winding_fill(shape: tuple[int, int], start: np.ndarray, end: np.ndarray,
                 weight: np.ndarray) -> np.ndarray:
    """Pixels (H, W) bool with non-zero winding number of weighted directed segments
    (``winding_count_fill`` != 0)."""
    return winding_count_fill(shape, start, end, weight) != 0


def winding_count_fill(shape: tuple[int, int], start: np.ndarray, end: np.ndarray,
                       weight: np.ndarray) -> np.ndarray:
    """Winding number (H, W) float32 (integer-valued) of weighted directed segments at the pixel
    centres.

    start, end (B, 2) in pixel coordinates (col, row), pixel centres at integers;
    weight (B,) how many times (an integer) each segment is traversed start -> end. A pixel
    centre is inside when the weighted count of crossings to its left is non-zero.
    """
    out = np.empty(shape, np.float32)
    _fill_kernel()(*_segments(start, end, weight), out, False)
    return out


def layer_count_fill(shape: tuple[int, int], px: np.ndarray, layers) -> np.ndarray:
    """How many layers (H, W) float32 cover each pixel centre: the sum over ``layers`` (pairs of
    edges (B, 2) into px (V, 2), pixel coordinates, and their weights (B,)) of the absolute
    ``winding_count_fill``."""
    out = np.zeros(shape, np.float32)
    for edges, weights in layers:
        _fill_kernel()(*_segments(px[edges[:, 0]], px[edges[:, 1]], weights), out, True)
    return out


def _segments(start: np.ndarray, end: np.ndarray, weight: np.ndarray) -> tuple:
    """The fill kernel's segments: x0, y0, x1, y1 (B,) float64 and the weights (B,) float64."""
    start = np.asarray(start, np.float64)
    end = np.asarray(end, np.float64)
    return (np.ascontiguousarray(start[:, 0]), np.ascontiguousarray(start[:, 1]), np.ascontiguousarray(end[:, 0]),
            np.ascontiguousarray(end[:, 1]), np.ascontiguousarray(np.broadcast_to(weight, start[:, 0].shape), np.float64))


def draw_segment_labels(shape: tuple[int, int], start: np.ndarray, end: np.ndarray,
                        values: np.ndarray | None = None) -> np.ndarray:
    """Label image (H, W) int32: pixels on segment i hold values[i] (default i + 1), others 0.

    Segments are sampled every 0.5 px; later segments win where they overlap.
    """
    label = np.zeros(shape, np.int32)
    if not len(start):
        return label
    values = np.arange(1, len(start) + 1) if values is None else values
    start = np.asarray(start, np.float64)
    end = np.asarray(end, np.float64)
    _segment_labels_kernel()(start[:, 0], start[:, 1], end[:, 0], end[:, 1], np.asarray(values, np.int64), label)
    return label


@functools.cache
def _segment_labels_kernel():
    """``draw_segment_labels``' loop (numba): each segment clipped to the raster (parametric slab
    clipping, so off-frame edges cost nothing), then sampled at ceil(2 length) + 1 evenly spaced
    points, each written to its nearest pixel, in the segments' order."""
    import numba

    @numba.njit(cache=True, nogil=True)
    def kernel(x0, y0, x1, y1, values, label):
        h, w = label.shape
        for s in range(x0.shape[0]):
            if not np.isfinite(x0[s] + y0[s] + x1[s] + y1[s]):
                continue
            dx, dy = x1[s] - x0[s], y1[s] - y0[s]
            t0, t1 = 0.0, 1.0
            for p0, d, hi in ((x0[s], dx, float(w)), (y0[s], dy, float(h))):
                if d == 0.0:
                    if p0 < -1.0 or p0 > hi:
                        t1 = -1.0
                else:
                    ta, tb = (-1.0 - p0) / d, (hi - p0) / d
                    t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
            if not t1 >= t0:
                continue
            ax, ay = x0[s] + t0 * dx, y0[s] + t0 * dy
            span = t1 - t0
            bx, by = dx * span, dy * span  # the clipped segment, relative to its start
            n = int(np.ceil(2.0 * np.hypot(bx, by))) + 1
            for k in range(n):
                frac = k / max(n - 1, 1)
                col, row = np.rint(ax + frac * bx), np.rint(ay + frac * by)
                if 0 <= col < w and 0 <= row < h:
                    label[int(row), int(col)] = values[s]

    return kernel


def _along_outline(hard: np.ndarray, start: np.ndarray, end: np.ndarray, offset_px: float = 1.5,
                   samples: int = 5) -> np.ndarray:
    """Fraction (S,) of each segment with the hard shadow on one side and not the other.

    Tested at a few points along each segment, ``offset_px`` to either side; segments
    wholly outside the raster count as on the outline (they may govern points near the frame).
    """
    h, w = hard.shape
    flat = hard.reshape(-1)
    dx, dy = (end - start).T
    length = np.maximum(np.hypot(dx, dy), 1e-12)
    t = (np.arange(samples) + 0.5) / samples
    mx = start[:, :1] + dx[:, None] * t
    my = start[:, 1:] + dy[:, None] * t
    ox = (-offset_px * dy / length)[:, None]
    oy = (offset_px * dx / length)[:, None]

    def side(sign):
        qx = np.rint(mx + sign * ox).astype(np.int64)
        qy = np.rint(my + sign * oy).astype(np.int64)
        inside = (qx >= 0) & (qx < w) & (qy >= 0) & (qy < h)
        value = flat[np.clip(qy, 0, h - 1) * w + np.clip(qx, 0, w - 1)] > 0
        return value, inside

    a, ia = side(1.0)
    b, ib = side(-1.0)
    both = ia & ib
    n = np.count_nonzero(both, axis=1)
    differs = np.count_nonzero((a != b) & both, axis=1)
    return np.where(n > 0, differs / np.maximum(n, 1), 1.0)


def rasterise_shadow(grid: GroundGrid, world_vertices: np.ndarray, light: np.ndarray,
                     silhouette, ground: np.ndarray | None = None, *, exact_px: float | None = None,
                     pool: Executor | None = None) -> ShadowRaster:
    """Hard shadow, governing silhouette edge and boundary distance for every pixel of ``grid``.

    world_vertices (V, 3); light (3,) unit with light[2] < 0; silhouette: an
    ``occluder.Silhouette`` for this pose and light; ground: the vertices projected
    along the light (V, 2), if already known. exact_px: the boundary distance (pixels) up to
    which the caller reads the distance and the label (default: everywhere). Where the distance
    is at most exact_px, both are then as without it; elsewhere the distance is only known to be
    larger (+inf far from every seed) and the label is an edge's or -1: the distance transform
    runs near the outline only, in two halves, one on pool's thread if given.
    """
    h, w = grid.height, grid.width
    px = grid.to_pixel(project_to_ground(world_vertices, light) if ground is None else ground)
    count = layer_count_fill((h, w), px, silhouette.fill_edges)
    hard = (count > 0.5).view(np.uint8)

    ids = silhouette.vertex_ids
    start, end = px[ids[:, 0]], px[ids[:, 1]]
    # Only edges that run along the hard shadow's outline govern points: a silhouette line
    # whose shadow falls inside the shadow (an open box's far rim, a fold of the dragon) has
    # the shadow on both sides of it.
    outline_fraction = _along_outline(hard, start, end)
    on_outline = outline_fraction > 0
    outline = np.flatnonzero(on_outline)
    label_img = draw_segment_labels((h, w), start[outline], end[outline], outline + 1)
    # Seeds: outline edge pixels near the hard shadow's boundary (within two pixels of a pixel
    # of the other side); the distance transform measures the distance to the zero pixels of src,
    # and labels each pixel with its nearest seed's edge.
    src = np.empty((h, w), np.uint8)
    before = np.empty(h + 1, np.int64)
    cols = np.empty(2, np.int64)
    seed_rc = _seeds_kernel()(hard, label_img, src, before, cols)
    if not len(seed_rc):
        return ShadowRaster(grid, hard, -np.ones((h, w), np.int32),
                            np.full((h, w), np.inf, np.float32), depth_count=count)
    # The whole raster: every pixel is within h + w of a seed (a step costs at most the rows plus
    # the columns it moves).
    reach_px = float(h + w) if exact_px is None else exact_px
    dist, edge_label = _distance_near_seeds(src, label_img, seed_rc, before, cols, reach_px, pool)
    return ShadowRaster(grid, hard, edge_label, dist, _end_neighbours(ids, on_outline), outline_fraction, count)


#: The 5 x 5 mask's steps reach two pixels: a pixel's value depends on those within two of its paths.
_MASK_REACH_PX = 2
#: Smaller boxes are not split (the transform takes a few ns a pixel; waking the second thread
#: costs about a tenth of a millisecond).
_SPLIT_MIN_PX = 65536
#: The side (pixels) of the tiles that the transform near the outline leaves out when no seed is
#: near (of 4, 8 and 16, the fastest on the masking scene's raster).
_TILE_PX = 8


def _distance_near_seeds(src: np.ndarray, label_img: np.ndarray, seed_rc: np.ndarray, before: np.ndarray,
                         cols: np.ndarray, exact_px: float, pool: Executor | None) -> tuple[np.ndarray, np.ndarray]:
    """``rasterise_shadow``'s distance (H, W) float32 and label (H, W) int32: the whole raster's
    distance transform (``_chamfer_kernel``, OpenCV's) where its distance is at most exact_px
    (everywhere for exact_px >= H + W: one window, the whole raster).

    A pixel at distance d <= exact_px from its seed gets the same value and label from any window
    holding every pixel within d (plus the mask's reach) of it: the transform's shortest paths run
    inside the box of the pixel and its seed, each step at most ``_MASK_REACH_PX`` long and none
    shorter than a pixel, and a window only removes paths (its values are never smaller). So the
    transform runs on the seeds' box widened by that margin, in two halves of rows that overlap
    by it, each kept where it is exact; outside the box the distance exceeds the margin. Within a
    window, the tiles farther than exact_px from every seed are left out (``_chamfer_kernel``).
    """
    h, w = src.shape
    margin = int(np.ceil(exact_px)) + _MASK_REACH_PX + 1
    seeded = np.flatnonzero(np.diff(before))
    r0, r1 = max(int(seeded[0]) - margin, 0), min(int(seeded[-1]) + 1 + margin, h)
    c0, c1 = max(int(cols[0]) - margin, 0), min(int(cols[1]) + 1 + margin, w)
    dist = np.full((h, w), np.inf, np.float32)
    label = np.full((h, w), -1, np.int32)
    reach = int(np.ceil(exact_px))

    def window(a: int, b: int, keep_a: int, keep_b: int) -> None:
        # Rows a..b of the box (its seeds: those of these rows); rows keep_a..keep_b of the result.
        if before[b] == before[a]:
            return
        _chamfer_kernel()(src, label_img, seed_rc[before[a]:before[b]], a, b, c0, c1, keep_a, keep_b, reach,
                          _TILE_PX, dist, label)

    split = (r0 + r1) // 2
    if pool is None or split - r0 < 2 * margin or (r1 - r0) * (c1 - c0) < _SPLIT_MIN_PX:
        window(r0, r1, r0, r1)
        return dist, label
    share(pool, lambda: window(r0, min(split + margin, r1), r0, split),
          lambda: window(max(split - margin, r0), r1, split, r1))
    return dist, label


def _fixed_point(step: float) -> int:
    """A mask step in OpenCV's fixed point (16 fractional bits), rounded from its float32 value."""
    return int(np.rint(np.float64(np.float32(step)) * 65536))


#: The steps of the L2 distance's 5 x 5 chamfer mask (horizontal or vertical, diagonal, knight's
#: move) and the initial distance, in fixed point, as ``cv2.distanceTransform`` takes them.
_STEP_HV, _STEP_DIAG, _STEP_KNIGHT = _fixed_point(1.0), _fixed_point(1.4), _fixed_point(2.1969)
_FAR = (2 ** 31 - 1) >> 2


@functools.cache
def _chamfer_kernel():
    """``cv2.distanceTransformWithLabels(window, DIST_L2, DIST_MASK_5, labelType=DIST_LABEL_PIXEL)``
    on rows a..b and columns c0..c1 of src (0 at the seeds; beyond the window is far, as for
    OpenCV given the window alone), with a tile mask OpenCV does not have (numba).

    The same two passes with the same fixed-point steps and the same order of comparisons, hence
    the same distances and, on a tie, the same nearest seed (tests/test_raster_kernels.py); the
    label is that seed's edge (label_img - 1). Tiles (``tile`` pixels square) farther than
    ``reach`` pixels from every seed in the window (seed_rc: the seeds' rows and columns) are
    left out, as if far: a pixel within reach of its seed keeps its value and label, as every
    pixel on its shortest paths is within reach of that seed too (no step is shorter than a
    pixel in both axes), and the others can only move away. Writes rows keep_a..keep_b of dist
    and label where a tile was computed and a seed reached (+inf and -1 stay elsewhere)."""
    import numba
    hv, diag, knight, far = _STEP_HV, _STEP_DIAG, _STEP_KNIGHT, _FAR
    scale = np.float32(1.0 / 65536)

    @loop_helper(inline=True)
    def step(tmp, lab, q, length, t0, l0):
        t = tmp[q] + length
        if t0 > t:
            return t, lab[q]
        return t0, l0

    # Flat buffers and unsigned offsets: no negative-index wraparound in the inner loops (with it,
    # the passes were slower than OpenCV's).
    @numba.njit(cache=True, nogil=True)
    def kernel(src, label_img, seed_rc, a, b, c0, c1, keep_a, keep_b, reach, tile, dist, label):
        nr, nc = b - a, c1 - c0
        th, tw = (nr + tile - 1) // tile, (nc + tile - 1) // tile
        # The tiles within reach of a seed: within k tiles of a seeded one (summed-area table).
        k = reach // tile + 1
        count = np.zeros((th + 1, tw + 1), np.int32)
        for s in range(seed_rc.shape[0]):
            count[(seed_rc[s, 0] - a) // tile + 1, (seed_rc[s, 1] - c0) // tile + 1] = 1
        for i in range(th):
            for j in range(tw):
                count[i + 1, j + 1] += count[i, j + 1] + count[i + 1, j] - count[i, j]
        active = np.zeros((th, tw), np.bool_)
        for i in range(th):
            for j in range(tw):
                i0, i1, j0, j1 = max(i - k, 0), min(i + k + 1, th), max(j - k, 0), min(j + k + 1, tw)
                active[i, j] = count[i1, j1] - count[i0, j1] - count[i1, j0] + count[i0, j0] > 0
        ws = nc + 4  # two far pixels around the window
        tmp = np.full((nr + 4) * ws, far, np.int32)
        lab = np.full((nr + 4) * ws, -1, np.int32)
        up2, up1, one, two = np.uint64(2 * ws), np.uint64(ws), np.uint64(1), np.uint64(2)
        for i in range(nr):
            row = np.uint64((i + 2) * ws + 2)
            for tj in range(tw):
                if not active[i // tile, tj]:
                    continue
                for j in range(tj * tile, min(tj * tile + tile, nc)):
                    q = row + np.uint64(j)
                    if src[a + i, c0 + j] == 0:
                        tmp[q] = 0
                        lab[q] = label_img[a + i, c0 + j] - 1
                        continue
                    t0, l0 = far, -1
                    t0, l0 = step(tmp, lab, q - up2 - one, knight, t0, l0)
                    t0, l0 = step(tmp, lab, q - up2 + one, knight, t0, l0)
                    t0, l0 = step(tmp, lab, q - up1 - two, knight, t0, l0)
                    t0, l0 = step(tmp, lab, q - up1 - one, diag, t0, l0)
                    t0, l0 = step(tmp, lab, q - up1, hv, t0, l0)
                    t0, l0 = step(tmp, lab, q - up1 + one, diag, t0, l0)
                    t0, l0 = step(tmp, lab, q - up1 + two, knight, t0, l0)
                    t0, l0 = step(tmp, lab, q - one, hv, t0, l0)
                    tmp[q], lab[q] = t0, l0
        for i in range(nr - 1, -1, -1):
            row = np.uint64((i + 2) * ws + 2)
            keep = keep_a <= a + i < keep_b
            for tj in range(tw - 1, -1, -1):
                if not active[i // tile, tj]:
                    continue
                for j in range(min(tj * tile + tile, nc) - 1, tj * tile - 1, -1):
                    q = row + np.uint64(j)
                    t0, l0 = tmp[q], lab[q]
                    if t0 > hv:
                        t0, l0 = step(tmp, lab, q + up2 + one, knight, t0, l0)
                        t0, l0 = step(tmp, lab, q + up2 - one, knight, t0, l0)
                        t0, l0 = step(tmp, lab, q + up1 + two, knight, t0, l0)
                        t0, l0 = step(tmp, lab, q + up1 + one, diag, t0, l0)
                        t0, l0 = step(tmp, lab, q + up1, hv, t0, l0)
                        t0, l0 = step(tmp, lab, q + up1 - one, diag, t0, l0)
                        t0, l0 = step(tmp, lab, q + up1 - two, knight, t0, l0)
                        t0, l0 = step(tmp, lab, q + one, hv, t0, l0)
                        tmp[q], lab[q] = t0, l0
                    if keep and t0 < far:
                        dist[a + i, c0 + j] = np.float32(t0) * scale
                        label[a + i, c0 + j] = l0

    return kernel


def _end_neighbours(ids: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """For each edge (S,), an outline edge sharing its first and its second vertex (-1: none).

    Of several, the lowest-numbered other one. Short edges can vanish under their
    neighbours' pixels in the label raster; adding the neighbours of the nearest edge to
    the candidates brings them back.
    """
    out = -np.ones((len(ids), 2), np.int64)
    if len(ids):
        _end_neighbours_kernel()(np.ascontiguousarray(ids, np.int64), np.ascontiguousarray(keep, np.bool_), out)
    return out


@functools.cache
def _end_neighbours_kernel():
    """``_end_neighbours``' loop (numba): the two lowest-numbered kept edges at each vertex, then
    for each kept edge's ends the one that is not the edge itself."""
    import numba

    @numba.njit(cache=True, nogil=True)
    def kernel(ids, keep, out):
        n_vert = 0
        for e in range(ids.shape[0]):
            if keep[e]:
                n_vert = max(n_vert, ids[e, 0] + 1, ids[e, 1] + 1)
        first = np.full(n_vert, -1, np.int64)
        second = np.full(n_vert, -1, np.int64)
        for e in range(ids.shape[0]):
            if keep[e]:
                for j in range(2):
                    v = ids[e, j]
                    if first[v] < 0:
                        first[v] = e
                    elif second[v] < 0:
                        second[v] = e
        for e in range(ids.shape[0]):
            if keep[e]:
                for j in range(2):
                    v = ids[e, j]
                    out[e, j] = first[v] if first[v] != e else second[v]

    return kernel


def candidate_labels(edge_label: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                     radii=(2, 6), max_candidates: int = 4,
                     neighbours: np.ndarray | None = None) -> np.ndarray:
    """Up to K distinct edge labels (n, K) around each pixel (rows, cols) of a label image.

    The pixel's own label comes first; then, nearest first, its neighbours along the
    outline (``neighbours``) and the labels found at ``radii`` pixels in 8 directions
    (the Voronoi cells next door), so the penumbra formula can pick the edge nearest in
    angle rather than in ground distance. Missing slots repeat the first label; -1 where
    the pixel has no label.
    """
    h, w = edge_label.shape
    flat = edge_label.reshape(-1)
    rows = np.asarray(rows, np.int64)
    cols = np.asarray(cols, np.int64)
    offsets = [(dr * r, dc * r) for r in radii for dr in (-1, 0, 1) for dc in (-1, 0, 1)
               if (dr, dc) != (0, 0)]
    reach = max(radii)
    index = rows * w + cols
    first = flat[index]
    columns = [first]
    if neighbours is not None and len(neighbours):
        own = np.maximum(first, 0)
        for j in (0, 1):
            nb = neighbours[:, j][own]
            columns.append(nb if first.min(initial=0) >= 0 else np.where(first >= 0, nb, -1))
    if len(rows) and rows.min() >= reach and rows.max() < h - reach and cols.min() >= reach \
            and cols.max() < w - reach:
        columns += [flat[index + (dr * w + dc)] for dr, dc in offsets]
    else:
        columns += [flat[np.clip(rows + dr, 0, h - 1) * w + np.clip(cols + dc, 0, w - 1)]
                    for dr, dc in offsets]
    # Greedy, column by column: a label takes the next free slot unless already in one.
    n, k = len(first), max_candidates
    slots = np.empty((k, n), first.dtype)
    slots[:] = first
    count = np.ones(n, np.intp)
    for j, v in enumerate(columns[1:], start=1):
        fresh = v >= 0
        for q in range(min(j, k)):
            fresh &= v != slots[q]
        if j >= k:
            fresh &= count < k
        sel = np.flatnonzero(fresh)
        slots.reshape(-1)[count[sel] * n + sel] = v[sel]
        count[sel] += 1
    return slots.T.copy()


def winding_at_points(points: np.ndarray, start: np.ndarray, end: np.ndarray,
                      weight: np.ndarray) -> np.ndarray:
    """Non-zero winding test (N,) bool of points (N, 2) against weighted directed segments
    (``winding_count_at_points`` != 0)."""
    return np.abs(winding_count_at_points(points, start, end, weight)) > 0.5


def winding_count_at_points(points: np.ndarray, start: np.ndarray, end: np.ndarray,
                            weight: np.ndarray) -> np.ndarray:
    """Winding number (N,) float (integer-valued) of points (N, 2) against weighted directed segments.

    The exact twin of ``winding_fill`` at arbitrary points (same half-open rule: a segment
    counts for a point when ymin <= y < ymax and it crosses the point's row at or left of
    it); used where a raster pixel is too coarse. The segments are binned by the rows of
    y they span, so each point tests only those of its bin: O(points x segments crossing
    its row + segments x bins spanned), compiled (numba).
    """
    out = np.zeros(len(points))
    if not len(start) or not len(points):
        return out
    points = np.ascontiguousarray(points[:, :2], np.float64)
    y0, y1 = start[:, 1].astype(np.float64), end[:, 1].astype(np.float64)
    x0, x1 = start[:, 0].astype(np.float64), end[:, 0].astype(np.float64)
    ymin, ymax = np.minimum(y0, y1), np.maximum(y0, y1)
    dirw = np.where(y1 > y0, 1.0, -1.0) * weight
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.where(y1 != y0, (x1 - x0) / (y1 - y0), 0.0)
    # Bins over the points' range of y, about one per 16 points (a segment in many bins costs
    # one entry per bin).
    lo, hi = float(points[:, 1].min()), float(points[:, 1].max())
    n_bins = int(np.clip(len(points) // 16, 1, 4096))
    height = max((hi - lo) / n_bins, 1e-300)
    _winding_kernel()(points, x0, y0, ymin, ymax, slope, dirw, lo, height, n_bins, out)
    return out


@functools.cache
def _winding_kernel():
    """The compiled loop of ``winding_at_points`` (numba, compiled on first use and cached)."""
    import numba

    @numba.njit(cache=True, nogil=True)
    def kernel(points, x0, y0, ymin, ymax, slope, dirw, lo, height, n_bins, out):
        # Bins of segments (CSR): bin b holds the segments whose [ymin, ymax] meets it.
        first = np.empty(len(x0), np.int64)
        last = np.empty(len(x0), np.int64)
        count = np.zeros(n_bins + 1, np.int64)
        for s in range(len(x0)):
            # Clipped to the bins like the points' own bins (a point at the top of the range
            # falls in the last bin); a segment beyond the range lands in an end bin, harmlessly.
            first[s] = int(min(max(np.floor((ymin[s] - lo) / height), 0.0), n_bins - 1))
            last[s] = int(min(max(np.floor((ymax[s] - lo) / height), 0.0), n_bins - 1))
            for k in range(first[s], last[s] + 1):
                count[k + 1] += 1
        for k in range(n_bins):
            count[k + 1] += count[k]
        # Each bin's segments stored contiguously (6 values each), read in order below.
        fill = count[:-1].copy()
        seg = np.empty((count[n_bins], 6))
        for s in range(len(x0)):
            for k in range(first[s], last[s] + 1):
                seg[fill[k], 0], seg[fill[k], 1], seg[fill[k], 2] = ymin[s], ymax[s], x0[s]
                seg[fill[k], 3], seg[fill[k], 4], seg[fill[k], 5] = y0[s], slope[s], dirw[s]
                fill[k] += 1
        for i in range(len(points)):
            px, py = points[i, 0], points[i, 1]
            k = int(min(max(np.floor((py - lo) / height), 0.0), n_bins - 1))
            total = 0.0
            for j in range(count[k], count[k + 1]):
                # Without branches: which segments count is unpredictable.
                crosses = (py >= seg[j, 0]) & (py < seg[j, 1]) & (seg[j, 2] + (py - seg[j, 3]) * seg[j, 4] <= px)
                total += seg[j, 5] * crosses
            out[i] = total

    return kernel


@functools.cache
def _fill_kernel():
    """The winding fills (numba): where each directed segment crosses the pixel rows (the first
    pixel centre at or right of the crossing, w past the row's end; a segment counts in the rows
    ymin <= y < ymax) with its signed weight, then the running sum along each row, into out
    (h, w), or with add_abs its absolute value added to out. Integer weights keep the float64
    sums exact."""
    import numba

    # The crossings grouped by row first (a counting sort), so that one row's worth of sums is
    # all the memory the pass needs besides out: no (h, w) accumulator to fault in.
    @numba.njit(cache=True, nogil=True)
    def kernel(x0, y0, x1, y1, weight, out, add_abs):
        h, w = out.shape
        n_seg = x0.shape[0]
        lo_row = np.empty(n_seg, np.int64)
        hi_row = np.empty(n_seg, np.int64)
        start = np.zeros(h + 1, np.int64)
        for s in range(n_seg):
            lo_row[s] = int(min(max(np.ceil(min(y0[s], y1[s])), 0.0), h))
            hi_row[s] = int(min(max(np.ceil(max(y0[s], y1[s])), 0.0), h))
            for r in range(lo_row[s], hi_row[s]):
                start[r + 1] += 1
        for r in range(h):
            start[r + 1] += start[r]
        col = np.empty(start[h], np.int64)
        signed = np.empty(start[h])
        fill = start[:h].copy()
        for s in range(n_seg):
            dx, dy = x1[s] - x0[s], y1[s] - y0[s]
            sign = (1.0 if y1[s] > y0[s] else -1.0) * weight[s]
            for r in range(lo_row[s], hi_row[s]):
                c = np.ceil(x0[s] + (r - y0[s]) / dy * dx)
                col[fill[r]] = int(min(max(c, 0.0), w))
                signed[fill[r]] = sign
                fill[r] += 1
        acc = np.zeros(w + 1)
        for r in range(h):
            for j in range(start[r], start[r + 1]):
                acc[col[j]] += signed[j]
            total = 0.0
            for c in range(w):
                total += acc[c]
                acc[c] = 0.0
                if add_abs:
                    out[r, c] += abs(total)
                else:
                    out[r, c] = total
            acc[w] = 0.0

    return kernel


@functools.cache
def _seeds_kernel():
    """The distance transform's input (numba): src 0 at the seeds (pixels with an outline edge's
    label on the hard shadow's boundary band: their 5 x 5 window, clipped to the raster, holds
    both values of hard), 1 elsewhere. Returns the seeds' rows and columns (seeds, 2) int64
    (row-major); fills before (h + 1,): the seeds in the rows above each row (and in all), cols
    (2,): the seeds' first and last column.

    The band is OpenCV's 3 x 3 dilation (its default border) of the 3 x 3 dilation minus erosion
    (replicated border) of hard (tests/test_raster_kernels.py): a 3 x 3 window's clipped
    neighbourhoods, each holding its centre pixel, cover the clipped 5 x 5 window."""
    import numba

    # Not inlined: numba's inlining of its loops into the kernel's failed one of its own checks (a warning).
    @loop_helper
    def visit(hard, label, k, src, before, cols, rc, n, row):
        """The labelled pixel k (flat) a seed or not; returns the seeds' count and the row reached."""
        h, w = src.shape
        r, c = k // w, k % w
        if label[r, c] <= 0:
            return n, row
        value = hard[r, c]
        seed = False
        for rr in range(max(r - 2, 0), min(r + 3, h)):
            for cc in range(max(c - 2, 0), min(c + 3, w)):
                if hard[rr, cc] != value:
                    seed = True
                    break
            if seed:
                break
        if not seed:
            return n, row
        while row < r:
            row += 1
            before[row] = n
        src[r, c] = 0
        rc[n, 0], rc[n, 1] = r, c
        cols[0], cols[1] = min(cols[0], c), max(cols[1], c)
        return n + 1, row

    @numba.njit(cache=True, nogil=True)
    def kernel(hard, label, src, before, cols):
        h, w = src.shape
        src[:] = 1
        rc = np.empty((h * w, 2), np.int64)  # its pages touched up to the seeds' count only
        n, row = 0, 0
        before[0] = 0
        cols[0], cols[1] = w, -1
        # The label is 0 but along the outline: read two pixels at a time.
        flat = label.reshape(-1)
        even = flat.shape[0] - flat.shape[0] % 2
        pairs = flat[:even].view(np.int64)
        for p in range(pairs.shape[0]):
            if pairs[p] != 0:
                n, row = visit(hard, label, 2 * p, src, before, cols, rc, n, row)
                n, row = visit(hard, label, 2 * p + 1, src, before, cols, rc, n, row)
        if even < flat.shape[0]:
            n, row = visit(hard, label, even, src, before, cols, rc, n, row)
        while row < h:
            row += 1
            before[row] = n
        return rc[:n].copy()

    return kernel
