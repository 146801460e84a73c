"""``softshadow board``: the printed board is the one ``[camera] kind = "markers"`` registers; a synthetic
photo of the printed page lying on the ground gives back the camera."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from fitting.photos.board import board_spec_for_paper, printed_board
from fitting.photos.markers import register_board
from softshadow import look_at_camera
from softshadow_cli.main import main


def _photo_of_page(board, camera, ground: int = 105, supersample: int = 3) -> np.ndarray:
    """An 8-bit photo of the page lying on the ground, north up, the board's top-left corner at the
    spec's origin: page pixel (c, r) has its centre at board point ((c + 0.5 - left) / ppm, ...)."""
    ox, oy = board.spec.origin_m
    left, top = board.board_origin_px
    ppm = board.px_per_m
    page_to_ground = np.array([[1 / ppm, 0, ox + (0.5 - left) / ppm], [0, -1 / ppm, oy - (0.5 - top) / ppm],
                               [0, 0, 1]])
    ground_to_image = camera.K @ np.column_stack([camera.R[:, 0], camera.R[:, 1], camera.t])
    s = supersample
    up = np.array([[s, 0, (s - 1) / 2], [0, s, (s - 1) / 2], [0, 0, 1.0]])
    big = cv2.warpPerspective(board.image, up @ ground_to_image @ page_to_ground, (camera.width * s, camera.height * s),
                              flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=ground)
    return cv2.resize(big, (camera.width, camera.height), interpolation=cv2.INTER_AREA)


def test_a_photo_of_the_printed_board_registers():
    spec = board_spec_for_paper("A3")
    spec = type(spec)(**{**spec.__dict__, "origin_m": (-0.1, 0.08)})
    board = printed_board(spec, "A3", dpi=150)
    camera = look_at_camera((0.35, -0.45, 0.55), (0.05, -0.05, 0.0), 960, 720, 55.0)
    photo = _photo_of_page(board, camera)
    reg = register_board(photo, spec, K=camera.K)
    assert reg.n_points >= 20 and reg.reprojection_error_px < 0.5
    cos = (np.trace(np.asarray(reg.camera.R) @ np.asarray(camera.R).T) - 1) / 2
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))) < 0.3
    centre = -np.asarray(camera.R).T @ np.asarray(camera.t)
    found = -np.asarray(reg.camera.R).T @ np.asarray(reg.camera.t)
    assert np.linalg.norm(found - centre) < 0.005  # metres


def test_the_page_has_the_stated_square_size():
    spec = board_spec_for_paper("A4", square_mm=30)
    board = printed_board(spec, "A4", dpi=200)
    px_per_mm = 200 / 25.4
    assert board.image.shape == (round(210 * px_per_mm), round(297 * px_per_mm))
    left, top = (int(v) for v in board.board_origin_px)
    # The first square (black) and its right neighbour (white with a marker's white border).
    side = 30 * px_per_mm
    row = board.image[int(top + side / 2), left:left + int(2.5 * side)]
    black = np.flatnonzero(row < 128)
    assert abs(np.flatnonzero(np.diff(black) > 1)[0] + 1 - side) <= 1.5


def test_board_spec_refuses_squares_that_do_not_fit():
    with pytest.raises(ValueError, match="do not fit on A4"):
        board_spec_for_paper("A4", square_mm=50)


def test_board_command_writes_pdf_and_prints_the_scene_entry(tmp_path, capsys):
    out = tmp_path / "board.pdf"
    assert main(["board", str(out), "--paper", "letter", "--dpi", "100"]) == 0
    printed = capsys.readouterr().out
    assert out.read_bytes().startswith(b"%PDF")
    assert 'kind = "markers"' in printed and "squares = [7, 5]" in printed and "square_m = 0.03" in printed
    assert main(["board", str(out)]) == 2  # exists
    assert "exists" in capsys.readouterr().err
    assert main(["board", str(tmp_path / "board.jpg")]) == 2
    assert main(["board", str(tmp_path / "b.png"), "--dictionary", "DICT_NOPE"]) == 2
    assert "unknown ArUco dictionary" in capsys.readouterr().err
