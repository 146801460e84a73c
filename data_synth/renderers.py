"""Renderers: linear radiance images of a synthetic scene seen along a camera's rays.

- ``PhysicalRenderer`` (default): irradiance by ray casting a sun disk and a
  uniform sky (``physical``), independent of the project's shadow model.
- ``ModelRenderer``: the project's own model (softshadow.render.SoftShadowModel)
  with k = tan(sun radius) and the light's rho, for identifiability, uncertainty
  and speed tests: ground = albedo * E_lit * (1 - alpha (1 - rho)).

Pixel values are albedo * irradiance (Lambertian radiance times pi); the
camera pipeline scales them by the exposure.
"""

from __future__ import annotations

import dataclasses
import math
import time

import cv2
import numpy as np
import trimesh

from .lighting import SunSky
from .physical import (combined_mesh, irradiance, shadow_reach, sky_visibility, sky_visibility_map,
                       sun_visibility)
from .textures import GroundAppearance
from .tracing import KIND_OBJECT, KIND_RECEIVER, ViewRays, pixel_axes, trace

__all__ = ["RENDERERS", "SynthScene", "RenderQuality", "ViewRender", "PhysicalRenderer", "ModelRenderer",
           "make_renderer"]

RENDERERS = ("physical", "model")


@dataclasses.dataclass(frozen=True, eq=False)
class SynthScene:
    """An object (world-frame mesh, linear RGB albedo) on a receiver (PlaneReceiver or
    HeightfieldReceiver). The ground's appearance is given per render (it may change
    between photos: paper laid out anew, another place)."""

    object_mesh: trimesh.Trimesh
    object_albedo: tuple[float, float, float]
    receiver: object


@dataclasses.dataclass(frozen=True)
class RenderQuality:
    """Sample counts. sun_samples: per receiver pixel in the penumbra (stratified over the
    disk and the pixel); with ``adaptive``, every pixel in the shadow's reach first gets
    ``pilot_samples`` and only partly lit pixels (and their neighbours) get sun_samples;
    sky_samples: per node of the sky-visibility grids; object_*: per object pixel."""

    sun_samples: int = 64
    pilot_samples: int = 16
    adaptive: bool = True
    sky_samples: int = 1024
    sky_fine_nodes: int = 96
    object_sun_samples: int = 4
    object_sky_samples: int = 36


@dataclasses.dataclass
class ViewRender:
    """radiance (H, W, 3) float32 linear; irradiance (H, W) float32; kind (H, W) uint8
    (0 sky, 1 receiver, 2 object); receiver points (H, W, 3) and validity; stats."""

    radiance: np.ndarray
    irradiance: np.ndarray
    kind: np.ndarray
    receiver_point: np.ndarray
    receiver_valid: np.ndarray
    stats: dict


SKY_RGB = np.array([0.75, 0.85, 1.0], np.float32)  # what a pixel that sees no surface shows (x lit level)


def _assemble(scene: SynthScene, ground: GroundAppearance, rays: ViewRays, hits, e_recv, e_obj, lit: float,
              stats) -> ViewRender:
    h, w = rays.height, rays.width
    n = h * w
    radiance = np.empty((n, 3), np.float32)
    radiance[:] = SKY_RGB * lit * 1.3
    e_all = np.full(n, np.nan, np.float32)
    recv = hits.kind == KIND_RECEIVER
    obj = hits.kind == KIND_OBJECT
    if recv.any():
        radiance[recv] = ground.reflectance(hits.points[recv]) * e_recv[:, None]
        e_all[recv] = e_recv
    if obj.any():
        radiance[obj] = np.asarray(scene.object_albedo, np.float32) * e_obj[:, None]
        e_all[obj] = e_obj
    return ViewRender(radiance.reshape(h, w, 3), e_all.reshape(h, w), hits.kind.reshape(h, w),
                      hits.receiver_point.reshape(h, w, 3), hits.receiver_valid.reshape(h, w), stats)


class PhysicalRenderer:
    """Ray-cast sun disk plus sky. The sky-visibility grids (independent of the sun) are
    computed once per renderer and reused for every view and time."""

    name = "physical"

    def __init__(self, scene: SynthScene, quality: RenderQuality = RenderQuality(), seed: int = 0):
        self.scene = scene
        self.quality = quality
        self.seed = seed
        self.occluders = combined_mesh(scene.object_mesh, scene.receiver.mesh)
        self._sky_map = None

    def sky_map(self):
        if self._sky_map is None:
            q = self.quality
            self._sky_map = sky_visibility_map(self.occluders, self.scene.receiver, self.scene.object_mesh.bounds,
                                               q.sky_samples, self.seed, q.sky_fine_nodes)
        return self._sky_map

    def check_light(self, sun: SunSky) -> None:
        """The receiver must not shadow itself (its shadows would be missing outside the object's reach)."""
        slope = self.scene.receiver.max_slope()
        limit = math.tan(math.radians(sun.elevation_deg) - sun.radius_rad)
        if slope >= limit:
            raise ValueError(f"receiver slope {slope:.2f} is too steep for a sun at {sun.elevation_deg:.1f} deg "
                             f"(limit {limit:.2f}): it would shadow itself")

    def render(self, rays: ViewRays, sun: SunSky, ground: GroundAppearance,
               rng: np.random.Generator) -> ViewRender:
        self.check_light(sun)
        q = self.quality
        t0 = time.perf_counter()
        hits = trace(rays, self.scene.object_mesh, self.scene.receiver)
        t_trace = time.perf_counter() - t0
        recv = np.flatnonzero(hits.kind == KIND_RECEIVER)
        pts, nrm = hits.points[recv], hits.normals[recv]
        # Margin 0.1 m: covers the in-pixel jitter of sun samples for footprints up to 0.2 m.
        reach = shadow_reach(self.scene.object_mesh.vertices, sun, pts, margin_m=0.1)
        t1 = time.perf_counter()
        sun_vis = np.ones(len(pts))
        if reach.any():
            sun_vis[reach] = self._sun(hits, rays, recv, np.flatnonzero(reach), pts, nrm, sun, rng)
        t_sun = time.perf_counter() - t1
        t1 = time.perf_counter()
        sky_vis = self.sky_map().at(pts)
        t_sky = time.perf_counter() - t1
        e_recv = irradiance(sun, nrm, sun_vis, sky_vis)
        obj = np.flatnonzero(hits.kind == KIND_OBJECT)
        e_obj = np.zeros(len(obj))
        if len(obj):
            opts, onrm = hits.points[obj], hits.normals[obj]
            facing = np.einsum("nj,j->n", onrm, sun.direction) > 0
            osun = np.zeros(len(obj))
            if facing.any():
                osun[facing] = sun_visibility(self.occluders, opts[facing], onrm[facing], sun,
                                              q.object_sun_samples, rng)
            osky = self._object_sky(hits, obj, rays.width)
            e_obj = irradiance(sun, onrm, osun, osky)
        refined = getattr(self, "_last_refined", int(reach.sum())) if reach.any() else 0
        sun_rays = (int(reach.sum()) * q.pilot_samples + refined * q.sun_samples if q.adaptive
                    else int(reach.sum()) * q.sun_samples)
        stats = {"seconds_trace": t_trace, "seconds_sun": t_sun, "seconds_sky_lookup": t_sky,
                 "receiver_pixels": int(len(recv)), "sun_reach_pixels": int(reach.sum()),
                 "sun_refined_pixels": refined, "sun_rays": sun_rays, "object_pixels": int(len(obj))}
        return _assemble(self.scene, ground, rays, hits, e_recv, e_obj, sun.lit_irradiance, stats)


    def _sun(self, hits, rays, recv, reach, pts, nrm, sun, rng) -> np.ndarray:
        """Sun visibility of the receiver points ``reach`` (indices into recv).

        Adaptive: a first pass with ``pilot_samples`` finds the pixels whose disk is
        partly hidden; those and their neighbours within 2 pixels (so a penumbra that a
        pilot pattern happened to miss is not lost) get ``sun_samples``; the others
        (deep umbra, full sun) keep the pilot's exact 0 or 1."""
        q = self.quality
        axes = pixel_axes(hits, rays.width, rays.height, recv[reach])
        if not q.adaptive or q.pilot_samples >= q.sun_samples:
            return sun_visibility(self.occluders, pts[reach], nrm[reach], sun, q.sun_samples, rng, pixel_axes=axes)
        vis = sun_visibility(self.occluders, pts[reach], nrm[reach], sun, q.pilot_samples, rng, pixel_axes=axes)
        mixed = np.zeros(rays.width * rays.height, np.uint8)
        mixed[recv[reach][(vis > 0) & (vis < 1)]] = 1
        near = cv2.dilate(mixed.reshape(rays.height, rays.width), np.ones((5, 5), np.uint8)).ravel()
        refine = near[recv[reach]] > 0
        if refine.any():
            vis[refine] = sun_visibility(self.occluders, pts[reach][refine], nrm[reach][refine], sun, q.sun_samples,
                                         rng, pixel_axes=axes[refine])
        self._last_refined = int(refine.sum())
        return vis

    def _object_sky(self, hits, obj: np.ndarray, width: int) -> np.ndarray:
        """Open sky of the object's pixels: computed on every other row and column (it is
        smooth and the object is not measured) and copied to the neighbours."""
        row, col = np.divmod(obj, width)
        anchor = (row - row % 2) * width + (col - col % 2)
        is_obj = np.zeros(len(hits.kind), bool)
        is_obj[obj] = True
        own = ~is_obj[anchor] | (anchor == obj)  # compute here when the anchor is not on the object
        src = np.where(own, obj, anchor)
        todo = np.unique(src)
        values = sky_visibility(self.occluders, hits.points[todo], hits.normals[todo],
                                self.quality.object_sky_samples, seed=self.seed + 1)
        lookup = np.zeros(len(hits.kind))
        lookup[todo] = values
        return lookup[src]


class ModelRenderer:
    """The project's soft shadow model with k = tan(sun radius) and rho of the light."""

    name = "model"

    def __init__(self, scene: SynthScene, rule: str = "edge", profile: str = "disk"):
        if scene.receiver.mesh is not None:
            raise ValueError("the model renderer draws shadows on the plane z = 0 only; "
                             "use renderer='physical' for a non-plane receiver")
        from softshadow import SoftShadowModel
        self.scene = scene
        self.model = SoftShadowModel.from_mesh(scene.object_mesh, rule=rule, profile=profile)

    def render(self, rays: ViewRays, sun: SunSky, ground: GroundAppearance,
               rng: np.random.Generator) -> ViewRender:
        from softshadow import Pose, ShadowParams, Sun
        t0 = time.perf_counter()
        hits = trace(rays, self.scene.object_mesh, self.scene.receiver)
        recv = np.flatnonzero(hits.kind == KIND_RECEIVER)
        pts = hits.points[recv]
        reach = shadow_reach(self.scene.object_mesh.vertices, sun, pts, margin_m=0.05, widen=2.0)
        shading = np.ones(len(pts))
        if reach.any():
            k, rho = sun.range_k, sun.rho
            sub = pts[reach].copy()
            sub[:, 2] = 0.0
            shading[reach] = np.asarray(self.model.at_points(ShadowParams(k, rho), Sun(sun.azimuth_deg,
                                                                                       sun.elevation_deg),
                                                             Pose(), sub, range_k_max=k))
        e_recv = sun.lit_irradiance * shading
        obj = np.flatnonzero(hits.kind == KIND_OBJECT)
        onrm = hits.normals[obj]
        e_obj = (sun.sun_normal_irradiance * np.clip(np.einsum("nj,j->n", onrm, sun.direction), 0, None)
                 + sun.sky_horizontal_irradiance * 0.5 * (1 + onrm[:, 2]))
        stats = {"seconds_total": time.perf_counter() - t0, "receiver_pixels": int(len(recv)),
                 "model_pixels": int(reach.sum()), "object_pixels": int(len(obj))}
        return _assemble(self.scene, ground, rays, hits, e_recv, e_obj, sun.lit_irradiance, stats)


def make_renderer(name: str, scene: SynthScene, quality: RenderQuality = RenderQuality(), seed: int = 0):
    """A renderer by name: 'physical' or 'model'."""
    if name == "physical":
        return PhysicalRenderer(scene, quality, seed)
    if name == "model":
        return ModelRenderer(scene)
    raise ValueError(f"unknown renderer {name!r}; choose one of {RENDERERS}")
