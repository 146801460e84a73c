"""Writing synthetic photos: sRGB JPEG with EXIF (piexif), 16-bit linear TIFF/PNG, optional DNG.

- JPEG: 8-bit sRGB, quality settable, EXIF DateTimeOriginal, OffsetTimeOriginal and GPS
  (written with piexif, encoded with Pillow).
- TIFF (tifffile) and PNG (OpenCV): 16-bit linear RGB, no gamma (docs/formats.md).
- DNG: an RGGB Bayer mosaic of the linear image, 16-bit, written with PiDNG (pidng on
  PyPI), which rawpy reads back; the camera colour matrix is the XYZ -> linear sRGB
  matrix, so the camera's RGB is linear sRGB and LibRaw's sRGB output is the input.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import io
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np

from softshadow import linear_to_srgb


__all__ = ["FORMATS", "EXTENSIONS", "PhotoMetadata", "exif_bytes", "write_photo", "write_corrupt_jpeg",
           "dng_available"]

FORMATS = ("jpg", "tiff", "png", "dng")
EXTENSIONS = {"jpg": ".jpg", "tiff": ".tiff", "png": ".png", "dng": ".dng"}

# XYZ (D65) -> linear sRGB (IEC 61966-2-1).
XYZ_TO_SRGB = np.array([[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]])


@dataclasses.dataclass(frozen=True)
class PhotoMetadata:
    """What goes into a JPEG's EXIF: aware local time (or None), GPS latitude/longitude (or None)."""

    time: _dt.datetime | None = None
    latitude: float | None = None
    longitude: float | None = None
    altitude_m: float | None = None
    make: str = "softshadow"
    model: str = "data_synth"
    focal_px: float | None = None  # the pinhole focal length in pixels, written as a camera would
    size: tuple[int, int] | None = None  # (width, height) in pixels, with focal_px


def _dms(value: float):
    """Degrees as EXIF rationals (deg, min, sec)."""
    value = abs(value)
    d = int(value)
    m = int((value - d) * 60)
    s = Fraction((value - d - m / 60) * 3600).limit_denominator(10000)
    return ((d, 1), (m, 1), (s.numerator, s.denominator))


def exif_bytes(meta: PhotoMetadata) -> bytes:
    """EXIF block with make/model, DateTimeOriginal + OffsetTimeOriginal and GPS (piexif)."""
    import piexif

    zeroth = {piexif.ImageIFD.Make: meta.make.encode(), piexif.ImageIFD.Model: meta.model.encode()}
    exif: dict = {}
    gps: dict = {}
    if meta.time is not None:
        if meta.time.tzinfo is None:
            raise ValueError("EXIF time needs a UTC offset (an aware datetime)")
        exif[piexif.ExifIFD.DateTimeOriginal] = meta.time.strftime("%Y:%m:%d %H:%M:%S").encode()
        off = meta.time.utcoffset()
        minutes = int(off.total_seconds() // 60)
        sign = "+" if minutes >= 0 else "-"
        exif[piexif.ExifIFD.OffsetTimeOriginal] = f"{sign}{abs(minutes) // 60:02d}:{abs(minutes) % 60:02d}".encode()
    if meta.focal_px is not None and meta.size is not None:
        # A 36 mm wide sensor across the image's long side: FocalLength in mm and the focal
        # plane's resolution in pixels per centimetre give the focal length in pixels back.
        px_per_mm = max(meta.size) / 36.0
        focal = Fraction(meta.focal_px / px_per_mm).limit_denominator(100000)
        res = Fraction(px_per_mm * 10.0).limit_denominator(100000)
        exif[piexif.ExifIFD.FocalLength] = (focal.numerator, focal.denominator)
        exif[piexif.ExifIFD.FocalPlaneXResolution] = (res.numerator, res.denominator)
        exif[piexif.ExifIFD.FocalPlaneYResolution] = (res.numerator, res.denominator)
        exif[piexif.ExifIFD.FocalPlaneResolutionUnit] = 3  # centimetres
        exif[piexif.ExifIFD.PixelXDimension] = int(meta.size[0])
        exif[piexif.ExifIFD.PixelYDimension] = int(meta.size[1])
    if meta.latitude is not None and meta.longitude is not None:
        gps[piexif.GPSIFD.GPSVersionID] = (2, 3, 0, 0)
        gps[piexif.GPSIFD.GPSLatitudeRef] = b"N" if meta.latitude >= 0 else b"S"
        gps[piexif.GPSIFD.GPSLatitude] = _dms(meta.latitude)
        gps[piexif.GPSIFD.GPSLongitudeRef] = b"E" if meta.longitude >= 0 else b"W"
        gps[piexif.GPSIFD.GPSLongitude] = _dms(meta.longitude)
        if meta.altitude_m is not None:
            gps[piexif.GPSIFD.GPSAltitudeRef] = 0 if meta.altitude_m >= 0 else 1
            gps[piexif.GPSIFD.GPSAltitude] = (int(round(abs(meta.altitude_m) * 100)), 100)
    return piexif.dump({"0th": zeroth, "Exif": exif, "GPS": gps, "1st": {}, "thumbnail": None})


def _to_uint16(linear: np.ndarray) -> np.ndarray:
    return np.round(np.clip(linear, 0.0, 1.0) * 65535.0).astype(np.uint16)


def dng_available() -> bool:
    """Whether the optional DNG writer (PiDNG, ``pip install pidng``) is installed."""
    import importlib.util
    return importlib.util.find_spec("pidng") is not None


def _write_dng(path: Path, linear: np.ndarray) -> None:
    try:
        from pidng.core import RAW2DNG, DNGTags, Tag
        from pidng.defs import CFAPattern, CalibrationIlluminant, DNGVersion, PhotometricInterpretation
    except ImportError as exc:
        raise RuntimeError("DNG output needs the 'pidng' package (pip install pidng)") from exc
    h, w = linear.shape[:2]
    if h % 2 or w % 2:
        raise ValueError(f"DNG output needs an even image size, got {w}x{h}")
    mosaic = bayer_mosaic(linear)
    tags = DNGTags()
    tags.set(Tag.ImageWidth, w)
    tags.set(Tag.ImageLength, h)
    tags.set(Tag.TileWidth, w)
    tags.set(Tag.TileLength, h)
    tags.set(Tag.PhotometricInterpretation, PhotometricInterpretation.Color_Filter_Array)
    tags.set(Tag.SamplesPerPixel, 1)
    tags.set(Tag.BitsPerSample, 16)
    tags.set(Tag.CFARepeatPatternDim, [2, 2])
    tags.set(Tag.CFAPattern, CFAPattern.RGGB)
    tags.set(Tag.BlackLevel, 0)
    tags.set(Tag.WhiteLevel, 65535)
    tags.set(Tag.ColorMatrix1, [[int(round(v * 10000)), 10000] for v in XYZ_TO_SRGB.ravel()])
    tags.set(Tag.CalibrationIlluminant1, CalibrationIlluminant.D65)
    tags.set(Tag.AsShotNeutral, [[1, 1], [1, 1], [1, 1]])
    tags.set(Tag.BaselineExposure, [[0, 1]])
    tags.set(Tag.Make, "softshadow")
    tags.set(Tag.Model, "data_synth")
    tags.set(Tag.DNGVersion, DNGVersion.V1_4)
    tags.set(Tag.DNGBackwardVersion, DNGVersion.V1_2)
    writer = RAW2DNG()
    writer.options(tags, path="", compress=False)
    # PiDNG appends ".dng" to the name it is given.
    writer.convert(mosaic, filename=str(path.with_suffix("")))


def bayer_mosaic(linear: np.ndarray) -> np.ndarray:
    """RGGB mosaic (H, W) uint16 of a linear RGB image (H, W, 3)."""
    q = _to_uint16(linear)
    out = np.empty(q.shape[:2], np.uint16)
    out[0::2, 0::2] = q[0::2, 0::2, 0]
    out[0::2, 1::2] = q[0::2, 1::2, 1]
    out[1::2, 0::2] = q[1::2, 0::2, 1]
    out[1::2, 1::2] = q[1::2, 1::2, 2]
    return out


def write_photo(path: str | Path, linear: np.ndarray, fmt: str, quality: int = 92,
                meta: PhotoMetadata | None = None) -> Path:
    """Write a linear RGB image (H, W, 3) in [0, 1] as ``fmt``; EXIF only in JPEGs."""
    path = Path(path)
    if fmt not in FORMATS:
        raise ValueError(f"unknown image format {fmt!r}; choose one of {FORMATS}")
    if fmt == "jpg":
        from PIL import Image
        if not 1 <= int(quality) <= 100:
            raise ValueError(f"JPEG quality must be 1..100, got {quality}")
        enc = np.round(linear_to_srgb(linear) * 255.0).astype(np.uint8)
        buf = io.BytesIO()
        kwargs = {"quality": int(quality)}
        if meta is not None:
            kwargs["exif"] = exif_bytes(meta)
        Image.fromarray(enc, "RGB").save(buf, "JPEG", **kwargs)
        path.write_bytes(buf.getvalue())
    elif fmt == "tiff":
        import tifffile
        tifffile.imwrite(path, _to_uint16(linear), photometric="rgb")
    elif fmt == "png":
        if not cv2.imwrite(str(path), cv2.cvtColor(_to_uint16(linear), cv2.COLOR_RGB2BGR)):
            raise OSError(f"cannot write {path}")
    else:
        _write_dng(path, linear)
    return path


def write_corrupt_jpeg(path: str | Path, linear: np.ndarray, quality: int = 92) -> Path:
    """A JPEG cut off inside its headers (before the scan), followed by junk: unreadable."""
    from PIL import Image
    enc = np.round(linear_to_srgb(linear) * 255.0).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(enc, "RGB").save(buf, "JPEG", quality=int(quality))
    data = buf.getvalue()
    sos = data.find(b"\xff\xda")  # start of scan: cut before it, so no decoder finds pixels
    cut = data[: sos if sos > 0 else 200]
    Path(path).write_bytes(cut + b"\x00corrupt\xff" * 8)
    return Path(path)
