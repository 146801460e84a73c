"""The sun's shadow map: the occluder seen from the light, its depth, and the depth test (NumPy).

The sun is orthographic: every point p maps to light space by a rigid change of
frame, (u, v) = ((p - o) . e1, (p - o) . e2) on a plane perpendicular to the
light L, and depth d = (p - o) . L (metres along the light's travel, growing
away from the sun). The occluder's faces drawn there with their depths give
the shadow map: for every light-space pixel the nearest face to the sun and
its depth. A receiver point is behind the occluder (in its cast shadow) when
its depth exceeds the occluder's depth at its (u, v) by more than a bias.

``rasterise_depth`` is generic over the projection: it takes any 2-D pixel
coordinates and per-vertex depths that are affine in them over a triangle
(orthographic depth here; a perspective projector passes NDC depth or 1/w).

The bias (see docs/shadow_map.md). The map stores, per pixel, which face is
nearest the sun. A receiver point takes the face of its pixel, or else of
the first of the 8 around it, whose light-space triangle contains it, and
compares against that face's plane evaluated at its own (u, v): exact, so a
point on a face of the occluder compares against itself and only rounding is
left. Where no such face is found (a face smaller than a pixel, missed by
every pixel centre) the nearest covered pixel's face plane is extrapolated,
by under 0.71 pixel: an error up to 0.71 px (tan a + tan b) for the two
surfaces' slopes. So

    bias = BIAS_PX * pixel + PRECISION_ULPS * eps(dtype) * scale + tolerance
           [+ SLOPE_PX * pixel * (min(tan_face, TAN_MAX) + min(tan_recv, TAN_MAX)) where extrapolated]

with tan the slope of the depth across light space (tan of the angle between
the surface's normal and the light), tan_recv from the receiver's normal when
given, and tolerance the receiver data's own depth error (a range image's
quantisation), which the caller states. Acne (a lit surface shadowing itself)
needs an error above the bias; peter-panning (a contact shadow detached from
the contact) is at most the bias measured along the light.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from .camera import GroundGrid
from .parallel_loops import loop_helper, parallel_numba
from .scratch import Scratch, scratch_array

__all__ = ["LightFrame", "ShadowMap", "rasterise_depth", "shadow_map", "depth_bias", "faces_away",
           "BIAS_PX", "SLOPE_PX", "TAN_MAX", "PRECISION_ULPS", "FACING_TOL"]

BIAS_PX = 0.05        # constant part of the bias, in light-space pixels
SLOPE_PX = 0.75       # slope-scaled part: > 0.71, the farthest a point lies from its pixel centre
TAN_MAX = 1000.0      # slopes are clipped here (faces within 0.06 deg of the light)
PRECISION_ULPS = 16.0  # rounding allowance, in ulps of the coordinates' magnitude
FACING_TOL = 1e-9     # |n . L| below this: edge-on to the sun, counted as facing away


@dataclasses.dataclass(frozen=True)
class LightFrame:
    """An orthonormal frame of the sun's view: e1, e2 span the plane perpendicular to the
    light (3,) unit, origin (3,) world metres (the occluder's centre keeps depths small)."""

    light: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    origin: np.ndarray

    @classmethod
    def of_light(cls, light, origin=(0.0, 0.0, 0.0)) -> "LightFrame":
        light = np.asarray(light, np.float64)
        light = light / np.linalg.norm(light)
        # The world axis least aligned with the light keeps the cross product well conditioned
        # at any elevation, 90 deg included.
        axis = np.zeros(3)
        axis[int(np.argmin(np.abs(light)))] = 1.0
        e1 = _cross(axis, light)
        e1 /= np.linalg.norm(e1)
        e2 = _cross(light, e1)
        return cls(light, e1, e2, np.asarray(origin, np.float64))

    def project(self, points: np.ndarray, dtype=np.float64) -> tuple[np.ndarray, np.ndarray]:
        """Light-space (u, v) (N, 2) and depth (N,) of world points (N, 3), computed in ``dtype``."""
        p = np.ascontiguousarray(np.asarray(points).reshape(-1, 3), dtype)
        # One compiled pass, not (p - o) @ M: that product went through BLAS, whose threads
        # made it several times slower on a loaded machine, and as array operations the
        # temporaries of 200k points cost more than the arithmetic.
        uv = np.empty((len(p), 2), dtype)
        depth = np.empty(len(p), dtype)
        frame = np.stack([self.origin, self.e1, self.e2, self.light]).astype(dtype)
        _project_kernel()(p, frame, uv, depth)
        return uv, depth


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b of two 3-vectors (np.cross costs twenty times more on them: a frame makes two)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@functools.cache
def _project_kernel():
    """The compiled loop of ``LightFrame.project``: (p - o) . e1, (p - o) . e2, (p - o) . L per
    point, in the arrays' own float type (numba)."""
    import numba

    @numba.njit(cache=True, nogil=True)
    def kernel(p, frame, uv, depth):
        for i in range(p.shape[0]):
            x, y, z = p[i, 0] - frame[0, 0], p[i, 1] - frame[0, 1], p[i, 2] - frame[0, 2]
            uv[i, 0] = x * frame[1, 0] + y * frame[1, 1] + z * frame[1, 2]
            uv[i, 1] = x * frame[2, 0] + y * frame[2, 1] + z * frame[2, 2]
            depth[i] = x * frame[3, 0] + y * frame[3, 1] + z * frame[3, 2]

    return kernel


def faces_away(normals: np.ndarray, light: np.ndarray) -> np.ndarray:
    """Attached shadow (N,) bool: the surface at a point with this unit normal (N, 3) faces
    away from the sun (n . L >= 0, the sun at or below its horizon; within FACING_TOL, so a
    face exactly edge-on to the light counts whatever the rounding), so the sun does not
    light it."""
    n = np.ascontiguousarray(np.asarray(normals).reshape(-1, 3), np.float64)
    out = np.empty(len(n), bool)
    _facing_kernel()(n, np.asarray(light, np.float64), -FACING_TOL, out)
    return out


@functools.cache
def _facing_kernel():
    """The compiled loop of ``faces_away`` (numba): one pass over the normals, where NumPy's
    column products cost more than the rest of a plan's per-point work."""
    import numba

    @numba.njit(cache=True, nogil=True)
    def kernel(n, light, tol, out):
        for i in range(n.shape[0]):
            out[i] = n[i, 0] * light[0] + n[i, 1] * light[1] + n[i, 2] * light[2] >= tol

    return kernel


def rasterise_depth(xy: np.ndarray, depth: np.ndarray, faces: np.ndarray,
                    shape: tuple[int, int], *, facing: np.ndarray | None = None,
                    out: tuple[np.ndarray, np.ndarray] | None = None, threads: int = 1,
                    scratch: Scratch | None = None, name: str = "zbuffer") -> tuple[np.ndarray, np.ndarray]:
    """Nearest-face depth buffer of triangles, generic over the projection.

    xy (V, 2) pixel coordinates (col, row; pixel centres at integers); depth (V,) any
    quantity affine in xy over each triangle (smaller is nearer); faces (F, 3);
    shape (H, W). Returns depth (H, W) in depth's dtype (+inf where no face covers the
    pixel centre) and face_id (H, W) int32 (the index into ``faces`` of the nearest face,
    -1 where none). A pixel centre on a shared edge belongs to both faces (no cracks).

    facing (F,) int8, optional: back-face culling. A face with facing s != 0 is drawn only
    where its signed area in pixel coordinates, (p1 - p0) x (p2 - p0), has the sign of s
    (a closed mesh's faces turned away from the viewer are never the nearest: skipping them
    halves the work and changes no pixel); 0 draws the face either way. out: the (H, W) depth
    (float64, or float32 for float32 depths) and face_id (int32) arrays to fill and return;
    threads: 2 lets the faces be drawn on two threads (below); scratch, name: keep the
    second thread's buffers under this name.

    Scanline: each face's rows, each row's span of columns from the face's edges, then the
    depth from the face's plane at those pixel centres; O(covered pixels + face rows). With
    threads=2, two numba threads (``parallel_loops``) and many faces (``SPLIT_FACES``), the two
    halves of the faces are drawn on two threads into two buffers, then merged, the first half's
    face kept on a tie; with fewer faces on a large buffer (``SPLIT_ROWS_PX``), each thread draws
    every face on its half of the rows. Either way the buffer is the one thread's, bit for bit.
    """
    h, w = shape
    dtype = np.result_type(depth.dtype, np.float32)
    if out is None:
        zbuf, fid = np.empty(h * w, dtype), np.empty(h * w, np.int32)
    else:
        zbuf, fid = out[0].reshape(-1), out[1].reshape(-1)
        if zbuf.dtype != dtype or fid.dtype != np.int32 or zbuf.size != h * w or fid.size != h * w:
            raise ValueError(f"rasterise_depth out needs ({h}, {w}) arrays of {dtype} and int32")
    zbuf.fill(np.inf)
    fid.fill(-1)
    if len(faces):
        cull = (np.zeros(len(faces), np.int8) if facing is None
                else np.ascontiguousarray(facing, np.int8).reshape(len(faces)))
        args = (np.ascontiguousarray(xy, np.float64), np.ascontiguousarray(depth, np.float64),
                np.ascontiguousarray(faces, np.int64), cull, zbuf, fid)
        numba = parallel_numba()
        if threads > 1 and len(faces) >= SPLIT_FACES and numba.get_num_threads() > 1:
            _zbuffer_kernel()[1](*args, scratch_array(scratch, f"{name}.split_depth", h * w, dtype),
                                 scratch_array(scratch, f"{name}.split_face", h * w, np.int32), h, w,
                                 dtype == np.float32)
        elif threads > 1 and h * w >= SPLIT_ROWS_PX and numba.get_num_threads() > 1:
            _zbuffer_kernel()[2](*args, h, w, dtype == np.float32)
        else:
            _zbuffer_kernel()[0](*args, h, w, dtype == np.float32)
    return zbuf.reshape(h, w), fid.reshape(h, w)


#: Meshes from this many faces are drawn on two threads, half the faces each, merged after (fewer:
#: the merge costs more than it saves); fewer faces on a buffer of at least SPLIT_ROWS_PX pixels
#: are drawn on two threads by halves of the rows (each thread sets up every face).
SPLIT_FACES = 2048
SPLIT_ROWS_PX = 65536


@functools.cache
def _zbuffer_kernel():
    """The compiled loop of ``rasterise_depth`` (numba, compiled on first use and cached on
    disk): as array operations its many short spans cost several times the ground back end's
    whole render.

    A small face's bounding box's pixel centres are tested against its three edges (edge
    functions, stepped along each row); a large face's rows are spanned from where they cross
    its edges. A centre within 1e-9 pixel of an edge, or on it, is inside, so a centre on a
    shared edge belongs to both faces.

    Returns (the kernel, the two-thread kernels): ``draw`` of all the faces; of each half of the
    faces on its own thread into its own buffer (the second's extra (H W,) depth and face
    buffers given), merged after; or of all the faces on each half of the rows."""
    numba = parallel_numba()

    @loop_helper
    def draw(lo, hi, xy, depth, faces, facing, zbuf, fid, h, w, single, row_lo, row_hi):
        # Faces lo..hi, on rows row_lo..row_hi only (a pixel's value does not depend on the others).
        for i in range(lo, hi):
            a, b, c = faces[i, 0], faces[i, 1], faces[i, 2]
            x0, y0, z0 = xy[a, 0], xy[a, 1], depth[a]
            x1, y1, z1 = xy[b, 0], xy[b, 1], depth[b]
            x2, y2, z2 = xy[c, 0], xy[c, 1], depth[c]
            e1x, e1y = x1 - x0, y1 - y0
            e2x, e2y = x2 - x0, y2 - y0
            area = e1x * e2y - e1y * e2x
            # Culled first (about half a closed mesh's faces); one test for the nine coordinates
            # (a sum is finite only if they all are, but may overflow: then each is tested).
            if area * facing[i] < 0:
                continue
            if not np.isfinite(x0 + y0 + z0 + x1 + y1 + z1 + x2 + y2 + z2) and not (
                    np.isfinite(x0) and np.isfinite(y0) and np.isfinite(z0) and np.isfinite(x1)
                    and np.isfinite(y1) and np.isfinite(z1) and np.isfinite(x2) and np.isfinite(y2)
                    and np.isfinite(z2)):
                continue
            if abs(area) <= 1e-12:
                continue
            xmin, xmax = min(x0, x1, x2), max(x0, x1, x2)
            ymin, ymax = min(y0, y1, y2), max(y0, y1, y2)
            if xmax < -0.5 or xmin > w - 0.5 or ymax < -0.5 or ymin > h - 0.5:
                continue
            c0 = int(min(max(np.ceil(xmin - 1e-9), 0.0), w))  # clipped as floats: no overflow
            c1 = int(min(max(np.floor(xmax + 1e-9), -1.0), w - 1))
            r0 = int(min(max(np.ceil(ymin - 1e-9), 0.0), h))
            r1 = int(min(max(np.floor(ymax + 1e-9), -1.0), h - 1))
            if c0 > c1 or r0 > r1:  # no pixel centre in its box (a face smaller than a pixel)
                continue
            # The way a face is drawn is chosen on its whole box: each half of the rows draws it
            # as one thread would.
            large = (c1 - c0 + 1) * (r1 - r0 + 1) > 64
            r0, r1 = max(r0, row_lo), min(r1, row_hi)
            if r0 > r1:
                continue
            # Depth plane in pixel coordinates: z = z0 + gx (x - x0) + gy (y - y0).
            dz1, dz2 = z1 - z0, z2 - z0
            gx = (dz1 * e2y - dz2 * e1y) / area
            gy = (dz2 * e1x - dz1 * e2x) / area
            # Edge functions, positive inside whatever the winding: E(x, y) = A x + B y + C for
            # the edges (0, 1), (1, 2), (2, 0); tolerances of 1e-9 pixel times each edge's length.
            sgn = 1.0 if area > 0 else -1.0
            ax, bx, cx = -(y1 - y0) * sgn, (x1 - x0) * sgn, 0.0
            ay, by = -(y2 - y1) * sgn, (x2 - x1) * sgn
            az, bz = -(y0 - y2) * sgn, (x0 - x2) * sgn
            cx = -(ax * x0 + bx * y0)
            cy = -(ay * x1 + by * y1)
            cz = -(az * x2 + bz * y2)
            tx = -1e-9 * (abs(ax) + abs(bx))
            ty = -1e-9 * (abs(ay) + abs(by))
            tz = -1e-9 * (abs(az) + abs(bz))
            if large:
                # A large face: each row's span from where the row crosses its edges (no pixel
                # of the box outside the face is visited).
                for row in range(r0, r1 + 1):
                    lo, hi = np.inf, -np.inf
                    for e in range(3):
                        if e == 0:
                            xa, ya, xb, yb = x0, y0, x1, y1
                        elif e == 1:
                            xa, ya, xb, yb = x1, y1, x2, y2
                        else:
                            xa, ya, xb, yb = x2, y2, x0, y0
                        if row < min(ya, yb) - 1e-9 or row > max(ya, yb) + 1e-9:
                            continue
                        dy = yb - ya
                        if abs(dy) <= 1e-12:
                            lo, hi = min(lo, min(xa, xb)), max(hi, max(xa, xb))
                        else:
                            xc = xa + min(max((row - ya) / dy, 0.0), 1.0) * (xb - xa)
                            lo, hi = min(lo, xc), max(hi, xc)
                    s0 = int(min(max(np.ceil(lo - 1e-9), 0.0), w))
                    s1 = int(min(max(np.floor(hi + 1e-9), -1.0), w - 1))
                    base = row * w
                    z_row = z0 + gy * (row - y0)
                    for col in range(s0, s1 + 1):
                        z = z_row + gx * (col - x0)
                        if single:
                            z = np.float64(np.float32(z))
                        if z < zbuf[base + col]:
                            zbuf[base + col] = z
                            fid[base + col] = i
                continue
            for row in range(r0, r1 + 1):
                fx = ax * c0 + bx * row + cx
                fy = ay * c0 + by * row + cy
                fz = az * c0 + bz * row + cz
                base = row * w
                z_row = z0 + gy * (row - y0)
                for col in range(c0, c1 + 1):
                    if fx >= tx and fy >= ty and fz >= tz:
                        z = z_row + gx * (col - x0)
                        if single:  # round as the buffer's float type would
                            z = np.float64(np.float32(z))
                        if z < zbuf[base + col]:
                            zbuf[base + col] = z
                            fid[base + col] = i
                    fx += ax
                    fy += ay
                    fz += az

    @numba.njit(cache=True, nogil=True)
    def kernel(xy, depth, faces, facing, zbuf, fid, h, w, single):
        draw(0, faces.shape[0], xy, depth, faces, facing, zbuf, fid, h, w, single, 0, h - 1)

    # Few faces on two threads: each draws every face on its own half of the rows (disjoint
    # pixels, each pixel's faces in the same order: the one thread's buffer, bit for bit).
    @numba.njit(cache=True, nogil=True, parallel=True)
    def rows_kernel(xy, depth, faces, facing, zbuf, fid, h, w, single):
        for part in numba.prange(2):
            lo, hi = (0, h // 2 - 1) if part == 0 else (h // 2, h - 1)
            draw(0, faces.shape[0], xy, depth, faces, facing, zbuf, fid, h, w, single, lo, hi)

    @numba.njit(cache=True, nogil=True, parallel=True)
    def split_kernel(xy, depth, faces, facing, zbuf, fid, zbuf2, fid2, h, w, single):
        half = faces.shape[0] // 2
        for part in numba.prange(2):
            if part == 0:
                draw(0, half, xy, depth, faces, facing, zbuf, fid, h, w, single, 0, h - 1)
            else:
                zbuf2.fill(np.inf)
                fid2.fill(-1)
                draw(half, faces.shape[0], xy, depth, faces, facing, zbuf2, fid2, h, w, single, 0, h - 1)
        # Strictly nearer only: on a tie the first half's (lower) face stays, as one thread keeps it.
        for p in numba.prange(zbuf.shape[0]):
            if zbuf2[p] < zbuf[p]:
                zbuf[p] = zbuf2[p]
                fid[p] = fid2[p]

    return kernel, split_kernel, rows_kernel


@dataclasses.dataclass(frozen=True)
class ShadowMap:
    """The occluder's depth from the sun on a light-space grid.

    grid: a ``GroundGrid`` whose (x, y) are light-space (u, v); depth (H, W) nearest depth
    at pixel centres (+inf: no face); face_id (H, W) index into ``plane`` (-1: none);
    plane (F, 3) each face's depth plane (A, B, d0), d = d0 + A (u - u0) + B (v - v0) about
    its first corner (u0, v0) = triangle[:, 0]; slope (F,) its |grad d|
    (tan of the angle between the face's normal and the light); triangle (F, 3, 2) its
    light-space corners; scale: the magnitude of the coordinates, for the rounding allowance.
    """

    grid: GroundGrid
    depth: np.ndarray
    face_id: np.ndarray
    plane: np.ndarray
    slope: np.ndarray
    triangle: np.ndarray
    scale: float

    def occluder_depth(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The occluder's depth (N,) at light-space points (N, 2) (+inf where no face is near),
        the slope (N,) of the face used, and whether its triangle contains the point (N,) (the
        depth is then exact; else extrapolated, and the bias grows with the slopes).

        The face nearest the sun at the point's pixel, or else at the first of its 8
        neighbours, whose triangle contains the point: its plane, exact. Where none does (a face
        smaller than a pixel, missed by every pixel centre), the nearest covered pixel's
        face within 2 pixels, its plane extrapolated, with its slope for the bias.
        """
        dtype = self.plane.dtype
        uv = np.ascontiguousarray(uv, dtype)
        best = np.empty(len(uv), dtype)
        slope = np.empty(len(uv), dtype)
        exact = np.empty(len(uv), bool)
        tol = -1e-7  # barycentric tolerance: a point on a shared edge is in both faces
        g = self.grid
        # Constants in the map's own float type, so a float32 map is tested in float32 throughout.
        _depth_kernel()(uv, float(g.origin_m[0]), float(g.origin_m[1]), float(g.pixel_m), self.face_id,
                        np.ascontiguousarray(self.triangle), np.ascontiguousarray(self.plane),
                        np.ascontiguousarray(self.slope, dtype), np.array([tol, 1.0 - tol, 1.0], dtype),
                        best, slope, exact)
        return best, slope, exact


_LOOKUP_OFFSETS = np.array([(0, 0), (-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1)])


# The point's own pixel first, then its 4 and its 4 diagonal neighbours (the exact lookup); the
# pixels within 2 of it nearest first (the extrapolated one; a stable sort keeps row-major order
# among equal distances).
_NEAREST_OFFSETS = np.array(sorted(((dr, dc) for dr in range(-2, 3) for dc in range(-2, 3)),
                                   key=lambda o: o[0] ** 2 + o[1] ** 2))


@functools.cache
def face_depth_at():
    """The compiled lookup of one point's occluder depth (numba), shared by ``ShadowMap``'s
    lookup and the dense plan's depth test: ``(u, v, row, col, face_id, triangle, plane,
    face_slope, tol, upper, one) -> (depth, slope, exact)``. (row, col): the point's map pixel
    (the nearest centre). The first face among that pixel's and its 8 neighbours' whose triangle
    contains the point (barycentric coordinates >= tol, summing to <= upper): its plane at the
    point, exact, slope 0. Else the face of the nearest covered pixel within 2: its plane
    extrapolated, with its slope. Else +inf. Arithmetic in the map's float type (``one``: 1 in it)."""

    @loop_helper
    def depth_at(u, v, row, col, face_id, triangle, plane, face_slope, tol, upper, one):
        h, w = face_id.shape
        for k in range(_LOOKUP_OFFSETS.shape[0]):
            r, c = row + _LOOKUP_OFFSETS[k, 0], col + _LOOKUP_OFFSETS[k, 1]
            if r < 0 or r >= h or c < 0 or c >= w:
                continue
            f = face_id[r, c]
            if f < 0:
                continue
            t0u, t0v = triangle[f, 0, 0], triangle[f, 0, 1]
            ex1, ey1 = triangle[f, 1, 0] - t0u, triangle[f, 1, 1] - t0v
            ex2, ey2 = triangle[f, 2, 0] - t0u, triangle[f, 2, 1] - t0v
            px, py = u - t0u, v - t0v
            area = ex1 * ey2 - ey1 * ex2
            if area == 0:
                area = one
            b1 = (px * ey2 - py * ex2) / area
            b2 = (ex1 * py - ey1 * px) / area
            if b1 >= tol and b2 >= tol and b1 + b2 <= upper:
                return np.float64(plane[f, 2] + plane[f, 0] * (u - t0u) + plane[f, 1] * (v - t0v)), 0.0, True
        for k in range(_NEAREST_OFFSETS.shape[0]):
            r, c = row + _NEAREST_OFFSETS[k, 0], col + _NEAREST_OFFSETS[k, 1]
            if r < 0 or r >= h or c < 0 or c >= w:
                continue
            f = face_id[r, c]
            if f >= 0:
                depth = plane[f, 2] + plane[f, 0] * (u - triangle[f, 0, 0]) + plane[f, 1] * (v - triangle[f, 0, 1])
                return np.float64(depth), np.float64(face_slope[f]), False
        return np.inf, 0.0, False

    return depth_at


@functools.cache
def _depth_kernel():
    """The compiled lookup of ``ShadowMap.occluder_depth`` (numba): ``face_depth_at`` at each point."""
    import numba
    depth_at = face_depth_at()

    @numba.njit(cache=True, nogil=True)
    def kernel(uv, ox, oy, pixel_m, face_id, triangle, plane, face_slope, const, best, slope, exact):
        tol, upper, one = const[0], const[1], const[2]
        for i in range(uv.shape[0]):
            u, v = uv[i, 0], uv[i, 1]
            col = int(np.rint((np.float64(u) - ox) / pixel_m))
            row = int(np.rint((oy - np.float64(v)) / pixel_m))
            best[i], slope[i], exact[i] = depth_at(u, v, row, col, face_id, triangle, plane, face_slope, tol, upper,
                                                   one)

    return kernel


def depth_bias(pixel_m: float, slope_face, slope_receiver=0.0, scale: float = 1.0,
               dtype=np.float64, exact=None, tolerance_m: float = 0.0) -> np.ndarray:
    """The depth test's bias (metres along the light), per point; see the module docstring.

    exact (N,) bool: where the occluder's depth came from the face containing the point
    (no slope term); None: everywhere extrapolated.
    """
    tan = np.minimum(slope_face, TAN_MAX) + np.minimum(slope_receiver, TAN_MAX)
    slope_term = SLOPE_PX * pixel_m * tan
    if exact is not None:
        slope_term = np.where(exact, 0.0, slope_term)
    return (BIAS_PX * pixel_m + PRECISION_ULPS * float(np.finfo(dtype).eps) * scale + tolerance_m
            + slope_term)


def _face_planes(uvd: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Depth planes (F, 3) and slopes (F,) of faces with light-space vertices uvd (V, 3).

    A plane is (A, B, d0): d = d0 + A (u - u0) + B (v - v0) about the face's first corner
    (u0, v0, d0). Relative to the corner, not as A u + B v + C: a face nearly edge-on to the
    light has large A, B, and C = d0 - A u0 - B v0 cancels catastrophically in float32.
    One compiled pass in uvd's float type (numba).
    """
    uvd = np.ascontiguousarray(uvd)
    plane = np.empty((len(faces), 3), uvd.dtype)
    slope = np.empty(len(faces), uvd.dtype)
    # 1e-300 in the float type (0 in float32, as NumPy rounds it): a face edge-on to the light
    # then gets an infinite slope there, as before.
    _planes_kernel()(uvd, np.ascontiguousarray(faces, np.int64), np.array([1e-300], uvd.dtype), plane, slope)
    return plane, slope


@functools.cache
def _planes_kernel():
    import numba

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def kernel(uvd, faces, tiny, plane, slope):
        for f in range(faces.shape[0]):
            i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
            ux, uy, uz = uvd[i1, 0] - uvd[i0, 0], uvd[i1, 1] - uvd[i0, 1], uvd[i1, 2] - uvd[i0, 2]
            vx, vy, vz = uvd[i2, 0] - uvd[i0, 0], uvd[i2, 1] - uvd[i0, 1], uvd[i2, 2] - uvd[i0, 2]
            nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
            nd = nz if abs(nz) > tiny[0] else tiny[0]
            a, b = -nx / nd, -ny / nd
            plane[f, 0], plane[f, 1], plane[f, 2] = a, b, uvd[i0, 2]
            slope[f] = np.hypot(a, b)

    return kernel


def shadow_map(grid: GroundGrid, uv: np.ndarray, depth: np.ndarray, faces: np.ndarray,
               dtype=np.float64, *, facing: np.ndarray | None = None,
               out: tuple[np.ndarray, np.ndarray] | None = None, threads: int = 1, scratch: Scratch | None = None,
               name: str = "shadow_map") -> ShadowMap:
    """The shadow map of faces (F, 3) with light-space vertices uv (V, 2) and depths (V,) on grid.

    dtype: the float type of the depth buffer and the planes (float32 to measure precision);
    facing: back-face culling per face, out: the depth and face-id arrays to fill, threads
    (``rasterise_depth``); scratch, name: keep the per-face arrays (triangles, planes, slopes)
    in these buffers under this name (``softshadow.scratch``: the map is then overwritten by the
    next one made with them).
    """
    uv = np.ascontiguousarray(uv, dtype)
    depth = np.ascontiguousarray(depth, dtype)
    faces = np.ascontiguousarray(faces, np.int64)
    zbuf, fid = rasterise_depth(grid.to_pixel(uv).astype(dtype), depth, faces,
                                (grid.height, grid.width), facing=facing, out=out, threads=threads,
                                scratch=scratch, name=name)
    # Each face's light-space triangle, depth plane and slope (``_face_planes``) and the
    # coordinates' magnitude, in one compiled pass.
    f = len(faces)
    triangle = scratch_array(scratch, f"{name}.triangle", (f, 3, 2), dtype)
    plane = scratch_array(scratch, f"{name}.plane", (f, 3), dtype)
    slope = scratch_array(scratch, f"{name}.slope", f, dtype)
    scale = _map_faces_kernel()(uv, depth, faces, np.array([1e-300], dtype), triangle, plane, slope)
    return ShadowMap(grid, zbuf, fid, plane, slope, triangle, float(scale))


@functools.cache
def _map_faces_kernel():
    """``shadow_map``'s per-face pass (numba): uv[faces] into triangle, ``_face_planes``' planes
    and slopes (its arithmetic, in uv's float type); returns the largest |u|, |v|, |depth| of
    the vertices, at least 1."""
    import numba

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def kernel(uv, depth, faces, tiny, triangle, plane, slope):
        scale = 1.0  # in float64: float32 values convert exactly
        for i in range(uv.shape[0]):
            scale = max(scale, abs(np.float64(uv[i, 0])), abs(np.float64(uv[i, 1])), abs(np.float64(depth[i])))
        for f in range(faces.shape[0]):
            i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
            triangle[f, 0, 0], triangle[f, 0, 1] = uv[i0, 0], uv[i0, 1]
            triangle[f, 1, 0], triangle[f, 1, 1] = uv[i1, 0], uv[i1, 1]
            triangle[f, 2, 0], triangle[f, 2, 1] = uv[i2, 0], uv[i2, 1]
            ux, uy, uz = uv[i1, 0] - uv[i0, 0], uv[i1, 1] - uv[i0, 1], depth[i1] - depth[i0]
            vx, vy, vz = uv[i2, 0] - uv[i0, 0], uv[i2, 1] - uv[i0, 1], depth[i2] - depth[i0]
            nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
            nd = nz if abs(nz) > tiny[0] else tiny[0]
            a, b = -nx / nd, -ny / nd
            plane[f, 0], plane[f, 1], plane[f, 2] = a, b, depth[i0]
            slope[f] = np.hypot(a, b)
        return scale

    return kernel
