"""Preset scenes: what to photograph, when, under which light and from where.

Each builder returns a ``PresetPlan`` (pure data); ``synthesize`` renders it.
Random choices (viewpoint jitter, exposure, ...) come from the seed.

- ``table2``: the seed paper's Table 2 scene: the 3 m pillar on white paper at
  Iwate (39.70 N, 141.13 E, Asia/Tokyo); 09:20 on 27 April and 13:21 and
  16:21 on 20 April 2026; three handheld photos per time, 40 s apart. Sun from
  time and site (NREL SPA via softshadow.sun.solar_position). Sky and sun are
  set per time so that the truth brightness 255 rho^(1/2.2) is 110, 120 and
  180 (rho 0.157, 0.190, 0.465) with a realistic penumbra: the sun's radius
  0.2665 deg widened a little by haze (k = tan r ~ 0.005-0.008).
- ``pillar``, ``ball``, ``dragon``: the built-in meshes at 10:30 on 20 April,
  two handheld photos and one top-down map.
- ``depth-background``: the pillar in front of a rising bank (a height field),
  seen by a camera that also writes a range image (z-depth) per photo.
- ``steps``: the pillar beside a flight of four steps (a mesh receiver) that
  climbs along its shadow at 10:30 on 20 April: the shadow runs over treads
  and sunlit risers; two handheld photos.
- ``wall``: the pillar 1 m in front of a 2.2 m wall (a mesh receiver) at 10:30:
  the shadow runs along the ground and up the wall's sunlit face; two
  handheld photos.
- ``hard-cases``: low sun (5 deg), sun near the zenith, a penumbra narrower
  than a pixel, the shadow partly out of frame, cluttered ground, a photo
  without any time, and a corrupt file. Suns are given per photo.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import math
from zoneinfo import ZoneInfo

import numpy as np

from scene import solar_position

from .camera_pipeline import SensorSettings
from .lighting import SunSky
from .misdescription import Misdescription
from .textures import BoardSpec, PaperSheet

__all__ = ["PRESETS", "DEFAULT_SIZE", "ViewSpec", "PhotoPlan", "PresetPlan", "build_preset", "IWATE"]

DEFAULT_SIZE = (1600, 1200)
IWATE = {"latitude": 39.70, "longitude": 141.13, "timezone": "Asia/Tokyo"}
TOKYO = ZoneInfo("Asia/Tokyo")


@dataclasses.dataclass(frozen=True)
class ViewSpec:
    """How a photo is taken: 'handheld' (perspective, framing ``key_points``) or 'topdown'
    (orthographic north-up map covering ``key_points``)."""

    kind: str = "handheld"
    bearing_deg: float = 180.0
    eye_height_m: float = 1.6
    fov_x_deg: float = 62.0
    roll_deg: float = 0.0
    aim_jitter_m: tuple[float, float] = (0.0, 0.0)
    margin: float = 0.08
    min_distance_m: float = 1.5
    topdown_extent_m: float | None = None  # width of the map in metres (default: fit key points)


@dataclasses.dataclass(frozen=True)
class PhotoPlan:
    """One photo. time: exact local shutter time (aware) or None; exif_time / scene_time: where the
    time is written (scene_time None: in scene.toml when the format has no EXIF)."""

    name: str
    group: str
    light: SunSky
    view: ViewSpec
    key_points: np.ndarray
    time: _dt.datetime | None
    papers: tuple[PaperSheet, ...] = ()
    texture: str = "concrete"
    exif_time: bool = True
    scene_time: bool | None = None
    scene_group: str | None = None
    write_sun: bool | None = None
    exposure_gain: float = 1.0
    sensor: SensorSettings = SensorSettings()
    corrupt: bool = False
    note: str = ""


@dataclasses.dataclass(frozen=True)
class PresetPlan:
    name: str
    mesh: str
    object_albedo: tuple[float, float, float]
    photos: tuple[PhotoPlan, ...]
    size: tuple[int, int]
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    scale: float = 1.0
    # "plane", "bank" (a height field, written as receiver kind "depth"), "steps", "wall", or a
    # receiver object (data_synth.receivers: PlaneReceiver, HeightfieldReceiver, MeshReceiver).
    receiver: object = "plane"
    receiver_azimuth_deg: float = 0.0  # steps / wall: the compass direction they climb or stand across
    board: BoardSpec | None = None
    site: dict | None = None  # where the photos were taken (their suns come from it)
    write_sun: bool = False
    fmt: str = "jpg"
    write_site: bool = True  # False: [site] and the EXIF GPS are left out (the sun is given or fitted)
    description: Misdescription = Misdescription()  # what scene.toml and the EXIF get wrong


def _time(y, mo, d, h, mi, s=0) -> _dt.datetime:
    return _dt.datetime(y, mo, d, h, mi, s, tzinfo=TOKYO)


def _sun_at(time: _dt.datetime) -> tuple[float, float]:
    return solar_position(time, IWATE["latitude"], IWATE["longitude"])


def _shadow_dir(azimuth_deg: float) -> np.ndarray:
    """Horizontal unit vector (2,) along which shadows point (away from the sun)."""
    a = math.radians(azimuth_deg + 180.0)
    return np.array([math.sin(a), math.cos(a)])


def _paper_along_shadow(azimuth_deg: float, length_m: float, width_m: float = 0.9,
                        behind_m: float = 0.3) -> PaperSheet:
    """A paper roll laid from behind the object's base along its shadow."""
    d = _shadow_dir(azimuth_deg)
    centre = d * (length_m / 2 - behind_m)
    return PaperSheet((float(centre[0]), float(centre[1])), (length_m, width_m), (azimuth_deg + 180.0) % 360)


def _key_points(base_xy, azimuth_deg, elevation_deg, top_m, board: BoardSpec | None,
                max_len_m: float = 3.0, half_width_m: float = 0.3) -> np.ndarray:
    """Points a photo must frame: the object's base, its shadow (up to max_len_m), the board."""
    d = _shadow_dir(azimuth_deg)
    length = min(top_m / math.tan(math.radians(elevation_deg)), max_len_m)
    side = np.array([-d[1], d[0]]) * half_width_m
    base = np.asarray(base_xy, dtype=float)
    pts = [base - side, base + side, base + d * length - side, base + d * length + side]
    out = np.array([[p[0], p[1], 0.0] for p in pts])
    if board is not None:
        out = np.concatenate([out, board.corners_world()])
    return out


def _sensor(rng: np.random.Generator) -> SensorSettings:
    return SensorSettings(exposure_white=float(rng.uniform(0.62, 0.78)), vignetting=float(rng.uniform(0.15, 0.3)),
                          blur_sigma_px=float(rng.uniform(0.5, 0.9)))


def _handheld(rng, bearing) -> ViewSpec:
    return ViewSpec("handheld", bearing_deg=float(bearing + rng.normal(0, 6)),
                    eye_height_m=float(rng.uniform(1.6, 1.85)), roll_deg=float(rng.normal(0, 2.0)),
                    aim_jitter_m=(float(rng.normal(0, 0.1)), float(rng.normal(0, 0.1))))


# A board printed large (A0-sized, 1.05 x 0.75 m) so that oblique handheld views still detect it.
BOARD_SOUTH = BoardSpec(origin_m=(-0.525, -0.7), square_m=0.15, marker_m=0.11)

# (label, time of the first photo, rho, sun radius in degrees (haze widens the real 0.2665))
TABLE2_TIMES = (
    ("09:20", (2026, 4, 27, 9, 20), 0.157, 0.32),
    ("13:21", (2026, 4, 20, 13, 21), 0.190, 0.30),
    ("16:21", (2026, 4, 20, 16, 21), 0.465, 0.42),
)


def _table2(seed: int, size) -> PresetPlan:
    rng = np.random.default_rng([seed, 2])
    photos = []
    number = 1
    for label, when, rho, radius in TABLE2_TIMES:
        t0 = _time(*when)
        az0, el0 = _sun_at(t0)
        length = min(3.0 / math.tan(math.radians(el0)) + 0.6, 4.0)
        paper = _paper_along_shadow(az0, max(length, 1.5))
        keys = _key_points((0, 0), az0, el0, 3.0, BOARD_SOUTH)
        # Stand beside the shadow (across it, on the board's south side), three spots 35 deg apart.
        across = min(((az0 + 180 + 90) % 360, (az0 + 180 - 90) % 360), key=lambda b: abs(b - 180.0))
        for k, bearing in enumerate((across - 35.0, across, across + 35.0)):
            t = t0 + _dt.timedelta(seconds=40 * k + int(rng.integers(0, 10)))
            az, el = _sun_at(t)
            photos.append(PhotoPlan(
                f"IMG_{number:04d}", label, SunSky.from_rho(az, el, rho, radius), _handheld(rng, bearing),
                keys, t, papers=(paper,), texture="concrete",
                exposure_gain=float(rng.uniform(0.9, 1.1)), sensor=_sensor(rng)))
            number += 1
    return PresetPlan("table2", "pillar", (0.55, 0.52, 0.48), tuple(photos), size, board=BOARD_SOUTH,
                      site=dict(IWATE), write_sun=False)


def _single_object(name: str, mesh: str, albedo, texture: str, top_m: float, paper_m: float, seed: int,
                   size) -> PresetPlan:
    rng = np.random.default_rng([seed, 3])
    t0 = _time(2026, 4, 20, 10, 30)
    az0, el0 = _sun_at(t0)
    d = _shadow_dir(az0)
    reach = top_m / math.tan(math.radians(el0))
    centre = d * reach * 0.5
    paper = PaperSheet((float(centre[0]), float(centre[1])), (reach + paper_m, paper_m), (az0 + 180) % 360)
    keys = _key_points((0, 0), az0, el0, top_m, BOARD_SOUTH, half_width_m=max(0.3, paper_m / 3))
    if top_m < 2.5:  # a short object is framed whole (the ball floats 1 m above the ground)
        box = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (0.0, top_m)])
        keys = np.concatenate([keys, box])
    photos = []
    views = [_handheld(rng, 170.0), _handheld(rng, 225.0), ViewSpec("topdown")]
    for k, view in enumerate(views):
        t = t0 + _dt.timedelta(seconds=45 * k)
        az, el = _sun_at(t)
        photos.append(PhotoPlan(f"IMG_{k + 1:04d}", "10:30", SunSky.from_rho(az, el, 0.25), view, keys, t,
                                papers=(paper,), texture=texture, exposure_gain=float(rng.uniform(0.9, 1.1)),
                                sensor=_sensor(rng)))
    return PresetPlan(name, mesh, albedo, tuple(photos), size, board=BOARD_SOUTH, site=dict(IWATE))


def _depth_background(seed: int, size) -> PresetPlan:
    rng = np.random.default_rng([seed, 4])
    t0 = _time(2026, 4, 20, 13, 0)  # sun in the SSW: the shadow climbs the bank to the NNE
    az0, el0 = _sun_at(t0)
    keys = np.array([[-0.5, -0.5, 0.0], [0.8, -0.5, 0.0], [0.3, 2.6, 0.6], [1.6, 2.6, 0.6]])
    photos = []
    for k, bearing in enumerate((105.0, 135.0)):
        t = t0 + _dt.timedelta(seconds=60 * k)
        az, el = _sun_at(t)
        view = dataclasses.replace(_handheld(rng, bearing), eye_height_m=1.6, min_distance_m=3.0)
        photos.append(PhotoPlan(f"IMG_{k + 1:04d}", "13:00", SunSky.from_rho(az, el, 0.22, 0.28), view, keys, t,
                                texture="concrete", exposure_gain=float(rng.uniform(0.9, 1.1)), sensor=_sensor(rng)))
    return PresetPlan("depth-background", "pillar", (0.55, 0.52, 0.48), tuple(photos), size, receiver="bank",
                      site=dict(IWATE))


def _mesh_receiver_scene(name: str, seed: int, size, rho: float, radius_deg: float, bearings,
                         extra_keys: np.ndarray) -> PresetPlan:
    """The pillar at 10:30 beside a mesh receiver built along its shadow (``steps`` or ``wall``)."""
    rng = np.random.default_rng([seed, 6, len(name)])
    t0 = _time(2026, 4, 20, 10, 30)
    az0, el0 = _sun_at(t0)
    along = (az0 + 180.0) % 360.0
    d = _shadow_dir(az0)
    side = np.array([-d[1], d[0]])
    base = np.array([[*(s * 0.35 * side), 0.0] for s in (-1, 1)])
    # The receiver's key points are given in (across, along, up) of the shadow's direction.
    keys = np.concatenate([base, np.array([[*(a * side + b * d), z] for a, b, z in extra_keys])])
    photos = []
    for k, bearing in enumerate(bearings):
        t = t0 + _dt.timedelta(seconds=60 * k)
        az, el = _sun_at(t)
        view = dataclasses.replace(_handheld(rng, (along + bearing) % 360.0), eye_height_m=1.7,
                                   min_distance_m=3.0)
        photos.append(PhotoPlan(f"IMG_{k + 1:04d}", "10:30", SunSky.from_rho(az, el, rho, radius_deg), view, keys,
                                t, texture="concrete", exposure_gain=float(rng.uniform(0.9, 1.1)),
                                sensor=_sensor(rng)))
    return PresetPlan(name, "pillar", (0.55, 0.52, 0.48), tuple(photos), size, receiver=name,
                      receiver_azimuth_deg=along, site=dict(IWATE))


def _steps(seed: int, size) -> PresetPlan:
    # Steps from 0.6 m to 1.56 m along the shadow (4 x 0.32 m treads, 0.16 m risers), 3 m wide.
    keys = np.array([[-0.9, 0.6, 0.0], [0.9, 0.6, 0.0], [-0.9, 2.3, 0.64], [0.9, 2.3, 0.64]])
    return _mesh_receiver_scene("steps", seed, size, 0.25, 0.30, (140.0, -140.0), keys)


def _wall(seed: int, size) -> PresetPlan:
    # The wall's near face 1 m along the shadow, 2.2 m high: the shadow climbs to about 1.4 m.
    keys = np.array([[-0.9, 1.0, 0.0], [0.9, 1.0, 0.0], [-0.9, 1.0, 2.0], [0.9, 1.0, 2.0]])
    return _mesh_receiver_scene("wall", seed, size, 0.20, 0.35, (150.0, -150.0), keys)


def _hard_cases(seed: int, size) -> PresetPlan:
    rng = np.random.default_rng([seed, 5])
    photos = []
    clock = _time(2026, 4, 22, 8, 0)

    def add(name, group, light, view, keys, **kw):
        nonlocal clock
        clock = clock + _dt.timedelta(hours=1)  # an hour apart: one group per case
        photos.append(PhotoPlan(name, group, light, view, keys, kw.pop("time", clock),
                                exposure_gain=float(rng.uniform(0.9, 1.1)), sensor=_sensor(rng),
                                scene_group=kw.pop("scene_group", group), **kw))

    low = SunSky.from_rho(250.0, 5.0, 0.62)
    add("IMG_0001", "low-sun", low, _handheld(rng, 200.0), _key_points((0, 0), 250, 5, 3.0, None, 4.0),
        papers=(_paper_along_shadow(250.0, 4.0),), note="sun 5 deg above the horizon")
    zen = SunSky.from_rho(170.0, 87.0, 0.2)
    add("IMG_0002", "zenith", zen, dataclasses.replace(_handheld(rng, 180.0), eye_height_m=2.2),
        _key_points((0, 0), 170, 87, 3.0, None, 1.0, 0.6), papers=(PaperSheet((0.0, 0.0), (1.5, 1.5)),),
        note="sun near the zenith")
    sub = SunSky.from_rho(200.0, 55.0, 0.25)
    add("IMG_0003", "subpixel", sub, ViewSpec("topdown", topdown_extent_m=80.0),
        _key_points((0, 0), 200, 55, 3.0, None), note="penumbra narrower than a pixel (coarse top-down map)")
    oof = SunSky.from_rho(150.0, 30.0, 0.3)
    keys = _key_points((0, 0), 150, 30, 3.0, None, 1.2)  # frames 1.2 m of a 5.2 m shadow
    add("IMG_0004", "out-of-frame", oof, ViewSpec("handheld", bearing_deg=240.0, eye_height_m=1.6, margin=0.02),
        keys, papers=(_paper_along_shadow(150.0, 4.0),), note="shadow partly out of frame")
    clutter = SunSky.from_rho(160.0, 45.0, 0.28)
    add("IMG_0005", "clutter", clutter, _handheld(rng, 190.0), _key_points((0, 0), 160, 45, 3.0, None),
        texture="cluttered", note="cluttered ground texture, no paper")
    notime = SunSky.from_rho(140.0, 50.0, 0.3)
    add("IMG_0006", "IMG_0006", notime, _handheld(rng, 180.0), _key_points((0, 0), 140, 50, 3.0, None),
        papers=(_paper_along_shadow(140.0, 3.0),), time=None, exif_time=False, scene_time=False,
        scene_group=None, note="no EXIF time and no time in scene.toml")
    add("IMG_0007", "corrupt", notime, _handheld(rng, 180.0), _key_points((0, 0), 140, 50, 3.0, None),
        corrupt=True, note="corrupt file")
    return PresetPlan("hard-cases", "pillar", (0.55, 0.52, 0.48), tuple(photos), size, site=None, write_sun=True)


_BUILDERS = {
    "table2": _table2,
    "pillar": lambda seed, size: _single_object("pillar", "pillar", (0.55, 0.52, 0.48), "concrete", 3.0, 1.0,
                                                seed, size),
    "ball": lambda seed, size: _single_object("ball", "ball", (0.7, 0.15, 0.1), "asphalt", 2.0, 1.6, seed, size),
    "dragon": lambda seed, size: _single_object("dragon", "dragon", (0.25, 0.45, 0.2), "concrete", 1.3, 2.4,
                                                seed, size),
    "depth-background": _depth_background,
    "steps": _steps,
    "wall": _wall,
    "hard-cases": _hard_cases,
}
# "street" has its own scene (many occluders, zones of ground, painted clouds): data_synth.street.
PRESETS = tuple(_BUILDERS) + ("street",)


def build_preset(name: str, seed: int = 0, size: tuple[int, int] | None = None) -> PresetPlan:
    """The plan of a preset at an image size (width, height; default 1600 x 1200)."""
    if name not in _BUILDERS:
        raise ValueError(f"unknown preset {name!r}; choose one of {PRESETS}")
    size = tuple(int(v) for v in (size or DEFAULT_SIZE))
    if len(size) != 2 or min(size) < 16:
        raise ValueError(f"image size must be two integers >= 16, got {size}")
    return _BUILDERS[name](int(seed), size)
