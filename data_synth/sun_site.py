"""A site and a time at which the sun stands where a draw wants it (pvlib's NREL SPA).

A randomized study draws the sun (azimuth, elevation) and must still write an honest
folder: a site and a shutter time from which the fitter's solar position gives that
sun. ``site_and_time_for_sun`` inverts the horizontal coordinates of the sun for the
latitude and the hour angle on a drawn day, then corrects the target by what pvlib
actually gives (refraction, the equation of time) until the two agree.
"""

from __future__ import annotations

import datetime as _dt
import math
from zoneinfo import ZoneInfo

import numpy as np

from scene import solar_position

__all__ = ["site_and_time_for_sun", "fixed_offset_zone"]


def fixed_offset_zone(longitude: float) -> tuple[str, ZoneInfo]:
    """The whole-hour time zone of a longitude (``Etc/GMT-9`` is UTC+9: POSIX signs are reversed)."""
    hours = int(round(longitude / 15.0))
    name = "Etc/GMT" if hours == 0 else f"Etc/GMT{-hours:+d}"
    return name, ZoneInfo(name)


def _declination_deg(day_of_year: int) -> float:
    import pvlib
    return math.degrees(float(pvlib.solarposition.declination_spencer71(day_of_year)))


def _equation_of_time_min(day_of_year: int) -> float:
    import pvlib
    return float(pvlib.solarposition.equation_of_time_spencer71(day_of_year))


def _latitude_and_hour_angle(az: float, el: float, decl: float, rng: np.random.Generator):
    """(latitude, hour angle) in degrees with the sun at (az, el) for declination decl, or None.

    sin(decl) = sin(lat) sin(el) + cos(lat) cos(el) cos(az) = R sin(lat + psi); of the (up to
    two) latitudes within +-80 deg one is taken at random. The hour angle (positive in the
    afternoon) follows from cos(el) sin(az) = -cos(decl) sin(H) and
    cos(decl) cos(H) = sin(el) cos(lat) - cos(el) cos(az) sin(lat).
    """
    a, e, d = (math.radians(v) for v in (az, el, decl))
    p, q = math.sin(e), math.cos(e) * math.cos(a)
    r = math.hypot(p, q)
    if abs(math.sin(d)) > r:
        return None
    psi = math.atan2(q, p)
    base = math.asin(math.sin(d) / r)
    candidates = [base - psi, math.pi - base - psi]
    lats = []
    for lat in candidates:
        lat = (lat + math.pi) % (2 * math.pi) - math.pi
        if abs(math.degrees(lat)) <= 80.0:
            lats.append(lat)
    if not lats:
        return None
    lat = lats[int(rng.integers(len(lats)))]
    h = math.atan2(-math.cos(e) * math.sin(a), math.sin(e) * math.cos(lat) - math.cos(e) * math.cos(a) * math.sin(lat))
    return math.degrees(lat), math.degrees(h)


def site_and_time_for_sun(azimuth_deg: float, elevation_deg: float, rng: np.random.Generator, year: int = 2026,
                          tries: int = 200) -> tuple[dict, _dt.datetime, tuple[float, float]]:
    """(site, local aware time, (azimuth, elevation) that pvlib gives there) for a sun near the target.

    The day is drawn uniformly in ``year`` (redrawn while the target cannot be reached that
    day: a low sun due east needs a day near an equinox), the longitude uniformly; the time
    zone is the longitude's whole hour. Two corrections bring pvlib's apparent sun within
    about 0.05 deg of the target.
    """
    for _ in range(tries):
        day = int(rng.integers(1, 366))
        longitude = float(rng.uniform(-179.0, 179.0))
        decl = _declination_deg(day)
        target = np.array([azimuth_deg, elevation_deg], dtype=float)
        aim = target.copy()
        solved = None
        for _ in range(3):
            lat_h = _latitude_and_hour_angle(float(aim[0]), float(aim[1]), decl, rng)
            if lat_h is None:
                solved = None
                break
            latitude, hour_angle = lat_h
            # Apparent solar time 12 h + H / 15; UTC = solar time - longitude / 15 - equation of time.
            utc_hours = 12.0 + hour_angle / 15.0 - longitude / 15.0 - _equation_of_time_min(day) / 60.0
            start = _dt.datetime(year, 1, 1, tzinfo=_dt.UTC) + _dt.timedelta(days=day - 1)
            when_utc = start + _dt.timedelta(hours=utc_hours)
            zone_name, zone = fixed_offset_zone(longitude)
            when = when_utc.astimezone(zone).replace(microsecond=0)
            got = np.array(solar_position(when, latitude, longitude), dtype=float)
            solved = (latitude, when, got, zone_name)
            miss = target - got
            miss[0] = (miss[0] + 180.0) % 360.0 - 180.0
            if abs(miss[0]) * math.cos(math.radians(target[1])) < 0.05 and abs(miss[1]) < 0.05:
                break
            aim = aim + miss
            aim[1] = float(np.clip(aim[1], 0.5, 89.5))
        if solved is None:
            continue
        latitude, when, got, zone_name = solved
        site = {"latitude": round(float(latitude), 6), "longitude": round(longitude, 6), "timezone": zone_name}
        return site, when, (float(got[0]), float(got[1]))
    raise ValueError(f"no site and day found for a sun at azimuth {azimuth_deg:.1f}, elevation {elevation_deg:.1f}")
