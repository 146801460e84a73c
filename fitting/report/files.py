"""Writing result files atomically, and the software versions a result records.

Every file a fit writes goes through ``atomic_path`` (a temporary file beside the
target, then ``os.replace``, atomic within one file system), so an interruption leaves
either the old file or the new one, never half of one.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import tempfile
from importlib import metadata
from pathlib import Path
from collections.abc import Iterator

__all__ = ["atomic_path", "atomic_writer", "safe_name", "software_versions"]

_OPENCV_DISTRIBUTIONS = ("opencv-contrib-python-headless", "opencv-python-headless",
                         "opencv-contrib-python", "opencv-python")


def software_versions() -> dict[str, str | None]:
    """Installed versions of the packages a result depends on (None when not installed).

    Keys: softshadow, jax, optimistix, numpy, opencv (whichever OpenCV wheel is
    installed; they all provide ``cv2``).
    """
    def version(name: str) -> str | None:
        try:
            return metadata.version(name)
        except metadata.PackageNotFoundError:
            return None

    opencv = next((v for v in map(version, _OPENCV_DISTRIBUTIONS) if v is not None), None)
    return {"softshadow": version("softshadow"), "jax": version("jax"),
            "optimistix": version("optimistix"), "numpy": version("numpy"), "opencv": opencv}


@contextlib.contextmanager
def atomic_path(path) -> Iterator[Path]:
    """A temporary path beside ``path`` (same suffix, so writers that go by it still work)
    for a writer that takes a file name; on success it replaces ``path``, on error it is
    removed and ``path`` is left as it was."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp" + path.suffix)
    os.close(fd)
    try:
        # mkstemp makes the file private (0600); give it the mode open() would have.
        os.chmod(tmp, 0o666 & ~_umask())
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


@contextlib.contextmanager
def atomic_writer(path, newline: str | None = None) -> Iterator[io.TextIOBase]:
    """``atomic_path`` opened for writing UTF-8 text (flushed to disk before it replaces ``path``)."""
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8", newline=newline) as fh:
        yield fh
        fh.flush()
        os.fsync(fh.fileno())


def _umask() -> int:
    """The process umask (read by setting and restoring it; there is no getter)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def safe_name(text: str) -> str:
    """A file-name-safe version of a label or photo stem: ':' becomes '-', anything but
    letters, digits, '.', '_' and '-' becomes '_' ('09:20' -> '09-20')."""
    name = re.sub(r"[^A-Za-z0-9._-]", "_", str(text).replace(":", "-")).strip(".")
    return name or "group"
