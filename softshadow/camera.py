"""Cameras: OpenCV pinhole cameras and top-down ground maps.

Pinhole convention (docs/formats.md): x_cam = R x_world + t, pixel (u, v) with
(0, 0) the centre of the top-left pixel, u to the right, v down. Ground maps:
north up, pixel (col, row) centred at (origin_x + col * pixel_m,
origin_y - row * pixel_m).

The ray/ground geometry here is NumPy: it picks which ground points each
pixel sees, a discrete step.
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["PinholeCamera", "GroundGrid", "look_at_camera"]


@dataclasses.dataclass(frozen=True)
class PinholeCamera:
    """OpenCV pinhole camera. K (3, 3) pixels; R (3, 3), t (3,) world to camera; size in pixels."""

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    width: int
    height: int
    dist: np.ndarray | None = None  # OpenCV distortion coefficients (k1, k2, p1, p2[, k3])

    def __post_init__(self):
        object.__setattr__(self, "K", np.asarray(self.K, dtype=np.float64).reshape(3, 3))
        object.__setattr__(self, "R", np.asarray(self.R, dtype=np.float64).reshape(3, 3))
        object.__setattr__(self, "t", np.asarray(self.t, dtype=np.float64).reshape(3))
        if self.dist is not None:
            object.__setattr__(self, "dist", np.asarray(self.dist, dtype=np.float64).ravel())
        if not (np.all(np.isfinite(self.K)) and np.all(np.isfinite(self.R)) and np.all(np.isfinite(self.t))):
            raise ValueError("camera K, R and t must be finite")
        if abs(np.linalg.det(self.R) - 1.0) > 1e-3:
            raise ValueError("camera R must be a rotation (det 1)")

    @property
    def centre(self) -> np.ndarray:
        """Camera centre in world coordinates, shape (3,)."""
        return -self.R.T @ self.t

    def with_size(self, width: int, height: int) -> "PinholeCamera":
        """The same camera for an image resampled to (width, height) pixels."""
        sx, sy = width / self.width, height / self.height
        K = self.K.copy()
        K[0] *= sx
        K[1] *= sy
        K[0, 2] = (self.K[0, 2] + 0.5) * sx - 0.5
        K[1, 2] = (self.K[1, 2] + 0.5) * sy - 0.5
        return dataclasses.replace(self, K=K, width=width, height=height)

    def pixel_rays(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """World directions (N, 3), not normalised, of the rays through pixels (u, v)."""
        uv = np.stack([np.ravel(u), np.ravel(v)], -1).astype(np.float64)
        if self.dist is not None and np.any(self.dist):
            import cv2
            norm = cv2.undistortPoints(uv[:, None, :], self.K, self.dist).reshape(-1, 2)
        else:
            Kinv = np.linalg.inv(self.K)
            norm = (uv @ Kinv[:2, :2].T) + Kinv[:2, 2]
        # R^T (x, y, 1) for each row (BLAS threads: see softshadow.one_blas_thread).
        return norm @ self.R[:2] + self.R[2]

    def fine_footprint_m(self, ground: np.ndarray, valid: np.ndarray, use: np.ndarray) -> float:
        """The finest ground size (m) of the pixels in ``use`` (a raster resolution): the 5th
        percentile of each pixel's footprint, the larger of its distances to the ground points
        of its right and lower neighbours; 0.01 when no pixel is used.

        ground (H*W, 3) the pixels' ground points (``ground_points`` of every pixel in row
        order), valid (H*W,) where they exist, use (H*W,) the pixels that matter.
        """
        h, w = self.height, self.width
        g = np.asarray(ground).reshape(h, w, 3)
        dx = np.zeros((h, w))
        dx[:, :-1] = np.linalg.norm(np.diff(g, axis=1), axis=-1)
        dx[:, -1] = dx[:, -2] if w > 1 else 0.0
        dy = np.zeros_like(dx)
        dy[:-1] = np.linalg.norm(np.diff(g, axis=0), axis=-1)
        dy[-1] = dy[-2] if h > 1 else 0.0
        fp = np.maximum(dx, dy).ravel()
        fp = np.where(valid & np.isfinite(fp), fp, np.inf)
        return float(np.percentile(fp[use], 5)) if np.any(use) else 0.01

    def ground_points(self, u: np.ndarray, v: np.ndarray, plane_z: float = 0.0):
        """Where pixel rays meet the plane z = plane_z.

        Returns (points (N, 3), valid (N,)): invalid where the ray does not
        descend to the plane in front of the camera (the sky, the horizon).
        """
        d = self.pixel_rays(u, v)
        c = self.centre
        dz = d[:, 2]
        valid = dz < -1e-12 if c[2] > plane_z else dz > 1e-12
        lam = np.where(valid, (plane_z - c[2]) / np.where(valid, dz, -1.0), 0.0)
        valid &= lam > 0
        return c + lam[:, None] * d, valid

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (N, 2) of world points (N, 3) and whether each is in front of the camera."""
        import cv2
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        depth = pts @ self.R[2] + self.t[2]
        rvec, _ = cv2.Rodrigues(self.R)
        uv, _ = cv2.projectPoints(pts, rvec, self.t, self.K,
                                  self.dist if self.dist is not None else np.zeros(5))
        return uv.reshape(-1, 2), depth > 1e-9


def look_at_camera(position, target, width: int, height: int, fov_x_deg: float,
                   up=(0.0, 0.0, 1.0)) -> PinholeCamera:
    """A pinhole camera at ``position`` looking at ``target`` with horizontal field of view."""
    position = np.asarray(position, dtype=np.float64)
    forward = np.asarray(target, dtype=np.float64) - position
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(up, dtype=np.float64))
    if np.linalg.norm(right) < 1e-9:  # looking straight down: keep north up in the image
        right = np.cross(forward, np.array([0.0, 1.0, 0.0]))
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    R = np.stack([right, down, forward])
    f = 0.5 * width / np.tan(np.deg2rad(fov_x_deg) / 2)
    K = np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1.0]])
    return PinholeCamera(K=K, R=R, t=-R @ position, width=width, height=height)


@dataclasses.dataclass(frozen=True)
class GroundGrid:
    """A top-down ground map: ``pixel_m`` metres per pixel, world centre of pixel (0, 0)."""

    pixel_m: float
    origin_m: tuple[float, float]
    width: int
    height: int

    def __post_init__(self):
        if not (self.pixel_m > 0 and np.isfinite(self.pixel_m)):
            raise ValueError(f"pixel_m must be positive, got {self.pixel_m}")
        if self.width <= 0 or self.height <= 0:
            raise ValueError("ground grid needs a positive width and height")

    @classmethod
    def around(cls, centre_xy, size_m: float, pixels: int) -> "GroundGrid":
        """A square grid of ``pixels`` x ``pixels`` covering ``size_m`` metres around a centre."""
        pixel_m = size_m / pixels
        ox = centre_xy[0] - (pixels - 1) / 2 * pixel_m
        oy = centre_xy[1] + (pixels - 1) / 2 * pixel_m
        return cls(pixel_m, (float(ox), float(oy)), pixels, pixels)

    def to_world(self, col, row) -> np.ndarray:
        """Ground points (..., 3) at z = 0 of (fractional) pixel coordinates."""
        col = np.asarray(col, dtype=np.float64)
        row = np.asarray(row, dtype=np.float64)
        x = self.origin_m[0] + col * self.pixel_m
        y = self.origin_m[1] - row * self.pixel_m
        return np.stack([x, y, np.zeros_like(x)], -1)

    def to_pixel(self, xy) -> np.ndarray:
        """Fractional (col, row) of world points (..., 2 or 3)."""
        xy = np.asarray(xy, dtype=np.float64)
        col = (xy[..., 0] - self.origin_m[0]) / self.pixel_m
        row = (self.origin_m[1] - xy[..., 1]) / self.pixel_m
        return np.stack([col, row], -1)

    def pixel_centres(self) -> np.ndarray:
        """World points (height, width, 3) of every pixel centre."""
        rows, cols = np.mgrid[0:self.height, 0:self.width]
        return self.to_world(cols, rows)
