"""The object itself as a receiver: the pixels where a camera sees the object, and the model's
light on them (NumPy and trimesh; the shadow's alpha from ``softshadow``).

A point on the object is lit by the sun unless its face turns away from the sun
(attached shadow) or another part of the object lies between it and the sun
(its cast self-shadow); the renderer's light-space back end decides both from
the point and its normal (``softshadow.internal.plan_points`` with normals: the face's
orientation, and the shadow map's depth test). Its light, relative to open
horizontal ground's lit level, is that of any receiver
(``fitting.samples.receiver_light``): (1 - rho) c (1 - alpha) + rho v, with c the sun's
incidence on its normal and v the sky it sees past the object and the receiver
(``softshadow.internal.open_sky_fraction``).

Which pixels see the object is a visible-surface test: each pixel's ray from the
camera is cast against the posed object and the receiver's blocker mesh
(trimesh, Embree when installed); pixels whose first hit is on the object keep
that point and its face's normal, turned to face the camera (so an open mesh's
faces read as the side seen).

The fit does not use these pixels (docs/receivers.md says why); this module
predicts the object's own shading so that it can be drawn and checked against
the physical renderer.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import trimesh

from softshadow import PinholeCamera, Pose, ShadowParams, SoftShadowModel, Sun
from softshadow.internal import open_sky_fraction, posed_vertices

from .receiver_light import shadow_factor, sun_incidence

__all__ = ["ObjectPixels", "visible_object_pixels", "object_light"]


@dataclasses.dataclass(frozen=True)
class ObjectPixels:
    """Pixels (N,) where a camera sees the object: rows, cols (N,) int; points (N, 3) world
    metres where each pixel's ray first meets the object; normals (N, 3) unit, of the face
    hit, facing the camera."""

    rows: np.ndarray
    cols: np.ndarray
    points: np.ndarray
    normals: np.ndarray


def _posed_mesh(model: SoftShadowModel, pose: Pose) -> trimesh.Trimesh:
    world, _ = posed_vertices(model.occluder, pose)
    return trimesh.Trimesh(world, model.occluder.faces, process=False)


def visible_object_pixels(model: SoftShadowModel, pose: Pose, camera: PinholeCamera,
                          receiver: trimesh.Trimesh | None = None, step: int = 1) -> ObjectPixels:
    """The pixels (every ``step``-th in each direction) whose ray from the camera meets the
    posed object before anything else (the receiver's mesh, when given, can hide it)."""
    obj = _posed_mesh(model, pose)
    n_obj = len(obj.faces)
    scene: trimesh.Trimesh = obj if receiver is None else trimesh.util.concatenate([obj, receiver])
    rows, cols = np.mgrid[0:camera.height:step, 0:camera.width:step]
    rows, cols = rows.ravel(), cols.ravel()
    dirs = camera.pixel_rays(cols.astype(np.float64), rows.astype(np.float64))
    dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    origins = np.broadcast_to(camera.centre, dirs.shape)
    loc, ray, tri = scene.ray.intersects_location(origins, dirs, multiple_hits=False)
    on_obj = tri < n_obj
    loc, ray, tri = loc[on_obj], ray[on_obj], tri[on_obj]
    normals = obj.face_normals[tri]
    # Facing the camera: the side of the face the pixel sees.
    flip = np.einsum("nj,nj->n", normals, camera.centre - loc) < 0
    normals = np.where(flip[:, None], -normals, normals)
    order = np.argsort(ray)
    return ObjectPixels(rows[ray[order]], cols[ray[order]], loc[order], normals[order])


def object_light(model: SoftShadowModel, params: ShadowParams, sun: Sun, pose: Pose, pixels: ObjectPixels,
                 receiver: trimesh.Trimesh | None = None, n_sky_directions: int = 64
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The model's light on the object's pixels, over open horizontal ground's lit level.

    Returns (light (N,), alpha (N,), c (N,), v (N,)): light = (1 - rho) c (1 - alpha) + rho v;
    alpha 1 in attached shadow and in the object's cast self-shadow (whose edge is hard in the
    model, see docs/shadow_map.md), c the sun's incidence over the open ground's, v the sky
    seen past the object and the receiver.
    """
    points, normals = pixels.points, pixels.normals
    rho = float(params.rho)
    # The renderer's shading is the sun's part, 1 - alpha (1 - rho): alpha from it.
    sun_part = np.asarray(model.at_points(params, sun, pose, points, normals), np.float64)
    alpha = (1.0 - sun_part) / (1.0 - rho)
    c = sun_incidence(normals, -sun.light_np)
    obj = _posed_mesh(model, pose)
    blockers = obj if receiver is None else trimesh.util.concatenate([obj, receiver])
    v = open_sky_fraction(blockers, points, normals, n_directions=n_sky_directions)
    return shadow_factor(alpha, rho, c, v), alpha, c, v
