"""The light of a synthetic scene: a sun disk of finite angular radius plus a uniform sky.

Frames as in docs/formats.md: azimuth clockwise from north (+y) towards east
(+x), elevation above the horizon, direction to the sun
s = (sin A cos E, cos A cos E, sin E). Irradiances are in arbitrary linear
units (the sun's normal irradiance defaults to 1); only ratios matter.

Truth derived from the light (written to truth.json, see docs/data_synth.md):

- ``range_k = tan(radius)``: the geometric range of a sun disk of angular
  radius r with the ``edge`` rule (a linear-ramp fit reads about 0.854 of it);
- ``rho = E_sky / (E_sun_horizontal + E_sky)``: umbra over lit irradiance
  on open horizontal ground, direct light only (no interreflections).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

__all__ = ["SUN_RADIUS_DEG", "SunSky", "sun_vector", "limb_darkening_weight"]

SUN_RADIUS_DEG = 0.2665  # mean apparent angular radius of the sun's disk


def sun_vector(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """Unit vector (3,) towards the sun (NumPy twin of softshadow.sun.sun_direction)."""
    a, e = math.radians(azimuth_deg), math.radians(elevation_deg)
    return np.array([math.sin(a) * math.cos(e), math.cos(a) * math.cos(e), math.sin(e)])


@dataclasses.dataclass(frozen=True)
class SunSky:
    """Sun disk plus uniform sky.

    azimuth_deg, elevation_deg: the sun's centre (degrees).
    radius_deg: angular radius of the disk (0.2665 for the real sun; haze can be
        mimicked by a slightly larger disk).
    sun_normal_irradiance: irradiance of the whole disk on a surface facing it.
    sky_radiance: uniform radiance of the sky over the upper hemisphere
        (open horizontal ground receives pi * sky_radiance from it).
    limb_darkening: linear limb-darkening coefficient u, radiance
        L(mu) ~ 1 - u (1 - mu) across the disk (0 = uniform, ~0.6 in the visible).
    """

    azimuth_deg: float
    elevation_deg: float
    radius_deg: float = SUN_RADIUS_DEG
    sun_normal_irradiance: float = 1.0
    sky_radiance: float = 0.0
    limb_darkening: float = 0.0

    def __post_init__(self):
        if not (0.0 < self.radius_deg < 10.0):
            raise ValueError(f"sun radius must be in (0, 10) degrees, got {self.radius_deg}")
        if not (self.elevation_deg - self.radius_deg > 0.0 and self.elevation_deg <= 90.0):
            raise ValueError(f"the whole sun disk must be above the horizon: elevation "
                             f"{self.elevation_deg} deg with radius {self.radius_deg} deg")
        if not (self.sun_normal_irradiance > 0 and self.sky_radiance >= 0):
            raise ValueError("sun irradiance must be positive and sky radiance non-negative")
        if not (0.0 <= self.limb_darkening <= 1.0):
            raise ValueError(f"limb darkening must be in [0, 1], got {self.limb_darkening}")

    @classmethod
    def from_rho(cls, azimuth_deg: float, elevation_deg: float, rho: float,
                 radius_deg: float = SUN_RADIUS_DEG, limb_darkening: float = 0.0,
                 sun_normal_irradiance: float = 1.0) -> "SunSky":
        """The light whose open-ground umbra/lit ratio is ``rho`` (0 < rho < 1)."""
        if not (0.0 < rho < 1.0):
            raise ValueError(f"rho must be in (0, 1), got {rho}")
        e_sun_h = sun_normal_irradiance * math.sin(math.radians(elevation_deg))
        e_sky = rho / (1.0 - rho) * e_sun_h
        return cls(azimuth_deg, elevation_deg, radius_deg, sun_normal_irradiance,
                   e_sky / math.pi, limb_darkening)

    @property
    def direction(self) -> np.ndarray:
        """Unit vector (3,) towards the sun's centre."""
        return sun_vector(self.azimuth_deg, self.elevation_deg)

    @property
    def radius_rad(self) -> float:
        return math.radians(self.radius_deg)

    @property
    def sun_horizontal_irradiance(self) -> float:
        """Sun irradiance on open horizontal ground. Exact for a radially symmetric disk
        wholly above the horizon: the disk's cosine-weighted mean direction is its centre."""
        return self.sun_normal_irradiance * math.sin(math.radians(self.elevation_deg))

    @property
    def sky_horizontal_irradiance(self) -> float:
        """Sky irradiance on open horizontal ground, pi * L_sky."""
        return math.pi * self.sky_radiance

    @property
    def lit_irradiance(self) -> float:
        """Sun plus sky on open horizontal ground."""
        return self.sun_horizontal_irradiance + self.sky_horizontal_irradiance

    @property
    def rho(self) -> float:
        """Truth brightness: open-ground umbra over lit irradiance (direct light)."""
        return self.sky_horizontal_irradiance / self.lit_irradiance

    @property
    def range_k(self) -> float:
        """Truth range of the soft shadow: tan(sun radius) (the ``edge`` rule's geometric value)."""
        return math.tan(self.radius_rad)

    def truth(self) -> dict:
        """The physical truth of this light, JSON-ready."""
        return {
            "range_k": self.range_k,
            "rho": self.rho,
            "sun_azimuth_deg": float(self.azimuth_deg),
            "sun_elevation_deg": float(self.elevation_deg),
            "sun_radius_deg": float(self.radius_deg),
            "limb_darkening": float(self.limb_darkening),
            "sun_normal_irradiance": float(self.sun_normal_irradiance),
            "sun_horizontal_irradiance": self.sun_horizontal_irradiance,
            "sky_radiance": float(self.sky_radiance),
            "sky_horizontal_irradiance": self.sky_horizontal_irradiance,
        }


def limb_darkening_weight(rho_disk: np.ndarray, u: float) -> np.ndarray:
    """Relative radiance at fractional disk radius rho_disk in [0, 1], normalised to mean 1.

    L ~ 1 - u (1 - mu), mu = sqrt(1 - rho^2); the disk-area mean of mu is 2/3.
    """
    if u == 0.0:
        return np.ones_like(rho_disk)
    mu = np.sqrt(np.clip(1.0 - rho_disk ** 2, 0.0, 1.0))
    return (1.0 - u * (1.0 - mu)) / (1.0 - u / 3.0)
