"""The printable ChArUco board that ``[camera] kind = "markers"`` registers photos with (NumPy/OpenCV, PIL).

``printed_board`` lays the board out on a sheet of paper at its true size for a given resolution, with a
caption that gives its squares and their size and a 10 cm scale bar to check the print; ``write_board``
saves it as PDF (its page size is the paper's, so printing at 100 % gives the stated squares) or PNG.
The board is the one ``fitting.board_from_spec`` builds from the same scene.toml entry, so a photo of the
print registers with that entry.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Literal

import numpy as np

from scene import CameraSpec

from .markers import board_from_spec

__all__ = ["PAPER_SIZES_MM", "PaperName", "PrintedBoard", "board_spec_for_paper", "printed_board", "write_board"]

PaperName = Literal["A4", "A3", "A2", "A1", "A0", "letter"]
#: Paper sizes (width, height) in millimetres, portrait. A2 to A0 are posters (a copy shop prints them).
PAPER_SIZES_MM: dict[str, tuple[float, float]] = {"A4": (210.0, 297.0), "A3": (297.0, 420.0), "A2": (420.0, 594.0),
                                                   "A1": (594.0, 841.0), "A0": (841.0, 1189.0),
                                                   "letter": (215.9, 279.4)}
_MARGIN_MM = 12.0  # white paper around the board: the detector's quiet zone, and printers' margins
_CAPTION_MM = 22.0  # below the board: the caption and the scale bar
_MM_PER_INCH = 25.4


@dataclasses.dataclass(frozen=True)
class PrintedBoard:
    """A board laid out on a sheet: ``image`` (H, W) uint8, white paper; ``dpi``; the board's top-left
    outer corner at pixel ``board_origin_px`` (x, y) of the page; ``px_per_m`` page pixels per metre;
    ``spec`` the scene.toml camera entry that registers it; ``landscape`` the page's orientation."""

    image: np.ndarray
    dpi: float
    board_origin_px: tuple[float, float]
    px_per_m: float
    spec: CameraSpec
    landscape: bool

    def page_point(self, board_xy_m: np.ndarray) -> np.ndarray:
        """Board-frame points (N, 2) in metres (x right, y down from the top-left corner) to page pixels
        (N, 2), pixel centres at integers."""
        xy = np.asarray(board_xy_m, dtype=np.float64).reshape(-1, 2)
        return xy * self.px_per_m + np.asarray(self.board_origin_px) - 0.5


def board_spec_for_paper(paper: PaperName = "A4", squares: tuple[int, int] = (7, 5),
                         dictionary: str = "DICT_4X4_50", square_mm: float | None = None) -> CameraSpec:
    """The ``[camera] kind = "markers"`` entry of a board that fits on ``paper`` in landscape: the given
    square size, or the largest whole millimetre that fits with the margins and caption; markers 3/4
    of a square. Raises ValueError when the squares do not fit."""
    width, height = sorted(PAPER_SIZES_MM[paper])[::-1]  # landscape: the long side across
    cols, rows = squares
    fit_mm = min((width - 2 * _MARGIN_MM) / cols, (height - 2 * _MARGIN_MM - _CAPTION_MM) / rows)
    size_mm = float(np.floor(fit_mm)) if square_mm is None else float(square_mm)
    if size_mm <= 0 or size_mm > fit_mm + 1e-9:
        raise ValueError(f"{cols}x{rows} squares of {size_mm:g} mm do not fit on {paper} "
                         f"(at most {np.floor(fit_mm):g} mm with the margins)")
    return CameraSpec(kind="markers", dictionary=dictionary, squares=(cols, rows), square_m=size_mm / 1000.0,
                      marker_m=0.75 * size_mm / 1000.0, origin_m=(0.0, 0.0))


def _caption(spec: CameraSpec) -> str:
    cols, rows = spec.squares
    return (f"ChArUco board {cols} x {rows}, {spec.dictionary}: squares {1000 * spec.square_m:.1f} mm, markers "
            f"{1000 * spec.marker_m:.1f} mm. Print at 100 % (no fit-to-page) and check the bar: 100 mm.")


def printed_board(spec: CameraSpec, paper: PaperName = "A4", dpi: float = 300.0) -> PrintedBoard:
    """The board of ``spec`` on a landscape sheet of ``paper`` at ``dpi``, with its caption and scale bar."""
    from PIL import Image, ImageDraw, ImageFont

    board = board_from_spec(spec)
    width_mm, height_mm = sorted(PAPER_SIZES_MM[paper])[::-1]
    px_per_mm = dpi / _MM_PER_INCH
    page_w, page_h = int(round(width_mm * px_per_mm)), int(round(height_mm * px_per_mm))
    cols, rows = spec.squares
    board_w_mm, board_h_mm = cols * 1000 * spec.square_m, rows * 1000 * spec.square_m
    if board_w_mm > width_mm - 2 * _MARGIN_MM or board_h_mm > height_mm - 2 * _MARGIN_MM - _CAPTION_MM:
        raise ValueError(f"a {board_w_mm:g} x {board_h_mm:g} mm board does not fit on {paper} with its margins")
    board_px = (int(round(board_w_mm * px_per_mm)), int(round(board_h_mm * px_per_mm)))
    raster = board.generateImage(board_px, marginSize=0, borderBits=1)
    left = int(round((page_w - board_px[0]) / 2))
    top = int(round(_MARGIN_MM * px_per_mm))
    page = Image.new("L", (page_w, page_h), 255)
    page.paste(Image.fromarray(raster), (left, top))
    draw = ImageDraw.Draw(page)
    font = ImageFont.load_default(size=max(8, int(round(3.2 * px_per_mm))))
    text_y = top + board_px[1] + 4 * px_per_mm
    draw.text((left, text_y), _caption(spec), fill=0, font=font)
    bar_y = text_y + 7 * px_per_mm
    bar_w = int(round(100 * px_per_mm))
    draw.rectangle([left, bar_y, left + bar_w - 1, bar_y + 1.5 * px_per_mm], fill=0)
    for tick in range(11):  # a tick each centimetre
        x = left + min(int(round(tick * 10 * px_per_mm)), bar_w - 1)
        draw.line([x, bar_y, x, bar_y + (3.5 if tick % 5 == 0 else 2.5) * px_per_mm], fill=0,
                  width=max(1, int(px_per_mm / 4)))
    return PrintedBoard(np.asarray(page), float(dpi), (float(left), float(top)), px_per_mm * 1000.0, spec, True)


def write_board(path, board: PrintedBoard) -> Path:
    """Save a printed board: PDF (``.pdf``; the page is the paper's size at its dpi) or PNG (``.png``, with
    its dpi recorded). Raises ValueError for another extension."""
    from PIL import Image

    path = Path(path)
    kind = path.suffix.lower()
    if kind not in (".pdf", ".png"):
        raise ValueError(f"the board is written as .pdf or .png, not {path.suffix or 'a name without extension'}")
    image = Image.fromarray(board.image)
    if kind == ".pdf":
        image.save(path, "PDF", resolution=board.dpi)
    else:
        image.save(path, "PNG", dpi=(board.dpi, board.dpi))
    return path
