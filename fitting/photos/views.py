"""A photo's view of the receiver: its image, camera (or top-down grid), sun and time.

NumPy only: pixel-to-ground geometry and its local Jacobian, the discrete
inputs of the differentiable fit.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt

import numpy as np

from softshadow import GroundGrid, PinholeCamera

__all__ = ["PhotoView"]


@dataclasses.dataclass
class PhotoView:
    """One photo ready to fit.

    gray (H, W) float32 linear; saturated (H, W) bool; exactly one of camera /
    grid; sun in degrees with its source ("given", "time+site", "fitted").
    """

    name: str
    gray: np.ndarray
    saturated: np.ndarray
    camera: PinholeCamera | None = None
    grid: GroundGrid | None = None
    sun_azimuth_deg: float | None = None
    sun_elevation_deg: float | None = None
    sun_source: str | None = None
    time: _dt.datetime | None = None
    reprojection_error_px: float | None = None
    ignore: np.ndarray | None = None  # (H, W) bool: pixels never to sample (board, clutter)
    receiver: object | None = None  # fitting.samples.receiver_points.ReceiverSurface; None: the plane z = 0

    @property
    def shape(self) -> tuple[int, int]:
        return self.gray.shape[:2]

    def ground_of_pixels(self, cols: np.ndarray, rows: np.ndarray):
        """Ground points (N, 3), valid (N,), and Jacobian d(ground xy)/d(col, row) (N, 2, 2)."""
        cols = np.asarray(cols, dtype=np.float64).ravel()
        rows = np.asarray(rows, dtype=np.float64).ravel()
        if self.grid is not None:
            pts = self.grid.to_world(cols, rows)
            jac = np.zeros((len(cols), 2, 2))
            jac[:, 0, 0] = self.grid.pixel_m
            jac[:, 1, 1] = -self.grid.pixel_m
            return pts, np.ones(len(cols), bool), jac
        pts, valid = self.camera.ground_points(cols, rows)
        px, vx = self.camera.ground_points(cols + 0.5, rows)
        mx, wx = self.camera.ground_points(cols - 0.5, rows)
        py, vy = self.camera.ground_points(cols, rows + 0.5)
        my, wy = self.camera.ground_points(cols, rows - 0.5)
        jac = np.stack([(px - mx)[:, :2], (py - my)[:, :2]], axis=-1)  # columns: d/dcol, d/drow
        return pts, valid & vx & wx & vy & wy, jac

    def project(self, points: np.ndarray):
        """Pixels (N, 2) (col, row) of ground/world points and whether they are in front/in range."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if self.grid is not None:
            return self.grid.to_pixel(points), np.ones(len(points), bool)
        return self.camera.project(points)
