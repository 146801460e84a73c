"""EXIF tags of a photo: capture time and focal length.

``read_exif`` returns a flat dict keyed by EXIF tag name (as in piexif/Pillow:
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
from pathlib import Path

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


def _text(value: bytes) -> str | None:
    text = value.rstrip(b"\x00").decode("utf-8", "replace").strip().rstrip("\x00").strip()
    if "\ufffd" in text or not all(ch.isprintable() for ch in text):
        return None
    return text


def _rational(pair) -> float | None:
    num, den = pair
    return float(num) / float(den) if den else None


def _convert(value, tag_type: int | None):
    """A piexif/Pillow tag value as a plain Python value, or None to leave it out."""
    if isinstance(value, bytes):
        return _text(value) if len(value) <= 256 else None
    if isinstance(value, str):
        return value.rstrip("\x00").strip()
    if tag_type in (5, 10):  # RATIONAL / SRATIONAL: (num, den) or a tuple of them
        if len(value) == 2 and all(isinstance(v, int) for v in value):
            return _rational(value)
        if len(value) > _MAX_ITEMS:
            return None
        items = [_rational(v) for v in value]
        return None if any(v is None for v in items) else tuple(items)
    if isinstance(value, tuple):
        if len(value) > _MAX_ITEMS:
            return None
        items = [_convert(v, None) for v in value]
        return None if any(v is None for v in items) else tuple(items)
    if isinstance(value, (int, float)):
        return value
    try:  # Pillow's IFDRational and friends
        return float(value)
    except (TypeError, ValueError):
        return None


def _from_piexif(path: Path) -> dict:
    import piexif
    data = piexif.load(str(path))
    out: dict = {}
    for ifd in ("0th", "GPS", "Interop", "Exif"):  # Exif last: it wins on shared names
        for tag, value in (data.get(ifd) or {}).items():
            info = piexif.TAGS.get(ifd, {}).get(tag)
            if info is None or info["name"] in _SKIP_TAGS:
                continue
            converted = _convert(value, info["type"])
            if converted is not None and converted != "":
                out[info["name"]] = converted
    return out


def _from_pillow(path: Path) -> dict:
    from PIL import ExifTags, Image
    out: dict = {}
    with Image.open(path) as im:
        exif = im.getexif()
        sources = [(dict(exif), ExifTags.TAGS)]
        for ifd, names in ((ExifTags.IFD.GPSInfo, ExifTags.GPSTAGS), (ExifTags.IFD.Exif, ExifTags.TAGS)):
            try:
                sources.append((dict(exif.get_ifd(ifd)), names))
            except Exception:  # a damaged sub-IFD: keep what IFD0 gave
                continue
    for tags, names in sources:
        for tag, value in tags.items():
            name = names.get(tag)
            if name is None or name in _SKIP_TAGS:
                continue
            converted = _convert(value, None)
            if converted is not None and converted != "":
                out[name] = converted
    return out


def read_exif(path) -> dict:
    """EXIF tags by name (see the module docstring); an empty dict when the file has none.

    piexif reads JPEG and TIFF (including TIFF-based RAW such as DNG, NEF, CR2, KDC);
    Pillow is the fallback (PNG eXIf chunks and anything piexif refuses). Never raises
    on a damaged or non-image file: EXIF is optional, the image reader reports damage.
    """
    path = Path(path)
    for reader in (_from_piexif, _from_pillow):
        try:
            with warnings.catch_warnings():  # Pillow warns on damaged EXIF; damage is not fatal here
                warnings.simplefilter("ignore")
                tags = reader(path)
        except Exception:  # not an EXIF container for this reader, or damaged
            continue
        if tags:
            return tags
    return {}


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
            return when.replace(tzinfo=_dt.timezone.utc)
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
