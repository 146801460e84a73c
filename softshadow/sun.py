"""Sun direction: the light the renderer casts shadows with (JAX, or NumPy for the discrete steps).

Frames as in docs/formats.md: world x east, y north, z up; azimuth A clockwise
from north towards east, elevation E above the horizon, direction *to* the
sun s = (sin A cos E, cos A cos E, sin E); light travels along L = -s.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Float

from ._typing import AnyArray

__all__ = ["sun_direction", "light_direction", "check_sun_above_horizon", "SunBelowHorizonError"]


class SunBelowHorizonError(ValueError):
    """The sun is at or below the horizon: there is no direct-sun shadow."""


def sun_direction(azimuth_deg, elevation_deg, xp=jnp) -> Float[AnyArray, "3 ..."]:
    """Unit vector towards the sun, shape (3, *batch) for angles of shape batch, in degrees.

    xp: the array module, ``jax.numpy`` (differentiable) or ``numpy`` (for the discrete
    steps, which must not dispatch eager JAX ops)."""
    a = xp.deg2rad(azimuth_deg)
    e = xp.deg2rad(elevation_deg)
    return xp.stack([xp.sin(a) * xp.cos(e), xp.cos(a) * xp.cos(e), xp.sin(e)])


def light_direction(azimuth_deg, elevation_deg, xp=jnp) -> Float[AnyArray, "3 ..."]:
    """Unit direction the sunlight travels, L = -s, shape (3, *batch) (as ``sun_direction``)."""
    return -sun_direction(azimuth_deg, elevation_deg, xp)


def check_sun_above_horizon(elevation_deg: float, minimum_deg: float = 0.5) -> None:
    """Raise SunBelowHorizonError when the sun is too low to cast a usable shadow."""
    if not np.isfinite(elevation_deg) or elevation_deg <= minimum_deg:
        raise SunBelowHorizonError(
            f"sun elevation {elevation_deg:.2f} deg is at or below the horizon "
            f"(minimum {minimum_deg} deg): no sun shadow to measure")
