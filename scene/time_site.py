"""Times and the site: when a photo was taken and where the sun stood (NumPy/pvlib).

Solar position comes from pvlib's NREL SPA (``method="nrel_numpy"``) with
atmospheric refraction, i.e. the apparent sun, which is where shadows point.
Angles follow the renderer's frame: azimuth clockwise from north (+y)
towards east (+x), elevation above the horizon, in degrees.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt

from .spec import SceneError, SceneSpec

__all__ = ["PhotoSun", "parse_time", "solar_position", "photo_sun"]


def parse_time(text: str, timezone: str | None = None) -> _dt.datetime:
    """ISO 8601 time; a naive time takes the site's time zone when one is given."""
    try:
        when = _dt.datetime.fromisoformat(str(text))
    except ValueError as exc:
        raise SceneError(f"cannot read time {text!r} (use ISO 8601, e.g. 2026-04-20T09:20:00+09:00)") from exc
    if when.tzinfo is None and timezone:
        from zoneinfo import ZoneInfo
        when = when.replace(tzinfo=ZoneInfo(timezone))
    return when


def solar_position(time: _dt.datetime, latitude: float, longitude: float,
                   altitude_m: float = 0.0) -> tuple[float, float]:
    """Apparent sun (azimuth_deg, elevation_deg) for an aware datetime and a site.

    Raises ValueError for a naive datetime: local civil time without an offset is ambiguous.
    """
    import pandas as pd
    import pvlib

    if time.tzinfo is None:
        raise ValueError(f"time {time.isoformat()} has no UTC offset or time zone")
    index = pd.DatetimeIndex([pd.Timestamp(time)])
    pos = pvlib.solarposition.get_solarposition(
        index, latitude, longitude, altitude=altitude_m, method="nrel_numpy")
    return float(pos["azimuth"].iloc[0]), float(pos["apparent_elevation"].iloc[0])


@dataclasses.dataclass(frozen=True)
class PhotoSun:
    """A photo's sun in degrees and where it came from: "given" (scene.toml) or "time+site"."""

    azimuth_deg: float
    elevation_deg: float
    source: str


def photo_sun(scene: SceneSpec, name: str, when: _dt.datetime | None) -> PhotoSun | None:
    """The sun of photo ``name``: given in scene.toml, else from its time and the site.

    None when neither is known (the fitter then fits the sun). A photo entry with only
    one of sun_azimuth_deg / sun_elevation_deg is a SceneError: half a sun is a typo,
    not an instruction.
    """
    spec = scene.photo(name)
    given = (spec.sun_azimuth_deg is not None, spec.sun_elevation_deg is not None)
    if given == (True, True):
        return PhotoSun(spec.sun_azimuth_deg, spec.sun_elevation_deg, "given")
    if any(given):
        have, missing = (("sun_azimuth_deg", "sun_elevation_deg") if given[0]
                         else ("sun_elevation_deg", "sun_azimuth_deg"))
        raise SceneError(f'[photos."{name}"] gives {have} without {missing}: give both, or neither '
                         "to take the sun from the time and [site]")
    if when is not None and scene.site is not None and when.tzinfo is not None:
        az, el = solar_position(when, scene.site.latitude, scene.site.longitude, scene.site.altitude_m)
        return PhotoSun(az, el, "time+site")
    return None
