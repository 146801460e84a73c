"""Plans: the discrete choices for a set of receiver points, made once (NumPy/OpenCV only).

A plan fixes, for a concrete pose and sun, which silhouette edges exist,
which edge governs each receiver point, whether the point is in the hard
shadow, and whether it lies in a penumbra band (where the differentiable
formula is evaluated). Its leaves are NumPy arrays; ``softshadow.evaluate``
then evaluates alpha in JAX, differentiable in k, the sun angles and the pose
as long as those discrete choices hold (they are piecewise constant, so
gradients there are exact). Re-plan when the sun or pose moves by more than a
penumbra width.
"""

from __future__ import annotations

import dataclasses
import functools

import equinox as eqx
import numpy as np
from jaxtyping import Bool, Float, Int

from .camera import GroundGrid
from .occluder import Occluder
from .params import Pose, Sun
from .posed import PosedOccluder
from .raster import ShadowRaster, candidate_labels, layer_count_fill, rasterise_shadow
from .shadowmap import LightFrame, depth_bias, faces_away, shadow_map
from .wedge_plan import (REACH_MARGIN, WedgeArrays, WedgeEdges, arrangement, concatenate_wedge, gather_candidates,
                         wedge_edges)

__all__ = ["EDGE_PADDING", "EdgeSet", "PointPlan", "GridPlan", "plan_points", "plan_grid", "concatenate_plans",
           "edge_band_widths", "bucket_size", "grid_bucket_size", "light_band_widths", "BACKENDS"]

MAX_RASTER_SIDE = 2048
# The wedge reaches half its width on each side of the outline; the band adds a fifth for the
# candidates' different depths along the light, plus a margin of raster pixels.
BAND_FRACTION = 0.6
N_CANDIDATES = 5
CANDIDATE_RADII_PX = (2, 6)  # rings of label samples around a pixel (raster.candidate_labels)
CANDIDATE_REACH_PX = max(CANDIDATE_RADII_PX)


def bucket_size(n: int, minimum: int = 64) -> int:
    """Round a count up to a power of two (>= minimum) so that jit sees few distinct shapes."""
    return max(minimum, 1 << int(np.ceil(np.log2(max(n, 1)))))


class EdgeSet(eqx.Module):
    """Silhouette edges in the mesh frame, padded to a bucket size (NumPy leaves).

    vertices_local (s, 2, 3) metres; outward_sign (s,); paper_normal_local (s, 3);
    neighbours (s, 2) int32: the outline edge sharing each edge's first and second vertex
    (-1: none; ``raster.ShadowRaster.edge_neighbours``), for the outline's corners
    (``penumbra.corner_alpha``); None where the plan has none. jump (s,): the depth
    complexity's change across each edge (``wedge_plan.edge_jumps``; the ``wedge`` rule's),
    None for the other rules.
    """

    vertices_local: Float[np.ndarray, "s 2 3"]
    outward_sign: Float[np.ndarray, " s"]
    paper_normal_local: Float[np.ndarray, "s 3"]
    neighbours: Int[np.ndarray, "s 2"] | None = None
    jump: Float[np.ndarray, " s"] | None = None


class PointPlan(eqx.Module):
    """Per-point discrete choices (NumPy leaves; a jitted evaluation takes them as they are).

    edge_id (n, K) candidate governing edges; hard (n,) 0/1 in the hard shadow;
    active (n,) in a penumbra band (elsewhere alpha is ``hard``); near_boundary (n,)
    0/1 within a quarter penumbra of the hard shadow's boundary, where the side may
    follow the edge's plane as the sun or pose moves. For the ``wedge`` rule: edge_id holds
    every edge the point's sun disk may meet (-1: none; ``wedge_plan``), and ``wedge`` the
    arrangement's discrete choices (``wedge_plan.WedgeArrays``); None for the other rules.
    """

    edges: EdgeSet
    edge_id: Int[np.ndarray, "n K"]
    hard: Float[np.ndarray, " n"]
    active: Bool[np.ndarray, " n"]
    near_boundary: Float[np.ndarray, " n"]
    wedge: WedgeArrays | None = None


def edge_band_widths(world_a: np.ndarray, world_b: np.ndarray, outward: np.ndarray,
                     light: np.ndarray, range_k: float) -> np.ndarray:
    """Ground width (m) of each edge's penumbra wedge at k, the larger of its two ends (S,)."""
    # A point p projects along d to p_xy - p_z d_xy / d_z, so the two projections of an end
    # (along L + k n and L - k n) lie |p_z| |r_out - r_in| apart, with r = d_xy / d_z.
    d_out = light + range_k * outward
    d_in = light - range_k * outward
    r = d_out[:, :2] / d_out[:, 2:] - d_in[:, :2] / d_in[:, 2:]
    height = np.maximum(np.abs(world_a[:, 2]), np.abs(world_b[:, 2]))
    return height * np.hypot(r[:, 0], r[:, 1])


#: What a padding edge holds in each ``EdgeSet`` field: a unit segment, never referenced.
EDGE_PADDING = {"vertices_local": np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), "outward_sign": 1.0,
                "paper_normal_local": np.array([0.0, 0.0, 1.0]), "neighbours": -1, "jump": 0.0}


def _pack_edges(occ: Occluder, sil, dtype=np.float64, raster: ShadowRaster | None = None,
                jump: np.ndarray | None = None) -> EdgeSet:
    """The silhouette's EdgeSet padded to a bucket, with the raster's outline neighbours (and
    the ``wedge`` rule's jumps, 0 on padding edges)."""
    s = len(sil.vertex_ids)
    size = bucket_size(s, 16)
    neighbours = np.full((size, 2), EDGE_PADDING["neighbours"], np.int32)
    if raster is not None and raster.edge_neighbours is not None and s:
        neighbours[:s] = raster.edge_neighbours
    verts = np.empty((size, 2, 3), dtype)
    verts[:] = EDGE_PADDING["vertices_local"]
    sign = np.full(size, EDGE_PADDING["outward_sign"], dtype)
    paper = np.empty((size, 3), dtype)
    paper[:] = EDGE_PADDING["paper_normal_local"]
    if s:
        verts[:s] = occ.vertices[sil.vertex_ids]
        sign[:s] = sil.outward_sign
        paper[:s] = sil.paper_normal_local
    packed_jump = None
    if jump is not None:
        packed_jump = np.full(size, EDGE_PADDING["jump"], dtype)
        packed_jump[:s] = jump
    return EdgeSet(verts, sign, paper, neighbours, packed_jump)


def _clean_outline(raster: ShadowRaster, label: np.ndarray) -> np.ndarray:
    """Whether each point's nearest edge lies on the outline along (nearly) all its length,
    so that its own plane may decide the side (a rough edge half inside the shadow may not)."""
    frac = raster.edge_outline_fraction
    if frac is None:
        return np.zeros(len(label), bool)
    return (label >= 0) & (frac[np.maximum(label, 0)] >= 0.99)


def _raster_for(posed: PosedOccluder, region_lo, region_hi, pixel_m, pad_m):
    """Raster over [lo, hi] (world xy) padded by pad_m, at pixel_m, intersected with the shadow's reach."""
    world = posed.world
    ground = posed.ground_vertices()
    reach_lo = np.minimum(ground.min(0), world[:, :2].min(0)) - pad_m
    reach_hi = np.maximum(ground.max(0), world[:, :2].max(0)) + pad_m
    lo = np.maximum(region_lo - pad_m, reach_lo)
    hi = np.minimum(region_hi + pad_m, reach_hi)
    if np.any(hi <= lo):
        return None
    size = hi - lo
    pixel_m = max(pixel_m, float(size.max()) / MAX_RASTER_SIDE)
    width = int(np.ceil(size[0] / pixel_m)) + 1
    height = int(np.ceil(size[1] / pixel_m)) + 1
    grid = GroundGrid(pixel_m, (float(lo[0]), float(hi[1])), width, height)
    return rasterise_shadow(grid, world, posed.light, posed.silhouette, ground)


BACKENDS = ("auto", "ground", "light")


def _empty_plan_arrays(size: int):
    """A plan's per-point arrays for ``size`` (padded) points: edge_id (size, K) int32, hard
    (size,), active (size,) bool, near_boundary (size,); points beyond the real ones stay lit."""
    return (np.zeros((size, N_CANDIDATES), np.int32), np.zeros(size), np.zeros(size, bool),
            np.zeros(size))


def plan_points(occ: Occluder, pose: Pose, sun: Sun, points: np.ndarray, range_k_max: float,
                rule: str = "edge", pixel_m: float | None = None,
                margin_px: float = 2.5, pad_to: int | None = None, normals: np.ndarray | None = None,
                backend: str = "auto", dtype=np.float64, receiver_tolerance_m: float = 0.0,
                pixel_axes: np.ndarray | None = None) -> PointPlan:
    """Discrete choices for receiver points (N, 3) anywhere: the ground, a range image, a mesh,
    the object itself.

    range_k_max: the largest k the plan must hold for (sets the band width).
    pixel_m: raster resolution in metres (default: the extent / 1024; for the light-space
    back end, of the sun's view of the region the shadow can reach).
    pad_to: pad the point arrays to this length (default: a power-of-two bucket).
    normals: receiver normals (N, 3), optional: a point whose surface faces away from the sun
    (n . L >= 0) is in attached shadow (hard = 1, alpha = 1), and the depth test's bias
    grows with the receiver's slope seen from the sun.
    backend: ``ground`` (the points lie on z = 0: top-down raster, as ``plan_grid``),
    ``light`` (the sun's shadow map and light-space raster, any points), ``auto`` (ground
    when every point has z = 0 and no normal is given or all are +z, else light).
    dtype: the float type of the light-space depth test (float32 to measure precision).
    receiver_tolerance_m: the receiver points' own depth error (a range image's
    quantisation), added to the depth test's bias (``softshadow.shadowmap``).
    pixel_axes (2, 3) or (N, 2, 3): the points' pixel footprints, for pixel means: the plan then
    holds the hard shadow's pieces in each pixel (its exact area there), which the ``wedge``
    rule's means need and the other rules' use (without, their means take the chosen edge's
    profile alone). The ``wedge`` rule needs no raster for points and tests depth by ray
    casting, not a shadow map (pixel_m, margin_px, dtype and receiver_tolerance_m do not apply).
    """
    if backend not in BACKENDS:
        raise ValueError(f"unknown receiver back end {backend!r}; choose one of {BACKENDS}")
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if normals is not None:
        normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        if len(normals) != len(points):
            raise ValueError(f"{len(normals)} normals for {len(points)} receiver points")
    if backend == "auto":
        flat = not np.any(points[:, 2]) and (normals is None or (
            not np.any(normals[:, :2]) and np.all(normals[:, 2] > 0)))
        backend = "ground" if flat else "light"
    if rule == "wedge":
        return _plan_points_wedge(occ, pose, sun, points, range_k_max, pad_to, normals, backend == "ground",
                                  pixel_axes)
    if backend == "light":
        plan = _plan_points_light(occ, pose, sun, points, range_k_max, rule, pixel_m, margin_px, pad_to,
                                  normals, dtype, receiver_tolerance_m)
        return plan if pixel_axes is None else _with_pixel_area(plan, occ, pose, sun, points, pixel_axes, False)
    if pixel_axes is not None:
        plan = plan_points(occ, pose, sun, points, range_k_max, rule, pixel_m, margin_px, pad_to, normals,
                           backend, dtype, receiver_tolerance_m)
        return _with_pixel_area(plan, occ, pose, sun, points, pixel_axes, True)
    posed = PosedOccluder.make(occ, pose, sun)
    sil, light = posed.silhouette, posed.light
    a, b, direction = posed.edge_geometry(rule)
    n = len(points)
    edge_id, hard, active, near_boundary = _empty_plan_arrays(pad_to or bucket_size(n))
    raster = None
    if n and len(sil.vertex_ids):
        widths = edge_band_widths(a, b, direction, light, range_k_max)
        lo, hi = points[:, :2].min(0), points[:, :2].max(0)
        if pixel_m is None:
            pixel_m = max(float((hi - lo).max()) / 1024, 1e-4)
        pad_m = 1.5 * float(widths.max()) + (margin_px + 2) * pixel_m
        raster = _raster_for(posed, lo, hi, pixel_m, pad_m)
        if raster is not None:
            h, label, dist = raster.lookup(points)
            ok = label >= 0
            band = BAND_FRACTION * widths[np.maximum(label, 0)] + margin_px * raster.grid.pixel_m
            cr = np.clip(np.rint(raster.grid.to_pixel(points)).astype(np.int64), 0,
                         [raster.grid.width - 1, raster.grid.height - 1])
            edge_id[:n] = np.maximum(candidate_labels(raster.edge_label, cr[:, 1], cr[:, 0],
                                                      radii=CANDIDATE_RADII_PX,
                                                      max_candidates=N_CANDIDATES,
                                                      neighbours=raster.edge_neighbours), 0)
            hard[:n] = h
            # Near the boundary a raster pixel is too coarse for the side: test exactly.
            near = np.nonzero(dist <= 2.0 * raster.grid.pixel_m)[0]
            if len(near):
                hard[near] = posed.hard_shadow_at(points[near, :2])
            active[:n] = ok & (dist <= band)
            near_boundary[:n] = ok & (dist <= 0.25 * widths[np.maximum(label, 0)]
                                      + 1.5 * raster.grid.pixel_m) & _clean_outline(raster, label)
    return PointPlan(_pack_edges(occ, sil, raster=raster), edge_id, hard, active, near_boundary)


def _within_reach(uv: np.ndarray, depth: np.ndarray, lo: np.ndarray, hi: np.ndarray, edge_depth: float,
                  range_k: float, margin_m: float) -> np.ndarray:
    """Indices of the points (light-space uv (N, 2), depth (N,)) within the occluder's view
    [lo, hi] padded by 1.5 times the widest wedge they can see from their own depth behind the
    nearest edge (``light_band_widths``) plus margin_m: the others are lit whatever the shadow.
    One compiled pass (numba) over what may be every pixel of a range image."""
    keep = np.empty(len(uv), bool)
    _reach_kernel()(np.ascontiguousarray(uv, np.float64), np.ascontiguousarray(depth, np.float64),
                    float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]), edge_depth,
                    1.5 * float(light_band_widths(np.float64(1.0), range_k)), margin_m, keep)
    return np.flatnonzero(keep)


@functools.cache
def _reach_kernel():
    """The compiled loop of ``_within_reach``: per_m is 1.5 wedge widths per metre behind."""
    import numba

    @numba.njit(cache=True, nogil=True)
    def kernel(uv, depth, lo_u, lo_v, hi_u, hi_v, edge_depth, per_m, margin_m, keep):
        for i in range(uv.shape[0]):
            pad = per_m * max(depth[i] - edge_depth, 0.0) + margin_m
            keep[i] = (uv[i, 0] >= lo_u - pad) & (uv[i, 0] <= hi_u + pad) & (uv[i, 1] >= lo_v - pad) \
                & (uv[i, 1] <= hi_v + pad)

    return kernel


def _spacing(uv: np.ndarray, cell_m: float) -> float:
    """The typical distance (m) between neighbouring points (N, 2) where they lie: the area of
    the cells of side ``cell_m`` they occupy, per point, square-rooted. Cells several points
    wide fill where the points are, so the area is theirs, holes and outline included."""
    col = ((uv[:, 0] - uv[:, 0].min()) / cell_m).astype(np.int64)
    row = ((uv[:, 1] - uv[:, 1].min()) / cell_m).astype(np.int64)
    width = int(col.max()) + 1
    taken = np.zeros(width * (int(row.max()) + 1), bool)
    taken[row * width + col] = True
    return cell_m * float(np.sqrt(np.count_nonzero(taken) / len(uv)))


def raster_grid(lo: np.ndarray, hi: np.ndarray, pixel_m: float, map_pixel_m: float) -> tuple[GroundGrid, float]:
    """The light-space raster's grid over [lo, hi] (2,) metres at ``pixel_m`` (coarsened to at most
    MAX_RASTER_SIDE pixels a side), and the shadow map's pixel (no coarser than the raster's,
    within the same cap)."""
    side = float((hi - lo).max())
    pixel_m = max(pixel_m, side / MAX_RASTER_SIDE)
    map_pixel_m = max(min(map_pixel_m, pixel_m), side / MAX_RASTER_SIDE, 1e-5)
    width = int(np.ceil((hi[0] - lo[0]) / pixel_m)) + 1
    height = int(np.ceil((hi[1] - lo[1]) / pixel_m)) + 1
    return GroundGrid(pixel_m, (float(lo[0]), float(hi[1])), width, height), map_pixel_m


def light_band_widths(depth_behind: np.ndarray | float, range_k: float) -> np.ndarray | float:
    """Width (m, perpendicular to the light) of a penumbra wedge at ``depth_behind`` metres
    behind its edge along the light: 2 k d for the ``edge`` rule (L +- k n, n perpendicular
    to L), and at most 2 k (1 + k) d for the ``paper`` rule's tilted N."""
    return 2.0 * range_k * (1.0 + range_k) * np.maximum(depth_behind, 0.0)


def _plan_points_light(occ: Occluder, pose: Pose, sun: Sun, points: np.ndarray, range_k_max: float,
                       rule: str, pixel_m: float | None, margin_px: float, pad_to: int | None,
                       normals: np.ndarray | None, dtype, receiver_tolerance_m: float) -> PointPlan:
    """``plan_points`` in the sun's view: the same raster code as the ground's, on the plane
    perpendicular to the light, plus the shadow map's depth test (``shadowmap``)."""
    posed = PosedOccluder.make(occ, pose, sun)
    sil, light, world = posed.silhouette, posed.light, posed.world
    n = len(points)
    edge_id, hard, active, near_boundary = _empty_plan_arrays(pad_to or bucket_size(n))
    attached = np.zeros(n, bool) if normals is None else faces_away(normals, light)
    hard[:n] = attached
    edges = _pack_edges(occ, sil)
    if not (n and len(sil.vertex_ids)):
        return PointPlan(edges, edge_id, hard, active, near_boundary)
    frame = LightFrame.of_light(light, 0.5 * (world.min(0) + world.max(0)))
    # In ``dtype`` (float32 rounds as a float32 pipeline would), the rest in float64.
    uv_v, d_v = (a.astype(np.float64, copy=False) for a in frame.project(world, dtype))
    uv_all, d_all = (a.astype(np.float64, copy=False) for a in frame.project(points, dtype))
    ids = sil.vertex_ids
    edge_depth = np.minimum(d_v[ids[:, 0]], d_v[ids[:, 1]])  # the edge's end nearer the sun
    # The region the shadow can reach: the occluder's view padded by the widest wedge any
    # point can see (and the raster's margins, at the coarsest pixel); points outside it are
    # lit (or in attached shadow) and take no further work.
    reach = float(light_band_widths(d_all.max() - edge_depth.min(), range_k_max))
    lo_occ = np.array([uv_v[:, 0].min(), uv_v[:, 1].min()])  # per column: (N, 2).min(0) is slow
    hi_occ = np.array([uv_v[:, 0].max(), uv_v[:, 1].max()])
    extent = float((hi_occ - lo_occ).max()) + 3.0 * reach
    margin_m = (margin_px + CANDIDATE_REACH_PX + 2) * max(pixel_m or 0.0, extent / 256)  # the coarsest raster
    # Each point's own reach: the wedge it can see from its own depth behind the nearest edge.
    cand = _within_reach(uv_all, d_all, lo_occ, hi_occ, float(edge_depth.min()), range_k_max, margin_m)
    if not len(cand):
        return PointPlan(edges, edge_id, hard, active, near_boundary)
    uv_p, d_p, pts = uv_all[cand], d_all[cand], points[cand]
    att = attached[cand]
    reach = float(light_band_widths(d_p.max() - edge_depth.min(), range_k_max))
    extent = float((hi_occ - lo_occ).max()) + 3.0 * reach
    lo_pts = np.array([uv_p[:, 0].min(), uv_p[:, 1].min()])  # per column: (N, 2).min(0) is slow
    hi_pts = np.array([uv_p[:, 0].max(), uv_p[:, 1].max()])
    if pixel_m is None:
        # The raster of labels and distances at about the points' own spacing in the sun's
        # view (finer buys nothing but time), within [extent / 2048, extent / 256]; the shadow
        # map no coarser than extent / 512, so that the occluder's faces stay larger than its
        # pixels and its lookups exact.
        spacing = _spacing(uv_p, extent / 128)
        pixel_m = float(np.clip(spacing, extent / 2048, extent / 256))
        map_pixel_m = float(np.clip(spacing, extent / 2048, extent / 512))
    else:
        map_pixel_m = pixel_m
    pixel_m = max(pixel_m, 1e-5)
    pad_m = 1.5 * reach + (margin_px + CANDIDATE_REACH_PX + 2) * pixel_m
    lo = np.maximum(lo_occ - pad_m, lo_pts - pad_m)
    hi = np.minimum(hi_occ + pad_m, hi_pts + pad_m)
    if np.any(hi <= lo):
        return PointPlan(edges, edge_id, hard, active, near_boundary)
    grid, map_pixel_m = raster_grid(lo, hi, pixel_m, map_pixel_m)
    # The ground's raster code with light-space vertex positions: hard = the occluder's
    # silhouette region, labels and distances to its outline.
    raster = rasterise_shadow(grid, world, light, sil, uv_v)
    in_view, label, dist = raster.lookup(uv_p)
    # Points in attached shadow are hard whatever the occluder does: no side, no depth test.
    near = np.flatnonzero((dist <= 2.0 * pixel_m) & ~att)
    if len(near):  # a raster pixel is too coarse for the side near the outline: test exactly
        in_view[near] = posed.hard_shadow_at(uv_p[near], projected=uv_v)
    # The depth test where the occluder is in the sun's way. The nearest faces to the sun are
    # lit ones for a closed mesh, any face for an open one.
    faces = occ.faces[sil.lit] if occ.watertight else occ.faces
    behind = np.zeros(len(cand), bool)
    test = np.flatnonzero((in_view > 0) & ~att)
    # Farther from the sun than the whole occluder: behind it wherever it is in the way, no
    # lookup needed (most of a cast shadow). The others go to the shadow map.
    far = d_p[test] > d_v[faces].max(initial=-np.inf) + 0.5 * map_pixel_m
    behind[test[far]] = True
    test = test[~far]
    if len(test):
        # The shadow map only where the lookups fall (and their 2-pixel neighbourhoods).
        uv_t = uv_p[test]
        m_lo = np.array([uv_t[:, 0].min(), uv_t[:, 1].min()]) - 3 * map_pixel_m
        m_hi = np.array([uv_t[:, 0].max(), uv_t[:, 1].max()]) + 3 * map_pixel_m
        map_grid = GroundGrid(map_pixel_m, (float(m_lo[0]), float(m_hi[1])),
                              int(np.ceil((m_hi[0] - m_lo[0]) / map_pixel_m)) + 1,
                              int(np.ceil((m_hi[1] - m_lo[1]) / map_pixel_m)) + 1)
        smap = shadow_map(map_grid, uv_v, d_v, faces, dtype)
        occ_depth, face_slope, exact = smap.occluder_depth(uv_t.astype(dtype))
        recv_slope = 0.0
        if normals is not None:
            nt = normals[cand[test]]
            cos = np.abs(nt[:, 0] * light[0] + nt[:, 1] * light[1] + nt[:, 2] * light[2])
            recv_slope = np.sqrt(np.maximum(1.0 - cos * cos, 0.0)) / np.maximum(cos, 1e-12)
        scale = max(smap.scale, float(np.abs(pts[test]).max()), float(np.abs(world).max()))
        bias = depth_bias(map_pixel_m, face_slope, recv_slope, scale, dtype, exact, receiver_tolerance_m)
        behind[test] = d_p[test].astype(dtype) > occ_depth + bias
    hard[cand] = behind | att
    ok = label >= 0
    widths = light_band_widths(d_p - edge_depth[np.maximum(label, 0)], range_k_max)
    band = BAND_FRACTION * widths + margin_px * pixel_m
    act = ok & (dist <= band) & ~att
    active[cand] = act
    near_boundary[cand] = act & (dist <= 0.25 * widths + 1.5 * pixel_m) & _clean_outline(raster, label)
    sel = np.flatnonzero(act)
    if len(sel):
        cr = np.clip(np.rint(grid.to_pixel(uv_p[sel])).astype(np.int64), 0, [grid.width - 1, grid.height - 1])
        edge_id[cand[sel]] = np.maximum(candidate_labels(raster.edge_label, cr[:, 1], cr[:, 0],
                                                         radii=CANDIDATE_RADII_PX, max_candidates=N_CANDIDATES,
                                                         neighbours=raster.edge_neighbours), 0)
    return PointPlan(_pack_edges(occ, sil, raster=raster), edge_id, hard, active, near_boundary)


@dataclasses.dataclass(frozen=True)
class GridPlan:
    """Discrete choices on a whole ground map: the hard shadow and the band pixels to evaluate.

    hard (H, W) uint8 0/1; band_index (m,) int32 flat pixel indices padded with H*W;
    plan: the PointPlan of the band pixels (``band_points``), with NumPy arrays for
    the jitted evaluation to take; raster: the ShadowRaster of the shadow's window
    (the projected mesh's bounding box plus the band's reach, within the padded
    grid), for debugging; n_edges: silhouette edges before padding; sky_hidden (H, W):
    the sky fraction the object hides from each pixel (``softshadow.sky``), None when
    not modelled.
    """

    grid: GroundGrid
    hard: np.ndarray
    band_index: np.ndarray
    plan: PointPlan
    raster: ShadowRaster | None
    n_band: int
    n_edges: int = 0
    sky_hidden: np.ndarray | None = None

    @property
    def band_points(self) -> np.ndarray:
        """World points (m, 3) of the band pixels (padding: the pixel one past the end)."""
        rows, cols = np.divmod(self.band_index.astype(np.int64), self.grid.width)
        return self.grid.to_world(cols, rows)


def plan_grid(occ: Occluder, pose: Pose, sun: Sun, grid: GroundGrid, range_k_max: float,
              rule: str = "edge", margin_px: float = 2.5, dtype=np.float64, footprint: bool = False) -> GridPlan:
    """Discrete choices for every pixel of a ground map; only band pixels go to JAX.

    dtype: the float type of the plan's arrays (the evaluation's, so a jitted call takes
    them without a conversion). footprint: plan the pixel means too (the hard shadow's exact
    area in each band pixel, ``PointPlan.wedge``'s pixel part); without it the map can only be
    point-sampled.
    """
    if rule == "wedge":
        return _plan_grid_wedge(occ, pose, sun, grid, range_k_max, dtype, footprint)
    posed = PosedOccluder.make(occ, pose, sun)
    sil, light, world = posed.silhouette, posed.light, posed.world
    a, b, direction = posed.edge_geometry(rule)
    h, w = grid.height, grid.width
    hard = np.zeros((h, w), np.uint8)
    band_idx = np.zeros(0, np.int64)
    near_b = np.zeros(0, bool)
    raster = None
    edge_label = np.zeros((0, N_CANDIDATES), np.int64)
    if len(sil.vertex_ids):
        widths = edge_band_widths(a, b, direction, light, range_k_max)
        pad = int(min(np.ceil(1.5 * widths.max() / grid.pixel_m) + margin_px + 3, 512))
        band_px = (BAND_FRACTION * widths / grid.pixel_m + margin_px).astype(np.float32)  # per edge
        # Raster only the shadow's window: the projected mesh's bounding box (which holds the
        # shadow and its outline) plus the band and the candidates' sampling radius, within the
        # grid padded by pad (edges just off the grid govern pixels on it).
        ground = posed.ground_vertices()
        px = grid.to_pixel(ground)
        reach = int(np.ceil(band_px.max())) + CANDIDATE_REACH_PX + 2
        c0 = int(max(np.floor(px[:, 0].min()) - reach, -pad))
        c1 = int(min(np.ceil(px[:, 0].max()) + reach, w - 1 + pad))
        r0 = int(max(np.floor(px[:, 1].min()) - reach, -pad))
        r1 = int(min(np.ceil(px[:, 1].max()) + reach, h - 1 + pad))
        if c1 >= c0 and r1 >= r0:
            window = GroundGrid(grid.pixel_m, (grid.origin_m[0] + c0 * grid.pixel_m,
                                               grid.origin_m[1] - r0 * grid.pixel_m), c1 - c0 + 1, r1 - r0 + 1)
            raster = rasterise_shadow(window, world, light, sil, ground)
            # The part of the grid inside the window, in grid (g) and window (w) pixels.
            gr0, gr1, gc0, gc1 = max(r0, 0), min(r1, h - 1), max(c0, 0), min(c1, w - 1)
            if gr1 >= gr0 and gc1 >= gc0:
                hard[gr0:gr1 + 1, gc0:gc1 + 1] = raster.hard[gr0 - r0:gr1 - r0 + 1, gc0 - c0:gc1 - c0 + 1]
                # The widest band first (a cheap test on the distance alone, on the window's part
                # inside the grid), then each pixel's own edge's.
                dist = raster.boundary_dist_px
                close = dist <= band_px.max()
                close[:gr0 - r0] = False
                close[gr1 - r0 + 1:] = False
                close[:, :gc0 - c0] = False
                close[:, gc1 - c0 + 1:] = False
                index_w = np.flatnonzero(close)
                lab_b = raster.edge_label.reshape(-1)[index_w]
                dist_b = dist.reshape(-1)[index_w]
                keep = dist_b <= band_px[lab_b]
                index_w, lab_b, dist_b = index_w[keep], lab_b[keep], dist_b[keep]
                rows_w, cols_w = np.divmod(index_w, window.width)
                band_idx = (rows_w + r0) * w + (cols_w + c0)
                near_b = ((dist_b <= 0.25 * widths[lab_b] / grid.pixel_m + 1.5)
                          & _clean_outline(raster, lab_b))
                edge_label = candidate_labels(raster.edge_label, rows_w, cols_w, radii=CANDIDATE_RADII_PX,
                                              max_candidates=N_CANDIDATES, neighbours=raster.edge_neighbours)
    m = len(band_idx)
    size = grid_bucket_size(m)
    ftype = np.dtype(dtype)
    index = np.full(size, h * w, np.int32)
    index[:m] = band_idx
    edge_id = np.zeros((size, N_CANDIDATES), np.int32)
    edge_id[:m] = np.maximum(edge_label, 0)
    active = np.zeros(size, bool)
    active[:m] = True
    hard_band = np.zeros(size, ftype)
    hard_band[:m] = hard.ravel()[band_idx]
    near = np.zeros(size, ftype)
    near[:m] = near_b
    wedge = None
    if footprint:  # the pixel means take the hard shadow's exact area in each pixel
        if m:
            # Only pixels near the outline can hold part of it (a raster pixel is the map's).
            near_outline = np.flatnonzero(raster.boundary_dist_px.reshape(-1)[index_w] <= 2.0)
            rows_g, cols_g = np.divmod(band_idx[near_outline], w)
            band_pts = grid.to_world(cols_g, rows_g).reshape(-1, 3)
            part = _pixel_area_choices(posed, band_pts, raster.depth_count.reshape(-1)[index_w[near_outline]]
                                       .astype(np.float64), np.eye(2, 3) * grid.pixel_m, len(near_outline))
            default = np.zeros(size)
            default[:m] = hard_band[:m]
            wedge = part.select(np.arange(len(near_outline)), pad_points=size, place=near_outline,
                                default_offset=default).astype(ftype)
        else:
            wedge = _no_wedge(size, True).astype(ftype)
    # NumPy arrays, not device arrays: a jitted call takes them far more cheaply than
    # jax.device_put or jnp.asarray would.
    plan = PointPlan(_pack_edges(occ, sil, ftype, raster), edge_id, hard_band, active, near, wedge)
    return GridPlan(grid, hard, index, plan, raster, m, len(sil.vertex_ids))


def grid_bucket_size(n: int, minimum: int = 256) -> int:
    """Round a count up to one of four sizes per octave (waste <= 25 %, few distinct shapes)."""
    if n <= minimum:
        return minimum
    step = 1 << (int(np.floor(np.log2(n))) - 2)
    return -(-n // step) * step


def concatenate_plans(plans: list[PointPlan], counts: list[int], pad_to: int | None = None,
                      edge_pad_to: int | None = None, pairs_to: int | None = None,
                      cross_to: int | None = None) -> PointPlan:
    """One plan for several point sets (each with its own sun): edges stacked, ids offset.

    counts: how many leading points of each plan are real (the rest is padding). pairs_to,
    cross_to: the ``wedge`` rule's pairs and crossings padded to these sizes (at least), for
    a fixed compiled shape.
    """
    verts, signs, papers, ids, hards, actives, nears, neighbours = [], [], [], [], [], [], [], []
    edge_offsets = []
    offset = 0
    for plan, n in zip(plans, counts):
        edge_offsets.append(offset)
        e = plan.edges
        if e.neighbours is not None:
            nbr = np.asarray(e.neighbours)
            neighbours.append(np.where(nbr >= 0, nbr + offset, -1).astype(np.int32))
        verts.append(np.asarray(e.vertices_local))
        signs.append(np.asarray(e.outward_sign))
        papers.append(np.asarray(e.paper_normal_local))
        ids.append(np.asarray(plan.edge_id)[:n] + offset)
        hards.append(np.asarray(plan.hard)[:n])
        actives.append(np.asarray(plan.active)[:n])
        nears.append(np.asarray(plan.near_boundary)[:n])
        offset += len(signs[-1])
    n_total = sum(counts)
    size = pad_to or bucket_size(n_total)
    e_size = edge_pad_to or bucket_size(offset, 16)
    pad = lambda x, m, fill: np.concatenate([x, np.full((m - len(x),) + x.shape[1:], fill, x.dtype)])
    v = np.concatenate(verts)
    v = pad(v, e_size, 0.0)
    v[offset:, 1, 0] = 1.0
    paper = pad(np.concatenate(papers), e_size, 0.0)
    paper[offset:, 2] = 1.0
    nbr = pad(np.concatenate(neighbours), e_size, -1) if len(neighbours) == len(plans) and plans else None
    jumps = [p.edges.jump for p in plans]
    jump = None
    if plans and all(j is not None for j in jumps):
        jump = pad(np.concatenate([np.asarray(j) for j in jumps]), e_size, 0.0)
    edges = EdgeSet(v, pad(np.concatenate(signs), e_size, 1.0), paper, nbr, jump)
    wedge = None
    if plans and all(p.wedge is not None for p in plans):
        # Each plan's pairs point at its own edges: offset them as the edge ids are.
        shifted = [_shift_edges(p.wedge, off) for p, off in zip(plans, edge_offsets)]
        wedge = concatenate_wedge(shifted, counts, size, pairs_to, cross_to)
    return PointPlan(edges, pad(np.concatenate(ids), size, 0), pad(np.concatenate(hards), size, 0.0),
                     pad(np.concatenate(actives), size, False), pad(np.concatenate(nears), size, 0.0), wedge)


def _shift_edges(arrays: WedgeArrays, offset: int) -> WedgeArrays:
    """The choices with their pairs' edge ids moved by ``offset`` (plans concatenated)."""
    return WedgeArrays(**{**arrays.fields(), "pair_edge": np.asarray(arrays.pair_edge) + offset})


def _with_pixel_area(plan: PointPlan, occ: Occluder, pose: Pose, sun: Sun, points: np.ndarray, pixel_axes,
                     ground: bool) -> PointPlan:
    """``plan`` with the hard shadow's pieces in the pixels of its active points (``_pixel_area_choices``)."""
    posed = PosedOccluder.make(occ, pose, sun)
    n = len(points)
    size = len(plan.hard)
    act = np.flatnonzero(np.asarray(plan.active)[:n])
    if ground:
        winding = posed.winding_count_at(points[act, :2])
    else:
        winding = np.asarray(plan.hard)[act].astype(np.float64)
        cast = np.flatnonzero(winding > 0)
        winding[cast] = _layers_in_front(posed, points[act[cast]])
    axes = np.asarray(pixel_axes, np.float64)
    axes = axes[act] if axes.ndim == 3 else axes
    part = _pixel_area_choices(posed, points[act], winding, axes, len(act))
    default = np.zeros(size)
    default[:n] = np.asarray(plan.hard)[:n]
    wedge = part.select(np.arange(len(act)), pad_points=size, place=act, default_offset=default)
    return dataclasses.replace(plan, wedge=wedge)


def _pixel_area_choices(posed: PosedOccluder, points: np.ndarray, winding: np.ndarray, pixel_axes: np.ndarray,
                        size: int) -> WedgeArrays:
    """The hard shadow's pieces in each point's pixel (the pixel part of ``WedgeArrays``, for the
    ``edge`` and ``paper`` rules' pixel means), for points (m, 3) with depth complexity winding
    (m,) and pixel axes (2, 3) or (m, 2, 3), padded to ``size`` points. The pairs index the
    silhouette edges in their order (``_pack_edges``)."""
    m = len(points)
    hard = (np.asarray(winding) >= 0.5).astype(np.float64)
    edges = wedge_edges(posed.occluder, posed.silhouette, posed.world, posed.rotation, posed.light, 0.0)
    centre = np.flatnonzero(edges.centre)  # the silhouette from the sun's centre, first
    reach_px = np.broadcast_to(_pixel_reach(np.asarray(pixel_axes, np.float64), posed.light), (m,))
    cand = gather_candidates(points, edges.a[centre], edges.b[centre],
                             np.full(len(centre), float(reach_px.max(initial=0.0))), posed.light, 0.0, reach_px)
    axes = np.asarray(pixel_axes, np.float64)
    axes = axes[cand.index] if axes.ndim == 3 else axes
    ids = cand.ids[:, :max(1, int(cand.count.max(initial=0)))]
    arrays, boundary, _ = arrangement(points[cand.index], ids, edges, posed.light, winding[cand.index], -1.0,
                                      reach_px[cand.index], axes)
    on = np.flatnonzero(boundary)
    default = np.zeros(size)
    default[:m] = hard
    return arrays.select(on, pad_points=size, place=cand.index[on], default_offset=default)


# -- the ``wedge`` rule -------------------------------------------------------------------------

def _pixel_reach(axes: np.ndarray, light: np.ndarray) -> np.ndarray:
    """How far across the light (metres) a pixel's box reaches from its centre, (...,) for axes
    (..., 2, 3): half the sum of its two sides seen along the light (the reach of the footprint's
    box in penumbra units, ``wedge._line_share``), with a margin."""
    across = axes - (axes @ light)[..., None] * light
    return 0.5 * (1.0 + REACH_MARGIN) * np.linalg.norm(across, axis=-1).sum(-1)


def _wedge_edges(posed: PosedOccluder, range_k_max: float) -> WedgeEdges:
    """The edges the ``wedge`` rule may need under this sun (``wedge_plan.wedge_edges``)."""
    return wedge_edges(posed.occluder, posed.silhouette, posed.world, posed.rotation, posed.light, range_k_max)


def _pack_wedge_edges(occ: Occluder, edges: WedgeEdges, dtype=np.float64) -> EdgeSet:
    """The wedge edges as an EdgeSet padded to a bucket (jump 0 on padding edges; the other
    rules' fields are unused)."""
    s = len(edges.jump)
    size = bucket_size(s, 16)
    verts = np.zeros((size, 2, 3), dtype)
    verts[:, 1, 0] = 1.0
    verts[:s] = occ.vertices[edges.vertex_ids]
    paper = np.zeros((size, 3), dtype)
    paper[:, 2] = 1.0
    jump = np.zeros(size, dtype)
    jump[:s] = edges.jump
    return EdgeSet(verts, np.ones(size, dtype), paper, None, jump)


def _wedge_choices(posed: PosedOccluder, edges, points, edge_reach: np.ndarray, range_k_max: float,
                   pixel_reach, winding_at, pixel_axes=None):
    """The ``wedge`` rule's choices: (active (m,) indices of the points to evaluate, the
    ``WedgeArrays`` of the points the arrangement saw, which of them are active (m,)).

    points: (n, 3), or a ground window (``gather_candidates``); winding_at:
    W(0) at point indices (m,) -> (m,). A point is evaluated when the boundary of {W >= 1} passes
    through its disk (of the plan's largest radius, widened by the pixel's reach) or its pixel;
    elsewhere the disk is wholly hidden or wholly seen, and alpha is the hard shadow.
    pixel_axes (2, 3) or (n, 2, 3): each point's pixel (``arrangement``), for the hard shadow's
    area within it."""
    cand = gather_candidates(points, edges.a, edges.b, edge_reach, posed.light, range_k_max, pixel_reach)
    winding = winding_at(cand.index)
    w = np.where(cand.ids >= 0, edges.jump[np.maximum(cand.ids, 0)], 0.0)
    keep = np.flatnonzero(w.sum(axis=1) >= winding)
    index = cand.index[keep]
    if isinstance(points, np.ndarray):
        pts = points[index]
    else:
        rows, cols = np.divmod(index, points.width)
        pts = points.to_world(cols, rows).reshape(-1, 3)
    axes = None
    if pixel_axes is not None:
        axes = np.asarray(pixel_axes, np.float64)
        axes = axes[index] if axes.ndim == 3 else axes
    reach = np.asarray(pixel_reach, np.float64)
    reach = reach[index] if reach.ndim else reach
    ids = cand.ids[keep, :max(1, int(cand.count[keep].max(initial=0)))]
    arrays, boundary, _ = arrangement(pts, ids, edges, posed.light, winding[keep], range_k_max * (1.0 + REACH_MARGIN),
                                      reach, axes)
    on = np.flatnonzero(boundary)
    return index[on], arrays, on


def _ground_reach(posed: PosedOccluder, edges: WedgeEdges, range_k_max: float, pixel_reach: float) -> np.ndarray:
    """How far (metres across the light) from an edge its candidates on the ground can lie (S,):
    the sun's cone at the edge's height above them, widened by the pixel's reach."""
    lz = max(abs(float(posed.light[2])), 1e-9)
    kappa = range_k_max * (1.0 + REACH_MARGIN)
    z = np.maximum(np.maximum(edges.a[:, 2], edges.b[:, 2]), 0.0)
    return kappa * (z + pixel_reach) / max(lz - kappa, 1e-9) + pixel_reach


def _no_wedge(size: int, pixel: bool) -> WedgeArrays:
    """The choices of ``size`` points without any pair."""
    none = dict(pair_point=np.zeros(0, np.int32), pair_edge=np.zeros(0, np.int32), flip=np.zeros(0),
                side_start=np.zeros(0), side_end=np.zeros(0), cross=np.zeros((0, 2), np.int32), cross_change=np.zeros(0))
    if pixel:
        none.update(pixel_hard_offset=np.zeros(0), pixel_flip=np.zeros(0), pixel_side_start=np.zeros(0),
                    pixel_side_end=np.zeros(0),
                    pixel_cross=np.zeros((0, 2), np.int32), pixel_cross_change=np.zeros(0))
    return WedgeArrays(hard_offset=np.zeros(0), **none).select(np.zeros(0, np.int64), pad_points=size)


def _layers_in_front(posed: PosedOccluder, points: np.ndarray) -> np.ndarray:
    """The depth complexity (N,) between points (N, 3) and the sun: how many layers of the mesh
    the ray from each point towards the sun crosses (lit faces for a closed mesh, every face not
    edge-on for an open one; ray casting, trimesh/embree)."""
    import trimesh
    occ, light = posed.occluder, posed.light
    count = np.zeros(len(points))
    if not len(points):
        return count
    ndotl = (occ.face_normals @ posed.rotation.T) @ light
    faces = occ.faces[ndotl < 0] if occ.watertight else occ.faces[np.abs(ndotl) > 1e-7]
    if not len(faces):
        return count
    mesh = trimesh.Trimesh(posed.world, faces, process=False)
    scale = float(np.abs(posed.world).max(initial=1.0))
    origins = points - (1e-6 * scale) * light  # off the receiver's own surface, towards the sun
    _, ray = mesh.ray.intersects_id(origins, np.broadcast_to(-light, points.shape), multiple_hits=True)
    np.add.at(count, ray, 1.0)
    return count


def _plan_points_wedge(occ: Occluder, pose: Pose, sun: Sun, points: np.ndarray, range_k_max: float,
                       pad_to: int | None, normals: np.ndarray | None, ground: bool,
                       pixel_axes: np.ndarray | None = None) -> PointPlan:
    """``plan_points`` for the ``wedge`` rule: points on the ground (``ground``: z = 0, the depth
    complexity from the fill layers' winding counts) or anywhere (normals: attached shadow; the
    depth complexity in front of each point by ray casting where the occluder may lie behind it,
    else from the winding counts in the sun's view)."""
    posed = PosedOccluder.make(occ, pose, sun)
    light = posed.light
    n = len(points)
    size = pad_to or bucket_size(n)
    hard = np.zeros(size)
    active = np.zeros(size, bool)
    wedge = _wedge_edges(posed, range_k_max)
    edges = _pack_wedge_edges(occ, wedge)
    none = np.zeros((size, 0), np.int32)
    attached = np.zeros(n, bool) if normals is None else faces_away(normals, light)
    hard[:n] = attached
    if not (n and len(wedge.jump)):
        return PointPlan(edges, none, hard, active, np.zeros(size), _no_wedge(size, pixel_axes is not None))
    if ground:
        winding = posed.winding_count_at(points[:, :2], posed.ground_vertices())
    else:
        frame = LightFrame.of_light(light, 0.5 * (posed.world.min(0) + posed.world.max(0)))
        uv_v, d_v = frame.project(posed.world)
        uv_p, d_p = frame.project(points)
        winding = posed.winding_count_at(uv_p, projected=uv_v)
        # Farther from the sun than the whole occluder: every layer in the view lies in front.
        among = np.flatnonzero((winding > 0) & (d_p <= d_v.max() + 1e-9 * float(np.abs(posed.world).max())))
        winding[among] = _layers_in_front(posed, points[among])
    winding[attached] = 0.0
    hard[:n] = hard[:n] + (1 - hard[:n]) * (winding >= 0.5)
    reach_px = np.zeros(n)  # point sampling: the disk alone
    if pixel_axes is not None:  # the pixels' own reach (the footprint's box)
        reach_px = np.broadcast_to(_pixel_reach(np.asarray(pixel_axes, np.float64), light), (n,)).copy()
    r = float(reach_px.max())
    kappa = range_k_max * (1.0 + REACH_MARGIN)
    if ground:
        reach = _ground_reach(posed, wedge, range_k_max, r)
    else:
        d_e = np.minimum(wedge.a @ frame.light, wedge.b @ frame.light) - frame.origin @ frame.light
        reach = kappa * np.maximum(float(d_p.max()) - d_e, 0.0) + r
    free = np.flatnonzero(~attached)
    sel, arrays, on = _wedge_choices(posed, wedge, points[free], reach, range_k_max,
                                     reach_px[free], lambda i: winding[free][i],
                                     None if pixel_axes is None else (
                                         pixel_axes if np.ndim(pixel_axes) == 2 else np.asarray(pixel_axes)[free]))
    active[free[sel]] = True
    return PointPlan(edges, none, hard, active, np.zeros(size),
                     _placed(arrays, on, free[sel], size, hard[:n]))


def _placed(arrays: WedgeArrays, on: np.ndarray, rows: np.ndarray, size: int, hard: np.ndarray) -> WedgeArrays:
    """The choices of the arrangement's points ``on`` placed at rows ``rows`` of ``size`` points
    whose other offsets are their hard shadow (n,)."""
    default = np.zeros(size)
    default[:len(hard)] = hard
    return arrays.select(on, pad_points=size, place=rows, default_offset=default)


def _plan_grid_wedge(occ: Occluder, pose: Pose, sun: Sun, grid: GroundGrid, range_k_max: float,
                     dtype, footprint: bool = True) -> GridPlan:
    """``plan_grid`` for the ``wedge`` rule: the depth complexity of the window's pixels from the
    winding counts of the fill layers, and the pixels whose disk or pixel the shadow's boundary
    passes in the band."""
    posed = PosedOccluder.make(occ, pose, sun)
    sil = posed.silhouette
    h, w = grid.height, grid.width
    hard = np.zeros((h, w), np.uint8)
    wedge = _wedge_edges(posed, range_k_max)
    ftype = np.dtype(dtype)
    band_idx = np.zeros(0, np.int64)
    arrays = None
    hard_band = np.zeros(0)
    if len(wedge.jump):
        ground = posed.ground_vertices()
        axes = np.eye(2, 3) * grid.pixel_m if footprint else None
        reach_m = float(_pixel_reach(axes, posed.light)) if footprint else 0.0
        reach = _ground_reach(posed, wedge, range_k_max, reach_m)
        ids_v = wedge.vertex_ids
        # The window: the shadow's outline (the silhouette's shadow) padded by the widest reach.
        seg = np.concatenate([ground[ids_v[:, 0]], ground[ids_v[:, 1]]])
        px = grid.to_pixel(seg)
        pad = float(reach.max()) / grid.pixel_m + 2.0
        c0 = int(max(np.floor(px[:, 0].min() - pad), 0))
        c1 = int(min(np.ceil(px[:, 0].max() + pad), w - 1))
        r0 = int(max(np.floor(px[:, 1].min() - pad), 0))
        r1 = int(min(np.ceil(px[:, 1].max() + pad), h - 1))
        if c1 >= c0 and r1 >= r0:
            window = GroundGrid(grid.pixel_m, (grid.origin_m[0] + c0 * grid.pixel_m,
                                               grid.origin_m[1] - r0 * grid.pixel_m), c1 - c0 + 1, r1 - r0 + 1)
            vpx = window.to_pixel(ground)
            count = layer_count_fill((window.height, window.width), vpx, sil.fill_edges)
            hard[r0:r1 + 1, c0:c1 + 1] = count >= 0.5
            flat_count = count.reshape(-1)
            sel, arrays, on = _wedge_choices(posed, wedge, window, reach, range_k_max, reach_m,
                                             lambda i: flat_count[i].astype(np.float64), axes)
            rows, cols = np.divmod(sel, window.width)
            band_idx = (rows + r0) * w + (cols + c0)
            hard_band = flat_count[sel] >= 0.5
    m = len(band_idx)
    size = grid_bucket_size(m)
    index = np.full(size, h * w, np.int32)
    index[:m] = band_idx
    active = np.zeros(size, bool)
    active[:m] = True
    hb = np.zeros(size, ftype)
    hb[:m] = hard_band
    choices = _no_wedge(size, footprint) if arrays is None else arrays.select(on, pad_points=size)
    plan = PointPlan(_pack_wedge_edges(occ, wedge, ftype), np.zeros((size, 0), np.int32), hb, active,
                     np.zeros(size, ftype), choices.astype(ftype))
    return GridPlan(grid, hard, index, plan, None, m, len(wedge.jump))
