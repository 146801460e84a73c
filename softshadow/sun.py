"""Sun direction (differentiable) and solar position from time and site (NumPy/pvlib).

Frames follow CONVENTIONS: world x east, y north, z up; azimuth A clockwise
from north towards east, elevation E above the horizon, direction *to* the
sun s = (sin A cos E, cos A cos E, sin E); light travels along L = -s.
"""

from __future__ import annotations

import datetime as _dt

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

__all__ = ["sun_direction", "light_direction", "solar_position", "SunBelowHorizonError"]


class SunBelowHorizonError(ValueError):
    """The sun is at or below the horizon: there is no direct-sun shadow."""


def sun_direction(azimuth_deg, elevation_deg, xp=jnp) -> Float[Array, "3"]:
    """Unit vector towards the sun, shape (3,), from angles in degrees.

    xp: the array module, ``jax.numpy`` (differentiable) or ``numpy`` (for the discrete
    steps, which must not dispatch eager JAX ops)."""
    a = xp.deg2rad(azimuth_deg)
    e = xp.deg2rad(elevation_deg)
    return xp.stack([xp.sin(a) * xp.cos(e), xp.cos(a) * xp.cos(e), xp.sin(e)])


def light_direction(azimuth_deg, elevation_deg, xp=jnp) -> Float[Array, "3"]:
    """Unit direction the sunlight travels, L = -s, shape (3,) (xp as in ``sun_direction``)."""
    return -sun_direction(azimuth_deg, elevation_deg, xp)


def solar_position(time: _dt.datetime, latitude: float, longitude: float,
                   altitude_m: float = 0.0) -> tuple[float, float]:
    """Apparent sun (azimuth_deg, elevation_deg) for an aware datetime and site.

    Uses pvlib's NREL SPA (``method="nrel_numpy"``) with atmospheric refraction
    (apparent elevation), which is where shadows point. Raises ValueError for a
    naive datetime: local civil time without an offset is ambiguous.
    """
    import pandas as pd
    import pvlib

    if time.tzinfo is None:
        raise ValueError(f"time {time.isoformat()} has no UTC offset or time zone")
    index = pd.DatetimeIndex([pd.Timestamp(time)])
    pos = pvlib.solarposition.get_solarposition(
        index, latitude, longitude, altitude=altitude_m, method="nrel_numpy")
    return float(pos["azimuth"].iloc[0]), float(pos["apparent_elevation"].iloc[0])


def check_sun_above_horizon(elevation_deg: float, minimum_deg: float = 0.5) -> None:
    """Raise SunBelowHorizonError when the sun is too low to cast a usable shadow."""
    if not np.isfinite(elevation_deg) or elevation_deg <= minimum_deg:
        raise SunBelowHorizonError(
            f"sun elevation {elevation_deg:.2f} deg is at or below the horizon "
            f"(minimum {minimum_deg} deg): no sun shadow to measure")
