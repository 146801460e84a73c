"""ChArUco registration against rendered views of a board lying on the ground.

The renderer here writes the board convention out independently of fitting.photos.markers:
board-image pixel (c, r), at ``PPM`` pixels per metre, has its centre at board point
((c + 0.5) / PPM, (r + 0.5) / PPM), which lies at world (ox + x, oy - y, 0); the
homography K [r1 r2 t] maps that ground point into the camera image.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from fitting.photos.markers import (Registration, RegistrationError, board_from_spec, board_outline_world,
                             board_world_points, marker_world_points, register_board)
from fitting.photos.read import srgb_to_linear
from softshadow.camera import look_at_camera
from scene import CameraSpec

PPM = 1000  # board image pixels per metre: 0.1 m squares are 100 px
SPEC = CameraSpec(kind="markers", origin_m=(-0.35, 0.25))  # default 7x5 DICT_4X4_50 board, centred on 0


def board_image(spec: CameraSpec = SPEC) -> np.ndarray:
    board = board_from_spec(spec)
    size = (int(round(spec.squares[0] * spec.square_m * PPM)), int(round(spec.squares[1] * spec.square_m * PPM)))
    return board.generateImage(size, marginSize=0)


def render_view(camera, image: np.ndarray, spec: CameraSpec = SPEC, supersample: int = 4,
                ground: int = 110) -> np.ndarray:
    """8-bit view of the board image lying on the ground, anti-aliased by supersampling."""
    ox, oy = spec.origin_m
    board_to_ground = np.array([[1 / PPM, 0, ox + 0.5 / PPM], [0, -1 / PPM, oy - 0.5 / PPM], [0, 0, 1]])
    ground_to_image = camera.K @ np.column_stack([camera.R[:, 0], camera.R[:, 1], camera.t])
    s = supersample
    up = np.array([[s, 0, (s - 1) / 2], [0, s, (s - 1) / 2], [0, 0, 1.0]])  # pixel centres kept
    big = cv2.warpPerspective(image, up @ ground_to_image @ board_to_ground,
                              (camera.width * s, camera.height * s), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=ground)
    return cv2.resize(big, (camera.width, camera.height), interpolation=cv2.INTER_AREA)


def rotation_error_deg(R1, R2) -> float:
    cos = (np.trace(np.asarray(R1) @ np.asarray(R2).T) - 1) / 2
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


OBLIQUE = look_at_camera((0.9, -0.8, 0.9), (0.0, 0.0, 0.0), 640, 480, 60.0)
FROM_NORTH_WEST = look_at_camera((-0.6, 1.1, 1.0), (0.05, -0.05, 0.0), 800, 600, 50.0)


# ---------------------------------------------------------------- convention


def test_board_world_points_follow_the_convention():
    # Corner 0 is one square right of and one square down from the board's top-left
    # corner: east and south of origin_m on the ground.
    pts = board_world_points(SPEC, [0, 1, 6, 23])
    np.testing.assert_allclose(pts, [[-0.25, 0.15, 0], [-0.15, 0.15, 0], [-0.25, 0.05, 0],
                                     [0.25, -0.15, 0]], atol=1e-9)
    outline = board_outline_world(SPEC)
    np.testing.assert_allclose(outline, [[-0.35, 0.25, 0], [0.35, 0.25, 0], [0.35, -0.25, 0],
                                         [-0.35, -0.25, 0]], atol=1e-12)
    # Marker 0 sits in the first white square of the top row (board x 0.1..0.2 m).
    m0 = marker_world_points(SPEC, [0])[0]
    np.testing.assert_allclose(m0[0], [-0.35 + 0.1125, 0.25 - 0.0125, 0], atol=1e-6)
    np.testing.assert_allclose(m0[2], [-0.35 + 0.1875, 0.25 - 0.0875, 0], atol=1e-6)
    with pytest.raises(RegistrationError, match="ids"):
        board_world_points(SPEC, [24])


def test_board_spec_validation():
    board = board_from_spec(SPEC)
    assert board.getChessboardSize() == (7, 5)
    assert board.getSquareLength() == pytest.approx(0.1) and board.getMarkerLength() == pytest.approx(0.075)
    with pytest.raises(RegistrationError, match="unknown ArUco dictionary"):
        board_from_spec(CameraSpec(kind="markers", dictionary="DICT_9X9_1"))
    with pytest.raises(RegistrationError, match="marker_m"):
        board_from_spec(CameraSpec(kind="markers", square_m=0.05, marker_m=0.075))


def test_top_down_view_shows_the_board_as_printed():
    # The renderer's ground truth, checked against the convention's meaning: looking
    # straight down with north up, the board appears as printed (not mirrored, not
    # turned), and the chessboard corners lie where board_world_points projects them.
    cam = look_at_camera((0.0, 0.0, 1.0), (0.0, 0.0, 0.0), 640, 480, 60.0)
    view = render_view(cam, board_image())
    detector = cv2.aruco.CharucoDetector(board_from_spec(SPEC))
    printed = np.pad(board_image(), 20, constant_values=255)
    c_print, i_print, _, _ = detector.detectBoard(printed)
    c_view, i_view, _, _ = detector.detectBoard(view)
    assert len(i_print) == len(i_view) == 24
    in_print = dict(zip(np.ravel(i_print).tolist(), np.asarray(c_print).reshape(-1, 2)))
    in_view = dict(zip(np.ravel(i_view).tolist(), np.asarray(c_view).reshape(-1, 2)))
    ids = sorted(in_view)
    A, _ = cv2.estimateAffine2D(np.array([in_print[i] for i in ids]), np.array([in_view[i] for i in ids]))
    scale = np.sqrt(abs(np.linalg.det(A[:, :2])))
    np.testing.assert_allclose(A[:, :2] / scale, np.eye(2), atol=0.01)  # a pure zoom: same handedness
    uv, _ = cam.project(board_world_points(SPEC, ids))
    np.testing.assert_allclose(np.array([in_view[i] for i in ids]), uv, atol=0.3)


# ---------------------------------------------------------------- registration


@pytest.mark.parametrize("camera", [OBLIQUE, FROM_NORTH_WEST], ids=["oblique", "north-west"])
def test_register_with_known_K(camera):
    reg = register_board(render_view(camera, board_image()), SPEC, K=camera.K)
    assert isinstance(reg, Registration) and reg.intrinsics_source == "given"
    assert reg.detection == "charuco" and reg.n_points == 24
    assert rotation_error_deg(reg.camera.R, camera.R) < 0.5
    assert np.linalg.norm(reg.camera.t - camera.t) < 0.01
    assert np.linalg.norm(reg.camera.centre - camera.centre) < 0.01
    assert reg.reprojection_error_px < 0.5
    assert (reg.camera.width, reg.camera.height) == (camera.width, camera.height)


@pytest.mark.parametrize("camera", [OBLIQUE, FROM_NORTH_WEST], ids=["oblique", "north-west"])
def test_register_with_fitted_focal_length(camera):
    reg = register_board(render_view(camera, board_image()), SPEC)
    assert reg.intrinsics_source == "fitted"
    assert reg.camera.K[0, 0] == pytest.approx(camera.K[0, 0], rel=0.01)
    np.testing.assert_allclose(reg.camera.K[:2, 2], [(camera.width - 1) / 2, (camera.height - 1) / 2])
    assert rotation_error_deg(reg.camera.R, camera.R) < 0.5
    assert np.linalg.norm(reg.camera.t - camera.t) < 0.01
    assert reg.reprojection_error_px < 0.5


def test_register_from_linear_float_image_and_exif_focal_length():
    cam = OBLIQUE
    view = render_view(cam, board_image())
    linear = srgb_to_linear(view / 255.0).astype(np.float32)  # as Photo.gray holds it
    # 35 mm equivalent matching the camera's focal length for this 4:3 image.
    f35 = cam.K[0, 0] * 43.266615305567875 / np.hypot(cam.width, cam.height)
    reg = register_board(linear, SPEC, exif={"FocalLengthIn35mmFilm": f35})
    assert reg.intrinsics_source == "exif"
    assert reg.camera.K[0, 0] == pytest.approx(cam.K[0, 0], rel=1e-9)
    assert rotation_error_deg(reg.camera.R, cam.R) < 0.5
    assert np.linalg.norm(reg.camera.t - cam.t) < 0.01
    rgb = np.repeat(view[..., None], 3, axis=2)
    assert register_board(rgb, SPEC, K=cam.K).n_points == 24


def test_K_from_camera_spec_is_used():
    cam = OBLIQUE
    spec = CameraSpec(kind="markers", origin_m=SPEC.origin_m, K=cam.K.tolist())
    reg = register_board(render_view(cam, board_image()), spec)
    assert reg.intrinsics_source == "scene"
    np.testing.assert_array_equal(reg.camera.K, cam.K)


def _distorted(image: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """What a lens with distortion ``dist`` shows of an ideal pinhole view ``image``."""
    h, w = image.shape[:2]
    rows, cols = np.mgrid[0:h, 0:w].astype(np.float32)
    pts = np.stack([cols.ravel(), rows.ravel()], -1)[:, None, :]
    ideal = cv2.undistortPoints(pts, K, dist, P=K).reshape(h, w, 2)
    return cv2.remap(image, ideal[..., 0], ideal[..., 1], cv2.INTER_LINEAR, borderValue=110)


def test_scene_distortion_is_used_for_marker_cameras():
    """[camera] K and dist in scene.toml: the registered camera keeps the distortion, and the
    pose is as good as without a lens error (dropping dist, as before, costs pixels)."""
    from fitting.folder.views import camera_view as _camera_view
    from fitting.photos.read import Photo
    from fitting.photos.views import PhotoView
    cam = OBLIQUE
    dist = np.array([-0.25, 0.08, 0.0, 0.0, 0.0])
    view = _distorted(render_view(cam, board_image()), cam.K, dist)
    spec = CameraSpec(kind="markers", origin_m=SPEC.origin_m, K=cam.K.tolist(), dist=dist.tolist())
    reg = register_board(view, spec)
    assert reg.intrinsics_source == "scene"
    np.testing.assert_allclose(reg.camera.dist, dist)
    assert reg.reprojection_error_px < 0.5
    assert rotation_error_deg(reg.camera.R, cam.R) < 0.5
    error = np.linalg.norm(reg.camera.centre - cam.centre)
    assert error < 0.003
    without = register_board(view, SPEC, K=cam.K)  # the lens ignored, as before: ~8 mm off
    assert np.linalg.norm(without.camera.centre - cam.centre) > 4 * error
    # The folder path (fitting.folder.api) registers with the scene's distortion too, and EXIF does
    # not override the scene's K.
    gray = srgb_to_linear(view / 255.0).astype(np.float32)
    photo = Photo("p.png", Path("p.png"), gray[..., None].repeat(3, -1), gray, "srgb8", 8,
                  {"FocalLengthIn35mmFilm": 10.0}, np.zeros(gray.shape, bool))
    pv = PhotoView("p.png", gray, np.zeros(gray.shape, bool))
    _camera_view(photo, spec, pv)
    np.testing.assert_allclose(pv.camera.dist, dist)
    np.testing.assert_array_equal(pv.camera.K, cam.K)


def test_marker_fallback_when_chessboard_corners_are_missing():
    # Only three isolated markers survive (the rest of the board painted white):
    # no chessboard corner has two detected neighbours, so the marker corners are used.
    image = board_image()
    board = board_from_spec(SPEC)
    ids = list(np.ravel(board.getIds()))
    sparse = np.full_like(image, 255)
    for marker_id in (0, 8, 16):
        xy = np.asarray(board.getObjPoints()[ids.index(marker_id)])[:, :2] * PPM
        (x0, y0), (x1, y1) = np.floor(xy.min(0)).astype(int), np.ceil(xy.max(0)).astype(int)
        sparse[y0:y1, x0:x1] = image[y0:y1, x0:x1]
    reg = register_board(render_view(OBLIQUE, sparse), SPEC, K=OBLIQUE.K)
    assert reg.detection == "markers" and reg.n_points == 12
    # Marker corners are L-corners, less precise than chessboard saddles.
    assert rotation_error_deg(reg.camera.R, OBLIQUE.R) < 1.0
    assert np.linalg.norm(reg.camera.centre - OBLIQUE.centre) < 0.03
    assert reg.reprojection_error_px < 0.5


def test_blank_and_noise_images_raise_board_not_found():
    for image in (np.zeros((240, 320), np.uint8), np.full((240, 320, 3), 0.4, np.float32),
                  np.random.default_rng(0).integers(0, 256, (240, 320)).astype(np.uint8)):
        with pytest.raises(RegistrationError, match=r"^board not found"):
            register_board(image, SPEC)


def test_one_marker_is_too_few_corners():
    image = board_image()
    board = board_from_spec(SPEC)
    ids = list(np.ravel(board.getIds()))
    xy = np.asarray(board.getObjPoints()[ids.index(8)])[:, :2] * PPM
    single = np.full_like(image, 255)
    (x0, y0), (x1, y1) = np.floor(xy.min(0)).astype(int), np.ceil(xy.max(0)).astype(int)
    single[y0:y1, x0:x1] = image[y0:y1, x0:x1]
    # The message gives the counts that decided: no chessboard corner, one marker's four corners.
    with pytest.raises(RegistrationError,
                       match=r"^too few board corners: 0 chessboard corners and 1 marker \(4 corners\); need 6$"):
        register_board(render_view(OBLIQUE, single), SPEC, K=OBLIQUE.K)


def test_face_on_view_refuses_to_fit_focal_length_but_works_with_K():
    cam = look_at_camera((0.0, 0.0, 1.2), (0.0, 0.0, 0.0), 640, 480, 60.0)
    view = render_view(cam, board_image())
    with pytest.raises(RegistrationError, match="focal length not constrained"):
        register_board(view, SPEC)
    reg = register_board(view, SPEC, K=cam.K)
    assert np.linalg.norm(reg.camera.centre - cam.centre) < 0.01
    assert rotation_error_deg(reg.camera.R, cam.R) < 0.5
