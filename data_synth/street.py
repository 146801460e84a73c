"""Preset ``street``: an ordinary street photo with truth, rendered by the ray-casting renderer.

What a person photographs on a sunny late afternoon: the camera held level at
eye height looks along the long shadows of two people and two poles, over a
street whose ground changes material (gravel, asphalt with white paint, a
concrete kerb, grass), towards facades and trees with the sky (and clouds)
above them. Everything that casts or receives light goes through
``PhysicalRenderer`` (sun disk plus uniform sky, ray cast): the shadows have
the sun's real penumbra (wide, far from the contact points), the facades and
trees are in the scene (they hide part of the sky from the ground near them),
and the albedo edges (paint, kerb, material borders) are not shadows.

Simplifications, stated: the light is grey (the sky's radiance is uniform and
has the sun's colour, so umbrae are not bluer here); clouds are painted on the
sky pixels (their radiance does not light the scene); the ground is the plane
z = 0.

There is no ``scene.toml``: this is the single-photo case (no geometry), so
``softshadow fit`` measures rho and the penumbra width per photo. truth.json
holds, per photo (one group each): ``rho`` (open-ground truth,
E_sky / (E_sun + E_sky)) and ``rho_umbra`` (the median of the same ratio over
the umbra pixels in view, where the occluders hide some sky as well).
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import time
from pathlib import Path

import numpy as np
import trimesh
from scipy import ndimage

from scene import solar_position

from .camera_pipeline import SensorSettings, camera_pipeline, handheld_camera
from .image_io import PhotoMetadata, write_photo
from .lighting import SunSky
from .physical import combined_mesh
from .presets import IWATE, TOKYO
from .receivers import PlaneReceiver
from .renderers import RenderQuality, SynthScene, make_renderer
from .tracing import KIND_RECEIVER, pinhole_rays

__all__ = ["StreetGround", "street_scene", "synthesize_street"]

STREET_SIZE = (1024, 768)
SUN_RADIUS_DEG = 0.2665
TEXTURE_PX = 512            # tileable texture side (texels)
TEXEL_M = 0.004             # ground size of a texel: textures repeat every 2.05 m


def _tileable_noise(rng: np.random.Generator, scale_texel: float) -> np.ndarray:
    """Unit-variance Gaussian noise (TEXTURE_PX, TEXTURE_PX) smoothed at scale_texel, periodic."""
    n = ndimage.gaussian_filter(rng.standard_normal((TEXTURE_PX, TEXTURE_PX)), scale_texel, mode="wrap")
    return n / n.std()


class StreetGround:
    """Ground albedo of the street by zone (world metres; the street runs along the camera's view, +v).

    Across the street (coordinate ``u`` along ``across``, metres from the centre line):
    asphalt for |u| < 3 with white dashed lane paint at |u| < 0.06; a concrete
    kerb 3 <= u < 3.25; gravel beyond it; grass at u <= -3. Each material
    has its own texture (gravel: pebbles, 0.3 log units; asphalt: fine
    aggregate; grass: blades and clumps; concrete: smooth).
    """

    def __init__(self, rng: np.random.Generator, centre_xy, across_xy):
        self.centre = np.asarray(centre_xy, float)
        self.across = np.asarray(across_xy, float) / np.linalg.norm(across_xy)
        self.along = np.array([-self.across[1], self.across[0]])
        pebbles = 0.6 * _tileable_noise(rng, 0.7) + 0.8 * _tileable_noise(rng, 2.5) + 0.5 * _tileable_noise(rng, 6)
        self.gravel = np.exp(0.3 * pebbles / pebbles.std())[..., None] * np.array([0.42, 0.39, 0.34])
        aggregate = _tileable_noise(rng, 0.6)
        self.asphalt = (0.12 * np.exp(0.15 * aggregate) + 0.1 * (aggregate > 2.0))[..., None] * np.ones(3)
        blades = 0.5 * _tileable_noise(rng, 0.8) + 0.7 * _tileable_noise(rng, 4.0)
        self.grass = np.exp(0.35 * blades / blades.std())[..., None] * np.array([0.08, 0.16, 0.05])
        self.concrete = (0.45 * np.exp(0.04 * _tileable_noise(rng, 1.0)))[..., None] * np.array([1.0, 0.99, 0.95])
        self.paint = (0.8 * np.exp(0.03 * _tileable_noise(rng, 1.0)))[..., None] * np.ones(3)

    def reflectance(self, xy: np.ndarray) -> np.ndarray:
        """Linear RGB albedo (N, 3) float32 at world points xy (N, 2 or 3)."""
        xy = np.asarray(xy, float).reshape(len(xy), -1)[:, :2]
        rel = xy - self.centre
        u, v = rel @ self.across, rel @ self.along
        col = np.mod(np.rint(xy[:, 0] / TEXEL_M), TEXTURE_PX).astype(int)
        row = np.mod(np.rint(-xy[:, 1] / TEXEL_M), TEXTURE_PX).astype(int)
        out = self.asphalt[row, col]
        for zone, tex in (((u >= 3.0) & (u < 3.25), self.concrete), (u >= 3.25, self.gravel),
                          (u <= -3.0, self.grass),
                          ((np.abs(u) < 0.06) & (np.mod(v, 3.0) < 1.5), self.paint)):
            out[zone] = tex[row[zone], col[zone]]
        return out.astype(np.float32)


def _person(x, y, height=1.75) -> trimesh.Trimesh:
    body = trimesh.creation.cylinder(radius=0.18, height=height - 0.25, sections=16)
    body.apply_translation([x, y, (height - 0.25) / 2])
    head = trimesh.creation.icosphere(subdivisions=2, radius=0.11)
    head.apply_translation([x, y, height - 0.12])
    person: trimesh.Trimesh = trimesh.util.concatenate([body, head])  # trimesh annotates it as any Geometry
    return person


def _pole(x, y, height) -> trimesh.Trimesh:
    pole = trimesh.creation.cylinder(radius=0.05, height=height, sections=12)
    pole.apply_translation([x, y, height / 2])
    return pole


def _tree(x, y) -> trimesh.Trimesh:
    trunk = trimesh.creation.cylinder(radius=0.15, height=3.0, sections=10)
    trunk.apply_translation([x, y, 1.5])
    crown = trimesh.creation.icosphere(subdivisions=2, radius=1.8)
    crown.apply_translation([x, y, 4.2])
    tree: trimesh.Trimesh = trimesh.util.concatenate([trunk, crown])  # trimesh annotates it as any Geometry
    return tree


def _facade(centre_xy, across_xy, width, height, depth=6.0) -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=[width, depth, height])
    angle = math.atan2(across_xy[1], across_xy[0])
    box.apply_transform(trimesh.transformations.rotation_matrix(angle, [0, 0, 1]))
    box.apply_translation([centre_xy[0], centre_xy[1], height / 2])
    return box


def street_scene(seed: int):
    """(light, occluders mesh, ground, camera factory, local time) of one street photo, from the seed."""
    rng = np.random.default_rng([seed, 31])
    minute = int(rng.integers(16 * 60, 17 * 60 + 10))             # late afternoon: long shadows
    when = _dt.datetime(2026, 4, 20, minute // 60, minute % 60, tzinfo=TOKYO)
    az, el = solar_position(when, IWATE["latitude"], IWATE["longitude"])
    rho = float(rng.uniform(0.15, 0.35))
    light = SunSky.from_rho(az, el, rho, radius_deg=SUN_RADIUS_DEG * float(rng.uniform(1.0, 1.3)))
    # The camera looks along the shadows (away from the sun), from 4 m behind the people.
    away = -np.array([math.sin(math.radians(az)), math.cos(math.radians(az))])
    across = np.array([away[1], -away[0]])
    people = [np.array([0.0, 0.0]) + s * across + f * away
              for s, f in ((rng.uniform(1.8, 2.6), rng.uniform(0.0, 1.0)), (rng.uniform(4.2, 5.0), 0.5))]
    poles = [rng.uniform(-0.8, -0.3) * across + 2.5 * away, rng.uniform(3.5, 4.5) * across + 5.0 * away]
    parts = [_person(x, y, height=float(rng.uniform(1.6, 1.9))) for x, y in people]
    parts += [_pole(x, y, height=float(rng.uniform(3.5, 5.0))) for x, y in poles]
    far = 24.0 * away
    parts += [_facade(far + 8.0 * across, across, 12.0, float(rng.uniform(6, 10))),
              _facade(far - 9.0 * across, across, 8.0, float(rng.uniform(5, 8)))]
    parts += [_tree(*(18.0 * away + 2.0 * across)), _tree(*(18.0 * away - 5.0 * across))]
    mesh = combined_mesh(*parts)
    ground = StreetGround(rng, centre_xy=(0.0, 0.0), across_xy=across)
    eye = np.array([*(1.5 * across - 4.0 * away)])
    bearing = math.degrees(math.atan2(-away[0], -away[1]))
    aim = 12.0 * away + 1.5 * across

    def camera(width, height):
        target = np.array([aim[0], aim[1], 0.0])
        distance = float(np.linalg.norm(aim - eye))
        return handheld_camera(target, bearing, distance, 1.6, width, height, fov_x_deg=66.0,
                               roll_deg=float(rng.uniform(-1.0, 1.0)))

    return light, mesh, ground, camera, when


def _sky(rays_dir: np.ndarray, rng: np.random.Generator, lit: float) -> np.ndarray:
    """Blue sky with white clouds (N, 3) for view directions (N, 3): appearance only."""
    z = np.maximum(rays_dir[:, 2], 0.02)
    blue = np.stack([0.35 + 0.25 * (1 - z), 0.5 + 0.2 * (1 - z), 0.95 + 0.0 * z], axis=1)
    field = _tileable_noise(rng, 12.0)
    u = np.mod(rays_dir[:, 0] / z * 60.0, TEXTURE_PX).astype(int)
    v = np.mod(rays_dir[:, 1] / z * 60.0, TEXTURE_PX).astype(int)
    cloud = np.clip((field[v, u] - 0.4) * 1.2, 0.0, 1.0)[:, None]
    return (lit * 1.1 * ((1 - cloud) * blue + cloud * 1.25)).astype(np.float32)


def synthesize_street(out_dir, seed: int = 0, size: tuple[int, int] | None = None, fmt: str = "jpg",
                      quality: int = 92, render_quality: RenderQuality | None = None, noise: bool = True) -> Path:
    """Render one street photo (``street_<seed>.<fmt>``) and truth.json into out_dir (created if needed)."""
    t_start = time.perf_counter()
    width, height = (int(v) for v in (size or STREET_SIZE))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    light, mesh, ground, make_camera, when = street_scene(seed)
    camera = make_camera(width, height)
    rays = pinhole_rays(camera)
    renderer = make_renderer("physical", SynthScene(mesh, (0.35, 0.33, 0.3), PlaneReceiver()),
                             render_quality or RenderQuality(), seed)
    rng = np.random.default_rng([seed, 7])
    render = renderer.render(rays, light, ground, rng)
    radiance = render.radiance.reshape(-1, 3)
    sky = render.kind.ravel() == 0
    radiance[sky] = _sky(rays.directions[sky], np.random.default_rng([seed, 5]), light.lit_irradiance)
    sensor = SensorSettings() if noise else SensorSettings(full_well_e=1e12, read_noise_e=0.0)
    linear = camera_pipeline(radiance.reshape(height, width, 3), light.lit_irradiance, sensor, rng)
    name = f"street_{seed}.{fmt}"
    write_photo(out / name, linear, fmt, quality, PhotoMetadata(when, IWATE["latitude"], IWATE["longitude"]))
    e = render.irradiance
    on_ground = render.kind == KIND_RECEIVER
    umbra = on_ground & (e <= light.sky_horizontal_irradiance * 1.0001)
    rho_umbra = (float(np.median(e[umbra] / (light.sun_horizontal_irradiance + e[umbra])))
                 if umbra.any() else None)
    group = light.truth()
    group.update(label=name, photos=[name], rho_umbra=rho_umbra, umbra_pixels=int(umbra.sum()),
                 range_k=None, time=when.strftime("%H:%M"))
    truth = {"groups": [group], "preset": "street", "renderer": "physical", "seed": int(seed),
             "size": [width, height], "format": fmt, "files": [name, "truth.json"],
             "renderer_detail": "ray-cast sun disk + uniform grey sky (data_synth.physical); clouds painted",
             "seconds": time.perf_counter() - t_start}
    (out / "truth.json").write_text(json.dumps(truth, indent=1), encoding="utf-8")
    return out
