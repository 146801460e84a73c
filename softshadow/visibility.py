"""What each pixel of a camera sees: a z-buffer of the scene's meshes and the ground (NumPy).

The scene is a list of ``Surface`` (triangle meshes in world metres, each with a linear
RGB albedo) and, optionally, the ground plane z = 0. ``visible_surfaces`` draws the
meshes with ``shadowmap.rasterise_depth`` (the same scanline z-buffer as the shadow
maps) in the camera's pixels, with depth -1/z_cam for a pinhole camera (affine in the
pixel over a planar triangle) or -z_world for a top-down map (orthographic, seen from
above), and keeps per pixel the nearest of that face and the ground. Each visible pixel's
point is where its ray meets the winning face's plane (exact, not interpolated) and its
normal is the face's own (flat shading: a coarse mesh shows its facets, which is what a
level-of-detail comparison must see; ``smooth=True`` interpolates vertex normals instead),
turned towards the camera so an open mesh is lit on the side the camera sees.

A camera with lens distortion is drawn in undistorted pixel coordinates of its K, and
each pixel takes the face at its undistorted position (nearest). Faces are cut at
``NEAR_M`` in front of the camera's plane (``clip.clip_near``).
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import trimesh

from .camera import GroundGrid, PinholeCamera
from .clip import clip_near
from .parallel_loops import parallel_numba
from .posed import pose_matrix
from .scratch import Scratch, scratch_array
from .shadowmap import rasterise_depth

__all__ = ["GROUND", "NOTHING", "Surface", "VisibleSurfaces", "visible_surfaces"]

NEAR_M = 1e-3
GROUND = -1   # ``VisibleSurfaces.surface`` of a ground pixel
NOTHING = -2  # a pixel that sees neither a mesh nor the ground (the sky)


def _albedo(value) -> np.ndarray:
    a = np.asarray(value, np.float64).reshape(-1)
    if a.shape == (1,):
        a = np.repeat(a, 3)
    if a.shape != (3,) or not np.all(np.isfinite(a)) or a.min() < 0:
        raise ValueError(f"albedo must be one or three finite numbers >= 0, got {value!r}")
    return a


@dataclasses.dataclass(frozen=True, eq=False)
class Surface:
    """A triangle mesh in the world: vertices (V, 3) metres, faces (F, 3), albedo (3,) linear RGB
    (a single number is grey); casts_shadows: drawn in projectors' shadow maps; closed: the
    mesh is closed with its faces wound counter-clockwise seen from outside (outward normals),
    so faces turned away from a viewer outside it are never seen and are not drawn; normals:
    the unit face normals (F, 3) when already known (a posed occluder's), else from the winding."""

    vertices: np.ndarray
    faces: np.ndarray
    albedo: np.ndarray = (0.8, 0.8, 0.8)
    name: str = "mesh"
    casts_shadows: bool = True
    closed: bool = False
    normals: np.ndarray | None = None

    def __post_init__(self):
        v = np.asarray(self.vertices, np.float64)
        f = np.asarray(self.faces, np.int64)
        if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
            raise ValueError(f"surface {self.name!r} needs vertices (V, 3) and faces (F, 3)")
        if len(f) and (f.min() < 0 or f.max() >= len(v)):
            raise ValueError(f"surface {self.name!r} has face indices outside its vertices")
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)
        object.__setattr__(self, "albedo", _albedo(self.albedo))
        if self.normals is not None:
            n = np.asarray(self.normals, np.float64)
            if n.shape != f.shape:
                raise ValueError(f"surface {self.name!r} needs one normal per face, got shape {n.shape}")
            object.__setattr__(self, "normals", n)

    @classmethod
    def from_trimesh(cls, mesh: trimesh.Trimesh, position=(0.0, 0.0, 0.0), rotation_deg=(0.0, 0.0, 0.0),
                     scale: float = 1.0, albedo=(0.8, 0.8, 0.8), name: str = "mesh",
                     casts_shadows: bool = True) -> "Surface":
        """A mesh placed as scene.toml places one: x_world = R(rotation_deg) (scale x) + position."""
        v = float(scale) * np.asarray(mesh.vertices, np.float64) @ pose_matrix(rotation_deg).T
        return cls(v + np.asarray(position, np.float64), np.asarray(mesh.faces), albedo, name, casts_shadows)

    @property
    def vertex_normals(self) -> np.ndarray:
        """Unit normals (V, 3) at the vertices: the area-weighted mean of their faces' normals."""
        t = self.vertices[self.faces]
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])  # length: twice the area
        acc = np.zeros_like(self.vertices)
        for corner in range(3):
            np.add.at(acc, self.faces[:, corner], n)
        return acc / np.maximum(np.linalg.norm(acc, axis=1, keepdims=True), 1e-300)

    @property
    def face_normals(self) -> np.ndarray:
        """Unit normals (F, 3): ``normals`` if given, else from the winding (zero for degenerate faces)."""
        if self.normals is not None:
            return self.normals
        t = self.vertices[self.faces]
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


@dataclasses.dataclass(frozen=True)
class VisibleSurfaces:
    """The surface each pixel sees.

    shape (H, W); pixel (N,) flat indices of the pixels that see something; points (N, 3)
    world metres; normals (N, 3) unit, on the camera's side of their face; albedo (N, 3) (None
    when not asked for); surface (H, W)
    int: index into the surfaces, ``GROUND`` or ``NOTHING``; face (H, W) int: the face
    within its surface (-1 for the ground and nothing).
    """

    shape: tuple[int, int]
    pixel: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    albedo: np.ndarray | None
    surface: np.ndarray
    face: np.ndarray


def visible_surfaces(camera: PinholeCamera | GroundGrid, surfaces=(), ground_albedo=None,
                     smooth: bool = False, *, scratch: Scratch | None = None, albedo: bool = True,
                     threads: int = 1) -> VisibleSurfaces:
    """The nearest surface at every pixel of ``camera`` (see the module docstring).

    surfaces: a sequence of ``Surface``; ground_albedo: the ground plane z = 0's albedo (one or
    three numbers), None for no ground; smooth: normals interpolated from the vertex normals
    (Gouraud/Phong-like, barycentric at the point) instead of the faces' own (flat, the default);
    scratch: keep the per-pixel arrays in these buffers (``softshadow.scratch``; the result is
    then overwritten by the next call with the same scratch); albedo: False leaves the points'
    albedos out (``albedo`` None: a caller that has the surfaces' albedos by ``surface``); threads: 2
    lets the z-buffer draw a large mesh on two threads (``rasterise_depth``).
    """
    h, w = camera.height, camera.width
    surfaces = list(surfaces)
    offsets = np.cumsum([0] + [len(s.faces) for s in surfaces])
    if len(surfaces) == 1:
        verts, faces = surfaces[0].vertices, surfaces[0].faces
    else:
        verts = np.vstack([s.vertices for s in surfaces]) if surfaces else np.zeros((0, 3))
        vstart = np.cumsum([0] + [len(s.vertices) for s in surfaces])
        faces = (np.vstack([s.faces + vstart[i] for i, s in enumerate(surfaces)]) if surfaces
                 else np.zeros((0, 3), np.int64))
    # Closed, outward-wound surfaces: their faces turned away from the camera are never the
    # nearest, so the z-buffer skips them (in pixel coordinates, rows down, a face seen from
    # its front winds with a negative signed area).
    facing = np.concatenate([np.full(len(s.faces), -1 if s.closed else 0, np.int8) for s in surfaces]) \
        if surfaces else np.zeros(0, np.int8)
    top = float(max(verts[:, 2].max(initial=0.0), 0.0)) + 1.0
    directions = np.zeros((0, 3))
    lookup = np.zeros(0, np.int64)  # the identity
    if isinstance(camera, GroundGrid):
        xy, depth = camera.to_pixel(verts), -verts[:, 2]
        drawn, source = faces, np.zeros(0, np.int64)
    else:
        z_cam = verts @ camera.R[2] + camera.t[2]
        if len(verts) and z_cam.min() > NEAR_M:  # nothing to cut
            cut, drawn, source = verts, faces, np.zeros(0, np.int64)
        else:
            # Faces cut at the near plane (a floor passing under and behind the camera stays whole
            # in view); a closed surface cut open shows its inside, so nothing is culled then.
            cut, drawn, source = clip_near(verts, z_cam, faces, NEAR_M)
            facing = np.zeros(len(drawn), np.int8)
        pc = cut @ camera.R.T + camera.t
        zs = np.maximum(pc[:, 2], NEAR_M)  # the originals behind the plane are no longer used
        K = camera.K
        a, b = pc[:, 0] / zs, pc[:, 1] / zs
        xy = np.column_stack([K[0, 0] * a + K[0, 1] * b + K[0, 2], K[1, 1] * b + K[1, 2]])
        depth = -1.0 / zs
        if camera.dist is not None and np.any(camera.dist):
            import cv2
            rows, cols = np.mgrid[0:h, 0:w]
            uv = np.stack([cols.ravel(), rows.ravel()], -1).astype(np.float64)[:, None, :]
            und = cv2.undistortPoints(uv, K, camera.dist, P=K).reshape(-1, 2)
            c, r = np.rint(und[:, 0]).astype(np.int64), np.rint(und[:, 1]).astype(np.int64)
            inside = (c >= 0) & (c < w) & (r >= 0) & (r < h)
            lookup = np.where(inside, np.clip(r, 0, h - 1) * w + np.clip(c, 0, w - 1), -1)
            directions = camera.pixel_rays(cols, rows)
    zbuf = scratch_array(scratch, "visible.zbuf", (h, w), np.float64)
    f_img = scratch_array(scratch, "visible.face_id", (h, w), np.int32)
    rasterise_depth(xy, depth, drawn, (h, w), facing=facing, out=(zbuf, f_img), threads=threads, scratch=scratch,
                    name="visible")
    all_normals = surfaces[0].face_normals if len(surfaces) == 1 else (
        np.vstack([s.face_normals for s in surfaces]) if surfaces else np.zeros((0, 3)))
    face_surface = np.repeat(np.arange(len(surfaces)), np.diff(offsets)) if surfaces else np.zeros(0, np.int64)
    albedos = np.array([s.albedo for s in surfaces], np.float64).reshape(-1, 3)
    ground = _albedo(ground_albedo) if ground_albedo is not None else np.zeros(3)
    if isinstance(camera, GroundGrid):
        view = np.array([0.0, camera.origin_m[0], camera.origin_m[1], camera.pixel_m, top])
        rays = np.zeros((6, 3))
    else:
        view = np.array([1.0, *camera.centre])
        Kinv = np.linalg.inv(camera.K)
        rays = np.vstack([Kinv[0], Kinv[1], np.zeros(3), camera.R])  # rows 0-1: K^-1's, rows 3-5: R
    surface = scratch_array(scratch, "visible.surface", (h, w), np.int64)
    face = scratch_array(scratch, "visible.face", (h, w), np.int64)
    pixel = scratch_array(scratch, "visible.pixel", h * w, np.int64)
    points = scratch_array(scratch, "visible.points", (h * w, 3))
    normals = scratch_array(scratch, "visible.normals", (h * w, 3))
    with_albedo = albedo
    albedo = scratch_array(scratch, "visible.albedo", (h * w if with_albedo else 0, 3))
    args = (f_img.reshape(-1), lookup, source, verts, np.ascontiguousarray(faces, np.int64),
            np.ascontiguousarray(all_normals), face_surface, np.ascontiguousarray(offsets, np.int64), albedos, ground,
            ground_albedo is not None, view, rays, directions, h, w, surface.reshape(-1), face.reshape(-1), pixel,
            points, normals, albedo)
    if parallel_numba().get_num_threads() > 1:
        n = _visible_kernel()[1](*args, scratch_array(scratch, "visible.distance", h * w),
                                 scratch_array(scratch, "visible.mesh_face", h * w, np.int32))
    else:  # one pass (the two passes' extra stores cost a fifth more on one thread)
        n = _visible_kernel()[0](*args)
    pixel, points, normals, albedo = pixel[:n], points[:n], normals[:n], albedo[:n] if with_albedo else None
    if smooth:
        on_mesh = surface.reshape(-1)[pixel] >= 0
        if on_mesh.any():
            # Turned as the face is (by the face's side, not the interpolated normal's: near an
            # outline that one may lean away from the camera while the face does not).
            vn = np.vstack([s.vertex_normals for s in surfaces])
            fid = face.reshape(-1)[pixel[on_mesh]] + offsets[surface.reshape(-1)[pixel[on_mesh]]]
            f = faces[fid]
            sign = np.where(np.einsum("ij,ij->i", normals[on_mesh], all_normals[fid]) < 0, -1.0, 1.0)[:, None]
            normals[on_mesh] = sign * _interpolate(points[on_mesh], verts[f], vn[f])
    return VisibleSurfaces((h, w), pixel, points, normals, albedo, surface, face)


@functools.cache
def _visible_kernel():
    """The compiled pass of ``visible_surfaces`` (numba): per pixel, the ray's distance to its
    z-buffer face's plane (exact) and to the ground, the nearer kept; the pixels that see
    something get their point, normal (turned towards the camera) and albedo, in pixel order.
    Returns how many do. ``surface``/``face`` get NOTHING, GROUND or a mesh's index and face.

    Returns (the kernel, the kernel on numba's threads). The second runs two passes parallel over
    rows: what each pixel sees (its face and distance kept in dist and mesh_face, (H W,)) and
    each row's count, then (at each row's place in the compact arrays, from the counts) the
    points, normals and albedos: the first's arrays."""
    numba = parallel_numba()

    @numba.njit(cache=True, nogil=True)
    def kernel(f_img, lookup, source, verts, faces, normals, face_surface, offsets, albedos, ground, has_ground,
               view, rays, directions, h, w, surface, face, pixel, points, out_normals, albedo):
        n = 0
        row, col = 0, -1
        for p in range(h * w):
            col += 1  # row order, without a division per pixel
            if col == w:
                row, col = row + 1, 0
            # The pixel's ray: a top-down map's (origin, pixel size, height in view[1:5]) or a
            # pinhole camera's (centre in view[1:4]; K^-1's first two rows and R in rays;
            # precomputed directions for a camera with lens distortion).
            if view[0] == 0.0:
                ox, oy, oz = view[1] + col * view[3], view[2] - row * view[3], view[4]
                dx, dy, dz = 0.0, 0.0, -1.0
            elif directions.shape[0]:
                ox, oy, oz = view[1], view[2], view[3]
                dx, dy, dz = directions[p, 0], directions[p, 1], directions[p, 2]
            else:
                ox, oy, oz = view[1], view[2], view[3]
                nx = rays[0, 0] * col + rays[0, 1] * row + rays[0, 2]
                ny = rays[1, 0] * col + rays[1, 1] * row + rays[1, 2]
                dx = nx * rays[3, 0] + ny * rays[4, 0] + rays[5, 0]
                dy = nx * rays[3, 1] + ny * rays[4, 1] + rays[5, 1]
                dz = nx * rays[3, 2] + ny * rays[4, 2] + rays[5, 2]
            t_mesh = np.inf
            fid = -1
            q = p if lookup.shape[0] == 0 else lookup[p]
            if q >= 0 and f_img[q] >= 0:
                fid = f_img[q] if source.shape[0] == 0 else source[f_img[q]]
                nx, ny, nz = normals[fid, 0], normals[fid, 1], normals[fid, 2]
                v0 = faces[fid, 0]
                denom = nx * dx + ny * dy + nz * dz
                if abs(denom) > 1e-12:
                    t = (nx * (verts[v0, 0] - ox) + ny * (verts[v0, 1] - oy) + nz * (verts[v0, 2] - oz)) / denom
                    if t > 0:
                        t_mesh = t
            t_ground = np.inf
            if has_ground and abs(dz) > 1e-12:
                t = -oz / dz
                if t > 0:
                    t_ground = t
            if t_mesh <= t_ground and t_mesh < np.inf:
                s = face_surface[fid]
                surface[p] = s
                face[p] = fid - offsets[s]
                t = t_mesh
                nx, ny, nz = normals[fid, 0], normals[fid, 1], normals[fid, 2]
                a0, a1, a2 = albedos[s, 0], albedos[s, 1], albedos[s, 2]
            elif t_ground < np.inf:
                surface[p] = GROUND
                face[p] = -1
                t = t_ground
                nx, ny, nz = 0.0, 0.0, 1.0
                a0, a1, a2 = ground[0], ground[1], ground[2]
            else:
                surface[p] = NOTHING
                face[p] = -1
                continue
            pixel[n] = p
            points[n, 0], points[n, 1], points[n, 2] = ox + t * dx, oy + t * dy, oz + t * dz
            if nx * dx + ny * dy + nz * dz > 0:  # towards the camera: the side it sees is lit
                nx, ny, nz = -nx, -ny, -nz
            out_normals[n, 0], out_normals[n, 1], out_normals[n, 2] = nx, ny, nz
            if albedo.shape[0]:
                albedo[n, 0], albedo[n, 1], albedo[n, 2] = a0, a1, a2
            n += 1
        return n


    @numba.njit(cache=True, nogil=True, parallel=True)
    def parallel_kernel(f_img, lookup, source, verts, faces, normals, face_surface, offsets, albedos, ground,
                        has_ground, view, rays, directions, h, w, surface, face, pixel, points, out_normals, albedo,
                        dist, mesh_face):
        # ``kernel``'s arithmetic, in two passes over rows (written out: as called functions the
        # same loops ran twice as slow).
        counts = np.zeros(h + 1, np.int64)
        for row in numba.prange(h):
            count = 0
            for col in range(w):
                p = row * w + col
                if view[0] == 0.0:
                    ox, oy, oz = view[1] + col * view[3], view[2] - row * view[3], view[4]
                    dx, dy, dz = 0.0, 0.0, -1.0
                elif directions.shape[0]:
                    ox, oy, oz = view[1], view[2], view[3]
                    dx, dy, dz = directions[p, 0], directions[p, 1], directions[p, 2]
                else:
                    ox, oy, oz = view[1], view[2], view[3]
                    nx = rays[0, 0] * col + rays[0, 1] * row + rays[0, 2]
                    ny = rays[1, 0] * col + rays[1, 1] * row + rays[1, 2]
                    dx = nx * rays[3, 0] + ny * rays[4, 0] + rays[5, 0]
                    dy = nx * rays[3, 1] + ny * rays[4, 1] + rays[5, 1]
                    dz = nx * rays[3, 2] + ny * rays[4, 2] + rays[5, 2]
                t_mesh = np.inf
                fid = -1
                q = p if lookup.shape[0] == 0 else lookup[p]
                if q >= 0 and f_img[q] >= 0:
                    fid = f_img[q] if source.shape[0] == 0 else source[f_img[q]]
                    nx, ny, nz = normals[fid, 0], normals[fid, 1], normals[fid, 2]
                    v0 = faces[fid, 0]
                    denom = nx * dx + ny * dy + nz * dz
                    if abs(denom) > 1e-12:
                        t = (nx * (verts[v0, 0] - ox) + ny * (verts[v0, 1] - oy) + nz * (verts[v0, 2] - oz)) / denom
                        if t > 0:
                            t_mesh = t
                t_ground = np.inf
                if has_ground and abs(dz) > 1e-12:
                    t = -oz / dz
                    if t > 0:
                        t_ground = t
                if t_mesh <= t_ground and t_mesh < np.inf:
                    s = face_surface[fid]
                    surface[p] = s
                    face[p] = fid - offsets[s]
                    dist[p], mesh_face[p] = t_mesh, fid
                    count += 1
                elif t_ground < np.inf:
                    surface[p] = GROUND
                    face[p] = -1
                    dist[p], mesh_face[p] = t_ground, -1
                    count += 1
                else:
                    surface[p] = NOTHING
                    face[p] = -1
            counts[row + 1] = count
        for row in range(h):
            counts[row + 1] += counts[row]
        for row in numba.prange(h):
            n = counts[row]
            for col in range(w):
                p = row * w + col
                if surface[p] == NOTHING:
                    continue
                if view[0] == 0.0:
                    ox, oy, oz = view[1] + col * view[3], view[2] - row * view[3], view[4]
                    dx, dy, dz = 0.0, 0.0, -1.0
                elif directions.shape[0]:
                    ox, oy, oz = view[1], view[2], view[3]
                    dx, dy, dz = directions[p, 0], directions[p, 1], directions[p, 2]
                else:
                    ox, oy, oz = view[1], view[2], view[3]
                    nx = rays[0, 0] * col + rays[0, 1] * row + rays[0, 2]
                    ny = rays[1, 0] * col + rays[1, 1] * row + rays[1, 2]
                    dx = nx * rays[3, 0] + ny * rays[4, 0] + rays[5, 0]
                    dy = nx * rays[3, 1] + ny * rays[4, 1] + rays[5, 1]
                    dz = nx * rays[3, 2] + ny * rays[4, 2] + rays[5, 2]
                fid, t = mesh_face[p], dist[p]
                if fid >= 0:
                    s = face_surface[fid]
                    nx, ny, nz = normals[fid, 0], normals[fid, 1], normals[fid, 2]
                    a0, a1, a2 = albedos[s, 0], albedos[s, 1], albedos[s, 2]
                else:
                    nx, ny, nz = 0.0, 0.0, 1.0
                    a0, a1, a2 = ground[0], ground[1], ground[2]
                pixel[n] = p
                points[n, 0], points[n, 1], points[n, 2] = ox + t * dx, oy + t * dy, oz + t * dz
                if nx * dx + ny * dy + nz * dz > 0:  # towards the camera: the side it sees is lit
                    nx, ny, nz = -nx, -ny, -nz
                out_normals[n, 0], out_normals[n, 1], out_normals[n, 2] = nx, ny, nz
                if albedo.shape[0]:
                    albedo[n, 0], albedo[n, 1], albedo[n, 2] = a0, a1, a2
                n += 1
        return counts[h]

    return kernel, parallel_kernel


def _interpolate(points: np.ndarray, tri: np.ndarray, corner_normals: np.ndarray) -> np.ndarray:
    """Unit normals (N, 3) at points (N, 3) in triangles (N, 3, 3) from their corners' normals
    (N, 3, 3), barycentric."""
    e1, e2, d = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], points - tri[:, 0]
    d11, d12, d22 = (np.einsum("ij,ij->i", a, b) for a, b in ((e1, e1), (e1, e2), (e2, e2)))
    d1, d2 = np.einsum("ij,ij->i", d, e1), np.einsum("ij,ij->i", d, e2)
    det = np.where(np.abs(d11 * d22 - d12 * d12) > 1e-300, d11 * d22 - d12 * d12, 1.0)
    b1 = np.clip((d22 * d1 - d12 * d2) / det, 0.0, 1.0)
    b2 = np.clip((d11 * d2 - d12 * d1) / det, 0.0, 1.0)
    b0 = np.clip(1.0 - b1 - b2, 0.0, 1.0)
    n = b0[:, None] * corner_normals[:, 0] + b1[:, None] * corner_normals[:, 1] + b2[:, None] * corner_normals[:, 2]
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
