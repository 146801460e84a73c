"""Receivers: the surface the shadow falls on (the ground plane, a height field, or any mesh).

Every receiver answers ``surface_normals(points, tri)`` for the points where
camera rays meet it (``tri``: the hit triangle of its mesh, unused by the
analytic ones) and, when it is not the plane z = 0, gives a triangle mesh for
ray casting (it can hide sky and sun from itself and from the object). The
plane and the height field also answer ``height(xy)`` and ``normal(xy)`` (a
function of x, y; their sky is tabulated on world grids). The height field
stands in for a range-sensor background (the seed's figures 19-24): a smooth
procedural terrain, so its shading uses analytic normals while rays hit its
dense mesh. ``MeshReceiver`` is any mesh (steps, a kerb, a wall), flat-shaded.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
import trimesh

__all__ = ["Receiver", "PlaneReceiver", "HeightfieldReceiver", "MeshReceiver", "bank_terrain", "rising_bank",
           "steps_receiver", "wall_receiver", "texture_coordinates"]


@dataclasses.dataclass(frozen=True)
class PlaneReceiver:
    """The ground plane z = 0 (normal +z)."""

    mesh: None = None

    def height(self, xy: np.ndarray) -> np.ndarray:
        """Heights (N,) of world points xy (N, 2)."""
        return np.zeros(len(xy))

    def normal(self, xy: np.ndarray) -> np.ndarray:
        """Unit normals (N, 3)."""
        out = np.zeros((len(xy), 3))
        out[:, 2] = 1.0
        return out

    def max_slope(self) -> float:
        return 0.0

    def surface_normals(self, points: np.ndarray, tri: np.ndarray | None = None) -> np.ndarray:
        return self.normal(np.asarray(points)[:, :2])


@dataclasses.dataclass(frozen=True, eq=False)
class HeightfieldReceiver:
    """z = f(x, y) over a rectangle, with gradient grad(x, y) -> (df/dx, df/dy).

    bounds: (xmin, ymin, xmax, ymax) metres; spacing: mesh spacing in metres.
    Outside the rectangle the surface continues as f clamped to the border.
    """

    f: Callable[[np.ndarray, np.ndarray], np.ndarray]
    grad: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
    bounds: tuple[float, float, float, float]
    spacing: float = 0.05
    mesh: trimesh.Trimesh = dataclasses.field(init=False)

    def __post_init__(self):
        x0, y0, x1, y1 = self.bounds
        xs = np.arange(x0, x1 + 0.5 * self.spacing, self.spacing)
        ys = np.arange(y0, y1 + 0.5 * self.spacing, self.spacing)
        gx, gy = np.meshgrid(xs, ys)
        verts = np.stack([gx.ravel(), gy.ravel(), self.f(gx, gy).ravel()], -1)
        nx = len(xs)
        i, j = np.meshgrid(np.arange(len(ys) - 1), np.arange(nx - 1), indexing="ij")
        a = (i * nx + j).ravel()
        b, c, d = a + 1, a + nx + 1, a + nx
        faces = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)])  # +z facing
        object.__setattr__(self, "mesh", trimesh.Trimesh(verts, faces, process=False))

    def _clamp(self, xy):
        x0, y0, x1, y1 = self.bounds
        return np.clip(xy[:, 0], x0, x1), np.clip(xy[:, 1], y0, y1)

    def height(self, xy: np.ndarray) -> np.ndarray:
        x, y = self._clamp(np.asarray(xy, dtype=np.float64).reshape(-1, 2))
        return self.f(x, y)

    def normal(self, xy: np.ndarray) -> np.ndarray:
        x, y = self._clamp(np.asarray(xy, dtype=np.float64).reshape(-1, 2))
        fx, fy = self.grad(x, y)
        n = np.stack([-fx, -fy, np.ones_like(fx)], -1)
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def surface_normals(self, points: np.ndarray, tri: np.ndarray | None = None) -> np.ndarray:
        """Analytic unit normals (N, 3) at points (N, 3) (the smooth surface the mesh samples)."""
        return self.normal(np.asarray(points)[:, :2])

    def max_slope(self) -> float:
        """Largest |grad f| on the mesh nodes (for the no-self-shadowing check)."""
        v = self.mesh.vertices
        fx, fy = self.grad(v[:, 0], v[:, 1])
        return float(np.max(np.hypot(fx, fy)))


def bank_terrain(bounds=(-4.0, -4.0, 4.0, 8.0), rise_m: float = 0.6, start_y: float = 0.9,
                 width_m: float = 1.6, bump_m: float = 0.04, spacing: float = 0.04) -> HeightfieldReceiver:
    """Flat ground that rises smoothly (a grassy bank) north of y = start_y, with gentle bumps.

    Height = rise * S((y - start_y) / width) + bump * sin(2.1 x) sin(1.7 y), S the
    smoothstep 3t^2 - 2t^3 on [0, 1]. The steepest slope is 1.5 rise / width + bumps.
    """
    def f(x, y):
        t = np.clip((y - start_y) / width_m, 0.0, 1.0)
        return rise_m * (3 * t ** 2 - 2 * t ** 3) + bump_m * np.sin(2.1 * x) * np.sin(1.7 * y) * (1 - 0.8 * t)

    def grad(x, y):
        t = np.clip((y - start_y) / width_m, 0.0, 1.0)
        inside = ((y - start_y) > 0) & ((y - start_y) < width_m)
        ds = np.where(inside, 6 * t * (1 - t) / width_m, 0.0)
        damp = 1 - 0.8 * t
        ddamp = np.where(inside, -0.8 / width_m, 0.0)
        fx = bump_m * 2.1 * np.cos(2.1 * x) * np.sin(1.7 * y) * damp
        fy = rise_m * ds + bump_m * np.sin(2.1 * x) * (1.7 * np.cos(1.7 * y) * damp + np.sin(1.7 * y) * ddamp)
        return fx, fy

    return HeightfieldReceiver(f, grad, tuple(bounds), spacing)


def rising_bank(azimuth_deg: float, start_m: float, rise_m: float, width_m: float = 1.6, bump_m: float = 0.02,
                centre_xy=(0.0, 0.0), half_extent_m: float = 8.0, spacing: float = 0.04) -> HeightfieldReceiver:
    """Flat ground that rises smoothly by ``rise_m`` towards the compass azimuth, with gentle bumps.

    t = (x, y) . (sin a, cos a) is the distance towards the azimuth from the origin: height =
    rise * S((t - start_m) / width_m) + bump * sin(2.1 x) sin(1.7 y) (1 - 0.8 S'), S the
    smoothstep 3u^2 - 2u^3 on [0, 1] (so the bumps fade on the slope). The steepest slope is
    at most 1.5 rise / width + 2.8 bump (``max_slope`` measures it). The mesh covers the square
    ``centre_xy`` +- ``half_extent_m``.
    """
    a = np.radians(azimuth_deg)
    ax, ay = float(np.sin(a)), float(np.cos(a))

    def smooth(x, y):
        t = (x * ax + y * ay - start_m) / width_m
        inside = (t > 0) & (t < 1)
        u = np.clip(t, 0.0, 1.0)
        return u, inside

    def f(x, y):
        u, _ = smooth(x, y)
        return rise_m * (3 * u ** 2 - 2 * u ** 3) + bump_m * np.sin(2.1 * x) * np.sin(1.7 * y) * (1 - 0.8 * u)

    def grad(x, y):
        u, inside = smooth(x, y)
        ds = np.where(inside, 6 * u * (1 - u) / width_m, 0.0)  # d S / d t
        du = np.where(inside, 1.0 / width_m, 0.0)
        sx, sy = np.sin(2.1 * x), np.sin(1.7 * y)
        damp = 1 - 0.8 * u
        fx = rise_m * ds * ax + bump_m * (2.1 * np.cos(2.1 * x) * sy * damp - 0.8 * sx * sy * du * ax)
        fy = rise_m * ds * ay + bump_m * (1.7 * sx * np.cos(1.7 * y) * damp - 0.8 * sx * sy * du * ay)
        return fx, fy

    cx, cy = float(centre_xy[0]), float(centre_xy[1])
    h = float(half_extent_m)
    return HeightfieldReceiver(f, grad, (cx - h, cy - h, cx + h, cy + h), spacing)


@dataclasses.dataclass(frozen=True, eq=False)
class MeshReceiver:
    """Any triangle mesh in world metres (steps, a kerb, a wall), shaded with its face normals.

    It may shadow itself and hide sky from itself; the physical renderer casts
    sun rays against it everywhere and computes its sky per pixel (it is not a
    function of x, y: a wall has many points over one ground point).
    """

    mesh: trimesh.Trimesh

    def surface_normals(self, points: np.ndarray, tri: np.ndarray) -> np.ndarray:
        """Unit face normals (N, 3) of the hit triangles tri (N,)."""
        return np.asarray(self.mesh.face_normals)[np.asarray(tri, dtype=np.int64)]



#: The receivers a synthetic scene can have.
Receiver = PlaneReceiver | HeightfieldReceiver | MeshReceiver

def texture_coordinates(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Where a receiver point reads the ground texture (N, 2), metres.

    Surfaces closer to horizontal than 60 degrees read it at their (x, y), as the
    ground does; steeper ones (a wall, a riser) at (position along the surface's
    horizontal tangent, height), so their texture is not smeared down the face.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    out = p[:, :2].copy()
    steep = np.abs(n[:, 2]) < 0.5
    if steep.any():
        t = np.stack([-n[steep, 1], n[steep, 0]], -1)
        t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
        out[steep, 0] = t[:, 0] * p[steep, 0] + t[:, 1] * p[steep, 1]
        out[steep, 1] = p[steep, 2] + 7.3  # an offset so that the face does not repeat the ground below
    return out


def _ground_square(half_m: float) -> trimesh.Trimesh:
    """The square [-half, half]^2 of the plane z = 0, facing up."""
    h = float(half_m)
    v = np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]])
    return trimesh.Trimesh(v, np.array([[0, 1, 2], [0, 2, 3]]), process=False)


def _placed_box(extents, centre_local, azimuth_deg: float) -> trimesh.Trimesh:
    """A box with extents (across, along, up) whose local +y points to the compass azimuth."""
    box = trimesh.creation.box(extents=extents)
    box.apply_translation(centre_local)
    a = np.radians(azimuth_deg)
    # Local +y -> (sin a, cos a, 0); local +x -> (cos a, -sin a, 0): a rotation about z by -a.
    rot = trimesh.transformations.rotation_matrix(-a, [0, 0, 1])
    box.apply_transform(rot)
    return box


def steps_receiver(azimuth_deg: float, start_m: float = 0.6, n_steps: int = 4, rise_m: float = 0.16,
                   tread_m: float = 0.32, width_m: float = 3.0, landing_m: float = 2.5,
                   ground_half_m: float = 60.0) -> MeshReceiver:
    """Open ground with a flight of steps climbing towards the compass azimuth.

    The first riser stands start_m from the origin (the object's base) along the
    azimuth; n_steps steps of rise_m and tread_m, the last one a landing
    landing_m deep; width_m across. Walking up, each riser faces back towards
    the origin (towards the sun when the azimuth points along the shadow).
    """
    parts = [_ground_square(ground_half_m)]
    for i in range(n_steps):
        top = rise_m * (i + 1)
        near = start_m + tread_m * i
        far = start_m + tread_m * (n_steps - 1) + landing_m
        parts.append(_placed_box((width_m, far - near, top), (0.0, (near + far) / 2, top / 2), azimuth_deg))
    return MeshReceiver(trimesh.util.concatenate(parts))


def wall_receiver(azimuth_deg: float, distance_m: float = 1.0, height_m: float = 2.2, thickness_m: float = 0.2,
                  width_m: float = 4.0, ground_half_m: float = 60.0) -> MeshReceiver:
    """Open ground with a wall across the compass azimuth, its near face distance_m from the origin."""
    wall = _placed_box((width_m, thickness_m, height_m), (0.0, distance_m + thickness_m / 2, height_m / 2),
                       azimuth_deg)
    return MeshReceiver(trimesh.util.concatenate([_ground_square(ground_half_m), wall]))
