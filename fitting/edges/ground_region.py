"""Where the ground can be in a photo with no scene description: the sky and what lies above the horizon.

NumPy/OpenCV/scikit-image only. A photo taken by someone standing on the
ground shows the sky (blue, or white clouds) at the top, buildings and trees
that rise above the horizon, and the ground below it. Shadow edges cast on the
ground can only lie below the horizon; cloud edges, facades and tree crowns
above it are edges of other surfaces and must not be measured as shadows.

The rules, on a copy reduced to ANALYSIS_SIDE_PX:

1. Sky seeds: smooth pixels (local std of log luminance below
   SKY_SMOOTH_LOG) that are blue (B > SKY_BLUE_RATIO x R and B >= G) and
   brighter than the SKY_MIN_PERCENTILE-th percentile of luminance. A shadow
   under a blue sky is bluish too, but it is darker and rarely smooth on ground.
2. Sky: the connected regions of smooth pixels that are either blue or bright
   and neutral (clouds: brighter than the median, channel ratios within
   CLOUD_NEUTRAL_LOG) that hold a seed and touch the top border.
3. Horizon: where the sky reaches lowest. In each column holding sky, the
   lowest sky pixel; the horizon row is the HORIZON_PERCENTILE-th percentile
   of those rows over the columns (columns where buildings hide it read
   higher), and a level camera is assumed (no roll).
4. Ground: below the horizon by HORIZON_MARGIN of the image height, and not
   sky. Without sky (a photo of the ground only, an overcast white sky that
   cannot be told from white paper) every pixel may be ground and
   ``sky_found`` is False.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from skimage import measure

__all__ = ["GroundRegion", "ground_region"]

ANALYSIS_SIDE_PX = 320        # the rules run on a copy of about this longer side
SMOOTH_WINDOW_PX = 5          # window (analysis px) of the local std of log luminance
SKY_SMOOTH_LOG = 0.06         # sky and clouds are smoother than this (log units) at that scale
SKY_BLUE_RATIO = 1.15         # blue sky: B > 1.15 R (linear)
CLOUD_NEUTRAL_LOG = 0.25      # clouds: |log(c / mean)| below this for every channel
HORIZON_PERCENTILE = 90.0
HORIZON_MARGIN = 0.02         # fraction of the image height left out below the horizon
MIN_SKY_FRACTION = 0.01       # less sky than this (of the image) is not trusted
SKY_MIN_PERCENTILE = 25.0     # blue sky is brighter than this percentile of the luminance (umbrae are not)


@dataclass(frozen=True)
class GroundRegion:
    """Where shadow edges on the ground may lie.

    ground: (H, W) bool, True where the ground may be.
    sky: (H, W) bool, True on the detected sky (blue or clouds).
    horizon_row: the estimated horizon (row, full-resolution pixels), or None without sky.
    sky_found: whether a sky was found (otherwise ground is all True).
    """

    ground: np.ndarray
    sky: np.ndarray
    horizon_row: float | None
    sky_found: bool

    def contains(self, points_uv: np.ndarray) -> np.ndarray:
        """(N,) bool: whether each (u, v) point (pixels) lies on the ground region."""
        pts = np.asarray(points_uv, float).reshape(-1, 2)
        h, w = self.ground.shape
        u = np.clip(np.rint(pts[:, 0]).astype(int), 0, w - 1)
        v = np.clip(np.rint(pts[:, 1]).astype(int), 0, h - 1)
        inside = np.isfinite(pts).all(axis=1)
        return inside & self.ground[v, u]


def ground_region(linear_rgb: np.ndarray | None, gray: np.ndarray) -> GroundRegion:
    """The ground region of a photo (see the module docstring).

    linear_rgb: (H, W, 3) linear colour, or None (gray only: no sky is detected,
        since a bright smooth gray region cannot be told from white paper).
    gray: (H, W) linear luminance.
    """
    h, w = gray.shape
    everything = np.ones((h, w), bool)
    if linear_rgb is None:
        return GroundRegion(everything, ~everything, None, False)
    scale = min(1.0, ANALYSIS_SIDE_PX / float(max(h, w)))
    size = (max(1, int(round(w * scale))), max(1, int(round(h * scale))))
    rgb = np.nan_to_num(np.asarray(linear_rgb, np.float32), nan=0.0, posinf=0.0)
    small = cv2.resize(rgb, size, interpolation=cv2.INTER_AREA).astype(np.float64)
    lum = cv2.resize(np.nan_to_num(np.asarray(gray, np.float32)), size, interpolation=cv2.INTER_AREA)
    lum = lum.astype(np.float64)
    floor = max(float(np.percentile(lum, 99.9)) * 1e-4, 1e-12)
    log_lum = np.log(np.maximum(lum, floor))
    mean = cv2.blur(log_lum, (SMOOTH_WINDOW_PX, SMOOTH_WINDOW_PX))
    sq = cv2.blur(log_lum * log_lum, (SMOOTH_WINDOW_PX, SMOOTH_WINDOW_PX))
    smooth = np.sqrt(np.maximum(sq - mean * mean, 0.0)) < SKY_SMOOTH_LOG
    bright = lum > np.median(lum)
    not_dark = lum > np.percentile(lum, SKY_MIN_PERCENTILE)
    r, g, b = (np.maximum(small[..., i], floor) for i in range(3))
    blue = (b > SKY_BLUE_RATIO * r) & (b >= g)
    chan_mean = (r + g + b) / 3.0
    neutral = np.max(np.abs(np.log(np.stack([r, g, b]) / chan_mean)), axis=0) < CLOUD_NEUTRAL_LOG
    seed = smooth & not_dark & blue
    skyish = smooth & ((not_dark & blue) | (bright & neutral))
    labels = measure.label(skyish, connectivity=1)
    top = np.unique(labels[0][labels[0] > 0])
    seeded = np.unique(labels[seed & (labels > 0)])
    keep = np.intersect1d(top, seeded)
    sky_small = np.isin(labels, keep) if keep.size else np.zeros_like(skyish)
    if sky_small.mean() < MIN_SKY_FRACTION:
        return GroundRegion(everything, ~everything, None, False)
    rows = np.arange(sky_small.shape[0])
    has_sky = sky_small.any(axis=0)
    lowest = np.array([rows[sky_small[:, c]].max() for c in np.nonzero(has_sky)[0]])
    horizon_small = float(np.percentile(lowest, HORIZON_PERCENTILE)) + 0.5
    horizon_row = horizon_small / scale - 0.5
    sky = cv2.resize(sky_small.astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST).astype(bool)
    ground = np.ones((h, w), bool)
    ground[: int(np.clip(np.ceil(horizon_row + HORIZON_MARGIN * h), 0, h))] = False
    ground &= ~sky
    return GroundRegion(ground, sky, float(horizon_row), True)
