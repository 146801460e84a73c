"""``softshadow render``: a scene.toml to an image of the model's soft shadow, or (with
projectors) to a camera image of the whole scene lit by the sun, an ambient term and projectors."""

from __future__ import annotations

import sys

import numpy as np

from scene import load_scene, parse_time, photo_sun
from softshadow import (GroundGrid, PinholeCamera, Pose, Projector, SceneLights, ShadowParams, SoftShadowModel,
    Sun, linear_to_srgb, load_mesh, look_at_camera, paper_to_range_k, paper_to_rho, render_scene, slide_from_text)
from softshadow.internal import PosedOccluder, Surface, posed_vertices

from .validate import OptionError

__all__ = ["render_scene_file", "shading_to_srgb8", "draw_outlines", "DEFAULT_VIEW"]

PAPER_ALBEDO = 0.85  # white paper, for display
DEFAULT_SIZE = "512x512"  # a top-down map's size when --size is not given
DEFAULT_SCENE_SIZE = "640x480"  # a scene image's size with a look-at camera
#: The default view of a scene with projectors: azimuth, elevation (degrees), field of view.
DEFAULT_VIEW = (210.0, 30.0, 50.0)


def shading_to_srgb8(shading: np.ndarray, albedo: float = PAPER_ALBEDO) -> np.ndarray:
    """Linear shading (H, W) to an 8-bit sRGB grey image (H, W, 3); NaN shows as black."""
    lin = np.nan_to_num(np.clip(shading * albedo, 0, 1), nan=0.0)
    g = np.rint(linear_to_srgb(lin) * 255).astype(np.uint8)
    return np.repeat(g[..., None], 3, axis=-1)


def draw_outlines(image: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Outer (alpha = 0+, blue), hard (0.5, yellow) and inner (1-, red) outlines over an image."""
    from skimage import measure
    out = image.copy()
    for level, colour in ((0.02, (40, 90, 255)), (0.5, (255, 210, 0)), (0.98, (230, 30, 30))):
        for contour in measure.find_contours(np.nan_to_num(alpha, nan=0.0), level):
            rc = np.rint(contour).astype(int)
            ok = (rc[:, 0] >= 0) & (rc[:, 0] < out.shape[0]) & (rc[:, 1] >= 0) & (rc[:, 1] < out.shape[1])
            out[rc[ok, 0], rc[ok, 1]] = colour
    return out


def render_scene_file(args):
    """(sRGB image (H, W, 3) uint8, linear shading (H, W)) for the render command's arguments."""
    scene = load_scene(args.scene)
    if args.photo is not None and args.photo not in scene.photos:
        import difflib
        near = difflib.get_close_matches(args.photo, list(scene.photos), n=1)
        raise OptionError(f"--photo {args.photo!r} is not a [photos] entry of {args.scene}"
                          + (f"; did you mean {near[0]!r}?" if near else
                             f" (its entries: {', '.join(scene.photos) or 'none'})"))
    if scene.object is None:
        raise ValueError(f"{args.scene} has no [object]")
    model = SoftShadowModel.from_mesh(load_mesh(scene.object.mesh, scene.base_dir), args.rule,
                                      args.profile)
    pose = Pose(scene.object.position, scene.object.rotation_deg, scene.object.scale)
    name = args.photo or (next(iter(scene.photos)) if scene.photos else None)
    photo = scene.photo(name) if name else None
    projectors = [p.projector(scene.base_dir) for p in scene.projectors] + _cli_projectors(args)
    scene_mode = bool(projectors) or getattr(args, "camera_position", None) is not None
    az, el = args.sun_azimuth, args.sun_elevation
    if scene_mode and getattr(args, "no_sun", False):
        return _render_lit_scene(args, scene, model, pose, None, projectors, name)
    if (az is None or el is None) and photo is not None:
        # The same sun as ``softshadow fit`` finds for this photo (time zone and altitude included).
        when = parse_time(photo.time, scene.site.timezone if scene.site else None) if photo.time else None
        sun = photo_sun(scene, name, when)
        if sun is not None:
            az = sun.azimuth_deg if az is None else az
            el = sun.elevation_deg if el is None else el
    if az is None or el is None:
        raise ValueError("no sun: give --sun-azimuth/--sun-elevation, or a sun or time + site in the scene")
    k = args.k if args.k is not None else (paper_to_range_k(args.range_paper)
                                           if args.range_paper is not None else 0.01)
    rho = args.rho if args.rho is not None else (paper_to_rho(args.brightness)
                                                 if args.brightness is not None else 0.3)
    params = ShadowParams(k, rho)
    sun = Sun(az, el)
    if scene_mode:
        return _render_lit_scene(args, scene, model, pose, sun, projectors, name, k, rho)
    cam = scene.camera_for(name) if name else scene.camera
    w, h = (int(v) for v in (args.size or DEFAULT_SIZE).lower().split("x"))
    if cam is not None and cam.kind == "explicit":
        camera = _explicit_camera(cam, args.size, w, h)
        rendered = model.camera_image(params, sun, pose, camera)
        shading = np.asarray(rendered.shading)
        alpha = (1 - shading) / max(1 - rho, 1e-9)
        shading = np.where(rendered.object_mask, 0.35, shading)  # the object in grey
    else:
        if cam is not None and cam.kind == "topdown":
            grid = cam.grid(w, h)
        else:
            grid = _default_grid(model, pose, sun, w, h, args.pixel_m)
        shading = np.asarray(model.ground_map(params, sun, pose, grid))
        alpha = (1 - shading) / max(1 - rho, 1e-9)
    image = shading_to_srgb8(shading)
    if args.silhouettes:
        image = draw_outlines(image, alpha)
    return image, shading


def _explicit_camera(cam, size, w: int, h: int) -> PinholeCamera:
    """The scene's explicit camera at --size (w x h), or without --size at the image size its
    principal point is the centre of."""
    K = np.asarray(cam.K)
    width = int(round(2 * (K[0, 2] + 0.5))) if size is None else w
    height = int(round(2 * (K[1, 2] + 0.5))) if size is None else h
    return PinholeCamera(K, cam.R, cam.t, width, height, cam.dist)


def _default_grid(model, pose, sun, w, h, pixel_m):
    """A north-up map framing the object and its whole shadow."""
    posed = PosedOccluder.make(model.occluder, pose, sun)
    pts = np.vstack([posed.ground_vertices(), posed.world[:, :2]])
    lo, hi = pts.min(0), pts.max(0)
    centre = (lo + hi) / 2
    if pixel_m is None:
        pixel_m = 1.15 * max((hi - lo)[0] / w, (hi - lo)[1] / h)
    origin = (centre[0] - (w - 1) / 2 * pixel_m, centre[1] + (h - 1) / 2 * pixel_m)
    return GroundGrid(pixel_m, origin, w, h)


def _xyz(text: str, option: str) -> tuple[float, float, float]:
    try:
        values = tuple(float(v) for v in str(text).split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not np.all(np.isfinite(values)):
        raise ValueError(f"{option} must be three numbers X,Y,Z (metres), got {text!r}")
    return values


def _per_projector(values, default, option: str, n: int) -> list:
    """One value for every projector, or one per projector in order."""
    values = list(values or [default])
    if len(values) == 1:
        return values * n
    if len(values) != n:
        raise ValueError(f"give {option} once, or once per --projector ({n}), not {len(values)} times")
    return values


def _cli_projectors(args) -> list[Projector]:
    """Projectors from --projector X,Y,Z --projector-target X,Y,Z [--projector-fov] [--slide]
    [--projector-intensity] (each repeatable, paired in order); slide paths relative to here."""
    positions = getattr(args, "projector", None) or []
    n = len(positions)
    extra = [o for o, v in (("--projector-target", args.projector_target), ("--projector-fov", args.projector_fov),
                            ("--slide", args.slide), ("--projector-intensity", args.projector_intensity)) if v]
    if not n:
        if extra:
            raise ValueError(f"{extra[0]} needs --projector X,Y,Z")
        return []
    targets = args.projector_target or []
    if len(targets) != n:
        raise ValueError(f"give one --projector-target X,Y,Z per --projector ({n}), got {len(targets)}")
    fovs = _per_projector(args.projector_fov, 30.0, "--projector-fov", n)
    slides = _per_projector(args.slide, "spot", "--slide", n)
    levels = _per_projector(args.projector_intensity, 1.0, "--projector-intensity", n)
    return [Projector(_xyz(p, "--projector"), _xyz(t, "--projector-target"), slide_from_text(s), fov_deg=float(f),
                      intensity=float(i))
            for p, t, f, s, i in zip(positions, targets, fovs, slides, levels)]


def _scene_camera(args, scene, name, model, pose):
    """The camera of a scene image: --camera-position/--camera-target, else the scene's explicit or
    top-down camera, else a look-at camera from DEFAULT_VIEW framing the object."""
    size = args.size or DEFAULT_SCENE_SIZE
    w, h = (int(v) for v in size.lower().split("x"))
    fov = args.camera_fov if args.camera_fov is not None else DEFAULT_VIEW[2]
    if args.camera_position is not None or args.camera_target is not None:
        if args.camera_position is None or args.camera_target is None:
            raise ValueError("give both --camera-position and --camera-target")
        return look_at_camera(_xyz(args.camera_position, "--camera-position"),
                              _xyz(args.camera_target, "--camera-target"), w, h, fov)
    cam = scene.camera_for(name) if name else scene.camera
    if cam is not None and cam.kind == "explicit":
        return _explicit_camera(cam, args.size, w, h)
    if cam is not None and cam.kind == "topdown":
        return cam.grid(w, h)
    world, _ = posed_vertices(model.occluder, pose)
    lo, hi = world.min(0), world.max(0)
    centre, radius = 0.5 * (lo + hi), 0.5 * float(np.linalg.norm(hi - lo))
    az, el = np.deg2rad(DEFAULT_VIEW[0]), np.deg2rad(DEFAULT_VIEW[1])
    direction = np.array([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)])
    distance = 2.5 * radius / np.tan(np.deg2rad(fov) / 2)
    return look_at_camera(centre + distance * direction, centre, w, h, fov)


def _depth_surface(scene, name) -> Surface | None:
    """The photo's range image as a triangle mesh (every other pixel, no triangles across depth
    jumps), placed by the photo's explicit camera; None without one."""
    from fitting.samples.receiver_points import depth_mesh, depth_points, read_depth
    path = (scene.photo(name).depth if name else None) or scene.receiver.depth
    cam = scene.camera_for(name) if name else scene.camera
    if path is None:
        raise ValueError("[receiver] kind = \"depth\" names no range image for this photo")
    if cam is None or cam.kind != "explicit":
        return None
    camera = _explicit_camera(cam, None, 0, 0)
    full = path if scene.base_dir is None else scene.base_dir / path
    points = depth_points(read_depth(full, (camera.height, camera.width)), camera)
    mesh = depth_mesh(points, step=2, centre=camera.centre)
    return Surface(mesh.vertices, mesh.faces, PAPER_ALBEDO, "receiver")


def _render_lit_scene(args, scene, model, pose, sun, projectors, name, k=0.01, rho=0.3):
    """(sRGB image (H, W, 3) uint8, linear radiance (H, W, 3)) of the whole scene."""
    if args.silhouettes:
        raise ValueError("--silhouettes draws a shadow map's outlines; it does not go with projectors or a "
                         "scene camera")
    camera = _scene_camera(args, scene, name, model, pose)
    receivers, ground = [], PAPER_ALBEDO
    rec = scene.receiver
    if rec.kind == "mesh":
        receivers.append(Surface.from_trimesh(load_mesh(rec.mesh, scene.base_dir), rec.position, rec.rotation_deg,
                                              rec.scale, PAPER_ALBEDO, "receiver"))
        ground = None  # the mesh is the receiver (it holds its own ground where it has one)
    elif rec.kind == "depth":
        surface = _depth_surface(scene, name)
        if surface is None:
            print("softshadow render: the range image needs the photo's explicit camera; the receiver is "
                  "drawn as the ground plane z = 0", file=sys.stderr)
        else:
            receivers.append(surface)
            ground = None
    if sun is not None:
        lights = SceneLights.from_rho(sun, k, rho)
        if args.ambient is not None:
            lights = SceneLights(args.ambient, lights.sun_irradiance, k)
    else:
        lights = SceneLights(0.3 if args.ambient is None else args.ambient, 0.0, k)
    rendered = render_scene(camera, model, pose, lights, sun, projectors, receivers=receivers, object_albedo=PAPER_ALBEDO,
                            ground_albedo=ground, range_k_max=max(k, 0.03), smooth=args.smooth,
                            supersample=args.supersample)
    radiance = np.asarray(rendered.image, np.float64)
    exposed = np.clip(radiance * args.exposure, 0.0, 1.0)
    return np.rint(linear_to_srgb(exposed) * 255).astype(np.uint8), radiance
