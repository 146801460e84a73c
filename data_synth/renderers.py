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
from .physical import (RAY_OFFSET_M, combined_mesh, irradiance, shadow_reach, sky_visibility,
                       sky_visibility_map, sun_visibility)
from .receivers import MeshReceiver, Receiver, texture_coordinates
from .textures import GroundAppearance
from .tracing import KIND_OBJECT, KIND_RECEIVER, ViewRays, pixel_axes, trace

__all__ = ["RENDERERS", "SynthScene", "RenderQuality", "ViewRender", "PhysicalRenderer", "ModelRenderer",
           "make_renderer"]

RENDERERS = ("physical", "model")


@dataclasses.dataclass(frozen=True, eq=False)
class SynthScene:
    """An object (world-frame mesh, linear RGB albedo) on a receiver (PlaneReceiver,
    HeightfieldReceiver or MeshReceiver). The ground's appearance is given per render (it may change
    between photos: paper laid out anew, another place)."""

    object_mesh: trimesh.Trimesh
    object_albedo: tuple[float, float, float]
    receiver: Receiver


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


def _dot_rows(a: np.ndarray, v: np.ndarray) -> np.ndarray:
    """a (N, 3) . v (3,) -> (N,), elementwise (BLAS threads fight Embree's here)."""
    return a[:, 0] * v[0] + a[:, 1] * v[1] + a[:, 2] * v[2]


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
        radiance[recv] = ground.reflectance(texture_coordinates(hits.points[recv], hits.normals[recv])) \
            * e_recv[:, None]
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
        self._blockers: trimesh.Trimesh | None = None

    def sky_map(self):
        """The receiver's sky on world grids (the plane and the height field: a function of x, y)."""
        if self._sky_map is None:
            q = self.quality
            self._sky_map = sky_visibility_map(self.occluders, self.scene.receiver, self.scene.object_mesh.bounds,
                                               q.sky_samples, self.seed, q.sky_fine_nodes)
        return self._sky_map

    def check_light(self, sun: SunSky) -> None:
        """A height field must not shadow itself (its shadows would be missing outside the object's
        reach); a mesh receiver may (its own shadows are cast everywhere, ``_self_shadow``)."""
        if isinstance(self.scene.receiver, MeshReceiver):
            return
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
        mesh_receiver = isinstance(self.scene.receiver, MeshReceiver)
        if mesh_receiver:
            sun_vis, near_edge = self._self_shadow(rays, recv, pts, nrm, sun)
            reach |= near_edge
        if reach.any():
            sun_vis[reach] = self._sun(hits, rays, recv, np.flatnonzero(reach), pts, nrm, sun, rng)
        t_sun = time.perf_counter() - t1
        t1 = time.perf_counter()
        sky_vis = self._mesh_receiver_sky(hits, rays, recv) if mesh_receiver else self.sky_map().at(pts)
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

    def _self_shadow(self, rays, recv, pts, nrm, sun) -> tuple[np.ndarray, np.ndarray]:
        """A mesh receiver's own hard shadow: sun visibility (M,) of the receiver pixels recv (M,)
        from one ray to the sun's centre against the receiver (0 or 1; faces turned away from
        the sun get 0, their cosine is 0 anyway), and the pixels within 3 of its edge (M,) bool,
        which the caller samples over the whole disk (their penumbra)."""
        facing = _dot_rows(nrm, sun.direction) > 0
        lit = np.zeros(len(pts))
        if facing.any():
            s = np.broadcast_to(sun.direction, (int(facing.sum()), 3))
            origins = pts[facing] + RAY_OFFSET_M * s
            lit[facing] = ~self.scene.receiver.mesh.ray.intersects_any(origins, s)
        img = np.zeros(rays.width * rays.height, np.uint8)
        img[recv] = 1 + lit.astype(np.uint8)  # 0: not the receiver, 1: its shadow, 2: lit
        img = img.reshape(rays.height, rays.width)
        kernel = np.ones((7, 7), np.uint8)
        # Edge: a lit and a shadowed receiver pixel within 3 pixels (not the object's outline).
        shadowed = cv2.dilate((img == 1).astype(np.uint8), kernel)
        lit_near = cv2.dilate((img == 2).astype(np.uint8), kernel)
        near = (shadowed & lit_near).ravel()[recv] > 0
        return lit, near & facing

    def _sky_blockers(self) -> trimesh.Trimesh:
        """What can hide sky from a mesh receiver: the object and the receiver's faces that
        rise above its lowest level (a flat floor there cannot block rays going up from points
        on or above it; leaving it out lets the bounding-sphere cull work)."""
        if self._blockers is None:
            mesh = self.scene.receiver.mesh
            low = float(mesh.bounds[0, 2])
            tall = np.asarray(mesh.triangles)[:, :, 2].max(axis=1) > low + 1e-6
            parts = [self.scene.object_mesh]
            if tall.any():
                parts.append(mesh.submesh([np.flatnonzero(tall)], append=True))
            self._blockers = combined_mesh(*parts)
        blockers: trimesh.Trimesh = self._blockers
        return blockers

    def _mesh_receiver_sky(self, hits, rays, recv, step: int = 4) -> np.ndarray:
        """Open sky (M,) of a mesh receiver's pixels recv: cast on a lattice of every step-th
        pixel and interpolated bilinearly between the four lattice pixels around a pixel when
        they lie on its own plane (the sky is smooth along a face); computed directly at the
        others (creases, the object's outline), so no value is blended across a crease. Each
        plane's points share one set of directions (its normal's), so the estimate is coherent."""
        h, w = rays.height, rays.width
        q = self.quality
        pts, nrm = hits.points, hits.normals
        plane = np.full(h * w, -1, np.int64)
        key = np.round(np.column_stack([nrm[recv], _dot_rows(nrm[recv] * pts[recv], np.ones(3))]) * 200.0)
        key = key.astype(np.int64) + 4096  # four small integers -> one (1-D unique is fast)
        flat = ((key[:, 0] * 8192 + key[:, 1]) * 8192 + key[:, 2]) * 8192 + key[:, 3]
        ids, first, inverse = np.unique(flat, return_index=True, return_inverse=True)
        plane[recv] = inverse
        normal_of = nrm[recv][first]  # one normal per plane
        blockers = self._sky_blockers()
        n_dirs = q.sky_samples // 4  # per pixel here, per grid node (4x denser) for the height field

        def sky(index):
            out = np.zeros(len(index))
            pid = plane[index]
            for p in np.unique(pid):
                sel = pid == p
                out[sel] = sky_visibility(blockers, pts[index[sel]],
                                          np.broadcast_to(normal_of[p], (int(sel.sum()), 3)), n_dirs, self.seed)
            return out

        ar = np.unique(np.r_[np.arange(0, h, step), h - 1])
        ac = np.unique(np.r_[np.arange(0, w, step), w - 1])
        anchors = (ar[:, None] * w + ac[None, :]).ravel()
        anchors = anchors[plane[anchors] >= 0]
        value = np.zeros(h * w)
        value[anchors] = sky(anchors)
        row, col = np.divmod(recv, w)
        i0 = np.clip(np.searchsorted(ar, row, "right") - 1, 0, max(len(ar) - 2, 0))
        j0 = np.clip(np.searchsorted(ac, col, "right") - 1, 0, max(len(ac) - 2, 0))
        i1, j1 = np.minimum(i0 + 1, len(ar) - 1), np.minimum(j0 + 1, len(ac) - 1)
        corners = [ar[i] * w + ac[j] for i in (i0, i1) for j in (j0, j1)]
        same = np.all([plane[c] == plane[recv] for c in corners], axis=0)
        fr = np.where(ar[i1] > ar[i0], (row - ar[i0]) / np.maximum(ar[i1] - ar[i0], 1), 0.0)
        fc = np.where(ac[j1] > ac[j0], (col - ac[j0]) / np.maximum(ac[j1] - ac[j0], 1), 0.0)
        weights = [(1 - fr) * (1 - fc), (1 - fr) * fc, fr * (1 - fc), fr * fc]
        out = np.zeros(len(recv))
        for c, wgt in zip(corners, weights):
            out += wgt * value[c]
        direct = np.flatnonzero(~same)
        if len(direct):
            out[direct] = sky(recv[direct])
        return out

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
