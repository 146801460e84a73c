"""``scene.toml``: reading and writing the photo-folder scene description (docs/formats.md).

Plain dataclasses, validated on load with messages that name the file and
key. Unknown tables and keys are refused by name (with the nearest known
name), so that a misspelt setting is never ignored in silence.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from softshadow import GroundGrid, PinholeCamera, Projector, slide_from_text
from softshadow.internal import FALLOFFS

__all__ = ["NO_GEOMETRY", "TABLES", "SceneError", "SiteSpec", "ObjectSpec", "ReceiverSpec", "CameraSpec", "PhotoSpec",
           "ProjectorSpec", "SceneSpec",
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


@dataclasses.dataclass
class ProjectorSpec:
    """A ``[[projector]]`` table: a slide projector lighting the scene (``softshadow render``;
    the fitter does not model projectors). See docs/projector.md.

    position (3,) metres; target (3,) the point it looks at, or direction (3,) its axis (then
    ``intensity`` is the irradiance at 1 m); up (3,); fov_deg: the full angle across the slide's
    width; slide: "spot", "sine" (with frequency, cycles across the slide, and amplitude in
    [0, 1]) or an image file (relative to the folder); intensity: irradiance at the target (linear,
    clear slide, surface facing the projector); falloff: "inverse-square" or "none";
    shadow_px: the shadow map's pixels across the slide's larger side.
    """

    position: tuple[float, float, float]
    target: tuple[float, float, float] | None = None
    direction: tuple[float, float, float] | None = None
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)
    fov_deg: float = 30.0
    slide: str = "spot"
    frequency: float | None = None
    amplitude: float | None = None
    intensity: float = 1.0
    falloff: str = "inverse-square"
    shadow_px: int = 1024

    @property
    def slide_text(self) -> str:
        """The slide as ``softshadow.slide_from_text`` reads it."""
        if self.slide == "sine":
            return f"sine:{self.frequency:g}:{1.0 if self.amplitude is None else self.amplitude:g}"
        return self.slide

    def projector(self, base_dir=None) -> Projector:
        """The ``softshadow.Projector`` (its slide made or read now; raises SlideError)."""
        if self.target is not None:
            target, reference = self.target, None
        else:
            d = np.asarray(self.direction, float)
            target, reference = tuple(np.asarray(self.position) + d / np.linalg.norm(d)), 1.0
        return Projector(self.position, target, slide_from_text(self.slide_text, base_dir), fov_deg=self.fov_deg,
                         up=self.up, intensity=self.intensity, falloff=self.falloff, reference_m=reference,
                         shadow_px=self.shadow_px)

    def to_toml(self) -> dict:
        out: dict[str, Any] = {"position": list(self.position)}
        if self.target is not None:
            out["target"] = list(self.target)
        else:
            out["direction"] = list(self.direction)
        out.update(up=list(self.up), fov_deg=self.fov_deg, slide=self.slide)
        if self.slide == "sine":
            out["frequency"] = self.frequency
            if self.amplitude is not None:
                out["amplitude"] = self.amplitude
        out.update(intensity=self.intensity, falloff=self.falloff, shadow_px=self.shadow_px)
        return out


@dataclasses.dataclass
class SceneSpec:
    object: ObjectSpec | None = None
    site: SiteSpec | None = None
    receiver: ReceiverSpec = dataclasses.field(default_factory=ReceiverSpec)
    camera: CameraSpec | None = None
    photos: dict[str, PhotoSpec] = dataclasses.field(default_factory=dict)
    base_dir: Path | None = None
    projectors: list[ProjectorSpec] = dataclasses.field(default_factory=list)

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


def _number(value, where: str, positive: bool = False) -> float:
    """A finite number from a TOML value (ints and floats; not strings or booleans)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"{where} must be a number, got {value!r}")
    x = float(value)
    if not np.isfinite(x):
        raise SceneError(f"{where} must be finite, got {value!r}")
    if positive and not x > 0:
        raise SceneError(f"{where} must be positive, got {value!r}")
    return x


def _array(value, shape, where: str) -> list:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise SceneError(f"{where} must be numbers with shape {shape}, got {value!r}") from exc
    if (shape is not None and arr.shape != shape) or arr.ndim == 0 or not np.all(np.isfinite(arr)):
        raise SceneError(f"{where} must be finite numbers" + (f" with shape {shape}" if shape else "")
                         + f", got {value!r}")
    return arr.tolist()


def _table(value, where: str) -> dict:
    if not isinstance(value, dict):
        raise SceneError(f"{where} must be a table, got {value!r}")
    return dict(value)


def _check_keys(table: dict, known, where: str) -> None:
    """Unknown keys are refused by name (a misspelt key would otherwise be ignored in silence)."""
    import difflib
    for key in table:
        if key not in known:
            near = difflib.get_close_matches(key, list(known), n=1)
            hint = f"; did you mean {near[0]!r}?" if near else f" (known: {', '.join(known)})"
            raise SceneError(f"{where}: unknown key {key!r}{hint}")


_CAMERA_KEYS = {"explicit": ("kind", "K", "R", "t", "dist"), "topdown": ("kind", "pixel_m", "origin_m"),
                "markers": ("kind", "dictionary", "squares", "square_m", "marker_m", "origin_m", "K", "dist")}


def _camera(table, where: str) -> CameraSpec:
    table = _table(table, where)
    kind = table.get("kind")
    if kind not in CAMERA_KINDS:
        raise SceneError(f"{where}.kind must be one of {CAMERA_KINDS}, got {kind!r}")
    _check_keys(table, _CAMERA_KEYS[kind], f"{where} (kind {kind!r})")
    cam = CameraSpec(kind=kind)
    if kind == "explicit":
        for key, shape in (("K", (3, 3)), ("R", (3, 3)), ("t", (3,))):
            if key not in table:
                raise SceneError(f"{where}: an explicit camera needs {key}")
            setattr(cam, key, _array(table[key], shape, f"{where}.{key}"))
        if abs(np.linalg.det(np.asarray(cam.R)) - 1) > 1e-3:
            raise SceneError(f"{where}.R is not a rotation matrix")
        _check_K(cam.K, f"{where}.K")
        if "dist" in table:
            cam.dist = _array(table["dist"], None, f"{where}.dist")
    elif kind == "topdown":
        if "pixel_m" not in table or "origin_m" not in table:
            raise SceneError(f"{where}: a top-down camera needs pixel_m and origin_m")
        cam.pixel_m = _number(table["pixel_m"], f"{where}.pixel_m", positive=True)
        cam.origin_m = _floats(table["origin_m"], 2, f"{where}.origin_m")
    else:
        cam.dictionary = str(table.get("dictionary", cam.dictionary))
        squares = table.get("squares", cam.squares)
        if (not isinstance(squares, (list, tuple)) or len(squares) != 2
                or not all(isinstance(v, int) and not isinstance(v, bool) for v in squares)):
            raise SceneError(f"{where}.squares must be two whole numbers, got {squares!r}")
        cam.squares = tuple(squares)
        cam.square_m = _number(table.get("square_m", cam.square_m), f"{where}.square_m", positive=True)
        cam.marker_m = _number(table.get("marker_m", cam.marker_m), f"{where}.marker_m", positive=True)
        if "origin_m" in table:
            cam.origin_m = _floats(table["origin_m"], 2, f"{where}.origin_m")
        if "K" in table:
            cam.K = _array(table["K"], (3, 3), f"{where}.K")
            _check_K(cam.K, f"{where}.K")
        if "dist" in table:
            cam.dist = _array(table["dist"], None, f"{where}.dist")
    return cam


def _check_K(K, where: str) -> None:
    """An intrinsic matrix: positive focal lengths (pixels), last row (0, 0, 1)."""
    K = np.asarray(K, dtype=float)
    if not (K[0, 0] > 0 and K[1, 1] > 0):
        raise SceneError(f"{where} must have positive focal lengths K[0][0] and K[1][1] (pixels), "
                         f"got {K[0, 0]:g} and {K[1, 1]:g}")
    if not (K[1, 0] == 0 and np.array_equal(K[2], [0.0, 0.0, 1.0])):
        raise SceneError(f"{where} must look like [[fx, s, cx], [0, fy, cy], [0, 0, 1]], got {K.tolist()}")


def _receiver(table, where: str) -> ReceiverSpec:
    table = _table(table, where)
    kind = table.pop("kind", "plane")
    if kind not in RECEIVER_KINDS:
        raise SceneError(f"{where}.kind must be one of {RECEIVER_KINDS}, got {kind!r}")
    known = {"plane": (), "depth": ("depth",), "mesh": ("mesh", "position", "rotation_deg", "scale")}[kind]
    _check_keys(table, known, f"{where} (kind {kind!r})")
    spec = ReceiverSpec(kind=kind)
    if kind == "depth" and "depth" in table:
        spec.depth = str(table.pop("depth"))
    if kind == "mesh":
        if "mesh" not in table:
            raise SceneError(f"{where}: a mesh receiver needs mesh (a file trimesh reads, or a built-in name)")
        spec.mesh = str(table.pop("mesh"))
        spec.position = _floats(table.pop("position", (0, 0, 0)), 3, f"{where}.position")
        spec.rotation_deg = _floats(table.pop("rotation_deg", (0, 0, 0)), 3, f"{where}.rotation_deg")
        spec.scale = _number(table.pop("scale", 1.0), f"{where}.scale", positive=True)
    return spec


_PROJECTOR_KEYS = ("position", "target", "direction", "up", "fov_deg", "slide", "frequency", "amplitude",
                   "intensity", "falloff", "shadow_px")


def _projector(table, where: str) -> ProjectorSpec:
    table = _table(table, where)
    _check_keys(table, _PROJECTOR_KEYS, where)
    if "position" not in table:
        raise SceneError(f"{where}: a projector needs position (metres)")
    if ("target" in table) == ("direction" in table):
        raise SceneError(f"{where}: give exactly one of target (the point it looks at) and direction")
    spec = ProjectorSpec(_floats(table["position"], 3, f"{where}.position"))
    if "target" in table:
        spec.target = _floats(table["target"], 3, f"{where}.target")
        if np.allclose(spec.target, spec.position):
            raise SceneError(f"{where}.target must differ from position")
    else:
        spec.direction = _floats(table["direction"], 3, f"{where}.direction")
        if not np.any(spec.direction):
            raise SceneError(f"{where}.direction must not be zero")
    if "up" in table:
        spec.up = _floats(table["up"], 3, f"{where}.up")
        axis = np.subtract(spec.target, spec.position) if spec.target is not None else np.asarray(spec.direction)
        up = np.asarray(spec.up)
        if not np.any(up) or np.linalg.norm(np.cross(axis / np.linalg.norm(axis), up / np.linalg.norm(up))) < 1e-9:
            raise SceneError(f"{where}.up must be a non-zero direction off the projector's axis")
    spec.fov_deg = _number(table.get("fov_deg", spec.fov_deg), f"{where}.fov_deg", positive=True)
    if not spec.fov_deg < 170:
        raise SceneError(f"{where}.fov_deg must be below 170 degrees, got {spec.fov_deg:g}")
    slide = table.get("slide", "spot")
    if not isinstance(slide, str) or not slide:
        raise SceneError(f"{where}.slide must be \"spot\", \"sine\" or an image file name, got {slide!r}")
    spec.slide = slide
    if slide == "sine":
        if "frequency" not in table:
            raise SceneError(f"{where}: a sine slide needs frequency (cycles across the slide)")
        spec.frequency = _number(table["frequency"], f"{where}.frequency")
        if spec.frequency < 0:
            raise SceneError(f"{where}.frequency must be >= 0, got {spec.frequency:g}")
        if "amplitude" in table:
            spec.amplitude = _number(table["amplitude"], f"{where}.amplitude")
            if not 0 <= spec.amplitude <= 1:
                raise SceneError(f"{where}.amplitude must be in [0, 1], got {spec.amplitude:g}")
    else:
        for key in ("frequency", "amplitude"):
            if key in table:
                raise SceneError(f"{where}.{key} goes with slide = \"sine\" only (slide is {slide!r})")
    spec.intensity = _number(table.get("intensity", spec.intensity), f"{where}.intensity")
    if spec.intensity < 0:
        raise SceneError(f"{where}.intensity must be >= 0, got {spec.intensity:g}")
    falloff = table.get("falloff", spec.falloff)
    if falloff not in FALLOFFS:
        raise SceneError(f"{where}.falloff must be one of {FALLOFFS}, got {falloff!r}")
    spec.falloff = falloff
    px = table.get("shadow_px", spec.shadow_px)
    if isinstance(px, bool) or not isinstance(px, int) or not 16 <= px <= 8192:
        raise SceneError(f"{where}.shadow_px must be a whole number in [16, 8192], got {px!r}")
    spec.shadow_px = px
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


#: The tables of scene.toml.
TABLES = ("site", "object", "receiver", "camera", "photos", "projector")
#: ``[object] mesh = NO_GEOMETRY``: the folder has no known occluder; each photo is measured on its own.
NO_GEOMETRY = "none"
_PHOTO_KEYS = ("time", "group", "sun_azimuth_deg", "sun_elevation_deg", "camera", "depth", "ignore")


def scene_from_dict(data: dict, base_dir=None, source="scene.toml") -> SceneSpec:
    """A SceneSpec from a parsed scene.toml. Unknown tables and keys, values of the wrong type and a
    missing [object] are SceneErrors naming the key: a misspelt setting is never ignored in silence.
    ``[object] mesh = "none"`` says explicitly that there is no geometry (``SceneSpec.object`` None)."""
    data = dict(data)
    spec = SceneSpec(base_dir=Path(base_dir) if base_dir is not None else None)
    _check_tables(data, source)
    if "site" in data:
        s = _table(data.pop("site"), f"{source} [site]")
        _check_keys(s, ("latitude", "longitude", "timezone", "altitude_m"), f"{source} [site]")
        for key in ("latitude", "longitude"):
            if key not in s:
                raise SceneError(f"{source} [site] needs numeric latitude and longitude")
        timezone = s.get("timezone")
        if timezone is not None and not isinstance(timezone, str):
            raise SceneError(f"{source} [site].timezone must be a name such as \"Asia/Tokyo\", got {timezone!r}")
        spec.site = SiteSpec(_number(s["latitude"], f"{source} [site].latitude"),
                             _number(s["longitude"], f"{source} [site].longitude"), timezone,
                             _number(s.get("altitude_m", 0.0), f"{source} [site].altitude_m"))
        if not (-90 <= spec.site.latitude <= 90 and -180 <= spec.site.longitude <= 360):
            raise SceneError(f"{source} [site] latitude/longitude out of range")
    if "object" not in data:
        raise SceneError(f"{source} has no [object] table: name the occluder ([object] mesh = \"pillar\" "
                         f"or a mesh file), or write [object] mesh = \"{NO_GEOMETRY}\" to measure each photo "
                         "on its own without geometry")
    o = _table(data.pop("object"), f"{source} [object]")
    _check_keys(o, ("mesh", "position", "rotation_deg", "scale"), f"{source} [object]")
    if "mesh" not in o:
        raise SceneError(f"{source} [object] needs mesh (a built-in name or a file path, or "
                         f"\"{NO_GEOMETRY}\" for no geometry)")
    if not isinstance(o["mesh"], str) or not o["mesh"]:
        raise SceneError(f"{source} [object].mesh must be a name or a file path, got {o['mesh']!r}")
    if o["mesh"] == NO_GEOMETRY:
        if len(o) > 1:
            raise SceneError(f"{source} [object]: mesh = \"{NO_GEOMETRY}\" takes no other keys")
    else:
        spec.object = ObjectSpec(o["mesh"],
                                 _floats(o.get("position", (0, 0, 0)), 3, f"{source} [object].position"),
                                 _floats(o.get("rotation_deg", (0, 0, 0)), 3, f"{source} [object].rotation_deg"),
                                 _number(o.get("scale", 1.0), f"{source} [object].scale", positive=True))
    if "receiver" in data:
        spec.receiver = _receiver(data.pop("receiver"), f"{source} [receiver]")
    if "camera" in data:
        spec.camera = _camera(data.pop("camera"), f"{source} [camera]")
    projectors = data.pop("projector", [])
    if isinstance(projectors, dict):
        raise SceneError(f"{source}: write projectors as [[projector]] (an array of tables), not [projector]")
    if not isinstance(projectors, list):
        raise SceneError(f"{source}: projector must be [[projector]] tables, got {projectors!r}")
    spec.projectors = [_projector(p, f"{source} [[projector]] #{i + 1}") for i, p in enumerate(projectors)]
    for name, p in _table(data.pop("photos", {}) or {}, f"{source} [photos]").items():
        where = f'{source} [photos."{name}"]'
        p = _table(p, where)
        _check_keys(p, _PHOTO_KEYS, where)
        photo = PhotoSpec()
        for key in ("time", "group"):
            if key in p:
                value = p.pop(key)
                if not isinstance(value, (str, int, float, _dt.datetime)) or isinstance(value, bool):
                    raise SceneError(f"{where}.{key} must be text, got {value!r}")
                setattr(photo, key, str(value))
        for key, low, high, what in (("sun_azimuth_deg", -360.0, 360.0, "degrees clockwise from north"),
                                     ("sun_elevation_deg", -90.0, 90.0, "degrees above the horizon")):
            if key in p:
                angle = _number(p.pop(key), f"{where}.{key}")
                if not low <= angle <= high:
                    raise SceneError(f"{where}.{key} must be in [{low:g}, {high:g}] ({what}), got {angle:g}")
                setattr(photo, key, angle)
        if "camera" in p:
            photo.camera = _camera(p.pop("camera"), f"{where}.camera")
        for key in ("depth", "ignore"):
            if key in p:
                value = p.pop(key)
                if not isinstance(value, str) or not value:
                    raise SceneError(f"{where}.{key} must be a file name, got {value!r}")
                setattr(photo, key, value)
        spec.photos[name] = photo
    return spec


def _check_tables(data: dict, source: str) -> None:
    import difflib
    for key in data:
        if key not in TABLES:
            near = difflib.get_close_matches(key, TABLES, n=1)
            hint = f"; did you mean [{near[0]}]?" if near else f" (known tables: {', '.join(TABLES)})"
            raise SceneError(f"{source}: unknown table [{key}]{hint}")


def scene_to_dict(spec: SceneSpec) -> dict:
    out: dict[str, Any] = {}
    if spec.site is not None:
        out["site"] = {k: v for k, v in dataclasses.asdict(spec.site).items() if v is not None}
    if spec.object is not None:
        o = spec.object
        out["object"] = {"mesh": o.mesh, "position": list(o.position),
                         "rotation_deg": list(o.rotation_deg), "scale": o.scale}
    else:
        out["object"] = {"mesh": NO_GEOMETRY}
    out["receiver"] = spec.receiver.to_toml()
    if spec.camera is not None:
        out["camera"] = spec.camera.to_toml()
    if spec.projectors:
        out["projector"] = [p.to_toml() for p in spec.projectors]
    if spec.photos:
        photos = {}
        for name, p in spec.photos.items():
            entry: dict[str, Any] = {}
            for key in ("time", "group", "sun_azimuth_deg", "sun_elevation_deg", "depth", "ignore"):
                if getattr(p, key) is not None:
                    entry[key] = getattr(p, key)
            if p.camera is not None:
                entry["camera"] = p.camera.to_toml()
            photos[name] = entry
        out["photos"] = photos
    return out


def dump_scene(spec: SceneSpec, path: str | Path) -> None:
    """Write a scene.toml."""
    import tomli_w
    Path(path).write_text(tomli_w.dumps(scene_to_dict(spec)), encoding="utf-8")
