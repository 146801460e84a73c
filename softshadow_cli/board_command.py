"""``softshadow board OUT.pdf``: the printable ChArUco board and the scene.toml entry that registers it."""

from __future__ import annotations

import argparse
import sys

__all__ = ["add_arguments", "run_board"]


def _squares(text: str) -> tuple[int, int]:
    from .validate import whole_pair
    try:
        cols, rows = whole_pair(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"squares must look like 7x5, got {text!r}") from None
    if cols < 3 or rows < 3:
        raise argparse.ArgumentTypeError(f"a board needs at least 3x3 squares, got {text!r}")
    return cols, rows


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("out", metavar="OUT", help="the board to write: a .pdf (print it at 100 %%) or a .png")
    p.add_argument("--paper", default="A4", choices=("A4", "A3", "A2", "A1", "A0", "letter"),
                   help="paper size, landscape (A2-A0: a poster; the larger the board, the farther the camera)")
    p.add_argument("--dpi", type=_positive, default=300.0, help="resolution of the page")
    p.add_argument("--squares", type=_squares, default=(7, 5), metavar="COLSxROWS", help="chessboard squares")
    p.add_argument("--square-mm", type=_positive, default=None, metavar="MM",
                   help="side of a square in millimetres (default: the largest whole millimetre that fits)")
    p.add_argument("--dictionary", default="DICT_4X4_50", help="the ArUco dictionary of the markers")
    p.add_argument("--force", action="store_true", help="overwrite OUT if it exists")


def run_board(args) -> int:
    from pathlib import Path

    from fitting.photos.board import board_spec_for_paper, printed_board, write_board
    from fitting.photos.markers import RegistrationError, board_from_spec

    out = Path(args.out)
    if out.suffix.lower() not in (".pdf", ".png"):
        print(f"softshadow board: OUT must end in .pdf or .png, got {out.name}", file=sys.stderr)
        return 2
    if out.exists() and not args.force:
        print(f"softshadow board: {out} exists (--force overwrites it)", file=sys.stderr)
        return 2
    if not out.parent.is_dir():
        print(f"softshadow board: the folder {out.parent} does not exist", file=sys.stderr)
        return 2
    try:
        spec = board_spec_for_paper(args.paper, args.squares, args.dictionary, args.square_mm)
        board_from_spec(spec)  # an unknown dictionary, or too few markers in it, is said here
        board = printed_board(spec, args.paper, args.dpi)
    except (ValueError, RegistrationError) as exc:
        print(f"softshadow board: {exc}", file=sys.stderr)
        return 2
    write_board(out, board)
    cols, rows = spec.squares
    print(f"wrote {out}: a {cols} x {rows} ChArUco board, squares {1000 * spec.square_m:.1f} mm, on {args.paper} "
          "(print at 100 %, then measure the 100 mm bar).")
    print("Lay it flat on the ground, north up (its caption towards south), and describe it in scene.toml; "
          "origin_m is where its top-left corner lies, in world metres:\n")
    print("[camera]\nkind = \"markers\"\n"
          f"dictionary = \"{spec.dictionary}\"\nsquares = [{cols}, {rows}]\n"
          f"square_m = {spec.square_m:.4f}\nmarker_m = {spec.marker_m:.4f}\norigin_m = [0.0, 0.0]")
    return 0
