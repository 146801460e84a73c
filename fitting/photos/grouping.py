"""Photo times and their grouping into times of day (docs/formats.md, "Photo folders").

A photo's time is its EXIF DateTimeOriginal (with OffsetTimeOriginal), else
the ``time`` of its scene.toml entry. Groups compare *local clock time of
day* and ignore the date: the paper's Table 2 puts photos of April 20 and
April 27 taken at the same hour into one column, as the sun is then nearly
in the same place. Times of day are not wrapped around midnight (shadows
are photographed in daylight).
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import math
from collections.abc import Mapping

from scene import SceneSpec, parse_time

from .exif import photo_time_from_exif

__all__ = ["PhotoGroup", "photo_time", "group_photos", "time_of_day_seconds", "NO_TIME_REASON"]

NO_TIME_REASON = "no time: no EXIF DateTimeOriginal and no time in scene.toml"


def photo_time(name: str, exif: Mapping, scene: SceneSpec | None) -> _dt.datetime | None:
    """The photo's capture time, or None when neither EXIF nor scene.toml gives one.

    EXIF first, else scene.toml ``[photos."name"].time``. With a site time zone in
    the scene, naive times are taken as the site's local time and aware times are
    converted to it, so ``.hour``/``.minute`` are the site's local civil time.
    Raises scene.SceneError for a scene time that is not ISO 8601.
    """
    tz_name = scene.site.timezone if scene is not None and scene.site is not None else None
    when = photo_time_from_exif(dict(exif or {}))
    if when is None and scene is not None:
        text = scene.photo(name).time
        if text is not None:
            when = parse_time(text, tz_name)
    if when is None or not tz_name:
        return when
    from zoneinfo import ZoneInfo
    zone = ZoneInfo(tz_name)
    return when.replace(tzinfo=zone) if when.tzinfo is None else when.astimezone(zone)


@dataclasses.dataclass
class PhotoGroup:
    """Photos of one time of day. label: group name; time: "HH:MM" local mean time of
    day, None when no member has a time; photos: file names, ordered by time then name."""

    label: str
    time: str | None
    photos: list[str]


def time_of_day_seconds(when: _dt.datetime) -> float:
    """Seconds since local midnight on the datetime's own clock (the date is ignored)."""
    return when.hour * 3600.0 + when.minute * 60.0 + when.second + when.microsecond * 1e-6


def _hhmm(seconds: float) -> str:
    minutes = int(math.floor(seconds / 60.0 + 0.5)) % (24 * 60)  # nearest minute, halves up
    return f"{minutes // 60:02d}:{minutes % 60:02d}"


def group_photos(times: Mapping[str, _dt.datetime | None],
                 explicit: Mapping[str, str] | None = None,
                 window_minutes: float = 20.0) -> tuple[list[PhotoGroup], list[tuple[str, str]]]:
    """Group photos into times of day.

    times: photo name -> capture time (None when unknown), e.g. from ``photo_time``.
    explicit: photo name -> group label from scene.toml ``group``; these photos form
        their groups whatever their times. Names absent from ``times`` are ignored.
    window_minutes: the remaining photos are sorted by time of day and a photo joins
        the previous one's group when it is at most this many minutes later (a chain,
        so a group may span more than the window).
    Returns (groups sorted by mean time of day, untimed groups last by label;
    skipped (name, reason) for photos with neither a time nor an explicit group).
    A time group is labelled with its "HH:MM" mean time of day; a label already taken
    gets a suffix "-2", "-3", ...
    """
    if not window_minutes >= 0:
        raise ValueError(f"window_minutes must be >= 0, got {window_minutes}")
    explicit = {name: str(label) for name, label in (explicit or {}).items() if name in times}
    tod = {name: time_of_day_seconds(t) for name, t in times.items() if t is not None}

    def order(name: str):
        return (tod.get(name, float("inf")), name)

    members: dict[str, list[str]] = {}
    for name, label in explicit.items():
        members.setdefault(label, []).append(name)
    labelled: list[tuple[str | None, list[str]]] = [(label, names) for label, names in members.items()]

    skipped: list[tuple[str, str]] = []
    chain: list[str] = []
    chains: list[list[str]] = []
    for name in sorted((n for n in times if n not in explicit), key=order):
        if name not in tod:
            skipped.append((name, NO_TIME_REASON))
            continue
        if chain and tod[name] - tod[chain[-1]] > window_minutes * 60.0:
            chains.append(chain)
            chain = []
        chain.append(name)
    if chain:
        chains.append(chain)
    labelled += [(None, c) for c in chains]

    groups: list[PhotoGroup] = []
    taken = set(members)
    for label, names in labelled:
        names = sorted(names, key=order)
        timed = [tod[n] for n in names if n in tod]
        mean = sum(timed) / len(timed) if timed else None
        hhmm = _hhmm(mean) if mean is not None else None
        if label is None:
            label, k = hhmm, 2
            while label in taken:
                label, k = f"{hhmm}-{k}", k + 1
            taken.add(label)
        groups.append(PhotoGroup(label=label, time=hhmm, photos=names))

    def group_order(g: PhotoGroup):
        timed = [tod[n] for n in g.photos if n in tod]
        return (0, sum(timed) / len(timed), g.label) if timed else (1, 0.0, g.label)

    groups.sort(key=group_order)
    return groups, sorted(skipped)
