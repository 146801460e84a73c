"""A scene described wrongly: what ``scene.toml`` and the EXIF say, against what was rendered.

A user measures the object by hand, places it by eye, reads the sun off a chart or
sets the camera's clock badly. ``Misdescription`` holds those errors; ``synthesize``
renders the true scene and writes the described one, and records both in truth.json
(``misdescription``) so that a study can tell a misdescribed folder from a
well-described one.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import math

__all__ = ["Misdescription", "MISDESCRIPTION_KINDS"]

#: The kinds of error a study draws (``Misdescription.kind``); "lod" is a fit option, not a file error.
MISDESCRIPTION_KINDS = ("scale", "position", "sun", "clock")


@dataclasses.dataclass(frozen=True)
class Misdescription:
    """Errors in what the folder says about the scene (all zero: a well-described scene).

    scale_factor: the written [object] scale over the true one (1.05: said 5 % too large).
    position_offset_m: written minus true [object] position, metres (3,).
    sun_offset_deg: written minus true sun (azimuth, elevation) in degrees, for photos whose
        sun is written into scene.toml.
    clock_offset_s: written minus true shutter time in seconds (EXIF and scene.toml times).
    """

    scale_factor: float = 1.0
    position_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sun_offset_deg: tuple[float, float] = (0.0, 0.0)
    clock_offset_s: float = 0.0

    def __post_init__(self):
        if not (self.scale_factor > 0 and math.isfinite(self.scale_factor)):
            raise ValueError(f"scale_factor must be positive, got {self.scale_factor}")
        if len(self.position_offset_m) != 3 or len(self.sun_offset_deg) != 2:
            raise ValueError("position_offset_m takes 3 values and sun_offset_deg 2")

    @property
    def kinds(self) -> tuple[str, ...]:
        """The kinds of error present (a subset of MISDESCRIPTION_KINDS; empty when well described)."""
        out = []
        if self.scale_factor != 1.0:
            out.append("scale")
        if any(self.position_offset_m):
            out.append("position")
        if any(self.sun_offset_deg):
            out.append("sun")
        if self.clock_offset_s:
            out.append("clock")
        return tuple(out)

    def scale(self, true_scale: float) -> float:
        return float(true_scale) * self.scale_factor

    def position(self, true_position) -> tuple[float, float, float]:
        x, y, z = (float(a) + float(b) for a, b in zip(true_position, self.position_offset_m))
        return x, y, z

    def sun(self, azimuth_deg: float, elevation_deg: float) -> tuple[float, float]:
        return ((float(azimuth_deg) + self.sun_offset_deg[0]) % 360.0, float(elevation_deg) + self.sun_offset_deg[1])

    def time(self, when: _dt.datetime | None) -> _dt.datetime | None:
        if when is None or not self.clock_offset_s:
            return when
        return when + _dt.timedelta(seconds=float(self.clock_offset_s))

    def to_json(self) -> dict:
        return {"kinds": list(self.kinds), "scale_factor": self.scale_factor,
                "position_offset_m": list(self.position_offset_m), "sun_offset_deg": list(self.sun_offset_deg),
                "clock_offset_s": self.clock_offset_s}
