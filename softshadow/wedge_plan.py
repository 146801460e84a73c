"""The ``wedge`` rule's discrete choices: which silhouette edges each receiver point's sun disk
may meet, and the depth complexity at the sun's centre (NumPy/numba).

For the differentiable part (``softshadow.wedge``) every silhouette edge whose segment, seen
from the point, can come within the sun's disk must be a candidate, outline or not (a fold of
the dragon in front of another part counts: it changes the depth complexity W). An edge is a
candidate of a point x when some point p of it in front of x lies inside the cone of the sun's
rays through x's pixel: |p_perp| <= k_max d + r, with d the depth of p in front of x along the
sun's direction, p_perp its offset across the sun's direction from x, k_max the largest disk
radius the plan must hold for (with a margin) and r the pixel's reach. The test is exact (the
minimum of a convex function of the position along the edge), behind a grid of cells in the
plane the edges project on (the ground, or the plane perpendicular to the light), in which each
edge is registered in the cells its reach covers. Each point keeps the K_MAX candidates deepest
inside their cones (``overflow`` counts the points that had more).

The depth complexity at the sun's centre, W(0), is the winding count of the lit faces' boundary
(their number along the ray; ``raster.winding_count_at_points``); the plan hands the evaluation
F = W(0) - sum_j w_j theta_j / 2 pi (``subtended_angles``), from which it recovers W(0)
as the sun and pose move.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import numpy as np
from jaxtyping import Float, Int

__all__ = ["K_MAX", "REACH_MARGIN", "WedgeArrays", "WedgeCandidates", "arrangement", "edge_jumps",
           "gather_candidates"]

K_MAX = 8            # candidate edges kept per point
REACH_MARGIN = 0.05  # the cone's radius is k_max (1 + REACH_MARGIN)
_DEPTH_MIN = 1e-7    # as ``wedge._DEPTH_MIN`` and ``_DEPTH_REL``: where segments are clipped
_DEPTH_REL = 1e-6


class WedgeCandidates:
    """ids (n, K) int32 candidate edges per point (-1: none), count (n,) how many, overflow:
    points that had more than K_MAX within reach (the farthest were dropped)."""

    def __init__(self, ids, count, overflow):
        self.ids, self.count, self.overflow = ids, count, overflow


def _light_frame(light: np.ndarray):
    """s = -L and (e1, e2) as ``wedge._light_frame`` (NumPy, float64)."""
    s = -np.asarray(light, np.float64)
    axis = np.zeros(3)
    axis[int(np.argmin(np.abs(s)))] = 1.0
    e1 = np.cross(axis, s)
    e1 /= np.linalg.norm(e1)
    return s, e1, np.cross(s, e1)


class WedgeArrays(eqx.Module):
    """The ``wedge`` rule's per-point choices (NumPy leaves), beside ``PointPlan.edge_id``.

    winding (n,): F = W(0) - sum_j w_j theta_j / 2 pi at the plan's parameters (the evaluation
    recovers W(0) from it). In the sun's view: side_start, side_end (n, K) 0/1: whether the
    start and the end of each candidate segment's part near the sun lie on the boundary of
    {W >= 1} (W = 0 just beside it on its lit side); cross_slots (n, C, 2) int32: the slots
    (j, i) of the crossings of segment j by segment i along which that changes, cross_change
    (n, C) by how much (+-1; 0 in padding). pixel_*: the same in the receiver's pixel (the
    segments' shadows on the pixel's plane, for the hard shadow's area in it), None when the
    plan was made without pixel axes.
    """

    winding: Float[np.ndarray, " n"]
    side_start: Float[np.ndarray, "n K"]
    side_end: Float[np.ndarray, "n K"]
    cross_slots: Int[np.ndarray, "n C 2"]
    cross_change: Float[np.ndarray, "n C"]
    pixel_side_start: Float[np.ndarray, "n K"] | None = None
    pixel_side_end: Float[np.ndarray, "n K"] | None = None
    pixel_cross_slots: Int[np.ndarray, "n D 2"] | None = None
    pixel_cross_change: Float[np.ndarray, "n D"] | None = None

    def take(self, index) -> "WedgeArrays":
        """The rows ``index`` of every array."""
        return jax.tree_util.tree_map(lambda x: np.asarray(x)[index], self)


def arrangement(points: np.ndarray, ids: np.ndarray, a: np.ndarray, b: np.ndarray, outward: np.ndarray,
                jump: np.ndarray, light: np.ndarray, winding: np.ndarray, radius: float, pixel_reach=0.0,
                pixel_axes: np.ndarray | None = None, max_crossings: int = 16):
    """The boundary of {W >= 1} among each point's candidates (``softshadow.wedge``), in the
    sun's view within ``radius`` (tan) of its centre, widened for each segment by pixel_reach
    over its depth, and, with pixel_axes, in the pixel's square.

    points (n, 3); ids (n, K) candidates (-1: none); a, b, outward (S, 3) the edges in the world;
    jump (S,); winding (n,) W(0); pixel_reach: scalar or (n,), metres; pixel_axes (2, 3) or
    (n, 2, 3): the offsets across the whole pixel along its two sides. Returns (WedgeArrays
    with C = the most crossings any point has, boundary (n,) bool: the boundary passes through
    the disk or the pixel, overflow: crossings dropped beyond ``max_crossings``).
    """
    n, k = ids.shape
    s, e1, e2 = _light_frame(light)
    frame = np.stack([s, e1, e2])
    with_pixel = pixel_axes is not None
    axes = np.zeros((n, 2, 3)) if not with_pixel else np.ascontiguousarray(
        np.broadcast_to(np.asarray(pixel_axes, np.float64), (n, 2, 3)))
    reach = np.ascontiguousarray(np.broadcast_to(np.asarray(pixel_reach, np.float64), (n,)))
    out = [np.zeros((n, k)), np.zeros((n, k)), np.zeros((n, max_crossings, 2), np.int32),
           np.zeros((n, max_crossings)), np.zeros(n, np.int64)]
    pix = [np.zeros((n, k)), np.zeros((n, k)), np.zeros((n, max_crossings, 2), np.int32),
           np.zeros((n, max_crossings)), np.zeros(n, np.int64)]
    offset = np.asarray(winding, np.float64).copy()
    boundary = np.zeros(n, bool)
    overflow = np.zeros(1, np.int64)
    _arrangement_kernel()(np.ascontiguousarray(points, np.float64), np.ascontiguousarray(ids, np.int64),
                          np.ascontiguousarray(a, np.float64), np.ascontiguousarray(b, np.float64),
                          np.ascontiguousarray(outward, np.float64), np.asarray(jump, np.float64), frame,
                          float(radius), reach, axes, with_pixel, offset, *out, *pix, boundary, overflow)
    c = max(1, int(out[4].max(initial=0)))
    arrays = WedgeArrays(offset, out[0], out[1], out[2][:, :c].copy(), out[3][:, :c].copy())
    if with_pixel:
        d = max(1, int(pix[4].max(initial=0)))
        arrays = WedgeArrays(offset, out[0], out[1], out[2][:, :c].copy(), out[3][:, :c].copy(),
                             pix[0], pix[1], pix[2][:, :d].copy(), pix[3][:, :d].copy())
    return arrays, boundary, int(overflow[0])


def edge_jumps(occ, sil) -> np.ndarray:
    """W's change (S,) across each silhouette edge: 1 for a closed, consistently oriented mesh;
    else the number of the fill layers (``Silhouette.fill_edges``) whose boundary runs along it
    (a fold of an open sheet bounds both its lit and its turned-away layer)."""
    ids = sil.vertex_ids
    jump = np.ones(len(ids))
    if occ.watertight or not len(ids):
        return jump
    n_v = len(occ.vertices)
    key = np.sort(ids, axis=1) @ np.array([n_v, 1])
    total = np.zeros(len(ids))
    found = np.zeros(len(ids), bool)
    for edges, weights in sil.fill_edges:
        layer_key = np.sort(edges, axis=1) @ np.array([n_v, 1])
        order = np.argsort(layer_key)
        pos = np.clip(np.searchsorted(layer_key[order], key), 0, max(len(order) - 1, 0))
        hit = (len(order) > 0) & (layer_key[order][pos] == key) if len(order) else np.zeros(len(ids), bool)
        total += np.where(hit, np.abs(weights[order][pos]) if len(order) else 0.0, 0.0)
        found |= hit
    # A merged collinear chain is no mesh edge: it keeps jump 1.
    return np.where(found & (total > 0), total, 1.0)


def gather_candidates(points: np.ndarray, points_plane: np.ndarray, a: np.ndarray, b: np.ndarray,
                      a_plane: np.ndarray, b_plane: np.ndarray, edge_reach: np.ndarray,
                      light: np.ndarray, range_k: float, pixel_reach, k_max: int = K_MAX) -> WedgeCandidates:
    """Candidate edges of each point (module docstring).

    points (n, 3) world; points_plane (n, 2) the points in the plane of the cells; a, b (S, 3)
    the edges' ends in the world and a_plane, b_plane (S, 2) in that plane; edge_reach (S,) a
    bound on how far (plane metres) an edge's candidates lie from it there; range_k: the cone's
    radius (tan); pixel_reach: r, scalar or (n,), metres across the light.
    """
    n = len(points)
    ids = -np.ones((n, k_max), np.int32)
    count = np.zeros(n, np.int32)
    if not n or not len(a):
        return WedgeCandidates(ids, count, 0)
    reach = np.maximum(np.asarray(edge_reach, np.float64), 1e-9)
    lo = np.minimum(points_plane.min(0), np.minimum(a_plane.min(0), b_plane.min(0)) - reach.max())
    hi = np.maximum(points_plane.max(0), np.maximum(a_plane.max(0), b_plane.max(0)) + reach.max())
    # Cells about the typical reach: an edge registers in a few, a point looks in one.
    span = float(np.max(hi - lo))
    cell = max(float(np.median(reach)), span / 4096, 1e-9)
    n_cols = int(np.ceil((hi[0] - lo[0]) / cell)) + 1
    n_rows = int(np.ceil((hi[1] - lo[1]) / cell)) + 1
    while n_cols * n_rows > 4_000_000:
        cell *= 2.0
        n_cols = int(np.ceil((hi[0] - lo[0]) / cell)) + 1
        n_rows = int(np.ceil((hi[1] - lo[1]) / cell)) + 1
    register, query = _kernels()
    ap = np.ascontiguousarray(a_plane, np.float64)
    bp = np.ascontiguousarray(b_plane, np.float64)
    counts = np.zeros(n_cols * n_rows + 1, np.int64)
    register(ap, bp, reach, lo[0], lo[1], cell, n_cols, n_rows, counts, np.zeros(0, np.int32), False)
    start = np.concatenate([[0], np.cumsum(counts[:-1])])
    members = np.empty(int(start[-1] + counts[-1]) if len(counts) else 0, np.int32)
    fill = start.copy()
    register(ap, bp, reach, lo[0], lo[1], cell, n_cols, n_rows, fill, members, True)
    s = -np.asarray(light, np.float64)
    r = np.broadcast_to(np.asarray(pixel_reach, np.float64), (n,)).copy()
    score = np.empty((n, k_max))
    overflow = np.zeros(1, np.int64)
    query(np.ascontiguousarray(points, np.float64), np.ascontiguousarray(points_plane, np.float64), r,
          np.ascontiguousarray(a, np.float64), np.ascontiguousarray(b, np.float64), s,
          float(range_k) * (1.0 + REACH_MARGIN), lo[0], lo[1], cell, n_cols, n_rows, start, members,
          ids, score, count, overflow)
    return WedgeCandidates(ids, count, int(overflow[0]))


@functools.cache
def _kernels():
    """The compiled loops of ``gather_candidates`` (numba, compiled on first use and cached)."""
    import numba

    @numba.njit(cache=True, nogil=True)
    def register(ap, bp, reach, x0, y0, cell, n_cols, n_rows, fill, members, write):
        # Each edge into every cell its reach covers: row by row, the columns the segment
        # spans within reach of the row's band (a slightly generous capsule).
        for e in range(ap.shape[0]):
            R = reach[e]
            ax, ay, bx, by = ap[e, 0], ap[e, 1], bp[e, 0], bp[e, 1]
            r_lo = max(int(np.floor((min(ay, by) - R - y0) / cell)), 0)
            r_hi = min(int(np.floor((max(ay, by) + R - y0) / cell)), n_rows - 1)
            dy = by - ay
            for row in range(r_lo, r_hi + 1):
                band_lo = y0 + row * cell - R
                band_hi = y0 + (row + 1) * cell + R
                if dy != 0.0:
                    t0 = (band_lo - ay) / dy
                    t1 = (band_hi - ay) / dy
                    if t0 > t1:
                        t0, t1 = t1, t0
                    t0 = max(t0, 0.0)
                    t1 = min(t1, 1.0)
                    if t0 > t1:
                        continue
                else:
                    t0, t1 = 0.0, 1.0
                xa = ax + t0 * (bx - ax)
                xb = ax + t1 * (bx - ax)
                c_lo = max(int(np.floor((min(xa, xb) - R - x0) / cell)), 0)
                c_hi = min(int(np.floor((max(xa, xb) + R - x0) / cell)), n_cols - 1)
                for col in range(c_lo, c_hi + 1):
                    k = row * n_cols + col
                    if write:
                        members[fill[k]] = e
                    fill[k] += 1

    @numba.njit(cache=True, nogil=True)
    def cone_gap(x, a, b, s, kappa, r):
        """min over the edge's part in front of x of |p_perp| - kappa d - r (<= 0: a candidate),
        and kappa d + r there (for the score)."""
        wa0, wa1, wa2 = a[0] - x[0], a[1] - x[1], a[2] - x[2]
        wb0, wb1, wb2 = b[0] - x[0], b[1] - x[1], b[2] - x[2]
        da = wa0 * s[0] + wa1 * s[1] + wa2 * s[2]
        db = wb0 * s[0] + wb1 * s[1] + wb2 * s[2]
        dmin = 1e-7 + 1e-6 * max(np.sqrt(wa0 * wa0 + wa1 * wa1 + wa2 * wa2),
                                 np.sqrt(wb0 * wb0 + wb1 * wb1 + wb2 * wb2))
        t_lo, t_hi = 0.0, 1.0
        step = db - da
        if da < dmin and db < dmin:
            return 1e300, 1.0
        if da < dmin:
            t_lo = (dmin - da) / step
        elif db < dmin:
            t_hi = (dmin - da) / step
        # p_perp(t) = P + t D, depth(t) = da + t step
        p0, p1, p2 = wa0 - da * s[0], wa1 - da * s[1], wa2 - da * s[2]
        q0, q1, q2 = wb0 - db * s[0], wb1 - db * s[1], wb2 - db * s[2]
        d0, d1, d2 = q0 - p0, q1 - p1, q2 - p2
        A = d0 * d0 + d1 * d1 + d2 * d2
        B = p0 * d0 + p1 * d1 + p2 * d2
        C = p0 * p0 + p1 * p1 + p2 * p2
        m = kappa * step
        best, best_t = 1e300, t_lo
        for k in range(3):
            if k == 0:
                t = t_lo
            elif k == 1:
                t = t_hi
            else:
                # f'(t) = (A t + B) / |P + t D| - m = 0
                if A <= m * m or A <= 0.0:
                    continue
                disc = (A * C - B * B) / (A - m * m)
                t = (-B + m * np.sqrt(max(disc, 0.0))) / A
                t = min(max(t, t_lo), t_hi)
            f = np.sqrt(max(A * t * t + 2.0 * B * t + C, 0.0)) - kappa * (da + t * step) - r
            if f < best:
                best, best_t = f, t
        return best, kappa * (da + best_t * step) + r

    @numba.njit(cache=True, nogil=True)
    def query(points, plane, rpix, a, b, s, kappa, x0, y0, cell, n_cols, n_rows, start, members,
              ids, score, count, overflow):
        k_max = ids.shape[1]
        for i in range(points.shape[0]):
            col = int(np.floor((plane[i, 0] - x0) / cell))
            row = int(np.floor((plane[i, 1] - y0) / cell))
            if col < 0 or col >= n_cols or row < 0 or row >= n_rows:
                continue
            k = row * n_cols + col
            n_found = 0
            extra = False
            for j in range(start[k], start[k + 1]):
                e = members[j]
                gap, scale = cone_gap(points[i], a[e], b[e], s, kappa, rpix[i])
                if gap > 0.0:
                    continue
                sc = gap / max(scale, 1e-300)
                # Insert, keeping the k_max lowest scores in order.
                if n_found < k_max:
                    pos = n_found
                    n_found += 1
                elif sc < score[i, k_max - 1]:
                    pos = k_max - 1
                    extra = True
                else:
                    extra = True
                    continue
                while pos > 0 and score[i, pos - 1] > sc:
                    score[i, pos] = score[i, pos - 1]
                    ids[i, pos] = ids[i, pos - 1]
                    pos -= 1
                score[i, pos] = sc
                ids[i, pos] = e
            count[i] = n_found
            if extra:
                overflow[0] += 1

    return register, query


@functools.cache
def _arrangement_kernel():
    """The compiled loop of ``arrangement`` (numba): per point, the segments in the sun's view
    (the arithmetic of ``wedge.gnomonic_segments``) and W(0)'s offset, then the walk along each
    segment (``walk``); with pixel axes, the same for the segments' shadows on the pixel's plane
    (``wedge.pixel_segments``)."""
    import numba

    @numba.njit(cache=True, nogil=True)
    def walk(ax, ay, bx, by, w, lo, hi, W0, row_start, row_end, slots, change, p, overflow):
        """Along each segment j's part [lo_j, hi_j] (positions from the foot of the perpendicular
        from the origin): W on its lit side, from a reference point nearest the origin (W0 at the
        origin plus the signed crossings of the path there), then through its crossings in order.
        Records the boundary's statuses at the part's ends and its changes at crossings; returns
        (crossings recorded, whether the boundary passes)."""
        k = ax.shape[0]
        c_max = slots.shape[1]
        ys = np.empty(k)
        js = np.empty(k)
        who = np.empty(k, np.int64)
        nc = 0
        passes = False
        for j in range(k):
            row_start[p, j] = 0.0
            row_end[p, j] = 0.0
            if w[j] <= 0.0 or lo[j] >= hi[j]:
                continue
            dx, dy = bx[j] - ax[j], by[j] - ay[j]
            ln = np.sqrt(dx * dx + dy * dy)
            tx, ty = dx / ln, dy / ln
            u = ay[j] * tx - ax[j] * ty
            ya = ax[j] * tx + ay[j] * ty
            inset = 1e-6 * (hi[j] - lo[j])
            ystar = min(max(0.0, lo[j] + inset), hi[j] - inset)
            qx, qy = ax[j] + (ystar - ya) * tx, ay[j] + (ystar - ya) * ty
            W = W0 - (w[j] if u < 0.0 else 0.0)
            m = 0
            for i in range(k):
                if i == j or w[i] <= 0.0:
                    continue
                dxi, dyi = bx[i] - ax[i], by[i] - ay[i]
                den = qx * dyi - qy * dxi
                if den != 0.0:
                    s_ = (ax[i] * dyi - ay[i] * dxi) / den
                    r_ = (ax[i] * qy - ay[i] * qx) / den
                    if 0.0 < s_ < 1.0 and 0.0 < r_ < 1.0:
                        W += -w[i] if den > 0.0 else w[i]
                den = dx * dyi - dy * dxi
                if den != 0.0:
                    ex, ey = ax[i] - ax[j], ay[i] - ay[j]
                    s_ = (ex * dyi - ey * dxi) / den
                    r_ = (ex * dy - ey * dx) / den
                    if 0.0 < s_ < 1.0 and 0.0 < r_ < 1.0:
                        y = ya + s_ * ln
                        if lo[j] < y < hi[j]:
                            ys[m] = y
                            js[m] = -w[i] if den > 0.0 else w[i]
                            who[m] = i
                            m += 1
            for q in range(1, m):
                yq, jq, wq = ys[q], js[q], who[q]
                r = q - 1
                while r >= 0 and ys[r] > yq:
                    ys[r + 1], js[r + 1], who[r + 1] = ys[r], js[r], who[r]
                    r -= 1
                ys[r + 1], js[r + 1], who[r + 1] = yq, jq, wq
            for q in range(m):
                if ys[q] < ystar:
                    W -= js[q]
            on = 1.0 if (W <= 0.0 and W + w[j] >= 1.0) else 0.0
            row_start[p, j] = on
            passes = passes or on > 0.0
            for q in range(m):
                W += js[q]
                new = 1.0 if (W <= 0.0 and W + w[j] >= 1.0) else 0.0
                if new != on:
                    if nc < c_max:
                        slots[p, nc, 0] = j
                        slots[p, nc, 1] = who[q]
                        change[p, nc] = new - on
                        nc += 1
                    else:
                        overflow[0] += 1
                    on = new
                    passes = passes or on > 0.0
            row_end[p, j] = on
        return nc, passes

    @numba.njit(cache=True, nogil=True)
    def clip_span(ax, ay, bx, by, t_lo, t_hi):
        """Liang-Barsky: the part [t_lo, t_hi] of a -> b inside the square |x|, |y| <= 1/2."""
        for d in range(2):
            p0 = ax if d == 0 else ay
            dd = (bx - ax) if d == 0 else (by - ay)
            if dd == 0.0:
                if abs(p0) > 0.5:
                    return 1.0, 0.0
                continue
            ta = (-0.5 - p0) / dd
            tb = (0.5 - p0) / dd
            if ta > tb:
                ta, tb = tb, ta
            t_lo = max(t_lo, ta)
            t_hi = min(t_hi, tb)
        return t_lo, t_hi

    @numba.njit(cache=True, nogil=True)
    def kernel(points, ids, a, b, outward, jump, frame, radius, reach, axes, with_pixel, offset,
               side_start, side_end, slots, change, count, p_start, p_end, p_slots, p_change, p_count,
               boundary, overflow):
        n, k = ids.shape
        ax = np.empty(k)
        ay = np.empty(k)
        bx = np.empty(k)
        by = np.empty(k)
        w = np.empty(k)
        lo = np.empty(k)
        hi = np.empty(k)
        s0, s1, s2 = frame[0, 0], frame[0, 1], frame[0, 2]
        for p in range(n):
            x0, x1, x2 = points[p, 0], points[p, 1], points[p, 2]
            W0 = offset[p]
            total = 0.0
            for j in range(k):
                w[j] = 0.0
                ax[j] = ay[j] = bx[j] = by[j] = 0.0
                lo[j], hi[j] = 1.0, 0.0
                e = ids[p, j]
                if e < 0:
                    continue
                wa0, wa1, wa2 = a[e, 0] - x0, a[e, 1] - x1, a[e, 2] - x2
                wb0, wb1, wb2 = b[e, 0] - x0, b[e, 1] - x1, b[e, 2] - x2
                da = wa0 * s0 + wa1 * s1 + wa2 * s2
                db = wb0 * s0 + wb1 * s1 + wb2 * s2
                dmin = 1e-7 + 1e-6 * max(np.sqrt(wa0 * wa0 + wa1 * wa1 + wa2 * wa2),
                                         np.sqrt(wb0 * wb0 + wb1 * wb1 + wb2 * wb2))
                if not (da > dmin or db > dmin):
                    continue
                step = db - da
                t = (dmin - da) / step if step != 0.0 else 0.0
                t = min(max(t, 0.0), 1.0)
                ta = t if da < dmin else 0.0
                tb = t if db < dmin else 1.0
                pa0, pa1, pa2 = wa0 + ta * (wb0 - wa0), wa1 + ta * (wb1 - wa1), wa2 + ta * (wb2 - wa2)
                pb0, pb1, pb2 = wa0 + tb * (wb0 - wa0), wa1 + tb * (wb1 - wa1), wa2 + tb * (wb2 - wa2)
                dpa, dpb = da + ta * step, da + tb * step
                px = (pa0 * frame[1, 0] + pa1 * frame[1, 1] + pa2 * frame[1, 2]) / dpa
                py = (pa0 * frame[2, 0] + pa1 * frame[2, 1] + pa2 * frame[2, 2]) / dpa
                qx = (pb0 * frame[1, 0] + pb1 * frame[1, 1] + pb2 * frame[1, 2]) / dpb
                qy = (pb0 * frame[2, 0] + pb1 * frame[2, 1] + pb2 * frame[2, 2]) / dpb
                n1 = outward[e, 0] * frame[1, 0] + outward[e, 1] * frame[1, 1] + outward[e, 2] * frame[1, 2]
                n2 = outward[e, 0] * frame[2, 0] + outward[e, 1] * frame[2, 1] + outward[e, 2] * frame[2, 2]
                if -(qy - py) * n1 + (qx - px) * n2 > 0:
                    px, py, qx, qy = qx, qy, px, py
                ax[j], ay[j], bx[j], by[j] = px, py, qx, qy
                w[j] = jump[e]
                total += w[j] * np.arctan2(px * qy - py * qx, px * qx + py * qy)
                # The part within the disk, widened by the pixel's reach at the segment's depth.
                dx, dy = qx - px, qy - py
                ln = np.sqrt(dx * dx + dy * dy)
                if ln > 0.0:
                    u = (py * dx - px * dy) / ln
                    rad = radius + reach[p] / max(dpa, dpb)
                    if abs(u) < rad:
                        chord = np.sqrt(rad * rad - u * u)
                        ya = (px * dx + py * dy) / ln
                        lo[j], hi[j] = max(ya, -chord), min(ya + ln, chord)
            offset[p] = W0 - total / (2.0 * np.pi)
            nc, passes = walk(ax, ay, bx, by, w, lo, hi, W0, side_start, side_end, slots, change, p, overflow)
            count[p] = nc
            boundary[p] = passes
            if not with_pixel:
                continue
            # The segments' shadows on the pixel's plane, in pixel units (the pixel: the unit
            # square about the point), along the sun's direction s: v - x = al a + be b + t s.
            a0, a1, a2 = axes[p, 0, 0], axes[p, 0, 1], axes[p, 0, 2]
            b0, b1, b2 = axes[p, 1, 0], axes[p, 1, 1], axes[p, 1, 2]
            c_bs = (b1 * s2 - b2 * s1, b2 * s0 - b0 * s2, b0 * s1 - b1 * s0)
            c_sa = (s1 * a2 - s2 * a1, s2 * a0 - s0 * a2, s0 * a1 - s1 * a0)
            c_ab = (a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)
            det = a0 * c_bs[0] + a1 * c_bs[1] + a2 * c_bs[2]
            if det == 0.0:
                continue
            flip = det < 0.0  # mirrored axes: swap them (as wedge.pixel_segments)
            for j in range(k):
                w[j] = 0.0
                lo[j], hi[j] = 1.0, 0.0
                e = ids[p, j]
                if e < 0:
                    continue
                wa0, wa1, wa2 = a[e, 0] - x0, a[e, 1] - x1, a[e, 2] - x2
                wb0, wb1, wb2 = b[e, 0] - x0, b[e, 1] - x1, b[e, 2] - x2
                ta_ = (c_ab[0] * wa0 + c_ab[1] * wa1 + c_ab[2] * wa2) / det
                tb_ = (c_ab[0] * wb0 + c_ab[1] * wb1 + c_ab[2] * wb2) / det
                if not (ta_ > 0.0 or tb_ > 0.0):
                    continue  # wholly on the far side of the pixel's plane from the sun
                pa_ = (c_bs[0] * wa0 + c_bs[1] * wa1 + c_bs[2] * wa2) / det
                pb_ = (c_sa[0] * wa0 + c_sa[1] * wa1 + c_sa[2] * wa2) / det
                qa_ = (c_bs[0] * wb0 + c_bs[1] * wb1 + c_bs[2] * wb2) / det
                qb_ = (c_sa[0] * wb0 + c_sa[1] * wb1 + c_sa[2] * wb2) / det
                # Clip the part behind the plane off (t >= 0).
                t_lo, t_hi = 0.0, 1.0
                if ta_ < 0.0:
                    t_lo = ta_ / (ta_ - tb_)
                elif tb_ < 0.0:
                    t_hi = ta_ / (ta_ - tb_)
                px, py = pa_ + t_lo * (qa_ - pa_), pb_ + t_lo * (qb_ - pb_)
                qx, qy = pa_ + t_hi * (qa_ - pa_), pb_ + t_hi * (qb_ - pb_)
                if flip:
                    px, py, qx, qy = py, px, qy, qx
                n1 = (c_bs[0] * outward[e, 0] + c_bs[1] * outward[e, 1] + c_bs[2] * outward[e, 2]) / det
                n2 = (c_sa[0] * outward[e, 0] + c_sa[1] * outward[e, 1] + c_sa[2] * outward[e, 2]) / det
                if flip:
                    n1, n2 = n2, n1
                if (qx - px) * n2 - (qy - py) * n1 > 0:
                    px, py, qx, qy = qx, qy, px, py
                ax[j], ay[j], bx[j], by[j] = px, py, qx, qy
                w[j] = jump[e]
                dx, dy = qx - px, qy - py
                ln = np.sqrt(dx * dx + dy * dy)
                if ln > 0.0:
                    c0, c1 = clip_span(px, py, qx, qy, 0.0, 1.0)
                    if c0 < c1:
                        ya = (px * dx + py * dy) / ln
                        lo[j], hi[j] = ya + c0 * ln, ya + c1 * ln
            nc, passes = walk(ax, ay, bx, by, w, lo, hi, W0, p_start, p_end, p_slots, p_change, p, overflow)
            p_count[p] = nc
            boundary[p] = boundary[p] or passes

    return kernel
