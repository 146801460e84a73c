"""``synthesize``: render a preset into a photo folder (images, scene.toml, truth.json).

Folder format as in docs/formats.md ("Photo folders", "scene.toml",
"softshadow synth"). truth.json holds, per group, the physical truth of the
light (range_k = tan(sun radius), rho = E_sky / (E_sun_h + E_sky) on open
ground), the group's sun, and its photos; plus per-photo details (exact time
and sun, camera, exposure, sensor) and the files written.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import json
import math
import time
from pathlib import Path
from typing import Literal

import numpy as np
import trimesh

from scene import CameraSpec, ObjectSpec, PhotoSpec, ReceiverSpec, SceneSpec, SiteSpec, dump_scene
from softshadow import GroundGrid, PinholeCamera, brightness_to_paper, builtin_mesh, load_mesh
from softshadow import one_blas_thread
from softshadow.internal import pose_matrix

from .camera_pipeline import camera_pipeline, fit_handheld_camera, topdown_grid
from .image_io import EXTENSIONS, FORMATS, PhotoMetadata, write_corrupt_jpeg, write_photo
from .presets import PresetPlan, PhotoPlan, build_preset
from .receivers import HeightfieldReceiver, MeshReceiver, PlaneReceiver, bank_terrain, steps_receiver, wall_receiver
from .renderers import RENDERERS, RenderQuality, SynthScene, make_renderer
from .textures import GroundAppearance, procedural_texture
from .tracing import pinhole_rays, topdown_rays

__all__ = ["synthesize", "synthesize_plan", "posed_mesh", "OutputExistsError"]

#: The renderers of a synthetic folder: "physical" (ray-cast sun disk and sky) or "model" (the fitted model).
Renderer = Literal["physical", "model"]
#: How the cameras are given: "explicit" (in scene.toml) or "markers" (a ChArUco board in view).
Cameras = Literal["explicit", "markers"]


class OutputExistsError(FileExistsError):
    """The output folder is not empty and overwriting was not allowed."""


def posed_mesh(name: str | trimesh.Trimesh, position, rotation_deg, scale: float) -> trimesh.Trimesh:
    """A built-in mesh (by name) or a trimesh placed in the world as softshadow.Pose does:
    x_world = R(rotation_deg) (scale x_mesh) + position."""
    mesh = name if isinstance(name, trimesh.Trimesh) else builtin_mesh(name)
    R = pose_matrix(rotation_deg)
    v = (float(scale) * np.asarray(mesh.vertices)) @ R.T + np.asarray(position, dtype=np.float64)
    return trimesh.Trimesh(v, np.asarray(mesh.faces), process=False)


RECEIVER_MESH_FILE = "receiver.ply"
#: The object's mesh, written into the folder when ``synthesize`` is given one (``object_mesh``).
OBJECT_MESH_FILE = "object.ply"


def _receiver(plan: PresetPlan):
    """The preset's receiver: the plane, the bank (a height field), a mesh (steps, wall), or the
    receiver object the plan carries."""
    if not isinstance(plan.receiver, str):
        return plan.receiver
    if plan.receiver == "bank":
        return bank_terrain()
    if plan.receiver == "steps":
        return steps_receiver(plan.receiver_azimuth_deg)
    if plan.receiver == "wall":
        return wall_receiver(plan.receiver_azimuth_deg)
    return PlaneReceiver()


def _prepare_out_dir(out_dir: Path, force: bool) -> None:
    """Refuse a non-empty folder unless forced; when forced, remove only what a previous
    synthesis wrote there (listed in its truth.json), never anything else."""
    if out_dir.exists() and not out_dir.is_dir():
        raise OutputExistsError(f"{out_dir} exists and is not a folder")
    if out_dir.exists() and any(out_dir.iterdir()):
        if not force:
            raise OutputExistsError(f"{out_dir} is not empty; use --force to write into it")
        truth = out_dir / "truth.json"
        if truth.exists():
            try:
                listed = json.loads(truth.read_text()).get("files", [])
            except (OSError, ValueError):
                listed = []
            for name in listed:
                p = out_dir / Path(name).name
                if p.is_file():
                    p.unlink()
    out_dir.mkdir(parents=True, exist_ok=True)


def _camera(photo: PhotoPlan, size) -> tuple[PinholeCamera | GroundGrid, CameraSpec]:
    w, h = size
    v = photo.view
    if v.kind == "topdown":
        keys = photo.key_points[:, :2]
        lo, hi = keys.min(0), keys.max(0)
        centre = (lo + hi) / 2
        if v.topdown_extent_m is not None:
            pixel_m = v.topdown_extent_m / w
        else:
            ext = (hi - lo) * (1 + 2 * v.margin)
            pixel_m = max(ext[0] / w, ext[1] / h)
        grid = topdown_grid(centre, w, h, pixel_m)
        return grid, CameraSpec(kind="topdown", pixel_m=grid.pixel_m, origin_m=grid.origin_m)
    cam = fit_handheld_camera(photo.key_points, v.bearing_deg, v.eye_height_m, w, h, v.fov_x_deg, v.margin,
                              v.roll_deg, v.aim_jitter_m, v.min_distance_m)
    return cam, CameraSpec(kind="explicit", K=cam.K.tolist(), R=cam.R.tolist(), t=cam.t.tolist())


def _penumbra_px(photo: PhotoPlan, mesh: trimesh.Trimesh, camera) -> float:
    """Widest geometric penumbra of the object on the ground (2 d tan r / sin(el), d its
    top's distance along the light) over the ground size of a pixel near the base: a
    rough figure for 'is the penumbra resolved' (recorded in truth.json)."""
    top = float(mesh.bounds[1, 2])
    el = math.radians(photo.light.elevation_deg)
    width_m = 2 * top / math.sin(el) * math.tan(photo.light.radius_rad) / math.sin(el)
    if isinstance(camera, GroundGrid):
        return width_m / camera.pixel_m
    depth = float(np.linalg.norm(camera.centre - np.array([0.0, 0.0, 0.0])))
    return width_m / (depth / camera.K[0, 0])


def _depth_image(camera: PinholeCamera, render) -> np.ndarray:
    """z-depth (H, W) float32 of the receiver along the optical axis, NaN where no receiver."""
    pts = render.receiver_point.reshape(-1, 3)
    z = pts @ camera.R[2] + camera.t[2]
    z = np.where(render.receiver_valid.ravel(), z, np.nan)
    return z.reshape(render.receiver_valid.shape).astype(np.float32)


def _mean_azimuth(azimuths_deg) -> float:
    """The circular mean of compass azimuths in degrees, in [0, 360) (359 and 1 average to 0, not 180)."""
    a = np.radians(np.asarray(azimuths_deg, dtype=np.float64))
    return float(np.degrees(np.arctan2(np.sin(a).mean(), np.cos(a).mean())) % 360.0)


def _group_truth(label: str, photos: list[PhotoPlan]) -> dict:
    light = photos[0].light
    truth = light.truth()
    truth.update(
        label=label,
        photos=[],
        sun_azimuth_deg=_mean_azimuth([p.light.azimuth_deg for p in photos]),
        sun_elevation_deg=float(np.mean([p.light.elevation_deg for p in photos])),
        range=100.0 * light.range_k,
        brightness=float(brightness_to_paper(light.rho)),
    )
    return truth


def synthesize(out_dir, preset: str = "table2", *, seed: int = 0, renderer: Renderer = "physical",
               size: tuple[int, int] | None = None, fmt: str | None = None, quality: int = 92,
               progress: bool = True, force: bool = False, write_sun: bool | None = None,
               cameras: Cameras = "explicit", render_quality: RenderQuality | None = None,
               noise: bool = True, object_mesh: trimesh.Trimesh | str | Path | None = None,
               sun_radius_deg: float | None = None) -> Path:
    """Render preset ``preset`` into ``out_dir`` and return its path.

    renderer: 'physical' (ray-cast sun disk + sky) or 'model' (the project's model).
    size: (width, height) override; fmt: 'jpg', 'tiff', 'png' or 'dng' (default jpg);
    quality: JPEG quality; force: write into a non-empty folder (removing only the
    files a previous synthesis listed). write_sun: write each photo's sun into
    scene.toml (default: the preset's choice; table2 leaves it to time + site).
    cameras: 'explicit' writes K, R, t per photo; 'markers' leaves registration to the
    printed board ([camera] kind = "markers"). noise: sensor noise on/off.
    object_mesh: a mesh (a trimesh, or a file trimesh reads) in its own frame (metres, z up, on
    the ground at its origin) in place of the preset's built-in object, posed as the preset
    poses it; it is written into the folder as ``object.ply`` and named in scene.toml.
    sun_radius_deg: every photo's sun disk radius in degrees in place of the preset's (a hazy
    day widens the penumbra); the truth's range_k follows it.
    """
    with one_blas_thread():  # an entry point (softshadow.one_blas_thread)
        return _synthesize(out_dir, preset, seed, renderer, size, fmt, quality, progress, force, write_sun,
                           cameras, render_quality, noise, object_mesh, sun_radius_deg)


def _synthesize(out_dir, preset, seed, renderer, size, fmt, quality, progress, force, write_sun, cameras,
                render_quality, noise, object_mesh=None, sun_radius_deg=None) -> Path:
    _check_options(renderer, cameras, quality)
    if object_mesh is not None and not isinstance(object_mesh, trimesh.Trimesh):
        object_mesh = load_mesh(object_mesh)  # MeshError with the reason when it cannot be read
    if preset == "street":
        if object_mesh is not None or sun_radius_deg is not None:
            raise ValueError("preset 'street' has its own objects and light: it takes no object mesh or sun radius")
        if renderer != "physical":
            raise ValueError("preset 'street' is rendered by the physical renderer only")
        from .street import synthesize_street
        _prepare_out_dir(Path(out_dir), force)
        return synthesize_street(out_dir, seed, size, fmt or "jpg", quality, render_quality, noise)
    plan: PresetPlan = build_preset(preset, seed, size)
    if sun_radius_deg is not None:
        plan = dataclasses.replace(plan, photos=tuple(
            dataclasses.replace(p, light=dataclasses.replace(p.light, radius_deg=float(sun_radius_deg)))
            for p in plan.photos))
    return _synthesize_plan(out_dir, plan, seed, renderer, fmt, quality, progress, force, write_sun, cameras,
                            render_quality, noise, object_mesh)


def synthesize_plan(out_dir, plan: PresetPlan, *, seed: int = 0, renderer: Renderer = "physical",
                    fmt: str | None = None, quality: int = 92, progress: bool = False, force: bool = False,
                    write_sun: bool | None = None, cameras: Cameras = "explicit",
                    render_quality: RenderQuality | None = None, noise: bool = True,
                    object_mesh: trimesh.Trimesh | str | Path | None = None) -> Path:
    """Render a plan (a preset's, or one drawn at random: ``data_synth.draw``) into ``out_dir``.

    The options are those of ``synthesize``; ``seed`` seeds the render's noise (sun
    samples, sensor noise, ground texture). The plan's ``description`` is what
    scene.toml and the EXIF say where it differs from the rendered truth.
    """
    with one_blas_thread():
        return _synthesize_plan(out_dir, plan, seed, renderer, fmt, quality, progress, force, write_sun, cameras,
                                render_quality, noise, object_mesh)


def _check_options(renderer, cameras, quality) -> None:
    if renderer not in RENDERERS:
        raise ValueError(f"unknown renderer {renderer!r}; choose one of {RENDERERS}")
    if cameras not in ("explicit", "markers"):
        raise ValueError(f"cameras must be 'explicit' or 'markers', got {cameras!r}")
    if not 1 <= int(quality) <= 100:
        raise ValueError(f"JPEG quality must be 1..100, got {quality}")


def _synthesize_plan(out_dir, plan: PresetPlan, seed, renderer, fmt, quality, progress, force, write_sun,
                     cameras, render_quality, noise, object_mesh) -> Path:
    t_start = time.perf_counter()
    _check_options(renderer, cameras, quality)
    if object_mesh is not None and not isinstance(object_mesh, trimesh.Trimesh):
        object_mesh = load_mesh(object_mesh)  # MeshError with the reason when it cannot be read
    preset = plan.name
    fmt = fmt or plan.fmt
    if fmt not in FORMATS:
        raise ValueError(f"unknown image format {fmt!r}; choose one of {FORMATS}")
    out = Path(out_dir)
    _prepare_out_dir(out, force)
    write_sun = plan.write_sun if write_sun is None else bool(write_sun)
    told = plan.description

    mesh = posed_mesh(plan.mesh if object_mesh is None else object_mesh, plan.position, plan.rotation_deg,
                      plan.scale)
    receiver = _receiver(plan)
    scene = SynthScene(mesh, plan.object_albedo, receiver)
    quality_settings = render_quality or RenderQuality()
    rend = make_renderer(renderer, scene, quality_settings, seed)
    textures: dict[str, np.ndarray] = {}

    files: list[str] = []
    object_file = plan.mesh
    if object_mesh is not None:
        object_file = OBJECT_MESH_FILE
        object_mesh.export(out / object_file)
        files.append(object_file)
    spec = SceneSpec(object=ObjectSpec(object_file, told.position(plan.position), tuple(plan.rotation_deg),
                                       told.scale(plan.scale)))
    site_written = plan.site is not None and plan.write_site
    if site_written:
        spec.site = SiteSpec(plan.site["latitude"], plan.site["longitude"], plan.site.get("timezone"))
    depth_receiver = isinstance(receiver, HeightfieldReceiver)
    if depth_receiver:
        spec.receiver = ReceiverSpec(kind="depth")
    if isinstance(receiver, MeshReceiver):
        # The receiver's mesh goes into the folder (world metres, placed as is).
        mesh_name = RECEIVER_MESH_FILE
        receiver.mesh.export(out / mesh_name)
        files.append(mesh_name)
        spec.receiver = ReceiverSpec(kind="mesh", mesh=mesh_name)
    if plan.board is not None:
        b = plan.board
        spec.camera = CameraSpec(kind="markers", dictionary=b.dictionary, squares=tuple(b.squares),
                                 square_m=b.square_m, marker_m=b.marker_m, origin_m=tuple(b.origin_m))

    groups: dict[str, dict] = {}
    group_photos: dict[str, list[PhotoPlan]] = {}
    for p in plan.photos:
        if not p.corrupt:
            group_photos.setdefault(p.group, []).append(p)
    for label, ps in group_photos.items():
        groups[label] = _group_truth(label, ps)

    details: dict[str, dict] = {}
    skipped: list[dict] = []
    iterator = plan.photos
    if progress:
        from tqdm import tqdm
        iterator = tqdm(plan.photos, desc=f"synth {preset}", unit="photo")
    for index, photo in enumerate(iterator):
        rng = np.random.default_rng([seed, 7, index])
        ext = ".jpg" if photo.corrupt else EXTENSIONS[fmt]
        name = photo.name + ext
        camera, cam_spec = _camera(photo, plan.size)
        rays = topdown_rays(camera) if isinstance(camera, GroundGrid) else pinhole_rays(camera)
        if photo.texture not in textures:
            textures[photo.texture] = procedural_texture(photo.texture, np.random.default_rng([seed, 11]))
        ground = GroundAppearance(textures[photo.texture], papers=photo.papers, board=plan.board)
        t0 = time.perf_counter()
        render = rend.render(rays, photo.light, ground, rng)
        seconds = time.perf_counter() - t0
        sensor = photo.sensor if noise else dataclasses.replace(photo.sensor, full_well_e=1e12, read_noise_e=0.0)
        linear = camera_pipeline(render.radiance, photo.light.lit_irradiance, sensor, rng, photo.exposure_gain)
        if photo.corrupt:
            write_corrupt_jpeg(out / name, linear, quality)
            files.append(name)
            skipped.append({"photo": name, "reason": photo.note or "corrupt file"})
            continue
        written_time = told.time(photo.time)
        exif_time = written_time if (photo.exif_time and fmt == "jpg") else None
        site = plan.site if site_written else {}
        focal = float(camera.K[0][0]) if isinstance(camera, PinholeCamera) else None
        meta = PhotoMetadata(exif_time, site.get("latitude"), site.get("longitude"), focal_px=focal,
                             size=tuple(plan.size))
        write_photo(out / name, linear, fmt, quality, meta)
        files.append(name)
        entry = PhotoSpec(camera=cam_spec if (cameras == "explicit" or cam_spec.kind == "topdown") else None)
        scene_time = photo.scene_time if photo.scene_time is not None else (fmt != "jpg" or not photo.exif_time)
        if scene_time and written_time is not None:
            entry.time = written_time.isoformat()
        entry.group = photo.scene_group
        sun_written = write_sun if photo.write_sun is None else photo.write_sun
        if sun_written:
            entry.sun_azimuth_deg, entry.sun_elevation_deg = told.sun(photo.light.azimuth_deg,
                                                                      photo.light.elevation_deg)
        if depth_receiver and isinstance(camera, PinholeCamera):
            # The range-image format of scene.toml: float32 metres along the optical axis, NaN = none.
            depth_name = photo.name + ".depth.npy"
            np.save(out / depth_name, _depth_image(camera, render))
            entry.depth = depth_name
            files.append(depth_name)
        spec.photos[name] = entry
        groups[photo.group]["photos"].append(name)
        details[name] = {
            "group": photo.group,
            "time": photo.time.isoformat() if photo.time else None,
            "time_written": written_time.isoformat() if written_time else None,
            "time_in_exif": exif_time is not None,
            "time_in_scene": entry.time is not None,
            "sun_in_scene": bool(sun_written),
            "sun_azimuth_deg": float(photo.light.azimuth_deg),
            "sun_elevation_deg": float(photo.light.elevation_deg),
            "camera": cam_spec.to_toml(),
            "exposure_gain": photo.exposure_gain,
            "sensor": dataclasses.asdict(sensor),
            "texture": photo.texture,
            "penumbra_px": _penumbra_px(photo, mesh, camera),
            "render_seconds": seconds,
            "render_stats": render.stats,
            "note": photo.note,
        }
    dump_scene(spec, out / "scene.toml")
    truth = {
        "groups": [g for g in groups.values() if g["photos"]],
        "renderer": renderer,
        "renderer_detail": ("ray-cast sun disk + uniform sky, trimesh/Embree (data_synth.physical)"
                            if renderer == "physical" else "softshadow.render.SoftShadowModel, rule edge, "
                            "profile linear, k = tan(sun radius)"),
        "preset": preset,
        "receiver": spec.receiver.to_toml(),
        "seed": int(seed),
        "size": list(plan.size),
        "format": fmt,
        "quality": int(quality),
        "render_quality": dataclasses.asdict(quality_settings),
        "truth_definition": {"range_k": "tan(sun angular radius), the edge rule's geometric value",
                             "rho": "E_sky / (E_sun_horizontal + E_sky) on open ground, direct light only",
                             "brightness": "255 rho^(1/2.2)", "range": "100 k"},
        "object": {"mesh": object_file, "position": list(plan.position), "rotation_deg": list(plan.rotation_deg),
                   "scale": plan.scale},
        "site": dict(plan.site) if plan.site else None,
        "misdescription": told.to_json(),
        "photos_detail": details,
        "expected_skipped": skipped,
        "files": files + ["scene.toml", "truth.json"],
        "seconds": time.perf_counter() - t_start,
    }
    (out / "truth.json").write_text(json.dumps(truth, indent=1, default=_json_default), encoding="utf-8")
    return out


def _json_default(value):
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (_dt.datetime, Path)):
        return str(value)
    raise TypeError(f"cannot write {type(value).__name__} to JSON")
