"""Photo reading: sRGB linearisation, 16-bit linear files, RAW, orientation, bad files,
folder listing, EXIF tags and times."""

from __future__ import annotations

import datetime as dt
import io
from pathlib import Path

import cv2
import numpy as np
import piexif
import pytest
import tifffile
from PIL import Image, ImageOps

from datapaths import WORKSPACE
from fitting.photos.exif import (FULL_FRAME_DIAGONAL_MM, intrinsics_from_exif, photo_time_from_exif,
                          read_exif)
from fitting.photos.read import (IMAGE_EXTENSIONS, RAW_EXTENSIONS, PhotoError, apply_orientation,
                            linear_to_srgb, list_photos, read_photo, srgb_to_linear)

# Real RAW files without a licence to copy them (../shared/data/raw, development workspace only).
RAW_DIR = WORKSPACE / "raw"
RAW_FILES = ["RAW_KODAK_DC50.KDC", "QT150_27.QTK"]


def _jpeg_bytes(rgb: np.ndarray, exif: dict | None = None, quality: int = 95) -> bytes:
    buf = io.BytesIO()
    kwargs = {"exif": piexif.dump(exif)} if exif else {}
    Image.fromarray(rgb).save(buf, format="JPEG", quality=quality, **kwargs)
    return buf.getvalue()


# ---------------------------------------------------------------- sRGB


def test_srgb_eotf_known_values():
    # IEC 61966-2-1 values: the knee, mid grey and the 8-bit code 128.
    enc = np.array([0.0, 0.04045, 0.5, 128 / 255, 1.0])
    expected = np.array([0.0, 0.04045 / 12.92, ((0.5 + 0.055) / 1.055) ** 2.4, 0.2158605001138992, 1.0])
    np.testing.assert_allclose(srgb_to_linear(enc), expected, rtol=1e-12, atol=1e-15)
    assert srgb_to_linear(0.5) == pytest.approx(0.21404114048223255, rel=1e-12)
    # Both branches meet at the knee (the piecewise curve is continuous), and it is monotone.
    assert 0.04045 / 12.92 == pytest.approx(((0.04045 + 0.055) / 1.055) ** 2.4, rel=1e-4)
    assert np.all(np.diff(srgb_to_linear(np.linspace(0, 1, 4097))) > 0)


def test_srgb_round_trip():
    x = np.linspace(0.0, 1.0, 10001)
    np.testing.assert_allclose(linear_to_srgb(srgb_to_linear(x)), x, atol=1e-12)
    np.testing.assert_allclose(srgb_to_linear(linear_to_srgb(x)), x, atol=1e-12)
    codes = np.arange(256)
    back = np.round(linear_to_srgb(srgb_to_linear(codes / 255.0)) * 255.0)
    np.testing.assert_array_equal(back, codes)


def test_8bit_png_is_linearised_exactly_per_code(tmp_path):
    codes = np.arange(256, dtype=np.uint8).reshape(16, 16)
    Image.fromarray(codes).save(tmp_path / "grey.png")
    photo = read_photo(tmp_path / "grey.png")
    assert photo.encoding == "srgb8" and photo.bit_depth == 8
    assert photo.linear.shape == (16, 16, 3) and photo.linear.dtype == np.float32
    exact = srgb_to_linear(codes / 255.0)
    np.testing.assert_allclose(photo.gray, exact, rtol=1e-6, atol=1e-9)
    for c in range(3):
        np.testing.assert_array_equal(photo.linear[..., c], photo.gray)
    np.testing.assert_array_equal(photo.saturated, codes == 255)


def test_rgb_png_channel_order_and_rec709_gray(tmp_path):
    rgb = np.zeros((2, 3, 3), dtype=np.uint8)
    rgb[0, 0] = (255, 0, 0)
    rgb[0, 1] = (0, 255, 0)
    rgb[0, 2] = (0, 0, 255)
    rgb[1, :] = (188, 188, 188)
    Image.fromarray(rgb).save(tmp_path / "rgb.png")
    photo = read_photo(tmp_path / "rgb.png")
    np.testing.assert_allclose(photo.gray[0], [0.2126, 0.7152, 0.0722], rtol=1e-6)
    np.testing.assert_allclose(photo.linear[0, 0], [1.0, 0.0, 0.0])
    np.testing.assert_allclose(photo.gray[1], srgb_to_linear(188 / 255), rtol=1e-5)
    np.testing.assert_array_equal(photo.saturated, [[True, True, True], [False, False, False]])


def test_16bit_png_is_linear_and_rgb_ordered(tmp_path):
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 65536, size=(12, 10, 3), dtype=np.uint16)
    rgb[0, 0] = (65535, 100, 200)
    assert cv2.imwrite(str(tmp_path / "lin.png"), rgb[..., ::-1])  # OpenCV writes BGR
    photo = read_photo(tmp_path / "lin.png")
    assert photo.encoding == "linear16" and photo.bit_depth == 16
    np.testing.assert_allclose(photo.linear, rgb / 65535.0, rtol=1e-6, atol=1e-9)
    assert photo.saturated[0, 0] and photo.saturated.sum() == np.any(rgb == 65535, axis=2).sum()
    # Declared sRGB-encoded 16-bit data goes through the EOTF instead.
    srgb = read_photo(tmp_path / "lin.png", assume_16bit="srgb")
    assert srgb.encoding == "srgb16"
    np.testing.assert_allclose(srgb.linear, srgb_to_linear(rgb / 65535.0), rtol=1e-5, atol=1e-8)
    grey = rgb[..., 1].copy()
    assert cv2.imwrite(str(tmp_path / "grey16.png"), grey)
    np.testing.assert_allclose(read_photo(tmp_path / "grey16.png").gray, grey / 65535.0, rtol=1e-6)


@pytest.mark.parametrize("layout", ["contig", "separate", "grey"])
def test_16bit_tiff_is_linear(tmp_path, layout):
    rng = np.random.default_rng(1)
    rgb = rng.integers(0, 65536, size=(9, 11, 3), dtype=np.uint16)
    path = tmp_path / "lin.tif"
    if layout == "contig":
        tifffile.imwrite(path, rgb, photometric="rgb")
        expected = rgb / 65535.0
    elif layout == "separate":
        tifffile.imwrite(path, np.moveaxis(rgb, -1, 0).copy(), photometric="rgb", planarconfig="separate")
        expected = rgb / 65535.0
    else:
        tifffile.imwrite(path, rgb[..., 0], photometric="minisblack")
        expected = np.repeat(rgb[..., :1], 3, axis=2) / 65535.0
    photo = read_photo(path)
    assert photo.encoding == "linear16" and photo.linear.shape == (9, 11, 3)
    np.testing.assert_allclose(photo.linear, expected, rtol=1e-6, atol=1e-9)


def test_8bit_tiff_is_srgb(tmp_path):
    codes = np.arange(256, dtype=np.uint8).reshape(16, 16)
    tifffile.imwrite(tmp_path / "g8.tiff", codes)
    photo = read_photo(tmp_path / "g8.tiff")
    assert photo.encoding == "srgb8"
    np.testing.assert_allclose(photo.gray, srgb_to_linear(codes / 255.0), rtol=1e-6)


def test_half_size_is_linear_2x2_mean(tmp_path):
    rng = np.random.default_rng(2)
    rgb = rng.integers(0, 256, size=(9, 12, 3), dtype=np.uint8)
    rgb[0, 0] = 255
    Image.fromarray(rgb).save(tmp_path / "x.png")
    full = read_photo(tmp_path / "x.png")
    half = read_photo(tmp_path / "x.png", half_size=True)
    assert half.linear.shape == (4, 6, 3)
    f = full.linear[:8]
    mean = 0.25 * (f[0::2, 0::2] + f[1::2, 0::2] + f[0::2, 1::2] + f[1::2, 1::2])
    np.testing.assert_allclose(half.linear, mean, rtol=1e-6)
    assert half.saturated[0, 0] and half.saturated.shape == (4, 6)


@pytest.mark.parametrize("orientation", range(1, 9))
def test_exif_orientation_matches_pillow(tmp_path, orientation):
    rng = np.random.default_rng(orientation)
    rgb = rng.integers(0, 256, size=(6, 10, 3), dtype=np.uint8)
    data = _jpeg_bytes(rgb, {"0th": {piexif.ImageIFD.Orientation: orientation}})
    (tmp_path / "o.jpg").write_bytes(data)
    photo = read_photo(tmp_path / "o.jpg")
    with Image.open(io.BytesIO(data)) as im:
        upright = np.asarray(ImageOps.exif_transpose(im))
    np.testing.assert_allclose(photo.linear, srgb_to_linear(upright / 255.0), rtol=1e-6)
    assert photo.exif["Orientation"] == orientation
    assert apply_orientation(rgb, orientation).shape[:2] == ((6, 10) if orientation < 5 else (10, 6))


# ---------------------------------------------------------------- RAW


def _raw_path(name: str) -> Path:
    path = RAW_DIR / name
    if not path.is_file():
        pytest.skip(f"real RAW test file {path} absent (only in the development workspace)")
    return path


@pytest.mark.parametrize("name", RAW_FILES)
def test_real_raw_decodes_linearly(name):
    import rawpy
    path = _raw_path(name)
    photo = read_photo(path, half_size=True)
    with rawpy.imread(str(path)) as raw:
        cfa = raw.raw_image_visible.astype(np.float64)
        black = float(np.mean(raw.black_level_per_channel))
        white = float(raw.white_level)
        sizes = raw.sizes
    with rawpy.imread(str(path)) as raw:  # rawpy's default display gamma (BT.709, ~1/2.2)
        gamma = raw.postprocess(no_auto_bright=True, use_camera_wb=True, output_bps=16,
                                half_size=True) / 65535.0
    assert photo.encoding == "raw" and photo.bit_depth == 16
    assert photo.linear.shape == (sizes.height // 2, sizes.width // 2, 3)
    assert np.all(np.isfinite(photo.linear)) and photo.linear.min() >= 0 and photo.linear.max() <= 1
    # Each half-size pixel comes from one 2x2 CFA block: a linear decode is proportional
    # to the block's raw signal (log-log slope 1), a gamma decode is not (slope ~0.6).
    h, w = cfa.shape[0] // 2 * 2, cfa.shape[1] // 2 * 2
    block = ((cfa[:h, :w] - black) / (white - black)).reshape(h // 2, 2, w // 2, 2).mean(axis=(1, 3))
    gamma_gray = gamma @ np.array([0.2126, 0.7152, 0.0722])
    ok = (~photo.saturated) & (block > 0.01) & (photo.gray > 0.005) & (gamma.max(axis=2) < 0.98)
    assert ok.mean() > 0.5
    slope_linear = np.polyfit(np.log(block[ok]), np.log(photo.gray[ok]), 1)[0]
    slope_gamma = np.polyfit(np.log(block[ok]), np.log(gamma_gray[ok]), 1)[0]
    assert 0.95 < slope_linear < 1.05
    assert slope_gamma < 0.8
    assert photo.gray.mean() < 0.8 * gamma_gray.mean()
    # Full size: the same radiometry at twice the resolution.
    full = read_photo(path)
    assert full.linear.shape == (sizes.height, sizes.width, 3)
    assert full.gray.mean() == pytest.approx(photo.gray.mean(), rel=0.02)


def test_truncated_raw_is_reported(tmp_path):
    path = _raw_path("RAW_KODAK_DC50.KDC")
    cut = tmp_path / "cut.kdc"
    cut.write_bytes(path.read_bytes()[:40000])
    with pytest.raises(PhotoError, match=r"^cut\.kdc: truncated or corrupt RAW"):
        read_photo(cut)


# Synthetic stand-in for the real RAW files (whose licences forbid copying them here): a DNG
# that data_synth writes from a known linear image (an RGGB mosaic, 16-bit, through pidng).

def _synthetic_dng(tmp_path) -> tuple[Path, np.ndarray]:
    from data_synth.image_io import write_photo
    rows, cols = np.mgrid[0:96, 0:128]
    level = 0.02 + 0.85 * (cols / 127.0) ** 1.5 * (0.6 + 0.4 * rows / 95.0)  # a smooth grey ramp
    img = np.repeat(level[..., None], 3, axis=2).astype(np.float32)
    return write_photo(tmp_path / "synthetic.dng", img, "dng"), level


def test_synthetic_dng_decodes_linearly(tmp_path):
    path, level = _synthetic_dng(tmp_path)
    photo = read_photo(path, half_size=True)
    assert photo.encoding == "raw" and photo.bit_depth == 16
    assert photo.linear.shape == (48, 64, 3)
    block = level.reshape(48, 2, 64, 2).mean(axis=(1, 3))
    ok = ~photo.saturated & (photo.gray > 0.005)
    assert ok.mean() > 0.9
    # Linear: proportional to the written radiometry (log-log slope 1); a display gamma reads ~0.45.
    slope = np.polyfit(np.log(block[ok]), np.log(photo.gray[ok]), 1)[0]
    assert 0.97 < slope < 1.03
    full = read_photo(path)
    assert full.linear.shape == (96, 128, 3)
    assert full.gray.mean() == pytest.approx(photo.gray.mean(), rel=0.02)


def test_truncated_synthetic_dng_is_reported(tmp_path):
    path, _ = _synthetic_dng(tmp_path)
    cut = tmp_path / "cut.dng"
    cut.write_bytes(path.read_bytes()[:4000])
    with pytest.raises(PhotoError, match=r"^cut\.dng: truncated or corrupt RAW"):
        read_photo(cut)


# ---------------------------------------------------------------- bad files


def test_truncated_jpeg(tmp_path):
    data = _jpeg_bytes(np.full((40, 60, 3), 90, np.uint8))
    (tmp_path / "cut.jpg").write_bytes(data[: len(data) // 2])
    with pytest.raises(PhotoError) as info:
        read_photo(tmp_path / "cut.jpg")
    assert str(info.value) == "cut.jpg: truncated JPEG"
    assert info.value.reason == "truncated JPEG"


def test_text_renamed_jpg(tmp_path):
    (tmp_path / "notes.jpg").write_text("this is not a photo\n")
    with pytest.raises(PhotoError, match=r"^notes\.jpg: not an image \(the file holds text\)$"):
        read_photo(tmp_path / "notes.jpg")
    (tmp_path / "blob.png").write_bytes(bytes(range(256)) * 4)
    with pytest.raises(PhotoError, match=r"^blob\.png: not an image \(content is not JPEG, PNG or TIFF\)$"):
        read_photo(tmp_path / "blob.png")
    (tmp_path / "notes.nef").write_text("hello\n")
    with pytest.raises(PhotoError, match=r"^notes\.nef: not an image"):
        read_photo(tmp_path / "notes.nef")


def test_garbage_behind_image_signatures(tmp_path):
    junk = bytes(range(256)) * 8
    (tmp_path / "g.jpg").write_bytes(b"\xff\xd8\xff\xe0" + junk)
    (tmp_path / "g.png").write_bytes(b"\x89PNG\r\n\x1a\n" + junk)
    (tmp_path / "g.tif").write_bytes(b"II*\x00" + junk)
    expected = {"g.jpg": "corrupt JPEG (no decodable image data)",
                "g.png": "corrupt PNG (no IHDR header)",
                "g.tif": "corrupt TIFF (no image in the file)"}
    for name, reason in expected.items():
        with pytest.raises(PhotoError) as info:
            read_photo(tmp_path / name)
        assert info.value.reason == reason and str(info.value) == f"{name}: {reason}"


def test_empty_missing_and_unsupported(tmp_path):
    (tmp_path / "empty.jpg").write_bytes(b"")
    with pytest.raises(PhotoError, match=r"^empty\.jpg: empty file \(0 bytes\)$"):
        read_photo(tmp_path / "empty.jpg")
    with pytest.raises(PhotoError, match=r"^gone\.png: file not found$"):
        read_photo(tmp_path / "gone.png")
    (tmp_path / "anim.gif").write_bytes(b"GIF89a")
    with pytest.raises(PhotoError, match=r"^anim\.gif: unsupported extension \.gif$"):
        read_photo(tmp_path / "anim.gif")


def test_truncated_png_and_tiff(tmp_path):
    rgb16 = np.random.default_rng(3).integers(0, 65536, size=(40, 40, 3), dtype=np.uint16)
    cv2.imwrite(str(tmp_path / "full16.png"), rgb16)
    data = (tmp_path / "full16.png").read_bytes()
    (tmp_path / "cut16.png").write_bytes(data[: len(data) // 2])
    with pytest.raises(PhotoError, match=r"^cut16\.png: truncated PNG$"):
        read_photo(tmp_path / "cut16.png")
    buf = io.BytesIO()
    Image.fromarray(rgb16[..., 0].astype(np.uint8)).save(buf, format="PNG")
    (tmp_path / "cut8.png").write_bytes(buf.getvalue()[: len(buf.getvalue()) // 2])
    with pytest.raises(PhotoError, match=r"^cut8\.png: truncated PNG$"):
        read_photo(tmp_path / "cut8.png")
    tifffile.imwrite(tmp_path / "full.tif", rgb16)
    data = (tmp_path / "full.tif").read_bytes()
    (tmp_path / "cut.tif").write_bytes(data[: len(data) // 2])
    with pytest.raises(PhotoError, match=r"^cut\.tif: truncated TIFF$"):
        read_photo(tmp_path / "cut.tif")


# ---------------------------------------------------------------- folders


def test_list_photos(tmp_path):
    for name in ["b.JPG", "a.png", "c.tiff", "d.NEF", "e.jpeg", "f.tif", "g.dng"]:
        (tmp_path / name).write_bytes(b"x")
    for name in ["scene.toml", "truth.json", "results.json", "README.md", "depth.npy", "post.obj",
                 "post.mtl", "bunny.ply", "part.STL", "pole.glb", ".DS_Store", ".hidden.jpg"]:
        (tmp_path / name).write_bytes(b"x")
    (tmp_path / "plots").mkdir()
    (tmp_path / "plots" / "inner.jpg").write_bytes(b"x")
    for name in ["notes.txt", "anim.gif", "Makefile"]:
        (tmp_path / name).write_bytes(b"x")
    photos, skipped = list_photos(tmp_path)
    assert [p.name for p in photos] == ["a.png", "b.JPG", "c.tiff", "d.NEF", "e.jpeg", "f.tif", "g.dng"]
    assert skipped == [("Makefile", "not an image (no extension)"),
                       ("anim.gif", "not an image (extension .gif)"),
                       ("notes.txt", "not an image (extension .txt)")]
    with pytest.raises(PhotoError, match="folder not found"):
        list_photos(tmp_path / "nowhere")


def test_extension_sets_follow_conventions():
    assert IMAGE_EXTENSIONS == {".jpg", ".jpeg", ".png", ".tif", ".tiff"}
    assert {".dng", ".nef", ".cr2", ".arw", ".orf", ".rw2", ".raf", ".pef"} <= RAW_EXTENSIONS
    assert not IMAGE_EXTENSIONS & RAW_EXTENSIONS


# ---------------------------------------------------------------- EXIF


def _exif_with_time(when: str, offset: str | None = None, subsec: str | None = None) -> dict:
    exif_ifd = {piexif.ExifIFD.DateTimeOriginal: when.encode(),
                piexif.ExifIFD.FocalLength: (50, 10),
                piexif.ExifIFD.FocalLengthIn35mmFilm: 28}
    if offset is not None:
        exif_ifd[piexif.ExifIFD.OffsetTimeOriginal] = offset.encode()
    if subsec is not None:
        exif_ifd[piexif.ExifIFD.SubSecTimeOriginal] = subsec.encode()
    return {"0th": {piexif.ImageIFD.Make: b"Acme\x00", piexif.ImageIFD.Model: b"Shadowcam 1"},
            "Exif": exif_ifd}


def test_exif_time_round_trip_jpeg(tmp_path):
    path = tmp_path / "t.jpg"
    path.write_bytes(_jpeg_bytes(np.full((8, 8, 3), 128, np.uint8),
                                 _exif_with_time("2026:04:20 09:20:05", "+09:00", "25")))
    exif = read_exif(path)
    assert exif["DateTimeOriginal"] == "2026:04:20 09:20:05"
    assert exif["OffsetTimeOriginal"] == "+09:00"
    assert exif["Make"] == "Acme" and exif["Model"] == "Shadowcam 1"
    assert exif["FocalLength"] == pytest.approx(5.0) and exif["FocalLengthIn35mmFilm"] == 28
    when = photo_time_from_exif(exif)
    tokyo = dt.timezone(dt.timedelta(hours=9))
    assert when == dt.datetime(2026, 4, 20, 9, 20, 5, 250000, tzinfo=tokyo)
    assert when.utcoffset() == dt.timedelta(hours=9)
    assert read_photo(path).exif["OffsetTimeOriginal"] == "+09:00"


def test_exif_time_without_offset_is_naive(tmp_path):
    path = tmp_path / "n.jpg"
    path.write_bytes(_jpeg_bytes(np.full((8, 8, 3), 128, np.uint8),
                                 _exif_with_time("2026:04:27 16:21:00")))
    when = photo_time_from_exif(read_exif(path))
    assert when == dt.datetime(2026, 4, 27, 16, 21, 0) and when.tzinfo is None
    assert photo_time_from_exif({"DateTimeOriginal": "2026:04:27 16:21:00",
                                 "OffsetTimeOriginal": "-05:30"}).utcoffset() == dt.timedelta(hours=-5, minutes=-30)


def test_exif_time_missing_or_unset():
    assert photo_time_from_exif({}) is None
    assert photo_time_from_exif({"DateTimeOriginal": "0000:00:00 00:00:00"}) is None
    assert photo_time_from_exif({"DateTimeOriginal": "    :  :     :  :  "}) is None
    # DateTime (file modification) is not a capture time.
    assert photo_time_from_exif({"DateTime": "2026:04:20 09:20:00"}) is None


def test_exif_from_png_via_pillow_and_none_from_plain_files(tmp_path):
    exif = Image.Exif()
    exif[0x010F] = "Acme"  # Make
    exif.get_ifd(0x8769)[0x9003] = "2026:04:20 13:21:00"  # Exif IFD: DateTimeOriginal
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(tmp_path / "e.png", exif=exif)
    tags = read_exif(tmp_path / "e.png")
    assert tags["Make"] == "Acme"
    assert photo_time_from_exif(tags) == dt.datetime(2026, 4, 20, 13, 21)
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(tmp_path / "plain.png")
    assert read_exif(tmp_path / "plain.png") == {}
    (tmp_path / "junk.jpg").write_text("no exif here")
    assert read_exif(tmp_path / "junk.jpg") == {}


def test_intrinsics_from_exif():
    # 35 mm equivalent on a 3:2 image: the 36 mm film width spans the image width.
    K = intrinsics_from_exif({"FocalLengthIn35mmFilm": 36}, 3000, 2000)
    np.testing.assert_allclose(K, [[3000, 0, 1499.5], [0, 3000, 999.5], [0, 0, 1]], rtol=1e-12)
    # On 4:3 the equivalent is defined by the diagonal.
    K43 = intrinsics_from_exif({"FocalLengthIn35mmFilm": 28}, 4000, 3000)
    assert K43[0, 0] == pytest.approx(28 * 5000 / FULL_FRAME_DIAGONAL_MM)
    # Focal length with the sensor's pixel density (2000 px per inch), image resized to half.
    tags = {"FocalLength": 10.0, "FocalPlaneXResolution": 2000.0, "FocalPlaneResolutionUnit": 2,
            "PixelXDimension": 4000, "PixelYDimension": 3000}
    assert intrinsics_from_exif(tags, 4000, 3000)[0, 0] == pytest.approx(10 * 2000 / 25.4)
    assert intrinsics_from_exif(tags, 2000, 1500)[0, 0] == pytest.approx(10 * 2000 / 25.4 / 2)
    assert intrinsics_from_exif(tags, 1500, 2000)[0, 0] == pytest.approx(10 * 2000 / 25.4 / 2)  # rotated
    # Focal length with a sensor width the caller knows (APS-C, 23.5 mm on the long side).
    K_sensor = intrinsics_from_exif({"FocalLength": 35.0}, 6000, 4000, sensor_width_mm=23.5)
    assert K_sensor[0, 0] == pytest.approx(35.0 * 6000 / 23.5)
    assert intrinsics_from_exif({"FocalLength": 35.0}, 6000, 4000) is None
    assert intrinsics_from_exif({}, 640, 480) is None
    assert intrinsics_from_exif({"FocalLengthIn35mmFilm": 0}, 640, 480) is None
