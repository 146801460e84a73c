"""A slide projector: projective texture mapping and a perspective shadow map (NumPy, discrete).

A projector is a point light at ``position`` looking at ``target`` (``up`` fixes the
slide's roll) whose beam passes through a slide (``softshadow.slides``): a pinhole
camera run backwards. Its camera is ``look_at_camera(position, target, W, H, fov_deg,
up)`` for the slide's W x H pixels, so the slide's pixel (u, v) lights the scene points
that a camera with that K, R, t would see at (u, v): the projective texture mapping of
Segal et al. that the Dowling paper uses. The irradiance it gives a surface point p with
unit normal n is

    E(p) = intensity * slide(u(p), v(p)) * max(0, n . l) * falloff(d) * lit(p)      (RGB)

with l the unit direction from p to the projector, d the distance, falloff(d) =
(reference_m / d)^2 for ``falloff="inverse-square"`` (reference_m defaults to the distance
to the target, so ``intensity`` is the irradiance at the target on a surface facing the
projector through a clear slide) or 1 for ``falloff="none"`` (the paper's OpenGL
projector), slide(...) bilinear, 0 outside the slide and behind the projector, and
lit(p) in {0, 1} the shadow test.

The shadow test is a perspective shadow map (Williams; the paper's section 5) built on
``shadowmap``: the occluding faces are drawn from the projector with
``rasterise_depth`` in normalised image coordinates (a, b) = (x/z, y/z) of the
projector's camera frame, with depth -1/z (affine in (a, b) over a planar triangle,
smaller is nearer), and each face's plane in (a, b, -1/z) is exact. A point's occluder
depth is the plane of the face at its map pixel (or a neighbour's) that contains it, so a
point on an occluder's surface compares against its own face; the bias is the sun's
(``shadowmap.depth_bias``, docs/shadow_map.md) with the light-space pixel replaced by the
map pixel's footprint at the point, pixel_tan * z (metres; an upper bound across the ray)
and the slopes taken against the ray to the projector. The test compares depths along
the projector's axis z, where an error along the ray shrinks by cos(off-axis angle), so
the bias is conservative off axis. Faces are cut ``NEAR_M`` in front of the projector's
plane (``clip.clip_near``): what lies behind it cannot be projected.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
from scipy import ndimage

from .camera import GroundGrid, PinholeCamera, look_at_camera
from .clip import clip_near
from .shadowmap import FACING_TOL, ShadowMap, depth_bias, shadow_map

__all__ = ["FALLOFFS", "NEAR_M", "Projector", "ProjectorShadowMap", "projector_shadow_map"]

FALLOFFS = ("inverse-square", "none")
NEAR_M = 1e-3  # faces closer than this to the projector's plane are not drawn in its shadow map
MAP_MARGIN_PX = 2  # map pixels beyond the slide's edges, so lookups at the rim find their faces


def _vector(value, name: str) -> np.ndarray:
    v = np.asarray(value, np.float64).reshape(-1)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"projector {name} must be 3 finite numbers, got {value!r}")
    return v


@dataclasses.dataclass(frozen=True, eq=False)
class Projector:
    """A slide projector (see the module docstring).

    position, target, up (3,) world metres / direction; slide (H, W, 3) linear
    transmittance in [0, 1] (``softshadow.slides``; (H, W) is taken as grey); fov_deg: the
    full angle across the slide's width (degrees, in (0, 170)); intensity >= 0: linear
    irradiance at ``reference_m`` on a surface facing the projector through a clear slide;
    falloff: "inverse-square" or "none"; reference_m: default the distance to the target;
    shadow_px: the shadow map's pixels across the slide's larger side.
    """

    position: np.ndarray
    target: np.ndarray
    slide: np.ndarray
    fov_deg: float = 30.0
    up: np.ndarray = (0.0, 0.0, 1.0)
    intensity: float = 1.0
    falloff: str = "inverse-square"
    reference_m: float | None = None
    shadow_px: int = 1024

    def __post_init__(self):
        pos, target, up = _vector(self.position, "position"), _vector(self.target, "target"), _vector(self.up, "up")
        object.__setattr__(self, "position", pos)
        object.__setattr__(self, "target", target)
        object.__setattr__(self, "up", up)
        forward = target - pos
        if np.linalg.norm(forward) < 1e-9:
            raise ValueError("projector target must differ from its position")
        if np.linalg.norm(up) < 1e-12:
            raise ValueError("projector up must not be zero")
        slide = np.asarray(self.slide, np.float64)
        if slide.ndim == 2:
            slide = np.repeat(slide[..., None], 3, axis=-1)
        if slide.ndim != 3 or slide.shape[2] != 3 or min(slide.shape[:2]) < 2:
            raise ValueError(f"projector slide must be an (H, W, 3) or (H, W) image, got shape {slide.shape}")
        if not np.all(np.isfinite(slide)) or slide.min() < 0:
            raise ValueError("projector slide values must be finite and >= 0")
        object.__setattr__(self, "slide", slide)
        if not (np.isfinite(self.fov_deg) and 0 < float(self.fov_deg) < 170):
            raise ValueError(f"projector fov_deg must be in (0, 170) degrees, got {self.fov_deg!r}")
        if not (np.isfinite(self.intensity) and float(self.intensity) >= 0):
            raise ValueError(f"projector intensity must be a number >= 0, got {self.intensity!r}")
        if self.falloff not in FALLOFFS:
            raise ValueError(f"projector falloff must be one of {FALLOFFS}, got {self.falloff!r}")
        if self.reference_m is not None and not (np.isfinite(self.reference_m) and self.reference_m > 0):
            raise ValueError(f"projector reference_m must be positive, got {self.reference_m!r}")
        if not (int(self.shadow_px) >= 16):
            raise ValueError(f"projector shadow_px must be at least 16, got {self.shadow_px!r}")

    @property
    def camera(self) -> PinholeCamera:
        """The projector as a pinhole camera whose image is the slide (W x H pixels)."""
        h, w = self.slide.shape[:2]
        return look_at_camera(self.position, self.target, w, h, float(self.fov_deg), self.up)

    @property
    def reference_distance_m(self) -> float:
        return float(self.reference_m) if self.reference_m is not None else float(
            np.linalg.norm(self.target - self.position))

    def image_coordinates(self, points) -> tuple[np.ndarray, np.ndarray]:
        """Normalised image coordinates (N, 2) (a, b) = (x/z, y/z) in the projector's camera frame
        (x right, y down along the slide) and the depth z (N,) along its axis (metres; <= 0 behind)."""
        cam = self.camera
        pc = np.asarray(points, np.float64).reshape(-1, 3) @ cam.R.T + cam.t
        z = pc[:, 2]
        safe = np.where(z > 0, z, 1.0)
        return pc[:, :2] / safe[:, None], z

    def slide_colour(self, points) -> np.ndarray:
        """The slide's transmittance (N, 3) at world points (N, 3): bilinear at their projection
        onto the slide, 0 outside it and behind the projector (projective texture mapping)."""
        ab, z = self.image_coordinates(points)
        K = self.camera.K
        u = K[0, 0] * ab[:, 0] + K[0, 1] * ab[:, 1] + K[0, 2]
        v = K[1, 1] * ab[:, 1] + K[1, 2]
        h, w = self.slide.shape[:2]
        # Inside the slide's outer pixel edges; bilinear with 0 beyond its border pixels' centres
        # would darken a half pixel inside the edge, so clamp to the edge instead.
        inside = (z > 0) & (u >= -0.5) & (u <= w - 0.5) & (v >= -0.5) & (v <= h - 0.5)
        coords = np.stack([np.clip(v, 0, h - 1), np.clip(u, 0, w - 1)])
        out = np.stack([ndimage.map_coordinates(self.slide[..., c], coords, order=1, mode="nearest")
                        for c in range(3)], -1)
        return np.where(inside[:, None], out, 0.0)

    def irradiance(self, points, normals=None, shadow: "ProjectorShadowMap | None" = None) -> np.ndarray:
        """Irradiance (N, 3) the projector gives world points (N, 3) with unit normals (N, 3)
        (None: surfaces facing the projector), through ``shadow`` (None: no shadows)."""
        p = np.asarray(points, np.float64).reshape(-1, 3)
        to_light = self.position - p
        d = np.linalg.norm(to_light, axis=1)
        d_safe = np.maximum(d, 1e-12)
        cos = np.ones(len(p)) if normals is None else np.maximum(
            np.einsum("ij,ij->i", np.asarray(normals, np.float64).reshape(-1, 3), to_light) / d_safe, 0.0)
        fall = (self.reference_distance_m / d_safe) ** 2 if self.falloff == "inverse-square" else np.ones(len(p))
        scalar = float(self.intensity) * cos * fall
        if shadow is not None:
            scalar = scalar * shadow.lit(p, normals)
        return self.slide_colour(p) * scalar[:, None]


@dataclasses.dataclass(frozen=True)
class ProjectorShadowMap:
    """A projector's perspective shadow map (see the module docstring).

    projector; smap: the ``ShadowMap`` in (a, -b) coordinates with depth -1/z, its slopes
    replaced by each face's tan against the ray from the projector (for the bias);
    pixel_tan: the map's pixel in normalised image units; scale: the coordinates' magnitude
    (metres) for the rounding allowance.
    """

    projector: Projector
    smap: ShadowMap | None
    pixel_tan: float
    scale: float

    @functools.cached_property
    def near_cover(self) -> np.ndarray:
        """Map pixels (H, W) bool with a covered pixel among their 3 x 3."""
        return ndimage.binary_dilation(self.smap.face_id >= 0, np.ones((3, 3), bool))

    def occluded(self, points, normals=None) -> np.ndarray:
        """Whether an occluder lies between the projector and each point (N,) bool, or (given unit
        normals (N, 3)) the point's surface faces away from the projector (attached shadow).
        Points behind the projector or outside the map: False (the slide gives them no light)."""
        p = np.asarray(points, np.float64).reshape(-1, 3)
        out = np.zeros(len(p), bool)
        if normals is not None:
            # Attached shadow, as for the sun: a surface turned away from the projector is unlit
            # (near the terminator the depth test's slope-scaled bias could otherwise pass it).
            ray = p - self.projector.position
            ray /= np.maximum(np.linalg.norm(ray, axis=1, keepdims=True), 1e-300)
            out = np.einsum("ij,ij->i", np.asarray(normals, np.float64).reshape(-1, 3), ray) >= -FACING_TOL
        if self.smap is None or not len(p):
            return out
        ab, z = self.projector.image_coordinates(p)
        g = self.smap.grid
        uv = np.column_stack([ab[:, 0], -ab[:, 1]])
        cr = g.to_pixel(uv)
        test = np.flatnonzero((z > NEAR_M) & (cr[:, 0] >= -0.5) & (cr[:, 0] <= g.width - 0.5)
                              & (cr[:, 1] >= -0.5) & (cr[:, 1] <= g.height - 0.5))
        # Only points with a covered map pixel among their 3 x 3 can be occluded (the lookup's
        # reach): the others (most of a lit floor) skip it.
        rc = np.clip(np.rint(cr[test]).astype(np.int64), 0, [g.width - 1, g.height - 1])
        test = test[self.near_cover[rc[:, 1], rc[:, 0]]]
        if not len(test):
            return out
        best, face_slope, exact = self.smap.occluder_depth(uv[test])
        # Unlike the sun's test, which runs only inside the occluder's silhouette region, this
        # one sees every point: an extrapolated plane (no face among the 9 pixels contains the
        # point) counts only where the point's own map pixel is covered, so the shadow's outline
        # is the map's raster (within 0.71 map pixel), not grown by the 2-pixel search.
        rc = np.clip(np.rint(cr[test]).astype(np.int64), 0, [g.width - 1, g.height - 1])
        covered = np.isfinite(self.smap.depth[rc[:, 1], rc[:, 0]])
        have = np.isfinite(best) & (best < 0) & (exact | covered)
        z_occ = np.where(have, -1.0 / np.where(have, best, -1.0), np.inf)
        recv_slope = 0.0
        if normals is not None:
            n = np.asarray(normals, np.float64).reshape(-1, 3)[test]
            ray = p[test] - self.projector.position
            ray /= np.maximum(np.linalg.norm(ray, axis=1, keepdims=True), 1e-300)
            cos = np.abs(np.einsum("ij,ij->i", n, ray))
            recv_slope = np.sqrt(np.maximum(1.0 - cos * cos, 0.0)) / np.maximum(cos, 1e-12)
        scale = max(self.scale, float(np.abs(p[test]).max()))
        bias = depth_bias(self.pixel_tan * z[test], face_slope, recv_slope, scale, np.float64, exact)
        out[test] |= z[test] > z_occ + bias
        return out

    def lit(self, points, normals=None) -> np.ndarray:
        """1.0 where the projector sees the point, 0.0 where an occluder hides it (N,)."""
        return (~self.occluded(points, normals)).astype(np.float64)


def projector_shadow_map(projector: Projector, vertices, faces) -> ProjectorShadowMap:
    """The perspective shadow map of the occluding triangles (world vertices (V, 3), faces (F, 3))
    seen from ``projector``; ``shadow_px`` pixels across the slide's larger side."""
    world = np.asarray(vertices, np.float64).reshape(-1, 3)
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    # Faces cut at the near plane: the part of a face in front of the projector still casts.
    _, z_world = projector.image_coordinates(world)
    world, faces, _ = clip_near(world, z_world, faces, NEAR_M)
    ab, z = projector.image_coordinates(world)
    h, w = projector.slide.shape[:2]
    K = projector.camera.K
    half = np.array([0.5 * w / K[0, 0], 0.5 * h / K[1, 1]])  # the slide's half extent in (a, b)
    pixel_tan = float(2 * half.max() / int(projector.shadow_px))
    width = int(np.ceil(2 * half[0] / pixel_tan)) + 2 * MAP_MARGIN_PX
    height = int(np.ceil(2 * half[1] / pixel_tan)) + 2 * MAP_MARGIN_PX
    # Map pixel (0, 0) centred at the slide's top-left corner less the margin; the map's "y" is
    # -b so that rows grow downwards along the slide as GroundGrid's rows do.
    origin = (-(width - 1) / 2 * pixel_tan, (height - 1) / 2 * pixel_tan)
    grid = GroundGrid(pixel_tan, origin, width, height)
    scale = float(np.abs(world).max(initial=1.0))
    keep = faces
    if not len(keep):
        return ProjectorShadowMap(projector, None, pixel_tan, scale)
    uv = np.column_stack([ab[:, 0], -ab[:, 1]])
    smap = shadow_map(grid, uv, -1.0 / np.maximum(z, NEAR_M), keep)  # originals behind: unused
    # The bias's slope term in metric terms: tan of the angle between each face's normal and the
    # ray from the projector to its centroid.
    tri = world[keep]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    ray = tri.mean(1) - projector.position
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    cos = np.abs(np.einsum("ij,ij->i", normal, ray))
    slope = np.sqrt(np.maximum(1.0 - cos * cos, 0.0)) / np.maximum(cos, 1e-12)
    return ProjectorShadowMap(projector, dataclasses.replace(smap, slope=slope), pixel_tan, scale)
