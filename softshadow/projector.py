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
from typing import Literal

import numpy as np

from .camera import GroundGrid, PinholeCamera, look_at_camera
from .clip import clip_near
from .parallel_loops import parallel_numba
from .scratch import Scratch, scratch_array
from .shadowmap import (_LOOKUP_OFFSETS, _NEAREST_OFFSETS, BIAS_PX, FACING_TOL, PRECISION_ULPS, SLOPE_PX, TAN_MAX,
                        ShadowMap, rasterise_depth)

__all__ = ["FALLOFFS", "NEAR_M", "Projector", "ProjectorShadowMap", "projector_shadow_map"]

FALLOFFS = ("inverse-square", "none")
NEAR_M = 1e-3  # faces closer than this to the projector's plane are not drawn in its shadow map
MAP_MARGIN_PX = 2  # map pixels beyond the slide's edges, so lookups at the rim find their faces


def _vector(value, name: str) -> np.ndarray:
    v = np.asarray(value, np.float64).reshape(-1)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"projector {name} must be 3 finite numbers, got {value!r}")
    return v


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class Projector:
    """A slide projector (see the module docstring).

    position, target, up (3,) world metres / direction; slide (H, W, 3) linear
    transmittance in [0, 1] (``softshadow.slides``; (H, W) is taken as grey); fov_deg: the
    full angle across the slide's width (degrees, in (0, 170)); intensity >= 0: linear
    irradiance at ``reference_m`` on a surface facing the projector through a clear slide;
    falloff: "inverse-square" or "none"; reference_m: default the distance to the target;
    shadow_px: the shadow map's pixels across the slide's larger side.
    """

    position: np.ndarray = dataclasses.field(kw_only=False)
    target: np.ndarray = dataclasses.field(kw_only=False)
    slide: np.ndarray = dataclasses.field(kw_only=False)
    fov_deg: float = 30.0
    up: np.ndarray = (0.0, 0.0, 1.0)
    intensity: float = 1.0
    falloff: Literal["inverse-square", "none"] = "inverse-square"
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

    @functools.cached_property
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
        p = np.ascontiguousarray(points, np.float64).reshape(-1, 3)
        out = np.zeros((len(p), 3))
        _light_kernel()(p, np.zeros((0, 3)), *self._kernel_args(), *_NO_MAP, np.zeros(0, np.int64), 0, out,
                        np.empty(0))
        return out

    def irradiance(self, points, normals=None, shadow: "ProjectorShadowMap | None" = None) -> np.ndarray:
        """Irradiance (N, 3) the projector gives world points (N, 3) with unit normals (N, 3)
        (None: surfaces facing the projector), through ``shadow`` (None: no shadows)."""
        p = np.ascontiguousarray(points, np.float64).reshape(-1, 3)
        out = np.zeros((len(p), 3))
        self.add_irradiance(p, normals, shadow, out)
        return out

    def add_irradiance(self, points: np.ndarray, normals, shadow: "ProjectorShadowMap | None",
                       out: np.ndarray, faces: np.ndarray | None = None) -> None:
        """``irradiance`` added to ``out`` (N, 3) in place (points (N, 3) float64, C order).

        faces (N,) int, optional: the face of the shadow map's triangles each point lies on (-1:
        none), as a camera's z-buffer knows it; a point whose face is the map's nearest at its
        pixel is lit without the lookup (it would find that face and the point on it).
        """
        n = np.zeros((0, 3)) if normals is None else np.ascontiguousarray(normals, np.float64).reshape(-1, 3)
        own = (np.zeros(0, np.int64) if faces is None or shadow is None or not shadow.faces_as_given
               else np.ascontiguousarray(faces, np.int64))
        _light_kernel()(points, n, *self._kernel_args(), *(_NO_MAP if shadow is None else shadow._kernel_args()),
                        own, 1, out, np.empty(0))

    def _kernel_args(self) -> tuple:
        cam = self.camera
        falloff = 1.0 if self.falloff == "inverse-square" else 0.0
        frame = np.vstack([cam.R, cam.t, cam.K[:2], self.position])  # rows 0-2 R, 3 t, 4-5 K, 6 position
        return frame, self._texture, float(self.intensity), falloff, self.reference_distance_m

    @functools.cached_property
    def _texture(self) -> np.ndarray:
        """The slide as the light kernel reads it: float32 (its values to 6e-8, and half the memory
        to fetch from), one channel when the slide is grey (H, W, 1), else (H, W, 3)."""
        grey = np.array_equal(self.slide[..., 0], self.slide[..., 1]) and np.array_equal(
            self.slide[..., 0], self.slide[..., 2])
        return np.ascontiguousarray(self.slide[..., :1] if grey else self.slide, np.float32)


@dataclasses.dataclass(frozen=True)
class ProjectorShadowMap:
    """A projector's perspective shadow map (see the module docstring).

    projector; smap: the ``ShadowMap`` in (a, -b) coordinates with depth -1/z, its slopes
    replaced by each face's tan against the ray from the projector (for the bias);
    pixel_tan: the map's pixel in normalised image units; scale: the coordinates' magnitude
    (metres) for the rounding allowance; faces_as_given: the map's face ids are the indices of
    the faces it was made from (no face was cut at the near plane).
    """

    projector: Projector
    smap: ShadowMap | None
    pixel_tan: float
    scale: float
    faces_as_given: bool = False

    def occluded(self, points, normals=None) -> np.ndarray:
        """Whether an occluder lies between the projector and each point (N,) bool, or (given unit
        normals (N, 3)) the point's surface faces away from the projector (attached shadow).
        Points behind the projector or outside the map: False (the slide gives them no light)."""
        return self.lit(points, normals) == 0.0

    def lit(self, points, normals=None) -> np.ndarray:
        """1.0 where the projector sees the point, 0.0 where an occluder hides it (N,)."""
        p = np.ascontiguousarray(points, np.float64).reshape(-1, 3)
        n = np.zeros((0, 3)) if normals is None else np.ascontiguousarray(normals, np.float64).reshape(-1, 3)
        lit = np.empty(len(p))
        _light_kernel()(p, n, *self.projector._kernel_args(), *self._kernel_args(), np.zeros(0, np.int64), 2,
                        np.zeros((0, 3)), lit)
        return lit

    @functools.cached_property
    def near_cover(self) -> np.ndarray:
        """Map pixels (H, W) uint8: 1 where a covered pixel lies among their 3 x 3 (only points
        there can be occluded)."""
        import cv2
        covered = (self.smap.face_id >= 0).view(np.uint8)
        return cv2.dilate(covered, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT, borderValue=0)

    def _kernel_args(self) -> tuple:
        if self.smap is None:
            return _NO_MAP
        g = self.smap.grid
        geometry = np.array([g.origin_m[0], g.origin_m[1], g.pixel_m, self.pixel_tan, self.scale])
        return (True, self.smap.face_id, self.near_cover, self._packed_faces, np.ascontiguousarray(self.smap.slope),
                geometry)

    @functools.cached_property
    def _packed_faces(self) -> np.ndarray:
        """Per face (F, 9), what a lookup reads, together: its first corner (u0, v0), the
        barycentric coordinates' gradients (b1 = (u - u0) g1u + (v - v0) g1v, b2 alike) and its
        depth plane (A, B, d0)."""
        tri, plane = self.smap.triangle, self.smap.plane
        e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
        area = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        area = np.where(area == 0, 1.0, area)
        return np.ascontiguousarray(np.column_stack([tri[:, 0], e2[:, 1] / area, -e2[:, 0] / area,
                                                     -e1[:, 1] / area, e1[:, 0] / area, plane]))


# A projector without a shadow map, as the light kernel takes it.
_NO_MAP = (False, np.zeros((1, 1), np.int32), np.zeros((1, 1), np.uint8), np.zeros((1, 9)), np.zeros(1),
           np.array([0.0, 0.0, 1.0, 1.0, 0.0]))


@functools.cache
def _light_kernel():
    """The compiled projector (numba): per point, projective texture mapping (the slide,
    bilinear, clamped at its edge pixels' centres), the cosine and the falloff, and the shadow
    map's test (``ProjectorShadowMap``'s rules: attached shadow; only points with a covered map
    pixel among their 3 x 3 are looked up; the exact face among the point's pixel and its 8
    neighbours, else the nearest covered pixel's within 2, extrapolated, counting only where the
    point's own pixel is covered; the bias of ``shadowmap.depth_bias`` with the map pixel's
    footprint pixel_tan z). mode 0: the slide's colour into out (N, 3); 1: the irradiance added
    to out; 2: lit (N,) 1.0 / 0.0."""
    numba = parallel_numba()

    # Parallel over the points (each writes its own row): a frame's 300,000 points are the
    # largest single step of a scene image.
    @numba.njit(cache=True, nogil=True, parallel=True)
    def kernel(points, normals, frame, slide, intensity, falloff, reference, has_map, face_id, near_cover, packed,
               face_slope, geometry, own_face, mode, out, lit):
        n_pts = points.shape[0]
        has_normals = normals.shape[0] > 0
        sh, sw, channels = slide.shape[0], slide.shape[1], slide.shape[2]
        px, py, pz = frame[6, 0], frame[6, 1], frame[6, 2]
        mh, mw = face_id.shape
        ox, oy, inv_pt, pixel_tan = geometry[0], geometry[1], 1.0 / geometry[2], geometry[3]
        # The rounding allowance's scale: the largest coordinate of the map's faces and the points.
        scale = geometry[4]
        if has_map and mode != 0:
            for i in numba.prange(n_pts):
                scale = max(scale, max(abs(points[i, 0]), abs(points[i, 1]), abs(points[i, 2])))
        rounding = PRECISION_ULPS * np.finfo(np.float64).eps * scale
        for i in numba.prange(n_pts):
            p0, p1, p2 = points[i, 0], points[i, 1], points[i, 2]
            x = frame[0, 0] * p0 + frame[0, 1] * p1 + frame[0, 2] * p2 + frame[3, 0]
            y = frame[1, 0] * p0 + frame[1, 1] * p1 + frame[1, 2] * p2 + frame[3, 1]
            z = frame[2, 0] * p0 + frame[2, 1] * p1 + frame[2, 2] * p2 + frame[3, 2]
            if mode == 2:
                lit[i] = 1.0
            u, v, inv_z = 0.0, 0.0, 1.0
            if mode != 2:
                # On the slide or no light at all: nothing else to do.
                inv_z = 1.0 / z if z > 0 else 1.0
                u = frame[4, 0] * (x * inv_z) + frame[4, 1] * (y * inv_z) + frame[4, 2]
                v = frame[5, 1] * (y * inv_z) + frame[5, 2]
                if not (z > 0 and -0.5 <= u <= sw - 0.5 and -0.5 <= v <= sh - 0.5):
                    continue
            scalar = 1.0
            cos_r = 1.0
            if mode != 0:
                lx, ly, lz = px - p0, py - p1, pz - p2
                d = np.sqrt(lx * lx + ly * ly + lz * lz)
                inv_d = 1.0 / max(d, 1e-12)
                if has_normals:
                    dot = normals[i, 0] * lx + normals[i, 1] * ly + normals[i, 2] * lz
                    # Attached shadow: the normal against the ray from the projector.
                    cos_r = -dot / max(d, 1e-300)
                    if cos_r >= -FACING_TOL:
                        if mode == 2:
                            lit[i] = 0.0
                        continue
                    scalar = max(dot * inv_d, 0.0)
                if mode == 1:
                    fall = 1.0
                    if falloff > 0.0:
                        q = reference * inv_d
                        fall = q * q
                    scalar = intensity * scalar * fall
                    if scalar == 0.0:
                        continue
            if mode != 0 and has_map and z > NEAR_M:
                inv = 1.0 / z if mode == 2 else inv_z
                a, b = x * inv, -(y * inv)
                col, row = (a - ox) * inv_pt, (oy - b) * inv_pt
                if -0.5 <= col <= mw - 0.5 and -0.5 <= row <= mh - 0.5:
                    r = int(min(max(np.rint(row), 0.0), mh - 1.0))
                    c = int(min(max(np.rint(col), 0.0), mw - 1.0))
                    # Only points with a covered pixel among their 3 x 3 can be occluded; a point on
                    # the face nearest the projector at its pixel is not.
                    if near_cover[r, c] and not (own_face.shape[0] and own_face[i] >= 0
                                                 and face_id[r, c] == own_face[i]):
                        # The face's plane at the point: exact from the first of the 9 pixels whose
                        # face contains it, else extrapolated from the nearest covered pixel's
                        # within 2.
                        best, fs, exact = np.inf, 0.0, False
                        for k in range(_LOOKUP_OFFSETS.shape[0]):
                            rr, cc = r + _LOOKUP_OFFSETS[k, 0], c + _LOOKUP_OFFSETS[k, 1]
                            if rr < 0 or rr >= mh or cc < 0 or cc >= mw:
                                continue
                            f = face_id[rr, cc]
                            if f < 0:
                                continue
                            qx, qy = a - packed[f, 0], b - packed[f, 1]
                            b1 = qx * packed[f, 2] + qy * packed[f, 3]
                            b2 = qx * packed[f, 4] + qy * packed[f, 5]
                            if b1 >= -1e-7 and b2 >= -1e-7 and b1 + b2 <= 1.0 + 1e-7:
                                best, exact = packed[f, 8] + packed[f, 6] * qx + packed[f, 7] * qy, True
                                break
                        if not exact:
                            for k in range(_NEAREST_OFFSETS.shape[0]):
                                rr, cc = r + _NEAREST_OFFSETS[k, 0], c + _NEAREST_OFFSETS[k, 1]
                                if rr < 0 or rr >= mh or cc < 0 or cc >= mw:
                                    continue
                                f = face_id[rr, cc]
                                if f >= 0:
                                    best = packed[f, 8] + packed[f, 6] * (a - packed[f, 0]) + packed[f, 7] * (
                                        b - packed[f, 1])
                                    fs = face_slope[f]
                                    break
                        if np.isfinite(best) and best < 0 and (exact or face_id[r, c] >= 0):
                            recv = 0.0
                            if has_normals:
                                cr = abs(cos_r)
                                recv = np.sqrt(max(1.0 - cr * cr, 0.0)) / max(cr, 1e-12)
                            pixel_m = pixel_tan * z
                            bias = BIAS_PX * pixel_m + rounding
                            if not exact:
                                bias += SLOPE_PX * pixel_m * (min(fs, TAN_MAX) + min(recv, TAN_MAX))
                            if z > -1.0 / best + bias:
                                if mode == 2:
                                    lit[i] = 0.0
                                continue
            if mode == 2:
                continue
            # Bilinear on the slide, its coordinates clamped to the edge pixels' centres; a grey
            # slide is one channel.
            vv, uu = min(max(v, 0.0), sh - 1.0), min(max(u, 0.0), sw - 1.0)
            r0, c0 = int(vv), int(uu)
            r1, c1 = min(r0 + 1, sh - 1), min(c0 + 1, sw - 1)
            fr, fc = vv - r0, uu - c0
            for k in range(channels):
                top = slide[r0, c0, k] * (1.0 - fc) + slide[r0, c1, k] * fc
                bottom = slide[r1, c0, k] * (1.0 - fc) + slide[r1, c1, k] * fc
                value = scalar * (top * (1.0 - fr) + bottom * fr)
                if channels == 1:
                    out[i, 0] += value
                    out[i, 1] += value
                    out[i, 2] += value
                else:
                    out[i, k] += value

    return kernel


def projector_shadow_map(projector: Projector, vertices, faces, *, facing=None, threads: int = 1,
                         scratch: Scratch | None = None, name: str = "projector") -> ProjectorShadowMap:
    """The perspective shadow map of the occluding triangles (world vertices (V, 3), faces (F, 3))
    seen from ``projector``; ``shadow_px`` pixels across the slide's larger side.

    facing (F,) int8, optional: -1 for the faces of closed, outward-wound meshes, whose faces
    turned away from the projector are then not drawn (``rasterise_depth``); 0 otherwise. threads:
    2 lets the map of a large mesh be drawn on two threads (``rasterise_depth``).
    scratch, name: keep the map's arrays in these buffers under this name (``softshadow.scratch``;
    the map is then overwritten by the next one made with them).
    """
    world = np.ascontiguousarray(vertices, np.float64).reshape(-1, 3)
    faces = np.ascontiguousarray(faces, np.int64).reshape(-1, 3)
    facing = None if facing is None else np.asarray(facing, np.int8).reshape(len(faces))
    # Faces cut at the near plane: the part of a face in front of the projector still casts. A
    # closed mesh cut open shows its inside, so nothing is culled then.
    ab, z = projector.image_coordinates(world)
    as_given = True
    if len(world) and z.min() <= NEAR_M:
        world, faces, _ = clip_near(world, z, faces, NEAR_M)
        facing, as_given = None, False
        ab, z = projector.image_coordinates(world)
    h, w = projector.slide.shape[:2]
    K = projector.camera.K
    half = np.array([0.5 * w / K[0, 0], 0.5 * h / K[1, 1]])  # the slide's half extent in (a, b)
    pixel_tan = float(2 * half.max() / int(projector.shadow_px))
    width = int(np.ceil(2 * half[0] / pixel_tan)) + 2 * MAP_MARGIN_PX
    height = int(np.ceil(2 * half[1] / pixel_tan)) + 2 * MAP_MARGIN_PX
    # Map pixel (0, 0) centred at the slide's top-left corner less the margin; the map's "y" is
    # -b so that rows grow downwards along the slide as GroundGrid's rows do (in its pixels a
    # face seen from its front winds with a negative signed area, as in a camera's).
    origin = (-(width - 1) / 2 * pixel_tan, (height - 1) / 2 * pixel_tan)
    grid = GroundGrid(pixel_tan, origin, width, height)
    scale = float(np.abs(world).max(initial=1.0))
    if not len(faces):
        return ProjectorShadowMap(projector, None, pixel_tan, scale)
    uv = np.column_stack([ab[:, 0], -ab[:, 1]])
    depth = -1.0 / np.maximum(z, NEAR_M)  # the originals behind the plane are unused
    zbuf, fid = rasterise_depth(grid.to_pixel(uv), depth, faces, (height, width), facing=facing,
                                out=(scratch_array(scratch, f"{name}.zbuf", (height, width)),
                                     scratch_array(scratch, f"{name}.face_id", (height, width), np.int32)),
                                threads=threads, scratch=scratch, name=name)
    # Per face, in one pass: the map's triangle and depth plane (``shadow_map``'s), the bias's slope
    # term in metric terms (tan of the angle between the face's normal and the ray from the
    # projector to its centroid) and the lookup's packed data.
    f = len(faces)
    triangle = scratch_array(scratch, f"{name}.triangle", (f, 3, 2))
    plane = scratch_array(scratch, f"{name}.plane", (f, 3))
    slope = scratch_array(scratch, f"{name}.slope", f)
    packed = scratch_array(scratch, f"{name}.packed", (f, 9))
    map_scale = _faces_kernel()(world, uv, depth, faces, projector.position, triangle, plane, slope, packed)
    smap = ShadowMap(grid, zbuf, fid, plane, slope, triangle, map_scale)
    out = ProjectorShadowMap(projector, smap, pixel_tan, scale, as_given)
    out.__dict__["_packed_faces"] = packed  # the cached property, computed here
    return out


@functools.cache
def _faces_kernel():
    """Per face (numba): its map triangle (F, 3, 2) and depth plane (F, 3) as ``shadow_map``
    makes them (``shadowmap._face_planes``'s arithmetic), tan of the angle between its normal
    and the ray from the projector to its centroid (F,), and ``_packed_faces``' row (F, 9);
    returns ``shadow_map``'s scale (the largest |u|, |v|, |depth| of the vertices, at least 1)."""
    import numba

    @numba.njit(cache=True, nogil=True)
    def kernel(world, uv, depth, faces, position, triangle, plane, slope, packed):
        scale = 1.0
        for i in range(uv.shape[0]):
            scale = max(scale, abs(uv[i, 0]), abs(uv[i, 1]), abs(depth[i]))
        for f in range(faces.shape[0]):
            i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
            u0, v0 = uv[i0, 0], uv[i0, 1]
            triangle[f, 0, 0], triangle[f, 0, 1] = u0, v0
            triangle[f, 1, 0], triangle[f, 1, 1] = uv[i1, 0], uv[i1, 1]
            triangle[f, 2, 0], triangle[f, 2, 1] = uv[i2, 0], uv[i2, 1]
            # The depth plane about the first corner (``_face_planes``).
            ux, uy, uz = uv[i1, 0] - u0, uv[i1, 1] - v0, depth[i1] - depth[i0]
            vx, vy, vz = uv[i2, 0] - u0, uv[i2, 1] - v0, depth[i2] - depth[i0]
            nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
            nd = nz if abs(nz) > 1e-300 else 1e-300
            pa, pb = -nx / nd, -ny / nd
            plane[f, 0], plane[f, 1], plane[f, 2] = pa, pb, depth[i0]
            # The lookup's barycentric gradients (``ProjectorShadowMap._packed_faces``).
            area = ux * vy - uy * vx
            if area == 0:
                area = 1.0
            packed[f, 0], packed[f, 1] = u0, v0
            packed[f, 2], packed[f, 3] = vy / area, -vx / area
            packed[f, 4], packed[f, 5] = -uy / area, ux / area
            packed[f, 6], packed[f, 7], packed[f, 8] = pa, pb, depth[i0]
            # The slope against the ray from the projector.
            ux, uy, uz = world[i1, 0] - world[i0, 0], world[i1, 1] - world[i0, 1], world[i1, 2] - world[i0, 2]
            vx, vy, vz = world[i2, 0] - world[i0, 0], world[i2, 1] - world[i0, 1], world[i2, 2] - world[i0, 2]
            nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
            rx = (world[i0, 0] + world[i1, 0] + world[i2, 0]) / 3.0 - position[0]
            ry = (world[i0, 1] + world[i1, 1] + world[i2, 1]) / 3.0 - position[1]
            rz = (world[i0, 2] + world[i1, 2] + world[i2, 2]) / 3.0 - position[2]
            norm = max(np.sqrt(nx * nx + ny * ny + nz * nz), 1e-300) * np.sqrt(rx * rx + ry * ry + rz * rz)
            cos = abs(nx * rx + ny * ry + nz * rz) / norm
            slope[f] = np.sqrt(max(1.0 - cos * cos, 0.0)) / max(cos, 1e-12)
        return scale

    return kernel

