"""The sky an occluder hides from points on the ground (NumPy, trimesh ray casting).

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

import numpy as np
import trimesh

__all__ = ["cosine_weighted_directions", "hidden_sky_fraction", "open_sky_fraction"]


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
