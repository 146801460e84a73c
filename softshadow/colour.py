"""The sRGB transfer functions (IEC 61966-2-1), NumPy only: decoding photos, encoding renders."""

from __future__ import annotations

import numpy as np

__all__ = ["srgb_to_linear", "linear_to_srgb"]


def srgb_to_linear(encoded) -> np.ndarray:
    """Exact piecewise sRGB EOTF: encoded values in [0, 1] (clipped) -> linear [0, 1], float64."""
    c = np.clip(np.asarray(encoded, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(linear) -> np.ndarray:
    """Inverse of ``srgb_to_linear``: linear [0, 1] (clipped) -> sRGB-encoded [0, 1], float64."""
    x = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
