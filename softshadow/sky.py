"""The sky an occluder hides from receiver points (NumPy, trimesh ray casting): one implementation
for the renderer (``SoftShadowModel(hidden_sky=True)``) and the fitter (``fitting.samples``).

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
h = 1 - that (``fitting.receiver_light``).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import trimesh
from scipy.ndimage import map_coordinates

from .camera import GroundGrid

__all__ = ["SkyNodes", "cosine_weighted_directions", "hidden_sky_fraction", "hidden_sky_map", "hidden_sky_nodes",
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


@dataclasses.dataclass(frozen=True)
class SkyNodes:
    """Hidden sky fractions cast on a square grid of ground nodes (x0 + j step, y0 + i step);
    ``at`` interpolates them bilinearly (0 outside the grid)."""

    x0: float
    y0: float
    step: float
    values: np.ndarray  # (n, n)

    def at(self, points_xy: np.ndarray) -> np.ndarray:
        """h (N,) at ground points (N, 2 or 3)."""
        xy = np.asarray(points_xy, dtype=np.float64)
        xy = xy.reshape(-1, xy.shape[-1])
        return map_coordinates(self.values, [(xy[:, 1] - self.y0) / self.step, (xy[:, 0] - self.x0) / self.step],
                               order=1, mode="constant", cval=0.0)


def hidden_sky_nodes(mesh_world: trimesh.Trimesh, fine_m: float = 0.0, n_directions: int = SKY_DIRECTIONS,
                     nodes: int = SKY_NODES, margin: float = 1.5) -> SkyNodes:
    """The hidden sky fraction of the ground (z = 0) around a posed mesh, on a node grid.

    h is smooth away from the object, so it is cast on a coarse grid of at most ``nodes`` a
    side (no finer than ``fine_m``) over the object's footprint padded by ``margin`` times its
    height (where a slim post hides about 0.5 % of the sky; 0 beyond) and interpolated
    bilinearly. Costs nodes^2 x n_directions rays (about 0.35 s for 64^2 x 256 on one core
    with embree): a renderer casts it once per pose.
    """
    if not len(mesh_world.faces) or mesh_world.bounds[1][2] <= 0.0:
        return SkyNodes(0.0, 0.0, 1.0, np.zeros((1, 1)))
    lo, hi = np.asarray(mesh_world.bounds, dtype=np.float64)
    pad = margin * float(hi[2])
    x0, y0 = lo[0] - pad, lo[1] - pad
    side = max(hi[0] - lo[0], hi[1] - lo[1]) + 2 * pad
    step = max(side / (nodes - 1), fine_m)
    n = int(np.ceil(side / step)) + 1
    gx, gy = np.meshgrid(x0 + step * np.arange(n), y0 + step * np.arange(n))
    pts = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    return SkyNodes(float(x0), float(y0), float(step), hidden_sky_fraction(mesh_world, pts, n_directions).reshape(n, n))


def hidden_sky_map(mesh_world: trimesh.Trimesh, grid: GroundGrid, **kwargs) -> np.ndarray:
    """Hidden sky fraction h (H, W) at the pixel centres of a top-down ground map
    (``hidden_sky_nodes`` with nodes no finer than its pixels)."""
    nodes = hidden_sky_nodes(mesh_world, grid.pixel_m, **kwargs)
    return nodes.at(grid.pixel_centres()).reshape(grid.height, grid.width)
