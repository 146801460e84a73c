"""EXIF tags of a photo: capture time and focal length.

``read_exif`` (Pillow) returns a flat dict keyed by EXIF tag name (the standard's:
"DateTimeOriginal", "OffsetTimeOriginal", "FocalLength",
"FocalLengthIn35mmFilm", "Make", "Model", "Orientation", ...). Text comes as
str (trailing NULs and blanks stripped), rationals as float, short arrays as
tuples; binary blobs (MakerNote, thumbnails, strip offsets) are left out.
When the same name sits in two IFDs the Exif IFD wins over IFD0.
"""

from __future__ import annotations

import datetime as _dt
import re
import warnings

import numpy as np

__all__ = ["read_exif", "photo_time_from_exif", "intrinsics_from_exif", "FULL_FRAME_DIAGONAL_MM"]

# The 35 mm film frame is 36 x 24 mm; "35 mm equivalent" focal lengths are defined
# by the angle of view across its diagonal (CIPA DC-004 / common camera practice).
FULL_FRAME_DIAGONAL_MM = float(np.hypot(36.0, 24.0))

# FocalPlaneResolutionUnit -> millimetres per unit (1 = no unit; 2 = inch is the EXIF default).
_UNIT_MM = {2: 25.4, 3: 10.0, 4: 1.0, 5: 0.001}
_SKIP_TAGS = frozenset({"MakerNote", "UserComment", "PrintImageMatching", "StripOffsets",
                        "StripByteCounts", "TileOffsets", "TileByteCounts", "JPEGInterchangeFormat",
                        "JPEGInterchangeFormatLength", "XMLPacket", "InterColorProfile",
                        "ExifTag", "GPSTag", "InteroperabilityTag", "SubIFDs"})
_MAX_ITEMS = 64  # longer arrays are data, not tags worth keeping


# Pillow's names for three tags differ from the EXIF standard's (CIPA DC-008), which we keep.
_STANDARD_NAMES = {"ExifImageWidth": "PixelXDimension", "ExifImageHeight": "PixelYDimension",
                   "SubsecTimeOriginal": "SubSecTimeOriginal"}


def _plain(value):
    """A Pillow tag value as a plain Python value (str, int, float or a tuple of them), or
    None to leave it out (binary blobs, long arrays, unprintable text)."""
    if isinstance(value, bytes):
        value = value.rstrip(b"\x00").decode("utf-8", "replace") if len(value) <= 256 else None
    if isinstance(value, str):
        text = value.strip().rstrip("\x00").strip()
        return text if "\ufffd" not in text and all(ch.isprintable() for ch in text) else None
    if isinstance(value, tuple):
        items = [_plain(v) for v in value] if len(value) <= _MAX_ITEMS else [None]
        return None if any(v is None for v in items) else tuple(items)
    if isinstance(value, (int, float)):
        return value
    try:  # Pillow's IFDRational (a zero denominator reads as NaN: left out)
        number = float(value)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return number if np.isfinite(number) else None


def read_exif(path) -> dict:
    """EXIF tags by name (see the module docstring); an empty dict when the file has none.

    Read with Pillow: JPEG, TIFF (including TIFF-based RAW such as DNG, NEF, CR2, KDC), PNG
    eXIf chunks, WebP. Never raises on a damaged or non-image file: EXIF is optional, the
    image reader reports damage.
    """
    from PIL import ExifTags, Image
    out: dict = {}
    try:
        with warnings.catch_warnings():  # Pillow warns on damaged EXIF; damage is not fatal here
            warnings.simplefilter("ignore")
            with Image.open(path) as im:
                exif = im.getexif()
                sources = [(dict(exif), ExifTags.TAGS)]
                for ifd, names in ((ExifTags.IFD.GPSInfo, ExifTags.GPSTAGS), (ExifTags.IFD.Exif, ExifTags.TAGS)):
                    try:  # the Exif IFD last: it wins on names shared with IFD0
                        sources.append((dict(exif.get_ifd(ifd)), names))
                    except Exception:  # a damaged sub-IFD: keep the rest
                        continue
    except Exception:  # not an image Pillow knows, or damaged
        return {}
    for tags, names in sources:
        for tag, value in tags.items():
            name = names.get(tag)
            if name is None or name in _SKIP_TAGS:
                continue
            value = _plain(value)
            if value is not None and value != "":
                out[_STANDARD_NAMES.get(name, name)] = value
    return out


_EXIF_TIME = re.compile(r"^\s*(\d{4})[:\-](\d{2})[:\-](\d{2})[ T](\d{2}):(\d{2}):(\d{2})")
_OFFSET = re.compile(r"^\s*([+-])(\d{2}):?(\d{2})\s*$")


def photo_time_from_exif(exif: dict) -> _dt.datetime | None:
    """Capture time from DateTimeOriginal (+ SubSecTimeOriginal, OffsetTimeOriginal).

    With a valid OffsetTimeOriginal the result is time-zone aware; without one it
    is naive (the camera's local clock). None when the tag is absent, blank or not
    a real date (cameras write "0000:00:00 00:00:00" when the clock was not set).
    """
    text = exif.get("DateTimeOriginal")
    if not isinstance(text, str):
        return None
    m = _EXIF_TIME.match(text)
    if not m:
        return None
    try:
        when = _dt.datetime(*(int(g) for g in m.groups()))
    except ValueError:
        return None
    sub = str(exif.get("SubSecTimeOriginal", "")).strip()
    if sub.isdigit():
        when = when.replace(microsecond=int((sub + "000000")[:6]))
    offset = exif.get("OffsetTimeOriginal")
    if isinstance(offset, str):
        if offset.strip().upper() == "Z":
            return when.replace(tzinfo=_dt.UTC)
        om = _OFFSET.match(offset)
        if om:
            minutes = int(om.group(2)) * 60 + int(om.group(3))
            if minutes < 24 * 60:
                sign = -1 if om.group(1) == "-" else 1
                when = when.replace(tzinfo=_dt.timezone(_dt.timedelta(minutes=sign * minutes)))
    return when


def _positive(exif: dict, key: str) -> float | None:
    value = exif.get(key)
    try:
        value = float(value)
    except (TypeError, ValueError):
        return None
    return value if np.isfinite(value) and value > 0 else None


def intrinsics_from_exif(exif: dict, width: int, height: int,
                         sensor_width_mm: float | None = None) -> np.ndarray | None:
    """Pinhole K (3, 3), pixels, for an upright image of ``width`` x ``height``, or None.

    Focal length in pixels, first available of:
    1. FocalLength (mm) with ``sensor_width_mm`` (the sensor's long side, given by the caller);
    2. FocalLengthIn35mmFilm: f_px = f35 * image diagonal (px) / 43.27 mm (the full-frame
       diagonal; "35 mm equivalent" is defined by the diagonal angle of view);
    3. FocalLength with FocalPlaneXResolution / FocalPlaneResolutionUnit (pixels per unit
       on the sensor at the camera's full resolution, rescaled when the image was resized,
       judged from PixelXDimension/PixelYDimension).
    Square pixels, no skew, principal point at the image centre ((W - 1) / 2, (H - 1) / 2).
    """
    if width <= 0 or height <= 0:
        return None
    f_mm = _positive(exif, "FocalLength")
    f_px = None
    if f_mm is not None and sensor_width_mm is not None and sensor_width_mm > 0:
        f_px = f_mm * max(width, height) / sensor_width_mm
    if f_px is None:
        f35 = _positive(exif, "FocalLengthIn35mmFilm")
        if f35 is not None:
            f_px = f35 * float(np.hypot(width, height)) / FULL_FRAME_DIAGONAL_MM
    if f_px is None and f_mm is not None:
        xres = _positive(exif, "FocalPlaneXResolution")
        unit = exif.get("FocalPlaneResolutionUnit", 2)
        if xres is not None and unit in _UNIT_MM:
            px_per_mm = xres / _UNIT_MM[unit]
            full_w, full_h = _positive(exif, "PixelXDimension"), _positive(exif, "PixelYDimension")
            scale = max(width, height) / max(full_w, full_h) if full_w and full_h else 1.0
            f_px = f_mm * px_per_mm * scale
    if f_px is None:
        return None
    return np.array([[f_px, 0.0, (width - 1) / 2.0],
                     [0.0, f_px, (height - 1) / 2.0],
                     [0.0, 0.0, 1.0]])
