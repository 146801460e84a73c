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

import dataclasses
import functools

import numpy as np

from .camera import GroundGrid
from .occluder import Occluder
from .params import Pose, Sun
from .plan import (BAND_FRACTION, CANDIDATE_RADII_PX, CANDIDATE_REACH_PX, MAX_RASTER_SIDE, N_CANDIDATES, EdgeSet,
                   PointPlan, _clean_outline, _pack_edges, _within_reach, bucket_size, light_band_widths)
from .posed import PosedOccluder
from .raster import candidate_labels, rasterise_shadow
from .shadowmap import LightFrame, depth_bias, faces_away, shadow_map

__all__ = ["DensePlan", "plan_dense_points"]


@dataclasses.dataclass(frozen=True)
class DensePlan:
    """The sun's plan at n points, compact.

    edges: the silhouette's ``EdgeSet``; hard (n,) 0/1: the hard shadow (attached shadow
    included) of every point; band (m,) int64: the points in a penumbra band, ascending;
    edge_id (m, K) int32, near_boundary (m,): their candidate edges and boundary flags
    (``PointPlan``'s meanings).
    """

    edges: EdgeSet
    hard: np.ndarray
    band: np.ndarray
    edge_id: np.ndarray
    near_boundary: np.ndarray

    def band_plan(self, size: int | None = None) -> PointPlan:
        """A ``PointPlan`` of the band points only, padded to ``size`` (default: a power-of-two
        bucket, so that a jitted evaluation sees few shapes); padding rows are inactive."""
        m = len(self.band)
        size = size or bucket_size(m)
        edge_id = np.zeros((size, N_CANDIDATES), np.int32)
        edge_id[:m] = self.edge_id
        hard = np.zeros(size)
        hard[:m] = self.hard[self.band]
        near = np.zeros(size)
        near[:m] = self.near_boundary
        return PointPlan(self.edges, edge_id, hard, np.arange(size) < m, near)

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


def _empty(edges: EdgeSet, hard: np.ndarray) -> DensePlan:
    return DensePlan(edges, hard, np.zeros(0, np.int64), np.zeros((0, N_CANDIDATES), np.int32), np.zeros(0))


def plan_dense_points(occ: Occluder, pose: Pose, sun: Sun, points: np.ndarray, range_k_max: float,
                      normals: np.ndarray | None = None, *, rule: str = "edge", margin_px: float = 2.5,
                      posed: PosedOccluder | None = None) -> DensePlan:
    """``plan_points(occ, pose, sun, points, range_k_max, rule, normals=normals, backend="light",
    margin_px=margin_px)``, compact (``DensePlan``) and faster for many points.

    points (N, 3) world metres; normals (N, 3) unit or None; posed: the occluder already posed
    under this sun (``PosedOccluder.make(occ, pose, sun)``), to share it with other steps.
    """
    posed = PosedOccluder.make(occ, pose, sun) if posed is None else posed
    sil, light, world = posed.silhouette, posed.light, posed.world
    points = np.ascontiguousarray(points, np.float64).reshape(-1, 3)
    n = len(points)
    if normals is not None:
        normals = np.ascontiguousarray(normals, np.float64).reshape(-1, 3)
        if len(normals) != n:
            raise ValueError(f"{len(normals)} normals for {n} receiver points")
    attached = np.zeros(n, bool) if normals is None else faces_away(normals, light)
    hard = attached.astype(np.float64)
    edges = _pack_edges(occ, sil)
    if not (n and len(sil.vertex_ids)):
        return _empty(edges, hard)
    frame = LightFrame.of_light(light, 0.5 * (world.min(0) + world.max(0)))
    uv_v, d_v = frame.project(world)
    uv_all, d_all = frame.project(points)
    ids = sil.vertex_ids
    edge_depth = np.minimum(d_v[ids[:, 0]], d_v[ids[:, 1]])
    # The region the shadow can reach, as plan_points takes it (its comments give the reasons).
    reach = float(light_band_widths(d_all.max() - edge_depth.min(), range_k_max))
    lo_occ = np.array([uv_v[:, 0].min(), uv_v[:, 1].min()])
    hi_occ = np.array([uv_v[:, 0].max(), uv_v[:, 1].max()])
    extent = float((hi_occ - lo_occ).max()) + 3.0 * reach
    margin_m = (margin_px + CANDIDATE_REACH_PX + 2) * extent / 256
    cand = _within_reach(uv_all, d_all, lo_occ, hi_occ, float(edge_depth.min()), range_k_max, margin_m)
    if not len(cand):
        return _empty(edges, hard)
    uv_p = np.empty((len(cand), 2))
    d_p = np.empty(len(cand))
    att = np.empty(len(cand), bool)
    _gather_kernel()(cand, uv_all, d_all, attached, uv_p, d_p, att)
    reach = float(light_band_widths(d_p.max() - edge_depth.min(), range_k_max))
    extent = float((hi_occ - lo_occ).max()) + 3.0 * reach
    lo_pts = np.array([uv_p[:, 0].min(), uv_p[:, 1].min()])
    hi_pts = np.array([uv_p[:, 0].max(), uv_p[:, 1].max()])
    spacing = _spacing(uv_p, extent / 128)
    pixel_m = max(float(np.clip(spacing, extent / 2048, extent / 256)), 1e-5)
    map_pixel_m = float(np.clip(spacing, extent / 2048, extent / 512))
    pad_m = 1.5 * reach + (margin_px + CANDIDATE_REACH_PX + 2) * pixel_m
    lo = np.maximum(lo_occ - pad_m, lo_pts - pad_m)
    hi = np.minimum(hi_occ + pad_m, hi_pts + pad_m)
    if np.any(hi <= lo):
        return _empty(edges, hard)
    pixel_m = max(pixel_m, float((hi - lo).max()) / MAX_RASTER_SIDE)
    map_pixel_m = max(min(map_pixel_m, pixel_m), float((hi - lo).max()) / MAX_RASTER_SIDE, 1e-5)
    width = int(np.ceil((hi[0] - lo[0]) / pixel_m)) + 1
    height = int(np.ceil((hi[1] - lo[1]) / pixel_m)) + 1
    grid = GroundGrid(pixel_m, (float(lo[0]), float(hi[1])), width, height)
    raster = rasterise_shadow(grid, world, light, sil, uv_v)
    in_view = np.empty(len(cand), np.uint8)
    label = np.empty(len(cand), np.int32)
    dist = np.empty(len(cand), np.float32)  # as ShadowRaster.lookup's: float32 pixels times the pixel size
    _lookup_kernel()(uv_p, grid.origin_m[0], grid.origin_m[1], pixel_m, raster.hard, raster.edge_label,
                     raster.boundary_dist_px, in_view, label, dist)
    near = np.flatnonzero((dist <= 2.0 * pixel_m) & ~att)
    if len(near):
        in_view[near] = posed.hard_shadow_at(uv_p[near], projected=uv_v)
    faces = occ.faces[sil.lit] if occ.watertight else occ.faces
    behind = np.zeros(len(cand), bool)
    test = np.flatnonzero((in_view > 0) & ~att)
    far = d_p[test] > d_v[faces].max(initial=-np.inf) + 0.5 * map_pixel_m
    behind[test[far]] = True
    test = test[~far]
    if len(test):
        uv_t = uv_p[test]
        m_lo = np.array([uv_t[:, 0].min(), uv_t[:, 1].min()]) - 3 * map_pixel_m
        m_hi = np.array([uv_t[:, 0].max(), uv_t[:, 1].max()]) + 3 * map_pixel_m
        map_grid = GroundGrid(map_pixel_m, (float(m_lo[0]), float(m_hi[1])),
                              int(np.ceil((m_hi[0] - m_lo[0]) / map_pixel_m)) + 1,
                              int(np.ceil((m_hi[1] - m_lo[1]) / map_pixel_m)) + 1)
        smap = shadow_map(map_grid, uv_v, d_v, faces)
        occ_depth, face_slope, exact = smap.occluder_depth(uv_t)
        recv_slope = 0.0
        pts_t = points[cand[test]]
        if normals is not None:
            nt = normals[cand[test]]
            cos = np.abs(nt[:, 0] * light[0] + nt[:, 1] * light[1] + nt[:, 2] * light[2])
            recv_slope = np.sqrt(np.maximum(1.0 - cos * cos, 0.0)) / np.maximum(cos, 1e-12)
        scale = max(smap.scale, float(np.abs(pts_t).max()), float(np.abs(world).max()))
        bias = depth_bias(map_pixel_m, face_slope, recv_slope, scale, np.float64, exact)
        behind[test] = d_p[test] > occ_depth + bias
    hard[cand] = behind | att
    act = np.empty(len(cand), bool)
    near_b = np.empty(len(cand), bool)
    clean = _clean_outline(raster, label)
    widths = light_band_widths(d_p - edge_depth[np.maximum(label, 0)], range_k_max)
    _band_kernel()(widths, label, dist, att, clean, BAND_FRACTION, margin_px * pixel_m, 1.5 * pixel_m, act, near_b)
    sel = np.flatnonzero(act)
    band = cand[sel]
    edge_id = np.zeros((len(sel), N_CANDIDATES), np.int32)
    if len(sel):
        cr = np.clip(np.rint(grid.to_pixel(uv_p[sel])).astype(np.int64), 0, [width - 1, height - 1])
        edge_id[:] = np.maximum(candidate_labels(raster.edge_label, cr[:, 1], cr[:, 0], radii=CANDIDATE_RADII_PX,
                                                 max_candidates=N_CANDIDATES, neighbours=raster.edge_neighbours), 0)
    return DensePlan(_pack_edges(occ, sil, raster=raster), hard, band, edge_id,
                     near_b[sel].astype(np.float64))


def _spacing(uv: np.ndarray, cell_m: float) -> float:
    """``plan._spacing`` (the points' typical spacing: the area of the cells of side ``cell_m``
    they occupy, per point, square-rooted) in one compiled pass."""
    lo_u, lo_v = float(uv[:, 0].min()), float(uv[:, 1].min())
    width = int((uv[:, 0].max() - lo_u) / cell_m) + 1
    height = int((uv[:, 1].max() - lo_v) / cell_m) + 1
    taken = _spacing_kernel()(uv, lo_u, lo_v, cell_m, width, height)
    return cell_m * float(np.sqrt(taken / len(uv)))


@functools.cache
def _spacing_kernel():
    import numba

    @numba.njit(cache=True, nogil=True)
    def kernel(uv, lo_u, lo_v, cell_m, width, height):
        taken = np.zeros(width * height, np.bool_)
        count = 0
        for i in range(uv.shape[0]):
            k = int((uv[i, 1] - lo_v) / cell_m) * width + int((uv[i, 0] - lo_u) / cell_m)
            if not taken[k]:
                taken[k] = True
                count += 1
        return count

    return kernel


@functools.cache
def _gather_kernel():
    import numba

    @numba.njit(cache=True, nogil=True)
    def kernel(cand, uv_all, d_all, attached, uv, d, att):
        for j in range(cand.shape[0]):
            i = cand[j]
            uv[j, 0], uv[j, 1], d[j], att[j] = uv_all[i, 0], uv_all[i, 1], d_all[i], attached[i]

    return kernel


@functools.cache
def _lookup_kernel():
    """``ShadowRaster.lookup`` at light-space points (the nearest pixel): hard, label and the
    distance in metres (0, -1, +inf outside the raster)."""
    import numba

    @numba.njit(cache=True, nogil=True)
    def kernel(uv, ox, oy, pixel_m, hard, edge_label, dist_px, in_view, label, dist):
        h, w = hard.shape
        for i in range(uv.shape[0]):
            c = np.rint((uv[i, 0] - ox) / pixel_m)
            r = np.rint((oy - uv[i, 1]) / pixel_m)
            if 0 <= c < w and 0 <= r < h:
                ci, ri = int(c), int(r)
                in_view[i] = hard[ri, ci]
                label[i] = edge_label[ri, ci]
                dist[i] = dist_px[ri, ci] * np.float32(pixel_m)
            else:
                in_view[i], label[i], dist[i] = 0, -1, np.inf

    return kernel


@functools.cache
def _band_kernel():
    """The band and boundary flags of ``plan_points``' light back end, per point from the
    width of its wedge: the band BAND_FRACTION of it plus the margin, near the boundary within
    a quarter of it plus 1.5 pixels on a clean outline edge."""
    import numba

    @numba.njit(cache=True, nogil=True)
    def kernel(widths, label, dist, att, clean, fraction, margin_m, near_m, act, near_b):
        for i in range(widths.shape[0]):
            a = label[i] >= 0 and dist[i] <= fraction * widths[i] + margin_m and not att[i]
            act[i] = a
            near_b[i] = a and dist[i] <= 0.25 * widths[i] + near_m and clean[i]

    return kernel
