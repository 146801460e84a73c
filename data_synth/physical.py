"""Physically based irradiance by ray casting (trimesh + Embree): sun disk plus uniform sky.

Independent of the project's shadow model: nothing here comes from
softshadow.penumbra/plan/raster/render. A receiver point p with unit normal n
receives

    E(p) = E_sun_normal * max(n.s, 0) * V_sun(p) + pi * L_sky * V_sky(p)

V_sun: the (limb-darkening weighted) fraction of the sun's disk seen from p,
estimated with stratified directions over the disk, each cast against the
occluders. V_sky: the fraction of the cosine-weighted hemisphere around n that
is open sky (upwards, d_z > 0, and not blocked); 1 on open horizontal ground.

Speed: the direct sun is wholly visible except near the shadow, so sun rays
are cast only for points inside the shadow's reach (``shadow_reach``). The
hidden sky is smooth, so it is computed on coarse world grids
(``SkyVisibilityMap``) and interpolated, except next to the object's walls
(where it jumps): there it is traced point by point.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import trimesh
from scipy.spatial import ConvexHull, QhullError

from .lighting import SunSky, limb_darkening_weight
from .receivers import Receiver
from .sampling import (bilinear, cap_directions, cosine_hemisphere_directions, orthonormal_basis,
                       stratified_square, strata_side)

__all__ = ["RAY_OFFSET_M", "SKY_SPREAD", "shadow_reach", "sun_visibility", "sky_visibility", "SkyGrid",
           "SkyVisibilityMap", "sky_visibility_map", "irradiance", "combined_mesh"]

RAY_OFFSET_M = 1e-3   # ray origins move this far along the ray to avoid hitting their own surface
MAX_RAYS_PER_CALL = 1_000_000  # chunking keeps memory of one batch near 100 MB


def combined_mesh(*meshes) -> trimesh.Trimesh:
    """One mesh of everything that can block light (None entries are skipped)."""
    meshes = [m for m in meshes if m is not None]
    if len(meshes) == 1:
        return meshes[0]
    combined: trimesh.Trimesh = trimesh.util.concatenate(meshes)  # trimesh annotates it as any Geometry
    return combined


def _any_hit(mesh: trimesh.Trimesh, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Whether each ray (origins (N, 3), directions (N, 3)) hits the mesh, chunked."""
    out = np.zeros(len(origins), bool)
    for s in range(0, len(origins), MAX_RAYS_PER_CALL):
        e = s + MAX_RAYS_PER_CALL
        out[s:e] = mesh.ray.intersects_any(origins[s:e], directions[s:e])
    return out


def shadow_reach(occluder_vertices: np.ndarray, sun: SunSky, points: np.ndarray,
                 margin_m: float = 0.01, widen: float = 1.5) -> np.ndarray:
    """Points (N, 3) that any direction of the sun's disk may see blocked by the occluder.

    The occluder's vertices are projected along the sun onto the plane
    perpendicular to it; a point is in reach when it lies behind the occluder
    (closer to the sun's far side) and its projection falls inside the convex
    hull dilated by (distance along the light) * tan(radius) * widen + margin.
    Conservative: every point outside the mask sees the whole disk.
    """
    s = sun.direction
    t1, t2 = orthonormal_basis(s)
    v = np.asarray(occluder_vertices, dtype=np.float64)
    va = np.stack([v @ t1, v @ t2], -1)
    top = float(np.max(v @ s))
    try:
        hull = ConvexHull(va)
        eq = hull.equations  # rows (nx, ny, c): inside where nx x + ny y + c <= 0
    except (QhullError, ValueError):  # flat or tiny occluder: fall back to its bounding box
        lo, hi = va.min(0), va.max(0)
        eq = np.array([[1.0, 0, -hi[0]], [-1.0, 0, lo[0]], [0, 1.0, -hi[1]], [0, -1.0, lo[1]]])
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.zeros(len(pts), bool)
    tan_r = np.tan(sun.radius_rad) * widen
    chunk = 262_144
    for a in range(0, len(pts), chunk):
        p = pts[a:a + chunk]
        depth = top - p @ s  # how far the occluder's top lies beyond p along the sun
        pa, pb = p @ t1, p @ t2
        dist = np.stack([pa, pb], -1) @ eq[:, :2].T + eq[:, 2]
        dilate = np.maximum(depth, 0.0) * tan_r + margin_m
        out[a:a + chunk] = (depth > -margin_m) & np.all(dist <= dilate[:, None], axis=1)
    return out


N_SUN_PATTERNS = 128  # distinct jittered disk patterns; each point draws one at random


def _sun_patterns(sun: SunSky, side: int, rng: np.random.Generator | None):
    """Directions (K, m, 3) and limb-darkening weights (K, m) of K stratified disk patterns."""
    u = stratified_square(N_SUN_PATTERNS if rng is not None else 1, side, rng)
    dirs, frac = cap_directions(sun.direction, sun.radius_rad, u)
    return dirs, limb_darkening_weight(frac, sun.limb_darkening)


def sun_visibility(mesh: trimesh.Trimesh, points: np.ndarray, normals: np.ndarray, sun: SunSky,
                   n_samples: int = 64, rng: np.random.Generator | None = None,
                   pixel_axes: np.ndarray | None = None, offset_m: float = RAY_OFFSET_M) -> np.ndarray:
    """Fraction (N,) of the sun's disk (limb-darkening weighted) seen from points (N, 3).

    Stratified over the disk (side x side strata). With rng, each point uses one of
    N_SUN_PATTERNS independently jittered patterns, drawn at random (unbiased, noise
    uncorrelated between points); without, the strata centres (deterministic).
    pixel_axes (N, 2, 3): the receiver extent of each point's pixel along u and v;
    each sun sample then starts from a random position in the pixel, so the
    estimate is also an area average (anti-aliasing of narrow penumbrae).
    normals are unused for the rays (origins move along the ray, which keeps the
    penumbra in place) but kept for a uniform signature.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    side = strata_side(n_samples)
    m = side * side
    table, weights = _sun_patterns(sun, side, rng)
    out = np.empty(len(pts))
    per_chunk = max(1, MAX_RAYS_PER_CALL // m)
    for a in range(0, len(pts), per_chunk):
        p = pts[a:a + per_chunk]
        pick = rng.integers(0, len(table), len(p)) if rng is not None else np.zeros(len(p), int)
        dirs, weight = table[pick], weights[pick]
        # Start each ray a little along itself (not along n): the ray's line, hence
        # where it meets the occluder, is unchanged, so the penumbra does not shift.
        origins = p[:, None, :] + offset_m * dirs
        if pixel_axes is not None and rng is not None:
            ax = pixel_axes[a:a + per_chunk]
            jit = rng.random((len(p), m, 2)) - 0.5
            origins = origins + jit[..., 0:1] * ax[:, None, 0, :] + jit[..., 1:2] * ax[:, None, 1, :]
        hit = _any_hit(mesh, origins.reshape(-1, 3), dirs.reshape(-1, 3)).reshape(len(p), m)
        out[a:a + per_chunk] = np.mean(weight * ~hit, axis=1)
    return out


def sky_visibility(mesh: trimesh.Trimesh | None, points: np.ndarray, normals: np.ndarray,
                   n_samples: int = 256, seed: int | None = 0, per_point_jitter: bool = False,
                   offset_m: float = RAY_OFFSET_M) -> np.ndarray:
    """Open-sky fraction (N,) of the cosine-weighted hemisphere around normals (N, 3).

    Sky means upwards (d_z > 0) and not blocked by the mesh. By default every point
    uses the same jittered stratified pattern (seeded): the estimate is then
    spatially coherent (no pixel noise), with an error that varies smoothly.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    side = strata_side(n_samples)
    m = side * side
    rng = np.random.default_rng(seed)
    pattern = stratified_square(1, side, rng)
    if mesh is not None:
        centre = mesh.bounds.mean(axis=0)
        radius = 0.5 * float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0])) + 1e-6
    out = np.empty(len(pts))
    per_chunk = max(1, MAX_RAYS_PER_CALL // m)
    for a in range(0, len(pts), per_chunk):
        p, n = pts[a:a + per_chunk], nrm[a:a + per_chunk]
        if per_point_jitter:
            dirs = cosine_hemisphere_directions(n, stratified_square(len(p), side, rng))
        elif np.all(n == n[0]):  # one normal (a plane): one set of directions for every point
            dirs = np.broadcast_to(cosine_hemisphere_directions(n[:1], pattern), (len(p), m, 3))
        else:
            dirs = cosine_hemisphere_directions(n, np.broadcast_to(pattern, (len(p), m, 2)))
        up = dirs[..., 2] > 0
        if mesh is not None:
            origins = p[:, None, :] + offset_m * dirs
            # Only rays that pass the mesh's bounding sphere can hit it (cheap cull in NumPy).
            oc = centre - p  # (P, 3)
            t_ca = np.einsum("pnj,pj->pn", dirs, oc)
            d2 = np.sum(oc * oc, -1)[:, None] - t_ca ** 2
            near = up & (d2 <= radius ** 2) & ((t_ca > 0) | (np.sum(oc * oc, -1) <= radius ** 2)[:, None])
            flat = near.ravel()
            blocked = np.zeros(flat.shape, bool)
            if flat.any():
                blocked[flat] = _any_hit(mesh, origins.reshape(-1, 3)[flat], dirs.reshape(-1, 3)[flat])
            up &= ~blocked.reshape(up.shape)
        out[a:a + per_chunk] = up.mean(axis=1)
    return out


@dataclasses.dataclass(frozen=True)
class SkyGrid:
    """Open-sky fraction sampled on a regular world grid: values (ny, nx) at
    x = x0 + i * step, y = y0 + j * step."""

    x0: float
    y0: float
    step: float
    values: np.ndarray

    def contains(self, xy: np.ndarray) -> np.ndarray:
        ny, nx = self.values.shape
        i = (xy[:, 0] - self.x0) / self.step
        j = (xy[:, 1] - self.y0) / self.step
        return (i >= 0) & (i <= nx - 1) & (j >= 0) & (j <= ny - 1)

    def sample(self, xy: np.ndarray) -> np.ndarray:
        i = (xy[:, 0] - self.x0) / self.step
        j = (xy[:, 1] - self.y0) / self.step
        return bilinear(self.values, j, i).astype(np.float64)

    def spread(self, xy: np.ndarray) -> np.ndarray:
        """Largest minus smallest of the four nodes of each point's cell (N,); 0 outside the grid."""
        ny, nx = self.values.shape
        i = np.clip(np.floor((xy[:, 0] - self.x0) / self.step).astype(np.int64), 0, nx - 2)
        j = np.clip(np.floor((xy[:, 1] - self.y0) / self.step).astype(np.int64), 0, ny - 2)
        v = self.values
        corners = np.stack([v[j, i], v[j, i + 1], v[j + 1, i], v[j + 1, i + 1]])
        return np.where(self.contains(xy), corners.max(axis=0) - corners.min(axis=0), 0.0)


#: A cell of the finest sky grid whose four nodes differ by more than this is traced point by
#: point: bilinear interpolation across the object's wall (a node inside it sees no sky, one
#: beside it about half) reads up to 0.65 of the sky too dark in the first pixels beside it.
SKY_SPREAD = 0.05


@dataclasses.dataclass(frozen=True)
class SkyVisibilityMap:
    """Nested sky grids, finest first; points outside all grids see the open sky (``outside``).

    With ``mesh`` and ``receiver``, points in cells of the finest grid whose nodes differ by
    more than ``spread`` (next to the object's walls) are traced one by one with the grids'
    directions (``sky_visibility``, n_samples, seed) instead of interpolated."""

    grids: tuple[SkyGrid, ...]
    outside: float = 1.0
    mesh: trimesh.Trimesh | None = dataclasses.field(default=None, repr=False)
    receiver: Receiver | None = dataclasses.field(default=None, repr=False)
    n_samples: int = 1024
    seed: int | None = 0
    spread: float = SKY_SPREAD

    def steep(self, xy: np.ndarray) -> np.ndarray:
        """Points (N,) that ``at`` traces rather than interpolates."""
        xy = np.asarray(xy, dtype=np.float64).reshape(len(xy), -1)[:, :2]
        if self.mesh is None or self.receiver is None or not self.grids:
            return np.zeros(len(xy), bool)
        return self.grids[0].spread(xy) > self.spread

    def at(self, xy: np.ndarray) -> np.ndarray:
        """Open-sky fraction (N,) at world points xy (N, 2 or 3), bilinear (traced where steep)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(len(xy), -1)[:, :2]
        out = np.full(len(xy), self.outside)
        todo = np.ones(len(xy), bool)
        for g in self.grids:
            inside = todo & g.contains(xy)
            if inside.any():
                out[inside] = g.sample(xy[inside])
            todo &= ~inside
        steep = self.steep(xy)
        if steep.any():
            p = xy[steep]
            pts = np.concatenate([p, self.receiver.height(p)[:, None]], -1)
            out[steep] = sky_visibility(self.mesh, pts, self.receiver.normal(p), self.n_samples, self.seed)
        return out


def sky_visibility_map(mesh: trimesh.Trimesh | None, receiver, object_bounds: np.ndarray,
                       n_samples: int = 1024, seed: int = 0, fine_nodes: int = 96,
                       fine_margin_m: float | None = None, coarse_margin_m: float = 10.0,
                       coarse_step_m: float = 0.4, outside: float = 1.0,
                       spread: float = SKY_SPREAD) -> SkyVisibilityMap:
    """Sky visibility of a receiver near an object: a fine grid around it and a coarse one further out.

    object_bounds (2, 3): the occluder's bounding box. The fine grid covers it
    plus ``fine_margin_m`` (default: its height, at least 1 m) with at most
    ``fine_nodes`` nodes a side; the coarse grid extends ``coarse_margin_m``
    beyond. Beyond that the object hides under ~0.1 % of the sky of a 3 m post;
    ``outside`` is used there (1 for the plane; pass the receiver's own open-sky
    level when it hides sky from itself). Points in fine cells whose nodes differ
    by more than ``spread`` are traced when looked up (``SkyVisibilityMap.at``).
    """
    lo, hi = np.asarray(object_bounds, dtype=np.float64)
    height = float(hi[2] - min(lo[2], 0.0))
    fine_margin = max(1.0, height) if fine_margin_m is None else fine_margin_m
    grids = []
    for margin, step in ((fine_margin, None), (coarse_margin_m, coarse_step_m)):
        x0, y0 = lo[0] - margin, lo[1] - margin
        x1, y1 = hi[0] + margin, hi[1] + margin
        if step is None:
            step = max(x1 - x0, y1 - y0) / (fine_nodes - 1)
        nx = int(np.ceil((x1 - x0) / step)) + 1
        ny = int(np.ceil((y1 - y0) / step)) + 1
        gx, gy = np.meshgrid(x0 + step * np.arange(nx), y0 + step * np.arange(ny))
        xy = np.stack([gx.ravel(), gy.ravel()], -1)
        pts = np.concatenate([xy, receiver.height(xy)[:, None]], -1)
        vals = sky_visibility(mesh, pts, receiver.normal(xy), n_samples, seed)
        grids.append(SkyGrid(float(x0), float(y0), float(step), vals.reshape(ny, nx)))
    return SkyVisibilityMap(tuple(grids), outside, mesh, receiver if mesh is not None else None, n_samples, seed,
                            spread)


def irradiance(sun: SunSky, normals: np.ndarray, sun_vis: np.ndarray, sky_vis: np.ndarray) -> np.ndarray:
    """E (N,) = E_sun_normal max(n.s, 0) V_sun + pi L_sky V_sky."""
    cos_s = np.clip(np.asarray(normals).reshape(-1, 3) @ sun.direction, 0.0, None)
    return sun.sun_normal_irradiance * cos_s * sun_vis + sun.sky_horizontal_irradiance * sky_vis
