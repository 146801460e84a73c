"""Camera rays and what they hit: the receiver (plane, height field or mesh) or the object.

Pinhole cameras follow softshadow.camera (OpenCV convention); a top-down map
(``GroundGrid``) is an orthographic camera looking straight down, north up.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import trimesh

from softshadow import GroundGrid, PinholeCamera

__all__ = ["ViewRays", "SurfaceHits", "pinhole_rays", "topdown_rays", "trace", "pixel_axes",
           "KIND_NONE", "KIND_RECEIVER", "KIND_OBJECT"]

KIND_NONE, KIND_RECEIVER, KIND_OBJECT = 0, 1, 2
TOPDOWN_HEIGHT_M = 1000.0


@dataclasses.dataclass(frozen=True)
class ViewRays:
    """Rays of an image's pixel centres: origins (N, 3), unit directions (N, 3), N = height * width."""

    origins: np.ndarray
    directions: np.ndarray
    width: int
    height: int
    camera: PinholeCamera | None = None  # lets ``trace`` cull by projecting the object's box


def pinhole_rays(camera: PinholeCamera) -> ViewRays:
    rows, cols = np.mgrid[0:camera.height, 0:camera.width]
    d = camera.pixel_rays(cols, rows)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(camera.centre, d.shape)
    return ViewRays(o, d, camera.width, camera.height, camera)


def topdown_rays(grid: GroundGrid) -> ViewRays:
    pts = grid.pixel_centres().reshape(-1, 3)
    o = pts + np.array([0.0, 0.0, TOPDOWN_HEIGHT_M])
    d = np.broadcast_to(np.array([0.0, 0.0, -1.0]), o.shape)
    return ViewRays(o, d, grid.width, grid.height)


@dataclasses.dataclass(frozen=True)
class SurfaceHits:
    """Per pixel (N = H*W): kind (KIND_*), hit point (N, 3), unit normal (N, 3) facing the
    camera, and where the ray meets the receiver ignoring the object (receiver_point,
    receiver_valid) for range images."""

    kind: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    receiver_point: np.ndarray
    receiver_valid: np.ndarray


def _slab_candidates(rays: ViewRays, bounds: np.ndarray, pad: float = 1e-3) -> np.ndarray:
    """Rays that meet the axis-aligned box ``bounds`` (2, 3) in front of their origin."""
    lo, hi = bounds[0] - pad, bounds[1] + pad
    d = rays.directions
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / np.where(np.abs(d) < 1e-15, 1e-15, d)
        t0 = (lo - rays.origins) * inv
        t1 = (hi - rays.origins) * inv
    tmin = np.max(np.minimum(t0, t1), axis=1)
    tmax = np.min(np.maximum(t0, t1), axis=1)
    return (tmax >= np.maximum(tmin, 0.0))


def _object_candidates(rays: ViewRays, bounds: np.ndarray) -> np.ndarray:
    """Indices of rays that may hit the object: pixels inside the projected bounding box
    (pinhole camera with the box in front), else a ray/box slab test."""
    cam = rays.camera
    if cam is not None:
        corners = np.array([[bounds[i, 0], bounds[j, 1], bounds[k, 2]]
                            for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        uv, front = cam.project(corners)
        if front.all():
            c0, r0 = np.floor(uv.min(0)).astype(int) - 2
            c1, r1 = np.ceil(uv.max(0)).astype(int) + 2
            c0, r0 = max(c0, 0), max(r0, 0)
            c1, r1 = min(c1, rays.width - 1), min(r1, rays.height - 1)
            if c0 > c1 or r0 > r1:
                return np.zeros(0, np.int64)
            rr, cc = np.mgrid[r0:r1 + 1, c0:c1 + 1]
            return (rr * rays.width + cc).ravel()
    return np.flatnonzero(_slab_candidates(rays, bounds))


def _first_hits(mesh: trimesh.Trimesh, origins, directions):
    """(index_ray, locations, index_tri) of the nearest hit per ray, rays without hits omitted."""
    loc, iray, itri = mesh.ray.intersects_location(origins, directions, multiple_hits=False)
    return iray, loc, itri


def _object_normals(mesh: trimesh.Trimesh, points: np.ndarray, tri: np.ndarray, smooth: bool) -> np.ndarray:
    if not smooth:
        return np.asarray(mesh.face_normals[tri])
    corners = mesh.triangles[tri]
    bary = trimesh.triangles.points_to_barycentric(corners, points)
    vn = mesh.vertex_normals[mesh.faces[tri]]
    n = np.einsum("nk,nkj->nj", bary, vn)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def is_smooth(mesh: trimesh.Trimesh, max_crease_deg: float = 35.0) -> bool:
    """Whether a mesh approximates a smooth surface (shade with interpolated normals)."""
    angles = mesh.face_adjacency_angles
    return bool(len(angles) and np.percentile(angles, 99.5) < np.radians(max_crease_deg))


def trace(rays: ViewRays, object_mesh: trimesh.Trimesh | None, receiver) -> SurfaceHits:
    """First surface along each ray: the object, the receiver or nothing (the sky)."""
    n = len(rays.origins)
    o, d = rays.origins, rays.directions
    kind = np.zeros(n, np.uint8)
    points = np.zeros((n, 3))
    normals = np.zeros((n, 3))
    t_recv = np.full(n, np.inf)
    tri = np.zeros(n, np.int64)
    if receiver.mesh is None:  # the plane z = 0, analytically
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -o[:, 2] / d[:, 2]
        ok = np.isfinite(t) & (t > 0)
        t_recv[ok] = t[ok]
    else:
        iray, loc, itri = _first_hits(receiver.mesh, o, d)
        t_recv[iray] = np.einsum("nj,nj->n", loc - o[iray], d[iray])
        tri[iray] = itri
    recv_valid = np.isfinite(t_recv)
    recv_pts = o + np.where(recv_valid, t_recv, 0.0)[:, None] * d
    kind[recv_valid] = KIND_RECEIVER
    points[recv_valid] = recv_pts[recv_valid]
    if recv_valid.any():
        normals[recv_valid] = receiver.surface_normals(recv_pts[recv_valid], tri[recv_valid])
    if object_mesh is not None:
        cand = _object_candidates(rays, object_mesh.bounds)
        if len(cand):
            iray, loc, itri = _first_hits(object_mesh, o[cand], d[cand])
            idx = cand[iray]
            t_obj = np.einsum("nj,nj->n", loc - o[idx], d[idx])
            closer = t_obj < t_recv[idx]
            idx, loc, itri = idx[closer], loc[closer], itri[closer]
            kind[idx] = KIND_OBJECT
            points[idx] = loc
            nrm = _object_normals(object_mesh, loc, itri, is_smooth(object_mesh))
            # Face the camera (open meshes can be seen from behind).
            flip = np.einsum("nj,nj->n", nrm, d[idx]) > 0
            nrm[flip] *= -1
            normals[idx] = nrm
    return SurfaceHits(kind, points, normals, recv_pts, recv_valid)


def pixel_axes(hits: SurfaceHits, width: int, height: int, index: np.ndarray) -> np.ndarray:
    """Receiver extent of the pixels ``index`` (M,) along u and v, shape (M, 2, 3).

    From the hits of neighbouring pixels: central differences where both
    neighbours hit the receiver, one-sided where one does (or where the other
    side jumps more than 3x: a depth discontinuity), zero where neither.
    """
    index = np.asarray(index, dtype=np.int64)
    row, col = np.divmod(index, width)
    recv = hits.kind == KIND_RECEIVER
    p = hits.points
    out = np.zeros((len(index), 2, 3))
    for k, (step, pos, size) in enumerate(((1, col, width), (width, row, height))):
        has_f = pos + 1 < size
        has_b = pos - 1 >= 0
        fi = np.where(has_f, index + step, index)
        bi = np.where(has_b, index - step, index)
        fok = has_f & recv[fi]
        bok = has_b & recv[bi]
        fwd = p[fi] - p[index]
        bwd = p[index] - p[bi]
        nf = np.linalg.norm(fwd, axis=1)
        nb = np.linalg.norm(bwd, axis=1)
        fok2 = fok & ~(bok & (nf > 3 * nb))
        bok2 = bok & ~(fok & (nb > 3 * nf))
        cnt = fok2.astype(float) + bok2.astype(float)
        out[:, k] = (fwd * fok2[:, None] + bwd * bok2[:, None]) / np.maximum(cnt, 1)[:, None]
    out[~recv[index]] = 0.0
    return out
