"""A projector's slides: the Dowling paper's spotlight and sine-modulated slides, and images (NumPy).

A slide is a float array (H, W, 3) of linear transmittances in [0, 1] (1 lets the
projector's full light through), row 0 at the top of the projected picture. The
projector (``softshadow.projector``) maps it onto the scene by projective texture
mapping.

- ``spot_slide``: the cross-section of a spotlight's beam: 1 inside a disk, falling
  smoothly (cos^2) to 0 at its rim, 0 outside.
- ``sine_slide``: the spotlight modulated by a sine grid in x and y, "a spotlight
  shining through some sort of grid or lattice"::

      slide = spot * (1 - A + A * g(x) g(y)),   g(s) = (1 + cos(2 pi f s)) / 2

  with s the position in slide widths from the slide's centre (so the centre is a bright
  cell), f the frequency in cycles across the slide's width and A in [0, 1] the amplitude
  (modulation depth). f = 0 (any A) is the plain spotlight; the paper's slides are
  (A, f) = (1, 0), (1, 4), (1, 15) and (0.5, 15).
- ``load_slide``: an image file (8-bit files are sRGB-decoded to linear, as photos are).
- ``slide_from_text``: "spot", "sine:FREQ[:AMP]" or an image path (the command line's and
  scene.toml's form).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .colour import srgb_to_linear

__all__ = ["PAPER_SLIDES", "SlideError", "spot_slide", "sine_slide", "load_slide", "slide_from_text",
           "DEFAULT_SLIDE_PX"]

DEFAULT_SLIDE_PX = 512
#: The Dowling paper's four slides (figures 6-9), as (amplitude, frequency).
PAPER_SLIDES = ((1.0, 0.0), (1.0, 4.0), (1.0, 15.0), (0.5, 15.0))


class SlideError(ValueError):
    """A slide that cannot be made or read, with the reason in one line."""


def _slide_coordinates(size: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixel centres (size, size) in slide widths from the centre: x right, y down, in (-0.5, 0.5)."""
    s = (np.arange(size) + 0.5) / size - 0.5
    return np.meshgrid(s, s)


def spot_slide(size: int = DEFAULT_SLIDE_PX, radius: float = 0.45, softness: float = 0.1) -> np.ndarray:
    """The spotlight's beam cross-section (size, size, 3): 1 within ``radius - softness`` of the
    centre, cos^2 down to 0 at ``radius`` (both in slide widths), 0 beyond."""
    if not (isinstance(size, (int, np.integer)) and size >= 2):
        raise SlideError(f"a slide needs at least 2 pixels a side, got {size!r}")
    if not (0 < radius <= 0.5 * np.sqrt(2)) or not (0 <= softness <= radius):
        raise SlideError(f"spot radius must be in (0, 0.71] and softness in [0, radius], got {radius}, {softness}")
    x, y = _slide_coordinates(int(size))
    r = np.hypot(x, y)
    # 0 at the inner radius, 1 at the rim; a zero softness gives a hard disk.
    t = np.clip((r - (radius - softness)) / max(softness, 1e-12), 0.0, 1.0)
    value = np.where(r <= radius, np.cos(0.5 * np.pi * t) ** 2, 0.0)
    return np.repeat(value[..., None], 3, axis=-1)


def sine_slide(frequency: float, amplitude: float = 1.0, size: int = DEFAULT_SLIDE_PX,
               radius: float = 0.45, softness: float = 0.1) -> np.ndarray:
    """The spotlight modulated by a sine grid (size, size, 3); see the module docstring.

    frequency >= 0: cycles across the slide's width; amplitude in [0, 1]: modulation depth.
    """
    f, a = float(frequency), float(amplitude)
    if not (np.isfinite(f) and f >= 0):
        raise SlideError(f"sine slide frequency must be a number >= 0, got {frequency!r}")
    if not (np.isfinite(a) and 0 <= a <= 1):
        raise SlideError(f"sine slide amplitude must be in [0, 1], got {amplitude!r}")
    if f > size / 4:
        raise SlideError(f"sine slide frequency {f:g} needs more than {size} pixels a side "
                         "(at least 4 per cycle)")
    x, y = _slide_coordinates(int(size))
    g = 0.25 * (1.0 + np.cos(2 * np.pi * f * x)) * (1.0 + np.cos(2 * np.pi * f * y))
    return spot_slide(size, radius, softness) * (1.0 - a + a * g)[..., None]


def load_slide(path: str | Path) -> np.ndarray:
    """An image file as a slide (H, W, 3) in [0, 1] linear: 8-bit files are sRGB-decoded, 16-bit
    ones scaled by 65535 (taken as linear), greyscale repeated to three channels."""
    import cv2
    path = Path(path)
    if not path.is_file():
        raise SlideError(f"slide image {path} not found")
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise SlideError(f"cannot read the slide image {path}")
    if img.ndim == 3:
        img = img[..., :3][..., ::-1]  # OpenCV's BGR(A) to RGB; alpha is not a transmittance here
    if img.dtype == np.uint8:
        lin = srgb_to_linear(img.astype(np.float64) / 255.0)
    elif img.dtype == np.uint16:
        lin = img.astype(np.float64) / 65535.0
    else:
        lin = np.clip(img.astype(np.float64), 0.0, 1.0)
    if lin.ndim == 2:
        lin = np.repeat(lin[..., None], 3, axis=-1)
    if min(lin.shape[:2]) < 2:
        raise SlideError(f"slide image {path} is smaller than 2x2 pixels")
    return np.ascontiguousarray(lin, dtype=np.float64)


def slide_from_text(text: str, base_dir: str | Path | None = None, size: int = DEFAULT_SLIDE_PX) -> np.ndarray:
    """A slide from "spot", "sine:FREQ[:AMP]" (AMP default 1) or an image path (relative to
    base_dir when given)."""
    text = str(text).strip()
    if text == "spot":
        return spot_slide(size)
    if text.startswith("sine"):
        parts = text.split(":")
        if parts[0] != "sine" or len(parts) not in (2, 3):
            raise SlideError(f"a sine slide is written sine:FREQ or sine:FREQ:AMP, got {text!r}")
        try:
            values = [float(p) for p in parts[1:]]
        except ValueError:
            raise SlideError(f"a sine slide is written sine:FREQ or sine:FREQ:AMP with numbers, got {text!r}") from None
        return sine_slide(values[0], values[1] if len(values) > 1 else 1.0, size)
    if not text:
        raise SlideError("empty slide: give spot, sine:FREQ[:AMP] or an image file")
    path = Path(text)
    if base_dir is not None and not path.is_absolute():
        path = Path(base_dir) / path
    return load_slide(path)
