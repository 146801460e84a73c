"""Reading a photo folder: its images and ignore masks, with one-line reasons for the files it skips."""

from __future__ import annotations

from pathlib import Path

from scene import SceneSpec

from ..photos.ignore_masks import IgnoreMaskError, ignore_mask_path, read_ignore_mask
from ..photos.read import Photo, PhotoError, list_photos, read_photo

__all__ = ["FolderError", "read_folder", "unreadable_summary", "unmatched_entries"]


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
    if "ignore mask" in reason:
        return "photo with an unusable ignore mask", "photos with unusable ignore masks"
    if "seems misspelt" in reason:
        return "photo whose scene.toml entry is misspelt", "photos whose scene.toml entries are misspelt"
    return "unreadable file", "unreadable files"


def unmatched_entries(scene: SceneSpec | None, files: list[Path]) -> tuple[list[dict], dict[str, str]]:
    """scene.toml's ``[photos."NAME"]`` entries that match no photo file, as ``skipped`` entries
    naming the close file name (names are case-sensitive), and {photo: entry} for the photos
    such an entry was surely meant for: a photo without an entry of its own whose name differs
    only in case. Those photos are left out rather than fitted without their entry (their
    camera, time or sun). A merely similar name (difflib) is suggested, not assumed: in a
    numbered series every name is similar to its neighbours."""
    import difflib
    if scene is None or not scene.photos:
        return [], {}
    names = [f.name for f in files]
    free = [n for n in names if n not in scene.photos]  # photos without an entry of their own
    unmatched = [e for e in scene.photos if e not in names]
    meant: dict[str, str] = {}
    for entry in unmatched:
        same = [n for n in free if n.lower() == entry.lower() and n not in meant]
        if same:
            meant[same[0]] = entry
    notes = []
    for entry in unmatched:
        photo = next((p for p, e in meant.items() if e == entry), None)
        if photo is not None:
            reason = (f'[photos."{entry}"] in scene.toml matches no file; did you mean "{photo}"? '
                      "(names are case-sensitive)")
        else:
            near = difflib.get_close_matches(entry, [n for n in free if n not in meant], n=1, cutoff=0.8)
            reason = f'[photos."{entry}"] in scene.toml matches no file in the folder' + (
                f' (a photo without an entry: "{near[0]}")' if near else "")
        notes.append({"photo": entry, "reason": reason})
    return notes, meant


def read_folder(folder: Path, scene: SceneSpec | None, half_size: bool = False) -> tuple[list[Photo], list[dict]]:
    """The readable photos of ``folder`` (each with its ignore mask) and a {"photo", "reason"} entry for
    every file left out. Raises FolderError when no photo can be read."""
    files, skipped_files = list_photos(folder)
    skipped = [{"photo": n, "reason": r} for n, r in skipped_files]
    notes, meant = unmatched_entries(scene, files)
    skipped += notes
    photos = []
    for f in files:
        if f.name in meant:
            entry = meant[f.name]
            skipped.append({"photo": f.name, "reason": f'its scene.toml entry seems misspelt as [photos."{entry}"] '
                                                       f'(names are case-sensitive): rename it [photos."{f.name}"]'})
            continue
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
        files_skipped = [s for s in skipped if s not in notes]
        raise FolderError(f"no readable photo in {folder}: {unreadable_summary(files_skipped)}"
                          + _first_reason(files_skipped), skipped)
    return photos, skipped


def _first_reason(skipped: list[dict]) -> str:
    """The first reason in full when it is not about the file's type (a mask, a scene.toml
    entry): the summary's kind alone would not say what to fix."""
    for s in skipped:
        if "ignore mask" in s["reason"] or "scene.toml" in s["reason"]:
            return f" ({s['photo']}: {s['reason']})"
    return ""
