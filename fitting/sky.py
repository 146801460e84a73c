"""The sky an occluder hides from points on the ground (NumPy, trimesh ray casting).

Under a sky of uniform radiance, a ground point whose cosine-weighted
hemisphere is hidden by the object in the fraction h receives (1 - h) of the
open ground's sky irradiance. rho is defined on open ground, so beside the
object its umbra reads darker by rho h (and its lit side by the same): the
fit's pixel model is 1 - alpha (1 - rho) - rho h, with h fixed per sample by
the geometry (a discrete step, no new parameter). This is written apart from
``data_synth``'s renderer so that the physical truth stays independent.
"""

from __future__ import annotations

import numpy as np
import trimesh

__all__ = ["cosine_weighted_directions", "hidden_sky_fraction"]


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
