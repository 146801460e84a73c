"""Each photo's camera (explicit, top-down or registered on a ChArUco board) and sun, as a ``PhotoView``."""

from __future__ import annotations

import dataclasses
import datetime as _dt

import cv2
import numpy as np

from scene import CameraSpec, SceneSpec, photo_sun

from ..photos.read import Photo
from ..photos.views import PhotoView

__all__ = ["camera_view", "sun_view", "decimated_spec", "check_principal_point"]


def _decimated_K(K, factor: int) -> list:
    """K (3, 3) of a camera for its image read with ``factor`` file pixels per pixel: pixel i
    covers file pixels factor * i ... factor * i + factor - 1, so u = (u_file + 0.5) / factor - 0.5."""
    given = np.asarray(K, dtype=np.float64)
    scaled = given.copy()
    scaled[:2] /= factor
    scaled[:2, 2] = (given[:2, 2] + 0.5) / factor - 0.5
    return scaled.tolist()


def decimated_spec(spec: CameraSpec, factor: int) -> CameraSpec:
    """The scene's camera (given for the photo file's size) for the photo read with ``factor``
    file pixels per pixel (2 with ``--half-size``): K scaled, or a top-down map's pixel_m and
    the centre of its pixel (0, 0)."""
    if factor == 1:
        return spec
    if spec.kind == "topdown":
        shift = (factor - 1) / 2 * spec.pixel_m
        return dataclasses.replace(spec, pixel_m=spec.pixel_m * factor,
                                   origin_m=(spec.origin_m[0] + shift, spec.origin_m[1] - shift))
    if spec.K is None:
        return spec
    return dataclasses.replace(spec, K=_decimated_K(spec.K, factor))


def check_principal_point(K, width: int, height: int, decimation: int = 1) -> None:
    """A ValueError when K's principal point lies outside the middle half of a width x height
    image: K was made for an image of another size (say 640x480 for 8000x6000 photos)."""
    cx, cy = float(np.asarray(K)[0, 2]), float(np.asarray(K)[1, 2])
    if abs(cx - (width - 1) / 2) <= width / 4 and abs(cy - (height - 1) / 2) <= height / 4:
        return
    # In the file's pixels (the scene's K is given for the file).
    fx, fy = (cx + 0.5) * decimation - 0.5, (cy + 0.5) * decimation - 0.5
    made = f"{2 * round(fx + 0.5)}x{2 * round(fy + 0.5)}"
    raise ValueError(f"the camera's principal point ({fx:.0f}, {fy:.0f}) is far from the centre of this "
                     f"{width * decimation}x{height * decimation} photo: K looks made for a {made} image; "
                     "give K for the photo's size")


def camera_view(photo: Photo, spec: CameraSpec | None, view: PhotoView) -> None:
    """Fill the view's camera or grid from the scene (scaled to the photo's decoded size, see
    ``decimated_spec``); markers are registered here. Raises ValueError with a one-line reason."""
    h, w = photo.gray.shape
    if spec is None:
        raise ValueError("no camera: give [camera] (explicit, topdown or markers) in scene.toml")
    factor = int(getattr(photo, "decimation", 1) or 1)
    spec = decimated_spec(spec, factor)
    if spec.K is not None:
        check_principal_point(spec.K, w, h, factor)
    if spec.kind == "topdown":
        view.grid = spec.grid(w, h)
    elif spec.kind == "explicit":
        cam = spec.pinhole(w, h)
        view.camera = cam
    else:
        from ..photos.markers import board_outline_world, register_board
        # Intrinsics: scene.toml's K with its distortion, else EXIF, else fitted (register_board).
        reg = register_board(photo.gray, spec, exif=photo.exif)
        view.camera = reg.camera
        view.reprojection_error_px = reg.reprojection_error_px
        outline = board_outline_world(spec)
        uv, front = reg.camera.project(outline)
        ignore = np.zeros((h, w), np.uint8)
        if front.all():
            cv2.fillConvexPoly(ignore, np.rint(uv).astype(np.int32), 1)
            ignore = cv2.dilate(ignore, np.ones((9, 9), np.uint8))
        view.ignore = ignore.astype(bool)


def sun_view(name: str, when: _dt.datetime | None, scene: SceneSpec, view: PhotoView) -> None:
    from softshadow.internal import check_sun_above_horizon
    sun = photo_sun(scene, name, when)
    if sun is None:
        view.sun_source = "fitted"
        return
    view.sun_azimuth_deg, view.sun_elevation_deg, view.sun_source = sun.azimuth_deg, sun.elevation_deg, sun.source
    check_sun_above_horizon(view.sun_elevation_deg)


