"""Light on a receiver of any orientation, relative to open horizontal ground (pure functions).

rho keeps its meaning on every receiver: umbra over lit irradiance on open
HORIZONTAL ground at that time, so the open ground's lit level is
E_lit = E_sun_h + E_sky with E_sky = rho E_lit and E_sun_h = (1 - rho) E_lit.
A receiver point with unit normal n, under a sun in direction s (towards the
sun, s_z = sin(elevation)) and a sky of uniform radiance, receives relative to
E_lit

    lit   = (1 - rho) c + rho v,     umbra = rho v,
    c = max(n . s, 0) / s_z          (the sun's incidence against the open ground's),
    v = the sky it sees               (the part of the cosine-weighted hemisphere around n
                                        that is open sky, over the open ground's whole sky:
                                        (1 + n_z) / 2 for an unobstructed plane; less what the
                                        object and the receiver itself hide from it),

and, with the soft shadow's alpha (0 lit, 1 umbra), (1 - rho) c (1 - alpha) + rho v.
On open horizontal ground c = 1 and v = 1 - h (h: the sky the object hides), which
is the flat-ground model 1 - alpha (1 - rho) - rho h. A face turned away from the
sun (c = 0) shows rho v whatever alpha is (its attached shadow).

Arithmetic only (NumPy or JAX arrays alike) except ``sun_incidence`` and
``plane_sky_fraction``, which take NumPy geometry.
"""

from __future__ import annotations

import numpy as np

__all__ = ["sun_incidence", "plane_sky_fraction", "lit_level", "umbra_level", "shadow_factor"]


def sun_incidence(normals: np.ndarray, sun_direction: np.ndarray) -> np.ndarray:
    """c (N,) = max(n . s, 0) / s_z: direct sun on unit normals (N, 3) over the open ground's.

    sun_direction (3,): unit vector towards the sun (above the horizon, s_z > 0).
    """
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    s = np.asarray(sun_direction, dtype=np.float64).reshape(3)
    if not s[2] > 0:
        raise ValueError("the sun must be above the horizon (s_z > 0)")
    return np.maximum(n[:, 0] * s[0] + n[:, 1] * s[1] + n[:, 2] * s[2], 0.0) / s[2]


def plane_sky_fraction(normals: np.ndarray) -> np.ndarray:
    """v (N,) = (1 + n_z) / 2: the uniform sky an unobstructed plane of unit normal n sees,
    over open horizontal ground's (1 on the ground, 1/2 on a wall, 0 facing down)."""
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    return 0.5 * (1.0 + n[:, 2])


def lit_level(rho, sun_cos, sky):
    """Lit irradiance over the open horizontal ground's: (1 - rho) c + rho v."""
    return (1.0 - rho) * sun_cos + rho * sky


def umbra_level(rho, sky):
    """Umbra irradiance over the open horizontal ground's lit one: rho v."""
    return rho * sky


def shadow_factor(alpha, rho, sun_cos, sky):
    """Irradiance under a soft shadow alpha over the open ground's lit one:
    (1 - rho) c (1 - alpha) + rho v."""
    return (1.0 - rho) * sun_cos * (1.0 - alpha) + rho * sky
