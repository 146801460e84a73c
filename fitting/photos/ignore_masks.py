"""Ignore masks the user gives per photo: pixels never to measure (people, cars, the sky, a board).

A mask is an image file of the photo's size (or twice it, for a half-size
read) whose non-zero pixels (in any channel, including alpha) are ignored.
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

    A mask exactly twice the photo's size (a half-size read) is reduced: a
    pixel is ignored when any of its 2x2 block is. Any other size is an error.
    """
    path = Path(path)
    raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if raw is None:
        raise IgnoreMaskError(f"{path.name}: ignore mask cannot be read as an image")
    mask = raw != 0 if raw.ndim == 2 else (raw != 0).any(axis=2)
    h, w = shape
    if mask.shape == (h, w):
        return mask
    if mask.shape[0] // 2 == h and mask.shape[1] // 2 == w:
        return block_reduce(mask[: 2 * h, : 2 * w], (2, 2), np.max)
    raise IgnoreMaskError(f"{path.name}: ignore mask is {mask.shape[1]}x{mask.shape[0]} px, "
                          f"the photo is {w}x{h} px")
