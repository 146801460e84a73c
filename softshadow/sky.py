"""The sky an occluder hides from receiver points (NumPy, trimesh ray casting): one implementation
for the renderer (``SoftShadowModel(hidden_sky=True)``) and the fitter (``fitting.samples.ground``).

Under a sky of uniform radiance, a ground point whose cosine-weighted
hemisphere is hidden by the object in the fraction h receives (1 - h) of the
open ground's sky irradiance. rho is defined on open ground, so beside the
object its umbra reads darker by rho h (and its lit side by the same): the
fit's pixel model is 1 - alpha (1 - rho) - rho h, with h fixed per sample by
the geometry (a discrete step, no new parameter). This is written apart from
``data_synth``'s renderer so that the physical truth stays independent.

On a receiver of any orientation (``open_sky_fraction``) the sky a point sees
is the part of the cosine-weighted hemisphere around its normal that points
up (d_z > 0) and is not blocked by the object or the receiver itself, over the
open ground's whole sky: (1 + n_z) / 2 for an unobstructed plane; the fit uses
h = 1 - that (``fitting.samples.receiver_light``).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import trimesh
from scipy.ndimage import binary_dilation, map_coordinates

from .camera import GroundGrid

__all__ = ["SkyNodes", "SkyPatch", "cosine_weighted_directions", "hidden_sky_fraction", "hidden_sky_map", "hidden_sky_nodes",
           "open_sky_fraction"]

SKY_DIRECTIONS = 256  # rays per node of a map: the fraction's step is 1/256 (rho h within ~0.001)
SKY_NODES = 64        # nodes a side of a map's sky grid (bilinear between them)


def cosine_weighted_directions(n: int) -> np.ndarray:
    """n unit directions (n, 3) over the upper hemisphere, cosine-weighted and evenly spread:
    a Fibonacci spiral on the unit disk lifted to the hemisphere (Malley's method)."""
    i = np.arange(n) + 0.5
    r = np.sqrt(i / n)
    phi = i * np.pi * (3.0 - np.sqrt(5.0))
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1.0 - r * r)])


def hidden_sky_fraction(mesh: trimesh.Trimesh, points: np.ndarray, n_directions: int = 64,
                        offset_m: float = 1e-4) -> np.ndarray:
    """Fraction h (N,) of the cosine-weighted sky that ``mesh`` hides from ground points (N, 3)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if not len(points) or not len(mesh.faces):
        return np.zeros(len(points))
    dirs = cosine_weighted_directions(n_directions)
    origins = np.repeat(points + [0.0, 0.0, offset_m], n_directions, axis=0)
    hit = mesh.ray.intersects_any(origins, np.tile(dirs, (len(points), 1)))
    return hit.reshape(len(points), n_directions).mean(axis=1)


def _frames(normals: np.ndarray) -> np.ndarray:
    """Orthonormal frames (N, 3, 3), rows (t1, t2, n), around unit normals (N, 3)."""
    n = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    helper = np.where(np.abs(n[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    t1 = np.cross(helper, n)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    return np.stack([t1, np.cross(n, t1), n], axis=1)


def open_sky_fraction(mesh: trimesh.Trimesh | None, points: np.ndarray, normals: np.ndarray,
                      n_directions: int = 64, offset_m: float = 1e-3) -> np.ndarray:
    """Sky v (N,) seen from points (N, 3) with unit normals (N, 3), over open ground's sky.

    The fraction of ``n_directions`` cosine-weighted directions around each normal that
    point up and miss ``mesh`` (the object and the receiver; None: nothing blocks). Rays
    start offset_m along the normal, off their own surface.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    if not len(points):
        return np.zeros(0)
    dirs = np.einsum("mk,nkj->nmj", cosine_weighted_directions(n_directions), _frames(normals))
    up = dirs[..., 2] > 1e-9
    if mesh is not None and len(mesh.faces):
        origins = np.broadcast_to((points + offset_m * normals)[:, None, :], dirs.shape)
        todo = up.ravel()
        hit = np.zeros(todo.shape, bool)
        hit[todo] = mesh.ray.intersects_any(origins.reshape(-1, 3)[todo], dirs.reshape(-1, 3)[todo])
        up &= ~hit.reshape(up.shape)
    return up.mean(axis=1)


def _bilinear(values: np.ndarray, x0: float, y0: float, step: float, xy: np.ndarray) -> np.ndarray:
    """Bilinear interpolation of node values (ny, nx) at x0 + j step, y0 + i step; 0 outside."""
    return map_coordinates(values, [(xy[:, 1] - y0) / step, (xy[:, 0] - x0) / step], order=1, mode="constant",
                           cval=0.0)


@dataclasses.dataclass(frozen=True)
class SkyPatch:
    """Finer nodes over the coarse cells next to the object's low parts (x0 + j step, y0 + i step).

    values (ny, nx): h at the nodes of the covered cells (0 elsewhere, never read); covered
    (ny - 1, nx - 1): the cells it answers for; exact (ny - 1, nx - 1): cells where a node
    inside the object (h = 1) meets one outside it, and their neighbours, whose points are
    cast one by one.
    """

    x0: float
    y0: float
    step: float
    values: np.ndarray
    covered: np.ndarray
    exact: np.ndarray

    def cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(covered, exact) (N,) for ground points xy (N, 2+)."""
        ny, nx = self.covered.shape
        fx, fy = (xy[:, 0] - self.x0) / self.step, (xy[:, 1] - self.y0) / self.step
        inside = (fx >= 0) & (fx <= nx) & (fy >= 0) & (fy <= ny)
        j = np.clip(np.floor(fx), 0, nx - 1).astype(np.int64)
        i = np.clip(np.floor(fy), 0, ny - 1).astype(np.int64)
        covered = inside & self.covered[i, j]
        return covered, covered & self.exact[i, j]


@dataclasses.dataclass(frozen=True)
class SkyNodes:
    """Hidden sky fractions cast on a square grid of ground nodes (x0 + j step, y0 + i step);
    ``at`` interpolates them bilinearly (0 outside the grid), from the finer ``patch`` next to
    the object, and casts h point by point where a patch cell straddles the object's wall."""

    x0: float
    y0: float
    step: float
    values: np.ndarray  # (n, n)
    patch: SkyPatch | None = None
    mesh: trimesh.Trimesh | None = dataclasses.field(default=None, repr=False)
    n_directions: int = SKY_DIRECTIONS

    def at(self, points_xy: np.ndarray) -> np.ndarray:
        """h (N,) at ground points (N, 2 or 3)."""
        xy = np.asarray(points_xy, dtype=np.float64)
        xy = xy.reshape(-1, xy.shape[-1])
        h = _bilinear(self.values, self.x0, self.y0, self.step, xy)
        if self.patch is not None:
            p = self.patch
            covered, exact = p.cells(xy)
            h[covered] = _bilinear(p.values, p.x0, p.y0, p.step, xy[covered])
            if exact.any():
                pts = np.column_stack([xy[exact, :2], np.zeros(int(exact.sum()))])
                h[exact] = hidden_sky_fraction(self.mesh, pts, self.n_directions)
        return h


def _cast_grid(mesh: trimesh.Trimesh, x0: float, y0: float, step: float, nx: int, ny: int,
               n_directions: int, todo: np.ndarray | None = None) -> np.ndarray:
    """h (ny, nx) at the ground nodes x0 + j step, y0 + i step (only where ``todo``; 0 elsewhere)."""
    gx, gy = np.meshgrid(x0 + step * np.arange(nx), y0 + step * np.arange(ny))
    out = np.zeros((ny, nx))
    todo = np.ones((ny, nx), bool) if todo is None else todo
    pts = np.column_stack([gx[todo], gy[todo], np.zeros(int(todo.sum()))])
    out[todo] = hidden_sky_fraction(mesh, pts, n_directions)
    return out


def _low_cells(mesh: trimesh.Trimesh, x0: float, y0: float, step: float, n: int, below_m: float) -> np.ndarray:
    """Coarse cells (n - 1, n - 1) under the xy bounding box of a face reaching below ``below_m``
    (where the object stands on or near the ground, h changes within a few centimetres)."""
    tri = mesh.triangles
    tri = tri[tri[:, :, 2].min(axis=1) < below_m]
    cells = n - 1
    mark = np.zeros((cells + 1, cells + 1), np.int64)  # 2-D difference array of the boxes
    if len(tri):
        lo = np.floor((tri[:, :, :2].min(axis=1) - (x0, y0)) / step).astype(np.int64)
        hi = np.floor((tri[:, :, :2].max(axis=1) - (x0, y0)) / step).astype(np.int64) + 1
        lo, hi = np.clip(lo, 0, cells), np.clip(hi, 0, cells)
        (b, a), (d, c) = lo.T, hi.T  # rows are y (a, c), columns x (b, d)
        np.add.at(mark, (a, b), 1)
        np.add.at(mark, (a, d), -1)
        np.add.at(mark, (c, b), -1)
        np.add.at(mark, (c, d), 1)
    return np.cumsum(np.cumsum(mark, axis=0), axis=1)[:cells, :cells] > 0


def hidden_sky_nodes(mesh_world: trimesh.Trimesh, fine_m: float = 0.0, n_directions: int = SKY_DIRECTIONS,
                     nodes: int = SKY_NODES, margin: float = 1.5, refine: int = 4) -> SkyNodes:
    """The hidden sky fraction of the ground (z = 0) around a posed mesh, on node grids.

    h is smooth away from the object, so it is cast on a coarse grid of at most ``nodes`` a
    side (no finer than ``fine_m``) over the object's footprint padded by ``margin`` times its
    height (where a slim post hides about 0.5 % of the sky; 0 beyond) and interpolated
    bilinearly. Next to the object's low parts (the coarse cells under faces reaching below
    one coarse step, and one cell round them) h falls steeply and jumps at a wall (h = 1 under
    the object, about 0.5 at its foot): there a patch of nodes up to ``refine`` times finer
    (no finer than ``fine_m``; at most ``nodes``^2 of them) is cast, and ``at`` casts h point
    by point in the patch cells that straddle a wall. Costs nodes^2 x n_directions rays (about
    0.35 s for 64^2 x 256 on one core with embree) plus the patch's: a renderer casts it once
    per pose.
    """
    if not len(mesh_world.faces) or mesh_world.bounds[1][2] <= 0.0:
        return SkyNodes(0.0, 0.0, 1.0, np.zeros((1, 1)))
    lo, hi = np.asarray(mesh_world.bounds, dtype=np.float64)
    pad = margin * float(hi[2])
    x0, y0 = lo[0] - pad, lo[1] - pad
    side = max(hi[0] - lo[0], hi[1] - lo[1]) + 2 * pad
    step = max(side / (nodes - 1), fine_m)
    n = int(np.ceil(side / step)) + 1
    values = _cast_grid(mesh_world, x0, y0, step, n, n, n_directions)
    coarse = SkyNodes(float(x0), float(y0), float(step), values, None, mesh_world, n_directions)
    if n < 2:
        return coarse
    near = binary_dilation(_low_cells(mesh_world, x0, y0, step, n, step), iterations=1)
    if not near.any():
        return coarse
    f = int(max(1, min(refine, step / max(fine_m, 1e-12), np.sqrt(nodes * nodes / near.sum()))))
    rows, cols = np.flatnonzero(near.any(axis=1)), np.flatnonzero(near.any(axis=0))
    r0, c0 = rows[0], cols[0]
    sub = near[r0:rows[-1] + 1, c0:cols[-1] + 1]
    covered = np.kron(sub, np.ones((f, f), bool))  # patch cells (ny - 1, nx - 1)
    cast = np.zeros((covered.shape[0] + 1, covered.shape[1] + 1), bool)
    for di in (0, 1):
        for dj in (0, 1):
            cast[di:di + covered.shape[0], dj:dj + covered.shape[1]] |= covered
    px0, py0, pstep = x0 + c0 * step, y0 + r0 * step, step / f
    pv = _cast_grid(mesh_world, px0, py0, pstep, cast.shape[1], cast.shape[0], n_directions, cast)
    solid = cast & (pv >= 1.0)  # every direction blocked: a node inside the object
    corners = [solid[:-1, :-1], solid[:-1, 1:], solid[1:, :-1], solid[1:, 1:]]
    # The cells that straddle a wall and their neighbours (h falls steeply within a cell of the
    # wall), not those wholly inside the object (h = 1 there is exact).
    straddle = np.logical_or.reduce(corners) & ~np.logical_and.reduce(corners)
    exact = covered & binary_dilation(straddle, np.ones((3, 3), bool)) & ~np.logical_and.reduce(corners)
    return dataclasses.replace(coarse, patch=SkyPatch(float(px0), float(py0), float(pstep), pv, covered, exact))


def hidden_sky_map(mesh_world: trimesh.Trimesh, grid: GroundGrid, **kwargs) -> np.ndarray:
    """Hidden sky fraction h (H, W) at the pixel centres of a top-down ground map
    (``hidden_sky_nodes`` with nodes no finer than its pixels)."""
    nodes = hidden_sky_nodes(mesh_world, grid.pixel_m, **kwargs)
    return nodes.at(grid.pixel_centres()).reshape(grid.height, grid.width)
