"""Level of detail chosen by visual masking: the coarsest level the current lights hide.

The Dowling paper (*Shadow Mapping and Visual Masking in Level of Detail Systems*) found by eye
that patterned projected light hides a simplified mesh's facets, and proposed that a level of
detail system choose the mesh for the lights of the moment. Here:

- ``MaskingScene``: a view and its lights, the paper's set-up (a slide projector above and
  beside the camera, an ambient term) with the sun optionally added;
- ``masked_ssim``: the judge, SSIM (scikit-image, Gaussian window sigma 1.5) between a level's
  image and the full mesh's under the same lights, over the pixels where either shows the
  object or its shadows; a level counts as hidden at ``HIDDEN_SSIM``;
- ``MaskingTable``: for one view, that SSIM measured for every level on a grid of lights (the
  slide's amplitude and frequency, the sun's range k), interpolated for the lights of any frame
  (no level is rendered then), with a margin: the table's own interpolation error, measured by
  leaving out each inner grid value in turn. ``MaskingTable.choose`` gives the coarsest level
  whose predicted SSIM less the margin reaches the threshold;
- ``measure_masking_table``: renders the grid once per view (``render_frame``).

The paper's own scheme "uses lookup tables to allow the use of a more sophisticated image
comparison method"; this is such a table, with SSIM as the comparison.
"""

from __future__ import annotations

import dataclasses
import functools
import json
from collections.abc import Sequence

import numpy as np

from .camera import PinholeCamera, look_at_camera
from .params import Sun
from .projector import Projector
from .scene_render import SceneLights
from .slides import sine_slide

__all__ = ["HIDDEN_SSIM", "MaskingScene", "masked_ssim", "comparison_region"]

#: SSIM from which a level counts as hidden (a conventional mark for "hard to tell apart").
HIDDEN_SSIM = 0.95


@dataclasses.dataclass(frozen=True)
class MaskingScene:
    """A view and its lights (world metres, the object standing on z = 0 near the origin).

    The defaults are the Dowling grid's: a three-quarter view, a slide projector above and
    beside the camera (its slides ``sine_slide(frequency, amplitude)``), an ambient term; the
    sun (``sun_azimuth_deg``/``sun_elevation_deg``, irradiance ``sun_irradiance`` on a surface
    facing it) when ``sun_irradiance`` > 0. Albedo 0.85 everywhere.
    """

    camera_position: tuple = (0.9, -3.3, 1.5)
    camera_target: tuple = (0.0, 0.0, 0.5)
    camera_fov_deg: float = 36.0
    width: int = 640
    height: int = 480
    projector_position: tuple = (-0.6, -2.8, 2.4)
    projector_target: tuple = (0.0, 0.0, 0.5)
    projector_fov_deg: float = 38.0
    slide_px: int = 512
    shadow_px: int = 1024
    ambient: float = 0.12
    sun_azimuth_deg: float = 250.0
    sun_elevation_deg: float = 35.0
    sun_irradiance: float = 0.6
    albedo: float = 0.85

    def camera(self, supersample: int = 1) -> PinholeCamera:
        """The camera, with supersample x supersample pixels for each of the image's."""
        return look_at_camera(self.camera_position, self.camera_target, self.width * supersample,
                              self.height * supersample, self.camera_fov_deg)

    def projector(self, amplitude: float, frequency: float) -> Projector:
        """The projector with the sine slide of this amplitude and frequency (0: the spotlight)."""
        return Projector(self.projector_position, self.projector_target, _slide(float(frequency), float(amplitude),
                                                                               int(self.slide_px)),
                         fov_deg=self.projector_fov_deg, shadow_px=self.shadow_px)

    def sun_at(self, azimuth_offset_deg: float = 0.0) -> Sun | None:
        """The sun (None without one), its azimuth turned by an offset."""
        if self.sun_irradiance <= 0:
            return None
        return Sun(self.sun_azimuth_deg + azimuth_offset_deg, self.sun_elevation_deg)

    def sun_description(self) -> str:
        if self.sun_irradiance <= 0:
            return "none"
        return (f"azimuth {self.sun_azimuth_deg:g} deg, elevation {self.sun_elevation_deg:g} deg, "
                f"irradiance {self.sun_irradiance:g}")

    def lights(self, range_k: float = 0.01) -> SceneLights:
        return SceneLights(self.ambient, max(self.sun_irradiance, 0.0), range_k)


@functools.lru_cache(maxsize=64)
def _slide(frequency: float, amplitude: float, size: int) -> np.ndarray:
    slide = sine_slide(frequency, amplitude, size)
    slide.setflags(write=False)
    return slide


def comparison_region(*masks: np.ndarray, dilate_px: int = 3) -> np.ndarray:
    """The pixels (H, W) bool where any of the masks is set, dilated by ``dilate_px``: what a
    comparison of two images of the object looks at (its outline counts)."""
    import cv2
    union = np.zeros(masks[0].shape, np.uint8)
    for m in masks:
        union |= m.astype(np.uint8)
    return cv2.dilate(union, np.ones((2 * dilate_px + 1,) * 2, np.uint8)) > 0


def masked_ssim(full: np.ndarray, level: np.ndarray, region: np.ndarray) -> float:
    """SSIM of two images (H, W) (grey, linear) averaged over ``region`` (H, W) bool.

    scikit-image's ``structural_similarity``, Gaussian window of sigma 1.5 (Wang et al. 2004),
    the data range of both images together.
    """
    from skimage.metrics import structural_similarity
    lo, hi = min(full.min(), level.min()), max(full.max(), level.max())
    _, smap = structural_similarity(full, level, data_range=float(hi - lo) or 1.0, gaussian_weights=True,
                                    sigma=1.5, use_sample_covariance=False, full=True)
    return float(smap[region].mean())
