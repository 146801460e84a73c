"""Reading photos into linear radiometry (docs/formats.md, "Photo folders").

8-bit JPEG/PNG/TIFF are sRGB-encoded and are linearised with the exact
piecewise sRGB EOTF; 16-bit PNG/TIFF are linear (unless the caller says they
are sRGB-encoded); camera RAW is decoded by LibRaw (rawpy) with camera white
balance, no gamma and no auto-brightening. Every reader returns a ``Photo``
whose ``linear`` image is scaled to [0, 1] of the encoding's full range, so
1.0 is the largest value the file can hold.

Decoders: Pillow for 8-bit images (it reports truncated JPEG/PNG data, where
OpenCV silently fills the missing rows), OpenCV for 16-bit PNG (Pillow
reduces 16-bit RGB PNG to 8 bits), tifffile for TIFF, rawpy for RAW. EXIF
orientation is applied to everything except RAW, which LibRaw already turns
upright.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Literal

import numpy as np

from softshadow import linear_to_srgb, srgb_to_linear

from .exif import read_exif
from .ignore_masks import is_auxiliary

__all__ = ["IMAGE_EXTENSIONS", "RAW_EXTENSIONS", "ALL_PHOTO_EXTENSIONS", "IGNORED_NAMES",
           "IGNORED_EXTENSIONS", "PhotoError", "Photo", "read_photo", "list_photos",
           "srgb_to_linear", "linear_to_srgb", "apply_orientation", "REC709_WEIGHTS"]

# Display-referred (or linear 16-bit) image files, lower case.
IMAGE_EXTENSIONS = frozenset({".jpg", ".jpeg", ".png", ".tif", ".tiff"})
# Camera RAW read with rawpy/LibRaw: the documented list first, then other
# formats LibRaw decodes (e.g. the Kodak .kdc and Apple QuickTake .qtk test files).
RAW_EXTENSIONS = frozenset({".dng", ".nef", ".cr2", ".arw", ".orf", ".rw2", ".raf", ".pef",
                            ".cr3", ".crw", ".nrw", ".srw", ".sr2", ".srf", ".x3f", ".3fr",
                            ".erf", ".mos", ".mrw", ".dcr", ".kdc", ".qtk", ".rwl", ".iiq"})
ALL_PHOTO_EXTENSIONS = IMAGE_EXTENSIONS | RAW_EXTENSIONS
# Files that belong in a photo folder but are not photos: ignored without a warning.
IGNORED_NAMES = frozenset({"scene.toml", "truth.json"})
IGNORED_EXTENSIONS = frozenset({".json", ".md", ".npy", ".obj", ".mtl", ".ply", ".stl", ".glb",
                                ".gltf", ".off", ".dae", ".3mf"})


# Linear-light luminance of Rec. 709 / sRGB primaries.
REC709_WEIGHTS = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)


class PhotoError(ValueError):
    """A photo that cannot be read. ``str(exc)`` is one line naming the file;
    ``exc.reason`` is the same reason without the file name (for ``skipped`` lists)."""

    def __init__(self, path, reason: str):
        self.path = Path(path)
        self.reason = reason
        super().__init__(f"{self.path.name}: {reason}")


@dataclasses.dataclass
class Photo:
    """A decoded photo.

    linear: (H, W, 3) float32, linear radiometry in [0, 1] of the encoding's range.
    gray: (H, W) float32, linear luminance (Rec. 709 weights; the channel itself for grey images).
    encoding: "srgb8", "srgb16" (16-bit declared sRGB), "linear16" or "raw".
    bit_depth: bits per sample in the file (8 or 16; RAW: 16, LibRaw's output depth).
    exif: EXIF tags by name (see ``fitting.photos.exif.read_exif``), empty when there are none.
    saturated: (H, W) bool, any channel at the encoding's maximum code value.
    ignore: (H, W) bool from the user's ignore mask (``fitting.photos.ignore_masks``), or None.
    decimation: pixels of the file per pixel of ``linear`` along each axis: 2 for a half-size
        read (pixel i covers the file's pixels 2i and 2i + 1), else 1. A camera given for the
        file's size is scaled by it (``fitting.folder.views.camera_view``).
    """

    name: str
    path: Path
    linear: np.ndarray
    gray: np.ndarray
    encoding: str
    bit_depth: int
    exif: dict
    saturated: np.ndarray
    ignore: np.ndarray | None = None
    decimation: int = 1

    @property
    def excluded(self) -> np.ndarray:
        """(H, W) bool: pixels never to measure (clipped, or in the ignore mask)."""
        return self.saturated if self.ignore is None else self.saturated | self.ignore

    @property
    def height(self) -> int:
        return int(self.linear.shape[0])

    @property
    def width(self) -> int:
        return int(self.linear.shape[1])


# Look-up tables: each code value linearised once, exactly.
_SRGB8_LUT = srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)
_SRGB16_LUT: np.ndarray | None = None


def _srgb16_lut() -> np.ndarray:
    global _SRGB16_LUT
    if _SRGB16_LUT is None:
        _SRGB16_LUT = srgb_to_linear(np.arange(65536) / 65535.0).astype(np.float32)
    return _SRGB16_LUT


def apply_orientation(image: np.ndarray, orientation) -> np.ndarray:
    """Turn an (H, W[, C]) array as stored into its upright view, per EXIF Orientation 1-8."""
    o = int(orientation) if orientation is not None else 1
    if o == 2:
        return image[:, ::-1]
    if o == 3:
        return image[::-1, ::-1]
    if o == 4:
        return image[::-1]
    if o == 5:
        return image.swapaxes(0, 1)
    if o == 6:
        return np.rot90(image, -1)
    if o == 7:
        return image[::-1, ::-1].swapaxes(0, 1)
    if o == 8:
        return np.rot90(image, 1)
    return image


def _sniff(head: bytes) -> str | None:
    """The container format from the file's first bytes, or None."""
    if head.startswith(b"\xff\xd8\xff"):
        return "jpeg"
    if head.startswith(b"\x89PNG\r\n\x1a\n"):
        return "png"
    if head[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
        return "tiff"
    return None


def _looks_like_text(head: bytes) -> bool:
    # A multi-byte character cut at the end of ``head`` decodes as a few U+FFFD.
    text = head.decode("utf-8", "replace")
    return bool(text) and text.count("\ufffd") <= 3 and all(
        ch.isprintable() or ch in "\r\n\t\ufffd" for ch in text)


def _check_file(path: Path) -> str:
    """Extension and size checks shared by all formats; returns the lower-case extension."""
    ext = path.suffix.lower()
    if ext not in ALL_PHOTO_EXTENSIONS:
        raise PhotoError(path, f"unsupported extension {ext or '(none)'}")
    if not path.exists():
        raise PhotoError(path, "file not found")
    if not path.is_file():
        raise PhotoError(path, "not a file")
    if path.stat().st_size == 0:
        raise PhotoError(path, "empty file (0 bytes)")
    return ext


def _read_pillow(path: Path, data: bytes, kind: str) -> np.ndarray:
    """8-bit images through Pillow, as stored (orientation not applied)."""
    from PIL import Image
    import io
    label = kind.upper()
    try:
        with Image.open(io.BytesIO(data)) as im:
            im.load()
            mode = im.mode
            if mode == "1":
                im = im.convert("L")
            elif mode in ("P", "PA"):
                im = im.convert("RGBA" if "transparency" in im.info or mode == "PA" else "RGB")
            elif mode == "CMYK" or mode == "YCbCr":
                im = im.convert("RGB")
            elif mode not in ("L", "LA", "RGB", "RGBA"):
                raise PhotoError(path, f"unsupported {label} pixel mode {mode}")
            return np.asarray(im)
    except PhotoError:
        raise
    except Image.UnidentifiedImageError as exc:
        raise PhotoError(path, f"corrupt {label} (no decodable image data)") from exc
    except OSError as exc:
        if "truncated" in str(exc).lower():
            raise PhotoError(path, f"truncated {label}") from exc
        raise PhotoError(path, f"corrupt {label} ({exc})") from exc
    except Exception as exc:  # Pillow raises assorted errors on damaged data
        raise PhotoError(path, f"corrupt {label} ({type(exc).__name__}: {exc})") from exc


def _png_bit_depth(data: bytes) -> int:
    # IHDR is the first chunk: 8-byte signature, 4 length, 4 type, 4 width, 4 height, 1 depth.
    return data[24] if len(data) > 24 else 8


def _read_png16(path: Path, data: bytes) -> np.ndarray:
    import cv2
    arr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if arr is None:
        if b"IEND" not in data[-64:]:
            raise PhotoError(path, "truncated PNG")
        raise PhotoError(path, "corrupt PNG (OpenCV could not decode it)")
    if arr.ndim == 3:  # OpenCV orders channels BGR(A)
        arr = arr[..., [2, 1, 0, 3][:arr.shape[2]]] if arr.shape[2] >= 3 else arr
    return arr


def _read_tiff(path: Path) -> np.ndarray:
    import tifffile
    try:
        with tifffile.TiffFile(path) as tif:
            if len(tif.pages) == 0:
                raise PhotoError(path, "corrupt TIFF (no image in the file)")
            page = tif.pages[0]
            arr = page.asarray()
            axes = page.axes
            photometric = int(page.photometric)
    except PhotoError:
        raise
    except Exception as exc:
        msg = str(exc)
        if "failed to read" in msg or "not enough data" in msg.lower() or isinstance(exc, EOFError):
            raise PhotoError(path, "truncated TIFF") from exc
        raise PhotoError(path, f"corrupt TIFF ({type(exc).__name__}: {msg})") from exc
    if axes.startswith("S") and arr.ndim == 3:  # planar configuration "separate"
        arr = np.moveaxis(arr, 0, -1)
    if arr.ndim not in (2, 3):
        raise PhotoError(path, f"unsupported TIFF layout (axes {axes}, shape {arr.shape})")
    if photometric == 0:  # MINISWHITE: 0 is white
        if arr.dtype.kind != "u":
            raise PhotoError(path, "unsupported TIFF (min-is-white with non-integer samples)")
        arr = np.iinfo(arr.dtype).max - arr
    elif photometric not in (1, 2):
        raise PhotoError(path, f"unsupported TIFF colour model (photometric {photometric}; "
                               "use grey or RGB)")
    return arr


def _libraw_message(exc: Exception) -> str:
    arg = exc.args[0] if exc.args else ""
    text = arg.decode("utf-8", "replace") if isinstance(arg, bytes) else str(arg)
    return text or type(exc).__name__


def _read_raw(path: Path, half_size: bool) -> np.ndarray:
    import rawpy
    with open(path, "rb") as fh:
        head = fh.read(512)
    if _looks_like_text(head):
        raise PhotoError(path, "not an image (the file holds text)")
    try:
        with rawpy.imread(str(path)) as raw:
            return raw.postprocess(gamma=(1, 1), no_auto_bright=True, use_camera_wb=True,
                                   output_bps=16, half_size=half_size)
    except rawpy.LibRawFileUnsupportedError as exc:
        raise PhotoError(path, "not a RAW image LibRaw can read") from exc
    except (rawpy.LibRawIOError, rawpy.LibRawDataError) as exc:
        raise PhotoError(path, f"truncated or corrupt RAW ({_libraw_message(exc)})") from exc
    except rawpy.LibRawError as exc:
        raise PhotoError(path, f"cannot decode RAW ({type(exc).__name__}: {_libraw_message(exc)})") from exc


def _half(x: np.ndarray) -> np.ndarray:
    """2x2 box mean (odd edge row/column dropped), shape (H//2, W//2, ...)."""
    h, w = x.shape[0] // 2 * 2, x.shape[1] // 2 * 2
    x = x[:h, :w]
    return 0.25 * (x[0::2, 0::2] + x[1::2, 0::2] + x[0::2, 1::2] + x[1::2, 1::2])


def read_photo(path, *, half_size: bool = False, assume_16bit: Literal["linear", "srgb"] = "linear") -> Photo:
    """Read one photo into linear radiometry.

    path: an image file (``IMAGE_EXTENSIONS`` or ``RAW_EXTENSIONS``).
    half_size: halve the resolution (RAW: LibRaw's half-size decode; other files:
        a 2x2 mean in linear units, the saturation mask or-ed over the 2x2 block); the
        photo's ``decimation`` is then 2, by which a camera given for the file is scaled.
    assume_16bit: "linear" (the documented default) or "srgb" for 16-bit PNG/TIFF.
    Raises PhotoError with a one-line reason naming the file.
    """
    path = Path(path)
    if assume_16bit not in ("linear", "srgb"):
        raise ValueError(f"assume_16bit must be 'linear' or 'srgb', got {assume_16bit!r}")
    ext = _check_file(path)
    exif = read_exif(path)

    if ext in RAW_EXTENSIONS:
        codes = _read_raw(path, half_size)
        encoding, bit_depth, orient = "raw", 16, None  # LibRaw already applies the flip
    else:
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise PhotoError(path, f"cannot read file ({exc.strerror or exc})") from exc
        kind = _sniff(data[:16])
        if kind is None:
            raise PhotoError(path, "not an image (the file holds text)" if _looks_like_text(data[:512])
                             else "not an image (content is not JPEG, PNG or TIFF)")
        if kind == "png" and data[12:16] != b"IHDR":
            raise PhotoError(path, "corrupt PNG (no IHDR header)")
        if kind == "tiff":
            codes = _read_tiff(path)
        elif kind == "png" and _png_bit_depth(data) == 16:
            codes = _read_png16(path, data)
        else:
            codes = _read_pillow(path, data, kind)
        orient = exif.get("Orientation")
        if codes.dtype == np.uint8:
            encoding, bit_depth = "srgb8", 8
        elif codes.dtype == np.uint16:
            encoding, bit_depth = ("linear16" if assume_16bit == "linear" else "srgb16"), 16
        else:
            raise PhotoError(path, f"unsupported sample type {codes.dtype} (use 8- or 16-bit integers)")

    if codes.ndim == 3 and codes.shape[2] in (2, 4):  # drop alpha
        codes = codes[..., : codes.shape[2] - 1]
    if codes.ndim == 3 and codes.shape[2] == 1:
        codes = codes[..., 0]
    if codes.ndim not in (2, 3) or (codes.ndim == 3 and codes.shape[2] != 3):
        raise PhotoError(path, f"unsupported image shape {codes.shape}")
    if codes.shape[0] == 0 or codes.shape[1] == 0:
        raise PhotoError(path, "image has no pixels")
    codes = np.ascontiguousarray(apply_orientation(codes, orient))

    max_code = 255 if codes.dtype == np.uint8 else 65535
    at_max = codes == max_code
    # Channel views, not .any(axis=2): a reduction over the last axis of (H, W, 3) is several times slower.
    saturated = (at_max[..., 0] | at_max[..., 1] | at_max[..., 2]) if codes.ndim == 3 else at_max
    if encoding == "srgb8":
        lin = _SRGB8_LUT[codes]
    elif encoding == "srgb16":
        lin = _srgb16_lut()[codes]
    else:
        lin = codes.astype(np.float32) / np.float32(max_code)

    if lin.ndim == 2:
        gray = lin
        lin = np.repeat(lin[..., None], 3, axis=2)
    else:
        wr, wg, wb = REC709_WEIGHTS
        gray = wr * lin[..., 0] + wg * lin[..., 1] + wb * lin[..., 2]
    if half_size and encoding != "raw":
        lin, gray = _half(lin), _half(gray)
        h, w = gray.shape
        s = saturated[: 2 * h, : 2 * w]
        saturated = s[0::2, 0::2] | s[1::2, 0::2] | s[0::2, 1::2] | s[1::2, 1::2]
    return Photo(name=path.name, path=path, linear=np.ascontiguousarray(lin, dtype=np.float32),
                 gray=np.ascontiguousarray(gray, dtype=np.float32), encoding=encoding,
                 bit_depth=bit_depth, exif=exif, saturated=np.ascontiguousarray(saturated),
                 decimation=2 if half_size else 1)


def list_photos(folder) -> tuple[list[Path], list[tuple[str, str]]]:
    """Photo files of a folder, sorted by name, and the other files skipped as (name, reason).

    Hidden files, sub-folders, scene.toml, truth.json, *.json, *.md, *.npy, ignore masks
    and range images (*.ignore.png, *.depth.png, *.depth.npy) and mesh
    files (.obj .mtl .ply .stl .glb .gltf .off .dae .3mf) belong in a photo folder and
    are ignored silently; any other file is skipped as "not an image (extension .xyz)".
    Raises PhotoError when the folder does not exist.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise PhotoError(folder, "not a folder" if folder.exists() else "folder not found")
    photos: list[Path] = []
    skipped: list[tuple[str, str]] = []
    for entry in sorted(folder.iterdir(), key=lambda p: p.name):
        name = entry.name
        if name.startswith(".") or not entry.is_file():
            continue
        ext = entry.suffix.lower()
        if name.lower() in IGNORED_NAMES or ext in IGNORED_EXTENSIONS or is_auxiliary(name):
            continue
        if ext in ALL_PHOTO_EXTENSIONS:
            photos.append(entry)
        else:
            skipped.append((name, f"not an image (extension {ext})" if ext
                            else "not an image (no extension)"))
    return photos, skipped
