"""``softshadow render``: a scene.toml to an image of the model's soft shadow."""

from __future__ import annotations

import numpy as np

from scene import load_scene, parse_time, photo_sun
from softshadow import (GroundGrid, PinholeCamera, Pose, PosedOccluder, ShadowParams, SoftShadowModel, Sun,
                        linear_to_srgb, load_mesh, paper_to_range_k, paper_to_rho)

__all__ = ["render_scene_file", "shading_to_srgb8", "draw_outlines"]

PAPER_ALBEDO = 0.85  # white paper, for display
DEFAULT_SIZE = "512x512"  # a top-down map's size when --size is not given


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
    if scene.object is None:
        raise ValueError(f"{args.scene} has no [object]")
    model = SoftShadowModel.from_mesh(load_mesh(scene.object.mesh, scene.base_dir), args.rule,
                                      args.profile)
    pose = Pose(scene.object.position, scene.object.rotation_deg, scene.object.scale)
    name = args.photo or (next(iter(scene.photos)) if scene.photos else None)
    photo = scene.photo(name) if name else None
    az, el = args.sun_azimuth, args.sun_elevation
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
    cam = scene.camera_for(name) if name else scene.camera
    w, h = (int(v) for v in (args.size or DEFAULT_SIZE).lower().split("x"))
    if cam is not None and cam.kind == "explicit":
        K = np.asarray(cam.K)  # without --size, the image the principal point is the centre of
        width = int(round(2 * (K[0, 2] + 0.5))) if args.size is None else w
        height = int(round(2 * (K[1, 2] + 0.5))) if args.size is None else h
        camera = PinholeCamera(K, cam.R, cam.t, width, height, cam.dist)
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
