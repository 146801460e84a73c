"""Each photo's camera (explicit, top-down or registered on a ChArUco board) and sun, as a ``PhotoView``."""

from __future__ import annotations

import datetime as _dt

import cv2
import numpy as np

from scene import CameraSpec, SceneSpec, photo_sun

from ..photos.read import Photo
from ..photos.views import PhotoView

__all__ = ["camera_view", "sun_view"]


def camera_view(photo: Photo, spec: CameraSpec | None, view: PhotoView) -> None:
    """Fill the view's camera or grid from the scene; markers are registered here."""
    h, w = photo.gray.shape
    if spec is None:
        raise ValueError("no camera: give [camera] (explicit, topdown or markers) in scene.toml")
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


