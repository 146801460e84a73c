"""Camera registration from a ChArUco board lying on the ground.

Board convention (shared with the synthesiser): OpenCV's CharucoBoard object
points are in the board frame (x right along the ``squares[0]`` columns, y
down the rows, origin at the board's top-left outer corner); the printed
board lies north-up on the ground, so a board point (x, y) sits at world
(origin_x + x, origin_y - y, 0) with ``origin_m`` from scene.toml.

Detection is OpenCV's CharucoDetector on an 8-bit image; the pose comes from
cv2.solvePnP on world points directly, so R, t are world-to-camera as in
docs/formats.md. Planar poses have a two-fold ambiguity: both IPPE solutions are
refined and the one with the camera above the ground and the lower error is
kept. Without K (scene.toml) or an EXIF focal length, the focal length is
fitted from the single view (square pixels, principal point at the image
centre, no distortion) by OpenCV's calibrateCameraExtended with every other
intrinsic fixed; a board seen nearly face-on does not constrain f and is refused.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import cv2
import numpy as np

from scene import CameraSpec
from softshadow import PinholeCamera

from .exif import intrinsics_from_exif
from .read import REC709_WEIGHTS, linear_to_srgb

__all__ = ["RegistrationError", "Registration", "board_from_spec", "board_world_points",
           "board_outline_world", "marker_world_points", "register_board", "MIN_POINTS",
           "MAX_FOCAL_REL_STD"]

MIN_POINTS = 6           # fewer correspondences give a fragile planar pose
MAX_FOCAL_REL_STD = 0.05  # a fitted focal length less certain than 5 % is refused
# Corner detection is rarely better than this on real photos; a floor keeps the
# focal-length uncertainty honest on clean (synthetic) images.
_NOISE_FLOOR_PX = 0.25


class RegistrationError(ValueError):
    """The board cannot give a camera for this photo: one-line reason."""


@dataclasses.dataclass
class Registration:
    """A camera found from the board.

    camera: world-to-camera pinhole camera for the image's full size.
    reprojection_error_px: RMS distance (pixels) between detected and reprojected points.
    n_points: number of point correspondences used.
    intrinsics_source: "given" (K passed by the caller), "scene" (K in scene.toml), "exif"
        (focal length from EXIF) or "fitted".
    detection: "charuco" (chessboard corners) or "markers" (ArUco marker corners, the fallback).
    """

    camera: PinholeCamera
    reprojection_error_px: float
    n_points: int
    intrinsics_source: Literal["given", "scene", "exif", "fitted"]
    detection: Literal["charuco", "markers"] = "charuco"


def board_from_spec(camera_spec: CameraSpec) -> cv2.aruco.CharucoBoard:
    """The OpenCV ChArUco board described by a scene.toml [camera] kind="markers"."""
    name = str(camera_spec.dictionary)
    dict_id = getattr(cv2.aruco, name, None) if name.startswith("DICT_") else None
    if not isinstance(dict_id, int):
        raise RegistrationError(f"unknown ArUco dictionary {name!r} (use an OpenCV name such as DICT_4X4_50)")
    squares = tuple(int(v) for v in camera_spec.squares)
    square_m, marker_m = float(camera_spec.square_m), float(camera_spec.marker_m)
    if len(squares) != 2 or min(squares) < 2:
        raise RegistrationError(f"board squares must be two counts >= 2, got {camera_spec.squares}")
    if not (0 < marker_m < square_m):
        raise RegistrationError(f"board needs 0 < marker_m < square_m, got {marker_m} and {square_m}")
    dictionary = cv2.aruco.getPredefinedDictionary(dict_id)
    n_markers = (squares[0] * squares[1]) // 2
    if n_markers > dictionary.bytesList.shape[0]:
        raise RegistrationError(f"{name} has too few markers for a {squares[0]}x{squares[1]} board")
    return cv2.aruco.CharucoBoard(squares, square_m, marker_m, dictionary)


def _origin(camera_spec: CameraSpec) -> np.ndarray:
    return np.asarray(camera_spec.origin_m if camera_spec.origin_m is not None else (0.0, 0.0), dtype=np.float64)


def _board_to_world(camera_spec: CameraSpec, board_xy: np.ndarray) -> np.ndarray:
    """Board-frame points (N, 2 or 3), metres -> world points (N, 3) on z = 0."""
    xy = np.asarray(board_xy, dtype=np.float64).reshape(-1, np.shape(board_xy)[-1])[:, :2]
    ox, oy = _origin(camera_spec)
    return np.stack([ox + xy[:, 0], oy - xy[:, 1], np.zeros(len(xy))], axis=1)


def board_world_points(camera_spec: CameraSpec, ids) -> np.ndarray:
    """World points (N, 3), metres, of the ChArUco chessboard corners with these ids."""
    board = board_from_spec(camera_spec)
    corners = np.asarray(board.getChessboardCorners(), dtype=np.float64)
    ids = np.asarray(ids, dtype=np.int64).ravel()
    if ids.size and (ids.min() < 0 or ids.max() >= len(corners)):
        raise RegistrationError(f"ChArUco corner ids must be in [0, {len(corners) - 1}], got {ids.tolist()}")
    return _board_to_world(camera_spec, corners[ids])


def marker_world_points(camera_spec: CameraSpec, marker_ids) -> np.ndarray:
    """World points (N, 4, 3), metres, of the four corners of each ArUco marker of the board
    (in OpenCV's corner order: the marker's top-left, top-right, bottom-right, bottom-left)."""
    board = board_from_spec(camera_spec)
    index = {int(i): k for k, i in enumerate(np.asarray(board.getIds()).ravel())}
    obj = board.getObjPoints()
    out = []
    for marker_id in np.asarray(marker_ids, dtype=np.int64).ravel():
        if int(marker_id) not in index:
            raise RegistrationError(f"marker id {int(marker_id)} is not on the board")
        out.append(_board_to_world(camera_spec, np.asarray(obj[index[int(marker_id)]])))
    return np.asarray(out, dtype=np.float64).reshape(-1, 4, 3)


def board_outline_world(camera_spec: CameraSpec) -> np.ndarray:
    """World corners (4, 3) of the board's outer edge (top-left, top-right, bottom-right,
    bottom-left in the board image), e.g. to mask the board out of a photo."""
    w = camera_spec.squares[0] * camera_spec.square_m
    h = camera_spec.squares[1] * camera_spec.square_m
    return _board_to_world(camera_spec, np.array([[0, 0], [w, 0], [w, h], [0, h]], dtype=np.float64))


def _to_gray8(image) -> np.ndarray:
    """8-bit grey for the detector. uint8 is taken as display-encoded; uint16 and float
    as linear (``Photo.gray``/``Photo.linear``) and sRGB-encoded here, so dark parts of
    the board keep their contrast."""
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    if img.ndim == 3 and img.shape[2] == 4:
        img = img[..., :3]
    if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] != 3) or img.size == 0:
        raise RegistrationError(f"expected an (H, W) or (H, W, 3) image, got shape {img.shape}")
    if img.dtype == np.uint8:
        return cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) if img.ndim == 3 else np.ascontiguousarray(img)
    if img.dtype == np.uint16:
        lin = img.astype(np.float32) / 65535.0
    elif img.dtype.kind == "f":
        lin = np.nan_to_num(img.astype(np.float32), nan=0.0)
    else:
        raise RegistrationError(f"unsupported image type {img.dtype}")
    if lin.ndim == 3:
        lin = lin @ REC709_WEIGHTS
    return np.round(linear_to_srgb(lin) * 255.0).astype(np.uint8)


def _detector_params(refinement: int) -> cv2.aruco.DetectorParameters:
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = refinement
    return params


def _board_markers(gray8: np.ndarray, board: cv2.aruco.CharucoBoard):
    """ArUco markers of the board, corners refined for use as pose points: (corners (M, 4, 2), ids (M,)).

    AprilTag-style edge refinement gave the most accurate marker corners of OpenCV's
    methods on rendered views (pose error about 3x lower than sub-pixel corner refinement).
    """
    detector = cv2.aruco.ArucoDetector(board.getDictionary(),
                                       _detector_params(cv2.aruco.CORNER_REFINE_APRILTAG))
    corners, ids, _ = detector.detectMarkers(gray8)
    if ids is None:
        return np.zeros((0, 4, 2)), np.zeros(0, dtype=np.int64)
    on_board = np.isin(np.ravel(ids), np.ravel(board.getIds()))
    corners = np.asarray(corners, dtype=np.float64).reshape(-1, 4, 2)[on_board]
    return corners, np.ravel(ids)[on_board].astype(np.int64)


def _correspondences(gray8: np.ndarray, camera_spec: CameraSpec):
    """(world (N, 3), image (N, 2), detection kind) from the image; raises RegistrationError.

    ChArUco chessboard corners (saddle points, the most accurate) when at least MIN_POINTS
    are found; else the corners of the board's ArUco markers (the fallback).
    """
    board = board_from_spec(camera_spec)
    # Sub-pixel marker corners seed the chessboard-corner interpolation (which then
    # refines each saddle point itself); on rendered views this was as good as any method.
    detector = cv2.aruco.CharucoDetector(board, cv2.aruco.CharucoParameters(),
                                         _detector_params(cv2.aruco.CORNER_REFINE_SUBPIX))
    ch_corners, ch_ids, mk_corners, mk_ids = detector.detectBoard(gray8)
    n_charuco = 0 if ch_ids is None else len(ch_ids)
    if n_charuco >= MIN_POINTS:
        return (board_world_points(camera_spec, np.ravel(ch_ids)),
                np.asarray(ch_corners, dtype=np.float64).reshape(-1, 2), "charuco")
    corners, ids = _board_markers(gray8, board)
    if mk_ids is not None and len(mk_ids) > len(ids):
        # The ChArUco detector's own markers, when it found more than the AprilTag-refined pass.
        on_board = np.isin(np.ravel(mk_ids), np.ravel(board.getIds()))
        corners = np.asarray(mk_corners, dtype=np.float64).reshape(-1, 4, 2)[on_board]
        ids = np.ravel(mk_ids)[on_board].astype(np.int64)
    if 4 * len(ids) >= MIN_POINTS:
        world = marker_world_points(camera_spec, ids).reshape(-1, 3)
        return world, corners.reshape(-1, 2), "markers"
    if n_charuco == 0 and len(ids) == 0:
        raise RegistrationError(f"board not found (no {camera_spec.dictionary} markers detected)")
    # Both counts decided: neither the chessboard corners nor the markers' corners were enough.
    raise RegistrationError(f"too few board corners: {n_charuco} chessboard corners and {len(ids)} "
                            f"marker{'s' if len(ids) != 1 else ''} ({4 * len(ids)} corners); need {MIN_POINTS}")


def _pose(world: np.ndarray, image: np.ndarray, K: np.ndarray, dist):
    """World-to-camera (R (3, 3), t (3,), rms px) from planar points; camera above z = 0."""
    dist = np.zeros(5) if dist is None else np.asarray(dist, dtype=np.float64)
    ok, rvecs, tvecs, _ = cv2.solvePnPGeneric(world, image, K, dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise RegistrationError("pose not found (solvePnP failed)")
    best = None
    for rvec, tvec in zip(rvecs, tvecs):
        rvec, tvec = cv2.solvePnPRefineLM(world, image, K, dist, rvec.copy(), tvec.copy())
        R, _ = cv2.Rodrigues(rvec)
        t = tvec.ravel()
        proj, _ = cv2.projectPoints(world, rvec, tvec, K, dist)
        rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - image) ** 2, axis=1))))
        above = (-R.T @ t)[2] > 0
        depth_ok = np.all(world @ R[2] + t[2] > 0)
        key = (not (above and depth_ok), rms)
        if best is None or key < best[0]:
            best = (key, R, t, rms)
    if best[0][0]:
        raise RegistrationError("pose not found (no solution with the camera above the ground)")
    return best[1], best[2], best[3]


def _k(f: float, width: int, height: int) -> np.ndarray:
    return np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])


def _fit_focal(world: np.ndarray, image: np.ndarray, width: int, height: int) -> np.ndarray:
    """K with the focal length that minimises the reprojection error (square pixels, centred
    principal point, no distortion): OpenCV's closed-form start (``initCameraMatrix2D``) refined
    by ``calibrateCameraExtended`` with everything but f fixed, which also gives f's standard
    deviation. Raises RegistrationError when f is not constrained (a board seen nearly face-on)."""
    obj = [np.asarray(world, np.float32)]  # the board's world points lie on z = 0, as OpenCV wants
    img = [np.asarray(image, np.float32).reshape(-1, 1, 2)]
    flags = (cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_PRINCIPAL_POINT | cv2.CALIB_FIX_ASPECT_RATIO
             | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    try:
        start = cv2.initCameraMatrix2D(obj, img, (width, height), aspectRatio=1.0)
        rms, K, _, _, _, std, _, _ = cv2.calibrateCameraExtended(
            obj, img, (width, height), _k(float(start[1, 1]), width, height), np.zeros(5),
            flags=flags, criteria=criteria)
    except cv2.error:
        raise RegistrationError("pose not found for any focal length") from None
    f = float(K[1, 1])
    # With the aspect ratio fixed, fy is the free parameter: its std is the second entry. OpenCV
    # takes the noise from the residuals; a floor (_NOISE_FLOOR_PX) keeps it honest on clean images.
    n = len(world)
    sigma = float(rms) * np.sqrt(2 * n / max(2 * n - 7, 1))
    std_f = float(np.ravel(std)[1]) * max(1.0, _NOISE_FLOOR_PX / max(sigma, 1e-12))
    rel_std = std_f / f if f > 0 and std_f > 0 else np.inf
    size = float(max(width, height))
    in_range = 0.1 * size < f < 60.0 * size  # fields of view from about 160 to 1 degrees
    if not (in_range and np.isfinite(rel_std) and rel_std <= MAX_FOCAL_REL_STD):
        spread = "unbounded" if not (in_range and np.isfinite(rel_std)) else f"+-{100 * rel_std:.0f}%"
        raise RegistrationError(f"focal length not constrained by this view of the board ({spread}; "
                                "seen nearly face-on?): give K in scene.toml or EXIF focal length")
    return _k(f, width, height)


def register_board(gray_or_rgb_image, camera_spec: CameraSpec, *, K=None, exif: dict | None = None,
                   dist=None) -> Registration:
    """Find the camera from a ChArUco board on the ground.

    gray_or_rgb_image: (H, W) or (H, W, 3); uint8 display-encoded, or float/uint16 linear
        (``Photo.gray`` works directly).
    camera_spec: the [camera] kind="markers" table (board layout and ``origin_m``).
    K, dist: (3, 3) intrinsics in pixels and OpenCV distortion coefficients given by the
        caller (source "given"); when K is None, ``camera_spec.K`` with ``camera_spec.dist``
        ("scene"), else EXIF (``fitting.photos.exif.intrinsics_from_exif``, no distortion: "exif"),
        else the focal length is fitted ("fitted").
    Raises RegistrationError ("board not found ...", "too few board corners: ...", "focal length
    not constrained ...") with a one-line reason.
    """
    gray8 = _to_gray8(gray_or_rgb_image)
    height, width = gray8.shape
    world, image, detection = _correspondences(gray8, camera_spec)
    if K is not None:
        source = "given"
    elif camera_spec.K is not None:
        K, dist, source = camera_spec.K, camera_spec.dist, "scene"
    if K is not None:
        K = np.asarray(K, dtype=np.float64).reshape(3, 3)
    else:
        dist = None
        K = intrinsics_from_exif(exif or {}, width, height)
        source = "exif"
        if K is None:
            K = _fit_focal(world, image, width, height)
            source = "fitted"
    R, t, rms = _pose(world, image, K, dist)
    camera = PinholeCamera(K=K, R=R, t=t, width=width, height=height,
                           dist=None if dist is None else np.asarray(dist, dtype=np.float64))
    return Registration(camera=camera, reprojection_error_px=rms, n_points=len(world),
                        intrinsics_source=source, detection=detection)
