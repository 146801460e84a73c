"""Camera pipeline and image files: sRGB, EXIF, 16-bit linear files, DNG, noise, optics, the printed board."""

from __future__ import annotations

import datetime as dt
import math
from zoneinfo import ZoneInfo

import cv2
import numpy as np
import pytest

from data_synth.camera_pipeline import SensorSettings, apply_optics, apply_sensor_noise, fit_handheld_camera
from softshadow import linear_to_srgb, srgb_to_linear
from data_synth.image_io import PhotoMetadata, bayer_mosaic, dng_available, write_corrupt_jpeg, write_photo
from data_synth.receivers import PlaneReceiver
from data_synth.textures import BoardSpec, GroundAppearance, board_object_to_world, procedural_texture
from data_synth.tracing import pinhole_rays, trace


def test_srgb_transfer_matches_the_standard_and_inverts():
    assert linear_to_srgb(np.array(0.5)) == pytest.approx(0.735357, abs=1e-5)
    assert linear_to_srgb(np.array(0.002)) == pytest.approx(0.02584, abs=1e-5)  # linear toe
    x = np.linspace(0, 1, 1001)
    assert np.allclose(srgb_to_linear(linear_to_srgb(x)), x, atol=1e-9)


def test_jpeg_exif_time_offset_and_gps_read_back(tmp_path):
    import piexif
    when = dt.datetime(2026, 4, 20, 13, 21, 7, tzinfo=ZoneInfo("Asia/Tokyo"))
    img = np.full((24, 32, 3), 0.3, np.float32)
    path = write_photo(tmp_path / "a.jpg", img, "jpg", 90, PhotoMetadata(when, 39.70, 141.13))
    exif = piexif.load(str(path))
    assert exif["Exif"][piexif.ExifIFD.DateTimeOriginal] == b"2026:04:20 13:21:07"
    assert exif["Exif"][piexif.ExifIFD.OffsetTimeOriginal] == b"+09:00"
    gps = exif["GPS"]

    def deg(dms):
        return sum(n / d / 60 ** i for i, (n, d) in enumerate(dms))
    assert gps[piexif.GPSIFD.GPSLatitudeRef] == b"N" and gps[piexif.GPSIFD.GPSLongitudeRef] == b"E"
    assert deg(gps[piexif.GPSIFD.GPSLatitude]) == pytest.approx(39.70, abs=1e-5)
    assert deg(gps[piexif.GPSIFD.GPSLongitude]) == pytest.approx(141.13, abs=1e-5)
    decoded = srgb_to_linear(cv2.imread(str(path))[..., ::-1] / 255.0)
    assert np.allclose(decoded, 0.3, atol=0.01)  # 8-bit sRGB of linear 0.3


def test_jpeg_without_time_has_no_date_tag(tmp_path):
    import piexif
    path = write_photo(tmp_path / "b.jpg", np.full((16, 16, 3), 0.5, np.float32), "jpg", 90, PhotoMetadata())
    exif = piexif.load(str(path))
    assert piexif.ExifIFD.DateTimeOriginal not in exif["Exif"]


def test_naive_time_is_refused(tmp_path):
    with pytest.raises(ValueError, match="UTC offset"):
        write_photo(tmp_path / "c.jpg", np.zeros((8, 8, 3)), "jpg", 90, PhotoMetadata(dt.datetime(2026, 4, 20)))


@pytest.mark.parametrize("fmt", ["tiff", "png"])
def test_16_bit_files_are_linear(tmp_path, fmt):
    rng = np.random.default_rng(0)
    img = rng.uniform(0, 1, (20, 30, 3)).astype(np.float32)
    path = write_photo(tmp_path / f"x.{fmt}", img, fmt)
    if fmt == "tiff":
        import tifffile
        back = tifffile.imread(path)
    else:
        back = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)[..., ::-1]
    assert back.dtype == np.uint16 and back.shape == img.shape
    assert np.max(np.abs(back / 65535.0 - img)) <= 0.5 / 65535 + 1e-7  # no gamma, only rounding


@pytest.mark.skipif(not dng_available(), reason="DNG output needs the optional 'pidng' package")
def test_dng_round_trip_through_rawpy(tmp_path):
    import rawpy
    img = np.full((40, 60, 3), 0.2, np.float32)
    img[:, 30:] = 0.5
    img[20:, :, 0] *= 0.7
    path = write_photo(tmp_path / "r.dng", img, "dng")
    with rawpy.imread(str(path)) as raw:
        assert np.array_equal(raw.raw_image_visible, bayer_mosaic(img))
        rgb = raw.postprocess(gamma=(1, 1), no_auto_bright=True, output_bps=16, use_camera_wb=True,
                              user_flip=0).astype(float) / 65535
    # Linear decode gives the linear image back (away from demosaicing at colour edges).
    assert np.allclose(rgb[5:15, 5:25], img[5:15, 5:25], atol=2e-3)
    assert np.allclose(rgb[25:35, 35:55], img[25:35, 35:55], atol=2e-3)


def test_corrupt_file_is_unreadable(tmp_path):
    path = write_corrupt_jpeg(tmp_path / "bad.jpg", np.full((32, 32, 3), 0.5))
    assert path.stat().st_size > 100
    assert cv2.imread(str(path)) is None


def test_poisson_gaussian_noise_has_the_model_variance():
    s = SensorSettings(full_well_e=2000.0, read_noise_e=10.0)
    rng = np.random.default_rng(1)
    for level in (0.05, 0.4):
        out = apply_sensor_noise(np.full((200, 200, 3), level, np.float32), s, rng)
        expected = level / s.full_well_e + (s.read_noise_e / s.full_well_e) ** 2
        assert out.mean() == pytest.approx(level, rel=0.01)
        assert out.var() == pytest.approx(expected, rel=0.05)


def test_vignetting_and_blur():
    s = SensorSettings(vignetting=0.3, blur_sigma_px=0.0)
    out = apply_optics(np.ones((101, 151, 3), np.float32), s)
    assert out[50, 75, 0] == pytest.approx(1.0)
    assert out[0, 0, 0] == pytest.approx(0.7, abs=1e-6)
    step = np.zeros((40, 40, 3), np.float32)
    step[:, 20:] = 1.0
    blurred = apply_optics(step, SensorSettings(vignetting=0.0, blur_sigma_px=1.5))
    assert blurred.mean() == pytest.approx(step.mean(), abs=1e-3)
    assert 0.1 < blurred[20, 19, 0] < 0.5 < blurred[20, 20, 0] < 0.9  # an edge spread over pixels


def test_printed_board_follows_the_project_convention():
    """Detect the ChArUco board in a rendered photo; the written camera must reproject its corners."""
    board = BoardSpec(origin_m=(-0.35, -0.7))
    ground = GroundAppearance(procedural_texture("concrete", np.random.default_rng(0), 256), board=board)
    keys = board.corners_world()
    cam = fit_handheld_camera(keys, 200.0, 1.2, 640, 480, margin=0.15)
    rays = pinhole_rays(cam)
    hits = trace(rays, None, PlaneReceiver())
    img = np.zeros((len(hits.kind), 3), np.float32)
    ok = hits.kind == 1
    img[ok] = ground.reflectance(hits.points[ok])
    img8 = np.round(linear_to_srgb(img.reshape(480, 640, 3)) * 255).astype(np.uint8)
    det = cv2.aruco.CharucoDetector(board.cv_board())
    corners, ids, marker_corners, marker_ids = det.detectBoard(img8)
    assert ids is not None and len(ids) >= 20
    world = board_object_to_world(board.cv_board().getChessboardCorners()[ids.ravel()], board.origin_m)
    uv, front = cam.project(world)
    assert front.all()
    err = np.linalg.norm(uv - corners.reshape(-1, 2), axis=1)
    # Sub-pixel agreement (one sample per pixel, no anti-aliasing); a wrong frame is off by squares.
    assert np.median(err) < 0.4 and err.max() < 1.5
    # Marker 0 is printed at the board's top-left, i.e. its north-west part on the ground.
    m0 = marker_corners[list(marker_ids.ravel()).index(0)].reshape(-1, 2).mean(0)
    g, _ = cam.ground_points(np.array([m0[0]]), np.array([m0[1]]))
    centre = keys.mean(0)
    assert g[0, 0] < centre[0] and g[0, 1] > centre[1]


def test_handheld_camera_frames_its_key_points():
    keys = np.array([[0, 0, 0], [3, 1, 0], [-1, 2, 0], [0.5, -1, 0]], float)
    cam = fit_handheld_camera(keys, 200.0, 1.6, 320, 240, margin=0.1)
    uv, front = cam.project(keys)
    assert front.all()
    assert np.all((uv[:, 0] > 31) & (uv[:, 0] < 288) & (uv[:, 1] > 23) & (uv[:, 1] < 216))
    # and tightly: one step closer would not frame them
    spread = max(np.ptp(uv[:, 0]) / 320, np.ptp(uv[:, 1]) / 240)
    assert spread > 0.6
    assert math.isclose(np.linalg.det(cam.R), 1.0, abs_tol=1e-9)
