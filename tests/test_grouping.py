"""Photo times (EXIF, else scene.toml) and grouping into times of day."""

from __future__ import annotations

import datetime as dt
from zoneinfo import ZoneInfo

import pytest

from fitting.photos.grouping import NO_TIME_REASON, PhotoGroup, group_photos, photo_time
from scene import SceneError, scene_from_dict

JST = dt.timezone(dt.timedelta(hours=9))


def _scene(timezone="Asia/Tokyo", photos=None):
    data = {"object": {"mesh": "pillar"}, "photos": photos or {}}
    if timezone is not False:
        data["site"] = {"latitude": 39.70, "longitude": 141.13}
        if timezone:
            data["site"]["timezone"] = timezone
    return scene_from_dict(data)


# ---------------------------------------------------------------- photo_time


def test_exif_time_wins_over_scene_time():
    scene = _scene(photos={"a.jpg": {"time": "2026-04-20T13:21:00+09:00"}})
    exif = {"DateTimeOriginal": "2026:04:20 09:20:00", "OffsetTimeOriginal": "+09:00"}
    assert photo_time("a.jpg", exif, scene) == dt.datetime(2026, 4, 20, 9, 20, tzinfo=JST)


def test_scene_time_when_no_exif():
    scene = _scene(photos={"a.jpg": {"time": "2026-04-20T13:21:00"}})
    when = photo_time("a.jpg", {}, scene)
    assert when == dt.datetime(2026, 4, 20, 13, 21, tzinfo=ZoneInfo("Asia/Tokyo"))
    assert when.utcoffset() == dt.timedelta(hours=9)
    assert photo_time("other.jpg", {}, scene) is None
    assert photo_time("a.jpg", {}, None) is None


def test_naive_exif_time_takes_site_timezone_or_stays_naive():
    exif = {"DateTimeOriginal": "2026:04:20 16:21:00"}
    with_tz = photo_time("a.jpg", exif, _scene())
    assert (with_tz.hour, with_tz.minute) == (16, 21)
    assert with_tz.utcoffset() == dt.timedelta(hours=9)
    naive = photo_time("a.jpg", exif, _scene(timezone=None))
    assert naive == dt.datetime(2026, 4, 20, 16, 21) and naive.tzinfo is None
    assert photo_time("a.jpg", exif, None).tzinfo is None


def test_aware_time_is_converted_to_site_local_clock():
    # A camera left on UTC: 00:20 UTC is 09:20 in Iwate; the time of day is the site's.
    exif = {"DateTimeOriginal": "2026:04:20 00:20:00", "OffsetTimeOriginal": "+00:00"}
    when = photo_time("a.jpg", exif, _scene())
    assert (when.hour, when.minute) == (9, 20)
    assert when == dt.datetime(2026, 4, 20, 0, 20, tzinfo=dt.UTC)


def test_bad_scene_time_names_it():
    scene = _scene(photos={"a.jpg": {"time": "twenty past nine"}})
    with pytest.raises(SceneError, match="twenty past nine"):
        photo_time("a.jpg", {}, scene)


# ---------------------------------------------------------------- group_photos


def _t(day, hh, mm, ss=0):
    return dt.datetime(2026, 4, day, hh, mm, ss, tzinfo=JST)


def test_chain_joins_across_more_than_one_window():
    # Each step is 15 min (< 20): one chain spanning 45 min; then a 21-minute gap.
    times = {"a": _t(20, 9, 0), "b": _t(20, 9, 15), "c": _t(20, 9, 30), "d": _t(20, 9, 45),
             "e": _t(20, 10, 6)}
    groups, skipped = group_photos(times)
    assert skipped == []
    assert [g.photos for g in groups] == [["a", "b", "c", "d"], ["e"]]
    assert groups[0] == PhotoGroup(label="09:23", time="09:23", photos=["a", "b", "c", "d"])
    assert groups[1].label == "10:06"


def test_window_boundary_is_inclusive_and_configurable():
    times = {"a": _t(20, 9, 0), "b": _t(20, 9, 20)}
    assert len(group_photos(times)[0]) == 1
    assert len(group_photos(times, window_minutes=19.9)[0]) == 2
    assert len(group_photos({"a": _t(20, 9, 0), "b": _t(20, 9, 20, 1)})[0]) == 2


def test_same_time_of_day_on_different_dates_is_one_group():
    # The paper pools April 20 and April 27 at each time of day.
    times = {"a20": _t(20, 9, 18), "a27": _t(27, 9, 22), "b20": _t(20, 13, 21),
             "c27": _t(27, 16, 21), "c20": _t(20, 16, 19)}
    groups, _ = group_photos(times)
    assert [(g.label, g.photos) for g in groups] == [("09:20", ["a20", "a27"]), ("13:21", ["b20"]),
                                                     ("16:20", ["c20", "c27"])]


def test_explicit_groups_override_time():
    times = {"a": _t(20, 9, 20), "b": _t(20, 9, 25), "c": _t(20, 13, 0), "d": None}
    groups, skipped = group_photos(times, explicit={"b": "afternoon", "c": "afternoon", "d": "noon",
                                                     "not_a_photo": "x"})
    by_label = {g.label: g for g in groups}
    assert set(by_label) == {"09:20", "afternoon", "noon"}
    assert by_label["afternoon"].photos == ["b", "c"]
    assert by_label["afternoon"].time == "11:13"  # mean of 09:25 and 13:00 is 11:12:30, halves round up
    assert by_label["noon"].photos == ["d"] and by_label["noon"].time is None
    assert by_label["09:20"].photos == ["a"]
    assert [g.label for g in groups] == ["09:20", "afternoon", "noon"]  # untimed last
    assert skipped == []


def test_missing_times_are_skipped_with_reason():
    groups, skipped = group_photos({"a": _t(20, 9, 20), "z": None, "m": None})
    assert [g.photos for g in groups] == [["a"]]
    assert skipped == [("m", NO_TIME_REASON), ("z", NO_TIME_REASON)]
    assert NO_TIME_REASON == "no time: no EXIF DateTimeOriginal and no time in scene.toml"
    assert group_photos({}) == ([], [])


def test_label_collisions_are_disambiguated():
    # An explicit label "09:20" and a time group at 09:20.
    groups, _ = group_photos({"a": _t(20, 9, 20), "b": _t(20, 13, 0)}, explicit={"b": "09:20"})
    assert sorted(g.label for g in groups) == ["09:20", "09:20-2"]
    assert next(g for g in groups if g.label == "09:20").photos == ["b"]
    # Two time groups that round to the same minute with a tiny window.
    groups, _ = group_photos({"a": _t(20, 9, 20, 0), "b": _t(20, 9, 20, 50)}, window_minutes=0.5)
    assert [g.label for g in groups] == ["09:20", "09:21"]
    groups, _ = group_photos({"a": _t(20, 9, 20, 10), "b": _t(20, 9, 20, 29)}, window_minutes=0.1)
    assert [g.label for g in groups] == ["09:20", "09:20-2"] and [g.time for g in groups] == ["09:20", "09:20"]


def test_mixed_naive_and_aware_use_their_own_clocks():
    times = {"a": dt.datetime(2026, 4, 20, 9, 20), "b": _t(27, 9, 25)}
    groups, _ = group_photos(times)
    assert [g.photos for g in groups] == [["a", "b"]]


def test_negative_window_rejected():
    with pytest.raises(ValueError, match="window_minutes"):
        group_photos({"a": _t(20, 9, 0)}, window_minutes=-1)
