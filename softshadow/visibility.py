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

import numpy as np
import trimesh

from .camera import GroundGrid, PinholeCamera
from .clip import clip_near
from .posed import pose_matrix
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
    (a single number is grey); casts_shadows: drawn in projectors' shadow maps."""

    vertices: np.ndarray
    faces: np.ndarray
    albedo: np.ndarray = (0.8, 0.8, 0.8)
    name: str = "mesh"
    casts_shadows: bool = True

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
        """Unit normals (F, 3) from the winding (zero for degenerate faces)."""
        t = self.vertices[self.faces]
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


@dataclasses.dataclass(frozen=True)
class VisibleSurfaces:
    """The surface each pixel sees.

    shape (H, W); pixel (N,) flat indices of the pixels that see something; points (N, 3)
    world metres; normals (N, 3) unit, on the camera's side of their face; albedo (N, 3); surface (H, W)
    int: index into the surfaces, ``GROUND`` or ``NOTHING``; face (H, W) int: the face
    within its surface (-1 for the ground and nothing).
    """

    shape: tuple[int, int]
    pixel: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    albedo: np.ndarray
    surface: np.ndarray
    face: np.ndarray


def _camera_rays(camera, h: int, w: int, top: float) -> tuple[np.ndarray, np.ndarray]:
    """Ray origins and directions (H*W, 3) of every pixel centre (row order)."""
    rows, cols = np.mgrid[0:h, 0:w]
    if isinstance(camera, GroundGrid):
        origin = camera.to_world(cols, rows).reshape(-1, 3)
        origin[:, 2] = top  # above everything, looking straight down
        return origin, np.tile([0.0, 0.0, -1.0], (len(origin), 1))
    d = camera.pixel_rays(cols, rows)
    return np.broadcast_to(camera.centre, d.shape), d


def visible_surfaces(camera: PinholeCamera | GroundGrid, surfaces=(), ground_albedo=None,
                     smooth: bool = False) -> VisibleSurfaces:
    """The nearest surface at every pixel of ``camera`` (see the module docstring).

    surfaces: a sequence of ``Surface``; ground_albedo: the ground plane z = 0's albedo (one or
    three numbers), None for no ground; smooth: normals interpolated from the vertex normals
    (Gouraud/Phong-like, barycentric at the point) instead of the faces' own (flat, the default).
    """
    h, w = camera.height, camera.width
    surfaces = list(surfaces)
    offsets = np.cumsum([0] + [len(s.faces) for s in surfaces])
    verts = np.vstack([s.vertices for s in surfaces]) if surfaces else np.zeros((0, 3))
    vstart = np.cumsum([0] + [len(s.vertices) for s in surfaces])
    faces = (np.vstack([s.faces + vstart[i] for i, s in enumerate(surfaces)]) if surfaces
             else np.zeros((0, 3), np.int64))
    origin, direction = _camera_rays(camera, h, w, float(max(verts[:, 2].max(initial=0.0), 0.0)) + 1.0)
    if isinstance(camera, GroundGrid):
        xy, depth = camera.to_pixel(verts), -verts[:, 2]
        drawn, source = faces, np.arange(len(faces))
        lookup = np.arange(h * w)
    else:
        # Faces cut at the near plane (a floor passing under and behind the camera stays whole in view).
        cut, drawn, source = clip_near(verts, verts @ camera.R[2] + camera.t[2], faces, NEAR_M)
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
        else:
            lookup = np.arange(h * w)
    fid = np.full(h * w, -1, np.int64)
    if len(drawn):
        _, f_img = rasterise_depth(xy, depth, drawn, (h, w))
        f_img = f_img.ravel()
        ok = lookup >= 0
        fid[ok] = np.where(f_img[lookup[ok]] >= 0, source[np.maximum(f_img[lookup[ok]], 0)], -1)
    # The ray's distance to the face's plane (exact), and to the ground.
    all_normals = (np.vstack([s.face_normals for s in surfaces]) if surfaces else np.zeros((0, 3)))
    t_mesh = np.full(h * w, np.inf)
    hit = np.flatnonzero(fid >= 0)
    if len(hit):
        n = all_normals[fid[hit]]
        v0 = verts[faces[fid[hit], 0]]
        denom = np.einsum("ij,ij->i", n, direction[hit])
        ok = np.abs(denom) > 1e-12
        t = np.einsum("ij,ij->i", n, v0 - origin[hit]) / np.where(ok, denom, 1.0)
        t_mesh[hit] = np.where(ok & (t > 0), t, np.inf)
    t_ground = np.full(h * w, np.inf)
    if ground_albedo is not None:
        dz = direction[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -origin[:, 2] / dz
        t_ground = np.where((np.abs(dz) > 1e-12) & (t > 0), t, np.inf)
    mesh_wins = t_mesh <= t_ground
    t_best = np.minimum(t_mesh, t_ground)
    pixel = np.flatnonzero(np.isfinite(t_best))
    points = origin[pixel] + t_best[pixel, None] * direction[pixel]
    on_mesh = mesh_wins[pixel]
    normals = np.tile([0.0, 0.0, 1.0], (len(pixel), 1))
    normals[on_mesh] = all_normals[fid[pixel[on_mesh]]]
    # Towards the camera: the side the camera sees is the lit side of an open surface.
    flip = np.einsum("ij,ij->i", normals, direction[pixel]) > 0
    normals[flip] *= -1
    if smooth and on_mesh.any():
        # Turned as the face is (by the face's side, not the interpolated normal's: near an outline
        # that one may lean away from the camera while the face does not).
        vn = np.vstack([s.vertex_normals for s in surfaces])
        f = faces[fid[pixel[on_mesh]]]
        sign = np.where(flip[on_mesh], -1.0, 1.0)[:, None]
        normals[on_mesh] = sign * _interpolate(points[on_mesh], verts[f], vn[f])
    surface = np.full(h * w, NOTHING, np.int64)
    face = np.full(h * w, -1, np.int64)
    which = np.searchsorted(offsets, fid[pixel[on_mesh]], side="right") - 1
    surface[pixel[on_mesh]] = which
    face[pixel[on_mesh]] = fid[pixel[on_mesh]] - offsets[which]
    surface[pixel[~on_mesh]] = GROUND
    albedos = np.array([s.albedo for s in surfaces]).reshape(-1, 3)
    albedo = np.empty((len(pixel), 3))
    albedo[on_mesh] = albedos[which] if len(which) else np.zeros((0, 3))
    albedo[~on_mesh] = _albedo(ground_albedo) if ground_albedo is not None else 0.0
    return VisibleSurfaces((h, w), pixel, points, normals, albedo, surface.reshape(h, w), face.reshape(h, w))


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
