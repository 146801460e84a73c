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
import os
from concurrent.futures import ThreadPoolExecutor

import equinox as eqx
import numpy as np
from jaxtyping import Float, Int

from .parallel_loops import loop_helper

__all__ = ["K_MAX", "REACH_MARGIN", "WEDGE_FIELDS", "WedgeArrays", "WedgeCandidates", "WedgeEdges", "arrangement",
           "bucket", "concatenate_wedge", "edge_jumps", "gather_candidates", "wedge_edges"]

K_MAX = 32           # candidate edges kept per point
REACH_MARGIN = 0.05  # the cone's radius is k_max (1 + REACH_MARGIN)
BACK_REACH = 20.0    # pixel reaches behind the point a candidate may lie at (in the receiver's plane)
_DEPTH_MIN = 1e-7    # as ``wedge._DEPTH_MIN`` and ``_DEPTH_REL``: where segments are clipped
_DEPTH_REL = 1e-6   # times the L1 norm of the offset


class WedgeCandidates:
    """The points that have candidates: index (m,) into the points, ids (m, K) int32 their
    candidate edges deepest in their cones first (-1: none), count (m,) how many, overflow: points
    that had more than K_MAX within reach (the farthest were dropped)."""

    def __init__(self, index, ids, count, overflow):
        self.index, self.ids, self.count, self.overflow = index, ids, count, overflow


def _light_frame(light: np.ndarray):
    """s = -L and (e1, e2) as ``wedge._light_frame`` (NumPy, float64)."""
    s = -np.asarray(light, np.float64)
    axis = np.zeros(3)
    axis[int(np.argmin(np.abs(s)))] = 1.0
    e1 = np.cross(axis, s)
    e1 /= np.linalg.norm(e1)
    return s, e1, np.cross(s, e1)


class WedgeArrays(eqx.Module):
    """The ``wedge`` rule's discrete choices (NumPy leaves) for n points: a flat list of P
    (point, edge) pairs, the segments that bound {W >= 1} near each point, and of their
    crossings.

    hard_offset (n,): F = [W(0) >= 1] - S / 2 pi at the plan's parameters, S the sum of the
    angles the boundary's pieces subtend at the sun's centre (the evaluation recovers [W(0) >= 1]
    from it as the sun and pose move). pair_point, pair_edge (P,) int32: each pair's point and
    edge (padding: point -1, edge 0, no boundary). In the sun's view from the point: flip (P,)
    1 where the segment runs from its second end to its first (so that its covered side is on
    its left); side_start, side_end (P,) 0/1: whether the start and the end of the segment's
    part near the sun lie on the boundary of {W >= 1} (W = 0 just beside it on its lit side);
    cross (C, 2) int32: the pairs (j, i) of the crossings of segment j by segment i along which
    that changes (the same point), cross_change (C,) by how much (+-1; 0 in padding). pixel_*:
    the same in the point's pixel (the segments' shadows along the sun on the pixel's plane, for
    the hard shadow's area in it; pixel_hard_offset from the pieces in the pixel), None when the
    plan was made without pixel axes.
    """

    hard_offset: Float[np.ndarray, " n"]
    pair_point: Int[np.ndarray, " P"]
    pair_edge: Int[np.ndarray, " P"]
    flip: Float[np.ndarray, " P"]
    side_start: Float[np.ndarray, " P"]
    side_end: Float[np.ndarray, " P"]
    cross: Int[np.ndarray, "C 2"]
    cross_change: Float[np.ndarray, " C"]
    pixel_hard_offset: Float[np.ndarray, " n"] | None = None
    pixel_flip: Float[np.ndarray, " P"] | None = None
    pixel_side_start: Float[np.ndarray, " P"] | None = None
    pixel_side_end: Float[np.ndarray, " P"] | None = None
    pixel_cross: Int[np.ndarray, "D 2"] | None = None
    pixel_cross_change: Float[np.ndarray, " D"] | None = None

    @property
    def n_pairs(self) -> int:
        return len(self.pair_point)

    def fields(self) -> dict:
        return {f: getattr(self, f) for f in WEDGE_FIELDS}

    def select(self, keep: np.ndarray, pad_points: int | None = None, place: np.ndarray | None = None,
               default_offset: np.ndarray | None = None, pairs_to: int | None = None,
               cross_to: int | None = None) -> "WedgeArrays":
        """The choices of the points ``keep`` (m,) (indices), renumbered 0..m-1 (or to ``place``
        (m,)) among ``pad_points`` points (default m), whose other offsets are default_offset
        (default 0); pairs and crossings padded to buckets (``bucket``), or to pairs_to and
        cross_to (at least what they hold)."""
        keep = np.asarray(keep, np.int64)
        target = np.arange(len(keep)) if place is None else np.asarray(place, np.int64)
        n_new = pad_points or len(keep)
        where = -np.ones(len(self.hard_offset), np.int64)
        where[keep] = target
        pair_point = np.asarray(self.pair_point)
        own = np.flatnonzero(pair_point >= 0)  # (padding pairs belong to no point, also when there is none)
        real = own[where[pair_point[own]] >= 0]
        remap = -np.ones(self.n_pairs, np.int64)
        remap[real] = np.arange(len(real))
        def per_point(values):
            out = np.zeros(n_new) if default_offset is None else np.array(default_offset, np.float64)
            out[target] = np.asarray(values)[keep]
            return out

        offset = per_point(self.hard_offset)
        p_size = max(pairs_to or 0, bucket(len(real)) if pairs_to is None else len(real))
        ftype = np.asarray(self.side_start).dtype

        def pairs(x, dtype=None):
            out = np.zeros(p_size, dtype or ftype)
            out[:len(real)] = np.asarray(x)[real]
            return out

        def crossings(cr, ch):
            cr, ch = np.asarray(cr), np.asarray(ch)
            ok = np.flatnonzero((remap[cr[:, 0]] >= 0) & (ch != 0)) if len(cr) else np.zeros(0, np.int64)
            size = max(cross_to or 0, bucket(len(ok)) if cross_to is None else len(ok))
            out, out_ch = np.zeros((size, 2), np.int32), np.zeros(size, ch.dtype)
            out[:len(ok)] = remap[cr[ok]]
            out_ch[:len(ok)] = ch[ok]
            return out, out_ch

        pp = -np.ones(p_size, np.int32)  # padding pairs belong to no point
        pp[:len(real)] = where[pair_point[real]]
        out = dict(hard_offset=offset, pair_point=pp, pair_edge=pairs(self.pair_edge, np.int32),
                   flip=pairs(self.flip), side_start=pairs(self.side_start), side_end=pairs(self.side_end))
        out["cross"], out["cross_change"] = crossings(self.cross, self.cross_change)
        if self.pixel_side_start is not None:
            out.update(pixel_hard_offset=per_point(self.pixel_hard_offset), pixel_flip=pairs(self.pixel_flip),
                       pixel_side_start=pairs(self.pixel_side_start), pixel_side_end=pairs(self.pixel_side_end))
            out["pixel_cross"], out["pixel_cross_change"] = crossings(self.pixel_cross, self.pixel_cross_change)
        return WedgeArrays(**out)

    def astype(self, dtype) -> "WedgeArrays":
        """Flags and changes in ``dtype`` (the offsets stay float64, indices int32)."""
        cast = {"flip", "side_start", "side_end", "cross_change", "pixel_flip", "pixel_side_start",
                "pixel_side_end", "pixel_cross_change"}
        return WedgeArrays(**{f: (None if v is None else np.asarray(v, dtype)) if f in cast else v
                              for f, v in self.fields().items()})


WEDGE_FIELDS = ("hard_offset", "pair_point", "pair_edge", "flip", "side_start", "side_end", "cross", "cross_change",
                "pixel_hard_offset", "pixel_flip", "pixel_side_start", "pixel_side_end", "pixel_cross",
                "pixel_cross_change")


def bucket(n: int, minimum: int = 64) -> int:
    """Pairs and crossings are padded to four sizes per octave (few compiled shapes)."""
    if n <= minimum:
        return minimum
    step = 1 << (int(np.floor(np.log2(n))) - 2)
    return -(-n // step) * step


def concatenate_wedge(parts: list[WedgeArrays], counts: list[int], pad_points: int, pairs_to: int | None = None,
                      cross_to: int | None = None) -> WedgeArrays:
    """One WedgeArrays for several point sets (their first ``counts`` points each), pairs
    renumbered, padded to ``pad_points`` points (and pairs_to, cross_to: ``select``)."""
    trimmed = [p.select(np.arange(c)) for p, c in zip(parts, counts)]
    offsets = np.cumsum([0] + list(counts))
    pair_base = np.cumsum([0] + [t.n_pairs for t in trimmed])
    cat = lambda name: np.concatenate([np.asarray(getattr(t, name)) for t in trimmed])
    out = {f: cat(f) for f in ("hard_offset", "pair_edge", "flip", "side_start", "side_end", "cross_change")}
    out["pair_point"] = np.concatenate([np.where(np.asarray(t.pair_point) >= 0, np.asarray(t.pair_point) + o, -1)
                                        for t, o in zip(trimmed, offsets)]).astype(np.int32)
    out["cross"] = np.concatenate([np.asarray(t.cross) + base for t, base in zip(trimmed, pair_base)]).astype(np.int32)
    if all(t.pixel_side_start is not None for t in trimmed):
        out.update({f: cat(f) for f in ("pixel_hard_offset", "pixel_flip", "pixel_side_start", "pixel_side_end",
                                        "pixel_cross_change")})
        out["pixel_cross"] = np.concatenate([np.asarray(t.pixel_cross) + base
                                             for t, base in zip(trimmed, pair_base)]).astype(np.int32)
    return WedgeArrays(**out).select(np.arange(int(offsets[-1])), pad_points=pad_points, pairs_to=pairs_to,
                                     cross_to=cross_to)


class WedgeEdges(eqx.Module):
    """The edges the ``wedge`` rule may need under one sun (NumPy leaves): the silhouette from the
    sun's centre and every edge beside a face within the disk's angle of edge-on to the sun (from
    some point of the receiver, such an edge may bound the mesh). a, b (S, 3) their ends in the
    world; vertex_ids (S, 2); jump (S,) the depth complexity's change across each (as
    ``edge_jumps``); centre (S,) bool: a silhouette edge from the sun's centre; faces (S, 13):
    each edge's two faces' unit normals, their inward directions (centroid less the edge's middle,
    world) and their count (1 or 2)."""

    a: Float[np.ndarray, "S 3"]
    b: Float[np.ndarray, "S 3"]
    vertex_ids: Int[np.ndarray, "S 2"]
    jump: Float[np.ndarray, " S"]
    centre: np.ndarray
    faces: Float[np.ndarray, "S 13"]


def wedge_edges(occ, sil, world: np.ndarray, rotation: np.ndarray, light: np.ndarray, range_k: float) -> WedgeEdges:
    """The ``WedgeEdges`` of a posed occluder (world vertices, rotation) with silhouette ``sil``
    under ``light``, for disks up to tan r = range_k."""
    ef = occ.edge_faces
    valid = ef >= 0
    extra = np.zeros(0, np.int64)
    if range_k > 0:  # (0: the sun's centre alone, the silhouette)
        light_local = rotation.T @ np.asarray(light, np.float64)
        ndotl = occ.face_normals @ light_local
        # Pre-merge silhouette edges (as ``occluder.silhouette``), to leave out of the extras.
        lit_e = valid & sil.lit[np.maximum(ef, 0)]
        on_sil = ((lit_e.sum(1) > 0) & (lit_e.sum(1) < valid.sum(1))) | (valid.sum(1) == 1)
        # A face within the cone's angle of edge-on: from some point it may face the sun or not.
        band = np.abs(ndotl) <= 1.5 * range_k * (1.0 + REACH_MARGIN) + 1e-9
        extra = np.flatnonzero((valid & band[np.maximum(ef, 0)]).any(1) & ~on_sil)
    sil_ids = np.asarray(sil.vertex_ids)
    edge_index = np.asarray(sil.edge_index) if sil.edge_index is not None else np.zeros(len(sil_ids), np.int64)
    vids = np.concatenate([sil_ids, occ.edges[extra]]).astype(np.int64)
    mesh_edge = np.concatenate([edge_index, extra]).astype(np.int64)
    jump = np.concatenate([edge_jumps(occ, sil), np.where(valid[extra].sum(1) == 1, 1.0,
                                                          1.0 if occ.watertight else 2.0)])
    centre = np.concatenate([np.ones(len(sil_ids), bool), np.zeros(len(extra), bool)])
    slots = np.concatenate([ef, -np.ones((len(ef), 1), ef.dtype)], 1)[mesh_edge][:, :2]
    count = (slots >= 0).sum(1)
    normals = occ.face_normals[np.maximum(slots, 0)] @ rotation.T            # (S, 2, 3)
    inward_all = np.concatenate([occ.edge_inward, np.zeros_like(occ.edge_inward[:, :1])], 1)
    inward = inward_all[mesh_edge][:, :2] @ rotation.T                        # (S, 2, 3)
    faces = np.concatenate([normals[:, 0], np.where(count[:, None] > 1, normals[:, 1], 0.0), inward[:, 0],
                            np.where(count[:, None] > 1, inward[:, 1], 0.0), count[:, None].astype(np.float64)], 1)
    return WedgeEdges(world[vids[:, 0]], world[vids[:, 1]], vids, jump, centre, np.ascontiguousarray(faces))


def arrangement(points: np.ndarray, ids: np.ndarray, edges: WedgeEdges, light: np.ndarray, winding: np.ndarray,
                radius: float, pixel_reach=0.0, pixel_axes: np.ndarray | None = None, max_crossings: int = 8):
    """The boundary of {W >= 1} among each point's candidates (``softshadow.wedge``), in the
    sun's view from the point within ``radius`` (tan) of the sun's centre, widened for each
    segment by pixel_reach over its depth (radius < 0: not at all), and, with pixel_axes, in the
    pixel's square.

    points (n, 3); ids (n, K) candidates (-1: none) into ``edges``; winding (n,) W(0);
    pixel_reach: scalar or (n,), metres; pixel_axes (2, 3) or (n, 2, 3): the offsets across the
    whole pixel along its two sides. Returns (WedgeArrays (unpadded), boundary (n,) bool: the
    boundary passes through the disk or the pixel, overflow: crossings dropped beyond
    ``max_crossings`` per point).
    """
    n, k = ids.shape
    s, e1, e2 = _light_frame(light)
    frame = np.stack([s, e1, e2])
    with_pixel = pixel_axes is not None
    axes = np.zeros((n, 2, 3)) if not with_pixel else np.ascontiguousarray(
        np.broadcast_to(np.asarray(pixel_axes, np.float64), (n, 2, 3)))
    reach = np.ascontiguousarray(np.broadcast_to(np.asarray(pixel_reach, np.float64), (n,)))
    offset = np.asarray(winding, np.float64).copy()
    pixel_offset = np.zeros(n)
    # Per point and slot; filled only up to each point's counts (np.empty: no zeroing pass).
    pair_edge = np.empty((n, k), np.int32)
    flags = [np.empty((n, k), np.int8) for _ in range(6)]  # start, end, pixel start, pixel end, flips
    n_pairs, n_cross, n_pcross = np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n, np.int64)
    cross, pcross = np.empty((n, max_crossings, 2), np.int8), np.empty((n, max_crossings, 2), np.int8)
    change, pchange = np.empty((n, max_crossings), np.int8), np.empty((n, max_crossings), np.int8)
    boundary = np.zeros(n, bool)
    overflow = np.zeros(64, np.int64)
    args = (np.ascontiguousarray(points, np.float64), np.ascontiguousarray(ids, np.int64),
            np.ascontiguousarray(edges.a, np.float64), np.ascontiguousarray(edges.b, np.float64), edges.faces,
            np.asarray(edges.centre, np.bool_), np.asarray(edges.jump, np.float64), frame, float(radius), reach, axes,
            with_pixel, offset, pixel_offset, pair_edge, *flags, n_pairs, cross, change, n_cross, pcross, pchange,
            n_pcross, boundary, overflow)
    _on_threads(_arrangement_kernel(), min(64, max(1, n // 256)), args)
    # Compact: the pairs in point order, the crossings' slots renumbered to pairs.
    pair_of = np.arange(k)[None, :] < n_pairs[:, None]
    base = np.concatenate([[0], np.cumsum(n_pairs)[:-1]])

    def crossings(cr, ch, count):
        some = np.flatnonzero(count)
        on = np.arange(max_crossings)[None, :] < count[some, None]
        rows = some[np.nonzero(on)[0]]
        return (cr[some][on] + base[rows][:, None]).astype(np.int32), ch[some][on].astype(np.float64)

    flag = lambda x: x[pair_of].astype(np.float64)
    out = dict(hard_offset=offset, pair_point=np.nonzero(pair_of)[0].astype(np.int32), pair_edge=pair_edge[pair_of],
               flip=flag(flags[4]), side_start=flag(flags[0]), side_end=flag(flags[1]))
    out["cross"], out["cross_change"] = crossings(cross, change, n_cross)
    if with_pixel:
        out.update(pixel_hard_offset=pixel_offset, pixel_flip=flag(flags[5]), pixel_side_start=flag(flags[2]),
                   pixel_side_end=flag(flags[3]))
        out["pixel_cross"], out["pixel_cross_change"] = crossings(pcross, pchange, n_pcross)
    return WedgeArrays(**out), boundary, int(overflow.sum())


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


def gather_candidates(points, a: np.ndarray, b: np.ndarray, edge_reach: np.ndarray, light: np.ndarray,
                      range_k: float, pixel_reach, k_max: int = K_MAX) -> WedgeCandidates:
    """Candidate edges of points (module docstring).

    points: (n, 3) world points, or a ``GroundGrid`` (its pixel centres on z = 0); a, b (S, 3) the
    edges' ends in the world; edge_reach (S,) a bound on how far (metres, across the light) an
    edge's candidates lie from it; range_k: the cone's radius (tan); pixel_reach: r, scalar or
    (n,) (a scalar for a grid), metres across the light. The cells are in the plane perpendicular
    to the light, where the cones are round.
    """
    grid = None if isinstance(points, np.ndarray) else points
    n = grid.width * grid.height if grid is not None else len(points)
    if not n or not len(a):
        return WedgeCandidates(np.zeros(0, np.int64), -np.ones((0, k_max), np.int32), np.zeros(0, np.int32), 0)
    _, e1, e2 = _light_frame(light)
    uv = lambda p: np.stack([p @ e1, p @ e2], axis=-1)
    reach = np.maximum(np.asarray(edge_reach, np.float64), 1e-9)
    a_uv, b_uv = uv(a), uv(b)
    if grid is not None:
        corners = grid.to_world(np.array([0, grid.width - 1, 0, grid.width - 1]),
                                np.array([0, 0, grid.height - 1, grid.height - 1])).reshape(-1, 3)
        cuv = uv(corners)
        g0, g1 = cuv.min(0), cuv.max(0)
        pts = np.zeros((1, 3))
        plane = np.zeros((1, 2))
        r = np.full(1, float(pixel_reach))
    else:
        pts = np.ascontiguousarray(points, np.float64)
        plane = np.ascontiguousarray(uv(pts))
        g0 = np.array([plane[:, 0].min(), plane[:, 1].min()])
        g1 = np.array([plane[:, 0].max(), plane[:, 1].max()])
        r = np.ascontiguousarray(np.broadcast_to(np.asarray(pixel_reach, np.float64), (n,)))
    lo = np.maximum(np.minimum(g0, np.minimum(a_uv.min(0), b_uv.min(0)) - reach.max()), g0 - reach.max())
    hi = np.minimum(np.maximum(g1, np.maximum(a_uv.max(0), b_uv.max(0)) + reach.max()), g1 + reach.max())
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
    ap, bp = np.ascontiguousarray(a_uv), np.ascontiguousarray(b_uv)
    counts = np.zeros(n_cols * n_rows + 1, np.int64)
    register(ap, bp, reach, lo[0], lo[1], cell, n_cols, n_rows, counts, np.zeros(0, np.int32), False)
    start = np.concatenate([[0], np.cumsum(counts[:-1])])
    members = np.empty(int(start[-1] + counts[-1]) if len(counts) else 0, np.int32)
    fill = start.copy()
    register(ap, bp, reach, lo[0], lo[1], cell, n_cols, n_rows, fill, members, True)
    s = -np.asarray(light, np.float64)
    ids = np.empty((n, k_max), np.int32)
    count = np.empty(n, np.int32)
    overflow = np.zeros(64, np.int64)
    geometry = np.array([grid.origin_m[0], grid.origin_m[1], grid.pixel_m] if grid is not None else [0.0, 0.0, 0.0])
    # Per edge: its ends across the light and along s, the box of its ends, its reach squared.
    box = [np.minimum(a_uv[:, 0], b_uv[:, 0]), np.maximum(a_uv[:, 0], b_uv[:, 0]),
           np.minimum(a_uv[:, 1], b_uv[:, 1]), np.maximum(a_uv[:, 1], b_uv[:, 1])]
    ends = np.ascontiguousarray(np.column_stack([a_uv, a @ s, b_uv, b @ s, *box, reach * reach]))
    _on_threads(query, min(64, max(1, n // 1024)),
                (grid is not None, grid.width if grid is not None else 0, n, geometry, pts, plane, r, e1, e2, ends, s,
                 float(range_k) * (1.0 + REACH_MARGIN), lo[0], lo[1], cell, n_cols, n_rows, start, members, ids, count,
                 overflow))
    index = np.flatnonzero(count)
    return WedgeCandidates(index, ids[index], count[index], int(overflow.sum()))


@functools.cache
def _helper_thread() -> ThreadPoolExecutor | None:
    """One more thread for the plan's compiled loops when the process may use two cores."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return ThreadPoolExecutor(1, thread_name_prefix="softshadow-plan") if cores > 1 else None


def _on_threads(loop, n_chunks: int, args: tuple) -> None:
    """loop(first, stride, n_chunks, *args) over its chunks, the even ones here and the odd ones on
    the helper thread (the loops release the GIL and write disjoint rows; interleaved chunks share
    the work evenly: the points are in raster order)."""
    helper = _helper_thread()
    if helper is None or n_chunks < 2:
        loop(0, 1, n_chunks, *args)
        return
    odd = helper.submit(loop, 1, 2, n_chunks, *args)
    try:
        loop(0, 2, n_chunks, *args)
    finally:
        odd.result()


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

    @loop_helper
    def cone_gap(px, py, pd, e, ends, kappa, r):
        """min over edge e of |p_perp| - kappa max(d, 0) - r (<= 0: a candidate), over its part in
        front of the point (px, py) (across the light), pd (along s), or behind it by at most
        BACK_REACH r (a pixel's box reaches there: an edge lying in the receiver's own plane); and
        kappa max(d, 0) + r there (for the score). ends (S, 6): each edge's ends across the light
        and along s."""
        pa0, pa1, da = ends[e, 0] - px, ends[e, 1] - py, ends[e, 2] - pd
        pb0, pb1, db = ends[e, 3] - px, ends[e, 4] - py, ends[e, 5] - pd
        C = pa0 * pa0 + pa1 * pa1
        d0, d1 = pb0 - pa0, pb1 - pa1
        A = d0 * d0 + d1 * d1
        B = pa0 * d0 + pa1 * d1
        step = db - da
        best, best_t = 1e300, 0.0
        # Two stretches of t in [0, 1]: depth >= 0 (the cone) and -back <= depth < 0 (the pixel's
        # tube alone); on each, f is convex: its minimum at an end or where f' = 0.
        back = BACK_REACH * r
        for part in range(2):
            lo_d, hi_d = (0.0, 1e300) if part == 0 else (-back, 0.0)
            if part == 1 and back <= 0.0:
                continue
            t_lo, t_hi = 0.0, 1.0
            if step != 0.0:
                ta, tb = (lo_d - da) / step, (hi_d - da) / step
                t_lo, t_hi = max(t_lo, min(ta, tb)), min(t_hi, max(ta, tb))
            elif not (lo_d <= da <= hi_d):
                continue
            if t_lo > t_hi:
                continue
            m = kappa * step if part == 0 else 0.0
            kap = kappa if part == 0 else 0.0
            for k in range(3):
                if k == 0:
                    t = t_lo
                elif k == 1:
                    t = t_hi
                else:
                    # f'(t) = (A t + B) / |P + t D| - m = 0
                    if A <= m * m:
                        continue
                    t = (-B + m * np.sqrt(max((A * C - B * B) / (A - m * m), 0.0))) / A
                    t = min(max(t, t_lo), t_hi)
                f = np.sqrt(max(A * t * t + 2.0 * B * t + C, 0.0)) - kap * (da + t * step) - r
                if f < best:
                    best, best_t = f, t
        return best, kappa * max(da + best_t * step, 0.0) + r

    @numba.njit(cache=True, nogil=True)
    def query(first, stride, n_chunks, is_grid, width, n, geometry, points, plane, rpix, e1, e2, ends, s, kappa,
              x0, y0, cell, n_cols, n_rows, start, members, ids, count, overflow):
        # Chunks first, first + stride, ... of n_chunks (``_on_threads``).
        k_max = ids.shape[1]
        for c in range(first, n_chunks, stride):
            x = np.zeros(3)
            score = np.empty(k_max)
            for i in range(c * n // n_chunks, (c + 1) * n // n_chunks):
                count[i] = 0
                if is_grid:
                    row, col_px = i // width, i % width
                    x[0] = geometry[0] + col_px * geometry[2]
                    x[1] = geometry[1] - row * geometry[2]
                    x[2] = 0.0
                    px = x[0] * e1[0] + x[1] * e1[1]
                    py = x[0] * e2[0] + x[1] * e2[1]
                    r = rpix[0]
                else:
                    x[0], x[1], x[2] = points[i, 0], points[i, 1], points[i, 2]
                    px, py, r = plane[i, 0], plane[i, 1], rpix[i]
                pd = x[0] * s[0] + x[1] * s[1] + x[2] * s[2]
                col = int(np.floor((px - x0) / cell))
                row = int(np.floor((py - y0) / cell))
                if col < 0 or col >= n_cols or row < 0 or row >= n_rows:
                    continue
                k = row * n_cols + col
                n_found = 0
                extra = False
                for j in range(start[k], start[k + 1]):
                    e = members[j]
                    # The box of the edge's ends across the light, grown by its reach, first.
                    ox = max(ends[e, 6] - px, 0.0, px - ends[e, 7])
                    oy = max(ends[e, 8] - py, 0.0, py - ends[e, 9])
                    if ox * ox + oy * oy > ends[e, 10]:
                        continue
                    gap, scale = cone_gap(px, py, pd, e, ends, kappa, r)
                    if gap > 0.0:
                        continue
                    sc = gap / max(scale, 1e-300)
                    # Insert, keeping the k_max lowest scores in order.
                    if n_found < k_max:
                        pos = n_found
                        n_found += 1
                    elif sc < score[k_max - 1]:
                        pos = k_max - 1
                        extra = True
                    else:
                        extra = True
                        continue
                    while pos > 0 and score[pos - 1] > sc:
                        score[pos] = score[pos - 1]
                        ids[i, pos] = ids[i, pos - 1]
                        pos -= 1
                    score[pos] = sc
                    ids[i, pos] = e
                count[i] = n_found
                for q in range(n_found, k_max):
                    ids[i, q] = -1
                if extra:
                    overflow[c] += 1

    return register, query


@functools.cache
def _arrangement_kernel():
    """The compiled loop of ``arrangement`` (numba): per point, the segments in the sun's view
    (the arithmetic of ``wedge.gnomonic_segments``) and the walk along each (``walk``); with pixel
    axes, the same for the segments' shadows on the pixel's plane (``wedge.pixel_segments``);
    then the pairs and crossings of the segments that take part."""
    import numba

    @numba.njit(cache=True, nogil=True)
    def walk(kk, ax, ay, bx, by, w, lo, hi, W0, st, en, cj, ci, cd, ys, js, who, box, with_angle):
        """Along each segment j's part [lo_j, hi_j] (positions from the foot of the perpendicular
        from the origin): W on its lit side, from a reference point nearest the origin (W0 at the
        origin plus the signed crossings of the path there), then through its crossings in order.
        Fills the boundary's statuses at the part's ends (st, en) and its changes at crossings
        (cj, ci, cd); returns (crossings, the boundary pieces' angle sum S at the origin, with
        statuses extended to the segments' ends, crossings dropped beyond cj's length). ys, js, who
        (k,) and box (4, k): scratch space (allocated once by the caller: allocations per point
        cost more than the walk); kk: the slots in use (the candidates come first)."""
        k = kk
        c_max = cj.shape[0]
        x_lo, x_hi, y_lo, y_hi = box[0], box[1], box[2], box[3]
        nc = 0
        dropped = 0
        angle = 0.0
        for i in range(k):  # bounding boxes: most pairs of segments are far apart
            x_lo[i], x_hi[i] = min(ax[i], bx[i]), max(ax[i], bx[i])
            y_lo[i], y_hi[i] = min(ay[i], by[i]), max(ay[i], by[i])
        for j in range(k):
            st[j] = 0.0
            en[j] = 0.0
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
            qx_lo, qx_hi, qy_lo, qy_hi = min(qx, 0.0), max(qx, 0.0), min(qy, 0.0), max(qy, 0.0)
            for i in range(k):
                if i == j or w[i] <= 0.0:
                    continue
                dxi, dyi = bx[i] - ax[i], by[i] - ay[i]
                path = x_lo[i] <= qx_hi and x_hi[i] >= qx_lo and y_lo[i] <= qy_hi and y_hi[i] >= qy_lo
                # Both tests: 0 < s, r < 1 for s = sn / den, r = rn / den, without dividing.
                if path:
                    den = qx * dyi - qy * dxi
                    sn = ax[i] * dyi - ay[i] * dxi
                    rn = ax[i] * qy - ay[i] * qx
                    if (den > 0.0 and 0.0 < sn < den and 0.0 < rn < den) or (
                            den < 0.0 and den < sn < 0.0 and den < rn < 0.0):
                        W += -w[i] if den > 0.0 else w[i]
                meet = x_lo[i] <= x_hi[j] and x_hi[i] >= x_lo[j] and y_lo[i] <= y_hi[j] and y_hi[i] >= y_lo[j]
                if meet:
                    den = dx * dyi - dy * dxi
                    ex, ey = ax[i] - ax[j], ay[i] - ay[j]
                    sn = ex * dyi - ey * dxi
                    rn = ex * dy - ey * dx
                    if (den > 0.0 and 0.0 < sn < den and 0.0 < rn < den) or (
                            den < 0.0 and den < sn < 0.0 and den < rn < 0.0):
                        y = ya + sn / den * ln
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
            st[j] = on
            # The angle from the segment's start A to its point at y, seen from the origin.
            a2 = ax[j] * ax[j] + ay[j] * ay[j]
            at = ax[j] * tx + ay[j] * ty
            axt = ax[j] * ty - ay[j] * tx
            for q in range(m):
                W += js[q]
                new = 1.0 if (W <= 0.0 and W + w[j] >= 1.0) else 0.0
                if new != on:
                    if nc < c_max:
                        cj[nc], ci[nc], cd[nc] = j, who[q], new - on
                        nc += 1
                        if with_angle:
                            yy = ys[q] - ya
                            angle -= (new - on) * np.arctan2(yy * axt, a2 + yy * at)
                    else:
                        dropped += 1
                    on = new
            en[j] = on
            if with_angle and on > 0.0:
                angle += np.arctan2(ln * axt, a2 + ln * at)
        return nc, angle, dropped

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

    @loop_helper
    def point_range(first, last, chunk, points, ids, a, b, faces, centre, jump, frame, radius, reach, axes,
                    with_pixel, offset, pixel_offset, pair_edge, p_st, p_en, p_pst, p_pen, p_flip, p_pflip, n_pairs, cross,
                    cross_change, n_cross, pcross, pcross_change, n_pcross, boundary, overflow):
        n, k = ids.shape
        c_max = cross.shape[1]
        ax = np.empty(k)
        ay = np.empty(k)
        bx = np.empty(k)
        by = np.empty(k)
        w = np.empty(k)
        lo = np.empty(k)
        hi = np.empty(k)
        st = np.zeros(k)
        en = np.zeros(k)
        pst = np.zeros(k)
        pen = np.zeros(k)
        flip_d = np.zeros(k, np.bool_)
        flip_p = np.zeros(k, np.bool_)
        cj = np.empty(c_max, np.int64)
        ci = np.empty(c_max, np.int64)
        cd = np.empty(c_max)
        pj = np.empty(c_max, np.int64)
        pi_ = np.empty(c_max, np.int64)
        pd = np.empty(c_max)
        need = np.zeros(k, np.bool_)
        near_pixel = np.zeros(k, np.bool_)
        ys = np.empty(k)
        js = np.empty(k)
        who = np.empty(k, np.int64)
        box = np.empty((4, k))
        slot = np.empty(k, np.int64)
        s0, s1, s2 = frame[0, 0], frame[0, 1], frame[0, 2]
        for p in range(first, last):
            x0, x1, x2 = points[p, 0], points[p, 1], points[p, 2]
            kk = 0
            while kk < k and ids[p, kk] >= 0:  # the candidates fill the first slots
                kk += 1
            W0 = offset[p]
            # W can fall only across a segment whose covered side holds the centre (a straight path
            # from the centre crosses each line once): if those cannot bring W0 down to 0, the
            # region is wholly hidden and there is no boundary to walk.
            down = 0.0
            for j in range(kk):
                w[j] = 0.0
                ax[j] = ay[j] = bx[j] = by[j] = 0.0
                lo[j], hi[j] = 1.0, 0.0
                near_pixel[j] = False
                e = ids[p, j]
                if e < 0:
                    continue
                wa0, wa1, wa2 = a[e, 0] - x0, a[e, 1] - x1, a[e, 2] - x2
                wb0, wb1, wb2 = b[e, 0] - x0, b[e, 1] - x1, b[e, 2] - x2
                da = wa0 * s0 + wa1 * s1 + wa2 * s2
                db = wb0 * s0 + wb1 * s1 + wb2 * s2
                # Whether its shadow along the sun may cross the pixel: the segment across the light
                # within the pixel's reach of the point (in front of it or, in the receiver's plane,
                # behind), as the gather's tube.
                ua0 = wa0 * frame[1, 0] + wa1 * frame[1, 1] + wa2 * frame[1, 2]
                ua1 = wa0 * frame[2, 0] + wa1 * frame[2, 1] + wa2 * frame[2, 2]
                ub0 = wb0 * frame[1, 0] + wb1 * frame[1, 1] + wb2 * frame[1, 2]
                ub1 = wb0 * frame[2, 0] + wb1 * frame[2, 1] + wb2 * frame[2, 2]
                du0, du1 = ub0 - ua0, ub1 - ua1
                dd = du0 * du0 + du1 * du1
                tt = min(max(-(ua0 * du0 + ua1 * du1) / dd, 0.0), 1.0) if dd > 0.0 else 0.0
                c0, c1 = ua0 + tt * du0, ua1 + tt * du1
                near_pixel[j] = (c0 * c0 + c1 * c1 <= reach[p] * reach[p]
                                 and max(da, db) >= -BACK_REACH * reach[p])
                dmin = 1e-7 + 1e-6 * max(abs(wa0) + abs(wa1) + abs(wa2), abs(wb0) + abs(wb1) + abs(wb2))
                if not (da > dmin or db > dmin):
                    continue  # no part in the sun's view (its shadow may still cross the pixel)
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
                # Seen from the point, the edge bounds the mesh (a contour) when exactly one of its
                # faces faces the point, or it has one face; its covered side is where its faces lie:
                # the inward direction of the face less edge-on to the point, projected at the
                # segment's middle.
                f1 = faces[e, 0] * wa0 + faces[e, 1] * wa1 + faces[e, 2] * wa2
                contour = True
                g = 6
                if faces[e, 12] > 1.5:
                    f2 = faces[e, 3] * wa0 + faces[e, 4] * wa1 + faces[e, 5] * wa2
                    contour = (f1 < 0.0) != (f2 < 0.0)
                    if abs(f2) > abs(f1):
                        g = 9
                m0, m1, m2 = 0.5 * (pa0 + pb0), 0.5 * (pa1 + pb1), 0.5 * (pa2 + pb2)
                dm = m0 * s0 + m1 * s1 + m2 * s2
                mx = (m0 * frame[1, 0] + m1 * frame[1, 1] + m2 * frame[1, 2]) / dm
                my = (m0 * frame[2, 0] + m1 * frame[2, 1] + m2 * frame[2, 2]) / dm
                gs = faces[e, g] * s0 + faces[e, g + 1] * s1 + faces[e, g + 2] * s2
                gx = faces[e, g] * frame[1, 0] + faces[e, g + 1] * frame[1, 1] + faces[e, g + 2] * frame[1, 2] - mx * gs
                gy = faces[e, g] * frame[2, 0] + faces[e, g + 1] * frame[2, 1] + faces[e, g + 2] * frame[2, 2] - my * gs
                flip_d[j] = (qx - px) * gy - (qy - py) * gx < 0.0
                if flip_d[j]:
                    px, py, qx, qy = qx, qy, px, py
                ax[j], ay[j], bx[j], by[j] = px, py, qx, qy
                w[j] = jump[e] if contour else 0.0
                # The part within the disk, widened by the pixel's reach at the segment's depth.
                dx, dy = qx - px, qy - py
                ln = np.sqrt(dx * dx + dy * dy)
                if ln > 0.0:
                    u = (py * dx - px * dy) / ln
                    rad = radius + reach[p] / max(dpa, dpb)
                    ya = (px * dx + py * dy) / ln
                    if abs(u) < rad:
                        chord = np.sqrt(rad * rad - u * u)
                        lo[j], hi[j] = max(ya, -chord), min(ya + ln, chord)
                        if u < 0.0 and lo[j] < hi[j]:
                            down += w[j]

            if (W0 >= 0.5 and down < W0) or radius < 0.0:  # (radius < 0: no disk, the pixel alone)
                nc, angle, dropped = 0, 0.0, 0
                for j in range(kk):
                    st[j] = 0.0
                    en[j] = 0.0
            else:
                nc, angle, dropped = walk(kk, ax, ay, bx, by, w, lo, hi, W0, st, en, cj, ci, cd, ys, js, who, box, True)
            overflow[chunk] += dropped
            offset[p] = (1.0 if W0 >= 0.5 else 0.0) - angle / (2.0 * np.pi)
            pixel_offset[p] = 1.0 if W0 >= 0.5 else 0.0
            npc = 0
            for j in range(kk):
                pst[j] = 0.0
                pen[j] = 0.0
            some_near = False
            for j in range(kk):
                some_near = some_near or near_pixel[j]
            if with_pixel and some_near:
                # The segments' shadows on the pixel's plane, in pixel units (the pixel: the unit
                # square about the point), along the sun's direction s: v - x = al a + be b + t s.
                a0, a1, a2 = axes[p, 0, 0], axes[p, 0, 1], axes[p, 0, 2]
                b0, b1, b2 = axes[p, 1, 0], axes[p, 1, 1], axes[p, 1, 2]
                cbs0, cbs1, cbs2 = b1 * s2 - b2 * s1, b2 * s0 - b0 * s2, b0 * s1 - b1 * s0
                csa0, csa1, csa2 = s1 * a2 - s2 * a1, s2 * a0 - s0 * a2, s0 * a1 - s1 * a0
                det = a0 * cbs0 + a1 * cbs1 + a2 * cbs2
                if det != 0.0:
                    down = 0.0
                    flip = det < 0.0  # mirrored axes: swap them (as wedge.pixel_segments)
                    for j in range(kk):
                        w[j] = 0.0
                        lo[j], hi[j] = 1.0, 0.0
                        e = ids[p, j]
                        if e < 0 or not near_pixel[j] or not centre[e]:
                            continue
                        wa0, wa1, wa2 = a[e, 0] - x0, a[e, 1] - x1, a[e, 2] - x2
                        wb0, wb1, wb2 = b[e, 0] - x0, b[e, 1] - x1, b[e, 2] - x2
                        # The whole segment along s, on either side of the plane (no cut at it:
                        # an edge lying in the plane would lose a finite part to a hair's tilt).
                        px = (cbs0 * wa0 + cbs1 * wa1 + cbs2 * wa2) / det
                        py = (csa0 * wa0 + csa1 * wa1 + csa2 * wa2) / det
                        qx = (cbs0 * wb0 + cbs1 * wb1 + cbs2 * wb2) / det
                        qy = (csa0 * wb0 + csa1 * wb1 + csa2 * wb2) / det
                        # The covered side: the inward direction of the face less edge-on to the
                        # sun (a silhouette's two faces project to the same side along it).
                        g = 6
                        if faces[e, 12] > 1.5 and abs(faces[e, 3] * s0 + faces[e, 4] * s1 + faces[e, 5] * s2) > abs(
                                faces[e, 0] * s0 + faces[e, 1] * s1 + faces[e, 2] * s2):
                            g = 9
                        gx = (cbs0 * faces[e, g] + cbs1 * faces[e, g + 1] + cbs2 * faces[e, g + 2]) / det
                        gy = (csa0 * faces[e, g] + csa1 * faces[e, g + 1] + csa2 * faces[e, g + 2]) / det
                        if flip:
                            px, py, qx, qy, gx, gy = py, px, qy, qx, gy, gx
                        flip_p[j] = (qx - px) * gy - (qy - py) * gx < 0.0
                        if flip_p[j]:
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
                                if py * dx - px * dy < 0.0:
                                    down += w[j]
                    if not (W0 >= 0.5 and down < W0):
                        npc, angle, dropped = walk(kk, ax, ay, bx, by, w, lo, hi, W0, pst, pen, pj, pi_, pd, ys, js,
                                                   who, box, True)
                        overflow[chunk] += dropped
                        pixel_offset[p] -= angle / (2.0 * np.pi)
            # The pairs: the segments on the boundary somewhere, or crossing it.
            any_on = False
            for j in range(kk):
                need[j] = st[j] > 0.0 or en[j] > 0.0 or pst[j] > 0.0 or pen[j] > 0.0
                any_on = any_on or need[j]
            for q in range(nc):
                need[cj[q]] = True
                need[ci[q]] = True
                any_on = True
            for q in range(npc):
                need[pj[q]] = True
                need[pi_[q]] = True
                any_on = True
            boundary[p] = any_on
            m = 0
            for j in range(kk):
                if need[j]:
                    slot[j] = m
                    pair_edge[p, m] = ids[p, j]
                    p_st[p, m], p_en[p, m] = st[j], en[j]
                    p_pst[p, m], p_pen[p, m] = pst[j], pen[j]
                    p_flip[p, m], p_pflip[p, m] = flip_d[j], flip_p[j]
                    m += 1
            n_pairs[p] = m
            for q in range(nc):
                cross[p, q, 0], cross[p, q, 1] = slot[cj[q]], slot[ci[q]]
                cross_change[p, q] = cd[q]
            n_cross[p] = nc
            for q in range(npc):
                pcross[p, q, 0], pcross[p, q, 1] = slot[pj[q]], slot[pi_[q]]
                pcross_change[p, q] = pd[q]
            n_pcross[p] = npc


    @numba.njit(cache=True, nogil=True)
    def kernel(first, stride, n_chunks, points, ids, a, b, faces, centre, jump, frame, radius, reach, axes,
               with_pixel, offset, pixel_offset, pair_edge, p_st, p_en, p_pst, p_pen, p_flip, p_pflip, n_pairs, cross,
               cross_change, n_cross, pcross, pcross_change, n_pcross, boundary, overflow):
        # Chunks first, first + stride, ... of n_chunks (``_on_threads``).
        n = ids.shape[0]
        for chunk in range(first, n_chunks, stride):
            point_range(chunk * n // n_chunks, (chunk + 1) * n // n_chunks, chunk, points, ids, a, b, faces,
                        centre, jump, frame, radius, reach, axes, with_pixel, offset, pixel_offset, pair_edge,
                        p_st, p_en, p_pst,
                        p_pen, p_flip, p_pflip, n_pairs, cross, cross_change, n_cross, pcross, pcross_change,
                        n_pcross, boundary, overflow)

    return kernel
