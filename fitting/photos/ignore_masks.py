"""Ignore masks the user gives per photo: pixels never to measure (people, cars, the sky, a board).

A mask is an image file of the photo's size (or twice it, for a half-size
read) whose non-zero pixels are ignored: in any colour channel, or, for a mask
with a transparent background, its opaque pixels (``read_ignore_mask``).
It is found as, in order:

1. ``ignore = "FILE"`` in the photo's ``[photos."NAME"]`` entry of
   scene.toml (relative to the folder);
2. ``<photo stem>.ignore.png`` beside the photo.

Files ending in ``.ignore.png``, ``.depth.png`` or ``.depth.npy`` are
auxiliary and never read as photos (``is_auxiliary``).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from skimage.measure import block_reduce

__all__ = ["AUXILIARY_SUFFIXES", "IgnoreMaskError", "is_auxiliary", "ignore_mask_path", "read_ignore_mask"]

AUXILIARY_SUFFIXES = (".ignore.png", ".depth.png", ".depth.npy")


class IgnoreMaskError(ValueError):
    """An ignore mask that cannot be used; ``str(exc)`` is one line naming the file."""


def is_auxiliary(name: str) -> bool:
    """Whether a file name is an ignore mask or a range image, not a photo."""
    return name.lower().endswith(AUXILIARY_SUFFIXES)


def ignore_mask_path(photo_path, scene=None) -> Path | None:
    """The ignore mask of a photo: scene.toml's ``ignore`` entry, else ``<stem>.ignore.png`` beside it, else None.

    scene: a ``scene.SceneSpec`` or None. A mask named in scene.toml that does
    not exist raises IgnoreMaskError (the user asked for it).
    """
    photo_path = Path(photo_path)
    if scene is not None:
        named = scene.photo(photo_path.name).ignore
        if named:
            path = photo_path.parent / named
            if not path.is_file():
                raise IgnoreMaskError(f"{named}: ignore mask named in scene.toml for {photo_path.name} not found")
            return path
    beside = photo_path.with_name(photo_path.stem + ".ignore.png")
    return beside if beside.is_file() else None


def read_ignore_mask(path, shape: tuple[int, int]) -> np.ndarray:
    """(H, W) bool, True = ignore, from a mask file for a photo of shape (H, W).

    Grey or colour masks: a pixel is ignored when any channel is non-zero. A mask with an alpha
    channel that is not the same everywhere (a layer exported with a transparent background):
    its opaque pixels are ignored, whatever their colour; a mask opaque everywhere is read by
    its colour. A mask exactly twice the photo's size (a half-size read) is reduced: a pixel
    is ignored when any of its 2x2 block is. Raises IgnoreMaskError (one line naming the file)
    for another size, a mask that covers the whole photo, or one that is not binary (faint
    values over much of it: compression noise).
    """
    path = Path(path)
    raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if raw is None:
        raise IgnoreMaskError(f"{path.name}: ignore mask cannot be read as an image")
    values = _mask_values(raw)
    mask = values != 0
    h, w = shape
    if mask.shape == (h, w):
        pass
    elif mask.shape[0] // 2 == h and mask.shape[1] // 2 == w:
        mask = block_reduce(mask[: 2 * h, : 2 * w], (2, 2), np.max)
    else:
        raise IgnoreMaskError(f"{path.name}: ignore mask is {mask.shape[1]}x{mask.shape[0]} px, "
                              f"the photo is {w}x{h} px")
    _check_binary(path.name, values, mask.mean())
    return mask


#: Values at most this fraction of the encoding's maximum are "faint": noise, not paint.
FAINT = 1 / 8
#: A mask whose faint pixels are more than this fraction of the photo is not binary.
FAINT_SHARE = 0.05
#: A mask that ignores more than this fraction of the photo covers the whole photo.
WHOLE_SHARE = 0.99


def _mask_values(raw: np.ndarray) -> np.ndarray:
    """(H, W) the values that decide: alpha when it varies, else the largest colour channel."""
    if raw.ndim == 2:
        return raw
    if raw.shape[2] in (2, 4):
        alpha = raw[..., -1]
        if alpha.min() != alpha.max():
            return alpha
        if alpha.max() == 0:  # transparent everywhere: nothing painted
            return np.zeros_like(alpha)
        raw = raw[..., :-1]
    return raw.max(axis=2)


def _check_binary(name: str, values: np.ndarray, ignored_share: float) -> None:
    top = np.iinfo(values.dtype).max if values.dtype.kind in "ui" else 1.0
    faint = (values > 0) & (values <= FAINT * top)
    faint_share = float(faint.mean())
    detail = ""
    if faint_share > FAINT_SHARE:
        lo, hi = values[faint].min(), values[faint].max()
        detail = (f"; {100 * faint_share:.0f} % of its pixels hold faint values {lo:g}-{hi:g} where "
                  "0 (keep) was meant: compression noise? save the mask as PNG, never through JPEG")
    if ignored_share > WHOLE_SHARE:
        why = detail or "; the pixels to keep must be 0 (black, or transparent)"
        raise IgnoreMaskError(f"{name}: the ignore mask covers the whole photo ({100 * ignored_share:.1f} % of "
                              f"its pixels are non-zero, and non-zero means ignore){why}")
    if detail:
        raise IgnoreMaskError(f"{name}: the ignore mask is not binary{detail}")
