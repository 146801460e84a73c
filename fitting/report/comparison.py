"""Matching fitted groups to references: the paper's Table 2, a truth.json, times of day.

Also the uncertainties in the paper's units (range = 100 k, brightness =
255 rho^(1/2.2)), propagated to first order. Shared by the report and the plots.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence

from softshadow import range_to_paper

from .results import GroupResult

__all__ = ["PAPER_TABLE2", "PAPER_TIME_TOLERANCE_MIN", "minutes_of_day", "nearest_paper_time",
           "reference_for_group", "truth_for_group", "groups_in_time_order", "range_stderr_paper",
           "brightness_stderr", "finite_or_none"]

#: The paper's hand-set Table 2 (seed 002, section 4.1): time -> (range, brightness),
#: in paper units (range = 100 k, brightness = 255 rho^(1/2.2)).
PAPER_TABLE2: dict[str, tuple[float, float]] = {
    "09:20": (6.0, 110.0), "13:21": (5.0, 120.0), "16:21": (8.0, 180.0)}

#: A group's time matches a reference time at most this far away (minutes).
PAPER_TIME_TOLERANCE_MIN = 30.0


_HHMM = re.compile(r"^\s*(\d{1,2}):(\d{2})(?::\d{2}(?:\.\d*)?)?\s*$")


def minutes_of_day(time_of_day: str | None) -> float | None:
    """'HH:MM' (or 'H:MM', 'HH:MM:SS') -> minutes since midnight; None if not a time."""
    if time_of_day is None:
        return None
    m = _HHMM.match(str(time_of_day))
    if m is None:
        return None
    hours, minutes = int(m.group(1)), int(m.group(2))
    if hours > 23 or minutes > 59:
        return None
    return hours * 60.0 + minutes


def nearest_paper_time(time_of_day: str | None, paper_times: Sequence[str] = tuple(PAPER_TABLE2),
                       tolerance_min: float = PAPER_TIME_TOLERANCE_MIN) -> str | None:
    """The entry of ``paper_times`` nearest to ``time_of_day`` ('HH:MM'), if within
    ``tolerance_min`` minutes; else None (also for a missing or unparsable time)."""
    here = minutes_of_day(time_of_day)
    if here is None:
        return None
    candidates = [(abs(minutes_of_day(t) - here), t) for t in paper_times if minutes_of_day(t) is not None]
    if not candidates:
        return None
    gap, best = min(candidates)
    return best if gap <= tolerance_min else None


def reference_for_group(group: GroupResult, reference: Mapping[str, tuple[float, float]] | None
                        ) -> tuple[float, float] | None:
    """The (range, brightness) reference for a group: by its label, else by the
    reference time nearest its time of day (within 30 minutes)."""
    if not reference:
        return None
    if group.label in reference:
        return reference[group.label]
    key = nearest_paper_time(group.time, tuple(reference))
    return None if key is None else reference[key]


def truth_for_group(group: GroupResult, truth: Mapping | None) -> dict | None:
    """The truth.json group for a result group: the one sharing most photos, else the
    one with the same label, else None."""
    if not truth:
        return None
    entries = [t for t in truth.get("groups", []) if isinstance(t, Mapping)]
    photos = set(group.photos)
    overlap = [(len(photos & set(t.get("photos") or [])), i) for i, t in enumerate(entries)]
    overlap = [o for o in overlap if o[0] > 0]
    if overlap:
        return dict(entries[max(overlap)[1]])
    same = [t for t in entries if t.get("label") == group.label]
    return dict(same[0]) if same else None


# --------------------------------------------------------------------------- uncertainty

def finite_or_none(x) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def range_stderr_paper(group: GroupResult) -> float | None:
    """One-sigma of ``range`` = 100 k in paper units."""
    s = finite_or_none(group.range_stderr)
    return None if s is None else float(range_to_paper(s))


def brightness_stderr(rho: float | None, rho_stderr: float | None) -> float | None:
    """One-sigma of brightness = 255 rho^(1/2.2), to first order:
    255/2.2 rho^(1/2.2 - 1) * stderr(rho). None where undefined (rho <= 0)."""
    rho, s = finite_or_none(rho), finite_or_none(rho_stderr)
    if rho is None or s is None or rho <= 0.0:
        return None
    return 255.0 / 2.2 * rho ** (1.0 / 2.2 - 1.0) * s


def groups_in_time_order(groups: Sequence[GroupResult]) -> list[GroupResult]:
    """Groups by time of day; groups without a parsable time keep their order, last."""
    keyed = [(0, minutes_of_day(g.time), i) if minutes_of_day(g.time) is not None else (1, 0.0, i)
             for i, g in enumerate(groups)]
    return [groups[i] for *_, i in sorted(keyed)]


