"""A shadow's true umbra-over-lit ratio from a shadow-free photo of the same scene.

Given a photo with a shadow and one without it (same camera, same scene), the
ratio image shadow / shadow-free is the shadow's attenuation pixel by pixel.
This is the reference a one-photo measurement is checked against.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage

__all__ = ["attenuation_image", "reference_at_profiles"]


def attenuation_image(gray: np.ndarray, free_gray: np.ndarray, smooth_px: float = 1.0) -> np.ndarray:
    """shadow / shadow-free, both (H, W) linear luminance Gaussian-smoothed by ``smooth_px`` (the
    pair is rarely registered to better than a pixel). (H, W), not yet divided by the lit level."""
    return (ndimage.gaussian_filter(gray, smooth_px)
            / np.maximum(ndimage.gaussian_filter(free_gray, smooth_px), 1e-6))


def reference_at_profiles(measurement, attenuation: np.ndarray) -> float | None:
    """Median over a measurement's kept profiles of the attenuation on the profile's umbra plateau
    over that on its lit plateau (the lit division removes the two exposures' difference); None
    when no kept profile has both plateaus. ``measurement``: an ``EdgeMeasurement``."""
    refs = []
    for p in measurement.profiles:
        if not p.kept:
            continue
        pts = p.position_uv[None, :] + p.offsets_px[:, None] * p.normal_uv[None, :]
        r = ndimage.map_coordinates(attenuation, [pts[:, 1], pts[:, 0]], order=1)
        umbra, lit = p.offsets_px < -0.5 * p.width_px - 1.0, p.offsets_px > 0.5 * p.width_px + 1.0
        if umbra.any() and lit.any():
            refs.append(np.median(r[umbra]) / np.median(r[lit]))
    return float(np.median(refs)) if refs else None
