"""Reading a photo folder: its images and ignore masks, with one-line reasons for the files it skips."""

from __future__ import annotations

from pathlib import Path

from scene import SceneSpec

from ..photos.ignore_masks import IgnoreMaskError, ignore_mask_path, read_ignore_mask
from ..photos.read import Photo, PhotoError, list_photos, read_photo

__all__ = ["FolderError", "read_folder", "unreadable_summary"]


class FolderError(ValueError):
    """The folder as a whole cannot be fitted (no images, unreadable scene.toml): a one-line
    reason; ``skipped`` holds the per-file reasons behind it ({"photo", "reason"}), if any."""

    def __init__(self, message: str, skipped: list[dict] | None = None):
        super().__init__(message)
        self.skipped = list(skipped or [])


def unreadable_summary(skipped: list[dict]) -> str:
    """One line for a folder where nothing could be read: how many files and why, by reason
    ("200 files, none readable: 199 text files, 1 empty file"); the details are in ``skipped``."""
    if not skipped:
        return "no image files"
    kinds: dict[tuple[str, str], int] = {}
    for s in skipped:
        kind = _reason_kind(str(s.get("reason", "")))
        kinds[kind] = kinds.get(kind, 0) + 1
    n = len(skipped)
    parts = ", ".join(f"{c} {kind[0] if c == 1 else kind[1]}"
                      for kind, c in sorted(kinds.items(), key=lambda kv: (-kv[1], kv[0])))
    return f"{n} file{'s' if n != 1 else ''}, none readable: {parts}"


# Reasons of fitting.photos.read, by the words they start with -> the kind of file (singular, plural).
_REASON_KINDS = (("not an image (the file holds text)", "text file", "text files"),
                 ("empty file", "empty file", "empty files"),
                 ("not an image (extension", "file of another type", "files of other types"),
                 ("not an image (no extension", "file without extension", "files without extension"),
                 ("not an image (content", "file that is not an image", "files that are not images"),
                 ("truncated", "truncated image", "truncated images"),
                 ("corrupt", "corrupt image", "corrupt images"),
                 ("unsupported", "unsupported image", "unsupported images"),
                 ("not a RAW", "unreadable RAW file", "unreadable RAW files"))


def _reason_kind(reason: str) -> tuple[str, str]:
    for start, one, many in _REASON_KINDS:
        if reason.startswith(start):
            return one, many
    return "unreadable file", "unreadable files"


def read_folder(folder: Path, scene: SceneSpec | None, half_size: bool = False) -> tuple[list[Photo], list[dict]]:
    """The readable photos of ``folder`` (each with its ignore mask) and a {"photo", "reason"} entry for
    every file left out. Raises FolderError when no photo can be read."""
    files, skipped_files = list_photos(folder)
    skipped = [{"photo": n, "reason": r} for n, r in skipped_files]
    photos = []
    for f in files:
        try:
            photo = read_photo(f, half_size=half_size)
            mask_path = ignore_mask_path(f, scene)
            if mask_path is not None:
                photo.ignore = read_ignore_mask(mask_path, photo.gray.shape)
            photos.append(photo)
        except PhotoError as exc:
            skipped.append({"photo": f.name, "reason": exc.reason})
        except IgnoreMaskError as exc:
            skipped.append({"photo": f.name, "reason": str(exc)})
    if not photos:
        raise FolderError(f"no readable photo in {folder}: {unreadable_summary(skipped)}", skipped)
    return photos, skipped
