"""``scene.toml``: reading and writing the photo-folder scene description (CONVENTIONS).

Plain dataclasses, validated on load with messages that name the file and
key. Unknown tables and keys are kept in ``extra`` so nothing is lost on a
round trip.
"""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from softshadow import GroundGrid, PinholeCamera

__all__ = ["SceneError", "SiteSpec", "ObjectSpec", "ReceiverSpec", "CameraSpec", "PhotoSpec", "SceneSpec",
           "load_scene", "dump_scene", "scene_from_dict", "scene_to_dict"]

CAMERA_KINDS = ("explicit", "topdown", "markers")
RECEIVER_KINDS = ("plane", "depth", "mesh")


class SceneError(ValueError):
    """A scene.toml that cannot be used, with the file and the key at fault."""


@dataclasses.dataclass
class SiteSpec:
    latitude: float
    longitude: float
    timezone: str | None = None
    altitude_m: float = 0.0


@dataclasses.dataclass
class ObjectSpec:
    mesh: str
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    scale: float = 1.0


@dataclasses.dataclass
class ReceiverSpec:
    """What the shadow falls on (besides the object itself, always a receiver too).

    kind "plane": the ground z = 0. kind "depth": a range image seen by each photo's own
    camera; ``depth`` names the file for every photo (a photo's own ``depth`` overrides
    it), relative to the folder: ``.npy`` float32 metres (NaN: no data) or 16-bit ``.png``
    millimetres (0: no data), each value the distance along the camera's optical axis
    (z_cam). kind "mesh": ``mesh`` is any mesh trimesh reads (or a built-in name), in world
    metres, placed with position / rotation_deg / scale as the object is.
    """

    kind: str = "plane"
    depth: str | None = None
    mesh: str | None = None
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    scale: float = 1.0

    def to_toml(self) -> dict:
        out: dict[str, Any] = {"kind": self.kind}
        if self.kind == "depth" and self.depth is not None:
            out["depth"] = self.depth
        if self.kind == "mesh":
            out.update(mesh=self.mesh, position=list(self.position), rotation_deg=list(self.rotation_deg),
                       scale=self.scale)
        return out


@dataclasses.dataclass
class CameraSpec:
    """One of: explicit (K, R, t[, dist]), topdown (pixel_m, origin_m), markers (board)."""

    kind: str
    K: list | None = None
    R: list | None = None
    t: list | None = None
    dist: list | None = None
    pixel_m: float | None = None
    origin_m: tuple[float, float] | None = None
    dictionary: str = "DICT_4X4_50"
    squares: tuple[int, int] = (7, 5)
    square_m: float = 0.1
    marker_m: float = 0.075

    def pinhole(self, width: int, height: int) -> PinholeCamera:
        if self.kind != "explicit":
            raise SceneError(f"camera kind {self.kind!r} is not an explicit pinhole camera")
        return PinholeCamera(self.K, self.R, self.t, width, height, self.dist)

    def grid(self, width: int, height: int) -> GroundGrid:
        if self.kind != "topdown":
            raise SceneError(f"camera kind {self.kind!r} is not a top-down map")
        return GroundGrid(float(self.pixel_m), tuple(self.origin_m), width, height)

    def to_toml(self) -> dict:
        out: dict[str, Any] = {"kind": self.kind}
        if self.kind == "explicit":
            out.update(K=_lists(self.K), R=_lists(self.R), t=_lists(self.t))
            if self.dist is not None:
                out["dist"] = _lists(self.dist)
        elif self.kind == "topdown":
            out.update(pixel_m=float(self.pixel_m), origin_m=_lists(self.origin_m))
        else:
            out.update(dictionary=self.dictionary, squares=list(self.squares),
                       square_m=self.square_m, marker_m=self.marker_m)
            if self.origin_m is not None:
                out["origin_m"] = _lists(self.origin_m)
            for key in ("K", "dist"):
                if getattr(self, key) is not None:
                    out[key] = _lists(getattr(self, key))
        return out


@dataclasses.dataclass
class PhotoSpec:
    time: str | None = None
    group: str | None = None
    sun_azimuth_deg: float | None = None
    sun_elevation_deg: float | None = None
    camera: CameraSpec | None = None
    depth: str | None = None   # this photo's range image (receiver kind "depth"), relative to the folder
    ignore: str | None = None  # this photo's ignore mask (non-zero pixels are left out), relative to the folder
    extra: dict = dataclasses.field(default_factory=dict)


@dataclasses.dataclass
class SceneSpec:
    object: ObjectSpec | None = None
    site: SiteSpec | None = None
    receiver: ReceiverSpec = dataclasses.field(default_factory=ReceiverSpec)
    camera: CameraSpec | None = None
    photos: dict[str, PhotoSpec] = dataclasses.field(default_factory=dict)
    extra: dict = dataclasses.field(default_factory=dict)
    base_dir: Path | None = None

    def photo(self, name: str) -> PhotoSpec:
        return self.photos.get(name, PhotoSpec())

    def camera_for(self, name: str) -> CameraSpec | None:
        spec = self.photo(name)
        return spec.camera or self.camera


def _lists(x):
    return np.asarray(x, dtype=float).tolist() if x is not None else None


def _floats(value, n, where):
    try:
        arr = np.asarray(value, dtype=float).reshape(n)
    except Exception as exc:
        raise SceneError(f"{where}: expected {n} numbers, got {value!r}") from exc
    if not np.all(np.isfinite(arr)):
        raise SceneError(f"{where}: values must be finite, got {value!r}")
    return tuple(float(v) for v in arr)


def _camera(table: dict, where: str) -> CameraSpec:
    kind = table.get("kind")
    if kind not in CAMERA_KINDS:
        raise SceneError(f"{where}.kind must be one of {CAMERA_KINDS}, got {kind!r}")
    cam = CameraSpec(kind=kind)
    if kind == "explicit":
        for key, shape in (("K", (3, 3)), ("R", (3, 3)), ("t", (3,))):
            if key not in table:
                raise SceneError(f"{where}: an explicit camera needs {key}")
            arr = np.asarray(table[key], dtype=float)
            if arr.shape != shape or not np.all(np.isfinite(arr)):
                raise SceneError(f"{where}.{key} must be finite with shape {shape}")
            setattr(cam, key, arr.tolist())
        if abs(np.linalg.det(np.asarray(cam.R)) - 1) > 1e-3:
            raise SceneError(f"{where}.R is not a rotation matrix")
        if "dist" in table:
            cam.dist = list(map(float, table["dist"]))
    elif kind == "topdown":
        if "pixel_m" not in table or "origin_m" not in table:
            raise SceneError(f"{where}: a top-down camera needs pixel_m and origin_m")
        cam.pixel_m = float(table["pixel_m"])
        if not cam.pixel_m > 0:
            raise SceneError(f"{where}.pixel_m must be positive")
        cam.origin_m = _floats(table["origin_m"], 2, f"{where}.origin_m")
    else:
        cam.dictionary = str(table.get("dictionary", cam.dictionary))
        cam.squares = tuple(int(v) for v in table.get("squares", cam.squares))
        cam.square_m = float(table.get("square_m", cam.square_m))
        cam.marker_m = float(table.get("marker_m", cam.marker_m))
        if "origin_m" in table:
            cam.origin_m = _floats(table["origin_m"], 2, f"{where}.origin_m")
        for key in ("K", "dist"):
            if key in table:
                setattr(cam, key, np.asarray(table[key], dtype=float).tolist())
    return cam


def _receiver(table: dict, where: str) -> ReceiverSpec:
    kind = table.pop("kind", "plane")
    if kind not in RECEIVER_KINDS:
        raise SceneError(f"{where}.kind must be one of {RECEIVER_KINDS}, got {kind!r}")
    spec = ReceiverSpec(kind=kind)
    if kind == "depth" and "depth" in table:
        spec.depth = str(table.pop("depth"))
    if kind == "mesh":
        if "mesh" not in table:
            raise SceneError(f"{where}: a mesh receiver needs mesh (a file trimesh reads, or a built-in name)")
        spec.mesh = str(table.pop("mesh"))
        spec.position = _floats(table.pop("position", (0, 0, 0)), 3, f"{where}.position")
        spec.rotation_deg = _floats(table.pop("rotation_deg", (0, 0, 0)), 3, f"{where}.rotation_deg")
        spec.scale = float(table.pop("scale", 1.0))
        if not spec.scale > 0:
            raise SceneError(f"{where}.scale must be positive")
    return spec


def load_scene(path: str | Path) -> SceneSpec:
    """Read and validate a scene.toml."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(f"cannot read {path}: {exc}") from exc
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{path} is not valid TOML: {exc}") from exc
    return scene_from_dict(data, base_dir=path.parent, source=str(path))


def scene_from_dict(data: dict, base_dir=None, source="scene.toml") -> SceneSpec:
    data = dict(data)
    spec = SceneSpec(base_dir=Path(base_dir) if base_dir is not None else None)
    if "site" in data:
        s = data.pop("site")
        try:
            spec.site = SiteSpec(float(s["latitude"]), float(s["longitude"]), s.get("timezone"),
                                 float(s.get("altitude_m", 0.0)))
        except (KeyError, TypeError, ValueError) as exc:
            raise SceneError(f"{source} [site] needs numeric latitude and longitude") from exc
        if not (-90 <= spec.site.latitude <= 90 and -180 <= spec.site.longitude <= 360):
            raise SceneError(f"{source} [site] latitude/longitude out of range")
    if "object" in data:
        o = data.pop("object")
        if "mesh" not in o:
            raise SceneError(f"{source} [object] needs mesh (a built-in name or a file path)")
        spec.object = ObjectSpec(str(o["mesh"]),
                                 _floats(o.get("position", (0, 0, 0)), 3, f"{source} [object].position"),
                                 _floats(o.get("rotation_deg", (0, 0, 0)), 3, f"{source} [object].rotation_deg"),
                                 float(o.get("scale", 1.0)))
        if not spec.object.scale > 0:
            raise SceneError(f"{source} [object].scale must be positive")
    if "receiver" in data:
        spec.receiver = _receiver(dict(data.pop("receiver")), f"{source} [receiver]")
    if "camera" in data:
        spec.camera = _camera(data.pop("camera"), f"{source} [camera]")
    for name, p in (data.pop("photos", {}) or {}).items():
        p = dict(p)
        where = f'{source} [photos."{name}"]'
        photo = PhotoSpec()
        if "time" in p:
            photo.time = str(p.pop("time"))
        if "group" in p:
            photo.group = str(p.pop("group"))
        for key in ("sun_azimuth_deg", "sun_elevation_deg"):
            if key in p:
                value = float(p.pop(key))
                if not np.isfinite(value):
                    raise SceneError(f"{where}.{key} must be finite")
                setattr(photo, key, value)
        if "camera" in p:
            photo.camera = _camera(p.pop("camera"), f"{where}.camera")
        for key in ("depth", "ignore"):
            if key in p:
                value = p.pop(key)
                if not isinstance(value, str) or not value:
                    raise SceneError(f"{where}.{key} must be a file name, got {value!r}")
                setattr(photo, key, value)
        photo.extra = p
        spec.photos[name] = photo
    spec.extra = data
    return spec


def scene_to_dict(spec: SceneSpec) -> dict:
    out: dict[str, Any] = {}
    if spec.site is not None:
        out["site"] = {k: v for k, v in dataclasses.asdict(spec.site).items() if v is not None}
    if spec.object is not None:
        o = spec.object
        out["object"] = {"mesh": o.mesh, "position": list(o.position),
                         "rotation_deg": list(o.rotation_deg), "scale": o.scale}
    out["receiver"] = spec.receiver.to_toml()
    if spec.camera is not None:
        out["camera"] = spec.camera.to_toml()
    out.update(spec.extra)
    if spec.photos:
        photos = {}
        for name, p in spec.photos.items():
            entry: dict[str, Any] = {}
            for key in ("time", "group", "sun_azimuth_deg", "sun_elevation_deg", "depth", "ignore"):
                if getattr(p, key) is not None:
                    entry[key] = getattr(p, key)
            if p.camera is not None:
                entry["camera"] = p.camera.to_toml()
            entry.update(p.extra)
            photos[name] = entry
        out["photos"] = photos
    return out


def dump_scene(spec: SceneSpec, path: str | Path) -> None:
    """Write a scene.toml."""
    import tomli_w
    Path(path).write_text(tomli_w.dumps(scene_to_dict(spec)), encoding="utf-8")
