"""A coarse search for the sun when neither the sun nor the time and site are known (NumPy).

The hard shadow predicted for each candidate sun is compared with the dark
pixels of a downsampled photo; the best candidate starts the least-squares
fit, which refines the sun together with k and rho.
"""

from __future__ import annotations

import cv2
import numpy as np

from softshadow import Pose, SoftShadowModel, Sun
from softshadow.internal import PosedOccluder, object_mask

from .views import PhotoView

__all__ = ["search_sun"]


def search_sun(model: SoftShadowModel, pose: Pose, view: PhotoView, width: int = 160,
               azimuth_step: float = 10.0, elevations=(10, 20, 30, 40, 50, 60, 70, 80)):
    """(azimuth_deg, elevation_deg, score) of the sun whose hard shadow best matches the photo."""
    h, w = view.shape
    scale = width / w
    small = cv2.resize(view.gray.astype(np.float32), (width, max(int(round(h * scale)), 1)),
                       interpolation=cv2.INTER_AREA)
    rows, cols = np.mgrid[0:small.shape[0], 0:small.shape[1]]
    full_c, full_r = (cols + 0.5) / scale - 0.5, (rows + 0.5) / scale - 0.5
    ground, valid, _ = view.ground_of_pixels(full_c, full_r)
    obj = object_mask(model.occluder, pose, view.camera if view.camera is not None else view.grid)
    obj_small = cv2.resize(obj.astype(np.uint8), small.shape[::-1], interpolation=cv2.INTER_NEAREST) > 0
    use = valid & ~obj_small.ravel() & np.isfinite(small.ravel())
    lit = np.percentile(small.ravel()[use], 90)
    darkness = 1.0 - np.clip(small.ravel()[use] / max(lit, 1e-9), 0, 1)
    darkness -= darkness.mean()
    pts = ground[use, :2]
    posed = PosedOccluder.make(model.occluder, pose, Sun(0.0, 45.0))  # posed once, lit per candidate
    best = (0.0, 45.0, -np.inf)
    for el in elevations:
        for az in np.arange(0.0, 360.0, azimuth_step):
            inside = posed.with_sun(az, el).hard_shadow_at(pts)
            if not inside.any():
                continue
            hard = inside - inside.mean()
            score = float(hard @ darkness) / (np.linalg.norm(hard) * np.linalg.norm(darkness) + 1e-12)
            if score > best[2]:
                best = (float(az), float(el), score)
    return best
