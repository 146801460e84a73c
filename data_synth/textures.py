"""Ground reflectance: procedural concrete/asphalt/clutter, white paper, a printed ChArUco board.

Reflectances are linear RGB albedos in [0, 1]. The base texture is tileable
(band-limited noise made periodic by construction in the Fourier domain) and
repeats over the whole ground; paper sheets are analytic rectangles (with an
anti-aliased edge) and the board is a raster placed on the ground following
the project's board convention (see ``BoardSpec``).
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from .sampling import bilinear

__all__ = ["TEXTURE_KINDS", "BoardSpec", "PaperSheet", "GroundAppearance", "procedural_texture",
           "board_raster", "board_object_to_world"]

TEXTURE_KINDS = ("concrete", "asphalt", "cluttered")


def _periodic_noise(size: int, rng: np.random.Generator, scale_px: float, beta: float = 1.0) -> np.ndarray:
    """Tileable noise (size, size), zero mean, unit std: white noise shaped by 1/f^beta above scale_px."""
    f = np.fft.fftfreq(size)
    fr = np.hypot(f[:, None], f[None, :])
    f0 = 1.0 / max(scale_px, 1.0)
    shape = 1.0 / (1.0 + (fr / f0) ** 2) ** (beta / 2 + 0.25) * np.exp(-(fr * 2.0) ** 2)
    spec = np.fft.fft2(rng.standard_normal((size, size))) * shape
    out = np.real(np.fft.ifft2(spec))
    return (out - out.mean()) / (out.std() + 1e-12)


def procedural_texture(kind: str, rng: np.random.Generator, size: int = 1024) -> np.ndarray:
    """A tileable ground albedo (size, size, 3) float32 for 'concrete', 'asphalt' or 'cluttered'."""
    if kind not in TEXTURE_KINDS:
        raise ValueError(f"unknown ground texture {kind!r}; choose one of {TEXTURE_KINDS}")
    coarse = _periodic_noise(size, rng, 120)
    mid = _periodic_noise(size, rng, 12)
    fine = _periodic_noise(size, rng, 1.5)
    if kind == "concrete":
        grey = 0.42 + 0.035 * coarse + 0.025 * mid + 0.03 * fine
        pits = _periodic_noise(size, rng, 2.0) > 2.6  # small dark air holes
        grey = np.where(pits, grey * 0.6, grey)
        tint = np.array([1.02, 1.0, 0.95])
    elif kind == "asphalt":
        grey = 0.11 + 0.012 * coarse + 0.01 * mid + 0.035 * np.abs(fine)
        stones = _periodic_noise(size, rng, 1.2) > 2.2  # bright aggregate
        grey = np.where(stones, grey + 0.12, grey)
        tint = np.array([1.0, 1.0, 1.03])
    else:  # cluttered: concrete with leaves, stains, cracks and pebbles of strong contrast
        grey = 0.38 + 0.06 * coarse + 0.05 * mid + 0.04 * fine
        tint = np.array([1.0, 1.0, 1.0])
    rgb = np.clip(grey[..., None] * tint, 0.02, 0.95).astype(np.float32)
    if kind == "cluttered":
        rgb = _add_clutter(rgb, rng)
    return rgb


def _add_clutter(rgb: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Leaves, dark stains, cracks and pebbles drawn with OpenCV; each shape is drawn at its
    nine periodic copies so the texture stays tileable."""
    size = rgb.shape[0]
    img = np.ascontiguousarray(rgb.copy())
    shifts = [np.array([dx, dy]) for dx in (-size, 0, size) for dy in (-size, 0, size)]

    def wrapped(draw):
        for s in shifts:
            draw(s)

    stain = np.zeros((size, size), np.float32)
    for _ in range(25):  # stains, blended once at the end
        c = rng.integers(0, size, 2)
        r = int(rng.integers(20, 80))
        wrapped(lambda s: cv2.circle(stain, tuple(int(v) for v in c + s), r, 1.0, -1, cv2.LINE_AA))
    img *= (1.0 - 0.45 * np.clip(stain, 0, 1))[..., None]
    for _ in range(160):  # leaves: ellipses in autumn colours
        c = rng.integers(0, size, 2)
        axes = tuple(int(v) for v in rng.integers(8, 30, 2))
        angle = float(rng.uniform(0, 180))
        colour = tuple(float(v) for v in rng.choice(
            [(0.45, 0.25, 0.06), (0.30, 0.32, 0.08), (0.55, 0.40, 0.10), (0.20, 0.12, 0.05)]))
        wrapped(lambda s: cv2.ellipse(img, tuple(int(v) for v in c + s), axes, angle, 0, 360, colour, -1,
                                      cv2.LINE_AA))
    for _ in range(40):  # cracks: random walks
        p = rng.uniform(0, size, 2)
        pts = [p.copy()]
        heading = rng.uniform(0, 2 * np.pi)
        for _ in range(20):
            heading += rng.normal(0, 0.4)
            p = p + 12 * np.array([np.cos(heading), np.sin(heading)])
            pts.append(p.copy())
        line = np.array(pts)
        wrapped(lambda s: cv2.polylines(img, [np.round(line + s).astype(np.int32)], False,
                                        (0.05, 0.05, 0.05), 2, cv2.LINE_AA))
    for _ in range(300):  # pebbles
        c = rng.integers(0, size, 2)
        g = float(rng.uniform(0.1, 0.8))
        r = int(rng.integers(2, 6))
        wrapped(lambda s: cv2.circle(img, tuple(int(v) for v in c + s), r, (g, g, g * 0.95), -1, cv2.LINE_AA))
    return np.clip(img, 0.02, 0.95).astype(np.float32)


@dataclasses.dataclass(frozen=True)
class BoardSpec:
    """An OpenCV ChArUco board printed on the ground (project convention).

    Board frame: x right along the squares[0] columns, y down along rows, origin
    at the board's top-left outer corner. World = (origin_x + x, origin_y - y, 0):
    the printed board lies north-up like a top-down map. ``sheet_margin_m``: white
    paper around the board (its quiet zone).
    """

    origin_m: tuple[float, float]
    squares: tuple[int, int] = (7, 5)
    square_m: float = 0.1
    marker_m: float = 0.075
    dictionary: str = "DICT_4X4_50"
    sheet_margin_m: float = 0.03

    def cv_board(self):
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard(tuple(self.squares), self.square_m, self.marker_m, dictionary)

    @property
    def size_m(self) -> tuple[float, float]:
        return self.squares[0] * self.square_m, self.squares[1] * self.square_m

    def corners_world(self) -> np.ndarray:
        """The board's four outer corners (4, 3) in world metres."""
        w, h = self.size_m
        board = np.array([[0, 0, 0], [w, 0, 0], [w, h, 0], [0, h, 0]], float)
        return board_object_to_world(board, self.origin_m)


def board_object_to_world(points_board: np.ndarray, origin_m) -> np.ndarray:
    """Board-frame points (N, 3) (x right, y down, z = 0) to world points on the ground (N, 3)."""
    p = np.asarray(points_board, dtype=np.float64).reshape(-1, 3)
    return np.stack([origin_m[0] + p[:, 0], origin_m[1] - p[:, 1], np.zeros(len(p))], -1)


def board_raster(board: BoardSpec, pixel_m: float = 0.001) -> np.ndarray:
    """The printed board as a grey raster (rows, cols) uint8, exactly squares * square_m in size."""
    w_m, h_m = board.size_m
    size = (int(round(w_m / pixel_m)), int(round(h_m / pixel_m)))
    return board.cv_board().generateImage(size, marginSize=0, borderBits=1)


@dataclasses.dataclass(frozen=True)
class PaperSheet:
    """A white sheet: centre (x, y) m, size (length along the heading, width) m, heading in
    degrees clockwise from north (compass), reflectance (linear albedo)."""

    centre: tuple[float, float]
    size: tuple[float, float]
    heading_deg: float = 0.0
    reflectance: float = 0.85

    def coverage(self, xy: np.ndarray, soft_m: float = 0.002) -> np.ndarray:
        """Fraction (N,) of a soft_m-wide neighbourhood of each point on the sheet (anti-aliased edge)."""
        h = math.radians(self.heading_deg)
        along = np.array([math.sin(h), math.cos(h)])
        across = np.array([math.cos(h), -math.sin(h)])
        dx = xy[:, 0] - self.centre[0]
        dy = xy[:, 1] - self.centre[1]
        a = np.abs(dx * along[0] + dy * along[1]) - self.size[0] / 2
        b = np.abs(dx * across[0] + dy * across[1]) - self.size[1] / 2
        return np.clip(0.5 - np.maximum(a, b) / soft_m, 0.0, 1.0)


@dataclasses.dataclass(frozen=True, eq=False)
class GroundAppearance:
    """Reflectance of the ground: a tileable base texture plus paper sheets and a board.

    base (T, T, 3) float32 repeats every T * base_pixel_m metres (row 0 north).
    """

    base: np.ndarray
    base_pixel_m: float = 0.002
    papers: tuple[PaperSheet, ...] = ()
    board: BoardSpec | None = None
    board_pixel_m: float = 0.001
    paper_grain: float = 0.01
    _board_img: np.ndarray | None = dataclasses.field(default=None, init=False)

    def __post_init__(self):
        if self.board is not None:
            img = board_raster(self.board, self.board_pixel_m).astype(np.float32) / 255.0
            # Printed ink is not perfectly black and paper not perfectly white.
            object.__setattr__(self, "_board_img", 0.04 + 0.81 * img)

    def reflectance(self, xy: np.ndarray) -> np.ndarray:
        """Linear RGB albedo (N, 3) float32 at world points xy (N, 2 or 3)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(len(xy), -1)
        col = xy[:, 0] / self.base_pixel_m
        row = -xy[:, 1] / self.base_pixel_m
        out = bilinear(self.base, row, col, wrap=True).reshape(len(xy), 3)
        if self.papers:
            cover = np.zeros(len(xy), np.float32)
            for sheet in self.papers:
                cover = np.maximum(cover, sheet.coverage(xy).astype(np.float32))
            on = cover > 0
            if on.any():
                grain = 1.0 + self.paper_grain * (out[on, 1] - out[:, 1].mean()) / (out[:, 1].std() + 1e-6)
                paper = (self.papers[0].reflectance * grain)[:, None] * np.array([1.0, 1.0, 0.98], np.float32)
                out[on] = (1 - cover[on, None]) * out[on] + cover[on, None] * paper
        if self.board is not None:
            out = self._draw_board(xy, out)
        return out

    def _draw_board(self, xy: np.ndarray, out: np.ndarray) -> np.ndarray:
        b = self.board
        ox, oy = b.origin_m
        w, h = b.size_m
        m = b.sheet_margin_m
        x_b = xy[:, 0] - ox
        y_b = oy - xy[:, 1]
        sheet = (x_b > -m) & (x_b < w + m) & (y_b > -m) & (y_b < h + m)
        if not sheet.any():
            return out
        img = self._board_img
        col = x_b[sheet] / self.board_pixel_m - 0.5
        row = y_b[sheet] / self.board_pixel_m - 0.5
        grey = bilinear(img, row, col, fill=0.85)
        out[sheet] = grey[:, None].astype(np.float32)
        return out
