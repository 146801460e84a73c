"""The object itself as a receiver (``fitting.samples.object_points``): which pixels see it, its attached
and cast self-shadow, and its light against the physical renderer (a small mesh, a small image)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import trimesh

from softshadow import Pose, ShadowParams, SoftShadowModel, Sun, look_at_camera
from softshadow.internal import object_mask


@pytest.fixture(scope="module")
def scene():
    """A pillar standing on a low block: the pillar shadows the block's top (a cast self-shadow),
    and the faces turned from the sun are in attached shadow. Seen from above at an angle."""
    from data_synth import SunSky
    block = trimesh.creation.box(extents=(0.9, 0.9, 0.3))
    block.apply_translation((0.0, 0.0, 0.15))
    pillar = trimesh.creation.box(extents=(0.12, 0.12, 1.0))
    pillar.apply_translation((0.0, 0.0, 0.8))
    mesh = trimesh.util.concatenate([block, pillar])
    light = SunSky.from_rho(200.0, 40.0, 0.25)
    sun = Sun(light.azimuth_deg, light.elevation_deg)
    model = SoftShadowModel.from_mesh(mesh)
    camera = look_at_camera((1.4, -1.8, 2.2), (0.0, 0.0, 0.3), 96, 72, 50.0)
    return model, mesh, sun, light, camera


def test_visible_pixels_are_the_object_seen_from_the_camera(scene):
    from fitting.samples.object_points import visible_object_pixels
    model, mesh, sun, _, camera = scene
    px = visible_object_pixels(model, Pose(), camera)
    seen = np.zeros((camera.height, camera.width), bool)
    seen[px.rows, px.cols] = True
    mask = object_mask(model.occluder, Pose(), camera)
    # The same pixels as the object's projected outline, but for its rasterised rim (the mask
    # takes every pixel a face touches, the rays only those whose centre it covers).
    inner = cv2.erode(mask.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    outer = cv2.dilate(mask.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    assert np.all(seen[inner]) and not np.any(seen & ~outer)
    assert np.count_nonzero(seen) > 0.8 * np.count_nonzero(mask)
    # Each point is on the mesh, and its normal faces the camera.
    _, dist, _ = trimesh.proximity.closest_point(mesh, px.points)
    assert np.max(dist) < 1e-6
    assert np.all(np.einsum("nj,nj->n", px.normals, camera.centre - px.points) > 0)
    # A wall between the camera and the object hides it.
    wall = trimesh.creation.box(extents=(4.0, 0.05, 4.0))
    wall.apply_translation((0.0, -1.2, 0.0))
    hidden = visible_object_pixels(model, Pose(), camera, receiver=wall)
    assert len(hidden.rows) < 0.5 * len(px.rows)


def test_self_shadow_and_attached_shadow_match_ray_casting(scene):
    """Alpha on the object's visible points against rays to the sun's centre (the pillar's
    shadow on the block's top) and the faces turned away (attached): all agree but a few points
    at the shadow's edges."""
    from fitting.samples.object_points import object_light, visible_object_pixels
    model, mesh, sun, light, camera = scene
    px = visible_object_pixels(model, Pose(), camera)
    _, alpha, c, _ = object_light(model, ShadowParams(light.range_k, light.rho), sun, Pose(), px)
    s = -sun.light_np
    away = px.normals @ s <= 0
    cast = mesh.ray.intersects_any(px.points + 1e-4 * s, np.broadcast_to(s, px.points.shape))
    truth = away | cast
    assert np.count_nonzero(cast & ~away) >= 30  # the block's top is shadowed by the pillar
    assert np.count_nonzero(away) >= 30
    shadowed = alpha > 0.5
    assert np.count_nonzero(shadowed != truth) <= 0.03 * len(truth)
    assert np.all(alpha[away] == 1.0) and np.all(c[away] == 0.0)


def test_object_light_matches_the_physical_renderer(scene):
    """The model's light on the object over open ground's lit level against data_synth.physical
    (sun disk and sky by independent ray casting): within 0.02 at 95 % of the visible points (the
    rest at the self-shadow's edge, which the model draws hard)."""
    from data_synth.physical import irradiance, sky_visibility, sun_visibility
    from fitting.samples.object_points import object_light, visible_object_pixels
    model, mesh, sun, light, camera = scene
    assert np.allclose(-sun.light_np, light.direction)
    px = visible_object_pixels(model, Pose(), camera)
    value, _, _, _ = object_light(model, ShadowParams(light.range_k, light.rho), sun, Pose(), px,
                                  n_sky_directions=256)
    v_sun = sun_visibility(mesh, px.points, px.normals, light, 64)
    physical = irradiance(light, px.normals, v_sun, sky_visibility(mesh, px.points, px.normals, 256))
    physical = physical / light.lit_irradiance
    err = np.abs(value - physical)
    assert np.percentile(err, 95) < 0.02, np.percentile(err, [50, 90, 95, 99])
    # Both levels are there: lit faces well above the shadowed ones.
    assert value.max() > 0.8 and value.min() < 0.25
