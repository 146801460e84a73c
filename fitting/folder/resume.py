"""Finished groups kept on disk (``OUT_DIR/groups/``) and reused only when nothing that decides
them has changed.

A group's record is reused when its **key** matches: a SHA-256 over the group's photos (names
and file contents), the whole scene (scene.toml as read, plus the contents of every file it
names: meshes, range images, ignore masks; and a photo's ``<stem>.ignore.png``), the fit
options that change a result, how photos are decoded (``half_size``) and the versions of
softshadow, JAX and optimistix. Replacing a photo by another file of the same name, editing
scene.toml, changing ``--profile`` or upgrading the software therefore refits the group
instead of reporting stale values. ``folder_key`` is the same key over a whole folder:
``fit_many`` reuses a finished folder only while it matches. Records are written atomically
(a temporary file, then ``os.replace``), so an interruption leaves whole records only.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

from scene import SceneSpec, scene_to_dict

from ..report.files import atomic_writer
from ..report.results import GroupResult

__all__ = ["photo_digest", "photo_file_digest", "group_key", "folder_key", "GroupStore", "RESULT_OPTIONS"]

#: FitOptions fields that change a group's numbers (plots, overlays and verbosity do not).
RESULT_OPTIONS = ("profiles", "blur", "rule", "range_k_max", "max_samples_per_photo", "robust",
                  "max_steps", "seed", "sky_occlusion", "lod", "lod_tolerance")


def _file_sha256(path: Path) -> str:
    with open(path, "rb") as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()


def photo_file_digest(path) -> str:
    """SHA-256 of a photo file and of the ignore mask beside it (``<stem>.ignore.png``)."""
    path = Path(path)
    digest = _file_sha256(path)
    beside = path.with_name(path.stem + ".ignore.png")
    return digest + (":" + _file_sha256(beside) if beside.is_file() else "")


def photo_digest(photo) -> str:
    """SHA-256 of a photo's file (``Photo.path``) and of the ignore mask beside it, or of its
    decoded pixels when it has no file."""
    path = getattr(photo, "path", None)
    if path is not None and Path(path).is_file():
        return photo_file_digest(path)
    return hashlib.sha256(photo.linear.tobytes()).hexdigest()


def _scene_files(scene: SceneSpec) -> list[str]:
    """Every file the scene names: the object's and the receiver's meshes, range images and
    ignore masks (relative to the folder; built-in mesh names are not files)."""
    names = [scene.object.mesh if scene.object is not None else None,
             scene.receiver.mesh, scene.receiver.depth]
    for entry in scene.photos.values():
        names += [entry.depth, entry.ignore]
    return sorted({n for n in names if n})


def _scene_part(scene: SceneSpec | None) -> dict:
    """The scene as read, with the contents of every file it names (not only their names)."""
    if scene is None:
        return {}
    part = scene_to_dict(scene)
    if scene.base_dir is not None:
        files = {name: Path(scene.base_dir) / name for name in _scene_files(scene)}
        part["_file_sha256"] = {name: _file_sha256(path) for name, path in files.items() if path.is_file()}
    return part


def group_key(photo_digests: dict[str, str], scene: SceneSpec | None, options, software: dict,
              extra: dict | None = None) -> str:
    """The resume key of one group: photo name -> digest (its photos), the scene, the options
    (``RESULT_OPTIONS`` of a FitOptions), software versions and anything else in ``extra``."""
    return _key(photo_digests, _scene_part(scene), options, software, extra)


def _key(photo_digests: dict[str, str], scene_part: dict, options, software: dict, extra: dict | None) -> str:
    opts = {k: getattr(options, k) for k in RESULT_OPTIONS if hasattr(options, k)}
    doc = {"photos": sorted(photo_digests.items()), "scene": scene_part, "options": opts,
           "software": {k: software.get(k) for k in ("softshadow", "jax", "optimistix")},
           "extra": extra or {}}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()


def folder_key(folder, options, software: dict, half_size: bool = False) -> str:
    """The resume key of a whole folder (``fit_many``): the same parts as its groups' keys
    (``group_key``): every photo's contents and the ignore mask beside it, the scene (scene.toml
    as read, with the contents of every file it names), the options, ``half_size`` and the
    software. A scene.toml that cannot be read enters with its bytes (the folder then fails
    and is never marked done)."""
    from scene import SceneError, load_scene

    from ..photos.read import list_photos
    folder = Path(folder)
    photos, _ = list_photos(folder)
    digests = {p.name: photo_file_digest(p) for p in photos}
    scene_file = folder / "scene.toml"
    if scene_file.is_file():
        try:
            scene_part = _scene_part(load_scene(scene_file))
        except (SceneError, OSError):
            scene_part = {"_unreadable_sha256": _file_sha256(scene_file)}
    else:
        scene_part = {}
    return _key(digests, scene_part, options, software, {"half_size": half_size, "folder": True})


@dataclasses.dataclass
class _Record:
    result: GroupResult
    skipped: list[dict]


class GroupStore:
    """``OUT_DIR/groups/*.json``: one record per finished group, {"resume_key", "group", "skipped"}.

    ``get(key)`` returns (GroupResult, skipped entries) of a record with that key, or None, and
    counts it in ``reused``; ``put`` writes a record. ``force`` ignores (and on ``clear``
    removes) the records already there.
    """

    def __init__(self, groups_dir: str | Path, force: bool = False):
        self.dir = Path(groups_dir)
        self.records: dict[str, _Record] = {}
        self.reused = 0
        if force or not self.dir.is_dir():
            return
        for f in sorted(self.dir.glob("*.json")):
            try:
                doc = json.loads(f.read_text(encoding="utf-8"))
                self.records[str(doc["resume_key"])] = _Record(GroupResult.from_json(doc["group"]),
                                                               list(doc.get("skipped", [])))
            except (ValueError, TypeError, KeyError, OSError):
                continue  # a damaged or old record is simply refitted

    def get(self, key: str) -> tuple[GroupResult, list[dict]] | None:
        record = self.records.get(key)
        if record is None:
            return None
        self.reused += 1
        return record.result, list(record.skipped)

    def clear(self) -> None:
        """Remove every record (a ``--force`` run starts from nothing)."""
        if self.dir.is_dir():
            for f in self.dir.glob("*.json"):
                f.unlink(missing_ok=True)

    def put(self, result: GroupResult, key: str, skipped: list[dict], file_stem: str) -> Path:
        target = self.dir / f"{file_stem}.json"
        with atomic_writer(target) as fh:
            json.dump({"resume_key": key, "group": result.to_json(), "skipped": skipped}, fh, indent=1)
        return target
