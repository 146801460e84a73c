"""scene: what a photo folder describes, read from and written to ``scene.toml``.

The site, the object and its pose, the receiver, the cameras and per-photo
entries (``spec``), and the photos' times and suns (``time_site``). Used by
``fitting`` (which reads folders) and ``data_synth`` (which writes them); it
builds on ``softshadow``'s cameras and nothing above it.
"""

from .spec import (NO_GEOMETRY, TABLES, CameraSpec, ObjectSpec, PhotoSpec, ProjectorSpec, ReceiverSpec, SceneError, SceneSpec, SiteSpec, dump_scene,
                   load_scene, scene_from_dict, scene_to_dict)
from .time_site import PhotoSun, parse_time, photo_sun, solar_position

__all__ = [
    "NO_GEOMETRY", "TABLES", "CameraSpec", "ObjectSpec", "PhotoSpec", "PhotoSun", "ProjectorSpec", "ReceiverSpec", "SceneError", "SceneSpec", "SiteSpec",
    "dump_scene", "load_scene", "parse_time", "photo_sun", "scene_from_dict", "scene_to_dict",
    "solar_position",
]
