"""Scenes drawn at random from a documented prior, for calibration studies.

``draw_parameters(rng, prior)`` draws every choice of one photo group (the sun, the
light, the object and its pose, the receiver, the cameras, the sensor and the file,
and what the folder gets wrong) into a ``SceneDraw``: plain JSON-ready data.
``synthesize_draw(draw, out_dir)`` renders it with the physical renderer (ray-cast sun
disk and sky, independent of the fitted model) into a photo folder with scene.toml and
truth.json; ``draw_scene(rng, prior, out_dir)`` does both. A draw is re-made exactly
from its JSON (``SceneDraw.from_json``).

The prior (``ScenePrior``, every range in its fields):

- sun: elevation uniform in 8-85 deg, azimuth uniform; a site (latitude, longitude,
  whole-hour time zone) and a day and time found for it (``data_synth.sun_site``), so
  the sun also follows from the time and the site;
- light: k = tan(sun radius) log-uniform in 0.002-0.03, rho log-uniform in 0.03-0.9;
- object: pillar, ball, knot (the built-in trefoil tube called ``dragon`` in
  softshadow) or any mesh handed in by name (the study adds the real dragon), scaled by a
  log-uniform 0.75-1.33 and turned about z uniformly;
- receiver: the ground plane (1/2), a bank rising along the shadow, written as range
  images (1/4), or a mesh: steps climbing along the shadow or a wall across it (1/4);
  a receiver the shadow cannot reach (a high sun's short shadow) falls back to the plane
  (``receiver_fallback``);
- photos: 1-6 per group, 20-90 s apart; image size with a log-uniform pixel count
  from 320x240 to 4000x3000 (4:3); render cost capped by at most 24 megapixels per
  group (fewer photos of a large size: a 4000x3000 group has one or two);
  handheld views across the shadow (35-145 deg off its direction) or facing a mesh
  receiver's lit side (40-75 deg off the sun's azimuth), a fifth of them top-down maps
  on the plane;
- camera: optical blur 0.3-1.3 px per photo, shot noise with 3,000-40,000 electrons at
  full scale (log-uniform) and 2-10 e- read noise, vignetting 0-0.35, lit white at
  0.45-0.85 of full scale with exposures that differ between photos (log-normal,
  sigma 0-0.25), JPEG quality 65-98 or (a tenth) 16-bit PNG;
- ground: concrete or asphalt, with a white paper sheet along the shadow on 70 % of
  the plane receivers;
- sun source: from time and site (45 %), given in scene.toml (30 %), or left to the
  fitter (25 %);
- misdescription: 40 % of the groups are described right; the others get one error:
  the object's scale off by 2-15 %, its position by 1-5 cm, the given sun by 0.5-3 deg,
  the clock by 5-20 minutes, or a forced level of detail of 1-25 % of the mesh's faces
  (a fit option: ``fit_lod``).
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import trimesh

from softshadow import builtin_mesh

from .camera_pipeline import SensorSettings
from .lighting import SunSky
from .misdescription import Misdescription
from .presets import PhotoPlan, PresetPlan, ViewSpec
from .receivers import PlaneReceiver, rising_bank, steps_receiver, wall_receiver
from .renderers import RenderQuality
from .sun_site import site_and_time_for_sun
from .synth import posed_mesh, synthesize_plan
from .textures import PaperSheet

__all__ = ["ScenePrior", "SceneDraw", "PhotoDraw", "draw_parameters", "synthesize_draw", "draw_scene",
           "scene_plan", "object_mesh_for", "BUILTIN_DRAW_MESHES"]

#: Meshes a draw can name without handing one in: softshadow's built-ins ("knot" is the built-in
#: procedural trefoil tube that softshadow calls "dragon").
BUILTIN_DRAW_MESHES = {"pillar": "pillar", "ball": "ball", "knot": "dragon"}
_ALBEDO = {"pillar": (0.55, 0.52, 0.48), "ball": (0.7, 0.15, 0.1), "knot": (0.25, 0.45, 0.2)}
_OTHER_ALBEDO = (0.6, 0.58, 0.52)


@dataclasses.dataclass(frozen=True)
class ScenePrior:
    """The ranges a draw comes from (see the module's docstring). Pairs are (low, high);
    ``*_share`` are probabilities; dicts map a choice to its weight."""

    elevation_deg: tuple[float, float] = (8.0, 85.0)
    azimuth_deg: tuple[float, float] = (0.0, 360.0)
    pixels: tuple[int, int] = (320 * 240, 4000 * 3000)  # log-uniform, 4:3
    photos: tuple[int, int] = (1, 6)
    group_pixel_budget: float = 24e6  # photos x pixels at most this (fewer photos of large images)
    range_k: tuple[float, float] = (0.002, 0.03)  # log-uniform
    rho: tuple[float, float] = (0.03, 0.9)  # log-uniform
    meshes: tuple[str, ...] = ("pillar", "ball", "knot")
    object_scale: tuple[float, float] = (0.75, 1.33)  # log-uniform
    receivers: Mapping[str, float] = dataclasses.field(
        default_factory=lambda: {"plane": 0.5, "depth": 0.25, "mesh": 0.25})
    sun_sources: Mapping[str, float] = dataclasses.field(
        default_factory=lambda: {"time+site": 0.45, "given": 0.30, "fitted": 0.25})
    topdown_share: float = 0.2  # of the photos on a plane receiver
    blur_px: tuple[float, float] = (0.3, 1.3)
    full_well_e: tuple[float, float] = (3000.0, 40000.0)  # log-uniform
    read_noise_e: tuple[float, float] = (2.0, 10.0)
    vignetting: tuple[float, float] = (0.0, 0.35)
    exposure_white: tuple[float, float] = (0.45, 0.85)
    exposure_spread: tuple[float, float] = (0.0, 0.25)  # sigma of the log gain between photos
    jpeg_quality: tuple[int, int] = (65, 98)
    png_share: float = 0.1
    textures: tuple[str, ...] = ("concrete", "asphalt")
    paper_share: float = 0.7  # of the plane receivers
    photo_spacing_s: tuple[float, float] = (20.0, 90.0)
    frame_shadow_m: tuple[float, float] = (2.5, 5.0)  # how much of the shadow's length a photo frames
    well_described_share: float = 0.4
    misdescription_weights: Mapping[str, float] = dataclasses.field(
        default_factory=lambda: {"scale": 1.0, "position": 1.0, "lod": 1.0, "sun": 2.0, "clock": 2.0})
    scale_error: tuple[float, float] = (0.02, 0.15)  # relative, either sign
    position_error_m: tuple[float, float] = (0.01, 0.05)  # horizontal, any direction
    sun_error_deg: tuple[float, float] = (0.5, 3.0)  # angular distance, any direction (given suns only)
    clock_error_min: tuple[float, float] = (5.0, 20.0)  # either sign (suns from time and site only)
    lod_fraction: tuple[float, float] = (0.01, 0.25)  # of the mesh's faces, log-uniform, at least lod_min_faces
    lod_min_faces: int = 60

    def to_json(self) -> dict:
        return {f.name: (dict(v) if isinstance(v := getattr(self, f.name), Mapping) else v)
                for f in dataclasses.fields(self)}


@dataclasses.dataclass(frozen=True)
class PhotoDraw:
    """One photo: seconds after the group's first, view, and camera."""

    seconds: float
    view: str  # "handheld" or "topdown"
    bearing_deg: float
    eye_height_m: float
    fov_x_deg: float
    roll_deg: float
    aim_jitter_m: tuple[float, float]
    blur_px: float
    exposure_gain: float


@dataclasses.dataclass(frozen=True)
class SceneDraw:
    """Every random choice of one group (JSON-ready). ``photo_draws`` are the photos; the
    rendered size is (width, height); ``misdescription`` what the folder gets wrong."""

    render_seed: int
    sun_azimuth_deg: float  # the first photo's sun (from site and time)
    sun_elevation_deg: float
    site: dict
    time: str  # the first photo's local time, ISO 8601
    range_k: float
    rho: float
    mesh: str
    object_scale: float
    object_rotation_deg: float
    receiver: str  # "plane", "depth" or "mesh"
    receiver_shape: str  # "plane", "bank", "steps" or "wall"
    receiver_fallback: bool  # the drawn receiver could not be reached by the shadow: the plane instead
    receiver_start_m: float | None
    receiver_rise_m: float | None
    receiver_bump_m: float | None
    sun_source: str  # "time+site", "given" or "fitted"
    width: int
    height: int
    photos_drawn: int
    photo_draws: tuple[PhotoDraw, ...]
    exposure_white: float
    exposure_spread: float
    vignetting: float
    full_well_e: float
    read_noise_e: float
    fmt: str
    jpeg_quality: int
    texture: str
    paper: bool
    frame_shadow_m: float
    misdescription: str | None  # None (well described), or one of scale, position, sun, clock, lod
    scale_factor: float = 1.0
    position_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sun_offset_deg: tuple[float, float] = (0.0, 0.0)
    clock_offset_s: float = 0.0
    fit_lod: int | None = None  # a forced level of detail (faces) for the fit; None: the default

    @property
    def photos(self) -> int:
        return len(self.photo_draws)

    @property
    def sun_radius_deg(self) -> float:
        return math.degrees(math.atan(self.range_k))

    @property
    def description(self) -> Misdescription:
        return Misdescription(self.scale_factor, tuple(self.position_offset_m), tuple(self.sun_offset_deg),
                              self.clock_offset_s)

    def to_json(self) -> dict:
        out = dataclasses.asdict(self)
        out["photo_draws"] = [dataclasses.asdict(p) for p in self.photo_draws]
        return out

    @classmethod
    def from_json(cls, data: dict) -> "SceneDraw":
        data = dict(data)
        data["photo_draws"] = tuple(PhotoDraw(**{**p, "aim_jitter_m": tuple(p["aim_jitter_m"])})
                                    for p in data["photo_draws"])
        for key in ("position_offset_m", "sun_offset_deg"):
            data[key] = tuple(data[key])
        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in data.items() if k in names})


def object_mesh_for(name: str, meshes: Mapping[str, trimesh.Trimesh] | None = None) -> trimesh.Trimesh:
    """The unposed mesh of a draw's object: a handed-in mesh by name, else a built-in."""
    if meshes and name in meshes:
        return meshes[name]
    if name in BUILTIN_DRAW_MESHES:
        return builtin_mesh(BUILTIN_DRAW_MESHES[name])
    raise ValueError(f"unknown mesh {name!r}: hand it in (meshes={{{name!r}: trimesh}}) or choose one of "
                     f"{sorted(BUILTIN_DRAW_MESHES)}")


def _log_uniform(rng, lo, hi) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _choice(rng, weights: Mapping[str, float]) -> str:
    names = list(weights)
    p = np.array([weights[n] for n in names], dtype=float)
    return names[int(rng.choice(len(names), p=p / p.sum()))]


def _sun_vector(az, el) -> np.ndarray:
    a, e = math.radians(az), math.radians(el)
    return np.array([math.sin(a) * math.cos(e), math.cos(a) * math.cos(e), math.sin(e)])


def _shadow_axes(az: float) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal unit vectors along the shadow (away from the sun) and across it (2,) each."""
    a = math.radians(az + 180.0)
    along = np.array([math.sin(a), math.cos(a)])
    return along, np.array([-along[1], along[0]])


def _ground_shadow_span(mesh: trimesh.Trimesh, az: float, el: float) -> tuple[float, float, float]:
    """The object's shadow on z = 0 along its direction: (nearest, farthest) distance from the
    origin, and the object's horizontal reach (its largest distance from the z axis), metres."""
    v = np.asarray(mesh.vertices)
    s = _sun_vector(az, el)
    ground = v[:, :2] - (v[:, 2:3] / s[2]) * s[None, :2]
    along, _ = _shadow_axes(az)
    t = ground @ along
    return float(t.min()), float(t.max()), float(np.hypot(v[:, 0], v[:, 1]).max())


def _receiver_placement(rng, prior: ScenePrior, kind: str, mesh: trimesh.Trimesh, az: float, el: float,
                        radius_deg: float):
    """(shape, start_m, rise_m, bump_m, fallback) of the drawn receiver kind: where the bank, the
    steps or the wall begin along the shadow, and the bank's rise and bumps (within what the sun
    allows: a height field must not shadow itself)."""
    if kind == "plane":
        return "plane", None, None, None, False
    near, far, reach = _ground_shadow_span(mesh, az, el)
    start = max(reach + 0.2, near + float(rng.uniform(0.2, 0.5)) * (far - near))
    shape = "bank" if kind == "depth" else ("steps" if rng.uniform() < 0.5 else "wall")
    if far - start < 0.25:
        return shape, None, None, None, True
    if shape != "bank":
        return shape, round(start, 4), None, None, False
    # No self-shadow: the slope stays under 0.75 of tan(elevation - radius). Bumps of b metres add at
    # most 3.5 b; they take a quarter of the allowance, up to 0.02 m.
    allowed = 0.75 * math.tan(math.radians(el - radius_deg))
    bump = min(0.02, 0.25 * allowed / 3.5)
    rise = min(float(rng.uniform(0.2, 0.6)), (allowed - 3.5 * bump) * 1.6 / 1.5)
    if rise < 0.04:
        return shape, None, None, None, True
    return shape, round(start, 4), round(rise, 4), round(bump, 5), False


def draw_parameters(rng: np.random.Generator, prior: ScenePrior = ScenePrior(),
                    meshes: Mapping[str, trimesh.Trimesh] | None = None) -> SceneDraw:
    """Draw one group from ``prior`` (see the module's docstring); ``meshes`` names the meshes
    beyond the built-ins (for example {"dragon": the real dragon, z up, on the ground})."""
    az = float(rng.uniform(*prior.azimuth_deg)) % 360.0
    el = float(rng.uniform(*prior.elevation_deg))
    site, when, (az, el) = site_and_time_for_sun(az, el, rng)
    k = _log_uniform(rng, *prior.range_k)
    rho = _log_uniform(rng, *prior.rho)
    radius = math.degrees(math.atan(k))
    mesh_name = prior.meshes[int(rng.integers(len(prior.meshes)))]
    scale = _log_uniform(rng, *prior.object_scale)
    rotation = float(rng.uniform(0.0, 360.0))
    posed = posed_mesh(object_mesh_for(mesh_name, meshes), (0, 0, 0), (0, 0, rotation), scale)
    kind = _choice(rng, prior.receivers)
    shape, start, rise, bump, fallback = _receiver_placement(rng, prior, kind, posed, az, el, radius)
    if fallback:
        shape = "plane"
    source = _choice(rng, prior.sun_sources)
    pixels = _log_uniform(rng, *prior.pixels)
    width = int(min(max(round(math.sqrt(pixels * 4 / 3) / 8) * 8, 320), 4000))
    height = int(round(width * 3 / 4))
    drawn = int(rng.integers(prior.photos[0], prior.photos[1] + 1))
    n = max(1, min(drawn, int(prior.group_pixel_budget // (width * height))))
    white = float(rng.uniform(*prior.exposure_white))
    spread = float(rng.uniform(*prior.exposure_spread))
    photos = []
    seconds = 0.0
    along_az = (az + 180.0) % 360.0
    for i in range(n):
        if i:
            seconds += float(rng.uniform(*prior.photo_spacing_s))
        side = 1.0 if rng.uniform() < 0.5 else -1.0
        if shape in ("steps", "wall"):
            # Facing the lit risers or wall, 40-75 deg off the sun's azimuth: nearer the sun's
            # direction a bulky object hides its own shadow.
            bearing = along_az + side * float(rng.uniform(105.0, 140.0))
        else:
            bearing = along_az + side * (90.0 + float(rng.uniform(-55.0, 55.0)))
        topdown = shape == "plane" and rng.uniform() < prior.topdown_share
        gain = float(np.exp(rng.normal(0.0, spread))) if spread > 0 else 1.0
        gain = min(gain, 0.97 / white)
        photos.append(PhotoDraw(
            seconds=round(seconds, 1), view="topdown" if topdown else "handheld", bearing_deg=round(bearing % 360, 3),
            eye_height_m=round(float(rng.uniform(1.5, 2.1)), 3), fov_x_deg=round(float(rng.uniform(50.0, 72.0)), 2),
            roll_deg=round(float(rng.normal(0.0, 2.0)), 3),
            aim_jitter_m=(round(float(rng.normal(0, 0.08)), 4), round(float(rng.normal(0, 0.08)), 4)),
            blur_px=round(float(rng.uniform(*prior.blur_px)), 4), exposure_gain=round(gain, 5)))
    png = rng.uniform() < prior.png_share
    quality = int(rng.integers(prior.jpeg_quality[0], prior.jpeg_quality[1] + 1))
    texture = prior.textures[int(rng.integers(len(prior.textures)))]
    paper = shape == "plane" and rng.uniform() < prior.paper_share
    frame = float(rng.uniform(*prior.frame_shadow_m))
    fields = dict(scale_factor=1.0, position_offset_m=(0.0, 0.0, 0.0), sun_offset_deg=(0.0, 0.0),
                  clock_offset_s=0.0, fit_lod=None)
    kind_wrong = None
    if rng.uniform() >= prior.well_described_share:
        weights = {name: w for name, w in prior.misdescription_weights.items()
                   if not (name == "sun" and source != "given") and not (name == "clock" and source != "time+site")}
        kind_wrong = _choice(rng, weights)
        sign = 1.0 if rng.uniform() < 0.5 else -1.0
        if kind_wrong == "scale":
            fields["scale_factor"] = round(1.0 + sign * float(rng.uniform(*prior.scale_error)), 5)
        elif kind_wrong == "position":
            m, a = float(rng.uniform(*prior.position_error_m)), float(rng.uniform(0, 2 * math.pi))
            fields["position_offset_m"] = (round(m * math.cos(a), 5), round(m * math.sin(a), 5), 0.0)
        elif kind_wrong == "sun":
            m, a = float(rng.uniform(*prior.sun_error_deg)), float(rng.uniform(0, 2 * math.pi))
            fields["sun_offset_deg"] = (round(m * math.cos(a) / math.cos(math.radians(el)), 5),
                                        round(m * math.sin(a), 5))
        elif kind_wrong == "clock":
            fields["clock_offset_s"] = round(sign * 60.0 * float(rng.uniform(*prior.clock_error_min)), 1)
        else:
            faces = len(posed.faces)
            lo = max(float(prior.lod_min_faces), prior.lod_fraction[0] * faces)
            hi = max(lo, prior.lod_fraction[1] * faces)
            fields["fit_lod"] = int(round(_log_uniform(rng, lo, hi)))
    return SceneDraw(
        render_seed=int(rng.integers(0, 2 ** 31 - 1)), sun_azimuth_deg=round(az, 6), sun_elevation_deg=round(el, 6),
        site=site, time=when.isoformat(), range_k=round(k, 7), rho=round(rho, 6), mesh=mesh_name,
        object_scale=round(scale, 5), object_rotation_deg=round(rotation, 4), receiver=kind, receiver_shape=shape,
        receiver_fallback=fallback, receiver_start_m=start, receiver_rise_m=rise, receiver_bump_m=bump, sun_source=source,
        width=width, height=height, photos_drawn=drawn, photo_draws=tuple(photos), exposure_white=round(white, 5),
        exposure_spread=round(spread, 5), vignetting=round(float(rng.uniform(*prior.vignetting)), 4),
        full_well_e=round(_log_uniform(rng, *prior.full_well_e), 1),
        read_noise_e=round(float(rng.uniform(*prior.read_noise_e)), 3), fmt="png" if png else "jpg",
        jpeg_quality=quality, texture=texture, paper=bool(paper), frame_shadow_m=round(frame, 3),
        misdescription=kind_wrong, **fields)


def _receiver_object(draw: SceneDraw, framed_centre):
    along_az = (draw.sun_azimuth_deg + 180.0) % 360.0
    if draw.receiver_shape == "bank":
        half = max(8.0, draw.frame_shadow_m + 5.0)
        return rising_bank(along_az, draw.receiver_start_m, draw.receiver_rise_m, bump_m=draw.receiver_bump_m,
                           centre_xy=framed_centre, half_extent_m=half)
    if draw.receiver_shape == "steps":
        return steps_receiver(along_az, start_m=draw.receiver_start_m)
    if draw.receiver_shape == "wall":
        return wall_receiver(along_az, distance_m=draw.receiver_start_m)
    return PlaneReceiver()


def _shadow_points(mesh: trimesh.Trimesh, receiver, sun: np.ndarray, max_points: int = 3000) -> np.ndarray:
    """Where rays from the object's vertices along the light meet the receiver (N, 3)."""
    v = np.asarray(mesh.vertices)
    if len(v) > max_points:
        v = v[np.linspace(0, len(v) - 1, max_points).astype(int)]
    if receiver.mesh is None:
        return np.concatenate([v[:, :2] - (v[:, 2:3] / sun[2]) * sun[None, :2], np.zeros((len(v), 1))], 1)
    origins = v - 1e-3 * sun  # start just off the surface, towards the ground
    directions = np.broadcast_to(-sun, origins.shape).copy()
    loc, ray, _ = receiver.mesh.ray.intersects_location(origins, directions, multiple_hits=False)
    return np.asarray(loc)


def _key_points(draw: SceneDraw, mesh: trimesh.Trimesh, receiver, sun: np.ndarray) -> np.ndarray:
    """What each photo frames: the object's shadow on the receiver over ``frame_shadow_m`` of its
    length from its near end (and the object's foot when its shadow starts within 1.5 m)."""
    along, across = _shadow_axes(draw.sun_azimuth_deg)
    pts = _shadow_points(mesh, receiver, sun)
    if len(pts) == 0:
        raise ValueError("the object's shadow misses the receiver")
    t = pts[:, :2] @ along
    near = float(t.min())
    keep = pts[t <= near + draw.frame_shadow_m]
    c = keep[:, :2] @ across
    tk = keep[:, :2] @ along
    corners = []
    for sel in (np.argmin(c), np.argmax(c), np.argmin(tk), np.argmax(tk)):
        corners.append(keep[sel])
    # The framed stretch's box, widened 0.3 m across and along (a margin for the penumbra).
    box = []
    for tt in (float(tk.min()) - 0.3, float(tk.max()) + 0.3):
        for cc in (float(c.min()) - 0.3, float(c.max()) + 0.3):
            xy = along * tt + across * cc
            z = float(np.interp(tt, np.sort(tk), keep[np.argsort(tk), 2]))
            box.append([xy[0], xy[1], z])
    out = [np.array(corners), np.array(box)]
    if near < 1.5:
        v = np.asarray(mesh.vertices)
        foot = v[v[:, 2] < v[:, 2].min() + 0.05]
        if len(foot):
            lo, hi = foot[:, :2].min(0), foot[:, :2].max(0)
            out.append(np.array([[x, y, 0.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])]))
    if draw.receiver_shape in ("steps", "wall"):
        # Frame a stretch of the receiver beside the shadow too (it is what the camera aims at).
        s = draw.receiver_start_m
        extra = [[*(along * (s + 0.1) + across * a), 0.0] for a in (-0.8, 0.8)]
        out.append(np.array(extra))
    return np.concatenate(out)


def _paper(draw: SceneDraw, keys: np.ndarray) -> PaperSheet:
    """A white sheet along the framed stretch of the shadow (its box, 0.3 m beyond each way)."""
    along, across = _shadow_axes(draw.sun_azimuth_deg)
    t = keys[:, :2] @ along
    c = keys[:, :2] @ across
    length, width = float(t.max() - t.min()), float(c.max() - c.min())
    centre = along * (t.max() + t.min()) / 2 + across * (c.max() + c.min()) / 2
    return PaperSheet((float(centre[0]), float(centre[1])), (length, width), (draw.sun_azimuth_deg + 180.0) % 360)


def scene_plan(draw: SceneDraw, meshes: Mapping[str, trimesh.Trimesh] | None = None
               ) -> tuple[PresetPlan, trimesh.Trimesh | None]:
    """The draw as a ``PresetPlan`` (and the object's mesh when it is not a built-in)."""
    from zoneinfo import ZoneInfo
    from scene import solar_position
    unposed = object_mesh_for(draw.mesh, meshes)
    rotation = (0.0, 0.0, draw.object_rotation_deg)
    posed = posed_mesh(unposed, (0, 0, 0), rotation, draw.object_scale)
    sun = _sun_vector(draw.sun_azimuth_deg, draw.sun_elevation_deg)
    receiver = _receiver_object(draw, (0.0, 0.0))
    if draw.receiver_shape == "bank":
        # Centre the bank's mesh on the framed shadow (it covers a square around it).
        keys0 = _key_points(draw, posed, PlaneReceiver(), sun)
        receiver = _receiver_object(draw, tuple(keys0[:, :2].mean(0)))
    keys = _key_points(draw, posed, receiver, sun)
    papers = (_paper(draw, keys),) if draw.paper else ()
    t0 = _dt.datetime.fromisoformat(draw.time)
    zone = ZoneInfo(draw.site["timezone"])
    light0 = SunSky.from_rho(draw.sun_azimuth_deg, draw.sun_elevation_deg, draw.rho, draw.sun_radius_deg)
    photos = []
    for i, p in enumerate(draw.photo_draws):
        when = (t0 + _dt.timedelta(seconds=p.seconds)).astimezone(zone)
        az, el = (draw.sun_azimuth_deg, draw.sun_elevation_deg) if i == 0 else solar_position(
            when, draw.site["latitude"], draw.site["longitude"])
        light = light0 if i == 0 else SunSky.from_rho(az, el, draw.rho, draw.sun_radius_deg)
        if p.view == "topdown":
            view = ViewSpec("topdown")
        else:
            view = ViewSpec("handheld", bearing_deg=p.bearing_deg, eye_height_m=p.eye_height_m, fov_x_deg=p.fov_x_deg,
                            roll_deg=p.roll_deg, aim_jitter_m=tuple(p.aim_jitter_m),
                            min_distance_m=1.5 if draw.receiver_shape == "plane" else 3.0)
        sensor = SensorSettings(exposure_white=draw.exposure_white, vignetting=draw.vignetting,
                                blur_sigma_px=p.blur_px, full_well_e=draw.full_well_e, read_noise_e=draw.read_noise_e)
        photos.append(PhotoPlan(f"IMG_{i + 1:04d}", "group", light, view, keys, when, papers=papers,
                                texture=draw.texture, exposure_gain=p.exposure_gain, sensor=sensor))
    name = draw.mesh if draw.mesh in BUILTIN_DRAW_MESHES and not (meshes and draw.mesh in meshes) else None
    plan = PresetPlan(
        "drawn", BUILTIN_DRAW_MESHES[name] if name else draw.mesh, _ALBEDO.get(draw.mesh, _OTHER_ALBEDO),
        tuple(photos), (draw.width, draw.height), rotation_deg=rotation, scale=draw.object_scale, receiver=receiver,
        receiver_azimuth_deg=(draw.sun_azimuth_deg + 180.0) % 360.0, site=dict(draw.site),
        write_sun=draw.sun_source == "given", fmt=draw.fmt, write_site=draw.sun_source == "time+site",
        description=draw.description)
    return plan, (None if name else unposed)


def synthesize_draw(draw: SceneDraw, out_dir, *, meshes: Mapping[str, trimesh.Trimesh] | None = None,
                    render_quality: RenderQuality | None = None, progress: bool = False,
                    force: bool = False) -> Path:
    """Render a draw into a photo folder (physical renderer); truth.json carries the draw
    (``draw``) beside the truth, and the forced level of detail when there is one."""
    import json
    plan, mesh = scene_plan(draw, meshes)
    out = synthesize_plan(out_dir, plan, seed=draw.render_seed, renderer="physical", fmt=draw.fmt,
                          quality=draw.jpeg_quality, progress=progress, force=force, render_quality=render_quality,
                          object_mesh=mesh)
    truth_path = Path(out) / "truth.json"
    truth = json.loads(truth_path.read_text())
    truth["draw"] = draw.to_json()
    truth["fit_options"] = {"lod": draw.fit_lod} if draw.fit_lod is not None else {}
    truth_path.write_text(json.dumps(truth, indent=1), encoding="utf-8")
    return out


def draw_scene(rng: np.random.Generator, prior: ScenePrior = ScenePrior(), out_dir=None, *,
               meshes: Mapping[str, trimesh.Trimesh] | None = None, render_quality: RenderQuality | None = None,
               force: bool = False) -> Path:
    """Draw one group from ``prior`` and render it into ``out_dir`` (see ``draw_parameters`` and
    ``synthesize_draw``); returns the folder."""
    if out_dir is None:
        raise ValueError("draw_scene needs out_dir, the folder to write")
    draw = draw_parameters(rng, prior, meshes)
    return synthesize_draw(draw, out_dir, meshes=meshes, render_quality=render_quality, force=force)
