"""The sun's plan at many receiver points at once (a camera's every pixel), in compiled passes.

``plan_points``' light-space back end makes its per-point choices as NumPy array operations:
at the 300,000 points of a 640 x 480 scene image their temporaries cost most of a frame.
``plan_dense_points`` makes the same choices, step by step with the same raster, shadow map and
rules (``softshadow.plan``), with the per-point steps (projection, the reach test, gathering,
the points' spacing, the raster lookup, the band) as compiled loops (numba), and keeps the
result compact: the hard shadow of every point and a ``PointPlan`` of the band points only,
which is all the penumbra formula (``softshadow.evaluate``) needs. ``DensePlan.point_plan``
expands it into the ``PointPlan`` that ``plan_points(..., backend="light")`` returns, equal to
it (tests/test_scene_frame.py).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np

from .camera import GroundGrid
from .occluder import Occluder
from .parallel_loops import loop_helper, parallel_numba
from .params import Pose, Sun
from .plan import (BAND_FRACTION, CANDIDATE_RADII_PX, CANDIDATE_REACH_PX, N_CANDIDATES, EdgeSet,
                   PointPlan, _pack_edges, bucket_size, light_band_widths, raster_grid)
from .posed import PosedOccluder
from .raster import rasterise_shadow
from .scratch import Scratch, scratch_array
from .shadowmap import (BIAS_PX, FACING_TOL, PRECISION_ULPS, SLOPE_PX, TAN_MAX, LightFrame, face_depth_at, faces_away,
                        shadow_map)

__all__ = ["DensePlan", "PointBlocks", "plan_dense_points"]


@dataclasses.dataclass(frozen=True)
class DensePlan:
    """The sun's plan at n points, compact.

    edges: the silhouette's ``EdgeSet``; hard (n,) 0/1: the hard shadow (attached shadow
    included) of every point; band (m,) int64: the points in a penumbra band, ascending;
    edge_id (m, K) int32, near_boundary (m,): their candidate edges and boundary flags
    (``PointPlan``'s meanings); edge_count: the silhouette's edges, the first of ``edges`` (the
    rest is padding).
    """

    edges: EdgeSet
    hard: np.ndarray
    band: np.ndarray
    edge_id: np.ndarray
    near_boundary: np.ndarray
    edge_count: int

    def band_plan(self, size: int | None = None) -> PointPlan:
        """A ``PointPlan`` of the band points only, padded to ``size`` (default: a power-of-two
        bucket, so that a jitted evaluation sees few shapes); padding rows are inactive."""
        return PointPlan(self.edges, *self.band_rows(size or bucket_size(len(self.band))))

    def band_rows(self, size: int, dtype=np.float64) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``band_plan(size)``'s per-point leaves: edge_id (size, K) int32, hard (size,), active
        (size,) bool, near_boundary (size,), the floats in ``dtype``."""
        m = len(self.band)
        edge_id = np.zeros((size, N_CANDIDATES), np.int32)
        edge_id[:m] = self.edge_id
        hard = np.zeros(size, dtype)
        hard[:m] = self.hard[self.band]
        near = np.zeros(size, dtype)
        near[:m] = self.near_boundary
        return edge_id, hard, np.arange(size) < m, near

    def point_plan(self, pad_to: int | None = None) -> PointPlan:
        """The ``PointPlan`` of all n points, as ``plan_points`` returns it (padded to ``pad_to``,
        default a power-of-two bucket)."""
        n = len(self.hard)
        size = pad_to or bucket_size(n)
        edge_id = np.zeros((size, N_CANDIDATES), np.int32)
        edge_id[self.band] = self.edge_id
        hard = np.zeros(size)
        hard[:n] = self.hard
        active = np.zeros(size, bool)
        active[self.band] = True
        near = np.zeros(size)
        near[self.band] = self.near_boundary
        return PointPlan(self.edges, edge_id, hard, active, near)


#: Points per run of ``PointBlocks``: a tenth of a 640-pixel image row, a short strip on the
#: ground (in the masking scene's view, 52 % of these runs are skipped, 27 % of runs of 256).
RUN_POINTS = 64


@dataclasses.dataclass(frozen=True)
class PointBlocks:
    """Bounds of runs of ``RUN_POINTS`` consecutive points (the last may be shorter), so that the
    sun's plan skips the runs out of the shadow's reach without reading their points: made once
    for points that stay (a camera's) and given to ``plan_dense_points`` for every sun.

    lo, hi (B, 3): each run's world bounds (m); normal (B, 3), uniform (B,) bool: the run's one
    normal where all its normals are equal (a flat ground), else uniform is False.
    """

    lo: np.ndarray
    hi: np.ndarray
    normal: np.ndarray
    uniform: np.ndarray

    @classmethod
    def of(cls, points: np.ndarray, normals: np.ndarray | None = None) -> "PointBlocks":
        """The runs' bounds of points (N, 3) and their normals (N, 3) or None (then none is uniform)."""
        points = np.ascontiguousarray(points, np.float64).reshape(-1, 3)
        normals = np.zeros((0, 3)) if normals is None else np.ascontiguousarray(normals, np.float64).reshape(-1, 3)
        if len(normals) and len(normals) != len(points):
            raise ValueError(f"{len(normals)} normals for {len(points)} points")
        b = -(-len(points) // RUN_POINTS)
        out = cls(np.empty((b, 3)), np.empty((b, 3)), np.zeros((b, 3)), np.zeros(b, np.bool_))
        _runs_kernel()(points, normals, out.lo, out.hi, out.normal, out.uniform)
        return out


def _empty(occ: Occluder, sil, hard: np.ndarray) -> DensePlan:
    """No point in a band: the silhouette's edges without a raster, and the hard shadow."""
    return DensePlan(_pack_edges(occ, sil), hard, np.zeros(0, np.int64), np.zeros((0, N_CANDIDATES), np.int32),
                     np.zeros(0), len(sil.vertex_ids))


def plan_dense_points(occ: Occluder, pose: Pose, sun: Sun, points: np.ndarray, range_k_max: float,
                      normals: np.ndarray | None = None, *, rule: str = "edge", margin_px: float = 2.5,
                      posed: PosedOccluder | Future | None = None, world: np.ndarray | None = None,
                      faces: np.ndarray | None = None, scratch: Scratch | None = None,
                      reached: Callable[[np.ndarray, np.ndarray], None] | None = None,
                      pool: ThreadPoolExecutor | None = None, blocks: PointBlocks | None = None) -> DensePlan:
    """``plan_points(occ, pose, sun, points, range_k_max, rule, normals=normals, backend="light",
    margin_px=margin_px)``, compact (``DensePlan``) and faster for many points.

    points (N, 3) world metres; normals (N, 3) unit or None; posed: the occluder already posed
    under this sun (``PosedOccluder.make(occ, pose, sun)``), to share it with other steps, or
    the Future of it (made on another thread) with world, its vertices (V, 3): the points are
    projected into the sun's view while it is made;
    faces (N,) int, optional: the occluder's face each point lies on (-1: not on it), as a
    camera's z-buffer knows it. A point whose own face is the shadow map's nearest face at its
    pixel is lit without the lookup (the lookup would find that face and the point on it).
    scratch: keep the per-point arrays in these buffers (``softshadow.scratch``; the plan's
    ``hard`` is then overwritten by the next call with the same scratch). reached(cand, hard),
    optional: called before the light-space raster is made (not at all when no point is within
    the shadow's reach), with the points within it (ascending) and the plan's ``hard`` (n,),
    final already at every point not among them (written at those later): another thread may
    shade those points while this one goes on. pool: a second thread that makes half the
    raster's distance transform, the band and its candidate edges (while this one tests the
    points near the outline) and packs the silhouette's edges (after what it was given before)
    while this one goes on: the same plan. blocks: ``PointBlocks.of(points, normals)``, kept
    while the points stay (a camera's): the runs of points out of the shadow's reach are then
    skipped (the same plan).
    """
    if posed is None:
        posed = PosedOccluder.make(occ, pose, sun)
    if isinstance(posed, Future):
        if world is None:
            raise ValueError("plan_dense_points: a Future of the posed occluder needs its world vertices")
        light = np.asarray(sun.light_np, np.float64)
    else:
        world, light = posed.world, posed.light
    points = np.ascontiguousarray(points, np.float64).reshape(-1, 3)
    n = len(points)
    if normals is not None:
        normals = np.ascontiguousarray(normals, np.float64).reshape(-1, 3)
        if len(normals) != n:
            raise ValueError(f"{len(normals)} normals for {n} receiver points")
    runs = (np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.bool_)) if blocks is None else \
        (blocks.lo, blocks.hi, blocks.normal, blocks.uniform)
    if len(runs[0]) not in (0, -(-n // RUN_POINTS)):
        raise ValueError(f"plan_dense_points: {len(runs[0])} runs of points for {n} points (PointBlocks.of(points))")
    # Per column: (V, 3).min(0) is several times slower.
    lo_w = np.array([world[:, j].min() for j in range(3)])
    hi_w = np.array([world[:, j].max() for j in range(3)])
    frame = LightFrame.of_light(light, 0.5 * (lo_w + hi_w))
    # The deepest point in the sun's view (``LightFrame.project``'s depth), needing neither the
    # silhouette nor the light-space vertices: made while the posed occluder may still be made.
    hard = scratch_array(scratch, "sun.hard", n)
    basis = np.stack([frame.origin, frame.e1, frame.e2, frame.light])
    d_max = _depth_max_kernel()(points, basis, runs[0], runs[1]) if n else -np.inf
    if isinstance(posed, Future):
        posed = posed.result()
        if not ((posed.world is world or np.array_equal(posed.world, world)) and np.array_equal(posed.light, light)):
            raise ValueError("plan_dense_points: the posed occluder is not the world vertices under this sun")
    sil = posed.silhouette
    if not (n and len(sil.vertex_ids)):
        attached = np.zeros(n, bool) if normals is None else faces_away(normals, light)
        return _empty(occ, sil, attached.astype(np.float64))
    uv_v, d_v = frame.project(world)
    ids = sil.vertex_ids
    edge_depth = np.minimum(d_v[ids[:, 0]], d_v[ids[:, 1]])
    # The region the shadow can reach, as plan_points takes it (its comments give the reasons).
    reach = float(light_band_widths(d_max - edge_depth.min(), range_k_max))
    lo_occ = np.array([uv_v[:, 0].min(), uv_v[:, 1].min()])
    hi_occ = np.array([uv_v[:, 0].max(), uv_v[:, 1].max()])
    extent = float((hi_occ - lo_occ).max()) + 3.0 * reach
    margin_m = (margin_px + CANDIDATE_REACH_PX + 2) * extent / 256
    # Per point in one pass: its attached shadow (``faces_away``) into hard, its light-space
    # position and depth (``LightFrame.project``), and whether it is within its own reach
    # (``plan._within_reach``): those gathered in order with their position, depth and attached
    # shadow; the gathered points' bounds beside.
    cand = scratch_array(scratch, "sun.cand", n, np.int64)
    uv_p = scratch_array(scratch, "sun.cand_uv", (n, 2))
    d_p = scratch_array(scratch, "sun.cand_depth", n)
    att = scratch_array(scratch, "sun.cand_attached", n, np.bool_)
    bounds = np.empty(5)
    count = _reach_kernel()(points, np.zeros((0, 3)) if normals is None else normals, basis, -FACING_TOL, hard,
                            lo_occ, hi_occ, float(edge_depth.min()),
                            1.5 * float(light_band_widths(np.float64(1.0), range_k_max)), margin_m, *runs, cand, uv_p,
                            d_p, att, bounds, parallel_numba().get_num_threads())
    if not count:
        return _empty(occ, sil, hard)
    cand, uv_p, d_p, att = cand[:count], uv_p[:count], d_p[:count], att[:count]
    reach = float(light_band_widths(bounds[4] - edge_depth.min(), range_k_max))
    extent = float((hi_occ - lo_occ).max()) + 3.0 * reach
    lo_pts, hi_pts = bounds[:2].copy(), bounds[2:4].copy()
    spacing = _spacing(uv_p, extent / 128, lo_pts, hi_pts)
    pixel_m = max(float(np.clip(spacing, extent / 2048, extent / 256)), 1e-5)
    map_pixel_m = float(np.clip(spacing, extent / 2048, extent / 512))
    pad_m = 1.5 * reach + (margin_px + CANDIDATE_REACH_PX + 2) * pixel_m
    lo = np.maximum(lo_occ - pad_m, lo_pts - pad_m)
    hi = np.minimum(hi_occ + pad_m, hi_pts + pad_m)
    if np.any(hi <= lo):
        return _empty(occ, sil, hard)
    grid, map_pixel_m = raster_grid(lo, hi, pixel_m, map_pixel_m)
    if reached is not None:
        # Just before the raster (one thread's NumPy and OpenCV, the longest step): work handed to
        # another thread then takes no core from this one's parallel passes.
        reached(cand, hard)
    # The distances that the band, the near-outline test and the candidates' rings read (a
    # band's widest wedge and margin, the rings' diagonal chamfer steps, a pixel for rounding).
    exact_px = (BAND_FRACTION * float(light_band_widths(bounds[4] - edge_depth.min(), range_k_max)) / pixel_m
                + margin_px + 1.5 * CANDIDATE_REACH_PX + 1.0)
    raster = rasterise_shadow(grid, world, light, sil, uv_v, exact_px=exact_px, pool=pool)
    m = len(cand)
    in_view = scratch_array(scratch, "sun.in_view", m, np.uint8)
    label = scratch_array(scratch, "sun.label", m, np.int32)
    dist = scratch_array(scratch, "sun.dist", m, np.float32)  # as ShadowRaster.lookup's: float32 pixels x size
    index = scratch_array(scratch, "sun.index", m, np.int64)
    # The raster at each point (``ShadowRaster.lookup``), and the points near the outline, where a
    # raster pixel is too coarse for the side: tested exactly.
    n_near = _lookup_kernel()(uv_p, grid.origin_m[0], grid.origin_m[1], pixel_m, raster.hard, raster.edge_label,
                              raster.boundary_dist_px, 2.0 * pixel_m, att, in_view, label, dist, index)
    # The band and its candidate edges need the raster and the points' depths only (not which
    # points are behind the occluder): the second thread (if any) makes them while this one
    # tests the points near the outline and in the occluder's view.
    frac = raster.edge_outline_fraction
    band_args = (cand, d_p, label, dist, att, uv_p, edge_depth, float(light_band_widths(np.float64(1.0), range_k_max)),
                 np.zeros(1) if frac is None else np.asarray(frac, np.float64), frac is not None, margin_px * pixel_m,
                 1.5 * pixel_m, grid.origin_m, pixel_m, raster, scratch)
    banded: Future | tuple = _submit(pool, _band_plan, *band_args)
    try:
        if n_near:
            # Here, while the second thread makes the band: sharing these points too (half each)
            # made both frames slower (measured in one process, alternated).
            near = index[:n_near].copy()
            in_view[near] = posed.hard_shadow_at(uv_p[near], projected=uv_v)
        # The silhouette's edges for the penumbra, made on the second thread (if any) meanwhile (from
        # this frame's raster and silhouette only: left running on an error, it touches no buffer).
        edges = _submit(pool, _pack_edges, occ, sil, raster=raster)
        lit_ids = np.flatnonzero(sil.lit) if occ.watertight else np.arange(len(occ.faces))
        lit_faces = occ.faces[lit_ids]
        # Farther from the sun than the whole occluder: behind it wherever it is in the way (most
        # of a cast shadow), the others in its view go to the shadow map; the hard shadow of every
        # point, final but at those.
        behind = scratch_array(scratch, "sun.behind", m, np.bool_)
        box = np.empty(4)
        # On this thread alone while the second makes the band: a loop split over both cores
        # would wait for the busy one.
        with _threads(1 if isinstance(banded, Future) and not banded.done() else None):
            n_test = _test_kernel()(cand, in_view, att, d_p, uv_p,
                                    float(d_v[lit_faces].max(initial=-np.inf)) + 0.5 * map_pixel_m, behind, hard,
                                    index, box)
        if n_test:
            test = index[:n_test]
            m_lo = box[:2] - 3 * map_pixel_m
            m_hi = box[2:] + 3 * map_pixel_m
            map_grid = GroundGrid(map_pixel_m, (float(m_lo[0]), float(m_hi[1])),
                                  int(np.ceil((m_hi[0] - m_lo[0]) / map_pixel_m)) + 1,
                                  int(np.ceil((m_hi[1] - m_lo[1]) / map_pixel_m)) + 1)
            shape = (map_grid.height, map_grid.width)
            smap = shadow_map(map_grid, uv_v, d_v, lit_faces,
                              out=(scratch_array(scratch, "sun.map_depth", shape),
                                   scratch_array(scratch, "sun.map_face", shape, np.int32)),
                              threads=2, scratch=scratch, name="sun.map")
            # ``ShadowMap.occluder_depth`` and ``depth_bias`` per point (their rules), the receiver's
            # slope from its normal, in one pass; the hard shadow of those points.
            scale = max(smap.scale, float(np.abs(world).max()))
            g = map_grid
            _depth_test_kernel()(cand, test, uv_p, d_p, points, np.zeros((0, 3)) if normals is None else normals,
                                 np.full(0, -1, np.int64) if faces is None else np.asarray(faces, np.int64),
                                 lit_ids, light, g.origin_m[0], g.origin_m[1], map_pixel_m, smap.face_id,
                                 np.ascontiguousarray(smap.triangle), smap.plane, smap.slope, scale, behind, hard)
        if isinstance(banded, Future):  # made here if the second thread has not started it
            banded = _band_plan(*band_args) if banded.cancel() else banded.result()
    finally:
        if isinstance(banded, Future) and not banded.cancel():
            banded.exception()  # its buffers are the next call's: never left running
    assert isinstance(banded, tuple)
    band, edge_id, near_b = banded
    if isinstance(edges, Future):  # made here if the second thread has not started them
        edges = _pack_edges(occ, sil, raster=raster) if edges.cancel() else edges.result()
    return DensePlan(edges, hard, band, edge_id, near_b, len(sil.vertex_ids))


def _band_plan(cand: np.ndarray, d_p: np.ndarray, label: np.ndarray, dist: np.ndarray, att: np.ndarray,
               uv_p: np.ndarray, edge_depth: np.ndarray, per_m: float, frac: np.ndarray, has_frac: bool,
               margin_m: float, near_m: float, origin_m: tuple, pixel_m: float, raster,
               scratch: Scratch | None):
    """The band points (m,) int64 (ascending, into the points), their candidate edges (m, K) int32
    and boundary flags (m,) float64: ``_band_kernel`` and ``_candidates_kernel`` over the
    candidates (cand, their depth, raster label and distance, attached shadow, light-space
    position; origin_m, pixel_m: the raster's top-left pixel centre and the pixel its lookups take)."""
    index = scratch_array(scratch, "sun.band_index", len(cand), np.int64)
    near_b = scratch_array(scratch, "sun.near_boundary", len(cand), np.bool_)
    n_band = _band_kernel()(d_p, label, dist, att, edge_depth, per_m, frac, has_frac, BAND_FRACTION, margin_m,
                            near_m, index, near_b)
    sel = index[:n_band].copy()
    edge_id = np.zeros((n_band, N_CANDIDATES), np.int32)
    if n_band:
        neighbours = raster.edge_neighbours
        neighbours = np.full((0, 2), -1, np.int64) if neighbours is None else np.asarray(neighbours, np.int64)
        _candidates_kernel()(uv_p, sel, origin_m[0], origin_m[1], pixel_m, raster.edge_label,
                             neighbours, _CANDIDATE_OFFSETS, edge_id)
    return cand[sel], edge_id, near_b[:n_band].astype(np.float64)


@contextlib.contextmanager
def _threads(n: int | None):
    """The compiled loops of this thread on n threads meanwhile (None: as they are)."""
    if n is None:
        yield
        return
    numba = parallel_numba()
    before = numba.get_num_threads()
    numba.set_num_threads(min(n, before))
    try:
        yield
    finally:
        numba.set_num_threads(before)


def _submit(pool: ThreadPoolExecutor | None, fn, *args, **kwargs):
    """fn(...) on the pool's thread (a Future), or here and now without a pool."""
    return fn(*args, **kwargs) if pool is None else pool.submit(fn, *args, **kwargs)


def _spacing(uv: np.ndarray, cell_m: float, lo: np.ndarray, hi: np.ndarray) -> float:
    """``plan._spacing`` (the points' typical spacing: the area of the cells of side ``cell_m``
    they occupy, per point, square-rooted) in one compiled pass; lo, hi (2,): the points' bounds."""
    width = int((hi[0] - lo[0]) / cell_m) + 1
    height = int((hi[1] - lo[1]) / cell_m) + 1
    taken = _spacing_kernel()(uv, float(lo[0]), float(lo[1]), cell_m, width, height)
    return cell_m * float(np.sqrt(taken / len(uv)))


@functools.cache
def _spacing_kernel():
    numba = parallel_numba()

    # The cells marked on two threads (two threads may mark one cell: both write True), then counted.
    @numba.njit(cache=True, nogil=True, parallel=True)
    def kernel(uv, lo_u, lo_v, cell_m, width, height):
        taken = np.zeros(width * height, np.bool_)
        for i in numba.prange(uv.shape[0]):
            taken[int((uv[i, 1] - lo_v) / cell_m) * width + int((uv[i, 0] - lo_u) / cell_m)] = True
        count = 0
        for k in range(taken.shape[0]):
            count += taken[k]
        return count

    return kernel


#: ``candidate_labels``' samples around a pixel (row, col steps), in its order: per radius, the 8
#: directions.
_CANDIDATE_OFFSETS = np.array([(dr * r, dc * r) for r in CANDIDATE_RADII_PX for dr in (-1, 0, 1) for dc in (-1, 0, 1)
                               if (dr, dc) != (0, 0)], np.int64)

#: Points per block of the parallel gathering passes (each block's count, then each block at its place).
_BLOCK = 8192


@functools.cache
def _runs_kernel():
    """``PointBlocks.of``'s pass: each run's bounds, and its normal where all are equal."""
    numba = parallel_numba()

    @numba.njit(cache=True, nogil=True, parallel=True)
    def kernel(points, normals, lo, hi, normal, uniform):
        n = points.shape[0]
        for b in numba.prange(lo.shape[0]):
            start, end = b * RUN_POINTS, min((b + 1) * RUN_POINTS, n)
            same = normals.shape[0] > 0
            for j in range(3):
                lo[b, j], hi[b, j] = np.inf, -np.inf
                if same:
                    normal[b, j] = normals[start, j]
            for i in range(start, end):
                for j in range(3):
                    lo[b, j], hi[b, j] = min(lo[b, j], points[i, j]), max(hi[b, j], points[i, j])
                    if same and normals[i, j] != normal[b, j]:
                        same = False
            uniform[b] = same

    return kernel


@functools.cache
def _run_bounds():
    """The bounds (lo, hi) of a linear map (x - origin) . axis over a run's box (lo, hi (B, 3)),
    widened by rounding: they hold the value that ``_reach_kernel`` computes at any point of the
    run (a box's extremes are at its corners). Not inlined: numba's inlining of its loop into a
    parallel loop failed one of its own checks (a warning)."""

    @loop_helper
    def bounds(lo, hi, b, origin, axis):
        low, high, size = 0.0, 0.0, 0.0
        for j in range(3):
            a0, a1 = (lo[b, j] - origin[j]) * axis[j], (hi[b, j] - origin[j]) * axis[j]
            low += min(a0, a1)
            high += max(a0, a1)
            size += max(abs(a0), abs(a1))
        slack = 1e-12 * (1.0 + size)  # far above the few ulps of a point's own sum
        return low - slack, high + slack

    return bounds


@functools.cache
def _depth_max_kernel():
    """The largest depth of the points in the light frame (basis: origin, e1, e2, light; the
    depth as ``_reach_kernel`` computes it). With the runs' bounds (``PointBlocks``; else lo, hi
    empty) only the runs that can hold it are read: the same value."""
    numba = parallel_numba()
    run_bounds = _run_bounds()

    @loop_helper(inline=True)
    def depth(points, basis, i):
        x, y, z = points[i, 0] - basis[0, 0], points[i, 1] - basis[0, 1], points[i, 2] - basis[0, 2]
        return x * basis[3, 0] + y * basis[3, 1] + z * basis[3, 2]

    # On one thread: it runs while the second thread poses the occluder (a parallel loop would
    # wait for a core).
    @numba.njit(cache=True, nogil=True)
    def kernel(points, basis, lo, hi):
        n = points.shape[0]
        n_runs = lo.shape[0]
        d_max = -np.inf
        if n_runs == 0:
            for i in range(n):
                d_max = max(d_max, depth(points, basis, i))
            return d_max
        # A point of each run bounds the maximum from below; a run whose box is shallower
        # than that cannot hold it.
        upper = np.empty(n_runs)
        for b in range(n_runs):
            upper[b] = run_bounds(lo, hi, b, basis[0], basis[3])[1]
            d_max = max(d_max, depth(points, basis, b * RUN_POINTS))
        floor = d_max
        for b in range(n_runs):
            if upper[b] >= floor:
                for i in range(b * RUN_POINTS, min((b + 1) * RUN_POINTS, n)):
                    d_max = max(d_max, depth(points, basis, i))
        return d_max

    return kernel


@functools.cache
def _reach_kernel():
    """Per point: attached shadow (n . L >= -FACING_TOL, as ``faces_away``; 1.0 in hard, else
    0.0), the light-space position and depth (``LightFrame.project``; basis: origin, e1, e2,
    light), and ``plan._within_reach``'s test (per_m: 1.5 wedge widths per metre behind the
    nearest edge): the points within reach gathered in order, their index, position, depth and
    attached shadow, and their bounds (lo u, lo v, hi u, hi v, hi depth). Returns their count.
    With the runs' bounds (``PointBlocks``: run_lo, run_hi, run_normal, run_uniform; else empty),
    a run wholly out of reach gets its attached shadow only (from its one normal if uniform)."""
    numba = parallel_numba()
    run_bounds = _run_bounds()

    # Parallel over blocks of points: each block's points gathered at its own place first, then
    # moved together (one pass over the points, as one thread's loop). The blocks are dealt to
    # the threads in turn (threads: how many): the points within reach fill part of a camera's
    # image (a cast shadow on the ground), and split in halves one thread had twice the other's.
    @numba.njit(cache=True, nogil=True, parallel=True)
    def kernel(points, normals, basis, tol, hard, lo, hi, edge_depth, per_m, margin_m, run_lo, run_hi, run_normal,
               run_uniform, cand, uv, d, att, bounds, threads):
        n = points.shape[0]
        light = basis[3]
        has_normals = normals.shape[0] > 0
        n_blocks = (n + _BLOCK - 1) // _BLOCK
        counts = np.zeros(n_blocks, np.int64)
        box = np.empty((n_blocks, 5))
        threads = max(min(threads, n_blocks), 1)
        for t in numba.prange(threads):
            for b in range(t, n_blocks, threads):
                count = b * _BLOCK
                lo_u, lo_v, hi_u, hi_v, hi_d = np.inf, np.inf, -np.inf, -np.inf, -np.inf
                for start in range(b * _BLOCK, min((b + 1) * _BLOCK, n), RUN_POINTS):
                    end = min(start + RUN_POINTS, n)
                    if run_lo.shape[0]:
                        r = start // RUN_POINTS
                        u0, u1 = run_bounds(run_lo, run_hi, r, basis[0], basis[1])
                        v0, v1 = run_bounds(run_lo, run_hi, r, basis[0], basis[2])
                        deepest = run_bounds(run_lo, run_hi, r, basis[0], light)[1]
                        pad = per_m * max(deepest - edge_depth, 0.0) + margin_m
                        if (u1 < lo[0] - pad) | (u0 > hi[0] + pad) | (v1 < lo[1] - pad) | (v0 > hi[1] + pad):
                            if run_uniform[r]:
                                one = 1.0 if has_normals and run_normal[r, 0] * light[0] + run_normal[r, 1] * light[1] \
                                    + run_normal[r, 2] * light[2] >= tol else 0.0
                                for i in range(start, end):
                                    hard[i] = one
                            else:
                                for i in range(start, end):
                                    hard[i] = 1.0 if has_normals and normals[i, 0] * light[0] \
                                        + normals[i, 1] * light[1] + normals[i, 2] * light[2] >= tol else 0.0
                            continue
                    for i in range(start, end):
                        x, y, z = points[i, 0] - basis[0, 0], points[i, 1] - basis[0, 1], points[i, 2] - basis[0, 2]
                        u = x * basis[1, 0] + y * basis[1, 1] + z * basis[1, 2]
                        v = x * basis[2, 0] + y * basis[2, 1] + z * basis[2, 2]
                        di = x * basis[3, 0] + y * basis[3, 1] + z * basis[3, 2]
                        attached = has_normals and \
                            normals[i, 0] * light[0] + normals[i, 1] * light[1] + normals[i, 2] * light[2] >= tol
                        hard[i] = 1.0 if attached else 0.0
                        pad = per_m * max(di - edge_depth, 0.0) + margin_m
                        if (u >= lo[0] - pad) & (u <= hi[0] + pad) & (v >= lo[1] - pad) & (v <= hi[1] + pad):
                            # count <= i: never over a point not yet read
                            cand[count], uv[count, 0], uv[count, 1], d[count], att[count] = i, u, v, di, attached
                            lo_u, lo_v = min(lo_u, u), min(lo_v, v)
                            hi_u, hi_v, hi_d = max(hi_u, u), max(hi_v, v), max(hi_d, di)
                            count += 1
                counts[b] = count - b * _BLOCK
                box[b, 0], box[b, 1], box[b, 2], box[b, 3], box[b, 4] = lo_u, lo_v, hi_u, hi_v, hi_d
        count = 0
        bounds[0], bounds[1], bounds[2], bounds[3], bounds[4] = np.inf, np.inf, -np.inf, -np.inf, -np.inf
        for b in range(n_blocks):  # in order: a block's list moves down, never over one not yet moved
            for k in range(b * _BLOCK, b * _BLOCK + counts[b]):
                cand[count], uv[count, 0], uv[count, 1], d[count], att[count] = cand[k], uv[k, 0], uv[k, 1], d[k], att[k]
                count += 1
            bounds[0], bounds[1] = min(bounds[0], box[b, 0]), min(bounds[1], box[b, 1])
            bounds[2], bounds[3], bounds[4] = max(bounds[2], box[b, 2]), max(bounds[3], box[b, 3]), max(bounds[4], box[b, 4])
        return count

    return kernel


@functools.cache
def _depth_test_kernel():
    """The sun's depth test at the candidates ``test`` (cand[test] into the points):
    ``ShadowMap.occluder_depth`` (the exact face among the point's map pixel
    and its 8 neighbours, else the nearest covered pixel's within 2, extrapolated) against
    the point's depth plus ``depth_bias`` (the receiver's slope from its normal), into
    behind[test], and the hard shadow into hard[cand[test]] (left as it is, 0, at a point on the
    occluder whose own face is the nearest at its pixel: it is lit)."""
    numba = parallel_numba()
    depth_at = face_depth_at()

    @numba.njit(cache=True, nogil=True, parallel=True)
    def kernel(cand, test, uv, depth, points, normals, faces, lit_ids, light, ox, oy, pixel_m, face_id, triangle,
               plane, face_slope, scale, behind, hard):
        h, w = face_id.shape
        for j in numba.prange(test.shape[0]):
            p = cand[test[j]]
            scale = max(scale, max(abs(points[p, 0]), abs(points[p, 1]), abs(points[p, 2])))
        rounding = PRECISION_ULPS * np.finfo(np.float64).eps * scale
        for j in numba.prange(test.shape[0]):
            q = test[j]
            p = cand[q]
            u, v = uv[q, 0], uv[q, 1]
            col = int(np.rint((u - ox) / pixel_m))
            row = int(np.rint((oy - v) / pixel_m))
            if faces.shape[0] and faces[p] >= 0 and 0 <= row < h and 0 <= col < w and face_id[row, col] >= 0 \
                    and lit_ids[face_id[row, col]] == faces[p]:
                continue
            best, fs, exact = depth_at(u, v, row, col, face_id, triangle, plane, face_slope, -1e-7, 1.0 + 1e-7, 1.0)
            bias = BIAS_PX * pixel_m + rounding + 0.0
            if not exact:
                recv = 0.0
                if normals.shape[0]:
                    cos = abs(normals[p, 0] * light[0] + normals[p, 1] * light[1] + normals[p, 2] * light[2])
                    recv = np.sqrt(max(1.0 - cos * cos, 0.0)) / max(cos, 1e-12)
                bias += SLOPE_PX * pixel_m * (min(fs, TAN_MAX) + min(recv, TAN_MAX))
            behind[q] = depth[q] > best + bias
            hard[p] = 1.0 if behind[q] else 0.0

    return kernel


@functools.cache
def _lookup_kernel():
    """``ShadowRaster.lookup`` at light-space points (the nearest pixel): hard, label and the
    distance in metres (0, -1, +inf outside the raster); the points not in attached shadow within
    ``near_m`` of the outline listed in ``near``. Returns their count."""
    numba = parallel_numba()

    # Parallel over blocks of points; the near points listed per block, then moved together.
    @numba.njit(cache=True, nogil=True, parallel=True)
    def kernel(uv, ox, oy, pixel_m, hard, edge_label, dist_px, near_m, att, in_view, label, dist, near):
        h, w = hard.shape
        pm = np.float32(pixel_m)
        n_pts = uv.shape[0]
        block = 8192
        n_blocks = (n_pts + block - 1) // block
        start = np.zeros(n_blocks + 1, np.int64)
        for b in numba.prange(n_blocks):
            n = b * block
            for i in range(b * block, min((b + 1) * block, n_pts)):
                c = np.rint((uv[i, 0] - ox) / pixel_m)
                r = np.rint((oy - uv[i, 1]) / pixel_m)
                if 0 <= c < w and 0 <= r < h:
                    ci, ri = int(c), int(r)
                    in_view[i] = hard[ri, ci]
                    label[i] = edge_label[ri, ci]
                    dist[i] = dist_px[ri, ci] * pm
                else:
                    in_view[i], label[i], dist[i] = 0, -1, np.inf
                # The comparison in float32, as the array version's (a float32 array against a float).
                if dist[i] <= np.float32(near_m) and not att[i]:
                    near[n] = i  # at the block's own place first (n <= i)
                    n += 1
            start[b + 1] = n - b * block
        n = 0
        for b in range(n_blocks):  # in order: a block's list moves down, never over one not yet moved
            for k in range(start[b + 1]):
                near[n + k] = near[b * block + k]
            n += start[b + 1]
        return n

    return kernel


@functools.cache
def _test_kernel():
    """The points in the occluder's view (and not in attached shadow): those deeper than
    ``d_far`` are behind it; the others listed in ``test``, their light-space bounding box in
    box (lo u, lo v, hi u, hi v). The hard shadow of every point into hard[cand] (attached or
    behind; 0 at the listed ones, which the depth test decides). Returns their count."""
    numba = parallel_numba()

    # Parallel over blocks of points; each block's list at its own place first, then moved together.
    @numba.njit(cache=True, nogil=True, parallel=True)
    def kernel(cand, in_view, att, d, uv, d_far, behind, hard, test, box):
        n_pts = in_view.shape[0]
        n_blocks = (n_pts + _BLOCK - 1) // _BLOCK
        counts = np.zeros(n_blocks, np.int64)
        boxes = np.empty((n_blocks, 4))
        for b in numba.prange(n_blocks):
            n = b * _BLOCK
            lo_u, lo_v, hi_u, hi_v = np.inf, np.inf, -np.inf, -np.inf
            for i in range(b * _BLOCK, min((b + 1) * _BLOCK, n_pts)):
                behind[i] = False
                hard[cand[i]] = 1.0 if att[i] else 0.0
                if in_view[i] == 0 or att[i]:
                    continue
                if d[i] > d_far:
                    behind[i] = True
                    hard[cand[i]] = 1.0
                    continue
                test[n] = i  # n <= i
                n += 1
                lo_u, lo_v, hi_u, hi_v = min(lo_u, uv[i, 0]), min(lo_v, uv[i, 1]), max(hi_u, uv[i, 0]), max(hi_v, uv[i, 1])
            counts[b] = n - b * _BLOCK
            boxes[b, 0], boxes[b, 1], boxes[b, 2], boxes[b, 3] = lo_u, lo_v, hi_u, hi_v
        n = 0
        box[0], box[1], box[2], box[3] = np.inf, np.inf, -np.inf, -np.inf
        for b in range(n_blocks):  # in order: a block's list moves down, never over one not yet moved
            for k in range(b * _BLOCK, b * _BLOCK + counts[b]):
                test[n] = test[k]
                n += 1
            box[0], box[1] = min(box[0], boxes[b, 0]), min(box[1], boxes[b, 1])
            box[2], box[3] = max(box[2], boxes[b, 2]), max(box[3], boxes[b, 3])
        return n

    return kernel


@functools.cache
def _band_kernel():
    """The band and boundary flags of ``plan_points``' light back end per point, from the width
    of its wedge (per_m times its depth behind its edge): the band BAND_FRACTION of it plus the
    margin, near the boundary within a quarter of it plus 1.5 pixels on a clean outline edge
    (all of its length on the outline). The band's points listed in ``band``; returns their
    count."""
    numba = parallel_numba()

    # Parallel over blocks of points; each block's list at its own place first, then moved together.
    @numba.njit(cache=True, nogil=True, parallel=True)
    def kernel(d, label, dist, att, edge_depth, per_m, frac, has_frac, fraction, margin_m, near_m, band, near_b):
        n_pts = d.shape[0]
        n_blocks = (n_pts + _BLOCK - 1) // _BLOCK
        counts = np.zeros(n_blocks, np.int64)
        for b in numba.prange(n_blocks):
            n = b * _BLOCK
            for i in range(b * _BLOCK, min((b + 1) * _BLOCK, n_pts)):
                lab = label[i]
                width = per_m * max(d[i] - edge_depth[max(lab, 0)], 0.0)
                if lab >= 0 and dist[i] <= fraction * width + margin_m and not att[i]:
                    near_b[n] = dist[i] <= 0.25 * width + near_m and has_frac and frac[lab] >= 0.99
                    band[n] = i  # n <= i
                    n += 1
            counts[b] = n - b * _BLOCK
        n = 0
        for b in range(n_blocks):  # in order: a block's list moves down, never over one not yet moved
            for k in range(b * _BLOCK, b * _BLOCK + counts[b]):
                band[n], near_b[n] = band[k], near_b[k]
                n += 1
        return n

    return kernel


@functools.cache
def _candidates_kernel():
    """``raster.candidate_labels`` (up to K distinct labels: the pixel's own, its outline
    neighbours, then the labels at the offsets, greedily), with -1 made 0, at the raster's nearest
    pixel (clipped to the raster) of the points uv[sel], into edge_id (len(sel), K)."""
    numba = parallel_numba()

    @numba.njit(cache=True, nogil=True, parallel=True)
    def kernel(uv, sel, ox, oy, pixel_m, edge_label, neighbours, offsets, edge_id):
        h, w = edge_label.shape
        k_max = edge_id.shape[1]
        has_neighbours = neighbours.shape[0] > 0
        n_columns = offsets.shape[0] + (2 if has_neighbours else 0)
        for j in numba.prange(sel.shape[0]):
            q = sel[j]
            col = min(max(np.int64(np.rint((uv[q, 0] - ox) / pixel_m)), 0), w - 1)
            row = min(max(np.int64(np.rint((oy - uv[q, 1]) / pixel_m)), 0), h - 1)
            # The labels as found in edge_id[j] (-1 kept until the end).
            first = edge_label[row, col]
            edge_id[j, 0] = first
            count = 1
            last = first  # the label seen last: the samples repeat it more often than not
            for c in range(n_columns):
                if count >= k_max:
                    break
                if has_neighbours and c < 2:
                    v = neighbours[first, c] if first >= 0 else -1
                else:
                    o = c - 2 if has_neighbours else c
                    v = edge_label[min(max(row + offsets[o, 0], 0), h - 1), min(max(col + offsets[o, 1], 0), w - 1)]
                if v < 0 or v == last:
                    continue
                last = v
                fresh = True
                for s in range(count):
                    if edge_id[j, s] == v:
                        fresh = False
                        break
                if fresh:
                    edge_id[j, count] = v
                    count += 1
            for s in range(k_max):
                edge_id[j, s] = max(edge_id[j, s] if s < count else first, 0)

    return kernel
